"""CUSUM for a shift of one regression coefficient (Basseville & Nikiforov, §2.2 and §8.1).

The innovation e_k of a reference model with residual variance σ² is tested for a shift δ
of its coefficient along a regressor s_k: under H0, e_k ~ N(0, σ²); under H1,
e_k ~ N(δ s_k, σ²). The log-likelihood ratio of one sample is

    ℓ_k = (δ s_k e_k − δ² s_k² / 2) / σ²                                   (LLR)

and Page's CUSUM  S_k = max(0, S_{k−1} + ℓ_k)  alarms at S_k > h. For independent
innovations the mean time between false alarms is at least e^h samples (Lorden 1971), so
h = ln(ARL₀) states the false-alarm rate; under a shift Δ of the coefficient S grows by
(δΔ − δ²/2) s²/σ² per sample on average, i.e. only when Δ > δ/2.

Pure numerics, no state of its own: the compiled kernels keep S in their arena
(`detect.kernel`); ``cusum_run`` is the plain reference used by the tests.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from fdi_daemon.core.compiled import jit

__all__ = ["cusum_increment", "cusum_threshold", "cusum_run", "SECONDS_PER_YEAR"]

SECONDS_PER_YEAR = 365.25 * 86400.0


@jit(inline=True)
def cusum_increment(
    e: float, s: float, inv_sigma2: float, shift: float
) -> float:  # pragma: no cover - jit
    """ℓ of eq. (LLR): innovation ``e``, regressor ``s``, 1/σ², shift δ (same units as
    the coefficient)."""
    return shift * s * (e - 0.5 * shift * s) * inv_sigma2


def cusum_threshold(false_alarm_years: float, fs_hz: float) -> float:
    """h = ln(ARL₀) for a mean time between false alarms of ``false_alarm_years`` at
    ``fs_hz`` samples per second (Lorden's bound for independent innovations)."""
    return math.log(false_alarm_years * SECONDS_PER_YEAR * fs_hz)


def cusum_run(
    e: ArrayLike, s: ArrayLike, sigma2: ArrayLike, shift: float, start: float = 0.0
) -> np.ndarray:
    """S_k of Page's CUSUM over arrays (plain Python reference, one sample at a time)."""
    e, s, sigma2 = (np.asarray(x, dtype=float) for x in (e, s, sigma2))
    out = np.empty(e.size)
    total = float(start)
    for k, (ek, sk, vk) in enumerate(zip(e, s, sigma2, strict=True)):
        total = max(0.0, total + shift * sk * (ek - 0.5 * shift * sk) / vk)
        out[k] = total
    return out
