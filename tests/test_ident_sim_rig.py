"""Identification on the simulated rig (hil_sim): fit on data not used for fitting, and the
friction signature on the calibration and the paper's test-case windows."""

import numpy as np
import pytest
from conftest_ident import true_gamma

from fdi_daemon.cli import main
from fdi_daemon.core.iir import IIRFilter
from fdi_daemon.core.velocity import VelocityEstimator
from fdi_daemon.ident import signature, validation
from fdi_daemon.io.model_file import load_model
from fdi_daemon.io.recordings import read_recording

pytestmark = pytest.mark.slow

#: the calibration run (configs/scenarios/signature_calibration_paired.yaml): a fault-free
#: pass and a fault pass of the same 6 Hz amplitude-stepped sine, 21 s apart
FAULT_WINDOW, REFERENCE_WINDOW, LOWPASS_HZ = "22:42", "1:21", 10.0


@pytest.mark.parametrize("validation_name", ["ident_chirp_long", "ident_chirp_seed1"])
def test_plant_fits_friction_free_validation_data(
    sim_model,
    sim_recordings,  # noqa: F811
    validation_name,
):
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


@pytest.fixture(scope="module")
def calibrated(sim_model, sim_recordings, tmp_path_factory):  # noqa: F811
    """`fdi signature` on the calibration run, as docs/identification.md gives it."""
    out = tmp_path_factory.mktemp("signature") / "rig.yaml"
    plot = out.with_suffix(".png")
    assert (
        main(
            [
                "signature",
                str(sim_recordings["signature_calibration_paired"]),
                "--model",
                str(sim_model),
                "--fault-window",
                FAULT_WINDOW,
                "--reference-window",
                REFERENCE_WINDOW,
                "--lowpass-hz",
                str(LOWPASS_HZ),
                "-o",
                str(out),
                "--plot",
                str(plot),
            ]
        )
        == 0
    )
    return load_model(out), plot


def test_signature_calibration_recovers_gamma(calibrated, sim_recordings):  # noqa: F811
    """Issue check: on the excitation that identifies it, γ_f within ±0.3 of the simulator's
    and not flagged. The truth comes from the ground-truth friction force of the window."""
    model, _ = calibrated
    rec = read_recording(sim_recordings["signature_calibration_paired"])
    t0, t1 = (float(x) for x in FAULT_WINDOW.split(":"))
    gamma_true = true_gamma(rec, t0, t1)
    assert 3.0 < gamma_true < 3.7  # the rig's bearing_viscous_per_n / bearing_mu_kinetic
    profile = model.provenance["signature"]["cost_profile"]
    assert not profile["flat"]
    assert abs(model.fault_filter.gamma_f - gamma_true) <= 0.3
    assert profile["interval_99"][0] <= model.fault_filter.gamma_f <= profile["interval_99"][1]


def test_signature_command_writes_a_stable_filter_and_its_choices(calibrated, sim_model):  # noqa: F811
    model, plot = calibrated
    assert np.all(np.abs(np.roots(model.fault_filter.f)) < 1)
    prov = model.provenance["signature"]
    assert prov["reference_window_s"] == [1.0, 21.0] and prov["lowpass_hz"] == LOWPASS_HZ
    bound = signature.plant_pole_bound(load_model(sim_model).plant_a)
    assert prov["max_pole_radius"] == pytest.approx(bound)
    assert np.max(np.abs(np.roots(model.fault_filter.f))) <= bound + 1e-9
    assert prov["fault_filter_fit_percent_full_band"] > 50
    assert plot.stat().st_size > 10_000


def _signature(model_path, rec_path, t0, t1, **options):
    model = load_model(model_path)
    rec = read_recording(rec_path)
    residual = signature.plant_residual(
        IIRFilter(model.plant_b, model.plant_a), rec.v_in, rec.accel
    )
    velocity = VelocityEstimator(model.fs).run(rec.accel)
    first, end = int(np.searchsorted(rec.t, t0)), int(np.searchsorted(rec.t, t1))
    return rec, signature.estimate_signature(
        residual[:end], velocity[:end], fit_from=first, **options
    )


@pytest.mark.parametrize("name, t0", [("test_case_2", 3.2), ("test_case_1", 3.3)])
@pytest.mark.parametrize("calibration_options", [False, True])
def test_single_sine_fault_window_is_flagged_flat(
    sim_model, sim_recordings, name, t0, calibration_options
):  # noqa: F811
    """The paper's single 8 Hz sine does not identify γ: flagged (flat or poorly identified)
    with the paper's settings
    and with the calibration's (low-pass on the fundamentals, G_e pole bound)."""
    options = {}
    if calibration_options:
        options = {
            "prefilter": signature.lowpass_prefilter(LOWPASS_HZ, 256.0),
            "max_pole_radius": signature.plant_pole_bound(load_model(sim_model).plant_a),
        }
    _, result = _signature(sim_model, sim_recordings[name], t0, 6.0, **options)
    assert result.status in ("flat", "poorly identified")
    assert result.recommendation and "step its amplitude" in result.recommendation


def test_reference_window_with_another_excitation_is_refused(
    sim_model, sim_recordings, tmp_path, capsys
):  # noqa: F811
    # 0.05 s off: a third of a 6 Hz period, so the valve voltages disagree
    code = main(
        [
            "signature",
            str(sim_recordings["signature_calibration_paired"]),
            "--model",
            str(sim_model),
            "--fault-window",
            FAULT_WINDOW,
            "--reference-window",
            "1.05:21.05",
            "-o",
            str(tmp_path / "m.yaml"),
        ]
    )
    assert code == 2
    assert "same excitation" in capsys.readouterr().err
    assert not (tmp_path / "m.yaml").exists()
