"""Friction physics of the rig: seal stiction before any fault, air-bearing friction faults."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest_sim import FS, run_sine_with_supply, sine

from hil_sim.rig import Rig, RigParams
from hil_sim.rig.params import GRAVITY_M_PER_S2


def _expected_contact_n(p: RigParams, supply_fraction: float) -> float:
    lift_area = p.bearing_mass_kg * GRAVITY_M_PER_S2 / p.bearing_contact_pressure_pa
    return max(
        0.0,
        p.bearing_mass_kg * GRAVITY_M_PER_S2 - supply_fraction * p.bearing_supply_pa * lift_area,
    )


def test_nominal_bearing_supply_has_no_bearing_friction():
    pre, post = run_sine_with_supply(1.4, 1.0)
    for out in (pre, post):
        assert np.all(out["friction_force"] == 0.0)
        assert np.all(out["contact_force"] == 0.0)
        assert np.all(out["fault_active"] == 0.0)
    # a supply slightly reduced but still above the lift-off pressure: still floating
    _, post = run_sine_with_supply(1.4, 0.85)
    assert np.all(post["friction_force"] == 0.0)


@pytest.mark.parametrize("supply", [0.65, 0.3, 0.0])
def test_bearing_friction_follows_coulomb_viscous_law(supply):
    p = RigParams()
    _, post = run_sine_with_supply(1.5, supply, seed=3)
    settled = slice(int(0.3 * FS), None)
    normal = _expected_contact_n(p, supply)
    assert post["contact_force"][settled] == pytest.approx(normal, rel=1e-4)
    v = post["velocity_true"][settled]
    f = post["friction_force"][settled]
    sliding = np.abs(v) > 5 * p.bearing_stribeck_velocity_m_per_s
    expected = normal * (p.bearing_mu_kinetic + p.bearing_viscous_per_n * np.abs(v[sliding]))
    assert np.mean(np.abs(f[sliding])) == pytest.approx(np.mean(expected), rel=0.1)
    assert np.all(post["fault_active"][settled] == 1.0)


def test_test_case_fault_sizes(test_case_recordings):
    small = test_case_recordings["test_case_1"]
    large = test_case_recordings["test_case_2"]
    f1 = np.abs(small["friction_force"][small.t > 3.3])
    f2 = np.abs(large["friction_force"][large.t > 3.2])
    assert 0.3 < f1.mean() < 1.2  # small, high-slip
    assert 2.0 < f2.mean() < 4.5  # abrupt, larger
    assert small["stuck"][small.t > 3.3].mean() < 0.02  # high slip
    assert large["stuck"][large.t > 3.2].mean() < 0.3  # low stick
    assert np.all(small["friction_force"][small.t < 3.05] == 0.0)
    assert np.all(large["friction_force"][large.t < 2.9] == 0.0)


@pytest.mark.parametrize("name, t_fault", [("test_case_1", 3.05), ("test_case_2", 2.9)])
def test_supply_change_reaches_contact_within_tens_of_ms(test_case_recordings, name, t_fault):
    rec = test_case_recordings[name]
    first = rec.t[np.flatnonzero(rec["fault_active"] > 0)[0]]
    assert t_fault <= first < t_fault + 0.06


def test_seal_stiction_before_any_fault_fades_with_amplitude():
    stuck = {}
    for amplitude, freq in ((0.1, 2.0), (0.3, 4.0), (1.4, 8.0)):
        out = Rig(seed=1).run(sine(amplitude, freq, 4.0))
        assert np.all(out["friction_force"] == 0.0)
        stuck[amplitude] = out["stuck"][int(FS) :].mean()
        # the mass rests exactly while stuck
        assert np.all(out["velocity_true"][out["stuck"] > 0] == 0.0)
    assert stuck[0.1] > 0.05
    assert stuck[0.1] > stuck[0.3] >= stuck[1.4]


def test_seal_friction_shows_in_acceleration_peaks():
    """At the test-case input the seal friction flips at each reversal: compared with a
    seal-free rig the acceleration differs around the peaks, by about 2·F_c/m."""
    p = RigParams()
    u = sine(1.4, 8.0, 3.0)
    with_seal = Rig(p, seed=0).run(u)
    no_seal = Rig(dataclasses.replace(p, seal_coulomb_n=1e-9, seal_static_n=1e-9), seed=0).run(u)
    diff = (with_seal["accel_true"] - no_seal["accel_true"])[int(FS) :]
    jump = 2 * p.seal_coulomb_n / p.moving_mass_kg
    assert 0.3 * jump < np.abs(diff).max() < 3 * jump
