"""Non-friction faults: each changes the signals as it physically should, nothing else."""

from __future__ import annotations

import numpy as np
import pytest
from conftest_sim import FS, scenario_path

from hil_sim.rig import FAULTS, RigParams
from hil_sim.scenarios import load_scenario, simulate

T_FAULT = 4.0


def _with_and_without(name: str):
    """The fault scenario and the same run (same seed, same noise) without its events."""
    scenario = load_scenario(scenario_path(f"fault_{name}"))
    faulty = simulate(scenario, seed=2)
    scenario.events = []
    clean = simulate(scenario, seed=2)
    before = faulty.t < T_FAULT
    after = faulty.t >= T_FAULT + 0.5
    return faulty, clean, before, after


def test_every_fault_has_a_scenario_and_identical_data_before_it():
    for name in FAULTS:
        faulty, clean, before, after = _with_and_without(name)
        assert faulty.meta["other_fault"] == name
        assert float(faulty.meta["other_fault_t"]) == T_FAULT
        for col in ("accel", "position", "v_in"):
            assert np.array_equal(faulty[col][before], clean[col][before]), (name, col)
        assert np.all(faulty["other_fault_active"][before] == 0.0)
        assert np.all(faulty["other_fault_active"][after] == 1.0)
        assert np.all(faulty["fault_active"] == 0.0)  # never a friction fault
        assert np.all(faulty["friction_force"] == 0.0)


def test_accel_bias_step_shifts_the_reading_only():
    faulty, clean, _, after = _with_and_without("accel_bias")
    lsb = 2 * RigParams().accel_range_m_per_s2 / 2**16
    shift = faulty["accel"][after] - clean["accel"][after]
    assert np.all(np.abs(shift - 0.3) <= lsb)
    assert np.array_equal(faulty["accel_true"], clean["accel_true"])  # the motion is unchanged


def test_valve_gain_loss_scales_the_motion():
    faulty, clean, _, after = _with_and_without("valve_gain")
    ratio = faulty["accel"][after].std() / clean["accel"][after].std()
    assert 0.5 < ratio < 0.7  # gain 0.6 on a flow-controlled actuator below the roll-off


def test_supply_drop_lowers_chamber_pressures_and_changes_the_response():
    faulty, clean, _, after = _with_and_without("supply_pressure")
    assert faulty["p1"][after].mean() < 0.8 * clean["p1"][after].mean()
    diff = faulty["accel"][after] - clean["accel"][after]
    assert diff.std() > 0.1 * clean["accel"][after].std()


def test_accel_dropout_reads_zero():
    faulty, clean, _, after = _with_and_without("accel_dropout")
    assert np.all(faulty["accel"][faulty.t >= T_FAULT] == 0.0)
    assert np.array_equal(faulty["accel_true"], clean["accel_true"])
    assert np.array_equal(faulty["position"], clean["position"])


def test_accel_saturation_clips_at_the_reduced_range():
    faulty, clean, _, after = _with_and_without("accel_saturation")
    limit = 0.06 * RigParams().accel_range_m_per_s2
    lsb = 2 * RigParams().accel_range_m_per_s2 / 2**16
    assert np.abs(faulty["accel"][faulty.t >= T_FAULT]).max() <= limit + lsb
    assert np.abs(clean["accel"][after]).max() > limit + 0.5  # the clean peaks are higher
    clipped = np.abs(faulty["accel"][after]) >= limit - lsb
    assert 0.05 < clipped.mean() < 0.6


@pytest.mark.parametrize("name", sorted(FAULTS))
def test_switching_a_fault_back_to_neutral_restores_the_reading_path(name):
    from hil_sim.rig import Rig

    neutral = FAULTS[name][1]
    rig = Rig(seed=0)
    rig.set_fault(name, 0.5 if name != "accel_dropout" else 1.0)
    assert rig.other_fault_active
    rig.set_fault(name, neutral)
    assert not rig.other_fault_active
    out = rig.run(np.zeros(int(FS)))
    assert np.all(out["other_fault_active"] == 0.0)
