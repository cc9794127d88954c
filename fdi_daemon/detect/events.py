"""Monitor events (DESIGN.md schema) and their JSON Lines file.

Every event is a flat dict ``{"t": s, "kind": k, "theta1": x|None, "theta2": x|None, ...}``;
non-finite numbers are stored as None so that each line is strict JSON. Kinds:

- ``calibrated``: the fault-free calibration period is over (band and baseline set);
- ``fault_detected``: the sequential test (or the paper's band) raised an alarm (``path``:
  fast, level, baseline or drift; the drift path's alarm is ``unconfirmed: true``);
- ``friction_isolated``: (θ1, θ2) track the friction signature (1, γ_f);
- ``other_fault``: an alarm whose estimates do not track the signature within
  ``isolation_timeout_s`` of the detection (for the drift path's: of the residual test's
  alarm) and that a linear change of the plant describes or a clipping accelerometer
  explains (with ``accel_clipping: true`` when the accelerometer sat at its rail during the
  episode, ``load_stopped: true`` when the load had stopped although the model says it
  moves: held by friction, or its drive lost, which the accelerometer cannot tell apart);
- ``cleared``: the estimates and the test statistic are back to normal;
- ``data_gap``: samples missing (``missing_samples``); the estimator restarts;
- ``link_lost`` / ``link_restored``: emitted by the service's link layer, not the monitor;
- ``bad_sample``: a non-finite or saturated sample (``reason``) that the monitor skipped.

Lines written to a file also carry ``"schema": EVENT_SCHEMA`` (lines without it are schema
1); the daemon's event log adds ``"time"``, the RFC 3339 wall clock (docs/service.md).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from fdi_daemon.errors import UserError

__all__ = [
    "EVENT_KINDS",
    "ALARM_KINDS",
    "EVENT_SCHEMA",
    "make_event",
    "write_events",
    "read_events",
]

#: version of the event line format; 2 added ``schema`` and (in the daemon) ``time``
EVENT_SCHEMA = 2

EVENT_KINDS = (
    "calibrated",
    "fault_detected",
    "friction_isolated",
    "other_fault",
    "cleared",
    "data_gap",
    "link_lost",
    "link_restored",
    "bad_sample",
)

#: the kinds that open or close an alarm episode
ALARM_KINDS = ("fault_detected", "friction_isolated", "other_fault", "cleared")


def _number(value: float | None) -> float | None:
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


def make_event(
    t: float, kind: str, theta1: float | None = None, theta2: float | None = None, **extra: Any
) -> dict[str, Any]:
    """One event dict; float extras are made JSON-safe (NaN/inf -> None)."""
    if kind not in EVENT_KINDS:
        raise ValueError(f"unknown event kind {kind!r}")
    event: dict[str, Any] = {
        "t": _number(t),
        "kind": kind,
        "theta1": _number(theta1),
        "theta2": _number(theta2),
    }
    for key, value in extra.items():
        event[key] = _number(value) if isinstance(value, float) else value
    return event


def write_events(path: str | Path, events: Iterable[dict[str, Any]], append: bool = False) -> int:
    """Write events as JSON Lines (with ``schema``); returns how many were written."""
    path = Path(path)
    count = 0
    try:
        with open(path, "a" if append else "w", encoding="utf-8") as fh:
            for event in events:
                line = {**event, "schema": EVENT_SCHEMA}
                fh.write(json.dumps(line, allow_nan=False, separators=(",", ":")) + "\n")
                count += 1
    except OSError as exc:
        raise UserError(f"{path}: cannot write events: {exc.strerror or exc}") from None
    return count


def read_events(path: str | Path) -> list[dict[str, Any]]:
    """Read a JSON Lines event file (blank lines skipped)."""
    path = Path(path)
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except OSError as exc:
        raise UserError(f"{path}: cannot read events: {exc.strerror or exc}") from None
    events = []
    for number, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            events.append(json.loads(line))
        except json.JSONDecodeError:
            raise UserError(f"{path}: line {number} is not a JSON object") from None
    return events
