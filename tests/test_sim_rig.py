"""The nonlinear rig: streaming contract, determinism, frequency response, stability."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest_sim import FS, h1_response, sine

from hil_sim.rig import FAULTS, Rig, RigOutput, RigParams


def _excitation(seconds: float, seed: int = 5) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * FS)) / FS
    return (
        0.8 * np.sin(2 * np.pi * 3.0 * t)
        + 0.6 * np.sin(2 * np.pi * 0.7 * t)
        + 0.2 * rng.standard_normal(len(t))
    )


def _run_with_fault(rig: Rig, u: np.ndarray, chunks: list[int]) -> dict[str, np.ndarray]:
    """Run `u` in the given chunk sizes, cutting the bearing supply at sample 600."""
    parts = []
    pos = 0
    for size in chunks:
        if pos <= 600 < pos + size:  # split so the fault lands exactly on sample 600
            parts.append(rig.run(u[pos:600]))
            rig.set_bearing_supply(0.3)
            parts.append(rig.run(u[600 : pos + size]))
        else:
            parts.append(rig.run(u[pos : pos + size]))
        pos += size
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def test_step_run_and_random_chunks_are_bit_equal():
    u = _excitation(6.0)
    whole_rig = Rig(seed=11)
    whole = _run_with_fault(whole_rig, u, [len(u)])

    rng = np.random.default_rng(0)
    sizes = []
    while sum(sizes) < len(u):
        sizes.append(int(min(rng.integers(1, 700), len(u) - sum(sizes))))
    chunk_rig = Rig(seed=11)
    chunked = _run_with_fault(chunk_rig, u, sizes)

    step_rig = Rig(seed=11)
    rows = []
    for k, v in enumerate(u):
        if k == 600:
            step_rig.set_bearing_supply(0.3)
        rows.append(step_rig.step(v))
    assert isinstance(rows[0], RigOutput)
    for name, col in whole.items():
        assert np.array_equal(col, chunked[name]), name
        stepped = np.array([getattr(r, name) for r in rows])
        assert np.array_equal(col, stepped), name
    assert np.array_equal(whole_rig.state, chunk_rig.state)
    assert np.array_equal(whole_rig.state, step_rig.state)
    assert whole["friction_force"][700:].std() > 0.1  # the fault really happened


def test_deterministic_per_seed_and_seeds_differ():
    u = _excitation(3.0)
    a = Rig(seed=4).run(u)
    b = Rig(seed=4).run(u)
    c = Rig(seed=5).run(u)
    for name in a:
        assert np.array_equal(a[name], b[name]), name
    assert not np.array_equal(a["accel"], c["accel"])
    assert not np.array_equal(a["position"], c["position"])


def test_sample_timing_and_one_sample_delay():
    step = np.r_[np.zeros(10), np.full(246, 1.0)]
    out = Rig(seed=0).run(step)
    rest = Rig(seed=0).run(np.zeros(256))
    assert np.allclose(np.diff(out["t"]), 1.0 / FS)
    assert np.array_equal(out["seq"], np.arange(256))
    assert out["v_in"][10] == pytest.approx(1.0, abs=2e-3)
    # the sensors are read before the sample's voltage acts (b0 = 0 in eq. (1)): up to and
    # including the step sample everything equals the run at rest, afterwards it moves
    for name in ("accel", "position", "accel_true", "p1"):
        assert np.array_equal(out[name][:11], rest[name][:11]), name
    assert not np.array_equal(out["p1"][11:], rest["p1"][11:])
    assert out["position_true"][-1] > 1e-3


def test_frequency_response_looks_like_paper_fig3(sweep_recording):
    f, G, coh = h1_response(sweep_recording.v_in, sweep_recording.accel)
    mag = np.abs(G)
    low = (f >= 1.0) & (f <= 6.0)
    slope = np.polyfit(np.log10(f[low]), 20 * np.log10(mag[low]), 1)[0]
    assert 14.0 <= slope <= 26.0
    assert coh[low].min() > 0.9
    band = (f > 0.5) & (f < 40)
    f_peak = f[band][np.argmax(mag[band])]
    peak = mag[band].max()
    assert 6.0 <= f_peak <= 14.0
    at = lambda hz: mag[np.argmin(np.abs(f - hz))]  # noqa: E731
    assert at(15.0) < peak
    assert at(20.0) < 0.4 * peak  # rolling off above 10 Hz
    assert mag[(f >= 30) & (f <= 45)].max() < 0.05 * peak  # little motion above 30 Hz
    # differentiator: phase near +90° at 1 Hz minus small lags
    assert 45.0 < np.degrees(np.angle(G[np.argmin(np.abs(f - 1.0))])) < 95.0


def test_acceleration_amplitude_plausible_for_test_case_input():
    out = Rig(seed=0).run(sine(1.4, 8.0, 3.0))
    peak = np.abs(out["accel"][256:]).max()
    assert 1.0 < peak < 10.0


def test_internal_step_is_converged():
    """Halving/quartering the fixed step changes the response by little (accuracy)."""
    u = _excitation(4.0)
    base = Rig(seed=2).run(u)
    fine = Rig(RigParams(substeps=64), seed=2).run(u)
    err = np.std(base["accel_true"] - fine["accel_true"]) / np.std(fine["accel_true"])
    assert err < 0.05
    assert np.max(np.abs(base["position_true"] - fine["position_true"])) < 5e-4


def test_long_multisine_stays_finite_inside_stroke_and_friction_dissipates():
    rig = Rig(seed=9)
    rig.set_centring(30.0)
    t = np.arange(int(300 * FS)) / FS
    u = (
        0.7 * np.sin(2 * np.pi * 0.3 * t)
        + 0.5 * np.sin(2 * np.pi * 2.1 * t)
        + 0.5 * np.sin(2 * np.pi * 7.3 * t)
    )
    out = rig.run(u[: len(u) // 2])
    rig.set_bearing_supply(0.2)  # stick-slip through the second half
    out2 = rig.run(u[len(u) // 2 :])
    p = RigParams()
    for o in (out, out2):
        for name, col in o.items():
            assert np.all(np.isfinite(col)), name
        assert np.abs(o["position_true"]).max() < p.stroke_m / 2
        assert o["p1"].min() > p.atmosphere_pa * 0.99
        assert o["p1"].max() < p.supply_pressure_pa * 1.01
        assert np.abs(o["velocity_true"]).max() < 0.5
        # friction dissipates: F·v >= 0 except in the internal step where v reverses
        for name in ("friction_force", "seal_friction_force"):
            power = o[name] * o["velocity_true"]
            assert power.sum() >= 0.0
            assert np.mean(power < 0.0) < 0.02, name
    assert out2["stuck"].mean() > out["stuck"].mean()
    assert 0.0 < out2["stuck"].mean() < 0.5  # stick-slip, not locked up


def test_end_stop_holds_the_piston():
    p = RigParams()
    out = Rig(seed=0).run(np.full(int(6 * FS), 2.0))  # drives into the end stop
    x = out["position_true"]
    assert np.all(np.isfinite(x))
    assert x.max() > p.stroke_m / 2
    assert x.max() < p.stroke_m / 2 + 0.003  # stiff bumper
    assert np.abs(out["velocity_true"][-256:]).max() < 1e-3  # at rest against the stop
    assert out["position"].max() <= p.lvdt_range_m


def test_setters_validate():
    rig = Rig()
    with pytest.raises(ValueError, match="unknown fault"):
        rig.set_fault("accel_gain", 1.0)
    with pytest.raises(ValueError):
        rig.set_bearing_supply(-0.1)
    with pytest.raises(ValueError):
        rig.set_fault("valve_gain", float("nan"))
    with pytest.raises(ValueError):
        rig.run(np.array([0.0, np.inf]))
    for name, (_, neutral, _) in FAULTS.items():
        rig.set_fault(name, neutral)
    assert not rig.other_fault_active
    with pytest.raises(ValueError, match="bore_m"):
        Rig(dataclasses.replace(RigParams(), rod_diameter_m=0.03))


def test_bench_sim_reports_speed():
    from fdi_daemon.bench.sim import bench_sim

    result = bench_sim(duration_s=5.0)
    assert result["simulated_s"] == 5.0
    assert result["sim_s_per_wall_s"] > 0
    assert result["hour_wall_s"] == pytest.approx(3600 * result["wall_s"] / 5.0)


def test_friction_free_response_is_fitted_by_a_fourth_order_model():
    """Eq. (1) must be able to describe the fault-free rig: a 4th-order output-error model
    (independent scipy least squares) fitted on one chirp run simulates another seed's run
    with >= 90 % fit (100·(1 - ||y - ŷ|| / ||y - mean y||))."""
    from conftest_sim import scenario_path
    from scipy import optimize, signal

    from hil_sim.scenarios import load_scenario, simulate

    scenario = load_scenario(scenario_path("ident_chirp_long"))
    est = simulate(scenario, seed=0)
    val = simulate(scenario, seed=1)

    def sim(theta, u):
        return signal.lfilter(np.r_[0.0, theta[:4]], np.r_[1.0, theta[4:]], u)

    u, y = est.v_in, est.accel
    lagged = np.column_stack(
        [-np.roll(y, k) for k in range(1, 5)] + [np.roll(u, k) for k in range(1, 5)]
    )[8:]
    arx, *_ = np.linalg.lstsq(lagged, y[8:], rcond=None)
    theta = optimize.least_squares(lambda th: sim(th, u) - y, np.r_[arx[4:], arx[:4]]).x
    assert np.all(np.abs(np.roots(np.r_[1.0, theta[4:]])) < 1.0)
    err = val.accel - sim(theta, val.v_in)
    fit = 100 * (1 - np.linalg.norm(err) / np.linalg.norm(val.accel - val.accel.mean()))
    assert fit >= 90.0
