"""Monitor: per-tick step and batch run agree; bad samples, gaps, snapshot, events."""

import json
import math

import numpy as np
import pytest
from conftest_detect import first_event, model_copy, scenario_recording, sim_rig_model

from fdi_daemon.detect.detector import STATES
from fdi_daemon.detect.monitor import Monitor
from fdi_daemon.errors import ConfigError
from fdi_daemon.io.recordings import Recording
from fdi_daemon.io.sample import Sample


def _samples(rec):
    seq = rec.columns.get("seq", np.arange(len(rec)))
    return [
        Sample(int(s), float(t), float(v), float(a))
        for s, t, v, a in zip(seq, rec.t, rec.v_in, rec.accel)
    ]


def _stepped(monitor, rec, thetas=None):
    """Events, statistic and state codes per tick; θ as reported appended to ``thetas``."""
    events, stat, state = [], [], []
    for sample in _samples(rec):
        events.extend(monitor.step(sample))
        stat.append(monitor.detector.statistic)
        state.append(STATES.index(monitor.detector.state))
        if thetas is not None:
            thetas.append((monitor.detector.theta1, monitor.detector.theta2))
    events.extend(monitor.finish())
    return events, np.array(stat), np.array(state)


@pytest.mark.slow
@pytest.mark.parametrize(
    "scenario,method",
    [("test_case_2", "sequential"), ("fault_valve_gain", "sequential"), ("test_case_1", "band")],
)
def test_step_and_batch_give_the_same_events_and_statistic(scenario, method):
    rec = scenario_recording(scenario)
    model = model_copy(detector={"method": method})
    thetas = []
    ev_step, stat_step, state_step = _stepped(Monitor(model), rec, thetas)
    ev_batch, trace = Monitor(model).run(rec)
    assert ev_batch == ev_step
    assert any(e["kind"] == "fault_detected" for e in ev_batch)
    np.testing.assert_array_equal(trace.statistic, stat_step)
    np.testing.assert_array_equal(trace.state, state_step)
    np.testing.assert_array_equal(np.column_stack([trace.theta1, trace.theta2]), thetas)
    # batch in pieces (continuing from the same state) gives the same again
    mon = Monitor(model)
    n = len(rec)
    pieces = []
    for a, b in ((0, 700), (700, 701), (701, 1300), (1300, n)):
        part = Recording({k: v[a:b] for k, v in rec.columns.items()}, dict(rec.meta))
        pieces.extend(mon.run(part)[0])
    pieces.extend(mon.finish())
    assert pieces == ev_batch


def test_during_an_episode_theta_is_fitted_on_the_data_since_the_change():
    """From the isolation window on, θ of eq. (17) is the least-squares fit on the samples
    since the reference window ended (the lag before the detection), a direct solve; once
    another isolation window has passed, on the samples from one isolation window after the
    detection on (the onset transient left out)."""
    from fdi_daemon.detect.pipeline import Pipeline

    rec = scenario_recording("test_case_2")
    model = sim_rig_model()
    monitor = Monitor(model)
    _, trace = monitor.run(rec)
    det = monitor.detector
    chain = Pipeline(model, det.window_samples).run(rec.v_in, rec.accel)
    k_d = int(np.flatnonzero(trace.state == STATES.index("fault_detected"))[0])

    def direct(first, k):
        g = np.column_stack([chain.g1[first : k + 1], chain.g2[first : k + 1]])
        return np.linalg.lstsq(g, chain.residual[first : k + 1], rcond=None)[0]

    post = k_d - det.lag_samples + 1  # the newest lag rows at the detection start the fit
    settled = k_d + det.iso_samples + 1
    for first, k in (
        (post, post + det.iso_samples - 1),
        (post, k_d + 100),
        (post, settled + det.iso_samples - 2),
        (settled, settled + det.iso_samples - 1),
        (settled, settled + det.window_samples - 1),
    ):
        np.testing.assert_allclose([trace.theta1[k], trace.theta2[k]], direct(first, k), rtol=1e-7)
    # before the isolation window is full: the sliding window's θ
    k = post + det.iso_samples - 2
    np.testing.assert_allclose(
        [trace.theta1[k], trace.theta2[k]], direct(k - det.window_samples + 1, k), rtol=1e-7
    )
    # a window later, the settled window is the sliding window
    k = settled + det.window_samples + 10
    np.testing.assert_allclose(
        [trace.theta1[k], trace.theta2[k]], direct(k - det.window_samples + 1, k), rtol=1e-7
    )


