"""The daemon's alarm across restarts and reloads, and the watchdog while the link is down.

- `test_a_five_minute_link_outage_keeps_the_watchdog_fed`: the real `ServiceLoop` over a
  real `ReconnectingLink` whose device is gone for 5 minutes, on an accelerated clock (the
  link's sleeps advance it), pinging a real AF_UNIX notify socket: no gap between pings
  longer than WatchdogSec/2, one link_lost / link_restored pair.
- `test_reload_and_sigkill_restart_keep_an_active_alarm`: `fdi run` as a process against
  the fake serial device: a friction fault raises one alarm; SIGHUP, then SIGKILL and a
  restart, keep it (same alarm id, no second alarm_raised, counters kept); a stall of the
  field link meanwhile is a link_lost/link_restored pair with the watchdog still fed; the
  alarm is acknowledged over the status socket.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import time

import pytest
import yaml
from reliability_support import Collector, model_path

from fdi_daemon.io.links.base import ReconnectingLink
from fdi_daemon.io.sample import Sample
from fdi_daemon.service.loop import ServiceLoop
from fdi_daemon.service.notify import Notifier

FS = 256.0
WATCHDOG_SEC = 30.0


class SimClock:
    """Simulated monotonic time; ``sleep`` advances it."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        self.now += seconds


class Device:
    """The field device behind the link: up or down; 8 samples per read while up."""

    def __init__(self, clock: SimClock) -> None:
        self.clock = clock
        self.up = True
        self.seq = 0


class DeviceLink:
    kind = "scripted"
    finished = False

    def __init__(self, device: Device) -> None:
        self.device = device
        self.samples = 0

    def open(self) -> None:
        if not self.device.up:
            raise ConnectionRefusedError("device not answering")

    def read(self, timeout_s: float) -> list[Sample]:
        if not self.device.up:
            raise ConnectionResetError("device gone")
        self.device.clock.sleep(8 / FS)
        seqs = range(self.device.seq, self.device.seq + 8)
        self.device.seq += 8
        self.samples += 8
        return [Sample(s, s / FS, 0.0, 0.0) for s in seqs]

    def close(self) -> None:
        pass

    def counters(self) -> dict[str, int]:
        return {"samples": self.samples}

    def describe(self) -> str:
        return "scripted device"


class QuietMonitor:
    def step(self, sample):
        return []

    def finish(self):
        return []

    def snapshot(self):
        return {"state": "monitoring"}


class TimedNotifier(Notifier):
    """A real notifier that also notes the simulated time of each watchdog ping."""

    def __init__(self, address: str, clock: SimClock) -> None:
        super().__init__(address)
        self.clock = clock
        self.ping_times: list[float] = []

    def watchdog(self) -> bool:
        self.ping_times.append(self.clock())
        return super().watchdog()


def test_a_five_minute_link_outage_keeps_the_watchdog_fed(tmp_path):
    clock = SimClock()
    device = Device(clock)
    link = ReconnectingLink(
        lambda: DeviceLink(device),
        backoff_initial_s=0.1,
        backoff_max_s=5.0,
        stall_timeout_s=3.0,
        clock=clock,
        sleep=clock.sleep,
    )
    from test_e2e_service import NotifyListener

    systemd = NotifyListener(tmp_path / "notify.sock")  # reads as systemd does
    notifier = TimedNotifier(str(systemd.path), clock)
    out = Collector()
    loop = ServiceLoop(
        link,
        QuietMonitor(),
        out,
        fs_hz=FS,
        read_timeout_s=0.05,
        status_period_s=1.0,
        notifier=notifier,
        watchdog_period_s=WATCHDOG_SEC / 2,
        clock=clock,
    )
    link.open()
    phases = [(60.0, True), (300.0, False), (60.0, True)]
    outage = (clock.now + 60.0, clock.now + 360.0)
    try:
        for seconds, up in phases:
            device.up = up
            end = clock.now + seconds
            while clock.now < end:
                loop.iterate()
        deadline = time.monotonic() + 10.0
        while (
            len(systemd.times("WATCHDOG=1")) < len(notifier.ping_times)
            and time.monotonic() < deadline
        ):
            time.sleep(0.05)
        received = len(systemd.times("WATCHDOG=1"))
    finally:
        notifier.close()
        systemd.close()
    pings = notifier.ping_times
    assert received == len(pings) and notifier.errors == 0
    gaps = [b - a for a, b in zip(pings, pings[1:])]
    assert max(gaps) <= WATCHDOG_SEC / 2 + 0.1, max(gaps)
    assert sum(outage[0] < t < outage[1] for t in pings) >= 19  # fed all through the outage
    assert [e["kind"] for e in out.events] == ["link_lost", "link_restored"]
    assert out.events[1]["down_s"] == pytest.approx(300.0, abs=6.0)


# ----------------------------------------------------------------------------- the process


