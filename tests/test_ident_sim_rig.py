"""Identification on the simulated rig (hil_sim): fit on data not used for fitting, and the
friction signature on the calibration and the paper's test-case windows."""

import numpy as np
import pytest
from conftest_ident import sim_model, sim_recordings, true_gamma  # noqa: F401  (fixtures)

from fdi_daemon.cli import main
from fdi_daemon.core.velocity import VelocityEstimator
from fdi_daemon.ident import plant, signature, validation
from fdi_daemon.io.model_file import load_model
from fdi_daemon.io.recordings import read_recording

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("validation_name", ["ident_chirp_long", "ident_chirp_seed1"])
def test_plant_fits_friction_free_validation_data(sim_model, sim_recordings,  # noqa: F811
                                                  validation_name):
    model = load_model(sim_model)
    rec = read_recording(sim_recordings[validation_name])
    y_sim = validation.simulate(model.plant_b, model.plant_a, rec.v_in, rec.accel)
    assert validation.fit_percent(rec.accel, y_sim) >= 90.0
    assert np.max(np.abs(np.roots(model.plant_a))) < 1


def test_identify_reports_the_choices_it_made(sim_model):  # noqa: F811
    choices = load_model(sim_model).provenance["identify"]["choices"]
    lo, hi = choices["band_hz"]
    assert 0 < lo < 3 and 12 < hi <= 21  # the chirp sweeps 0-20 Hz
    assert choices["lag_samples_rule"] != "given" and choices["band_rule"] != "given"


def _signature(model_path, rec_path, t0, t1):
    model = load_model(model_path)
    rec = read_recording(rec_path)
    residual = signature.plant_residual(model.plant_b, model.plant_a, rec.v_in, rec.accel)
    velocity = VelocityEstimator(model.fs).run(rec.accel)
    first, end = int(np.searchsorted(rec.t, t0)), int(np.searchsorted(rec.t, t1))
    return rec, signature.estimate_signature(residual[:end], velocity[:end], fit_from=first)


def test_signature_calibration_recovers_gamma_or_flags(sim_model, sim_recordings):  # noqa: F811
    """Issue check: γ_f within ±0.3 of the simulator's when the excitation identifies it,
    flagged when it does not. The truth comes from the ground-truth friction force."""
    rec, result = _signature(sim_model, sim_recordings["signature_calibration"], 11.0, 40.0)
    gamma_true = true_gamma(rec, 11.0, 40.0)
    assert 3.0 < gamma_true < 3.7  # the rig's bearing_viscous_per_n / bearing_mu_kinetic
    assert result.flat or abs(result.gamma_f - gamma_true) <= 0.3


@pytest.mark.parametrize("name, t0", [("test_case_2", 3.2), ("test_case_1", 3.3)])
def test_single_sine_fault_window_is_flagged_flat(sim_model, sim_recordings, name, t0):  # noqa: F811
    _, result = _signature(sim_model, sim_recordings[name], t0, 6.0)
    assert result.flat
    assert result.recommendation and "signature_calibration" in result.recommendation


def test_signature_command_on_the_rig(sim_model, sim_recordings, tmp_path):  # noqa: F811
    out = tmp_path / "rig.yaml"
    assert main(["signature", str(sim_recordings["signature_calibration"]), "--model",
                 str(sim_model), "--fault-window", "11:40", "-o", str(out),
                 "--plot", str(tmp_path / "sig.png")]) == 0
    model = load_model(out)
    assert model.fault_filter is not None and 0 <= model.fault_filter.gamma_f <= 10
    assert np.all(np.abs(np.roots(model.fault_filter.f)) < 1)
    assert (tmp_path / "sig.png").stat().st_size > 10_000
