"""Pipeline: eqs. (1), (3), (15)–(17) per tick and batch, against independent references."""

import numpy as np
import pytest
from conftest_detect import msd_system
from scipy.signal import lfilter

from fdi_daemon.core.velocity import VelocityEstimator
from fdi_daemon.core.window_ls import solve_sums
from fdi_daemon.detect.pipeline import Pipeline
from fdi_daemon.errors import ConfigError

N = 128


@pytest.fixture(scope="module")
def system():
    return msd_system(fault_time_s=3.0, duration_s=6.0)


def test_batch_matches_references(system):
    model, rec = system
    pl = Pipeline(model, N)
    out = pl.run(rec.v_in, rec.accel)
    xhat = lfilter(model.plant_b, model.plant_a, rec.v_in)
    v = VelocityEstimator.from_settings(model.velocity, model.fs).run(rec.accel)
    ff = model.fault_filter
    np.testing.assert_allclose(out.xhat, xhat, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(out.residual, rec.accel - xhat, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(out.velocity, v, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(out.g1, lfilter(ff.b, ff.f, np.sign(v)), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(out.g2, lfilter(ff.b, ff.f, v), rtol=1e-12, atol=1e-14)
    sol = solve_sums(out.sums, out.counts, N, 1e-6, (0.0, 0.0))
    for k in (N - 1, 700, 1000, 1535):
        sl = slice(k - N + 1, k + 1)
        ref = np.linalg.lstsq(
            np.column_stack([out.g1[sl], out.g2[sl]]), out.residual[sl], rcond=None
        )[0]
        np.testing.assert_allclose([sol.theta1[k], sol.theta2[k]], ref, rtol=1e-8)


def test_friction_fault_gives_the_signature(system):
    """Exact Ĝ and G_e, lead-compensated velocity: θ -> (1, γ_f) once the window is faulty."""
    model, rec = system
    pl = Pipeline(model, N)
    out = pl.run(rec.v_in, rec.accel)
    sol = solve_sums(out.sums, out.counts, N, 1e-6, (0.0, 0.0))
    before = int(2.9 * 256)
    after = slice(int(4.0 * 256), None)
    assert abs(sol.theta1[before]) < 0.05 and abs(sol.theta2[before]) < 0.2
    np.testing.assert_allclose(np.median(sol.theta1[after]), 1.0, rtol=0.1)
    np.testing.assert_allclose(np.median(sol.theta2[after]), model.fault_filter.gamma_f, rtol=0.1)


def _observer_model(model):
    import copy

    observed = copy.deepcopy(model)
    observed.velocity = {"method": "model_observer"}
    return observed


def test_the_model_observer_runs_on_the_plant_models_prediction(system):
    """velocity.method model_observer: v̂ = L·x̂̈ + V·r with x̂̈ the pipeline's own Ĝ v_in."""
    from fdi_daemon.core.velocity_observer import ModelVelocityObserver

    model, rec = system
    out = Pipeline(_observer_model(model), N).run(rec.v_in, rec.accel)
    xhat = lfilter(model.plant_b, model.plant_a, rec.v_in)
    v = ModelVelocityObserver(model.fs).run(rec.accel, xhat)
    np.testing.assert_allclose(out.velocity, v, rtol=1e-10, atol=1e-14)


@pytest.mark.parametrize("observer", [False, True], ids=["highpass", "model_observer"])
def test_step_run_and_chunks_agree(system, observer):
    model, rec = system
    if observer:
        model = _observer_model(model)
    v_in, accel = rec.v_in, rec.accel
    whole = Pipeline(model, N)
    ref = whole.run(v_in, accel)
    ref_theta = solve_sums(ref.sums, ref.counts, N, 1e-6, (0.0, 0.0))
    one = Pipeline(model, N)
    got = []
    for v, a in zip(v_in.tolist(), accel.tolist()):
        one.step(v, a)
        got.append((one.xhat, one.residual, one.v, one.g1, one.g2, one.wls.theta1, one.wls.theta2))
    got = np.array(got)
    for col, name in enumerate(("xhat", "residual", "velocity", "g1", "g2")):
        np.testing.assert_allclose(got[:, col], getattr(ref, name), rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(got[:, 5], ref_theta.theta1, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(got[:, 6], ref_theta.theta2, rtol=1e-9, atol=1e-12)
    rng = np.random.default_rng(0)
    cuts = np.sort(rng.choice(np.arange(1, v_in.size), 30, replace=False))
    chunked = Pipeline(model, N)
    parts = [chunked.run(v_in[idx], accel[idx]) for idx in np.split(np.arange(v_in.size), cuts)]
    np.testing.assert_allclose(
        np.concatenate([p.g1 for p in parts]), ref.g1, rtol=1e-12, atol=1e-13
    )
    np.testing.assert_array_equal(np.concatenate([p.sums for p in parts]), ref.sums)


def test_bad_accel_is_replaced_by_the_prediction(system):
    model, rec = system
    bad = np.zeros(rec.t.size, dtype=bool)
    bad[[100, 101, 500]] = True
    pl = Pipeline(model, N)
    out = pl.run(rec.v_in, np.where(bad, np.nan, rec.accel), bad_accel=bad)
    assert np.all(np.isfinite(out.residual)) and np.all(out.residual[bad] == 0.0)
    one = Pipeline(model, N)
    for k, (v, a) in enumerate(zip(rec.v_in.tolist(), rec.accel.tolist())):
        one.step(v, None if bad[k] else a)
    assert one.residual == pytest.approx(out.residual[-1], rel=1e-12, abs=1e-13)


def test_model_without_signature_is_refused(system):
    model, _ = system
    import copy

    broken = copy.deepcopy(model)
    broken.fault_filter = None
    with pytest.raises(ConfigError, match="fault_filter"):
        Pipeline(broken, N)
    broken = copy.deepcopy(model)
    broken.velocity = {"highpass_hz": -1}
    with pytest.raises(ConfigError, match="velocity"):
        Pipeline(broken, N)


def test_the_position_observer_runs_on_the_position_column_step_and_batch():
    """velocity.method position_observer: v̂ from the recording's position and ẍ; per tick
    (Sample.position) and batch agree, and a missing position holds the last one."""
    import copy
    import math

    from conftest_detect import scenario_recording, sim_rig_model

    from fdi_daemon.core.velocity_position import PositionVelocityObserver

    model = copy.deepcopy(sim_rig_model())
    model.velocity = {"method": "position_observer", "crossover_hz": 15.0}
    rec = scenario_recording("test_case_2")
    position = np.asarray(rec["position"], dtype=float).copy()
    position[700:705] = np.nan
    whole = Pipeline(model, N)
    out = whole.run(rec.v_in, rec.accel, position=position)
    ref = PositionVelocityObserver(model.fs, crossover_hz=15.0).run(rec.accel, position)
    np.testing.assert_allclose(out.velocity, ref, rtol=1e-12, atol=1e-15)
    one = Pipeline(model, N)
    got = []
    for v, a, x in zip(rec.v_in.tolist(), rec.accel.tolist(), position.tolist()):
        one.step(v, a, x)
        got.append(one.v)
    np.testing.assert_allclose(got, out.velocity, rtol=1e-12, atol=1e-15)
    assert math.isfinite(one.theta1) and one.theta1 == pytest.approx(whole.theta1, rel=1e-9)


def test_a_position_model_needs_a_position_column(tmp_path, capsys):
    import copy

    from conftest_detect import scenario_recording, sim_rig_model

    from fdi_daemon.cli import main
    from fdi_daemon.io.model_file import save_model
    from fdi_daemon.io.recordings import Recording, write_recording

    model = copy.deepcopy(sim_rig_model())
    model.velocity = {"method": "position_observer"}
    path = save_model(tmp_path / "m.yaml", model)
    rec = scenario_recording("test_case_2")
    cols = {k: rec[k] for k in ("t", "v_in", "accel", "seq")}
    no_position = write_recording(tmp_path / "r.csv", Recording(cols, dict(rec.meta)))
    assert main(["replay", str(no_position), "--model", str(path)]) == 2
    assert "has no position column" in capsys.readouterr().err


def test_a_missing_position_is_a_bad_sample_in_step_and_batch():
    """A position model on a link that drops the position: one bad_sample event per run
    (reason named), the same events per tick and in batch."""
    import copy

    from conftest_detect import scenario_recording, sim_rig_model

    from fdi_daemon.detect.monitor import Monitor
    from fdi_daemon.io.recordings import Recording
    from fdi_daemon.io.sample import Sample

    model = copy.deepcopy(sim_rig_model())
    model.velocity = {"method": "position_observer"}
    rec = scenario_recording("test_case_2")
    cols = dict(rec.columns)
    cols["position"] = np.asarray(cols["position"], dtype=float).copy()
    cols["position"][600:610] = np.nan
    events, _ = Monitor(model).run(Recording(cols, dict(rec.meta)))
    bad = [e for e in events if e["kind"] == "bad_sample"]
    assert len(bad) == 1 and bad[0]["count"] == 10 and bad[0]["reason"] == "position not finite"
    one = Monitor(model)
    stepped = []
    for k in range(len(rec)):
        stepped.extend(
            one.step(
                Sample(
                    int(cols["seq"][k]),
                    float(cols["t"][k]),
                    float(cols["v_in"][k]),
                    float(cols["accel"][k]),
                    float(cols["position"][k]),
                )
            )
        )
    stepped.extend(one.finish())
    assert [(e["kind"], e["t"]) for e in stepped] == [(e["kind"], e["t"]) for e in events]


def _flat_tops(accel, run):
    """(first, last) sample of every run of ``run`` or more equal, non-zero samples."""
    edges = np.flatnonzero(np.diff(accel) != 0) + 1
    starts = np.concatenate([[0], edges])
    ends = np.concatenate([edges, [accel.size]]) - 1
    keep = (ends - starts + 1 >= run) & (accel[starts] != 0)
    return list(zip(starts[keep], ends[keep]))


def _clipped_reference(accel, run, window):
    """Independent of the kernel: a flat top at the value of the previous one of its sign,
    which ended at most ``window`` samples before it reached ``run`` samples, clips from that
    sample to its last; a sample is clipped while the last clipped sample is less than
    ``window`` old."""
    last_clip = np.full(accel.size, -np.inf)
    previous = {}
    for first, last in _flat_tops(accel, run):
        found = first + run - 1
        before = previous.get(accel[first] > 0)
        if before is not None and accel[first] == accel[before] and found - before <= window:
            last_clip[found : last + 1] = np.arange(found, last + 1)
        previous[accel[first] > 0] = last
    return np.arange(accel.size) - np.maximum.accumulate(last_clip) < window


def test_a_recurring_flat_top_is_the_accelerometers_rail_not_a_quantised_peak(system):
    """A slow ADC-quantised sine with noise has flat tops at scattered values, and at one
    value only a cycle (longer than the window) apart: no clipping. A faster one clipped at
    ±c sits at two rails: clipping from the second flat top of a sign on. Per tick as the
    reference above."""
    from fdi_daemon.detect.kernel import CLIP_RUN

    model, _ = system
    rng = np.random.default_rng(11)
    t = np.arange(20 * 256) / 256.0
    lsb = 2**-8
    wave = 3.0 * np.sin(2 * np.pi * 0.7 * t) + 0.0005 * rng.standard_normal(t.size)
    quantised = np.round(wave / lsb) * lsb
    assert len(_flat_tops(quantised, CLIP_RUN)) >= 5  # the test has something to refuse
    fast = 3.0 * np.sin(2 * np.pi * 3.0 * t) + 0.0005 * rng.standard_normal(t.size)
    clipped = np.round(np.clip(fast, -2.5, 2.5) / lsb) * lsb
    clipped[: 5 * 256] = quantised[: 5 * 256]  # clipping from 5 s on
    for accel, expect_any in ((quantised, False), (clipped, True)):
        pl = Pipeline(model, N)
        flags = []
        for v, a in zip(np.sin(t), accel):
            pl.step(v, a)
            flags.append(pl.clipped)
        reference = _clipped_reference(accel, CLIP_RUN, N)
        np.testing.assert_array_equal(flags, reference)
        assert reference.any() == expect_any
    assert not reference[: 5 * 256].any() and reference[6 * 256 :].mean() > 0.9
