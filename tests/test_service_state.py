"""State file (atomic, refused when corrupt or of another model), trend store, alarm keeper."""

from __future__ import annotations

import json
import logging
import math
import os
import sqlite3

import numpy as np
import pytest
from reliability_support import load_test_model

from fdi_daemon.alarms.lifecycle import AlarmSettings
from fdi_daemon.io.sample import Sample
from fdi_daemon.service.alarm_keeper import AlarmKeeper
from fdi_daemon.service.state_file import model_identity, read_state, write_state
from fdi_daemon.service.trend import MinuteAggregator, TrendStore, read_trend, trend_meta


class Clock:
    def __init__(self, now=1_700_000_000.0):
        self.now = now

    def __call__(self):
        return self.now


def snapshot(level, t=1.0, baseline=None):
    monitor = {"friction_level": level}
    if baseline is not None:
        monitor["baseline_level"] = baseline
    return {"t": t, "monitor": monitor}


# ----------------------------------------------------------------------------- state file


def test_state_file_round_trip_and_atomic_replace(tmp_path):
    path = tmp_path / "state.json"
    write_state(path, {"model": "abc", "alarm": {"x": 1}})
    write_state(path, {"model": "abc", "alarm": {"x": 2}})
    assert read_state(path, "abc")["alarm"] == {"x": 2}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["state.json"]  # no temp file left


def test_a_missing_state_file_is_a_fresh_start_without_a_word(tmp_path, caplog):
    with caplog.at_level(logging.INFO):
        assert read_state(tmp_path / "state.json", "abc") is None
    assert caplog.records == []


@pytest.mark.parametrize(
    "content, why",
    [
        ('{"format": "fdi-state", "version": 1, "model": "ab', "corrupt"),
        ("", "corrupt"),
        ('[1, 2]', "corrupt"),
        ('{"format": "fdi-state", "version": 7, "model": "abc"}', "corrupt"),
        ('{"format": "fdi-state", "version": 1, "model": "other"}', "another model"),
    ],
)
def test_a_bad_state_file_is_refused_with_one_line_and_kept_aside(tmp_path, caplog, content, why):
    path = tmp_path / "state.json"
    path.write_text(content)
    with caplog.at_level(logging.WARNING, logger="fdi.state"):
        assert read_state(path, "abc") is None
    assert len(caplog.records) == 1 and why in caplog.records[0].getMessage()
    assert not path.exists() and (tmp_path / "state.json.refused").read_text() == content


def test_model_identity_follows_the_units_of_the_level_only():
    model = load_test_model()
    base = model_identity(model)
    assert base == model_identity(
        load_test_model(detector={"threshold": 99.0}, provenance={"note": "edited"})
    )
    other = load_test_model()
    other.fault_filter.gamma_f = other.fault_filter.gamma_f + 0.1
    assert model_identity(other) != base
    assert len(base) == 64


# ----------------------------------------------------------------------------- trend


def test_minute_aggregator_statistics_against_numpy():
    rng = np.random.default_rng(4)
    agg = MinuteAggregator()
    t0 = 60.0 * 1000
    levels = rng.uniform(0, 1, 600)
    levels[::7] = np.nan
    rows = []
    for k, level in enumerate(levels):
        rows.append(agg.level(t0 + 0.1 * k, float(level)))
        if k % 10 == 0:
            rows.append(agg.samples(t0 + 0.1 * k, [0.5, -1.0, math.nan]))
    assert [r for r in rows if r is not None] == []
    agg.priority = 2
    row = agg.level(t0 + 60.0, 0.3)
    good = levels[np.isfinite(levels)]
    assert row["minute"] == 1000 and row["readings"] == good.size
    assert row["level_mean"] == pytest.approx(good.mean(), rel=1e-12)
    assert row["level_min"] == good.min() and row["level_max"] == good.max()
    assert row["samples"] == 180 and row["priority"] == 2
    # nan values of v_in are skipped in the sum but counted as samples
    assert row["command_rms_v"] == pytest.approx(math.sqrt(60 * 1.25 / 180))


