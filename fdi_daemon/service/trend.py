"""The friction trend: one row per minute in SQLite (stdlib ``sqlite3``), for years.

`MinuteAggregator` (pure, on the loop's thread) folds the level readings and the valve
command of one wall-clock minute into a row; `TrendStore` (on the sink thread) appends rows
to ``trend.sqlite`` in the state directory; `read_trend` reads them back (``fdi trend``).

Table ``trend_minute`` (one row per UTC minute that had data)::

    minute          INTEGER PRIMARY KEY  unix time // 60 (UTC minute number)
    level_mean_m    INTEGER  friction level, mean over the minute, 1/1000 of the signature
    level_min_m     INTEGER  smallest level reading (same unit)
    level_max_m     INTEGER  largest level reading (same unit)
    baseline_m      INTEGER  the model's fault-free baseline level (same unit), NULL: none
    command_rms_mv  INTEGER  RMS of the valve command v_in over the minute, mV
    readings        INTEGER  valid level readings used (one per status refresh, rig moving)
    samples         INTEGER  samples received in the minute
    priority        INTEGER  alarm priority at the end of the minute (0 none .. len(steps))
    alarm_state     INTEGER  alarm state code at the end of the minute (lifecycle.STATE_CODES)

Levels are NULL in a minute without a valid reading (the rig at rest). Scaled integers
keep a row at about 31 bytes (SQLite stores small integers in 1-3 bytes, a REAL in 8).

Retention: minute rows older than ``keep_minutes_days`` (default 90) are folded, once an
hour, into table ``trend_hour`` (same columns, ``hour`` = unix time // 3600 instead of
``minute``): level mean weighted by readings, min of the minima, max of the maxima, the
command RMS over all samples, sums of readings and samples, the highest priority and
state code, the last baseline. So the file holds 90 days of minutes (about 4 MB) and then
grows by about 0.3 MB a year (measured: docs/service.md).

The view ``trend`` shows both tables in plain units (``time_unix`` s, ``period_s`` 60 or
3600, ``level_*`` and ``baseline`` in signature units, ``command_rms_v`` V). Table
``trend_meta`` (key, value) holds the alarm steps (``steps``, JSON) and the model hash.
"""

from __future__ import annotations

import json
import logging
import math
import os
import sqlite3
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "MinuteAggregator",
    "TrendStore",
    "open_trend_store",
    "read_trend",
    "trend_meta",
    "TREND_FILE",
]

log = logging.getLogger("fdi.trend")

TREND_FILE = "trend.sqlite"
LEVEL_SCALE = 1000.0  # stored unit: 1/1000 of the signature
COMMAND_SCALE = 1000.0  # stored unit: mV

_SCHEMA = """
CREATE TABLE IF NOT EXISTS trend_minute (
    minute INTEGER PRIMARY KEY,
    level_mean_m INTEGER, level_min_m INTEGER, level_max_m INTEGER, baseline_m INTEGER,
    command_rms_mv INTEGER, readings INTEGER NOT NULL, samples INTEGER NOT NULL,
    priority INTEGER NOT NULL, alarm_state INTEGER NOT NULL);
CREATE TABLE IF NOT EXISTS trend_hour (
    hour INTEGER PRIMARY KEY,
    level_mean_m INTEGER, level_min_m INTEGER, level_max_m INTEGER, baseline_m INTEGER,
    command_rms_mv INTEGER, readings INTEGER NOT NULL, samples INTEGER NOT NULL,
    priority INTEGER NOT NULL, alarm_state INTEGER NOT NULL);
CREATE TABLE IF NOT EXISTS trend_meta (key TEXT PRIMARY KEY, value TEXT);
CREATE VIEW IF NOT EXISTS trend AS
    SELECT hour * 3600 AS time_unix, 3600 AS period_s, level_mean_m / 1000.0 AS level_mean,
        level_min_m / 1000.0 AS level_min, level_max_m / 1000.0 AS level_max,
        baseline_m / 1000.0 AS baseline, command_rms_mv / 1000.0 AS command_rms_v,
        readings, samples, priority, alarm_state FROM trend_hour
    UNION ALL
    SELECT minute * 60, 60, level_mean_m / 1000.0, level_min_m / 1000.0,
        level_max_m / 1000.0, baseline_m / 1000.0, command_rms_mv / 1000.0,
        readings, samples, priority, alarm_state FROM trend_minute;
"""
#: fold the minutes of whole hours before ``cutoff`` (a minute number) into trend_hour
_ROLL_UP = """
INSERT OR REPLACE INTO trend_hour SELECT minute / 60,
    CAST(ROUND(SUM(level_mean_m * readings) * 1.0
               / NULLIF(SUM(CASE WHEN level_mean_m IS NOT NULL THEN readings END), 0))
         AS INTEGER),
    MIN(level_min_m), MAX(level_max_m),
    (SELECT baseline_m FROM trend_minute AS last WHERE last.minute / 60 = m.minute / 60
     ORDER BY last.minute DESC LIMIT 1),
    CAST(ROUND(sqrt(SUM(command_rms_mv * command_rms_mv * samples) * 1.0
                    / NULLIF(SUM(CASE WHEN command_rms_mv IS NOT NULL THEN samples END), 0)))
         AS INTEGER),
    SUM(readings), SUM(samples), MAX(priority), MAX(alarm_state)
FROM trend_minute AS m WHERE minute < ? GROUP BY minute / 60
"""
KEEP_MINUTES_DAYS = 90.0
COLUMNS = (
    "minute",
    "level_mean",
    "level_min",
    "level_max",
    "baseline",
    "command_rms_v",
    "readings",
    "samples",
    "priority",
    "alarm_state",
)