def test_bad_samples_and_gaps():
    rec = scenario_recording("test_case_2")
    cols = {k: v.copy() for k, v in rec.columns.items()}
    cols["accel"][[300, 301, 302]] = np.nan
    cols["v_in"][400] = np.inf
    keep = np.ones(len(rec), dtype=bool)
    keep[100:110] = False  # a gap of 10 samples (the windows refill before the fault)
    cols = {k: v[keep] for k, v in cols.items()}
    gappy = Recording(cols, dict(rec.meta))
    model = sim_rig_model()
    events, _ = Monitor(model).run(gappy)
    ev_step, _, _ = _stepped(Monitor(model), gappy)
    assert events == ev_step
    bad = [e for e in events if e["kind"] == "bad_sample"]
    assert [(e["count"], e["reason"]) for e in bad] == [
        (3, "accel not finite"),
        (1, "v_in not finite"),
    ]
    assert bad[0]["t"] == pytest.approx(rec.t[300])
    gaps = [e for e in events if e["kind"] == "data_gap"]
    assert len(gaps) == 1 and gaps[0]["missing_samples"] == 10
    assert gaps[0]["t"] == pytest.approx(rec.t[110])
    # the fault at 2.9 s is still detected after the restart
    assert first_event(events, "fault_detected") is not None


@pytest.mark.parametrize("with_seq", [False, True])
def test_long_recordings_give_the_events_of_step_across_chunks(with_seq):
    """Three chunks of `Monitor.run`: clean ones take the one-pass fast path, the middle
    one (a NaN, a gap of 10 samples) the general path; the same events and statistic as
    step by step, and the numbering goes on across the chunks (no spurious gap)."""
    rec = scenario_recording("fault_free_hour", duration_s=180.0)
    cols = {k: v.copy() for k, v in rec.columns.items()}
    cols["seq"] = np.arange(len(rec))
    cols["accel"][20_000] = np.nan
    keep = np.ones(len(rec), dtype=bool)
    keep[25_000:25_010] = False
    numbered = Recording({k: v[keep] for k, v in cols.items()}, dict(rec.meta))
    assert len(numbered) > 2 * 16384
    rec = (
        numbered
        if with_seq
        # without seq the time column tells the gap
        else Recording({k: v for k, v in numbered.columns.items() if k != "seq"}, rec.meta)
    )
    model = sim_rig_model()
    events, trace = Monitor(model).run(rec)
    ev_step, stat_step, _ = _stepped(Monitor(model), numbered)
    assert events == ev_step
    np.testing.assert_array_equal(trace.statistic, stat_step)
    kinds = [e["kind"] for e in events]
    assert kinds.count("data_gap") == 1 and kinds.count("bad_sample") == 1


@pytest.mark.parametrize(
    "defect", ["t", "v_in", "accel", "limit", "gap", "duplicate", "seq_jump", "position"]
)
def test_a_chunk_with_any_defect_is_not_clean(defect):
    from fdi_daemon.detect.monitor import _NO_SEQ, _clean_chunk

    n = 50
    t = np.arange(n) / 256.0
    v_in, accel, position = np.zeros(n), np.ones(n), np.zeros(n)
    seq = np.arange(n, dtype=np.int64) if defect == "seq_jump" else _NO_SEQ
    args = dict(needs_position=defect == "position", limit=10.0)
    assert _clean_chunk(
        t, v_in, accel, position, args["needs_position"], 0, n, args["limit"], 256.0, seq, False
    )
    if defect in ("t", "v_in", "accel", "position"):
        {"t": t, "v_in": v_in, "accel": accel, "position": position}[defect][30] = np.nan
    elif defect == "limit":
        accel[30] = -10.0  # at the limit: saturated
    elif defect == "gap":
        t[30:] += 0.6 / 256.0  # a step of 1.6 periods
    elif defect == "duplicate":
        t[30] = t[29]
    else:
        seq[30:] += 1
    assert not _clean_chunk(
        t, v_in, accel, position, args["needs_position"], 0, n, args["limit"], 256.0, seq, False
    )


