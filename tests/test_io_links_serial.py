"""Serial link against the real streaming device on a pty: data, injected faults, restarts."""

import time

import numpy as np
import pytest

from fdi_daemon.io.links.base import ReconnectingLink, make_link
from fdi_daemon.io.links.serial_link import SerialLink
from hil_sim.devices import SimulatedDevice, realtime_rig
from hil_sim.devices.realtime import DEFAULT_SCENARIO
from hil_sim.scenarios import scenario_from_dict, simulate


def read_until(link, predicate, timeout_s=10.0):
    out = []
    end = time.monotonic() + timeout_s
    while time.monotonic() < end and not predicate(out):
        out += link.read(0.05)
    return out


def read_for(link, seconds):
    end = time.monotonic() + seconds
    out = []
    while time.monotonic() < end:
        out += link.read(0.05)
    return out


def missing(samples):
    seqs = [s.seq for s in samples]
    return sum(b - a - 1 for a, b in zip(seqs, seqs[1:]))


def test_serial_link_delivers_the_simulated_rig_exactly():
    ref = simulate(scenario_from_dict(DEFAULT_SCENARIO), seed=2, duration_s=30.0)
    with SimulatedDevice("serial", realtime_rig(seed=2)) as dev:
        link = make_link(dev.link_config)
        link.open()
        samples = read_for(link, 1.2)
        link.close()
    assert len(samples) > 150 and missing(samples) == 0
    for s in samples:
        assert s.t == ref.t[s.seq]
        assert s.accel == float(np.float32(ref.accel[s.seq]))
        assert s.v_in == float(np.float32(ref.v_in[s.seq]))
        assert s.position == float(np.float32(ref["position"][s.seq]))


def test_injected_corruption_is_rejected_and_counted_exactly():
    with SimulatedDevice("serial", realtime_rig(seed=2), seed=9) as dev:
        link = SerialLink(dev.link_config["port"])
        link.open()
        try:
            start = read_until(link, lambda got: len(got) >= 20)
            base = link.counters()
            dev.inject("corrupt", count=5)
            dev.inject("truncate", count=3)
            dev.inject("garbage", count=20_000)  # a flood: spread over 20 gaps
            injected = dev.serial.injected
            done = lambda got: (  # noqa: E731
                injected()["corrupted_frames"] == 5
                and injected()["truncated_frames"] == 3
                and injected()["garbage_bytes"] + injected()["garbage_dropped_bytes"] == 20_000
                and len(got) > 60
            )
            during = read_until(link, done)
            during += read_for(link, 0.2)
        finally:
            link.close()
    c = link.counters()
    sent = injected()
    assert sent["tx_dropped"] == 0 and sent["garbage_bytes"] > 0
    assert c["crc_errors"] - base["crc_errors"] == 5 + 3
    assert c["bytes_dropped"] - base["bytes_dropped"] == 5 * 22 + 3 * 11 + sent["garbage_bytes"]
    assert missing(start + during) == 5 + 3


@pytest.mark.parametrize("rate", [1e-3, 1e-2])
def test_byte_noise_loses_exactly_the_frames_it_hit(rate):
    with SimulatedDevice("serial", realtime_rig(seed=2), seed=4) as dev:
        link = SerialLink(dev.link_config["port"])
        link.open()
        try:
            before = read_until(link, lambda got: len(got) >= 20)
            base = link.counters()
            dev.inject("noise", rate=rate)
            during = read_for(link, 1.5)
            dev.inject("noise", rate=0.0)
            noisy = dev.serial.injected()["noisy_frames"]
            during += read_for(link, 0.2)
        finally:
            link.close()
    c = link.counters()
    assert missing(before + during) == noisy
    assert c["crc_errors"] - base["crc_errors"] <= noisy
    if rate >= 1e-2:
        assert noisy > 20 and c["bytes_dropped"] - base["bytes_dropped"] == 22 * noisy


def test_a_stall_shows_as_a_seq_jump_of_exactly_the_stalled_frames():
    with SimulatedDevice("serial", realtime_rig(seed=2)) as dev:
        link = SerialLink(dev.link_config["port"])
        link.open()
        try:
            before = read_until(link, lambda got: len(got) >= 20)
            dev.inject("stall", seconds=0.5)
            after = read_for(link, 1.0)
        finally:
            link.close()
        stalled = dev.serial.injected()["stalled_frames"]
    assert stalled > 100
    assert missing(before + after) == stalled


def test_a_killed_and_restarted_device_is_found_again_through_its_symlink(tmp_path):
    port = str(tmp_path / "rig.tty")
    first = SimulatedDevice("serial", realtime_rig(seed=2), link_path=port)
    first.start()
    link = ReconnectingLink(lambda: SerialLink(port), backoff_initial_s=0.05, backoff_max_s=0.4)
    link.open()
    before = read_until(link, lambda got: len(got) >= 400)
    first.stop()
    assert read_for(link, 0.5) == []
    assert [e["kind"] for e in link.events()] == ["link_lost"]
    second = SimulatedDevice("serial", realtime_rig(seed=3), link_path=port)
    second.start()
    try:
        after = read_until(link, lambda got: len(got) >= 20)
    finally:
        second.stop()
        link.close()
    assert [e["kind"] for e in link.events()] == ["link_restored"]
    assert len(after) >= 20 and after[0].seq < before[-1].seq
    assert link.counters()["crc_errors"] == 0


def test_stall_longer_than_the_stall_timeout_reconnects():
    with SimulatedDevice("serial", realtime_rig(seed=2)) as dev:
        link = ReconnectingLink(
            lambda: SerialLink(dev.link_config["port"]),
            backoff_initial_s=0.05,
            backoff_max_s=0.2,
            stall_timeout_s=0.3,
        )
        link.open()
        try:
            before = read_until(link, lambda got: len(got) >= 20)
            dev.inject("stall", seconds=1.0)
            after = read_until(link, lambda got: len(got) >= 100, timeout_s=10.0)
        finally:
            link.close()
        stalled = dev.serial.injected()["stalled_frames"]
    kinds = [e["kind"] for e in link.events()]
    assert kinds[:2] == ["link_lost", "link_restored"]
    assert link.counters()["stalls"] >= 1
    assert missing(before + after) >= stalled > 0


@pytest.mark.parametrize("path", ["/nonexistent/tty0"])
def test_opening_a_missing_port_is_a_link_error(path):
    from fdi_daemon.io.links.base import LinkError

    with pytest.raises(LinkError, match="cannot open serial port"):
        SerialLink(path).open()
