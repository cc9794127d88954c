"""Weighted rational fit, eq. (2): Levy/SK start, LM refinement, enforced stability."""

import numpy as np
import pytest
from conftest_ident import FS, PLANT_POLES, PLANT_ZEROS, match_roots, plant, plant_output

from fdi_daemon.ident import rational_fit, spectral, stable_poly


def test_exact_response_gives_exact_coefficients():
    b, a = plant()
    f = np.linspace(0.5, 100, 200)
    fit = rational_fit.fit_rational(f, rational_fit.frequency_response(b, a, f, FS), FS, 4)
    np.testing.assert_allclose(fit.a, a, atol=1e-7)
    np.testing.assert_allclose(fit.b, b, atol=1e-8)
    assert fit.b[0] == 0.0


@pytest.mark.parametrize("noise", [0.0, 0.01, 0.03])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_poles_and_zeros_from_a_spectral_estimate(noise, seed):
    """Tolerance: 0.03 for the lag window's smoothing bias, plus a term growing with noise."""
    rng = np.random.default_rng(100 + seed)
    u = rng.standard_normal(8192)
    y = plant_output(u, noise, seed)
    fr = spectral.blackman_tukey(u, y, FS, 256)
    sel = (fr.freq_hz >= 0.5) & (fr.freq_hz <= 120)
    fit = rational_fit.fit_rational(fr.freq_hz[sel], fr.G[sel], FS, 4)
    assert match_roots(fit.poles, PLANT_POLES) < 0.03 + 2.5 * noise
    assert match_roots(fit.zeros, PLANT_ZEROS) < 0.03 + 3.0 * noise
    assert np.all(np.abs(fit.poles) < 1)


def test_unstable_data_give_a_stable_model():
    """G = q⁻¹/(1 - 1.2 q⁻¹) has a pole outside the unit circle. The start reflects it to
    1/1.2 (same |G| on the circle); the refinement must stay stable and do at least as well
    as that reflected start on the weighted cost."""
    f = np.linspace(0.5, 120, 300)
    G = rational_fit.frequency_response([0, 1.0], [1, -1.2], f, FS)
    fit = rational_fit.fit_rational(f, G, FS, 1)
    assert fit.reflected_poles >= 1
    assert np.all(np.abs(fit.poles) < 1)
    start = rational_fit.frequency_response([0, 1.0 / 1.2], [1, -1.0 / 1.2], f, FS)
    start_cost = np.sum(np.abs((start - G) / G) ** 2)
    assert fit.cost <= start_cost * (1 + 1e-9)


def test_pole_radius_bound_is_respected():
    b, a = plant()
    f = np.linspace(0.5, 100, 200)
    fit = rational_fit.fit_rational(
        f, rational_fit.frequency_response(b, a, f, FS), FS, 4, max_pole_radius=0.88
    )
    assert np.max(np.abs(fit.poles)) < 0.88


def test_too_few_points_is_an_error():
    with pytest.raises(ValueError, match="too few"):
        rational_fit.fit_rational([1.0, 2.0], np.array([1 + 1j, 2 + 0j]), FS, 4)


def test_reflection_parameterisation_round_trip():
    a = np.real(np.poly(PLANT_POLES))
    np.testing.assert_allclose(
        stable_poly.poly_from_eta(stable_poly.eta_from_poly(a)), a, atol=1e-12
    )
    rng = np.random.default_rng(3)
    for _ in range(20):
        poly = stable_poly.poly_from_eta(rng.normal(scale=1, size=5), radius=0.95)
        assert np.max(np.abs(np.roots(poly))) < 0.95


def test_reflect_unstable_keeps_the_magnitude():
    b, a = [0, 1.0, 0.3], np.real(np.poly([1.5, 0.5]))
    b2, a2, count = stable_poly.reflect_unstable(np.array(b), a)
    assert count == 1 and stable_poly.is_stable(a2)
    f = np.linspace(1, 120, 50)
    np.testing.assert_allclose(
        np.abs(rational_fit.frequency_response(b2, a2, f, FS)),
        np.abs(rational_fit.frequency_response(b, a, f, FS)),
        rtol=1e-7,
    )
