"""Link factory, sequence unwrapping and the reconnecting wrapper's backoff and events."""

import socket
import time

import pytest

from fdi_daemon.errors import ConfigError
from fdi_daemon.io.links.base import (
    Link,
    LinkError,
    ReconnectingLink,
    SeqUnwrapper,
    link_settings,
    make_link,
    make_reconnecting_link,
)
from fdi_daemon.io.sample import Sample


class FakeClock:
    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now

    def sleep(self, dt):
        assert dt >= 0
        self.now += dt


class ScriptedLink(Link):
    """A link whose open/read outcomes are scripted by the test (the wrapper is under test)."""

    kind = "scripted"

    def __init__(self, device):
        self.device = device

    def open(self):
        if not self.device["up"]:
            raise LinkError("connection refused")

    def read(self, timeout_s):
        if not self.device["up"]:
            raise LinkError("connection reset")
        seq = self.device["seq"]
        self.device["seq"] += 1
        return [Sample(seq, seq / 256.0, 0.0, 0.0)] if self.device["talking"] else []

    def close(self):
        pass

    def counters(self):
        return {"samples": 1}


def test_seq_unwrapper_follows_wraps_and_keeps_backward_jumps():
    u = SeqUnwrapper(16)
    assert [u(v) for v in (65534, 65535, 0, 1)] == [65534, 65535, 65536, 65537]
    assert u(10) == 65546
    assert u(5) == 65541  # a step back stays a step back


def test_backoff_doubles_to_the_cap_and_never_spins():
    clock = FakeClock()
    device = {"up": False, "seq": 0, "talking": True}
    link = ReconnectingLink(lambda: ScriptedLink(device), 0.1, 1.0, clock=clock, sleep=clock.sleep)
    link.open()
    while clock.now < 10.0:
        assert link.read(0.05) == []
    attempts = link.counters()["connect_attempts"]
    # attempts at 0, .1, .3, .7, 1.5, 2.5, ... 9.5: 1 + 4 doubling + 8 at the cap
    assert 10 <= attempts <= 14
    events = link.events()
    assert [e["kind"] for e in events] == ["link_lost"]  # one event per outage
    device["up"] = True
    clock.now += 1.0
    samples = link.read(0.05)
    assert len(samples) == 1
    restored = link.events()
    assert [e["kind"] for e in restored] == ["link_restored"]
    assert restored[0]["down_s"] >= 10.0


def test_a_device_that_accepts_connections_but_stays_silent_is_one_outage():
    """Restored means samples flow again, not that the port reopened (a stalled device)."""
    clock = FakeClock()
    device = {"up": True, "seq": 0, "talking": True}
    link = ReconnectingLink(
        lambda: ScriptedLink(device), 0.1, 0.4, stall_timeout_s=1.0, clock=clock, sleep=clock.sleep
    )
    link.open()
    assert link.read(0.1)
    device["talking"] = False
    while clock.now < 20.0:  # stalls, reconnects, stalls again ... all one outage
        link.read(0.1)
        clock.now += 0.1
    assert [e["kind"] for e in link.events()] == ["link_lost"]
    assert link.counters()["stalls"] >= 5
    device["talking"] = True
    while not link.read(0.1):
        clock.now += 0.1
    restored = link.events()
    assert [e["kind"] for e in restored] == ["link_restored"]
    assert restored[0]["down_s"] >= 18.0


def test_lost_and_restored_events_carry_the_last_sample_time():
    clock = FakeClock()
    device = {"up": True, "seq": 100, "talking": True}
    link = ReconnectingLink(lambda: ScriptedLink(device), 0.1, 5.0, clock=clock, sleep=clock.sleep)
    link.open()
    got = link.read(0.1) + link.read(0.1)
    assert [s.seq for s in got] == [100, 101]
    device["up"] = False
    assert link.read(0.1) == []
    lost = link.events()
    assert lost[0]["kind"] == "link_lost" and lost[0]["t"] == 101 / 256.0
    assert "reset" in lost[0]["reason"]
    device["up"] = True
    while not link.connected:
        link.read(0.1)
    assert link.events()[0]["kind"] == "link_restored"
    c = link.counters()
    assert c["disconnects"] == 1 and c["connects"] == 2 and c["connected"] == 1
    assert c["samples"] == 2  # the first link's count survives the reconnect (+ the new one's)


def test_a_silent_link_counts_as_stalled_and_is_reopened():
    clock = FakeClock()
    device = {"up": True, "seq": 0, "talking": False}
    link = ReconnectingLink(
        lambda: ScriptedLink(device), 0.1, 5.0, stall_timeout_s=2.0, clock=clock, sleep=clock.sleep
    )
    link.open()
    for _ in range(30):
        link.read(0.1)
        clock.now += 0.1
    assert link.counters()["stalls"] == 1
    assert "no samples" in link.events()[0]["reason"]


def test_backoff_against_a_real_closed_port_is_bounded():
    with socket.socket() as s:  # find a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    link = make_reconnecting_link(
        {
            "kind": "modbus-tcp",
            "port": port,
            "timeout_s": 0.5,
            "reconnect": {"backoff_initial_s": 0.05, "backoff_max_s": 0.4},
        }
    )
    link.open()
    end = time.monotonic() + 2.0
    reads = 0
    while time.monotonic() < end:
        assert link.read(0.02) == []
        reads += 1
    attempts = link.counters()["connect_attempts"]
    # a busy loop would make one attempt per read; capped backoff allows at most ~2 s / 0.4 s + 4
    assert 3 <= attempts <= 12 < reads
    assert [e["kind"] for e in link.events()] == ["link_lost"]


def test_make_link_validates_and_names_the_key():
    with pytest.raises(ConfigError, match="link.kind"):
        link_settings({"kind": "carrier-pigeon"})
    with pytest.raises(ConfigError, match="link.port: required"):
        link_settings({"kind": "serial"})
    with pytest.raises(ConfigError, match="link.bogus: unknown key"):
        link_settings({"kind": "serial", "port": "/dev/x", "bogus": 1})
    with pytest.raises(ConfigError, match="link.word_order"):
        link_settings({"kind": "modbus-tcp", "word_order": "middle"})
    with pytest.raises(ConfigError, match="link.port: expected int"):
        link_settings({"kind": "modbus-tcp", "port": "502"})
    for port in (99999, 0, -1):  # they were LINK LOST events, "cannot connect", for ever
        with pytest.raises(ConfigError, match=f"link.port: {port} is not a TCP port"):
            link_settings({"kind": "modbus-tcp", "port": port})
    with pytest.raises(ConfigError, match="link.reconnect.backoff_max_s"):
        link_settings({"kind": "sim", "reconnect": {"backoff_max_s": "soon"}})
    with pytest.raises(ConfigError, match="link.realtime: expected bool"):
        link_settings({"kind": "replay", "path": "x.csv", "realtime": 1})
    kind, settings, reconnect = link_settings({"kind": "modbus-rtu", "port": "/dev/ttyUSB0"})
    assert kind == "modbus-rtu" and settings["device_id"] == 1 and settings["word_order"] == "big"
    assert reconnect == {"backoff_initial_s": 0.1, "backoff_max_s": 5.0, "stall_timeout_s": 3.0}
    for config in (
        {"kind": "serial", "port": "/dev/null"},
        {"kind": "modbus-tcp", "port": 1502},
        {"kind": "modbus-rtu", "port": "/dev/null", "word_order": "little"},
        {"kind": "replay", "path": "x.csv", "realtime": False},
        {"kind": "sim", "seed": 3},
    ):
        assert make_link(config).kind == config["kind"]
