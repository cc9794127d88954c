"""Spectral estimates (Blackman–Tukey, Welch H1), lag-window choice and band selection."""

import numpy as np
import pytest
from conftest_ident import FS, chirp, plant, plant_output

from fdi_daemon.ident import rational_fit, spectral


def _direct_bt(u, y, lag, freq_hz):
    """Independent reference: explicit covariance sums and a direct Fourier sum."""
    u = u - u.mean()
    y = y - y.mean()
    n = len(u)
    taus = np.arange(-lag, lag + 1)
    w = 0.5 * (1 + np.cos(np.pi * taus / lag))

    def cov(a, b, tau):
        return (
            np.sum(a[tau:] * b[: n - tau]) / n if tau >= 0 else np.sum(a[: n + tau] * b[-tau:]) / n
        )

    r_yu = np.array([cov(y, u, t) for t in taus])
    r_uu = np.array([cov(u, u, t) for t in taus])
    omega = 2 * np.pi * np.asarray(freq_hz) / FS
    e = np.exp(-1j * np.outer(omega, taus))
    return (e @ (w * r_yu)) / (e @ (w * r_uu))


def test_blackman_tukey_matches_direct_sums():
    rng = np.random.default_rng(1)
    u = rng.standard_normal(300)
    y = plant_output(u, 0.05, seed=3)
    fr = spectral.blackman_tukey(u, y, FS, 40)
    pick = [3, 17, 40, 90]
    ref = _direct_bt(u, y, 40, fr.freq_hz[pick])
    np.testing.assert_allclose(fr.G[pick], ref, rtol=1e-10)


def test_blackman_tukey_and_welch_find_the_known_response():
    rng = np.random.default_rng(7)
    u = rng.standard_normal(8192)
    y = plant_output(u, 0.01, seed=7)
    b, a = plant()
    for fr in (spectral.blackman_tukey(u, y, FS, 256), spectral.welch_h1(u, y, FS)):
        sel = (fr.freq_hz > 1) & (fr.freq_hz < 30)
        true = rational_fit.frequency_response(b, a, fr.freq_hz[sel], FS)
        rel = np.abs(fr.G[sel] - true) / np.abs(true)
        assert np.median(rel) < 0.03, fr.method
        assert np.min(fr.coherence[sel]) > 0.9


def test_lag_window_grows_when_noise_falls():
    u = chirp(1024)
    chosen = [
        spectral.select_lag_window(u, plant_output(u, noise, seed=4), FS)[0]
        for noise in (1.0, 0.01)
    ]
    assert chosen[0] < chosen[1]


def test_band_of_a_chirp_lies_inside_its_sweep():
    u = chirp(1024, f1_hz=20.0)
    y = plant_output(u, 0.02, seed=5)
    m, _ = spectral.select_lag_window(u, y, FS)
    lo, hi = spectral.informative_band(spectral.blackman_tukey(u, y, FS, m))
    assert 0 < lo < 3.0
    assert 15.0 < hi < 22.0


def test_no_band_when_output_is_unrelated_noise():
    rng = np.random.default_rng(9)
    u = chirp(1024)
    y = rng.standard_normal(1024)
    fr = spectral.blackman_tukey(u, y, FS, 32)
    with pytest.raises(ValueError, match="no informative band"):
        spectral.informative_band(fr)


def test_lag_window_shapes():
    hann = spectral.lag_window("hann", 10)
    assert hann[10] == 1.0 and hann[0] == pytest.approx(0.0)
    hamming = spectral.lag_window("hamming", 10)
    assert hamming[0] == pytest.approx(0.08)
    with pytest.raises(ValueError):
        spectral.lag_window("boxcar", 10)
