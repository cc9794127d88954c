"""γ_f's interval: the moving-block bootstrap of the cost profile, and what the status and the
recommendation say (fdi_daemon/ident/gamma_interval.py, signature_advice.py)."""

import numpy as np
import pytest
from conftest_ident import signature_data
from scipy import signal

from fdi_daemon.ident import signature as sig
from fdi_daemon.ident.gamma_interval import bootstrap_interval, optimal_block_length
from fdi_daemon.ident.signature_advice import (
    CalibrationContext,
    advise,
    amplitude_range,
    dominant_frequency_hz,
    plant_resonance_hz,
)


def _ar1(phi: float, n: int, seed: int) -> np.ndarray:
    white = np.random.default_rng(seed).standard_normal(n)
    return signal.lfilter([np.sqrt(1 - phi**2)], [1.0, -phi], white)


def test_block_length_follows_the_correlation():
    white = np.random.default_rng(0).standard_normal(4096)
    assert optimal_block_length(white) <= 3
    assert optimal_block_length(_ar1(0.95, 4096, 1)) >= 15
    assert optimal_block_length(np.zeros(100)) == 1


def _periodic_misfit(phi: float, n: int, seed: int) -> np.ndarray:
    """An error at the regressor's own period whose size drifts (AR(1) envelope): the
    coloured misfit a sine-driven window leaves."""
    return _ar1(phi, n, seed) * np.sin(2 * np.pi * np.arange(n) / 37.0 + 0.3)


def _line_profile(noise: np.ndarray, grid: np.ndarray) -> tuple[np.ndarray, int]:
    """e_t(γ) = y − γ x for y = 3x + noise: a profile whose least point is the LS slope."""
    x = np.sin(2 * np.pi * np.arange(len(noise)) / 37.0) * (
        1 + 0.5 * np.cos(np.arange(len(noise)) / 300)
    )
    y = 3.0 * x + noise
    errors = y[None, :] - grid[:, None] * x[None, :]
    return errors, int(np.argmin(np.sum(errors**2, axis=1)))


def test_correlated_errors_widen_the_interval_and_it_is_seeded():
    grid = np.arange(0.0, 6.0001, 0.05)
    white, best_w = _line_profile(0.5 * np.random.default_rng(3).standard_normal(4000), grid)
    slow, best_s = _line_profile(0.5 * _periodic_misfit(0.98, 4000, 4), grid)
    w = bootstrap_interval(grid, white, best_w)
    s = bootstrap_interval(grid, slow, best_s)
    assert w.low < 3.0 < w.high and s.low < 3.0 < s.high
    assert s.block_samples > 4 * w.block_samples
    assert (s.high - s.low) > 2 * (w.high - w.low)
    assert bootstrap_interval(grid, slow, best_s) == s  # same data, same interval


@pytest.mark.slow  # 80 bootstraps of 1000 draws
def test_coverage_of_the_bootstrap_on_correlated_errors():
    """99 % intervals over 40 seeded periodic misfits (AR(0.9) envelope): with the chosen
    blocks at least 38 hold the true slope (measured 40; 38 of 40 at AR(0.97), 36 at 0.99),
    resampling single samples (blocks of 1) only 21."""
    grid = np.arange(0.0, 6.0001, 0.05)
    held = {None: 0, 1: 0}
    for seed in range(40):
        errors, best = _line_profile(0.8 * _periodic_misfit(0.9, 3000, 100 + seed), grid)
        for block in held:
            interval = bootstrap_interval(grid, errors, best, draws=1000, block_samples=block)
            held[block] += interval.low <= 3.0 <= interval.high
    assert held[None] >= 38 and held[1] <= 30


