"""The alarm lifecycle (fdi_daemon.alarms.lifecycle): one alarm per fault, priority steps
with deadband and delays, acknowledge, shelving, return to normal, persistence, batch = step."""

from __future__ import annotations

import json

import numpy as np
import pytest

from fdi_daemon.alarms.lifecycle import AlarmLifecycle, AlarmSettings

FAULT = {"kind": "fault_detected"}
FRICTION = {"kind": "friction_isolated"}
CLEARED = {"kind": "cleared"}


def settings(**changes):
    """Settings without smoothing (the tests feed exact levels), unless asked."""
    return AlarmSettings(**{"smoothing_s": 0.0, **changes})


def kinds(events):
    return [e["kind"] for e in events]


def feed(lc, times, levels, events=None):
    events = events or {}
    out = []
    for i, (t, level) in enumerate(zip(times, levels)):
        out.extend(lc.step(float(t), level, events.get(i)))
    return out


def test_a_repeated_detector_fault_is_one_alarm():
    lc = AlarmLifecycle(settings())
    out = lc.step(0.0, 0.3, FAULT)
    assert kinds(out) == ["alarm_raised"] and out[0]["alarm_id"] == 1
    assert out[0]["priority"] == 1 and out[0]["state"] == "unacknowledged"
    out = lc.step(1.0, 0.3, FRICTION) + lc.step(2.0, 0.3, FAULT)
    assert out == [] and lc.summary(2.0)["classification"] == "friction"


def test_priority_rises_one_event_per_step_after_the_on_delay():
    lc = AlarmLifecycle(settings(raise_delay_s=5.0))
    lc.step(0.0, 0.1, FAULT)
    assert lc.priority == 1
    assert lc.step(1.0, 0.55) == [] and lc.step(5.9, 0.6) == []  # on-delay not yet over
    out = lc.step(6.0, 0.6)
    assert kinds(out) == ["alarm_priority"] and out[0]["priority"] == 2
    assert out[0]["previous"] == 1 and out[0]["step"] == 0.5
    lc.step(7.0, 1.5)
    out = lc.step(12.0, 1.5)
    assert [e["priority"] for e in out] == [3]
    # each step has its own on-delay: above 1.0 for 3 s of 5 is step 2 only
    lc3 = AlarmLifecycle(settings(raise_delay_s=5.0))
    lc3.step(0.0, 0.0, FAULT)
    assert lc3.step(1.0, 0.6) == [] and lc3.step(3.0, 1.2) == []
    assert [e["priority"] for e in lc3.step(6.0, 1.2)] == [2]
    assert [e["priority"] for e in lc3.step(8.0, 1.2)] == [3]
    # a jump over two steps at once: two events, one per step
    lc2 = AlarmLifecycle(settings(raise_delay_s=0.0))
    lc2.step(0.0, 0.0, FAULT)
    out = lc2.step(1.0, 1.2)
    assert [(e["previous"], e["priority"]) for e in out] == [(1, 2), (2, 3)]
    assert [e["step"] for e in out] == [0.5, 1.0]


def test_a_level_that_dithers_around_a_step_does_not_chatter():
    rng = np.random.default_rng(1)
    lc = AlarmLifecycle(settings(raise_delay_s=5.0, lower_delay_s=300.0, deadband=0.05))
    lc.step(0.0, 0.3, FAULT)
    times = np.arange(1.0, 3 * 3600.0, 1.0)
    levels = 0.5 + 0.04 * np.sin(times / 7.0) + 0.01 * rng.standard_normal(times.size)
    out = feed(lc, times, levels)
    assert kinds(out) == ["alarm_priority"]  # up once to 2, never back down (within deadband)
    assert lc.priority == 2
    # the same dither without a deadband chatters: the test can fail
    lc0 = AlarmLifecycle(settings(raise_delay_s=0.0, lower_delay_s=0.0, deadband=0.0))
    lc0.step(0.0, 0.3, FAULT)
    assert len(feed(lc0, times, levels)) > 100


def test_smoothing_keeps_noisy_readings_from_chattering_and_follows_a_step():
    rng = np.random.default_rng(2)
    times = np.arange(1.0, 4 * 3600.0, 0.1)  # 10 Hz readings, as the daemon's
    levels = 0.47 + 0.08 * rng.standard_normal(times.size)
    counts = {}
    for smoothing in (0.0, 30.0):
        lc = AlarmLifecycle(settings(smoothing_s=smoothing, raise_delay_s=0.0, lower_delay_s=0.0))
        lc.step(0.0, 0.3, FAULT)
        counts[smoothing] = len(feed(lc, times, levels))
    assert counts[30.0] == 0 and counts[0.0] > 20
    # a step of the level: the smoothed level crosses 0.5 after 30 s * ln(1/(1 - 0.5/1.4))
    lc = AlarmLifecycle(settings(smoothing_s=30.0, raise_delay_s=0.0))
    lc.step(0.0, 0.0, FAULT)
    out = feed(lc, np.arange(0.1, 60.0, 0.1), np.full(599, 1.4))
    first = out[0]["time"]
    assert first == pytest.approx(30.0 * np.log(1 / (1 - 0.5 / 1.4)), abs=0.11)


