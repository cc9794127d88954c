"""Friction signature, eqs. (11)–(13): γ grid, OE fit of G_e, refinement, flatness."""

import numpy as np
import pytest
from conftest_ident import OE_B, OE_F, signature_data
from scipy import signal

from fdi_daemon.core.iir import IIRFilter
from fdi_daemon.ident import signature as sig


def test_gamma_grid_is_the_papers():
    grid = sig.gamma_grid()
    assert len(grid) == 51 and grid[0] == 0.0 and grid[-1] == pytest.approx(10.0)
    assert np.allclose(np.diff(grid), 0.2)
    with pytest.raises(ValueError):
        sig.gamma_grid(1.0, 0.0, 0.2)


def test_friction_signal_and_residual():
    v = np.array([-2.0, 0.0, 0.5])
    np.testing.assert_allclose(sig.friction_signal(v, 2.0), [-5.0, 0.0, 2.0])
    b, a = [0.0, 0.5], [1.0, -0.5]
    u = np.arange(5.0)
    np.testing.assert_allclose(
        sig.plant_residual(IIRFilter(b, a), u, np.ones(5)), 1.0 - signal.lfilter(b, a, u)
    )


@pytest.mark.parametrize("gamma", [0.0, 3.0, 6.0])
def test_recovers_gamma_from_an_identifying_excitation(gamma):
    residual, velocity = signature_data(gamma, "sweep", noise_fraction=0.05)
    result = sig.estimate_signature(residual, velocity)
    assert abs(result.gamma_f - gamma) <= 0.3
    assert not result.flat and result.recommendation is None
    assert result.interval[0] <= result.gamma_f <= result.interval[1] + 1e-9
    # G_e is the filter that made the data, up to the noise
    w = np.linspace(0.05, np.pi, 100)
    true = signal.freqz(OE_B, OE_F, worN=w)[1]
    est = signal.freqz(result.fit.b, result.fit.f, worN=w)[1]
    assert np.max(np.abs(est - true)) / np.max(np.abs(true)) < 0.05


def test_refinement_lands_between_grid_points():
    residual, velocity = signature_data(3.1, "sweep", noise_fraction=0.0)
    result = sig.estimate_signature(residual, velocity)
    assert result.gamma_f == pytest.approx(3.1, abs=0.02)
    assert result.sse_min <= result.sse.min()


def test_single_sine_is_flagged():
    residual, velocity = signature_data(3.0, "sine", noise_fraction=0.1)
    result = sig.estimate_signature(residual, velocity)
    assert result.status == "poorly identified"
    assert "step its amplitude" in result.recommendation
    summary = result.summary()
    assert summary["status"] == "poorly identified"
    assert summary["interval_99"][1] - summary["interval_99"][0] > 2


def test_progress_callback_counts_every_fit():
    residual, velocity = signature_data(1.0, "sweep", noise_fraction=0.05, n_samples=400)
    calls = []
    grid = sig.gamma_grid(0, 2, 0.5)
    sig.estimate_signature(residual, velocity, grid, on_step=lambda: calls.append(1))
    assert len(calls) == sig.sweep_fits(len(grid)) == 3 * len(grid) - 1


def test_zero_velocity_is_an_error():
    with pytest.raises(ValueError, match="velocity is zero"):
        sig.estimate_signature(np.ones(300), np.zeros(300))


def test_window_after_a_lead_in_and_prefilter_keep_gamma():
    """Samples before fit_from only run the prefilter in; L r = G_e L x_f keeps γ."""
    from scipy.signal import butter

    residual, velocity = signature_data(3.0, "sweep", noise_fraction=0.02, n_samples=1400)
    result = sig.estimate_signature(
        residual,
        velocity,
        sig.gamma_grid(0, 10, 0.5),
        prefilter=butter(3, 1.0, btype="high", fs=256.0),
        fit_from=376,
    )
    assert abs(result.gamma_f - 3.0) <= 0.3
    assert len(result.residual) == 1024 and len(result.fit.y_sim) == 1024