def test_trend_store_round_trip_and_view(tmp_path):
    path = tmp_path / "trend.sqlite"
    store = TrendStore(path, {"steps": [0.25, 0.5, 1.0]})
    row = {
        "minute": 29_000_000,
        "level_mean": 0.4321,
        "level_min": 0.1,
        "level_max": 0.9,
        "baseline": None,
        "command_rms_v": 1.2345,
        "readings": 600,
        "samples": 15360,
        "priority": 1,
        "alarm_state": 1,
    }
    store.append(row)
    store.append(
        {
            **row,
            "minute": row["minute"] + 1,
            "level_mean": None,
            "level_min": None,
            "level_max": None,
            "readings": 0,
        }
    )
    store.append({**row, "level_mean": 0.0, "readings": 3})  # fewer readings: not replaced
    store.close()
    data = read_trend(path)
    assert list(data["time_unix"]) == [29_000_000 * 60, 29_000_001 * 60]
    assert data["level_mean"][0] == 0.432 and math.isnan(data["level_mean"][1])
    assert data["command_rms_v"][0] == 1.234 and math.isnan(data["baseline"][0])
    assert trend_meta(path)["steps"] == [0.25, 0.5, 1.0]
    assert len(read_trend(path, since_unix=29_000_001 * 60)["time_unix"]) == 1
    with sqlite3.connect(path) as db:
        assert db.execute("SELECT level_mean_m FROM trend_minute").fetchall() == [(432,), (None,)]


# ----------------------------------------------------------------------------- keeper


def test_keeper_level_above_the_baseline_sets_the_priority():
    clock = Clock()
    keeper = AlarmKeeper(AlarmSettings(raise_delay_s=0.0), "m", clock=clock)
    (raised,) = keeper.detector_event({"t": 5.0, "kind": "fault_detected"})
    assert raised["kind"] == "alarm_raised" and raised["t"] == 5.0
    clock.now += 1
    events, _ = keeper.status(snapshot(0.9, t=6.0, baseline=0.35))  # 0.55 above the baseline
    assert [e["priority"] for e in events] == [2] and events[0]["t"] == 6.0
    assert keeper.summary()["baseline_level"] == 0.35


def test_keeper_requests_are_refused_unless_allowed_and_emitted_by_the_loop():
    clock = Clock()
    keeper = AlarmKeeper(AlarmSettings(), "m", clock=clock)
    keeper.detector_event({"kind": "fault_detected"})
    answer = keeper.handle({"request": "acknowledge", "by": "test"})
    assert not answer["ok"] and "allow_remote_acknowledge" in answer["error"]
    keeper.allow_remote = True
    assert not keeper.handle({"request": "shelve", "by": "test"})["ok"]
    assert not keeper.handle({"request": "reboot", "by": "test"})["ok"]
    answer = keeper.handle({"request": "acknowledge", "by": "test"})
    assert answer["ok"] and answer["alarm"]["state"] == "acknowledged"
    answer = keeper.handle({"request": "shelve", "by": "test", "duration_s": 60})
    assert answer["ok"] and answer["alarm"]["state_code"] == 4
    assert [e["kind"] for e in keeper.take_pending()] == ["alarm_acknowledged", "alarm_shelved"]
    assert keeper.take_pending() == []


def test_keeper_state_survives_a_file_round_trip(tmp_path):
    clock = Clock()
    keeper = AlarmKeeper(AlarmSettings(raise_delay_s=0.0), "m", clock=clock)
    keeper.detector_event({"kind": "fault_detected"})
    keeper.status(snapshot(0.7))
    write_state(tmp_path / "s.json", keeper.state({"fault_detected": 1, "calibrated": 3}))
    clock.now += 30
    restored = AlarmKeeper(
        AlarmSettings(), "m", stored=read_state(tmp_path / "s.json", "m"), clock=clock
    )
    assert restored.summary()["priority"] == 2 and restored.lifecycle.active
    assert restored.event_counts == {"fault_detected": 1, "calibrated": 3}
    assert restored.detector_event({"kind": "fault_detected"}) == []


def test_keeper_trend_rows_carry_the_valve_command_rms():
    clock = Clock(60.0 * 2000)
    keeper = AlarmKeeper(AlarmSettings(), "m", clock=clock)
    for k in range(10):
        keeper.samples([Sample(k, k / 256, 2.0, 0.0)] * 4)
        keeper.status(snapshot(0.1))
    clock.now += 60
    _, row = keeper.status(snapshot(0.2))
    assert row["command_rms_v"] == 2.0 and row["samples"] == 40 and row["readings"] == 10


def test_state_file_is_fsynced_before_the_rename(tmp_path, monkeypatch):
    calls = []
    real_fsync, real_replace = os.fsync, os.replace
    monkeypatch.setattr(os, "fsync", lambda fd: (calls.append("fsync"), real_fsync(fd)))
    monkeypatch.setattr(os, "replace", lambda a, b: (calls.append("replace"), real_replace(a, b)))
    write_state(tmp_path / "state.json", {"model": "m"})
    assert calls == ["fsync", "replace", "fsync"]  # file, rename, then the folder
    assert json.loads((tmp_path / "state.json").read_text())["model"] == "m"


