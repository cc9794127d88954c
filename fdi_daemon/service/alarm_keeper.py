"""The daemon's alarm point: the lifecycle fed from the loop, requests from the servers.

`AlarmKeeper` lives as long as the daemon process (a reload keeps it) and is driven by the
loop thread through three calls, all with the wall clock (it survives restarts):

- ``detector_event(event)``: every event of ``Monitor.step`` (fault_detected,
  friction_isolated, other_fault, cleared raise or close the alarm; others are ignored);
- ``status(snapshot)``: every status refresh (``service.status_period_s``, 10 Hz): the
  level reading ``snapshot["monitor"]["friction_level"]`` (units of the signature; None
  while the rig rests) minus the baseline (``baseline_level`` of the monitor snapshot or
  of the snapshot itself, when the model has one), and the trend minute;
- ``samples(batch)``: the valve commands for the trend's operating condition.

Each returns what the loop hands to its outputs: lifecycle events, a finished trend row.
The finished rows also go into `RecentTrend`, the last hours that ``summary()`` (the
snapshot's ``alarm`` section) carries as ``trend`` for the dashboard.
Acknowledge and shelve requests come from the status socket and Modbus server threads
(`request`); the decision is made at once under a lock, the events are handed to the loop
(`take_pending`) so that every output still leaves from the loop's thread.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from fdi_daemon.alarms.lifecycle import STATE_CODES, AlarmLifecycle, AlarmSettings
from fdi_daemon.io.sample import Sample
from fdi_daemon.service.recent_trend import RecentTrend
from fdi_daemon.service.trend import MinuteAggregator

__all__ = ["AlarmKeeper", "baseline_of"]


def baseline_of(snapshot: dict[str, Any]) -> float | None:
    """The fault-free baseline level in a status snapshot (None when the model has none)."""
    monitor = snapshot.get("monitor") or {}
    value = monitor.get("baseline_level", snapshot.get("baseline_level"))
    return float(value) if isinstance(value, (int, float)) and math.isfinite(value) else None


class AlarmKeeper:
    """See the module docstring."""

    def __init__(
        self,
        settings: AlarmSettings,
        model: str,
        *,
        stored: dict[str, Any] | None = None,
        allow_remote: bool = False,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self.model = model
        self.allow_remote = allow_remote
        self._clock = clock
        self._lock = threading.Lock()
        self._pending: list[dict[str, Any]] = []
        self.event_counts: dict[str, int] = {}
        self.lifecycle = AlarmLifecycle(settings)
        self.restored = stored is not None
        if stored is not None:
            self.lifecycle = AlarmLifecycle.from_dict(stored["alarm"], settings, now=clock())
            self.event_counts = {
                str(k): int(v) for k, v in (stored.get("event_counts") or {}).items()
            }
        self.trend = MinuteAggregator()
        self.recent = RecentTrend()
        self.last_t: float | None = None
        self.baseline: float | None = None

    # ------------------------------------------------------------------ loop thread
    def detector_event(self, event: dict[str, Any]) -> list[dict[str, Any]]:
        if isinstance(event.get("t"), (int, float)):
            self.last_t = event["t"]
        with self._lock:
            return self._stamp(self.lifecycle.step(self._clock(), None, event))

    def status(
        self, snapshot: dict[str, Any]
    ) -> tuple[list[dict[str, Any]], dict[str, Any] | None]:
        now = self._clock()
        level = (snapshot.get("monitor") or {}).get("friction_level")
        level = float(level) if isinstance(level, (int, float)) else None
        self.baseline = baseline_of(snapshot)
        if isinstance(snapshot.get("t"), (int, float)):
            self.last_t = snapshot["t"]
        excess = None if level is None else level - (self.baseline or 0.0)
        with self._lock:
            events = self._stamp(self.lifecycle.step(now, excess))
            self._mark_trend(now)
        return events, self._finished(self.trend.level(now, level))

    def samples(self, batch: list[Sample]) -> dict[str, Any] | None:
        return self._finished(self.trend.samples(self._clock(), [s.v_in for s in batch]))

    def recall_trend(self, path: str | Path) -> int:
        """The last hours of the trend store at ``path`` for the snapshot (after a restart);
        returns the minute rows read."""
        return self.recent.load(path, self._clock())

    def take_pending(self) -> list[dict[str, Any]]:
        """Events of requests answered since the last call (for the loop to emit)."""
        with self._lock:
            pending, self._pending = self._pending, []
        return pending

    def summary(self) -> dict[str, Any]:
        now = self._clock()
        with self._lock:
            return {
                **self.lifecycle.summary(now),
                "baseline_level": self.baseline,
                "steps": list(self.lifecycle.settings.steps),
                "remote_acknowledge": self.allow_remote,
                "trend": self.recent.summary(now),
            }

    def state(self, event_counts: dict[str, int]) -> dict[str, Any]:
        """What the state file holds (`fdi_daemon.service.state_file`)."""
        with self._lock:
            return {
                "model": self.model,
                "written": self._clock(),
                "alarm": self.lifecycle.to_dict(),
                "event_counts": dict(event_counts),
            }

    def carried_over(self) -> str | None:
        """One line naming the alarm a restart inherited from the state file (None when
        there is none): id, priority, since when, acknowledged or not, shelved."""
        if not self.restored:
            return None
        now = self._clock()
        with self._lock:
            s = self.lifecycle.summary(now)
        if s["state"] == "normal":
            return None
        since = (
            time.strftime("%Y-%m-%d %H:%M:%S %z", time.localtime(s["started"]))
            if isinstance(s["started"], (int, float))
            else "an unknown time"
        )
        text = (
            f"alarm carried over from an earlier run: #{s['alarm_id']} P{s['priority']} "
            f"{s['state'].replace('_', ' ')} since {since}"
        )
        if s["shelved_until"] is not None and now < s["shelved_until"]:
            until = time.strftime("%H:%M:%S", time.localtime(s["shelved_until"]))
            text += f", shelved until {until}"
        return text

    def reconfigure(self, settings: AlarmSettings, allow_remote: bool) -> None:
        """New settings after a reload; the alarm itself goes on."""
        with self._lock:
            self.lifecycle.settings = settings
            self.allow_remote = allow_remote

    # ------------------------------------------------------------------ server threads
    def handle(self, request: dict[str, Any]) -> dict[str, Any]:
        """A request of the status socket or Modbus server: {"request", "by", "duration_s",
        "why"}."""
        return self.request(
            str(request.get("request")),
            str(request.get("by", "")),
            request.get("duration_s"),
            str(request.get("why") or ""),
        )

    def request(
        self, action: str, by: str, duration_s: float | None = None, why: str = ""
    ) -> dict[str, Any]:
        """acknowledge | shelve (duration_s) | unshelve; the answer says why if refused."""
        if not self.allow_remote:
            return {
                "ok": False,
                "error": "remote acknowledge and shelving are disabled "
                "(alarms.allow_remote_acknowledge: false)",
            }
        now = self._clock()
        with self._lock:
            if action == "acknowledge":
                ok, reason, events = self.lifecycle.acknowledge(now, by, why)
            elif action == "shelve":
                if not isinstance(duration_s, (int, float)) or isinstance(duration_s, bool):
                    return {"ok": False, "error": "shelve needs duration_s (seconds)"}
                ok, reason, events = self.lifecycle.shelve(now, float(duration_s), by, why)
            elif action == "unshelve":
                ok, reason, events = self.lifecycle.unshelve(now, by, why)
            else:
                return {
                    "ok": False,
                    "error": f"unknown request {action!r} (acknowledge, shelve, unshelve)",
                }
            self._pending.extend(self._stamp(events))
            self._mark_trend(now)
            summary = self.lifecycle.summary(now)
        return (
            {"ok": True, "result": reason, "alarm": summary}
            if ok
            else {"ok": False, "error": reason, "alarm": summary}
        )

    # ------------------------------------------------------------------ internals
    def _stamp(self, events: list[dict[str, Any]]) -> list[dict[str, Any]]:
        """Lifecycle events as daemon events: ``t`` is the last sample time (DESIGN.md)."""
        return [{"t": self.last_t, **e} for e in events]

    def _finished(self, row: dict[str, Any] | None) -> dict[str, Any] | None:
        if row is not None:
            self.recent.add(row)
        return row

    def _mark_trend(self, now: float) -> None:
        lc = self.lifecycle
        self.trend.baseline = self.baseline
        self.trend.priority = lc.priority
        self.trend.alarm_state = STATE_CODES["shelved" if lc.shelved(now) else lc.state]
