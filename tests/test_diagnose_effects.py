"""Blind tests of the diagnose workflow: each effect hidden in the §V model is named and
closing it at least halves the held-out gap; with nothing hidden, nothing is named.
(The closed-loop stage and the Duffing oscillator: `test_diagnose_machines.py`.)"""

from __future__ import annotations

import numpy as np
import pytest

from fdi_daemon.diagnose.effects import EFFECT_NAMES, FittedEffect, friction_form
from fdi_daemon.diagnose.select import map_share
from hil_sim.msd import MsdParams, simulate_recording
from tests.diagnose_cases import FS, HIDDEN, changed_recording, nominal_model, recording

#: effects the §V simulator cannot hide, with the test that hides them
ELSEWHERE = {
    "gain_fault": "test_a_gain_fault_is_named_with_its_ratio",
    "force_offset": "test_diagnose_machines.py::test_closed_loop_stage",
    "stiffness_change": "test_a_changed_spring_is_named_with_its_ratio",
    "mass_change": "test_a_changed_mass_is_named_with_its_ratio",
}


def test_every_library_effect_has_a_case():
    assert set(HIDDEN) | set(ELSEWHERE) == set(EFFECT_NAMES)


@pytest.mark.parametrize("effect", sorted(HIDDEN))
def test_hidden_effect_is_named_and_gap_halves(effect, diagnosis):
    rec = recording(effect)
    b, a = nominal_model()
    result = diagnosis(rec.v_in, rec.accel, FS, "acceleration", b, a)
    assert result.named, f"nothing named for hidden {effect}"
    assert result.named[0] == effect
    assert result.gap_after <= 0.5 * result.gap_before


@pytest.mark.parametrize(
    "gain, refit_gain, plausible",
    [(1.0, 0.0, True), (1.2, 0.2, True), (0.02, 0.0, False), (-0.0025, 0.0, False)],
)
def test_a_map_is_possible_only_with_its_own_gain(gain, refit_gain, plausible):
    # a sensor that clips maps the output as a saturation maps the input: φ = sat(w) − w
    # enters with the gain of w itself, (1 + r) with the numerator refit's gain r
    refit = FittedEffect("linear_refit", None, [np.zeros(3)], physical={"input_gain": refit_gain})
    clip = FittedEffect(
        "output_saturation", 0.6, [np.array([gain])], physical={"gain": gain, "plausible": True}
    )
    map_share([refit, clip])
    assert clip.physical["map_share"] == pytest.approx(gain / (1.0 + refit_gain))
    assert clip.physical["plausible"] is plausible


@pytest.mark.parametrize("refit_gain", [-1.0, -1.05])
def test_no_map_beside_a_refit_that_reverses_the_input(refit_gain):
    # the rig's 3.4 N Coulomb friction under 0.4 V on one BLAS thread: r = -1.05 with an
    # input saturation named before the friction. An input gain 1 + r <= 0 has no map's
    # share, whichever round named the map; the other effects keep their verdicts
    refit = FittedEffect("linear_refit", None, [np.zeros(3)], physical={"input_gain": refit_gain})
    saturation = FittedEffect(
        "input_saturation", 0.3, [np.array([-0.78])], physical={"input_gain": -0.78}
    )
    friction = FittedEffect("coulomb_friction", None, [np.zeros(3)], physical={"plausible": True})
    map_share([refit, saturation, friction])
    assert saturation.physical["plausible"] is False
    assert "map_share" not in saturation.physical
    assert friction.physical["plausible"] is True


@pytest.mark.parametrize(
    "coulomb, excess, possible, named_as",
    [
        (0.3, 0.7, True, "stribeck_friction"),  # static 1.0 above the Coulomb level 0.3
        (-0.3, -0.7, True, "stribeck_friction"),  # the same in the other sign convention
        (-0.27, 0.18, True, "coulomb_friction"),  # 0.09 at rest, 0.27 in motion: built up
        (0.3, -0.3, True, "coulomb_friction"),  # none at rest: a smooth sign
        (0.3, -0.5, False, None),
    ],
)  # −0.2 at rest: the friction reversed
def test_a_stribeck_form_is_named_by_its_level_at_rest(coulomb, excess, possible, named_as):
    out: dict = {}
    assert friction_form(out, coulomb, excess) is possible
    if possible:
        assert out.get("named_as", "stribeck_friction") == named_as
    fit = FittedEffect("stribeck_friction", 0.01, [np.zeros(3)] * 2, physical=out)
    assert fit.named_as == (named_as or "stribeck_friction")