@dataclass
class _Minute:
    minute: int
    count: int = 0
    total: float = 0.0
    low: float = math.inf
    high: float = -math.inf
    command_sq: float = 0.0
    samples: int = 0


class MinuteAggregator:
    """Per-minute statistics of the level readings and the valve command (pure, no I/O).

    ``level(now, level)``: one reading (None/NaN: none, the minute still counts);
    ``samples(now, v_in_values)``: the valve commands of a batch of samples; both return the
    finished row (a dict with `COLUMNS`) when ``now`` is in a later minute, else None.
    ``baseline``, ``priority`` and ``alarm_state`` are set by the caller and go into the row
    of the minute they are current at its end.
    """

    def __init__(self) -> None:
        self._current: _Minute | None = None
        self.baseline: float | None = None
        self.priority = 0
        self.alarm_state = 0

    def _roll(self, now: float) -> dict[str, Any] | None:
        minute = int(now // 60)
        cur = self._current
        if cur is not None and minute <= cur.minute:
            return None
        self._current = _Minute(minute)
        return None if cur is None else self._row(cur)

    def level(self, now: float, level: float | None) -> dict[str, Any] | None:
        row = self._roll(now)
        if level is not None and math.isfinite(level):
            cur = self._current
            assert cur is not None  # _roll started the minute
            cur.count += 1
            cur.total += level
            cur.low = min(cur.low, level)
            cur.high = max(cur.high, level)
        return row

    def samples(self, now: float, v_in: list[float]) -> dict[str, Any] | None:
        row = self._roll(now)
        cur = self._current
        assert cur is not None  # _roll started the minute
        cur.samples += len(v_in)
        cur.command_sq += sum(v * v for v in v_in if math.isfinite(v))
        return row

    def flush(self) -> dict[str, Any] | None:
        """The row of the minute in progress (at shutdown), or None."""
        cur, self._current = self._current, None
        return None if cur is None or not (cur.count or cur.samples) else self._row(cur)

    def _row(self, cur: _Minute) -> dict[str, Any]:
        has = cur.count > 0
        return {
            "minute": cur.minute,
            "level_mean": cur.total / cur.count if has else None,
            "level_min": cur.low if has else None,
            "level_max": cur.high if has else None,
            "baseline": self.baseline,
            "command_rms_v": math.sqrt(cur.command_sq / cur.samples) if cur.samples else None,
            "readings": cur.count,
            "samples": cur.samples,
            "priority": self.priority,
            "alarm_state": self.alarm_state,
        }


def open_trend_store(path: str | Path, meta: dict[str, Any]) -> TrendStore:
    """The store at ``path``; a file that is not a trend database is moved aside
    (``trend.sqlite.refused``, one log line) and a new one started."""
    try:
        return TrendStore(path, meta)
    except sqlite3.DatabaseError as exc:
        aside = Path(f"{path}.refused")
        os.replace(path, aside)
        log.warning(
            "trend %s is not a trend database (%s): kept as %s, starting a new one",
            path,
            exc,
            aside.name,
        )
        return TrendStore(path, meta)


def _sqrt(value: float | None) -> float | None:
    return None if value is None else math.sqrt(value)


def _scaled(value: float | None, scale: float) -> int | None:
    return None if value is None or not math.isfinite(value) else int(round(value * scale))


class TrendStore:
    """``trend.sqlite``: append rows (one transaction each: a row a minute)."""

    def __init__(
        self,
        path: str | Path,
        meta: dict[str, Any] | None = None,
        keep_minutes_days: float = KEEP_MINUTES_DAYS,
    ) -> None:
        self.path = Path(path)
        self.keep_minutes = int(round(keep_minutes_days * 1440))
        self.path.parent.mkdir(parents=True, exist_ok=True)
        # written from the sink thread only; made on the main thread
        self._db = sqlite3.connect(self.path, check_same_thread=False)
        self._db.create_function("sqrt", 1, _sqrt, deterministic=True)
        # WAL with synchronous=NORMAL: a commit (a row a minute) costs no fsync; a crash of
        # the process loses nothing committed, a power loss at most the last rows
        self._db.execute("PRAGMA journal_mode=WAL")
        self._db.execute("PRAGMA synchronous=NORMAL")
        with self._db:
            self._db.executescript(_SCHEMA)
            for key, value in (meta or {}).items():
                self._db.execute(
                    "INSERT OR REPLACE INTO trend_meta VALUES (?, ?)", (key, json.dumps(value))
                )
        self.written = 0

    def append(self, row: dict[str, Any]) -> None:
        """One minute; a second row for the same minute (a restart within it) replaces it
        only if it saw more readings."""
        values = (
            row["minute"],
            _scaled(row["level_mean"], LEVEL_SCALE),
            _scaled(row["level_min"], LEVEL_SCALE),
            _scaled(row["level_max"], LEVEL_SCALE),
            _scaled(row["baseline"], LEVEL_SCALE),
            _scaled(row["command_rms_v"], COMMAND_SCALE),
            int(row["readings"]),
            int(row["samples"]),
            int(row["priority"]),
            int(row["alarm_state"]),
        )
        with self._db:
            self._db.execute(
                "INSERT INTO trend_minute VALUES (?,?,?,?,?,?,?,?,?,?) ON CONFLICT(minute) "
                "DO UPDATE SET level_mean_m=excluded.level_mean_m, "
                "level_min_m=excluded.level_min_m, level_max_m=excluded.level_max_m, "
                "baseline_m=excluded.baseline_m, command_rms_mv=excluded.command_rms_mv, "
                "readings=excluded.readings, samples=excluded.samples, "
                "priority=excluded.priority, alarm_state=excluded.alarm_state "
                "WHERE excluded.readings > trend_minute.readings",
                values,
            )
            if row["minute"] % 60 == 0:  # once an hour: fold what is past retention
                cutoff = (row["minute"] - self.keep_minutes) // 60 * 60
                self._db.execute(_ROLL_UP, (cutoff,))
                self._db.execute("DELETE FROM trend_minute WHERE minute < ?", (cutoff,))
        self.written += 1

    def close(self) -> None:
        self._db.close()


def read_trend(path: str | Path, since_unix: float | None = None) -> dict[str, np.ndarray]:
    """The rows (from ``since_unix`` on) as arrays in plain units (`COLUMNS`, NaN = NULL);
    ``time_unix`` (s, the start of the minute or hour) replaces ``minute``, ``period_s``
    says which (60 or 3600)."""
    db = sqlite3.connect(f"file:{Path(path)}?mode=ro", uri=True)
    try:
        rows = db.execute(
            "SELECT time_unix, period_s, level_mean, level_min, level_max, baseline, "
            "command_rms_v, "
            "readings, samples, priority, alarm_state FROM trend WHERE time_unix >= ? "
            "ORDER BY time_unix",
            (-math.inf if since_unix is None else since_unix,),
        ).fetchall()
    finally:
        db.close()
    names = ("time_unix", "period_s") + COLUMNS[1:]
    data = np.array(rows, dtype=float).reshape(-1, len(names))  # None -> nan
    return {name: data[:, i] for i, name in enumerate(names)}


def trend_meta(path: str | Path) -> dict[str, Any]:
    db = sqlite3.connect(f"file:{Path(path)}?mode=ro", uri=True)
    try:
        return {k: json.loads(v) for k, v in db.execute("SELECT key, value FROM trend_meta")}
    finally:
        db.close()
