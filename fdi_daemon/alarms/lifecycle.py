"""The friction alarm's lifecycle (ISA-18.2 / IEC 62682), fed by the detector's events.

The detector says *whether* there is a fault (``fault_detected``, ``friction_isolated``,
``other_fault``, ``cleared``); this module turns that into **one alarm per fault** that an
operator handles: raised once, its priority stepping up as the friction level grows,
acknowledged, shelved for a while, and returned to normal only when the fault has really
gone. Pure logic: the caller passes the time (s, any clock that survives restarts; the
daemon uses the wall clock) and the friction level, and gets lifecycle events back.

States (ISA-18.2 alarm state model; shelving is a flag on top of any state)::

    normal --fault--> unacknowledged --ack--> acknowledged
                        | return               | return
                        v                      v
             returned_unacknowledged --ack--> normal

- **Raise.** The first detector fault while ``normal`` raises the alarm (``alarm_raised``,
  priority at least 1). A detector fault while an alarm is open (or waiting to return) is
  the same alarm: nothing new is raised. That is also how a restart or a reload in the
  middle of an alarm is absorbed: the restored state holds the open alarm, the detector's
  renewed ``fault_detected`` joins it.
- **Level.** Decisions use the level readings smoothed by a first-order filter of time
  constant ``smoothing_s`` (an exponential moving average whose weight follows the time
  between readings, so a reading after a long rest counts fully): the per-reading noise
  of the estimate must not chatter across a step.
- **Priority** = how many of ``steps`` (friction level, units of the signature; default
  0.25 / 0.5 / 1.0) the level has crossed, at least 1 while the alarm is active. It rises
  one ``alarm_priority`` event per step once the level has stayed at or above the step for
  ``raise_delay_s`` (on-delay); it falls only once the level has stayed below the step
  minus ``deadband`` for ``lower_delay_s`` (deadband and off-delay: no chattering). These
  delays, like the return delay below, count *moving time*: only the time between valid
  readings at most `READING_GAP_S` apart (a resting rig shows no level, so neither the
  fault nor its absence).
- **Return to normal** (``alarm_returned``) when the detector's last word is ``cleared``
  since ``return_delay_s`` *and* the level has been back at the baseline (below
  ``return_level``) for ``return_delay_s`` of moving time. A detector fault within that time
  keeps the same alarm. A state restored after a restart
  treats the detector as cleared at the moment of the restore: the new detector run may not
  raise again (it may learn the fault as normal), so the level decides.
- **Acknowledge** (``alarm_acknowledged``): from ``unacknowledged`` to ``acknowledged``, or
  from ``returned_unacknowledged`` to ``normal``. Refused in other states.
- **Shelve** (``alarm_shelved``): the alarm point is not annunciated until ``until``
  (at most ``max_shelve_s`` ahead); ``alarm_unshelved`` at expiry or on request. Events are
  still produced and recorded while shelved (with ``shelved: true``).

Every event: ``{"kind", "time", "alarm_id", "state", "priority", "level", "shelved", ...}``
with the state and priority *after* the transition. `to_dict` / `AlarmLifecycle.from_dict`
round-trip the whole state (the daemon's state file); `run` is the batch path, identical to
calling `step` per input.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

__all__ = [
    "AlarmSettings",
    "AlarmLifecycle",
    "LIFECYCLE_KINDS",
    "STATES",
    "STATE_CODES",
    "DETECTOR_FAULT_KINDS",
    "DETECTOR_INPUTS",
]

STATES = ("normal", "unacknowledged", "acknowledged", "returned_unacknowledged")
#: register codes of the alarm state (4 = shelved, whatever the state underneath)
STATE_CODES = {
    "normal": 0,
    "unacknowledged": 1,
    "acknowledged": 2,
    "returned_unacknowledged": 3,
    "shelved": 4,
}
LIFECYCLE_KINDS = (
    "alarm_raised",
    "alarm_priority",
    "alarm_acknowledged",
    "alarm_shelved",
    "alarm_unshelved",
    "alarm_returned",
)
DETECTOR_FAULT_KINDS = ("fault_detected", "friction_isolated", "other_fault")
#: the detector events that drive the lifecycle
DETECTOR_INPUTS = frozenset(DETECTOR_FAULT_KINDS + ("cleared",))
STATE_VERSION = 1
#: readings further apart than this (s) are not moving time for the return to normal
READING_GAP_S = 60.0


@dataclass(frozen=True)
class AlarmSettings:
    """Alarm-management settings (levels in units of the friction signature, times in s)."""

    steps: tuple[float, ...] = (0.25, 0.5, 1.0)
    deadband: float = 0.1
    raise_delay_s: float = 60.0
    lower_delay_s: float = 3600.0
    return_delay_s: float = 600.0
    return_level: float = 0.1
    max_shelve_s: float = 86400.0
    smoothing_s: float = 30.0

    def __post_init__(self) -> None:
        steps = tuple(float(s) for s in self.steps)
        object.__setattr__(self, "steps", steps)
        if (
            not steps
            or any(not (s > 0 and math.isfinite(s)) for s in steps)
            or list(steps) != sorted(set(steps))
        ):
            raise ValueError("steps must be positive, finite and strictly increasing")
        if not 0 <= self.deadband < steps[0]:
            raise ValueError("deadband must be in [0, the lowest step)")
        if not 0 < self.return_level <= steps[0] - self.deadband:
            raise ValueError("return_level must be in (0, the lowest step - deadband]")
        for name in (
            "raise_delay_s",
            "lower_delay_s",
            "return_delay_s",
            "max_shelve_s",
            "smoothing_s",
        ):
            value = getattr(self, name)
            if not (value >= 0 and math.isfinite(value)):
                raise ValueError(f"{name} must be a finite number >= 0")


@dataclass
class _State:
    state: str = "normal"
    alarm_id: int = 0  # id of the current (or last) alarm; 0 = none yet
    started: float | None = None
    classification: str | None = None  # "friction" | "other" | None (not isolated yet)
    priority: int = 0
    peak_priority: int = 0
    level: float | None = None  # smoothed level (the decisions' input)
    level_time: float | None = None  # time of the last valid reading
    peak_level: float | None = None
    detector_fault: bool = False
    cleared_at: float | None = None
    # moving time (s) for which the level has been: below return_level; at or above each
    # step (on-delays); below each step - deadband (off-delays). None: not now.
    low_s: float | None = None
    above_s: list = field(default_factory=list)
    below_s: list = field(default_factory=list)
    shelved_until: float | None = None
    acknowledged_at: float | None = None
    last_time: float | None = None
    counters: dict[str, int] = field(default_factory=lambda: {k: 0 for k in LIFECYCLE_KINDS})


def _note(why: str) -> dict[str, str]:
    """The operator's note of a request as an event field (none when empty)."""
    return {"why": why} if why else {}


