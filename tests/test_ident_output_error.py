"""Output-error fit of eq. (8) with [nb nf nk] = [4 3 0]."""

import numpy as np
import pytest
from conftest_ident import OE_B, OE_F, match_roots
from scipy import signal

from fdi_daemon.ident import output_error, stable_poly


def _data(noise_fraction, seed=1, n=1024):
    rng = np.random.default_rng(seed)
    u = np.sign(np.sin(2 * np.pi * np.arange(n) / 50)) + 0.3 * rng.standard_normal(n)
    past = rng.standard_normal(200)  # the window does not start at rest
    y = signal.lfilter(OE_B, OE_F, np.concatenate([past, u]))[200:]
    return u, y + noise_fraction * np.std(y) * rng.standard_normal(n)


def _response_error(b, f):
    w = np.linspace(0, np.pi, 200)
    true = signal.freqz(OE_B, OE_F, worN=w)[1]
    return np.max(np.abs(signal.freqz(b, f, worN=w)[1] - true)) / np.max(np.abs(true))


@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("noise", [0.0, 0.02, 0.1])
def test_recovers_the_known_filter(noise, seed):
    """Poles of F and the frequency response, within tolerances proportional to the noise."""
    u, y = _data(noise, seed)
    fit = output_error.fit_output_error(u, y, 4, 3, 0)
    assert match_roots(np.roots(fit.f), np.roots(OE_F)) < 1e-9 + 0.7 * noise
    assert _response_error(fit.b, fit.f) < 1e-9 + 0.5 * noise
    assert stable_poly.is_stable(fit.f)
    if noise == 0:
        np.testing.assert_allclose(fit.b, OE_B, atol=1e-9)
        np.testing.assert_allclose(fit.f, OE_F, atol=1e-9)


def test_warm_start_reaches_the_same_fit():
    u, y = _data(0.02)
    cold = output_error.fit_output_error(u, y)
    warm = output_error.fit_output_error(u, y, start=(OE_B * 0.8, np.array([1, -2.0, 1.3, -0.3])))
    np.testing.assert_allclose(warm.b, cold.b, atol=1e-5)
    assert warm.sse == pytest.approx(cold.sse, rel=1e-6)


def test_unstable_start_ends_stable():
    u, y = _data(0.02)
    fit = output_error.fit_output_error(u, y, start=(OE_B, np.real(np.poly([1.3, 0.5, -0.2]))))
    assert stable_poly.is_stable(fit.f)
    assert fit.sse == pytest.approx(output_error.fit_output_error(u, y).sse, rel=1e-6)


def test_analytic_jacobian_matches_finite_differences():
    u, y = _data(0.05, n=300)
    problem = output_error._Problem(u, y, 4, 3, 0, 0.999)
    rng = np.random.default_rng(4)
    x = np.concatenate([OE_B, stable_poly.eta_from_poly(OE_F, 0.999), rng.normal(size=3)])
    jac = problem.jacobian(x)
    num = np.empty_like(jac)
    for j in range(len(x)):
        d = np.zeros(len(x))
        d[j] = 1e-6
        num[:, j] = (problem.residual(x + d) - problem.residual(x - d)) / 2e-6
    np.testing.assert_allclose(jac, num, atol=1e-5 * np.max(np.abs(num)))


def test_delay_and_short_window():
    rng = np.random.default_rng(5)
    u = rng.standard_normal(800)
    y = signal.lfilter(np.concatenate([[0, 0], OE_B]), OE_F, u)
    fit = output_error.fit_output_error(u, y, 4, 3, 2)
    np.testing.assert_allclose(fit.b, OE_B, atol=1e-6)
    assert fit.nk == 2 and len(fit.b_delayed) == 6
    with pytest.raises(ValueError, match="too short"):
        output_error.fit_output_error(u[:8], y[:8])
