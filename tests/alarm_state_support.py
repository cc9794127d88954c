"""A state folder whose state file holds an unacknowledged alarm of the default model."""

from __future__ import annotations

import time
from pathlib import Path

from fdi_daemon.alarms.lifecycle import AlarmLifecycle, AlarmSettings
from fdi_daemon.io.model_file import load_model
from fdi_daemon.service.config import load_config
from fdi_daemon.service.state_file import model_identity, write_state


def seed_open_alarm(state: Path, age_s: float = 3600.0) -> float:
    """Write ``state/state.json`` with alarm #1 raised ``age_s`` ago (unacknowledged, P1)
    and the counts of earlier runs; returns when it was raised (unix s)."""
    config = load_config(None)
    lifecycle = AlarmLifecycle(AlarmSettings())
    started = time.time() - age_s
    lifecycle.step(started, None, {"kind": "fault_detected", "t": 1.0})
    assert lifecycle.state == "unacknowledged"
    write_state(
        state / "state.json",
        {
            "model": model_identity(load_model(config.model_path)),
            "written": started,
            "alarm": lifecycle.to_dict(),
            "event_counts": {"alarm_raised": 1, "calibrated": 7},
        },
    )
    return started