class AlarmLifecycle:
    """One alarm point (the rig's friction fault): see the module docstring."""

    def __init__(self, settings: AlarmSettings | None = None) -> None:
        self.settings = settings or AlarmSettings()
        self._s = _State()

    # ------------------------------------------------------------------ queries
    @property
    def state(self) -> str:
        return self._s.state

    @property
    def priority(self) -> int:
        return self._s.priority

    @property
    def active(self) -> bool:
        return self._s.state in ("unacknowledged", "acknowledged")

    def shelved(self, now: float) -> bool:
        return self._s.shelved_until is not None and now < self._s.shelved_until

    def summary(self, now: float) -> dict[str, Any]:
        """What the status snapshot and the registers show."""
        s = self._s
        return {
            "state": s.state,
            "state_code": STATE_CODES["shelved" if self.shelved(now) else s.state],
            "alarm_id": s.alarm_id,
            "priority": s.priority,
            "peak_priority": s.peak_priority,
            "started": s.started,
            "classification": s.classification,
            "level": s.level,
            "peak_level": s.peak_level,
            "shelved_until": s.shelved_until,
            "annunciated": self.active and not self.shelved(now),
            "counters": dict(s.counters),
        }

    # ------------------------------------------------------------------ inputs
    def step(
        self, now: float, level: float | None = None, event: Mapping[str, Any] | None = None
    ) -> list[dict[str, Any]]:
        """One input: the time, a level reading (None/NaN: none) and/or a detector event."""
        s = self._s
        if s.last_time is not None and now < s.last_time:
            now = s.last_time  # the clock stepped back: keep time monotone
        s.last_time = now
        out: list[dict[str, Any]] = []
        if level is not None and math.isfinite(level):
            self._on_level(now, float(level), out)
        if event is not None:
            self._on_event(now, event, out)
        self._on_time(now, out)
        return out

    def run(
        self, inputs: Iterable[tuple[float, float | None, Mapping[str, Any] | None]]
    ) -> list[dict[str, Any]]:
        """Batch path: ``step`` over (time, level, event) tuples; same events, same state."""
        out: list[dict[str, Any]] = []
        for now, level, event in inputs:
            out.extend(self.step(now, level, event))
        return out

    def acknowledge(self, now: float, by: str = "", why: str = "") -> tuple[bool, str, list[dict]]:
        """Operator acknowledge; returns (accepted, reason, events); ``why``, when given,
        goes into the event (the operator's note)."""
        s = self._s
        if s.state == "unacknowledged":
            s.state = "acknowledged"
        elif s.state == "returned_unacknowledged":
            s.state = "normal"
        else:
            return False, f"nothing to acknowledge (alarm state {s.state})", []
        s.acknowledged_at = now
        return True, "acknowledged", [self._event(now, "alarm_acknowledged", by=by, **_note(why))]

    def shelve(
        self, now: float, duration_s: float, by: str = "", why: str = ""
    ) -> tuple[bool, str, list[dict]]:
        """Shelve the alarm point for ``duration_s`` (0 < d <= max_shelve_s)."""
        if not (
            isinstance(duration_s, (int, float)) and 0 < duration_s <= self.settings.max_shelve_s
        ):
            return (False, f"shelve duration must be in (0, {self.settings.max_shelve_s:g}] s", [])
        self._s.shelved_until = now + float(duration_s)
        return (
            True,
            "shelved",
            [self._event(now, "alarm_shelved", by=by, until=self._s.shelved_until, **_note(why))],
        )

    def unshelve(self, now: float, by: str = "", why: str = "") -> tuple[bool, str, list[dict]]:
        if not self.shelved(now):
            return False, "not shelved", []
        self._s.shelved_until = None
        return (
            True,
            "unshelved",
            [self._event(now, "alarm_unshelved", by=by, reason="request", **_note(why))],
        )

    # ------------------------------------------------------------------ persistence
    def to_dict(self) -> dict[str, Any]:
        return {
            "version": STATE_VERSION,
            "settings": {**asdict(self.settings), "steps": list(self.settings.steps)},
            "state": {**asdict(self._s)},
        }

    @classmethod
    def from_dict(
        cls,
        data: Mapping[str, Any],
        settings: AlarmSettings | None = None,
        now: float | None = None,
    ) -> AlarmLifecycle:
        """Restore a state written by `to_dict` (ValueError if it is not one).

        ``settings``: the current settings (default: the stored ones). ``now``: the time of
        the restore; the detector counts as cleared from then on (module docstring).
        """
        if not isinstance(data, Mapping) or data.get("version") != STATE_VERSION:
            raise ValueError(f"not an alarm state of version {STATE_VERSION}")
        try:
            stored = dict(data["state"])
            state = _State(
                **{**stored, "counters": {**_State().counters, **dict(stored.get("counters", {}))}}
            )
            if settings is None:
                settings = AlarmSettings(**data["settings"])
        except (KeyError, TypeError) as exc:
            raise ValueError(f"malformed alarm state: {exc}") from None
        if state.state not in STATES:
            raise ValueError(f"unknown alarm state {state.state!r}")
        lifecycle = cls(settings)
        lifecycle._s = state
        if now is not None and state.detector_fault:
            state.detector_fault = False
            state.cleared_at = now
        return lifecycle

    # ------------------------------------------------------------------ internals
    def _event(self, now: float, kind: str, **extra: Any) -> dict[str, Any]:
        s = self._s
        s.counters[kind] = s.counters.get(kind, 0) + 1
        return {
            "kind": kind,
            "time": now,
            "alarm_id": s.alarm_id,
            "state": s.state,
            "priority": s.priority,
            "level": s.level,
            "shelved": self.shelved(now),
            **extra,
        }

    def _on_event(self, now: float, event: Mapping[str, Any], out: list) -> None:
        s = self._s
        kind = event.get("kind")
        if kind in DETECTOR_FAULT_KINDS:
            s.detector_fault = True
            s.cleared_at = None
            if kind == "friction_isolated":
                s.classification = "friction"
            elif kind == "other_fault" and s.classification is None:
                s.classification = "other"
            if not self.active:
                self._raise(now, kind, out)
        elif kind == "cleared":
            s.detector_fault = False
            s.cleared_at = now

    def _raise(self, now: float, cause: str, out: list) -> None:
        s = self._s
        s.state = "unacknowledged"
        s.alarm_id += 1
        s.started = now
        s.classification = {"friction_isolated": "friction", "other_fault": "other"}.get(cause)
        s.priority = max(1, self._crossed(s.level)) if s.level is not None else 1
        s.peak_priority = s.priority
        s.peak_level = s.level
        s.acknowledged_at = None
        # the level of the fault is not measured yet (the reported level restarts at the
        # detection, its first reading a window later): the event says so rather than
        # showing the level from before the fault; alarm_priority and the status have it
        out.append(
            self._event(
                now,
                "alarm_raised",
                cause=cause,
                classification=s.classification,
                level=None,
                level_before=s.level,
            )
        )

    def _crossed(self, level: float) -> int:
        return sum(level >= step for step in self.settings.steps)

    def _on_level(self, now: float, reading: float, out: list) -> None:
        s, cfg = self._s, self.settings
        dt = math.inf if s.level_time is None else now - s.level_time
        if s.level is None or cfg.smoothing_s == 0:
            s.level = reading
        else:
            s.level += -math.expm1(-dt / cfg.smoothing_s) * (reading - s.level)
        s.level_time = now
        level = s.level
        moving = dt if dt <= READING_GAP_S else 0.0
        s.low_s = _held(s.low_s, level < cfg.return_level, moving)
        if len(s.above_s) != len(cfg.steps):  # first reading, or the steps were changed
            s.above_s, s.below_s = [None] * len(cfg.steps), [None] * len(cfg.steps)
        for i, step in enumerate(cfg.steps):
            s.above_s[i] = _held(s.above_s[i], level >= step, moving)
            s.below_s[i] = _held(s.below_s[i], level < step - cfg.deadband, moving)
        if not self.active:
            return
        s.peak_level = level if s.peak_level is None else max(s.peak_level, level)
        risen = sum(h is not None and h >= cfg.raise_delay_s for h in s.above_s)
        kept = max(1, sum(not (h is not None and h >= cfg.lower_delay_s) for h in s.below_s))
        if risen > s.priority:
            self._set_priority(now, risen, out)
        elif kept < s.priority:
            self._set_priority(now, kept, out)

    def _set_priority(self, now: float, target: int, out: list) -> None:
        s = self._s
        direction = 1 if target > s.priority else -1
        while s.priority != target:  # one event per step crossed
            previous = s.priority
            s.priority += direction
            s.peak_priority = max(s.peak_priority, s.priority)
            out.append(
                self._event(
                    now,
                    "alarm_priority",
                    previous=previous,
                    step=self.settings.steps[max(s.priority, previous) - 1],
                )
            )

    def _on_time(self, now: float, out: list) -> None:
        s, cfg = self._s, self.settings
        if s.shelved_until is not None and now >= s.shelved_until:
            s.shelved_until = None
            out.append(self._event(now, "alarm_unshelved", reason="expired"))
        if (
            self.active
            and not s.detector_fault
            and s.cleared_at is not None
            and now - s.cleared_at >= cfg.return_delay_s
            and s.low_s is not None
            and s.low_s >= cfg.return_delay_s
        ):
            s.state = "normal" if s.state == "acknowledged" else "returned_unacknowledged"
            s.priority = 0
            out.append(self._event(now, "alarm_returned"))


def _held(held_s: float | None, condition: bool, moving_s: float) -> float | None:
    """Moving time a condition has held: None when it does not hold, 0 at the first
    reading where it does, then + the moving time since the previous reading."""
    if not condition:
        return None
    return 0.0 if held_s is None else held_s + moving_s
