"""The replay summary (DESIGN.md): what a replay found, as one JSON object."""

from __future__ import annotations

from typing import Any

from fdi_daemon.io.outputs import finite_or_none

__all__ = ["replay_summary"]


def _first(events: list[dict[str, Any]], kind: str) -> float | None:
    return next((e["t"] for e in events if e["kind"] == kind), None)


def replay_summary(
    events: list[dict[str, Any]],
    samples: int,
    fs_hz: float,
    method: str,
    theta_final: tuple[float | None, float | None],
    level_final: float | None = None,
) -> dict[str, Any]:
    """``{"samples", "fs", "first_detection_t", "isolated_t", "classification",
    "theta_final", "alarm_episodes", ...}`` (DESIGN.md keys first).

    ``alarm_episodes``: the detector's episodes (``fault_detected`` events); ``alarms``: the
    alarm lifecycle's alarms (``alarm_raised``, `fdi_daemon.alarms.replay`) and
    ``alarm_peak_priority`` the highest priority any of them reached (0: none).
    ``friction_level_final``: ``level_final``, the last reported friction level of the file
    (`detect.friction_level`; None if it was never measured), not θ1 of the last window.
    """
    kinds = [e["kind"] for e in events]
    first_detection = _first(events, "fault_detected")
    isolated = _first(events, "friction_isolated")
    other = _first(events, "other_fault")
    classification = None
    if first_detection is not None:
        decided = [e for e in events if e["kind"] in ("friction_isolated", "other_fault")]
        if decided:
            classification = "friction" if decided[0]["kind"] == "friction_isolated" else "other"
    theta_safe = [finite_or_none(v) for v in theta_final]
    counts = {kind: kinds.count(kind) for kind in dict.fromkeys(kinds)}
    return {
        "samples": int(samples),
        "fs": float(fs_hz),
        "first_detection_t": first_detection,
        "isolated_t": isolated,
        "classification": classification,
        "theta_final": theta_safe,
        "alarm_episodes": kinds.count("fault_detected"),
        "alarms": kinds.count("alarm_raised"),
        "alarm_peak_priority": max(
            (int(e["priority"]) for e in events if e["kind"] in ("alarm_raised", "alarm_priority")),
            default=0,
        ),
        "other_fault_t": other,
        "method": method,
        "friction_level_final": finite_or_none(level_final),
        "event_counts": counts,
        "bad_samples": sum(int(e.get("count", 1)) for e in events if e["kind"] == "bad_sample"),
        "missing_samples": sum(
            int(e.get("missing_samples", 0)) for e in events if e["kind"] == "data_gap"
        ),
    }
