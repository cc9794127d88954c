"""The in-process dashboard of `fdi replay --realtime --dashboard`.

The paced replay calls `ReplayStatus.on_tick(monitor, t, new_events)` after every sample, on
its own thread. At most every `period_s` that builds a status snapshot — `Monitor.snapshot()`
plus a ``link`` section describing the replay — and publishes it into a `LatestSnapshot`;
the dashboard thread only reads that, never the monitor.

Link section of a replay: ``kind`` "replay", ``where`` the recording, ``rate_hz`` samples per
wall-clock second over the last ~2 s, ``samples`` done (of ``total_samples``), ``gaps`` and
``bad_samples`` from the monitor's events, ``crc_errors`` 0 (a file has none), and
``tick_latency_us``: how long after its due time each sample was done, p50/p99 over the last
10 s, where the pacing's origin is estimated as the earliest wall time at which any sample
so far was done, less its sample-time offset (a running minimum, so latencies are >= 0); a
sample done later than `deadline_s` is a deadline miss.
"""

from __future__ import annotations

import collections
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from fdi_daemon.dashboard.app import LatestSnapshot, run_alongside

ALARM_ROWS = 20


class ReplayStatus:
    """Snapshots of a paced replay, published into `board` (see module doc)."""

    def __init__(
        self,
        recording: str,
        model_path: str,
        provenance: dict[str, Any],
        total_samples: int,
        fs_hz: float,
        board: LatestSnapshot,
        *,
        period_s: float = 0.1,
        deadline_s: float = 0.05,
        clock: Callable[[], float] = time.monotonic,
    ):
        self.recording = recording
        self.model = {"path": model_path, "provenance": provenance}
        self.total_samples = total_samples
        self.board = board
        self.period_s = period_s
        self.deadline_s = deadline_s
        self._clock = clock
        self._alarms: collections.deque = collections.deque(maxlen=ALARM_ROWS)
        self._lateness_s: collections.deque = collections.deque(maxlen=int(10 * fs_hz))
        self._rate_marks: collections.deque = collections.deque()
        self._first: tuple[float, float] | None = None  # (wall time due, sample time)
        self._next_publish = -np.inf
        self.samples = self.gaps = self.bad_samples = self.deadline_misses = 0
        self._last_t = float("nan")

    def on_tick(self, monitor: Any, t: float, new_events: list[dict[str, Any]]) -> None:
        """After each replayed sample (sample time `t`, the events it raised): account for
        it; publish a snapshot when one is due."""
        now = self._clock()
        self.account(now, t, new_events)
        if now >= self._next_publish:
            self._next_publish = now + self.period_s
            self.board.publish(self.snapshot(monitor.snapshot()))

    def account(self, now: float, t: float, new_events: list[dict[str, Any]]) -> None:
        """Counters, lateness and rate for one sample at sample time `t` done at `now`."""
        if self._first is None:
            self._first = (now, t)
        # the schedule's origin: the earliest wall time any sample so far says sample 0 was due
        due_s = now - (t - self._first[1])
        if due_s < self._first[0]:
            self._first = (due_s, self._first[1])
        lateness_s = now - (self._first[0] + (t - self._first[1]))
        self._lateness_s.append(lateness_s)
        if lateness_s > self.deadline_s:
            self.deadline_misses += 1
        self.samples += 1
        self._last_t = t
        self._rate_marks.append((now, self.samples))
        while now - self._rate_marks[0][0] > 2.0:
            self._rate_marks.popleft()
        for event in new_events:
            kind = event.get("kind")
            if kind == "data_gap":
                self.gaps += 1
            elif kind == "bad_sample":
                self.bad_samples += 1
            self._alarms.append(event)

    def rate_hz(self) -> float:
        (t0, n0), (t1, n1) = self._rate_marks[0], self._rate_marks[-1]
        return (n1 - n0) / (t1 - t0) if t1 > t0 else 0.0

    def snapshot(self, monitor_snapshot: dict[str, Any]) -> dict[str, Any]:
        """The status snapshot (TEAM.md schema) of the replay so far."""
        lateness_us = np.asarray(self._lateness_s) * 1e6
        p50, p99 = (
            np.percentile(lateness_us, [50, 99])
            if lateness_us.size
            else (float("nan"), float("nan"))
        )
        return {
            "time": time.time(),
            "t": self._last_t,
            "state": monitor_snapshot.get("state"),
            "link": {
                "kind": "replay",
                "where": self.recording,
                "connected": True,
                "rate_hz": self.rate_hz(),
                "samples": self.samples,
                "total_samples": self.total_samples,
                "gaps": self.gaps,
                "crc_errors": 0,
                "bad_samples": self.bad_samples,
                "tick_latency_us": {"p50": float(p50), "p99": float(p99)},
                "deadline_misses": self.deadline_misses,
            },
            "monitor": monitor_snapshot,
            "alarms": list(self._alarms),
            "model": self.model,
        }


def replay_with_dashboard(
    paced: Callable[[Callable], Any],
    monitor: Any,
    recording: str,
    model_path: str,
    total_samples: int,
) -> Any:
    """Run `paced(on_tick)` (the paced replay) with the dashboard on screen; returns what
    `paced` returns. The final state stays on screen until `q` when stdin is a terminal."""
    board = LatestSnapshot()
    status = ReplayStatus(
        recording, model_path, dict(monitor.model.provenance), total_samples, monitor.fs_hz, board
    )
    result: list[Any] = []

    def work() -> int:
        result.append(paced(status.on_tick))
        board.publish(status.snapshot(monitor.snapshot()))
        return 0

    run_alongside(work, board, linger=True)
    return result[0]