def test_minutes_past_retention_are_folded_into_hours(tmp_path):
    rng = np.random.default_rng(9)
    path = tmp_path / "trend.sqlite"
    store = TrendStore(path, keep_minutes_days=1.0)
    first = 29_000_000 - 29_000_000 % 60
    n = 3 * 1440 + 1
    rows = []
    for k in range(n):
        resting = k % 300 < 40
        mean = float(rng.uniform(0, 1))
        rows.append(
            {
                "minute": first + k,
                "level_mean": None if resting else mean,
                "level_min": None if resting else mean - 0.1,
                "level_max": None if resting else mean + 0.1,
                "baseline": 0.05,
                "command_rms_v": float(rng.uniform(0.5, 1.5)),
                "readings": 0 if resting else int(rng.integers(100, 600)),
                "samples": 15360,
                "priority": int(k > 2000),
                "alarm_state": 0,
            }
        )
        store.append(rows[-1])
    store.close()
    with sqlite3.connect(path) as db:
        minutes = db.execute("SELECT MIN(minute), COUNT(*) FROM trend_minute").fetchone()
        hours = db.execute("SELECT * FROM trend_hour ORDER BY hour").fetchall()
    cutoff = (first + n - 1 - 1440) // 60 * 60
    assert minutes == (cutoff, first + n - cutoff)
    assert len(hours) == (cutoff - first) // 60
    for hour in hours[::7]:
        sel = [r for r in rows if r["minute"] // 60 == hour[0]]
        m = np.array([round(r["level_mean"] * 1000) if r["readings"] else 0 for r in sel])
        w = np.array([r["readings"] for r in sel])
        cmd = np.array([round(r["command_rms_v"] * 1000) for r in sel], dtype=float)
        expected_mean = round(float((m * w).sum() / w.sum())) if w.sum() else None
        assert hour[1] == expected_mean
        lows = [round((r["level_mean"] - 0.1) * 1000) for r in sel if r["readings"]]
        assert hour[2] == (min(lows) if lows else None)
        assert hour[5] == round(math.sqrt((cmd**2 * 15360).sum() / (15360 * len(sel))))
        assert hour[6] == w.sum() and hour[7] == 15360 * len(sel)
        assert hour[8] == max(r["priority"] for r in sel) and hour[4] == 50
    data = read_trend(path)  # the view: hours, then minutes, one time axis
    assert np.all(np.diff(data["time_unix"]) > 0)
    assert set(np.unique(data["period_s"])) == {60.0, 3600.0}


def test_a_file_that_is_not_a_trend_database_is_moved_aside(tmp_path, caplog):
    from fdi_daemon.service.trend import open_trend_store

    path = tmp_path / "trend.sqlite"
    path.write_bytes(b"this is not SQLite" * 100)
    with caplog.at_level(logging.WARNING, logger="fdi.trend"):
        store = open_trend_store(path, {"steps": [0.25]})
    store.close()
    assert len(caplog.records) == 1 and "not a trend database" in caplog.text
    assert (tmp_path / "trend.sqlite.refused").read_bytes().startswith(b"this is not")
    assert trend_meta(path) == {"steps": [0.25]}


def test_a_reload_keeps_the_alarm_unless_the_model_changes_its_unit(tmp_path, caplog):
    from reliability_support import model_path

    from fdi_daemon.service.config import config_from_dict
    from fdi_daemon.service.daemon import Daemon

    config = config_from_dict(
        {
            "link": {"kind": "replay", "path": "rec.csv"},
            "model": {"path": str(model_path())},
            "service": {"state_dir": str(tmp_path)},
            "alarms": {"steps": [0.3, 0.6]},
        },
        "rig.yaml",
        tmp_path,
    )
    daemon = Daemon()
    first = daemon.alarm_keeper(config, load_test_model())
    first.detector_event({"kind": "fault_detected"})
    daemon.keeper = first
    same = daemon.alarm_keeper(config, load_test_model(detector={"threshold": 40.0}))
    assert same is first and same.lifecycle.settings.steps == (0.3, 0.6)
    other = load_test_model()
    other.fault_filter.gamma_f += 1.0
    with caplog.at_level(logging.WARNING, logger="fdi.daemon"):
        fresh = daemon.alarm_keeper(config, other)
    assert fresh is not first and fresh.lifecycle.state == "normal"
    assert "another unit" in caplog.text
