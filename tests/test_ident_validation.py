"""Validation metrics: fit %, initial-state estimation, residual–input correlation, band errors."""

import numpy as np
import pytest
from conftest_ident import chirp, plant
from scipy import signal

from fdi_daemon.ident import validation


def test_fit_percent_extremes():
    y = np.sin(np.linspace(0, 20, 500))
    assert validation.fit_percent(y, y) == pytest.approx(100.0)
    assert validation.fit_percent(y, np.full_like(y, y.mean())) == pytest.approx(0.0)
    with pytest.raises(ValueError):
        validation.fit_percent(np.ones(10), np.ones(10))


def test_simulate_estimates_the_initial_state_and_offset():
    b, a = plant()
    rng = np.random.default_rng(0)
    u_before = rng.standard_normal(300)
    u = chirp(1024)
    y = signal.lfilter(b, a, np.concatenate([u_before, u]))[300:] + 0.25  # sensor offset
    at_rest = validation.simulate(b, a, u)
    assert validation.fit_percent(y, at_rest) < 99.0
    assert validation.fit_percent(y, validation.simulate(b, a, u, y)) == pytest.approx(
        100.0, abs=1e-6
    )


def test_residual_input_correlation_band():
    rng = np.random.default_rng(1)
    u = rng.standard_normal(4000)
    independent = validation.residual_input_correlation(rng.standard_normal(4000), u, 20)
    assert independent["bound"] == pytest.approx(2.5758293 / np.sqrt(4000))
    assert independent["fraction_outside"] < 0.1
    leaked = validation.residual_input_correlation(np.roll(u, 3) + rng.standard_normal(4000), u)
    assert leaked["max_abs"] > 5 * leaked["bound"]
    assert leaked["lags"][np.argmax(np.abs(leaked["r"]))] == 3


def test_band_errors():
    f = np.linspace(0, 10, 101)
    data = np.ones(101, dtype=complex)
    model = np.where(f < 5, 1.1, 1.0).astype(complex)
    rows = validation.band_errors(f, data, model, [0, 5, 10.01])
    assert rows[0]["rms_relative_error"] == pytest.approx(0.1)
    assert rows[1]["rms_relative_error"] == pytest.approx(0.0)
    assert rows[0]["points"] == 50 and rows[1]["points"] == 51