@pytest.mark.parametrize("effect", ["cubic_stiffness", "output_saturation"])
def test_a_hidden_spring_or_clip_is_named_alone(effect, diagnosis):
    # before the loop's joint fit (docs/diagnose.md §4.3, the joint fit) the hidden cubic spring
    # was named with an output clip of gain ≈ 0 second, standing in for the part of the
    # spring the loop had not fitted; a clip must have a clip's gain (`map_share`). Later
    # a sensor offset came second, credited with the loop's fit from its own start
    # (`select._beyond_its_start`)
    rec = recording(effect)
    b, a = nominal_model()
    result = diagnosis(rec.v_in, rec.accel, FS, "acceleration", b, a)
    assert result.named == [effect]
    physical = result.selection.named[0].physical
    if effect == "output_saturation":
        assert physical["map_share"] == pytest.approx(1.0, abs=0.1)
    else:  # the spring's size in input units: k₃ over the input's gain
        truth = HIDDEN[effect]["k3_n_per_m3"] / MsdParams().gain_n_per_v
        assert physical["cubic_coefficient_input_equivalent"] == pytest.approx(truth, rel=0.1)


def test_no_hidden_effect_names_none(diagnosis):
    rec = recording(None)
    b, a = nominal_model()
    result = diagnosis(rec.v_in, rec.accel, FS, "acceleration", b, a)
    assert result.named == []
    assert result.gap_after == result.gap_before
    # the nominal model is exact: its gap is the noise, and the floor says so
    floor = result.info["noise_floor"]
    assert floor["at_floor"]
    assert 0.8 < result.gap_before / floor["floor"] < 1.25


def test_a_gain_fault_is_named_with_its_ratio(diagnosis):
    rec = changed_recording("gain_n_per_v", 1.2)
    b, a = nominal_model()
    result = diagnosis(rec.v_in, rec.accel, FS, "acceleration", b, a)
    assert result.named == ["gain_fault"]
    assert result.selection.linear["named"] == "gain_fault"
    assert abs(result.selection.named[0].physical["gain_ratio"] - 1.2) < 0.01
    assert result.gap_after <= 0.5 * result.gap_before


@pytest.mark.parametrize(
    "kind,ratio",
    [("acceleration", 0.8), ("acceleration", 1.2), ("velocity", 0.8), ("position", 0.8)],
)
def test_a_changed_spring_is_named_with_its_ratio(kind, ratio, diagnosis):
    # every force effect brings the loop's free spring, so each would close this gap; a
    # linear change of the mechanics is named after the parameter of the mode that moved
    # (read through each output's state chain)
    rec = changed_recording("stiffness_n_per_m", ratio)
    b, a = nominal_model()
    column = {"acceleration": "accel"}.get(kind, kind)
    result = diagnosis(rec.v_in, rec[column], FS, kind, b, a)
    assert result.named == ["stiffness_change"]
    params = result.selection.named[0].physical
    assert params["mode_change"] == "stiffness"
    assert params["stiffness_ratio"] == pytest.approx(ratio, abs=0.02)
    f0 = MsdParams().stiffness_n_per_m ** 0.5 / (2 * np.pi)  # 1 kg
    assert params["resonance_hz_nominal"] == pytest.approx(f0, rel=1e-6)
    assert params["resonance_hz"] == pytest.approx(f0 * ratio**0.5, abs=0.05)
    assert result.gap_after <= 0.5 * result.gap_before


@pytest.mark.parametrize(
    "kind,ratio", [("acceleration", 1.25), ("velocity", 0.8), ("position", 0.8)]
)
def test_a_changed_mass_is_named_with_its_ratio(kind, ratio, diagnosis):
    # a mass moves the mode as a spring does (ω² = k/m), and its damping per unit mass by
    # the same ratio (2ζω = c/m), which a spring leaves alone: the same fit as a changed
    # spring, named after the mode it moves
    rec = changed_recording("mass_kg", ratio)
    b, a = nominal_model()
    result = diagnosis(rec.v_in, rec[{"acceleration": "accel"}.get(kind, kind)], FS, kind, b, a)
    assert result.named[0] == "mass_change"
    params = result.selection.named[0].physical
    assert params["mode_change"] == "mass"
    assert params["mass_ratio"] == pytest.approx(ratio, abs=0.02)
    assert result.gap_after <= 0.5 * result.gap_before


