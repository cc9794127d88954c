"""The dashboard's trend panel: the last hours of the friction level (the snapshot's
``alarm.trend``) against the baseline and the alarm steps, with the alarm's state."""

from __future__ import annotations

import math
import re

import pytest
from conftest_dashboard import make_snapshot, screen_text
from test_dashboard_render import SIZES, daemon_events, lines_of

from fdi_daemon.dashboard.render import _trend_layers, render

BASELINE, STEPS = 0.08, [0.25, 0.5, 1.0]


def alarm_section(
    mean: list | None, state: str = "unacknowledged", priority: int = 2, **extra
) -> dict:
    trend = (
        None
        if mean is None
        else {
            "bucket_s": 600,
            "end": 1_780_000_200,
            "mean": mean,
            "max": [None if m is None else round(m + 0.05, 3) for m in mean],
        }
    )
    return {
        "state": state,
        "state_code": {"normal": 0, "unacknowledged": 1, "acknowledged": 2}.get(state, 3),
        "priority": priority,
        "shelved_until": None,
        "baseline_level": BASELINE,
        "steps": STEPS,
        "trend": trend,
        **extra,
    }


def wear(n: int = 36) -> list:
    """Flat at the baseline, a rest (3 empty buckets), then rising 0.03 per bucket."""
    return [None if 10 <= i < 13 else round(BASELINE + max(0, i - 21) * 0.03, 3) for i in range(n)]


def panel_rows(text: str, title: str) -> list[str]:
    """The rows of the panel whose top border starts with `title`, its bottom border last."""
    lines = lines_of(text)
    top = next(i for i, line in enumerate(lines) if "╭─ " + title in line)
    start = lines[top].index("╭─ " + title)
    rows = []
    for line in lines[top + 1 :]:
        rows.append(line[start:])
        if line[start] == "╰":
            return rows
    raise AssertionError("the panel has no bottom border")


#: a dashed level line: the same braille cell, a space, the same cell, ...
DASHED = re.compile(r"([\u2801-\u28ff]) \1 \1 \1")


@pytest.mark.parametrize("width,height", [(80, 24), (100, 30), (200, 50)])
def test_trend_panel_shows_the_hours_the_baseline_steps_and_alarm(width, height):
    snapshot = make_snapshot("friction_isolated", theta=(0.98, 2.3))
    snapshot["alarm"] = alarm_section(wear())
    text = screen_text(render(snapshot), width, height)
    lines = lines_of(text)
    assert len(lines) == height and all(len(line) <= width for line in lines)
    rows = panel_rows(text, "━ level ━ max")
    top = next(line for line in lines if "╭─ ━ level" in line)
    assert "base 0.08" in top and "steps +0.25/0.5/1" in top
    assert "-6 h … now" in rows[-1] and "ALARM P2 unacknowledged" in rows[-1]
    body = rows[:-1]
    assert sum("\u2800" < ch <= "\u28ff" for row in body for ch in row) > 40
    # the steps in range (baseline + 0.25 crossed, + 0.5 the next) are dashed rows
    assert sum(bool(DASHED.search(row)) for row in body) >= 1 + (height >= 30), body
    # the event rows stay whole next to it
    assert "friction_isolated" in text and "fault_detected" in text


def test_trend_layers_mark_the_steps_up_to_the_next_one_and_break_at_rests():
    layers, y_range = _trend_layers(alarm_section(wear()))
    levels = [s.level for s in layers if s.level is not None]
    dashed = [s.level for s in layers if s.dashed]
    top = max(v for v in wear() if v is not None) + 0.05  # the largest max: 0.55
    # baseline, +0.25 (crossed), +0.5 (the next one: 0.58 > 0.55); +1.0 left out
    assert levels == pytest.approx([BASELINE, BASELINE + 0.25, BASELINE + 0.5])
    assert dashed == pytest.approx([BASELINE + 0.25, BASELINE + 0.5])
    assert y_range[0] < BASELINE and y_range[1] > BASELINE + 0.5 > top
    mean = layers[-1]
    # a step per bucket, from its start to its end, in hours before now
    assert mean.t[:3] == pytest.approx([-6.0, -35 / 6, -35 / 6]) and mean.t[-1] == 0.0
    assert [math.isnan(v) for v in mean.y[::2]] == [v is None for v in wear()]
    assert [v for v in mean.y[::2] if v == v] == [v for v in mean.y[1::2] if v == v]


