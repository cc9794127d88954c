"""The §V mass-spring-damper simulator (hil_sim.msd)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal, stats

from fdi_daemon.io.recordings import read_recording, write_recording
from hil_sim.msd import MsdParams, MsdSimulator, multisine, nominal_tf, simulate_recording

FS = 256.0


def _reference_accel(p: MsdParams, u: np.ndarray) -> np.ndarray:
    """Exact ZOH solution from scipy, with the continuous model written out here."""
    m, k, c, g = p.mass_kg, p.stiffness_n_per_m, p.damping_n_s_per_m, p.gain_n_per_v
    if p.input_filter_hz is None:
        a = [[0, 1], [-k / m, -c / m]]
        b = [[0], [g / m]]
        cc = [[-k / m, -c / m]]
        d = [[g / m]]
    else:
        w, z = 2 * math.pi * p.input_filter_hz, p.input_filter_damping
        a = [[0, 1, 0, 0], [-w * w, -2 * z * w, 0, 0], [0, 0, 0, 1], [g / m, 0, -k / m, -c / m]]
        b = [[0], [w * w], [0], [0]]
        cc = [[g / m, 0, -k / m, -c / m]]
        d = [[0]]
    sysd = signal.cont2discrete(
        (np.array(a, float), np.array(b, float), np.array(cc, float), np.array(d, float)),
        1 / FS,
        method="zoh",
    )
    _, y, _ = signal.dlsim(sysd[:4] + (1 / FS,), u)
    return y[:, 0]


@pytest.mark.parametrize("filter_hz", [20.0, None])
def test_linear_model_matches_exact_discrete_solution(filter_hz):
    p = MsdParams(input_filter_hz=filter_hz)
    u = multisine(4.0, FS, 0.5, 15.0, 0.5, seed=3)
    out = MsdSimulator(p).run(u)
    ref = _reference_accel(p, u)
    np.testing.assert_allclose(out["accel"], ref, rtol=0, atol=1e-9 * np.max(np.abs(ref)))
    b, a = nominal_tf(p)
    np.testing.assert_allclose(signal.lfilter(b, a, u), ref, atol=1e-9 * np.max(np.abs(ref)))


def test_viscous_fault_is_the_linear_model_with_more_damping():
    p = MsdParams(viscous_n_s_per_m=3.0, fault_time_s=0.0)
    u = multisine(3.0, FS, 0.5, 15.0, 0.5, seed=4)
    ref = _reference_accel(MsdParams(damping_n_s_per_m=p.damping_n_s_per_m + 3.0), u)
    np.testing.assert_allclose(
        MsdSimulator(p).run(u)["accel"], ref, atol=1e-9 * np.max(np.abs(ref))
    )


def test_coulomb_friction_sign_and_size():
    # free mass (no spring, no filter, no damping), constant push
    base = dict(
        stiffness_n_per_m=0.0,
        damping_n_s_per_m=0.0,
        input_filter_hz=None,
        gain_n_per_v=1.0,
        mass_kg=2.0,
        fault_time_s=0.0,
        coulomb_n=1.0,
    )
    out = MsdSimulator(MsdParams(**base)).run(np.full(64, 3.0))  # 3 N > 1 N: slides
    np.testing.assert_allclose(out["accel"][1:], (3.0 - 1.0) / 2.0, rtol=1e-9)
    assert np.all(out["friction_force"][1:] == pytest.approx(1.0))  # opposes +motion
    out = MsdSimulator(MsdParams(**base)).run(np.full(64, -3.0))
    np.testing.assert_allclose(out["accel"][1:], (-3.0 + 1.0) / 2.0, rtol=1e-9)
    assert np.all(out["friction_force"][1:] == pytest.approx(-1.0))
    out = MsdSimulator(MsdParams(**base)).run(np.full(64, 0.6))  # below break-away: sticks
    assert np.all(out["velocity"] == 0.0) and np.all(out["position"] == 0.0)
    np.testing.assert_allclose(out["accel"], 0.0, atol=1e-12)
    np.testing.assert_allclose(out["friction_force"], 0.6, rtol=1e-9)  # holds the push


def test_coulomb_and_viscous_faults_together():
    base = dict(
        stiffness_n_per_m=0.0,
        damping_n_s_per_m=0.0,
        input_filter_hz=None,
        gain_n_per_v=1.0,
        mass_kg=1.0,
        fault_time_s=0.0,
        coulomb_n=1.0,
        viscous_n_s_per_m=2.0,
    )
    out = MsdSimulator(MsdParams(**base)).run(np.full(512, 3.0))
    v = out["velocity"]
    # m v' = F − F_c − c_v v from rest: v = (F − F_c)/c_v (1 − exp(−c_v t/m))
    np.testing.assert_allclose(
        v, (3.0 - 1.0) / 2.0 * (1 - np.exp(-2.0 * out["t"])), rtol=1e-6, atol=1e-9
    )
    np.testing.assert_allclose(out["friction_force"][1:], 1.0 + 2.0 * v[1:], rtol=1e-9)
    np.testing.assert_allclose(
        out["accel"][1:], 3.0 - out["friction_force"][1:], rtol=1e-9, atol=1e-12
    )


def test_fault_switches_on_at_its_time_and_stick_slip_stays_bounded():
    p = MsdParams(fault_time_s=1.0, coulomb_n=3.0)
    u = 0.8 * np.sin(2 * np.pi * 2.0 * np.arange(int(3 * FS)) / FS)
    out = MsdSimulator(p).run(u)
    before = out["t"] < 1.0
    assert np.all(out["friction_force"][before] == 0.0)
    assert np.all(out["fault_active"] == (~before).astype(float))
    ff = out["friction_force"][~before]
    assert np.max(np.abs(ff)) <= 3.0 + 1e-9
    v = out["velocity"][~before]
    stuck = v == 0.0
    assert stuck.any() and (~stuck).any()  # stick-slip: exact stops and slips
    # friction opposes the velocity whenever sliding
    assert np.all(ff[~stuck] * v[~stuck] > 0)
    assert np.max(np.abs(out["accel"])) < 10 * np.max(np.abs(_reference_accel(MsdParams(), u)))


def test_noise_is_uniform_with_the_set_width_and_seeded():
    width = 0.4
    p = MsdParams(accel_noise_width=width, velocity_noise_width=0.01, position_noise_width=1e-3)
    u = np.zeros(20000)
    out = MsdSimulator(p, seed=7).run(u)
    noise = out["accel"]
    assert noise.min() >= -width / 2 and noise.max() <= width / 2
    assert noise.min() < -0.49 * width and noise.max() > 0.49 * width
    assert stats.kstest(noise, stats.uniform(loc=-width / 2, scale=width).cdf).pvalue > 0.01
    assert np.std(out["velocity"]) == pytest.approx(0.01 / math.sqrt(12), rel=0.05)
    assert np.std(out["position"]) == pytest.approx(1e-3 / math.sqrt(12), rel=0.05)
    again = MsdSimulator(p, seed=7).run(u)
    other = MsdSimulator(p, seed=8).run(u)
    assert np.array_equal(again["accel"], noise)
    assert not np.array_equal(other["accel"], noise)


def test_input_effects_equal_the_linear_model_on_the_transformed_input():
    u = multisine(3.0, FS, 0.5, 15.0, 0.5, seed=5)
    lin = lambda x: _reference_accel(MsdParams(), x)  # noqa: E731
    tol = 1e-9 * np.max(np.abs(lin(u)))
    sat = MsdSimulator(MsdParams(effects={"input_saturation": {"level_v": 0.4}})).run(u)
    np.testing.assert_allclose(sat["accel"], lin(np.clip(u, -0.4, 0.4)), atol=tol)
    dz = MsdSimulator(MsdParams(effects={"dead_zone": {"half_width_v": 0.1}})).run(u)
    np.testing.assert_allclose(
        dz["accel"], lin(np.sign(u) * np.maximum(np.abs(u) - 0.1, 0)), atol=tol
    )
    dt = MsdSimulator(MsdParams(effects={"dead_time": {"delay_s": 3 / FS}})).run(u)
    np.testing.assert_allclose(
        dt["accel"], lin(np.concatenate([np.full(3, u[0]), u[:-3]])), atol=tol
    )


def test_output_effects_and_recording_round_trip(tmp_path):
    u = multisine(2.0, FS, 0.5, 15.0, 0.5, seed=6)
    clean = MsdSimulator(MsdParams()).run(u)["accel"]
    p = MsdParams(
        effects={"output_saturation": {"level_m_s2": 3.0}, "sensor_offset": {"offset_m_s2": 0.5}}
    )
    rec = simulate_recording(p, u, seed=1)
    np.testing.assert_allclose(rec.accel, np.clip(clean + 0.5, -3.0, 3.0), atol=1e-9)
    path = write_recording(tmp_path / "msd.csv", rec)
    back = read_recording(path)
    assert back.fs == FS
    for col in ("t", "v_in", "accel", "position", "velocity", "friction_force"):
        np.testing.assert_allclose(back[col], rec[col], rtol=1e-8, atol=1e-12)


def test_unknown_effect_is_refused():
    with pytest.raises(ValueError, match="unknown effect"):
        MsdParams(effects={"magic": {}})
    with pytest.raises(ValueError, match="missing"):
        MsdParams(effects={"backlash": {}})