@pytest.mark.parametrize("kind", ["acceleration", "velocity", "position"])
def test_added_damping_is_viscous_friction_with_its_coefficient(kind, diagnosis):
    # the numerator refit takes most of this gap and the mode's damping line accounts for
    # it (`mode_lines`); the loop's spring alone would fit it as well as viscous friction
    # does: the mode says which parameter changed (ζ 0.1 -> 0.1 + Δc/(2 m ω)), read through
    # each output's state chain
    rec = recording("viscous_friction")
    b, a = nominal_model()
    result = diagnosis(rec.v_in, rec[{"acceleration": "accel"}.get(kind, kind)], FS, kind, b, a)
    assert result.named == ["viscous_friction"]
    viscous = result.selection.named[0].physical
    assert viscous["mode_change"] == "damping"
    p = MsdParams()  # ζ = c / (2 √(k m)), 1 kg
    true_zeta = (p.damping_n_s_per_m + HIDDEN["viscous_friction"]["coefficient_n_s_per_m"]) / (
        2 * p.stiffness_n_per_m**0.5
    )
    assert viscous["damping_ratio"] == pytest.approx(true_zeta, abs=0.005)
    # its size from the mode: Δ(c/m) = 2 N·s/m / 1 kg
    assert viscous["damping_change_per_s"] == pytest.approx(2.0, rel=0.02)
    assert result.gap_after <= 0.5 * result.gap_before


def test_a_dead_time_is_named_with_its_value_not_absorbed_by_the_refit(diagnosis):
    rec = recording("dead_time")
    b, a = nominal_model()
    result = diagnosis(rec.v_in, rec.accel, FS, "acceleration", b, a)
    assert result.selection.linear["refit_significant"]
    assert result.selection.linear["named"] == "dead_time"
    true_s = HIDDEN["dead_time"]["delay_s"]
    assert abs(result.selection.named[0].physical["dead_time_s"] - true_s) < 0.5 / FS
    assert abs(result.info["dead_time_by_correlation_s"] - true_s) < 1.0 / FS


@pytest.mark.parametrize("effect", ["coulomb_friction", "viscous_friction", "stribeck_friction"])
def test_named_friction_is_physically_possible(effect, diagnosis):
    rec = recording(effect)
    b, a = nominal_model()
    result = diagnosis(rec.v_in, rec.accel, FS, "acceleration", b, a)
    named = result.selection.named[0]
    params = named.physical
    assert params["plausible"]
    if named.name == "mode_damping":  # the refit's damping line: it adds damping
        assert params["damping_change_per_s"] > 0
        return
    powers = [v for k, v in params.items() if k.endswith("_power_ratio")]
    assert powers and all(p < 0 for p in powers)  # it takes energy out of the motion


@pytest.mark.parametrize("effect", [None, "input_saturation"])
def test_fit_linear_baseline(effect, diagnosis):
    rec = recording(effect)
    result = diagnosis(rec.v_in, rec.accel, FS, "acceleration", None, None)
    if effect is None:
        assert result.named == []
    else:
        assert result.named[0] == effect
        assert result.gap_after <= 0.5 * result.gap_before


@pytest.mark.parametrize(
    "kind,effect", [("velocity", "coulomb_friction"), ("position", "dead_zone"), ("velocity", None)]
)
def test_velocity_and_position_outputs(kind, effect, diagnosis):
    rec = recording(effect)
    b, a = nominal_model()
    result = diagnosis(rec.v_in, rec[kind], FS, kind, b, a)
    if effect is None:
        assert result.named == []
    else:
        assert result.named[0] == effect
        assert result.gap_after <= 0.5 * result.gap_before


def test_an_input_that_never_leaves_its_median_names_nothing(diagnosis):
    # a step: dead zone and saturation have nothing to search; no crash, nothing named
    u = np.r_[np.zeros(500), np.ones(2000)]
    rec = simulate_recording(MsdParams(accel_noise_width=0.2), u, seed=2)
    b, a = nominal_model()
    assert diagnosis(rec.v_in, rec.accel, FS, "acceleration", b, a).named == []


def test_a_constant_force_is_no_candidate_where_the_acceleration_has_no_dc_response():
    # the §V mass hangs on a spring: its acceleration model has two zeros at z = 1, and a
    # constant force only moves it to a new rest (zero acceleration again). A free mass
    # (force → acceleration 1/m, no zero at DC) keeps the candidate.
    from fdi_daemon.diagnose.baseline import prepare, zero_at_dc

    rec = recording(None)
    b, a = nominal_model()
    ctx, _ = prepare(rec.v_in, rec.accel, FS, "acceleration", b, a)
    assert "force_offset" not in ctx.candidates and "sensor_offset" in ctx.candidates
    free_mass = (np.array([0.1, 0.05]), np.array([1.0, -0.5]))
    ctx, _ = prepare(rec.v_in, rec.accel, FS, "acceleration", *free_mass)
    assert "force_offset" in ctx.candidates
    # a zero near 1 counts when the data cannot tell it from one at 1 (below the DC block)
    zero_at = np.exp(-2 * np.pi * 0.1 / 256.0)  # 0.1 Hz at 256 Hz
    assert zero_at_dc(np.poly([zero_at, 0.3]), 256.0, below_hz=0.2)
    assert not zero_at_dc(np.poly([zero_at, 0.3]), 256.0, below_hz=0.05)
    assert not zero_at_dc(np.poly([-0.9, 0.3]), 256.0, below_hz=0.2)