def test_reference_difference_cancels_an_input_driven_model_error():
    """A plant-model error that grows with the input amplitude looks like viscous friction
    (here exactly: G_e·0.8v); the same excitation played fault-free and subtracted removes it."""
    gamma, error_gain = 3.0, 0.8
    residual, velocity = signature_data(gamma, "sweep", noise_fraction=0.02)
    model_error = signal.lfilter(OE_B, OE_F, error_gain * velocity)
    rng = np.random.default_rng(7)
    reference = model_error + 0.02 * np.std(residual) * rng.standard_normal(len(residual))
    both = np.concatenate([reference, residual + model_error])
    v_both = np.concatenate([velocity, velocity])
    n = len(residual)
    grid = sig.gamma_grid(0, 6, 0.2)
    biased = sig.estimate_signature(both, v_both, grid, fit_from=n)
    assert abs(biased.gamma_f - (gamma + error_gain)) <= 0.3
    cancelled = sig.estimate_signature(sig.reference_difference(both, n), v_both, grid, fit_from=n)
    assert abs(cancelled.gamma_f - gamma) <= 0.3 and not cancelled.flat
    with pytest.raises(ValueError):
        sig.reference_difference(both, 0)


def test_lowpass_prefilter_and_pole_bound_keep_gamma():
    residual, velocity = signature_data(3.0, "sweep", noise_fraction=0.02)
    sos = sig.lowpass_prefilter(12.0, 256.0)
    assert sos.shape == (4, 6)
    result = sig.estimate_signature(
        residual, velocity, sig.gamma_grid(0, 6, 0.2), prefilter=sos, max_pole_radius=0.95
    )
    assert abs(result.gamma_f - 3.0) <= 0.3 and not result.flat
    assert np.max(np.abs(np.roots(result.fit.f))) <= 0.95 + 1e-9
    with pytest.raises(ValueError):
        sig.lowpass_prefilter(200.0, 256.0)


def test_pole_bound_is_respected_and_derived_from_the_plant():
    assert sig.plant_pole_bound(np.real(np.poly([0.81, 0.5]))) == pytest.approx(0.9)
    residual, velocity = signature_data(2.0, "sweep", noise_fraction=0.02, n_samples=600)
    result = sig.estimate_signature(
        residual, velocity, sig.gamma_grid(0, 4, 0.5), max_pole_radius=0.8
    )
    assert np.max(np.abs(np.roots(result.fit.f))) <= 0.8 + 1e-9  # OE_F has a pole at 0.9


def test_fault_filter_refit_at_gamma_recovers_g_e():
    residual, velocity = signature_data(3.0, "sweep", noise_fraction=0.0)
    fit = sig.fit_fault_filter(residual, velocity, 3.0)
    w = np.linspace(0.05, np.pi, 100)
    true = signal.freqz(OE_B, OE_F, worN=w)[1]
    est = signal.freqz(fit.b, fit.f, worN=w)[1]
    assert np.max(np.abs(est - true)) / np.max(np.abs(true)) < 0.01
    assert sig.fit_percent(residual, fit.y_sim) > 99


def test_calibration_band_spans_the_excited_tones():
    """Sines at 6 and 9 Hz (1.0 and 0.5 V, 20 s at 256 Hz) plus noise 40 dB below: the band is
    the span of the input spectrum within 20 dB of its peak, the tones widened by at most
    the Welch resolution (0.5 Hz here); the noise and the 2 Hz tone 26 dB down lie outside."""
    fs = 256.0
    t = np.arange(int(20 * fs)) / fs
    rng = np.random.default_rng(7)
    v_in = (
        np.sin(2 * np.pi * 6.0 * t)
        + 0.5 * np.sin(2 * np.pi * 9.0 * t)
        + 0.05 * np.sin(2 * np.pi * 2.0 * t)
        + 0.01 * rng.standard_normal(t.size)
    )
    lo, hi = sig.calibration_band_hz(v_in, fs)
    assert 5.0 <= lo <= 6.0 and 9.0 <= hi <= 10.0
