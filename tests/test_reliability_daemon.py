"""The daemon as a process: SIGKILL mid-run and restart; a real-time run with no deadline miss.

`fdi run --config` runs as a subprocess (`test_e2e_service.DaemonProcess`) against the fake
device served from this test process over a real transport, with the recorder and the
event log on. Crash safety: after each SIGKILL (at seeded random moments) every event-log
line parses, every recording reads (``strict=False``), the newest recording reaches to
within 1 s of the device's sample time at the kill, and a restart appends to the event log
and starts a new recording file. Real time: over Modbus TCP the daemon keeps every tick
within its deadline (``service.deadline_s``, 50 ms) and loses no sample.
"""

from __future__ import annotations

import json
import signal
import time

import numpy as np
import pytest
from reliability_support import ALARMS, write_config
from test_e2e_service import (
    DaemonProcess,
    archived_recordings,
    device_time_s,
    monitoring,
    start_device,
)

from fdi_daemon.io.recordings import read_recording

STARTUP_TIMEOUT_S = 180.0


def event_lines(path) -> list[str]:
    return path.read_text(encoding="utf-8").splitlines() if path.exists() else []


def crash_cycles(tmp_path, kills: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    device, link = start_device("serial", seed=seed)
    config = write_config(tmp_path / "rig.yaml", link, tmp_path)
    events_path = tmp_path / "events.jsonl"
    daemon = None
    previous_lines: list[str] = []
    try:
        for run in range(kills + 1):
            daemon = DaemonProcess(config, tmp_path)
            daemon.wait_for(monitoring, STARTUP_TIMEOUT_S, f"run {run}: monitoring")
            if run == kills:  # the last restart: it resumed, now stop it cleanly
                assert daemon.stop(signal.SIGTERM) == 0, daemon.output()
                break
            time.sleep(float(rng.uniform(0.2, 3.0)))  # a random moment of the run
            t_kill = device_time_s(device)
            assert daemon.stop(signal.SIGKILL) == -signal.SIGKILL

            lines = event_lines(events_path)
            assert lines[: len(previous_lines)] == previous_lines, "the event log was rewritten"
            events = [json.loads(line) for line in lines]  # every line is whole JSON
            assert sum(e["kind"] == "calibrated" for e in events) == run + 1
            previous_lines = lines
            files = archived_recordings(tmp_path / "recordings")
            assert len(files) == run + 1, "a restart starts a new recording file"
            recs = [read_recording(f, strict=False) for f in files]
            assert recs[-1].t[-1] >= t_kill - 1.0, (run, recs[-1].t[-1], t_kill)
            assert all(r.fs == 256.0 and len(r) > 0 for r in recs)
        events = [json.loads(line) for line in event_lines(events_path)]
        assert [e for e in events if e["kind"] in ALARMS] == []
    finally:
        if daemon is not None:
            daemon.stop(signal.SIGKILL)
        device.stop()


@pytest.mark.slow
def test_sigkill_and_restart_keep_logs_and_recordings(tmp_path):
    crash_cycles(tmp_path, kills=2, seed=11)


@pytest.mark.soak
def test_sigkill_and_restart_soak(tmp_path):
    crash_cycles(tmp_path, kills=20, seed=12)


def realtime_run(tmp_path, seconds: float, judge_deadlines: bool) -> None:
    """Run the daemon in real time over Modbus TCP; nothing may be lost or go wrong.

    Deadline misses are a timing figure: they are judged only in the on-demand soak run (and
    reported by `fdi bench`), never in CI, where the machine is shared and noisy."""
    device, link = start_device("modbus-tcp", seed=5)
    config = write_config(tmp_path / "rig.yaml", link, tmp_path, recorder=True)
    daemon = DaemonProcess(config, tmp_path)
    try:
        before = daemon.wait_for(
            lambda s: s if monitoring(s) else None, STARTUP_TIMEOUT_S, "monitoring"
        )
        # count from a clean point: ticks before this (process start-up) are not judged
        time.sleep(seconds)
        after = daemon.snapshot()
        assert after is not None and daemon.proc.poll() is None, daemon.output()
        link_before, link_after = before["link"], after["link"]
        misses = (link_before["deadline_misses"], link_after["deadline_misses"])
        if judge_deadlines:
            assert misses == (0, 0), (misses, link_after["lateness_us"], daemon.output())
        assert link_after["gaps"] == 0 and link_after["missing_samples"] == 0
        assert link_after["samples"] - link_before["samples"] >= 0.9 * seconds * 256
        assert after["state"] == "monitoring"
        assert daemon.stop(signal.SIGTERM) == 0, daemon.output()
        summary = [line for line in daemon.lines if "deadline misses" in line]
        assert summary, daemon.output()
        print(summary[-1])  # the figures, with `pytest -s`
        if judge_deadlines:
            assert "deadline misses 0 " in summary[-1], summary
    finally:
        daemon.stop(signal.SIGKILL)
        device.stop()


@pytest.mark.slow
def test_realtime_modbus_tcp_30_s_loses_nothing(tmp_path):
    realtime_run(tmp_path, 30.0, judge_deadlines=False)


@pytest.mark.soak
def test_realtime_modbus_tcp_10_min_without_deadline_miss(tmp_path):
    realtime_run(tmp_path, 600.0, judge_deadlines=True)


def test_the_daemons_signal_handlers_hold_until_its_shutdown_is_done(tmp_path, monkeypatch):
    """A second SIGTERM while the outputs close (a slow disk, a broker far away) is the
    daemon's, not Python's default that ends the process half-way through its shutdown."""
    from conftest_detect import SCENARIOS

    from fdi_daemon.io.recordings import write_recording
    from fdi_daemon.service.daemon import Daemon
    from hil_sim.scenarios import load_scenario, simulate

    rec = write_recording(
        tmp_path / "rec.csv",
        simulate(load_scenario(SCENARIOS / "test_case_2.yaml"), duration_s=1.0),
    )
    config = write_config(
        tmp_path / "rig.yaml",
        {"kind": "replay", "path": str(rec), "realtime": False},
        tmp_path / "state",
        recorder=False,
        status_socket=False,
    )
    daemon = Daemon(config, echo=lambda line: None)
    during = []
    shutdown = daemon.shutdown
    monkeypatch.setattr(
        daemon, "shutdown", lambda: (during.append(signal.getsignal(signal.SIGTERM)), shutdown())
    )
    before = signal.getsignal(signal.SIGTERM)
    assert daemon.run(duration_s=5.0) == 0
    assert during == [daemon._on_stop]
    assert signal.getsignal(signal.SIGTERM) == before