def test_priority_falls_only_below_the_deadband_for_the_off_delay_and_never_below_1():
    lc = AlarmLifecycle(settings(raise_delay_s=0.0, lower_delay_s=60.0, deadband=0.05))
    lc.step(0.0, 1.2, FAULT)
    assert lc.priority == 3
    assert lc.step(10.0, 0.97) == []  # below 1.0 but within the deadband
    assert lc.step(20.0, 0.9) == []  # off-delay starts
    assert lc.step(79.0, 0.9) == []
    out = lc.step(80.0, 0.0)  # below 0.95 for 60 s; below 0.45 just now
    assert [(e["previous"], e["priority"]) for e in out] == [(3, 2)]
    assert lc.step(110.0, 0.0) == [] and lc.step(139.0, 0.0) == []
    out = lc.step(140.0, 0.0)  # each step keeps its own off-delay
    assert [(e["previous"], e["priority"]) for e in out] == [(2, 1)]
    assert lc.active and lc.priority == 1
    assert lc.step(300.0, 0.0) == []  # never below 1 while active


def test_cleared_then_a_new_fault_within_the_return_delay_is_the_same_alarm():
    lc = AlarmLifecycle(settings(return_delay_s=600.0))
    lc.step(0.0, 0.4, FAULT)
    out = lc.step(100.0, 0.1, CLEARED) + lc.step(200.0, 0.1) + lc.step(650.0, 0.4, FAULT)
    out += lc.step(700.0, 0.1, CLEARED)
    assert out == [] and lc.summary(700.0)["alarm_id"] == 1 and lc.active


def every_10_s(lc, start, stop, level):
    """Readings of ``level`` every 10 s in [start, stop); the events they raised."""
    return feed(lc, np.arange(start, stop, 10.0), np.full(int(np.ceil((stop - start) / 10)), level))


def test_return_needs_the_detector_cleared_and_the_level_back_for_the_delay_of_motion():
    lc = AlarmLifecycle(settings(return_delay_s=600.0, return_level=0.1))
    lc.step(0.0, 0.4, FAULT)
    assert lc.step(100.0, 0.4, CLEARED) == []
    assert every_10_s(lc, 110.0, 900.0, 0.15) == []  # below the lowest step, not back
    assert every_10_s(lc, 900.0, 1200.0, 0.05) == []  # back: 290 s of motion so far
    assert every_10_s(lc, 5000.0, 5300.0, 0.05) == []  # a rest (no readings), then 580 s
    assert lc.step(5300.0, 0.05) == []  # 590 s
    out = lc.step(5310.0, 0.05)
    assert kinds(out) == ["alarm_returned"]
    assert out[0]["state"] == "returned_unacknowledged" and out[0]["priority"] == 0
    ok, _, events = lc.acknowledge(5300.0, by="test")
    assert ok and kinds(events) == ["alarm_acknowledged"] and lc.state == "normal"
    # a new fault after the return is a new alarm
    out = lc.step(6000.0, 0.3, FAULT)
    assert kinds(out) == ["alarm_raised"] and out[0]["alarm_id"] == 2


def test_the_level_back_before_the_detector_clears_still_waits_for_the_delay():
    lc = AlarmLifecycle(settings(return_delay_s=600.0))
    lc.step(0.0, 0.0, {"kind": "other_fault"})
    assert every_10_s(lc, 10.0, 2000.0, 0.0) == []  # low all along, detector still faulty
    assert lc.step(2000.0, 0.0, CLEARED) == []
    assert every_10_s(lc, 2010.0, 2600.0, 0.0) == []
    assert kinds(lc.step(2600.0, 0.0)) == ["alarm_returned"]


def test_acknowledge_states():
    lc = AlarmLifecycle(settings(return_delay_s=10.0))
    ok, reason, events = lc.acknowledge(0.0)
    assert not ok and "nothing to acknowledge" in reason and events == []
    lc.step(1.0, 0.3, FAULT)
    ok, _, events = lc.acknowledge(2.0, by="socket")
    assert ok and events[0]["state"] == "acknowledged" and events[0]["by"] == "socket"
    assert not lc.acknowledge(3.0)[0]
    lc.step(4.0, 0.0, CLEARED)
    out = lc.step(20.0, 0.0)
    assert kinds(out) == ["alarm_returned"] and out[0]["state"] == "normal"