def test_duplicates_and_backwards_samples_are_dropped():
    model = sim_rig_model()
    mon = Monitor(model)
    rec = scenario_recording("test_case_2")
    samples = _samples(rec)[:50]
    events = []
    for s in samples[:20] + [samples[19], samples[10]] + samples[20:]:
        events.extend(mon.step(s))
    events.extend(mon.finish())
    bad = [e for e in events if e["kind"] == "bad_sample"]
    assert [(e["count"], e["reason"]) for e in bad] == [(2, "duplicate")]
    assert mon._samples == 50


def test_saturated_accel_with_a_configured_limit():
    model = model_copy(detector={"accel_limit_mps2": 50.0})
    rec = scenario_recording("test_case_2")
    cols = {k: v.copy() for k, v in rec.columns.items()}
    cols["accel"][[200, 201, 700]] = [50.0, -50.0, 51.0]  # at or beyond full scale
    events, _ = Monitor(model).run(Recording(cols, dict(rec.meta)))
    bad = [(e["count"], e["reason"]) for e in events if e["kind"] == "bad_sample"]
    assert bad == [(2, "accel saturated"), (1, "accel saturated")]


def test_snapshot_schema():
    model = sim_rig_model()
    mon = Monitor(model)
    assert mon.snapshot()["state"] == "starting"
    rec = scenario_recording("test_case_2")
    mon.run(rec)
    snap = mon.snapshot()
    assert set(snap) == {
        "state",
        "theta1",
        "theta2",
        "friction_level",
        "friction_level_spread",
        "baseline_level",
        "band",
        "signature",
        "residual_rms",
        "statistic",
        "threshold",
        "history",
    }
    assert snap["state"] in STATES
    assert snap["signature"] == [1.0, model.fault_filter.gamma_f]
    assert set(snap["band"]) == {"theta1", "theta2"}
    hist = snap["history"]
    assert 0 < len(hist["t"]) <= 300 and len(hist["t"]) == len(hist["theta1"])
    assert hist["t"][-1] - hist["t"][0] <= 30.0
    json.dumps(snap, allow_nan=False)  # strict JSON
    # the per-tick path keeps the same history
    mon2 = Monitor(model)
    for s in _samples(rec):
        mon2.step(s)
    assert mon2.snapshot()["history"] == hist


def test_events_are_strict_json():
    events, _ = Monitor(sim_rig_model()).run(scenario_recording("test_case_2"))
    for e in events:
        line = json.dumps(e, allow_nan=False)
        assert {"t", "kind", "theta1", "theta2"} <= set(json.loads(line))


def test_settings_of_another_tool_are_ignored_with_a_warning(caplog):
    """A model file shared with another tool may carry its settings (DESIGN.md: more keys
    welcome): they are ignored with a warning naming them, and the monitor runs as without
    them; a typo of a known key is still refused."""
    rec = scenario_recording("test_case_2")
    plain, _ = Monitor(sim_rig_model()).run(rec)
    shared = model_copy(
        detector={"cusum_drift": 0.5, "threshold": 30.0},
        velocity={**sim_rig_model().velocity, "estimator": "kalman"},
    )
    with caplog.at_level("WARNING", logger="fdi.model"):
        events, _ = Monitor(shared).run(rec)
    assert events == plain
    assert "'cusum_drift'" in caplog.text and "'estimator'" in caplog.text
    with pytest.raises(ConfigError, match="did you mean 'highpass_hz'"):
        Monitor(model_copy(velocity={"highpas_hz": 1.0}))


def test_bad_settings_and_unstable_filters_are_refused():
    with pytest.raises(ConfigError, match="unknown setting"):
        Monitor(model_copy(detector={"treshold": 3}))
    with pytest.raises(ConfigError, match="method"):
        Monitor(model_copy(detector={"method": "magic"}))
    with pytest.raises(ConfigError, match="whole number"):
        Monitor(model_copy(detector={"persistence_samples": 0}))
    model = model_copy()
    model.fault_filter.f = np.array([1.0, -2.0, 1.0])  # double pole at z = 1
    with pytest.raises(ConfigError, match="not stable"):
        Monitor(model)


