"""The compiled tick (`detect.kernel`, `core.kernels`): against the reference objects
(scipy's lfilter, the velocity estimators, `solve_packed`, direct sums), and step, random
chunks and batch bit-equal for every velocity method."""

import copy
import math

import numpy as np
import pytest
from conftest_detect import msd_system, scenario_recording, sim_rig_model
from scipy.signal import butter, lfilter

from fdi_daemon.core.compiled import Arena
from fdi_daemon.core.kernels import solve_packed as solve_packed_kernel
from fdi_daemon.core.kernels import sums_floats, sums_push
from fdi_daemon.core.normal_equations import packed_products, solve_packed
from fdi_daemon.core.velocity_observer import velocity_from_settings
from fdi_daemon.detect.detector import STATES
from fdi_daemon.detect.monitor import Monitor
from fdi_daemon.detect.pipeline import Pipeline
from fdi_daemon.io.recordings import Recording
from fdi_daemon.io.sample import Sample

N = 128
METHODS = {
    "highpass": {"lead_compensation_hz": 8.0},
    "model_observer": {"method": "model_observer"},
    "position_observer": {"method": "position_observer"},
}


def _push_all(rows, window):
    """Window sums after every row, by the kernel's block algorithm."""
    arena = Arena()
    w = rows.shape[1]
    fo, io = arena.alloc(sums_floats(window, w) + w, 2)
    src = fo + sums_floats(window, w)
    out = np.empty_like(rows)
    sl = fo + (window + 2) * w
    for k, row in enumerate(rows):
        arena.f[src : src + w] = row
        sums_push(arena.f, arena.i, fo, window, w, io, src)
        out[k] = arena.f[sl : sl + w]
    return out, int(arena.i[io + 1])


def test_window_sums_equal_direct_sums_and_do_not_drift():
    rng = np.random.default_rng(3)
    rows = rng.normal(size=(5000, 3)) * 1e3 + 1e6  # large offset: drift would show
    window = 37
    got, count = _push_all(rows, window)
    assert count == window
    for k in (0, 5, window - 1, window, 1000, 4999):
        direct = rows[max(0, k - window + 1) : k + 1].sum(axis=0)
        np.testing.assert_allclose(got[k], direct, rtol=1e-12)
    # at the end of every block the sums are the block's own additions: exact
    k = 100 * window - 1
    np.testing.assert_array_equal(got[k], np.cumsum(rows[k - window + 1 : k + 1], axis=0)[-1])


def test_solve_packed_kernel_is_the_float_path_bit_for_bit():
    rng = np.random.default_rng(4)
    for p in (2, 3, 4):
        phi = rng.normal(size=(60, p))
        y = phi @ rng.normal(size=p) + 0.1 * rng.normal(size=60)
        row = packed_products(phi, y).sum(axis=0)
        theta, sse, ok = solve_packed(row.tolist(), p)
        f = np.concatenate([row, np.zeros(2 * p * p + p + p)])
        sse_k, ok_k = solve_packed_kernel(f, 0, p, 1e-9, row.size, row.size + 2 * p * p + p)
        assert f[-p:].tolist() == theta and sse_k == sse and ok_k == ok
    zeros = np.zeros(15 + 2 * 16 + 4 + 4)
    assert not solve_packed_kernel(zeros, 0, 4, 1e-9, 15, 15 + 36)[1]


def _model(method):
    model, rec = msd_system(fault_time_s=3.0, duration_s=6.0)
    model = copy.deepcopy(model)
    model.velocity = dict(METHODS[method])
    return model, rec


def _position(rec):
    """A position consistent with the accelerometer: its double integral (detrended)."""
    v = np.cumsum(rec.accel) / 256.0
    x = np.cumsum(v - v.mean()) / 256.0
    x[300:304] = np.nan  # held by the kernel
    return x


