"""The alarm lifecycle over a replay: what the daemon's alarm point would have shown.

The daemon (`fdi_daemon.service.alarm_keeper`) feeds `AlarmLifecycle` every detector event
as it happens and, at every status refresh (``service.status_period_s``, 10 Hz), the level
reading: the monitor's friction level minus the baseline's fault-free level at the current
operating condition (minus 0 without a baseline). A replay does the same with the
recording's sample time as the clock:

- **readings** every ``round(fs · status_period_s)`` samples (`status_stride`; 26 samples
  = 9.85 Hz of sample time at 256 Hz), from the monitor's trace (its ``friction_level``, as
  in the snapshot, and the window's velocity RMS for the baseline's bin);
- **detector events** at their sample time ``t``; at a tie the event goes first (the daemon's
  loop hands a batch's events to the lifecycle before the status refresh that follows).

Both are merged in time order and run through `AlarmLifecycle.run` (the batch path, equal
to ``step`` per input). The lifecycle's events carry ``t`` (sample time, s) like the
daemon's; they carry no ``time`` (a replay's wall clock says nothing about the recording).
"""

from __future__ import annotations

import heapq
from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np

from fdi_daemon.alarms.lifecycle import DETECTOR_INPUTS, AlarmLifecycle, AlarmSettings

__all__ = [
    "STATUS_PERIOD_S",
    "status_stride",
    "level_readings",
    "replay_alarms",
    "alarm_events",
    "merge_events",
]

#: the daemon's status refresh period (s): service.status_period_s's default
STATUS_PERIOD_S = 0.1


def status_stride(fs_hz: float, period_s: float = STATUS_PERIOD_S) -> int:
    """Samples between two level readings: the status period in whole samples (>= 1)."""
    return max(1, int(round(fs_hz * period_s)))


def level_readings(
    t: np.ndarray, friction_level: np.ndarray, baseline_level: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(time s, level above the baseline) of each reading; NaN where the rig rests.

    ``baseline_level`` NaN (no baseline, or none for that bin): the level itself, as the
    daemon does (``level - (baseline or 0)``).
    """
    base = np.asarray(baseline_level, dtype=float)
    level = np.asarray(friction_level, dtype=float) - np.where(np.isfinite(base), base, 0.0)
    return np.asarray(t, dtype=float), level


def _inputs(
    events: list[dict[str, Any]], times: np.ndarray, levels: np.ndarray
) -> Iterator[tuple[float, float | None, Mapping[str, Any] | None]]:
    """(time, level, event) in time order; at a tie the detector event first."""
    detector = sorted(
        (float(e["t"]), 0, k, None, e) for k, e in enumerate(events) if e["kind"] in DETECTOR_INPUTS
    )  # what the daemon's loop hands on
    readings = ((float(t), 1, k, float(v), None) for k, (t, v) in enumerate(zip(times, levels)))
    for now, _, _, level, event in heapq.merge(detector, readings, key=lambda x: x[:3]):
        yield now, level, event


def replay_alarms(
    events: list[dict[str, Any]],
    times: np.ndarray,
    levels: np.ndarray,
    settings: AlarmSettings | None = None,
) -> list[dict[str, Any]]:
    """The lifecycle's events for a replay's detector ``events`` and level readings
    ``(times, levels)``. The lifecycle's clock, the sample time, becomes ``t`` (s); a replay's
    events carry no ``time`` (docs/service.md, "Event lines")."""
    lifecycle = AlarmLifecycle(settings)
    return [{"t": e.pop("time"), **e} for e in lifecycle.run(_inputs(events, times, levels))]


def alarm_events(
    monitor, events: list[dict[str, Any]], trace, stride: int, settings: AlarmSettings | None = None
) -> list[dict[str, Any]]:
    """The lifecycle's events over a replay: readings every ``stride`` samples of the
    monitor's ``trace`` (whose ``every`` divides ``stride``), θ1 minus the baseline of the
    window's velocity RMS."""
    rows = slice(None, None, stride // trace.every)
    times, levels = level_readings(
        trace.t[rows], trace.friction_level[rows], monitor.baseline_levels(trace.v_rms[rows])
    )
    return replay_alarms(events, times, levels, settings)


def merge_events(
    detector: list[dict[str, Any]], alarms: list[dict[str, Any]]
) -> list[dict[str, Any]]:
    """One event list in time order (a stable sort: at a tie the detector's event first, it
    caused the lifecycle's)."""
    return sorted(detector + alarms, key=lambda e: e["t"])
