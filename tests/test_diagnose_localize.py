"""Localisation (time, state, frequency) and the statistics of the selection."""

from __future__ import annotations

import numpy as np
import pytest

from fdi_daemon.diagnose.effects import least_squares
from fdi_daemon.diagnose.localize import localize, state_bins, time_segments, whiteness
from fdi_daemon.diagnose.select import effective_samples

FS = 256.0


def test_time_segments_find_an_injected_burst():
    rng = np.random.default_rng(0)
    e = 0.1 * rng.standard_normal(int(30 * FS))
    e[int(12.2 * FS) : int(12.8 * FS)] += 2.0 * np.sin(np.arange(int(0.6 * FS)))
    top = time_segments(e, FS)[0]
    assert top["t0"] <= 12.2 < top["t1"]
    assert top["ratio_to_median"] > 5


def test_state_bins_see_a_velocity_sign_step():
    rng = np.random.default_rng(1)
    v = np.sin(2 * np.pi * 0.5 * np.arange(int(20 * FS)) / FS)
    noise = 0.05 * rng.standard_normal(v.size)
    friction = state_bins(-0.3 * np.sign(v) + noise, v, "velocity", signed=True)
    unrelated = state_bins(noise, v, "velocity", signed=True)
    assert friction["explained"] > 0.9
    assert unrelated["explained"] < 0.01
    means = [b["mean"] for b in friction["bins"]]
    assert max(means) == pytest.approx(0.3, abs=0.02)
    assert min(means) == pytest.approx(-0.3, abs=0.02)


def test_whiteness_and_effective_samples():
    rng = np.random.default_rng(2)
    white = rng.standard_normal(5000)
    coloured = np.convolve(white, np.ones(20) / 20, mode="same")
    assert whiteness(white)["white"]
    assert not whiteness(coloured)["white"]
    assert effective_samples(white) > 0.8 * white.size
    # a 20-tap moving average: integrated autocorrelation time about 20
    assert 10 < white.size / effective_samples(coloured) < 30


def test_localize_cross_correlation_flags_a_missed_input_path():
    rng = np.random.default_rng(3)
    n = int(20 * FS)
    u = rng.standard_normal(n)
    e_linked = 0.5 * np.roll(u, 3) + 0.1 * rng.standard_normal(n)
    e_free = 0.1 * rng.standard_normal(n)
    y = u + e_linked
    test = slice(2 * n // 3, n)
    zeros = np.zeros(n)
    linked = localize(e_linked, y, u, zeros + u, zeros + u, FS, test)["cross_correlation"]
    free = localize(e_free, y, u, zeros + u, zeros + u, FS, test)["cross_correlation"]
    assert linked["max_abs"] > 10 * linked["bound_99"]
    assert free["max_abs"] < 2 * free["bound_99"]


def test_least_squares_matches_numpy_on_collinear_columns():
    rng = np.random.default_rng(4)
    base = rng.standard_normal(3000)
    x = np.column_stack([base, np.roll(base, 1) * 0.999 + 1e-3 * base, rng.standard_normal(3000)])
    y = x @ np.array([1.0, -2.0, 0.5]) + 0.01 * rng.standard_normal(3000)
    theta = least_squares(x, y)
    ref = np.linalg.lstsq(x, y, rcond=None)[0]
    np.testing.assert_allclose(theta, ref, rtol=1e-6)