def write_config(path, link, state_dir):
    config = {
        "link": {
            **link,
            "reconnect": {"backoff_initial_s": 0.1, "backoff_max_s": 1.0, "stall_timeout_s": 1.0},
        },
        "model": {"path": str(model_path())},
        "sinks": {
            "event_log": "events.jsonl",
            "status_socket": "status.sock",
            "modbus_status": {"enabled": False},
        },
        "recorder": {"enabled": False},
        "service": {"state_dir": str(state_dir)},
        "alarms": {"allow_remote_acknowledge": True},
    }
    path.write_text(yaml.safe_dump(config))
    return path


def socket_request(path, request: dict) -> dict:
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
        sock.settimeout(10)
        sock.connect(str(path))
        sock.sendall(json.dumps(request).encode() + b"\n")
        data = b""
        while data.count(b"\n") < 2:
            chunk = sock.recv(65536)
            assert chunk, data
            data += chunk
    return json.loads(data.splitlines()[1])


@pytest.mark.slow
def test_reload_and_sigkill_restart_keep_an_active_alarm(tmp_path):
    from test_e2e_service import (
        CALIBRATION_TIMEOUT_S,
        DaemonProcess,
        NotifyListener,
        monitoring,
        start_device,
    )

    device, link = start_device("serial", seed=4)
    notify = NotifyListener(tmp_path / "notify.sock")
    env = {"NOTIFY_SOCKET": str(notify.path), "WATCHDOG_USEC": "2000000"}
    config = write_config(tmp_path / "rig.yaml", link, tmp_path)
    daemon = DaemonProcess(config, tmp_path, env=env)

    def raised():
        return [e for e in daemon.events() if e["kind"] == "alarm_raised"]

    def alarm_of(snap):
        return snap.get("alarm") or {}

    try:
        daemon.wait_for(monitoring, CALIBRATION_TIMEOUT_S, "calibration")
        device.set_fault("bearing_supply", 0.35)
        daemon.wait_event("alarm_raised")
        first = daemon.wait_for(
            lambda s: alarm_of(s) if alarm_of(s).get("annunciated") else None,
            60.0,
            "the alarm in the snapshot",
        )
        assert first["alarm_id"] == 1 and first["state"] == "unacknowledged"

        # SIGHUP: the monitor recalibrates on the faulty rig; the alarm goes on
        announced = sum(line.startswith("fdi run: config") for line in daemon.lines)
        os.kill(daemon.proc.pid, signal.SIGHUP)
        daemon.wait_for(
            lambda s: sum(line.startswith("fdi run: config") for line in daemon.lines) > announced,
            60.0,
            "reload",
        )
        samples = daemon.snapshot()["link"]["samples"]
        snap = daemon.wait_for(
            lambda s: s if s["link"]["samples"] > samples + 3 * 256 else None,
            60.0,
            "3 s of samples after the reload",
        )
        assert alarm_of(snap)["alarm_id"] == 1 and alarm_of(snap)["annunciated"], snap["alarm"]
        assert snap["counters"].get("fault_detected", 0) >= 1  # counters not reset
        assert len(raised()) == 1

        # SIGKILL and a restart: the state file brings the same alarm back
        assert daemon.stop(signal.SIGKILL) == -signal.SIGKILL
        daemon = DaemonProcess(config, tmp_path, env=env)
        snap = daemon.wait_for(
            lambda s: s if s.get("alarm") and s["link"]["samples"] > 3 * 256 else None,
            CALIBRATION_TIMEOUT_S,
            "the restarted daemon",
        )
        assert alarm_of(snap)["alarm_id"] == 1 and alarm_of(snap)["annunciated"], snap["alarm"]
        assert alarm_of(snap)["priority"] >= 1
        assert snap["counters"].get("fault_detected", 0) >= 1
        assert len(raised()) == 1

        # the field link stalls: a status and one link_lost/link_restored pair, the
        # watchdog fed throughout (WatchdogSec 2 s: systemd would kill after a 2 s gap)
        before = len(daemon.events())
        stall_start = time.monotonic()
        device.inject("stall", seconds=6.0)
        daemon.wait_event("link_lost", after=before)
        down = daemon.wait_for(
            lambda s: s if not s["link"]["connected"] else None, 30.0, "the link down in the status"
        )
        assert down["state"] != "starting"
        daemon.wait_event("link_restored", after=before)
        pings = [t for t in notify.times("WATCHDOG=1") if t > stall_start]
        gaps = [b - a for a, b in zip([stall_start] + pings, pings)]
        assert pings and max(gaps) < 2.0, gaps
        kinds = [e["kind"] for e in daemon.events()[before:]]
        assert kinds.count("link_lost") == 1 and kinds.count("link_restored") == 1

        # acknowledge over the status socket
        answer = socket_request(daemon.socket, {"request": "acknowledge"})
        assert answer["ok"] and answer["alarm"]["state"] == "acknowledged", answer
        daemon.wait_event("alarm_acknowledged")
        assert daemon.stop(signal.SIGTERM) == 0, daemon.output()
        state = json.loads((tmp_path / "state.json").read_text())
        assert state["alarm"]["state"]["state"] == "acknowledged"
        assert state["alarm"]["state"]["alarm_id"] == 1
    finally:
        daemon.stop(signal.SIGKILL)
        device.stop()
        notify.close()
