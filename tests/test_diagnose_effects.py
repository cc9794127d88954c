"""Blind tests of the diagnose workflow: each effect hidden in the §V model is named and
closing it at least halves the held-out gap; with nothing hidden, nothing is named."""

from __future__ import annotations

import numpy as np
import pytest

from hil_sim.msd import MsdParams, simulate_recording
from fdi_daemon.diagnose.effects import EFFECT_NAMES
from fdi_daemon.diagnose.workflow import run_diagnose
from tests.diagnose_cases import FS, HIDDEN, nominal_model, recording


def test_every_library_effect_has_a_case():
    assert set(HIDDEN) == set(EFFECT_NAMES)


@pytest.mark.parametrize("effect", sorted(HIDDEN))
def test_hidden_effect_is_named_and_gap_halves(effect):
    rec = recording(effect)
    b, a = nominal_model()
    result = run_diagnose(rec.v_in, rec.accel, FS, "acceleration", b, a)
    assert result.named, f"nothing named for hidden {effect}"
    assert result.named[0] == effect
    assert result.gap_after <= 0.5 * result.gap_before


def test_no_hidden_effect_names_none():
    rec = recording(None)
    b, a = nominal_model()
    result = run_diagnose(rec.v_in, rec.accel, FS, "acceleration", b, a)
    assert result.named == []
    assert result.gap_after == result.gap_before


@pytest.mark.parametrize("effect", [None, "input_saturation"])
def test_fit_linear_baseline(effect):
    rec = recording(effect)
    result = run_diagnose(rec.v_in, rec.accel, FS, "acceleration", None, None)
    if effect is None:
        assert result.named == []
    else:
        assert result.named[0] == effect
        assert result.gap_after <= 0.5 * result.gap_before


@pytest.mark.parametrize("kind,effect", [("velocity", "coulomb_friction"),
                                         ("position", "dead_zone"),
                                         ("velocity", None)])
def test_velocity_and_position_outputs(kind, effect):
    rec = recording(effect)
    b, a = nominal_model()
    result = run_diagnose(rec.v_in, rec[kind], FS, kind, b, a)
    if effect is None:
        assert result.named == []
    else:
        assert result.named[0] == effect
        assert result.gap_after <= 0.5 * result.gap_before


def test_an_input_that_never_leaves_its_median_names_nothing():
    # a step: dead zone and saturation have nothing to search; no crash, nothing named
    u = np.r_[np.zeros(500), np.ones(2000)]
    rec = simulate_recording(MsdParams(accel_noise_width=0.2), u, seed=2)
    b, a = nominal_model()
    assert run_diagnose(rec.v_in, rec.accel, FS, "acceleration", b, a).named == []