def test_shelving_expires_and_is_bounded():
    lc = AlarmLifecycle(settings(max_shelve_s=3600.0))
    lc.step(0.0, 0.3, FAULT)
    assert lc.summary(0.0)["annunciated"]
    assert not lc.shelve(1.0, 7200.0)[0] and not lc.shelve(1.0, 0.0)[0]
    ok, _, events = lc.shelve(1.0, 600.0, by="modbus")
    assert ok and events[0]["until"] == 601.0 and events[0]["shelved"]
    summary = lc.summary(300.0)
    assert not summary["annunciated"] and summary["state_code"] == 4
    assert lc.step(600.0, 0.3) == []
    out = lc.step(601.0, 0.3)
    assert kinds(out) == ["alarm_unshelved"] and out[0]["reason"] == "expired"
    assert lc.summary(601.0)["annunciated"]
    lc.shelve(700.0, 60.0)
    ok, _, events = lc.unshelve(710.0)
    assert ok and events[0]["reason"] == "request" and not lc.unshelve(711.0)[0]


def scripted_inputs(seed=3, n=4000):
    """Seconds of levels with faults, clears and a dither, as (time, level, event)."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.5, 30.0, n))
    level = np.clip(
        np.linspace(0.0, 1.4, n) * (t < t[n // 2]) + 0.05 * rng.standard_normal(n), 0, None
    )
    level[rng.random(n) < 0.1] = np.nan
    choices = [None] * 300 + [FAULT, FRICTION, CLEARED, {"kind": "calibrated"}]
    events = [choices[k] for k in rng.integers(0, len(choices), n)]
    return [(float(a), float(b), c) for a, b, c in zip(t, level, events)]


@pytest.fixture(params=[0.0, 60.0], ids=["raw", "smoothed"])
def smoothing(request):
    return request.param


def test_batch_equals_step_and_chunks_with_the_same_final_state(smoothing):
    inputs = scripted_inputs()
    cfg = settings(
        raise_delay_s=30.0, lower_delay_s=300.0, return_delay_s=300.0, smoothing_s=smoothing
    )
    one = AlarmLifecycle(cfg)
    stepped = [e for args in inputs for e in one.step(*args)]
    whole = AlarmLifecycle(cfg)
    batched = whole.run(inputs)
    chunked_lc = AlarmLifecycle(cfg)
    chunked = []
    cuts = [0, 7, 100, 1500, 1501, 3999, len(inputs)]
    for a, b in zip(cuts[:-1], cuts[1:]):
        chunked.extend(chunked_lc.run(inputs[a:b]))
    assert stepped == batched == chunked
    assert one.to_dict() == whole.to_dict() == chunked_lc.to_dict()
    assert {"alarm_raised", "alarm_priority", "alarm_returned"} <= set(kinds(stepped))


def test_state_round_trips_through_json_mid_alarm(smoothing):
    inputs = scripted_inputs(seed=5)
    cfg = settings(raise_delay_s=30.0, return_delay_s=900.0, smoothing_s=smoothing)
    straight = AlarmLifecycle(cfg)
    expected = straight.run(inputs)
    resumed = AlarmLifecycle(cfg)
    out = []
    for a, b in ((0, 1000), (1000, 2500), (2500, len(inputs))):
        out.extend(resumed.run(inputs[a:b]))
        resumed = AlarmLifecycle.from_dict(json.loads(json.dumps(resumed.to_dict())))
    assert out == expected and resumed.to_dict() == straight.to_dict()


def test_a_restored_alarm_absorbs_the_detectors_renewed_fault():
    lc = AlarmLifecycle(settings(return_delay_s=600.0))
    lc.step(0.0, 0.6, FAULT)
    lc.step(10.0, 0.6, FRICTION)
    restored = AlarmLifecycle.from_dict(json.loads(json.dumps(lc.to_dict())), now=50.0)
    assert restored.active and restored.summary(50.0)["alarm_id"] == 1
    assert restored.step(60.0, 0.6, FAULT) == []  # the new detector run raises again: joined
    # without a new fault the level decides: low for the return delay after the restore
    quiet = AlarmLifecycle.from_dict(lc.to_dict(), now=50.0)
    assert quiet.step(100.0, 0.6) == [] and every_10_s(quiet, 700.0, 1300.0, 0.0) == []
    assert kinds(quiet.step(1300.0, 0.0))[-1] == "alarm_returned"


@pytest.mark.parametrize(
    "data",
    [
        None,
        {},
        {"version": 99},
        {"version": 1},
        {"version": 1, "settings": {}, "state": {"state": "x"}},
        {"version": 1, "settings": {}, "state": {"bogus": 1}},
    ],
)
def test_a_malformed_state_is_refused(data):
    with pytest.raises(ValueError):
        AlarmLifecycle.from_dict(data)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"steps": ()},
        {"steps": (0.5, 0.25)},
        {"steps": (-1.0,)},
        {"deadband": 0.3},
        {"return_delay_s": -1.0},
        {"return_level": 0.0},
        {"return_level": 0.22},
        {"raise_delay_s": float("nan")},
    ],
)
def test_bad_settings_are_refused(kwargs):
    with pytest.raises(ValueError):
        AlarmSettings(**kwargs)