@pytest.mark.parametrize("method", list(METHODS))
def test_chain_matches_the_reference_blocks(method):
    model, rec = _model(method)
    position = _position(rec)
    out = Pipeline(model, N).run(rec.v_in, rec.accel, position=position)
    xhat = lfilter(model.plant_b, model.plant_a, rec.v_in)
    vel = velocity_from_settings(model.velocity, model.fs)
    if method == "model_observer":
        v = vel.run(rec.accel, xhat)
    elif method == "position_observer":
        v = vel.run(rec.accel, position)
    else:
        v = vel.run(rec.accel)
    ff = model.fault_filter
    np.testing.assert_allclose(out.xhat, xhat, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(out.velocity, v, rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(out.g1, lfilter(ff.b, ff.f, np.sign(v)), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(out.g2, lfilter(ff.b, ff.f, v), rtol=1e-12, atol=1e-14)
    k = 1200
    sl = slice(k - N + 1, k + 1)
    g = np.column_stack([out.g1[sl], out.g2[sl]])
    np.testing.assert_allclose(
        out.sums[k],
        [
            g[:, 0] @ g[:, 0],
            g[:, 0] @ g[:, 1],
            g[:, 1] @ g[:, 1],
            g[:, 0] @ out.residual[sl],
            g[:, 1] @ out.residual[sl],
            out.residual[sl] @ out.residual[sl],
        ],
        rtol=1e-9,
    )


def test_the_trusted_flag_matches_a_direct_computation():
    """`trusted` per tick (high-pass velocity: 2 Hz and 8 Hz stretches) against scipy: the
    low-pass at `trusted_from_hz`, window sums by direct addition, share <= 0.3."""
    model = sim_rig_model()
    t = np.arange(int(12 * 256)) / 256.0
    freq = np.where((t // 3) % 2 == 0, 2.0, 8.0)
    accel = np.sin(2 * np.pi * np.cumsum(freq) / 256.0) * (2 * np.pi * freq) ** 2 * 0.002
    pl = Pipeline(model, N)
    got = []
    for a in accel:
        pl.step(0.0, float(a))
        got.append(pl.trusted)
    v = velocity_from_settings(model.velocity, model.fs).run(accel)
    low = lfilter(*butter(2, pl.trusted_from_hz, fs=model.fs), v)
    k = np.arange(N - 1, t.size)
    low2 = np.array([low[i - N + 1 : i + 1] @ low[i - N + 1 : i + 1] for i in k])
    v2 = np.array([v[i - N + 1 : i + 1] @ v[i - N + 1 : i + 1] for i in k])
    share = low2 / v2
    clear = np.abs(share - 0.3) > 1e-6
    np.testing.assert_array_equal(np.array(got)[k][clear], (share <= 0.3)[clear])
    assert 0.2 < np.mean(share <= 0.3) < 0.8


def _rig_model(method):
    model = copy.deepcopy(sim_rig_model())
    if method != "highpass":
        model.velocity = dict(METHODS[method])
    return model


def _stepped(monitor, cols):
    events, trace = [], []
    for k in range(len(cols["t"])):
        events.extend(
            monitor.step(
                Sample(
                    int(cols["seq"][k]),
                    float(cols["t"][k]),
                    float(cols["v_in"][k]),
                    float(cols["accel"][k]),
                    float(cols["position"][k]),
                )
            )
        )
        det = monitor.detector
        trace.append((det.statistic, STATES.index(det.state), det.theta1, det.theta2))
    return events, np.array(trace)


@pytest.mark.parametrize("method", list(METHODS))
def test_step_batch_and_random_chunks_are_bit_equal(method):
    """A fault (test case 2: detection, isolation) replayed per tick, whole and in random
    chunks mixed with per-tick steps: the same events, and bit-equal traces."""
    rec = scenario_recording("test_case_2")
    model = _rig_model(method)
    cols = {k: np.asarray(rec[k]) for k in ("t", "v_in", "accel", "position", "seq")}
    ev_step, tr_step = _stepped(Monitor(model), cols)
    assert any(e["kind"] == "fault_detected" for e in ev_step)
    ev_whole, whole = Monitor(model).run(Recording(cols, dict(rec.meta)))
    assert ev_whole == ev_step
    np.testing.assert_array_equal(whole.statistic, tr_step[:, 0])
    np.testing.assert_array_equal(whole.state, tr_step[:, 1])
    np.testing.assert_array_equal(whole.theta1, tr_step[:, 2])
    np.testing.assert_array_equal(whole.theta2, tr_step[:, 3])
    rng = np.random.default_rng(7)
    cuts = np.sort(rng.choice(np.arange(1, len(rec)), 25, replace=False))
    mixed = Monitor(model)
    events, stat = [], []
    for i, idx in enumerate(np.split(np.arange(len(rec)), cuts)):
        part = {k: v[idx] for k, v in cols.items()}
        if i % 3 == 2:  # some pieces per tick
            ev, tr = _stepped(mixed, part)
            events.extend(ev)
            stat.append(tr[:, 0])
        else:
            ev, trace = mixed.run(Recording(part, dict(rec.meta)))
            events.extend(ev)
            stat.append(trace.statistic)
    assert events == ev_step
    np.testing.assert_array_equal(np.concatenate(stat), tr_step[:, 0])


def test_warm_up_leaves_the_state_alone():
    rec = scenario_recording("test_case_2")
    warm = Monitor(sim_rig_model())
    warm.warm_up()
    assert np.array_equal(warm.arena.f, Monitor(sim_rig_model()).arena.f, equal_nan=True)
    ev_warm, tr_warm = warm.run(rec)
    ev, tr = Monitor(sim_rig_model()).run(rec)
    assert ev_warm == ev
    np.testing.assert_array_equal(tr_warm.statistic, tr.statistic)


def test_a_bad_sample_uses_the_prediction_in_the_kernel():
    model, rec = _model("highpass")
    one = Pipeline(model, N)
    one.step(0.3, None)
    assert one.residual == 0.0 and math.isfinite(one.xhat)


def test_a_full_calibration_buffer_is_not_written_past_when_its_code_is_ignored():
    """`monitor_tick` returns CALIBRATED until `Detector.decide` takes the buffer; a caller
    that ignores the code must not overwrite the state that follows it in the arena."""
    from fdi_daemon.detect import kernel as K

    model, rec = msd_system(duration_s=6.0)
    monitor = Monitor(model)
    det = monitor.detector
    f, ii = monitor.arena.f, monitor.arena.i
    end = det.fo + K.E_CAL + 2 * det.calibration_samples
    after = f[end : det.epo + 64].copy()
    codes = [
        K.monitor_tick(f, ii, det.io, float(u), float(a), math.nan, 0.0)
        for u, a in zip(rec.v_in, rec.accel)
    ]
    assert codes.count(K.CALIBRATED) > 100  # ignored again and again
    assert ii[det.io + K.D_CAL_COUNT] == det.calibration_samples
    np.testing.assert_array_equal(f[end : det.epo + 64], after)
