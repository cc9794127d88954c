"""Page's CUSUM for a shift along a regressor (`core.cusum`): the compiled increment against
the plain reference, the threshold from the mean time between false alarms, and Lorden's
bound checked by simulation on white innovations."""

import math

import numpy as np
from numba import njit

from fdi_daemon.core.cusum import SECONDS_PER_YEAR, cusum_increment, cusum_run, cusum_threshold


@njit(cache=False)
def _compiled_run(e, s, sigma2, shift):
    out = np.empty(e.size)
    total = 0.0
    for k in range(e.size):
        total = max(0.0, total + cusum_increment(e[k], s[k], 1.0 / sigma2[k], shift))
        out[k] = total
    return out


def test_the_compiled_increment_is_the_log_likelihood_ratio():
    rng = np.random.default_rng(0)
    e, s = rng.normal(size=500), rng.normal(size=500)
    sigma2 = rng.uniform(0.5, 2.0, size=500)
    shift = 0.3
    # the LLR of N(shift·s, σ²) against N(0, σ²), written out from the two densities
    llr = (-((e - shift * s) ** 2) + e**2) / (2.0 * sigma2)
    direct = np.empty(500)
    total = 0.0
    for k in range(500):
        total = max(0.0, total + llr[k])
        direct[k] = total
    np.testing.assert_allclose(cusum_run(e, s, sigma2, shift), direct, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(_compiled_run(e, s, sigma2, shift), direct, rtol=1e-12, atol=1e-12)


def test_threshold_is_the_log_of_the_run_length_in_ticks():
    assert math.isclose(cusum_threshold(10.0, 256.0), math.log(10 * SECONDS_PER_YEAR * 256))
    assert math.isclose(cusum_threshold(10.0, 256.0), 25.115, abs_tol=1e-3)


def test_mean_run_length_without_a_shift_is_at_least_e_to_the_h():
    """Lorden's bound on white innovations: h = 3 gives ARL₀ ≥ e³ ≈ 20 ticks."""
    rng = np.random.default_rng(1)
    h, shift, runs = 3.0, 1.0, []
    for _ in range(400):
        total, k = 0.0, 0
        while total <= h:
            k += 1
            total = max(0.0, total + shift * (rng.normal() - 0.5 * shift))
        runs.append(k)
    assert np.mean(runs) >= math.exp(h)


def test_a_shift_is_found_and_its_drift_is_the_kullback_leibler_rate():
    """Under a shift Δ = δ the statistic grows by δ²s²/(2σ²) a tick on average."""
    rng = np.random.default_rng(2)
    n, shift = 4000, 0.5
    s = np.ones(n)
    e = shift * s + rng.normal(size=n)
    stat = cusum_run(e, s, np.ones(n), shift)
    assert abs(stat[-1] / n - shift**2 / 2) < 0.03
