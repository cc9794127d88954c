"""Weeks next to the rig, simulated: fault-free days, then wear, through restarts.

The daemon's alarm parts (`AlarmKeeper`: lifecycle + trend minute, the state file, the
SQLite trend store) are driven with synthetic level readings every 10 s on a simulated wall
clock: the rig runs 06:00-22:00 and rests at night (no level readings), its level wanders
with the operating condition; a week fault-free, then friction grows by 1.3 signature
units over three weeks. The detector is played by a deliberately chattering stand-in: it
raises ``fault_detected`` whenever the level is 0.3 above the baseline and says
``cleared`` 20 minutes later (the 27-73 episodes of issue 13). Every 3 days the daemon
"restarts": the state goes through the state file and a new keeper starts from it.

Expected: one alarm, raised once, its priority rising 1 -> 2 -> 3 (one event per step),
never back down and never returned; the trend's rows show the level, the steps being
crossed and the rig's night rests; `fdi trend` reads them.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from fdi_daemon.alarms.lifecycle import AlarmSettings
from fdi_daemon.cli import main
from fdi_daemon.service.alarm_keeper import AlarmKeeper
from fdi_daemon.service.state_file import read_state, write_state
from fdi_daemon.service.trend import TrendStore, read_trend

DAYS = 28
WEAR_START_DAY = 7
WEAR = 1.3  # signature units reached at the end
BASELINE = 0.08  # fault-free level of this rig (the model's baseline)
READING_S = 10.0
START = 1_790_000_000.0 - 1_790_000_000.0 % 86400  # a UTC midnight


class Clock:
    def __init__(self, now: float) -> None:
        self.now = now

    def __call__(self) -> float:
        return self.now


def true_excess(day: float) -> float:
    return WEAR * min(1.0, max(0.0, (day - WEAR_START_DAY) / (DAYS - WEAR_START_DAY)))


def simulate(tmp_path, restart_every_days: float = 3.0, seed: int = 7):
    rng = np.random.default_rng(seed)
    clock = Clock(START)
    settings = AlarmSettings()
    state_path = tmp_path / "state.json"
    store = TrendStore(tmp_path / "trend.sqlite", {"steps": list(settings.steps)})
    keeper = AlarmKeeper(settings, "model", clock=clock)
    events: list[dict] = []
    next_restart = START + restart_every_days * 86400
    detector_on_until = None
    restarts = 0
    condition = 0.0  # operating condition effect on the level, a slow random walk
    counts: dict[str, int] = {}
    for k in range(int(DAYS * 86400 / READING_S)):
        clock.now = START + k * READING_S
        day = (clock.now - START) / 86400
        hour = (k * READING_S % 86400) / 3600
        moving = 6.0 <= hour < 22.0
        condition = 0.98 * condition + 0.004 * rng.standard_normal()
        level = (
            BASELINE + true_excess(day) + condition + 0.03 * rng.standard_normal()
            if moving
            else None
        )
        # the chattering stand-in detector
        detector = []
        if moving and detector_on_until is None and level - BASELINE > 0.3:
            detector = [
                {"t": day * 86400, "kind": "fault_detected"},
                {"t": day * 86400, "kind": "friction_isolated"},
            ]
            detector_on_until = clock.now + 1200.0
        elif detector_on_until is not None and clock.now >= detector_on_until:
            detector = [{"t": day * 86400, "kind": "cleared"}]
            detector_on_until = None
        for event in detector:
            counts[event["kind"]] = counts.get(event["kind"], 0) + 1
            events.extend(keeper.detector_event(event))
        snapshot = {
            "t": day * 86400,
            "monitor": {"friction_level": level, "baseline_level": BASELINE},
        }
        new, row = keeper.status(snapshot)
        events.extend(new)
        if moving:
            keeper.samples([_Sample(1.0 + 0.2 * math.sin(day))] * 26)
        if row is not None:
            store.append(row)
        if clock.now >= next_restart:  # the daemon restarts: state file round trip
            write_state(state_path, keeper.state(counts))
            keeper = AlarmKeeper(
                settings, "model", stored=read_state(state_path, "model"), clock=clock
            )
            detector_on_until = None  # the new detector run starts afresh
            next_restart += restart_every_days * 86400
            restarts += 1
    store.close()
    return events, counts, restarts, keeper


class _Sample:
    __slots__ = ("v_in",)

    def __init__(self, v_in: float) -> None:
        self.v_in = v_in


@pytest.fixture(scope="module")
def weeks(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("weeks")
    return tmp, *simulate(tmp)


def test_wear_through_restarts_is_one_alarm_rising_through_its_steps(weeks):
    tmp, events, counts, restarts, keeper = weeks
    assert restarts >= 8
    assert counts["fault_detected"] > 20  # the stand-in detector chatters ...
    raised = [e for e in events if e["kind"] == "alarm_raised"]
    assert len(raised) == 1  # ... the alarm does not
    steps = [(e["previous"], e["priority"]) for e in events if e["kind"] == "alarm_priority"]
    assert steps == [(1, 2), (2, 3)]
    assert not [e for e in events if e["kind"] == "alarm_returned"]
    day_raised = (raised[0]["time"] - START) / 86400
    assert WEAR_START_DAY < day_raised < WEAR_START_DAY + 0.35 / WEAR * (DAYS - WEAR_START_DAY)
    summary = keeper.summary()
    assert summary["alarm_id"] == 1 and summary["priority"] == 3 and summary["annunciated"]


def test_the_trend_shows_the_wear_the_steps_and_the_rests(weeks, tmp_path, capsys):
    tmp, events, *_ = weeks
    data = read_trend(tmp / "trend.sqlite")
    minutes = len(data["time_unix"])
    assert minutes == DAYS * 1440 - 1  # every minute has a row (the last is in progress)
    hour = (data["time_unix"] % 86400) / 3600
    night = (hour < 6) | (hour >= 22)
    assert np.all(np.isnan(data["level_mean"][night])) and np.all(data["readings"][night] == 0)
    day_rows = ~night
    assert np.all(data["readings"][day_rows] == 6)
    # the level per day follows the wear (within the operating-condition wander)
    day = (data["time_unix"] - START) // 86400
    for d in (3, 14, 27):
        mean = np.nanmean(data["level_mean"][day == d])
        assert mean == pytest.approx(BASELINE + true_excess(d + 14 / 24), abs=0.06), d
    assert np.all(data["baseline"][day_rows] == BASELINE)
    # the alarm priority column rises once through 1, 2, 3 and stays
    changes = data["priority"][np.flatnonzero(np.diff(data["priority"])) + 1]
    assert list(changes) == [1, 2, 3]
    assert (
        main(
            [
                "trend",
                "--db",
                str(tmp / "trend.sqlite"),
                "--since",
                "2026-09-01",
                "--csv",
                str(tmp_path / "trend.csv"),
                "--plot",
                str(tmp_path / "trend.png"),
            ]
        )
        == 0
    )
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 1 + DAYS
    assert lines[-1].split()[5] == "3"  # the last day's highest priority
    assert (tmp_path / "trend.png").stat().st_size > 10_000
    assert len((tmp_path / "trend.csv").read_text().splitlines()) == minutes + 1


def test_trend_outputs_that_would_destroy_the_trend_are_refused(tmp_path, capsys):
    db = tmp_path / "trend.sqlite"
    db.write_bytes(b"the trend of months")
    assert main(["trend", "--db", str(db), "--csv", str(db)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is also an input" in err
    assert main(["trend", "--db", str(db), "--plot", str(tmp_path / "t.xyz")]) == 2
    assert "cannot write a plot as .xyz" in capsys.readouterr().err
    assert db.read_bytes() == b"the trend of months"
