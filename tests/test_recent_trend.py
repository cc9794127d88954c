"""The last hours of the trend in the status snapshot (`alarm.trend`), from the keeper.

`AlarmKeeper` is driven like the daemon's loop drives it (a status refresh with a level
reading every 10 s) on a fake wall clock; the 10-minute buckets it puts into its summary are
checked against means and maxima computed directly from the readings it was given.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from fdi_daemon.alarms.lifecycle import AlarmSettings
from fdi_daemon.service.alarm_keeper import AlarmKeeper
from fdi_daemon.service.recent_trend import RecentTrend
from fdi_daemon.service.sinks import json_line

START = 1_790_000_000.0 - 1_790_000_000.0 % 3600  # a whole hour
BASELINE = 0.08
READING_S = 10.0


class Clock:
    def __init__(self, now: float) -> None:
        self.now = now

    def __call__(self) -> float:
        return self.now


def drive(hours: float, rest: tuple[float, float] = (2.0, 2.5), seed: int = 3):
    """Readings every 10 s for `hours`, none while the rig rests (`rest`, hours); returns
    the keeper, the clock and the (time, level) readings given."""
    rng = np.random.default_rng(seed)
    clock = Clock(START)
    keeper = AlarmKeeper(AlarmSettings(), "model", clock=clock)
    given = []
    for k in range(int(hours * 3600 / READING_S)):
        clock.now = START + k * READING_S
        hour = k * READING_S / 3600
        moving = not rest[0] <= hour < rest[1]
        level = BASELINE + 0.1 * hour + 0.02 * rng.standard_normal() if moving else None
        keeper.status(
            {"t": hour * 3600, "monitor": {"friction_level": level, "baseline_level": BASELINE}}
        )
        if level is not None:
            given.append((clock.now, level))
    return keeper, clock, np.array(given)


def reference(given: np.ndarray, now: float) -> tuple[list, list]:
    """Mean and max per 10-minute bucket of the readings in finished minutes."""
    last = int(now // 600)
    done = given[given[:, 0] // 60 < now // 60]
    means, maxima = [], []
    for bucket in range(last - 35, last + 1):
        levels = done[done[:, 0] // 600 == bucket, 1]
        means.append(float(levels.mean()) if levels.size else None)
        maxima.append(float(levels.max()) if levels.size else None)
    return means, maxima


def test_no_trend_before_the_first_finished_minute():
    keeper, _, _ = drive(50 / 3600)
    assert keeper.summary()["trend"] is None


def test_snapshot_carries_the_last_six_hours_in_ten_minute_buckets():
    keeper, clock, given = drive(7.0)
    trend = keeper.summary()["trend"]
    assert trend["bucket_s"] == 600
    assert trend["end"] == (clock.now // 600 + 1) * 600
    means, maxima = reference(given, clock.now)
    assert len(trend["mean"]) == len(trend["max"]) == 36
    for got, want in ((trend["mean"], means), (trend["max"], maxima)):
        assert [g is None for g in got] == [w is None for w in want]
        assert [g for g in got if g is not None] == pytest.approx(
            [w for w in want if w is not None], abs=5e-4
        )  # 3 decimals, like the store
    # the rest (hours 2-2.5 after START) is 3 empty buckets; the first hour is past 6 h
    assert sum(v is None for v in trend["mean"]) == 3
    assert trend["mean"][-1] == pytest.approx(BASELINE + 0.1 * 6.95, abs=0.02)


def test_buckets_age_out_and_a_long_pause_leaves_no_trend():
    keeper, clock, _ = drive(1.0)
    assert keeper.summary()["trend"] is not None
    clock.now += 6 * 3600 + 600  # nothing for more than the 6 hours shown
    assert keeper.summary()["trend"] is None


def test_a_full_trend_is_under_one_kilobyte_of_json():
    keeper, _, _ = drive(6.5, rest=(0.0, 0.0))
    trend = keeper.summary()["trend"]
    assert all(v is not None for v in trend["mean"][:-1])
    size = len(json_line({"trend": trend}))
    assert size < 1000, size


def test_minutes_without_readings_are_skipped():
    recent = RecentTrend()
    recent.add(
        {"minute": int(START // 60) - 1, "level_mean": None, "level_max": None, "readings": 0}
    )
    assert recent.summary(START + 60) is None
    recent.add({"minute": int(START // 60), "level_mean": 0.5, "level_max": 0.7, "readings": 2})
    recent.add({"minute": int(START // 60) + 1, "level_mean": 0.2, "level_max": 0.3, "readings": 6})
    trend = recent.summary(START + 120)
    assert trend["mean"][-1] == pytest.approx((0.5 * 2 + 0.2 * 6) / 8)
    assert trend["max"][-1] == 0.7
    assert json.loads(json.dumps(trend)) == trend


def test_a_restart_recalls_the_last_hours_from_the_trend_store(tmp_path):
    """The rows the first keeper finished go to the store (as the sink thread does); a new
    keeper (the restarted daemon) reads them back and shows the same buckets."""
    from fdi_daemon.service.trend import TrendStore

    clock = Clock(START)
    keeper = AlarmKeeper(AlarmSettings(), "model", clock=clock)
    store = TrendStore(tmp_path / "trend.sqlite")
    rng = np.random.default_rng(5)
    for k in range(int(5 * 3600 / READING_S)):
        clock.now = START + k * READING_S
        level = BASELINE + 0.05 * k * READING_S / 3600 + 0.02 * rng.standard_normal()
        _, row = keeper.status({"monitor": {"friction_level": level, "baseline_level": BASELINE}})
        if row is not None:
            store.append(row)
    store.close()
    before = keeper.summary()["trend"]
    restarted = AlarmKeeper(AlarmSettings(), "model", clock=clock)
    assert restarted.summary()["trend"] is None
    assert restarted.recall_trend(tmp_path / "trend.sqlite") == 5 * 60 - 1
    after = restarted.summary()["trend"]
    assert after["end"] == before["end"]
    assert [v is None for v in after["mean"]] == [v is None for v in before["mean"]]
    for key in ("mean", "max"):  # the store keeps 1/1000 of the signature
        assert [v for v in after[key] if v is not None] == pytest.approx(
            [v for v in before[key] if v is not None], abs=1.5e-3
        )
    # the minute in progress at the restart, finished again by the new keeper, counts once
    restarted.recent.add(
        {"minute": int(clock.now // 60) - 1, "level_mean": 9.0, "level_max": 9.0, "readings": 6}
    )
    assert restarted.summary()["trend"] == after
    assert restarted.recall_trend(tmp_path / "missing.sqlite") == 0


def test_the_restarted_daemon_shows_the_hours_before_its_restart(tmp_path):
    """`Daemon.alarm_keeper` on a state file of the same model refills the snapshot's trend
    from ``trend.sqlite``; another model's rows (no state file of its own) are not shown."""
    import time

    from reliability_support import load_test_model, model_path

    from fdi_daemon.service.config import config_from_dict
    from fdi_daemon.service.daemon import Daemon
    from fdi_daemon.service.state_file import write_state
    from fdi_daemon.service.trend import TrendStore

    config = config_from_dict(
        {
            "link": {"kind": "replay", "path": "rec.csv"},
            "model": {"path": str(model_path())},
            "service": {"state_dir": str(tmp_path)},
        },
        "rig.yaml",
        tmp_path,
    )
    model = load_test_model()
    first = Daemon().alarm_keeper(config, model)
    assert first.summary()["trend"] is None
    store = TrendStore(config.output_path(config.alarms["trend"]))
    now_minute = int(time.time() // 60)
    for minute in range(now_minute - 90, now_minute):
        store.append(
            {
                "minute": minute,
                "level_mean": 0.3,
                "level_min": 0.2,
                "level_max": 0.4,
                "baseline": BASELINE,
                "command_rms_v": 1.0,
                "readings": 600,
                "samples": 15360,
                "priority": 1,
                "alarm_state": 1,
            }
        )
    store.close()
    other = load_test_model()
    other.fault_filter.gamma_f += 1.0  # another unit of the level, no state file of its own
    assert Daemon().alarm_keeper(config, other).summary()["trend"] is None
    write_state(config.output_path(config.alarms["state_file"]), first.state({}))
    trend = Daemon().alarm_keeper(config, model).summary()["trend"]
    shown = [v for v in trend["mean"] if v is not None]
    assert len(shown) in (9, 10) and set(shown) == {0.3}  # 90 minutes: 9-10 buckets
    assert set(v for v in trend["max"] if v is not None) == {0.4}
