"""The replay's status snapshots: Monitor.snapshot() plus a link section describing the replay."""

from __future__ import annotations

import pytest
from conftest_dashboard import make_snapshot, screen_text

from fdi_daemon.dashboard.app import LatestSnapshot
from fdi_daemon.dashboard.render import render
from fdi_daemon.dashboard.replay_view import ALARM_ROWS, ReplayStatus


class FakeMonitor:
    def __init__(self) -> None:
        self.calls = 0

    def snapshot(self) -> dict:
        self.calls += 1
        return make_snapshot("monitoring")["monitor"]


class FakeClock:
    def __init__(self) -> None:
        self.now = 50.0

    def __call__(self) -> float:
        return self.now


def test_counts_lateness_events_and_publishes_at_the_period():
    clock, board, monitor = FakeClock(), LatestSnapshot(), FakeMonitor()
    fs = 256.0
    status = ReplayStatus(
        "rec.csv",
        "model.yaml",
        {"tool": "test"},
        1000,
        fs,
        board,
        period_s=0.1,
        deadline_s=0.05,
        clock=clock,
    )
    late = {100: 0.2, 101: 0.06}  # sample index -> seconds late
    for k in range(512):
        clock.now = 50.0 + k / fs + late.get(k, 0.0)
        events = []
        if k == 300:
            events = [{"t": k / fs, "kind": "data_gap", "missing_samples": 3}]
        if k == 400:
            events = [
                {"t": k / fs, "kind": "bad_sample"},
                {"t": k / fs, "kind": "fault_detected", "theta1": 0.3, "theta2": 0.4},
            ]
        status.on_tick(monitor, k / fs, events)
    # 2 s of samples, one snapshot per 0.1 s rounded up to whole samples (27 -> 0.105 s)
    assert 17 <= monitor.calls <= 20
    assert 480 <= board().snapshot["link"]["samples"] < 512  # the last one published
    snap = status.snapshot(monitor.snapshot())  # what the replay publishes when it ends
    link = snap["link"]
    assert link["kind"] == "replay" and link["where"] == "rec.csv"
    assert link["samples"] == 512 and link["total_samples"] == 1000
    assert link["gaps"] == 1 and link["bad_samples"] == 1 and link["crc_errors"] == 0
    assert link["deadline_misses"] == 2
    assert link["rate_hz"] == pytest.approx(fs, rel=0.01)
    assert link["tick_latency_us"]["p50"] == pytest.approx(0.0, abs=1.0)
    assert [a["kind"] for a in snap["alarms"]] == ["data_gap", "bad_sample", "fault_detected"]
    assert snap["t"] == pytest.approx(511 / fs)
    assert snap["model"] == {"path": "model.yaml", "provenance": {"tool": "test"}}
    text = screen_text(render(snap))
    assert "replay" in text and "512/1000" in text and "MONITORING" in text


def test_alarm_list_keeps_the_last_rows():
    clock, board = FakeClock(), LatestSnapshot()
    status = ReplayStatus("r", "m", {}, 100, 256.0, board, clock=clock)
    for k in range(ALARM_ROWS + 5):
        clock.now += 1 / 256
        status.account(clock.now, k / 256, [{"t": float(k), "kind": "cleared"}])
    alarms = status.snapshot(FakeMonitor().snapshot())["alarms"]
    assert len(alarms) == ALARM_ROWS and alarms[-1]["t"] == ALARM_ROWS + 4


def test_a_slow_first_sample_does_not_make_the_rest_look_early():
    clock, board = FakeClock(), LatestSnapshot()
    status = ReplayStatus("r", "m", {}, 600, 256.0, board, clock=clock)
    for k in range(600):
        clock.now = 50.0 + k / 256 + (0.08 if k == 0 else 0.001)
        status.account(clock.now, k / 256, [])
    latency = status.snapshot(FakeMonitor().snapshot())["link"]["tick_latency_us"]
    assert latency["p50"] == pytest.approx(0.0, abs=1.0)
    assert latency["p99"] == pytest.approx(0.0, abs=1.0)
