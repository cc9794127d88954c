"""Soak: long fault-free changing operation raises no alarm.

The monitor's own tests already replay ``fault_free_hour`` (seed 0, `Monitor.run`) and 24
separately simulated hours with a fresh monitor each (tests/test_detect_sim_rig.py). These
are different: the CI version goes through `fdi replay` (an npz file, the summary's
``alarm_episodes``) on another hour (seed 7); the soak version keeps ONE monitor running
over 24 consecutive hours of ONE uninterrupted simulated run (the rig's state and drift
continue; each hour a fresh random program), as the daemon would run for a day.
"""

from __future__ import annotations

import json

import pytest
from reliability_support import REPO, continuous_fault_free_hours, load_test_model, model_path

from fdi_daemon.cli import main
from fdi_daemon.detect.monitor import Monitor
from fdi_daemon.io.recordings import Recording, write_recording


@pytest.mark.slow
def test_fdi_replay_of_another_fault_free_hour_has_no_alarm_episode(tmp_path):
    from hil_sim.scenarios import load_scenario, simulate

    rec = simulate(load_scenario(REPO / "configs" / "scenarios" / "fault_free_hour.yaml"), seed=7)
    cols = {k: rec.columns[k] for k in ("t", "v_in", "accel", "seq")}
    path = write_recording(tmp_path / "hour.npz", Recording(cols, dict(rec.meta)))
    del rec, cols
    summary = tmp_path / "summary.json"
    assert (
        main(
            [
                "replay",
                str(path),
                "--model",
                str(model_path()),
                "--summary",
                str(summary),
                "--events",
                str(tmp_path / "ev.jsonl"),
            ]
        )
        == 0
    )
    result = json.loads(summary.read_text())
    assert result["samples"] == 3600 * 256
    assert result["alarm_episodes"] == 0 and result["classification"] is None
    assert result["event_counts"] == {"calibrated": 1}


@pytest.mark.soak
def test_one_monitor_over_24_continuous_hours_has_no_alarm():
    monitor = Monitor(load_test_model())
    kinds: dict[str, int] = {}
    samples = 0
    for rec in continuous_fault_free_hours(24, seed=21):
        events, _ = monitor.run(rec, trace_every=len(rec))
        for e in events:
            kinds[e["kind"]] = kinds.get(e["kind"], 0) + 1
        samples += len(rec)
    assert samples == 24 * 3600 * 256
    assert kinds == {"calibrated": 1}