def test_no_trend_yet_and_the_alarm_states():
    snapshot = make_snapshot("monitoring")
    snapshot["alarm"] = alarm_section(None, state="normal", priority=0)
    text = screen_text(render(snapshot), 80, 24)
    assert "no trend yet" in text and "no alarm" in text
    snapshot["alarm"] = alarm_section(wear(), state="acknowledged", priority=3)
    assert "alarm P3 acknowledged" in screen_text(render(snapshot), 80, 24)
    snapshot["alarm"] = alarm_section(wear(), state="returned_unacknowledged")
    assert "returned, unacknowledged" in screen_text(render(snapshot), 80, 24)
    snapshot["alarm"] = alarm_section(wear(), state_code=4, shelved_until=1_780_003_600.0)
    text = screen_text(render(snapshot), 80, 24)
    assert "shelved until " in text and "ALARM" not in text


def test_without_an_alarm_section_the_layout_is_as_before():
    snapshot = make_snapshot("monitoring")
    assert "━ level" not in screen_text(render(snapshot), 80, 24)
    snapshot["alarm"] = None  # a daemon without the alarm keeper
    assert "no trend yet" not in screen_text(render(snapshot), 80, 24)


@pytest.mark.parametrize("width,height", SIZES)
def test_malformed_trend_never_breaks_the_view(width, height):
    snapshot = make_snapshot("monitoring")
    for trend in (
        {"bucket_s": "x", "mean": [1]},
        {"bucket_s": 600, "mean": "abc"},
        {"bucket_s": 600, "mean": [None, None], "max": [None]},
        {"bucket_s": 600, "mean": [0.1, float("nan")], "max": [0.2]},
        [1, 2],
    ):
        snapshot["alarm"] = {"trend": trend, "steps": "bad", "baseline_level": "x"}
        lines = lines_of(screen_text(render(snapshot), width, height))
        assert len(lines) == height


def test_event_rows_at_80x24_stay_whole_with_the_trend_panel():
    snapshot = make_snapshot("friction_isolated", n_alarms=0)
    snapshot["alarms"] = daemon_events()
    snapshot["alarm"] = alarm_section(wear())
    text = screen_text(render(snapshot), 80, 24)
    assert "20.547 s friction_isolated  Δθ1 +1.6 harmonics" in text
    assert "20.020 s fault_detected     stat 64.7/30 fast" in text
    assert "2.387 s calibrated         samples 256" in text


def test_alarm_event_rows_show_priority_step_and_level():
    snapshot = make_snapshot("friction_isolated", n_alarms=0)
    common = {"time": 1_780_000_000.0, "alarm_id": 1, "state": "unacknowledged", "shelved": False}
    snapshot["alarms"] = daemon_events() + [
        {
            "t": 20.020,
            "kind": "alarm_raised",
            **common,
            "priority": 1,
            "level": 1.33,
            "cause": "fault_detected",
            "classification": "friction",
        },
        {
            "t": 89.137,
            "kind": "alarm_priority",
            **common,
            "priority": 2,
            "level": 1.331,
            "previous": 1,
            "step": 0.5,
        },
    ]
    snapshot["alarm"] = alarm_section(wear())
    text = screen_text(render(snapshot), 80, 24)
    assert "89.137 s alarm_priority     prio 2 level 1.33" in text
    assert "20.020 s alarm_raised       prio 1 friction" in text
    snapshot["alarms"][-2]["classification"] = None  # not known yet at the raise
    text = screen_text(render(snapshot), 80, 24)
    assert "alarm_raised       prio 1 " in text and "None" not in text
    wide = screen_text(render(snapshot), 120, 30)
    assert "alarm_priority     prio 2 level 1.33 step 0.5" in wide


def test_compact_view_names_the_alarm():
    snapshot = make_snapshot("friction_isolated")
    snapshot["alarm"] = alarm_section(wear())
    lines = lines_of(screen_text(render(snapshot), 60, 18))
    assert len(lines) == 18
    assert any(line.startswith("alarm ALARM P2 unacknowledged") for line in lines)