def test_statuses_and_their_recommendations():
    residual, velocity = signature_data(3.0, "sweep", noise_fraction=0.05)
    ok = sig.estimate_signature(residual, velocity)
    assert ok.status == "identified" and ok.recommendation is None
    assert ok.interval[0] <= 3.0 <= ok.interval[1]
    parts = ok.summary()
    assert parts["interval_99"][0] <= parts["interval_99_bootstrap"][0]
    assert parts["interval_99"][1] >= parts["interval_99_profile"][1]

    residual, velocity = signature_data(3.0, "sine", noise_fraction=0.1)
    sine = sig.estimate_signature(residual, velocity)
    assert sine.status == "poorly identified" and not sine.flat
    assert sine.interval[1] - sine.interval[0] > 2 and "step its amplitude" in sine.recommendation

    noisy, velocity = signature_data(3.0, "sweep", noise_fraction=2.0, n_samples=400)
    flat = sig.estimate_signature(noisy, velocity, sig.gamma_grid(0, 6, 0.2))
    assert flat.status in ("flat", "not identified (edge)")
    assert flat.interval == (0.0, pytest.approx(6.0))  # nothing excluded: the whole grid


def test_at_the_grid_edge_no_gamma_is_excluded():
    residual, velocity = signature_data(6.0, "sweep", noise_fraction=0.05)
    result = sig.estimate_signature(residual, velocity, sig.gamma_grid(0, 4, 0.2))
    assert result.status == "not identified (edge)"
    assert result.interval == (0.0, pytest.approx(4.0))


def test_advice_names_what_to_change_in_this_run():
    fs = 256.0
    t = np.arange(int(20 * fs)) / fs
    steady = 0.03 * np.sin(2 * np.pi * 8.0 * t)
    stepped = (1.0 + 1.5 * (np.floor(t / 2.5) % 4) / 3) * steady
    assert amplitude_range(steady, fs)[1] / amplitude_range(steady, fs)[0] == pytest.approx(1.0)
    assert amplitude_range(stepped, fs)[1] / amplitude_range(stepped, fs)[0] > 2.0
    assert dominant_frequency_hz(stepped, fs) == pytest.approx(8.0, abs=0.1)
    one = advise(False, (1.0, 4.0), 10.0, steady, CalibrationContext(fs, False, 9.5))
    assert "--reference-window" in one and "step its amplitude" in one
    assert "from 8 Hz to below the plant's resonance at 9.5 Hz" in one
    assert "beyond 20 s" in one and "30 % of the gamma grid" in one
    paired = advise(False, (1.0, 4.0), 10.0, stepped, CalibrationContext(fs, True, 30.0))
    assert "--reference-window" not in paired and "signature_calibration" not in paired
    assert "widen its amplitude range" in paired and "resonance" not in paired
    assert advise(True, (0, 10), 10.0, stepped, CalibrationContext(fs, True)).startswith(
        "gamma_f is not identifiable"
    )


def test_plant_resonance():
    pole = 0.95 * np.exp(1j * 2 * np.pi * 10.0 / 256.0)
    a = np.real(np.poly([pole, np.conj(pole), 0.5]))
    assert plant_resonance_hz(a, 256.0) == pytest.approx(10.0)
    assert plant_resonance_hz(np.array([1.0, -0.5]), 256.0) is None


def test_the_likelihood_ratio_interval_ends_between_grid_points():
    """A profile lr(γ) = c (γ − γ0)² tabulated on the 0.2 grid: the ends lie where it crosses
    the threshold (γ0 ± √(t/c)) within a tenth of a step, not on the grid points inside
    (which fall short by up to a step, and missed a truth 0.002 below one, issue 43)."""
    likelihood_ratio_interval, threshold = sig.likelihood_ratio_interval, sig.CHI2_1_99
    grid = np.arange(0.0, 10.0001, 0.2)
    gamma0, c = 3.37, 30.0
    lo, hi = likelihood_ratio_interval(grid, c * (grid - gamma0) ** 2, threshold)
    half = np.sqrt(threshold / c)
    assert abs(lo - (gamma0 - half)) < 0.02 and abs(hi - (gamma0 + half)) < 0.02
    inside = grid[c * (grid - gamma0) ** 2 <= threshold]
    assert lo < inside.min() and hi > inside.max()
    # a profile accepted up to the grid's end keeps that end; nothing accepted: None
    assert likelihood_ratio_interval(grid, c * (grid - 9.9) ** 2, threshold)[1] == 10.0
    assert likelihood_ratio_interval(grid, np.full(grid.size, 10.0), threshold) is None