def test_quiet_on_a_fault_free_recording():
    rec = scenario_recording("ident_chirp_long")
    events, trace = Monitor(sim_rig_model()).run(rec)
    assert [e["kind"] for e in events] == ["calibrated"]
    assert math.isfinite(float(np.nanmax(trace.statistic)))


def test_rig_at_rest_then_moving_raises_no_alarm():
    from hil_sim.scenarios import scenario_from_dict, simulate

    rec = simulate(
        scenario_from_dict(
            {
                "name": "rest_then_sine",
                "duration_s": 20.0,
                "excitation": [
                    {"kind": "zero", "duration_s": 8.0},
                    {"kind": "sine", "amplitude_v": 1.4, "frequency_hz": 8.0, "duration_s": 6.0},
                    {"kind": "zero"},
                ],
            }
        ),
        seed=3,
    )
    events, trace = Monitor(sim_rig_model()).run(rec)
    assert [e["kind"] for e in events] == ["calibrated"]
    at_rest = trace.t < 8.0
    assert np.isnan(trace.theta1[at_rest]).mean() > 0.5  # invalid windows, no estimate


def _pieces_run(model, rec, cuts, trace_every):
    """`Monitor.run` over ``rec`` cut at ``cuts`` (final=False but for the last piece)."""
    mon = Monitor(model)
    events, traces = [], []
    bounds = [0, *cuts, len(rec)]
    for a, b in zip(bounds[:-1], bounds[1:]):
        part = Recording({k: v[a:b] for k, v in rec.columns.items()}, dict(rec.meta))
        ev, tr = mon.run(part, trace_every=trace_every, final=b == len(rec))
        events.extend(ev)
        traces.append(tr)
    return mon, events, traces


@pytest.mark.parametrize("with_seq", [True, False])
def test_a_recording_in_pieces_gives_the_events_trace_and_state_of_one_run(with_seq):
    """The streaming contract of `Monitor.run` (a day-long file read chunk by chunk):
    random cuts, some inside a run of bad samples, beside a gap, a duplicate and samples
    going backwards, give the events, trace rows and final state of one whole run."""
    rec = scenario_recording("fault_free_hour", duration_s=120.0)
    n = len(rec)
    cols = {k: np.array(v, dtype=float) for k, v in rec.columns.items()}
    cols["seq"] = np.arange(n)
    cols["accel"][5_000:5_600] = np.nan  # more than 1 s of bad samples: two events
    cols["v_in"][9_000] = np.inf
    order = list(range(n))
    del order[12_000:12_020]  # a gap of 20
    b = order.index(20_000)
    order[b:b] = list(range(19_990, 20_000))  # 10 samples again
    d = order.index(24_000)
    order.insert(d, 23_999)  # a duplicate
    cols = {k: v[order] for k, v in cols.items()}
    if not with_seq:
        del cols["seq"]
    rec = Recording(cols, dict(rec.meta))
    model = sim_rig_model()
    whole = Monitor(model)
    ev_whole, tr_whole = whole.run(rec, trace_every=7)
    kinds = [e["kind"] for e in ev_whole]
    assert kinds.count("data_gap") == 1 and kinds.count("bad_sample") >= 4
    rng = np.random.default_rng(45)
    cuts = sorted({*rng.integers(1, len(rec) - 1, 12).tolist(), 5_100, 5_101, 12_000, 20_005})
    mon, events, traces = _pieces_run(model, rec, cuts, 7)
    assert events == ev_whole
    for name in ("t", "theta1", "theta2", "statistic", "state", "friction_level"):
        np.testing.assert_array_equal(
            np.concatenate([getattr(t, name) for t in traces]), getattr(tr_whole, name)
        )
    np.testing.assert_array_equal(mon.arena.f, whole.arena.f)
    np.testing.assert_array_equal(mon.arena.i, whole.arena.i)
    assert mon.snapshot() == whole.snapshot()
    assert (mon._last_seq, mon._samples) == (whole._last_seq, whole._samples)
