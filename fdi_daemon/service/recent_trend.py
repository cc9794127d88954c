"""The last hours of the friction trend, small enough for every status snapshot.

`RecentTrend` folds the finished minute rows of `fdi_daemon.service.trend.MinuteAggregator`
(the rows the trend store also gets) into 10-minute buckets over the last 6 hours and gives
them to the status snapshot as ``alarm.trend`` (the dashboard draws it)::

    {"bucket_s": 600, "end": 1790012400,        # unix s, the end of the newest bucket
     "mean": [0.081, null, ...],                # level mean per bucket, oldest first
     "max":  [0.113, null, ...]}                # largest level reading per bucket

Levels are the friction level (units of the signature, 3 decimals like the trend store),
not its excess over the baseline; ``null`` is a bucket without a reading (the rig at rest or
the daemon not running). The buckets are aligned to the clock, so the list always ends
with the bucket of "now"; about 0.5 kB of JSON when all 36 buckets hold data.

After a restart, ``load`` refills the buckets from the minute rows of ``trend.sqlite``, so
the dashboard keeps showing the hours before it.
"""

from __future__ import annotations

import logging
import math
import sqlite3
from pathlib import Path
from typing import Any

from fdi_daemon.service.trend import read_trend

log = logging.getLogger("fdi.trend")

__all__ = ["RecentTrend"]

DECIMALS = 3  # the trend store's resolution (1/1000 of the signature)


class RecentTrend:
    """See the module docstring. Pure (no I/O); ``add`` per finished minute row,
    ``summary(now)`` per status snapshot."""

    def __init__(self, hours: float = 6.0, bucket_s: int = 600) -> None:
        self.bucket_s = int(bucket_s)
        self.count = max(int(round(hours * 3600 / self.bucket_s)), 1)
        #: bucket number (unix s // bucket_s) -> [readings, sum of level * readings, max]
        self._buckets: dict[int, list[float]] = {}
        self._last_minute = -1

    def add(self, row: dict[str, Any]) -> None:
        """One minute row (``minute``, ``level_mean``, ``level_max``, ``readings``); a minute
        already counted (loaded, then finished again after a restart within it) is skipped."""
        mean, high, readings = row.get("level_mean"), row.get("level_max"), row.get("readings")
        if int(row["minute"]) <= self._last_minute:
            return
        self._last_minute = int(row["minute"])
        if (
            mean is None
            or high is None
            or not readings
            or not (math.isfinite(mean) and math.isfinite(high))
        ):
            return
        number = int(row["minute"]) * 60 // self.bucket_s
        acc = self._buckets.setdefault(number, [0, 0.0, -math.inf])
        acc[0] += readings
        acc[1] += mean * readings
        acc[2] = max(acc[2], high)
        for old in [n for n in self._buckets if n <= number - self.count]:
            del self._buckets[old]

    def load(self, path: str | Path, now: float) -> int:
        """Add the minute rows of the trend store at ``path`` from the hours shown before
        ``now`` (unix s); returns how many. A missing or unreadable store adds none (an
        unreadable one is logged: the trend store itself moves it aside)."""
        if not Path(path).exists():
            return 0
        first = (int(now // self.bucket_s) - self.count + 1) * self.bucket_s
        try:
            rows = read_trend(path, since_unix=first)
        except sqlite3.Error as exc:
            log.warning("trend %s: cannot read the last hours for the status (%s)", path, exc)
            return 0
        minutes = rows["period_s"] == 60
        for t, mean, high, readings in zip(
            rows["time_unix"][minutes],
            rows["level_mean"][minutes],
            rows["level_max"][minutes],
            rows["readings"][minutes],
        ):
            self.add(
                {
                    "minute": int(t // 60),
                    "level_mean": float(mean),
                    "level_max": float(high),
                    "readings": int(readings),
                }
            )
        return int(minutes.sum())

    def summary(self, now: float) -> dict[str, Any] | None:
        """The buckets of the last hours up to ``now`` (unix s); None without any data."""
        last = int(now // self.bucket_s)
        first = last - self.count + 1
        numbers = range(first, last + 1)
        if not any(n in self._buckets for n in numbers):
            return None
        rows = [self._buckets.get(n) for n in numbers]
        return {
            "bucket_s": self.bucket_s,
            "end": (last + 1) * self.bucket_s,
            "mean": [None if r is None else round(r[1] / r[0], DECIMALS) for r in rows],
            "max": [None if r is None else round(r[2], DECIMALS) for r in rows],
        }
