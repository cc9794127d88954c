"""Butterworth design in NumPy alone: the steps of ``scipy.signal.butter(..., output="ba")``
(analog prototype, pre-warped cut-off, low/high-pass transform, bilinear transform, zeros
and poles to polynomials), in the same order of operations, so the coefficients are
scipy's to the last bit (`tests/test_core_filter_design.py` checks that).

Why not scipy: importing ``scipy.signal`` takes longer than everything else `fdi replay`
of a short file does (0.6 s of its 1.5 s on the shared 2-core machine, ``python -X
importtime``), and the monitor needs only these few lines of it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["butter"]


def butter(
    order: int, cutoff_hz: float, fs: float, btype: str = "low"
) -> tuple[np.ndarray, np.ndarray]:
    """(b, a) of a digital Butterworth low-pass (``btype`` "low") or high-pass ("high") of
    ``order`` with its -3 dB point at ``cutoff_hz`` for the sample rate ``fs`` (Hz);
    ValueError outside 0 < cutoff_hz < fs/2, as scipy."""
    if btype not in ("low", "high"):
        raise ValueError(f"btype must be 'low' or 'high', not {btype!r}")
    if int(order) != order or order < 0:
        raise ValueError("Filter order must be a nonnegative integer")
    wn = np.float64(cutoff_hz) / (float(fs) / 2)
    if not 0 < wn < 1:
        raise ValueError(
            f"Digital filter critical frequencies must be 0 < Wn < fs/2 (fs={fs} -> fs/2={fs / 2})"
        )
    # analog prototype (buttap): unit cut-off, no zeros
    m = np.arange(-order + 1, order, 2, dtype=np.float64)
    p = -np.exp(1j * np.pi * m / (2 * order))
    z = np.zeros(0, dtype=np.float64)
    k = 1.0
    fs2 = 2.0  # scipy works on the normalised rate
    warped = float(2 * fs2 * np.tan(np.pi * wn / fs2))
    degree = p.shape[0] - z.shape[0]
    if btype == "low":  # lp2lp_zpk
        z, p, k = warped * z, warped * p, k * warped**degree
    else:  # lp2hp_zpk
        k = k * np.real(np.prod(-z) / np.prod(-p))
        z = np.concatenate((warped / z, np.zeros(degree)))
        p = warped / p
    # bilinear_zpk at fs = 2
    degree = p.shape[0] - z.shape[0]
    two_fs = 2.0 * fs2
    z_z = np.concatenate(((two_fs + z) / (two_fs - z), -np.ones(degree)))
    p_z = (two_fs + p) / (two_fs - p)
    k_z = k * np.real(np.prod(two_fs - z) / np.prod(two_fs - p))
    # zpk2tf
    b = np.multiply(k_z, _poly(z_z))
    a = _poly(p_z)
    return np.atleast_1d(b), np.atleast_1d(a)


def _poly(roots: np.ndarray) -> np.ndarray:
    """The monic polynomial with these roots (`numpy.poly`, real when they pair up)."""
    out = np.ones((1,), dtype=roots.dtype)
    for root in roots:
        out = np.convolve(out, np.stack((np.ones_like(root), -root)), mode="full")
    if np.iscomplexobj(out):
        r = np.asarray(roots, dtype=np.complex128)
        if np.all(np.sort(np.imag(r)) == np.sort(np.imag(np.conj(r)))):
            out = np.real(out).copy()
    return out
