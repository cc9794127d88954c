"""Noise floor and dead time: what the data say before any effect is fitted.

The noise floor is the part of the gap that no model of the input can remove.

- Periodic excitation (a multisine repeated, or several realisations of a multisine each
  repeated, `repeated_input`): the output's period-to-period variation. Where the input
  one period P later is the same input, and has been for the model's warm-up, the output
  differs only by the noise: over those samples k the noise variance per sample is
  mean((y[k+P] − y[k])²)/2, and

      floor = √(noise variance) / std(y on the held-out part)        (an NRMSE, like the gap)

- Otherwise, from the spectrum of the nominal error e = y − ŷ₀: its median power density
  where the input has no power (above the band holding 99 % of the input power), taken
  as white over 0..fs/2. Effects put harmonics there too, so the median (not the
  mean) is used; where the input fills the band to fs/2 the floor is unknown (None).

The workflow names nothing when the nominal gap is within FLOOR_MARGIN of the floor.

The dead time is estimated explicitly from the peak of the measured–nominal output
cross-correlation (`delay_by_correlation`) and reported whatever is named; the refit check
(`select.linear_round`) names it when a pure shift explains the refit.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

#: a gap below FLOOR_MARGIN × floor is "at the floor": nothing is named
FLOOR_MARGIN = 1.25
#: quantile of the error's power density above the input band taken as the noise level
#: (the median: harmonics of an effect there are peaks, the noise is the floor between)
QUIET_QUANTILE = 0.5
#: an input sample "repeats" when it differs from the one a period later by less than this
#: share of the input's RMS (a measured input repeats within its noise)
REPEAT_TOLERANCE = 0.05
#: least share of the record whose input must repeat for the periodic floor
REPEAT_SHARE = 0.25


def repeated_input(
    u: np.ndarray, min_samples: int, settle: int = 0
) -> tuple[int, np.ndarray] | None:
    """(P, k): the input's period P (the autocorrelation's highest peak at a lag of at least
    ``min_samples``) and the samples k whose input repeats one period later, u[k+P] = u[k]
    within REPEAT_TOLERANCE, as have the max(settle, min_samples) − 1 samples before it
    (the model has forgotten where the inputs differed); None when they cover less than
    REPEAT_SHARE of the record. One multisine repeated repeats everywhere after
    its first period; R realisations of p periods each repeat on (p − 1)/p of the record."""
    x = np.asarray(u, float) - np.mean(u)
    n = len(x)
    if n < 3 * min_samples or not np.any(x):
        return None
    spec = np.fft.rfft(x, 2 * n)
    acf = np.fft.irfft(spec * np.conj(spec))[: n // 2 + 1]
    acf = acf / (acf[0] * (n - np.arange(acf.size)) / n)  # unbiased, normalised
    lags = np.arange(min_samples, acf.size)
    if lags.size == 0:
        return None
    period = int(lags[np.argmax(acf[lags])])
    same = np.abs(x[period:] - x[:-period]) <= REPEAT_TOLERANCE * np.sqrt(np.mean(x * x))
    # a run of min_samples at least: not a chance crossing of two different inputs
    width = max(settle, min_samples)
    run = np.convolve(same, np.ones(width), "full")[: same.size]
    kept = np.flatnonzero(run >= width)
    if kept.size < REPEAT_SHARE * n:
        return None
    return period, kept


def noise_floor(
    y: np.ndarray, e: np.ndarray, u: np.ndarray, fs_hz: float, warmup: int, test: slice
) -> dict:
    """``{"floor": NRMSE or None, "method": ..., ...}`` for the output y (comparison
    domain) with nominal error e; warmup: samples the model needs to forget its past."""
    y = np.asarray(y, float)
    spread = float(np.std(y[test]))
    if spread == 0.0:
        return {"floor": None, "method": "none"}
    repeated = repeated_input(u, max(8, int(0.2 * fs_hz)), warmup)
    if repeated is not None:
        period, k = repeated
        var = 0.5 * float(np.mean((y[k + period] - y[k]) ** 2))
        return {
            "floor": math.sqrt(var) / spread,
            "method": "periodic",
            "period_s": period / fs_hz,
            "repeated_share": k.size / len(y),
        }
    variance, f_hi = quiet_variance(u, e, fs_hz, test)
    if f_hi is None:
        return {"floor": None, "method": "none"}
    return {
        "floor": None if variance is None else math.sqrt(variance) / spread,
        "method": "spectrum",
        "input_band_hz": f_hi,
    }


def quiet_variance(
    u: np.ndarray, e: np.ndarray, fs_hz: float, test: slice
) -> tuple[float | None, float | None]:
    """(variance, f_hi): the variance of white noise in e from its power density where the
    input has no power (the QUIET_QUANTILE above 1.5 × f_hi, f_hi the band holding 99 % of
    the input power), taken as white over 0..fs/2; None when the input fills the band
    (f_hi None: no input at all)."""
    x = np.asarray(u, float)[test] - np.mean(u[test])
    nper = min(len(x), 256)  # many averages: a steady level estimate
    f, pu = signal.welch(x, fs=fs_hz, nperseg=nper)
    _, pe = signal.welch(np.asarray(e, float)[test], fs=fs_hz, nperseg=nper)
    if not np.sum(pu) > 0:
        return None, None
    cum = np.cumsum(pu) / np.sum(pu)
    f_hi = float(f[min(np.searchsorted(cum, 0.99), f.size - 1)])
    quiet = f > 1.5 * f_hi
    if np.count_nonzero(quiet) < 8:
        return None, f_hi
    return float(np.quantile(pe[quiet], QUIET_QUANTILE)) * fs_hz / 2.0, f_hi


def delay_by_correlation(y: np.ndarray, y0: np.ndarray, fs_hz: float, max_lag: int) -> float:
    """Dead time (s) from the cross-correlation of the measured and the nominal output:
    the lag of its peak within ±max_lag samples, refined by a parabola through the peak
    and its neighbours. Positive: the measurement lags the model."""
    a = np.asarray(y, float) - np.mean(y)
    b = np.asarray(y0, float) - np.mean(y0)
    n = len(a)
    spec = np.fft.rfft(a, 2 * n) * np.conj(np.fft.rfft(b, 2 * n))
    full = np.fft.irfft(spec)
    lags = np.arange(-max_lag, max_lag + 1)
    r = full[lags % (2 * n)]
    k = int(np.argmax(r))
    shift = 0.0
    if 0 < k < r.size - 1:
        den = r[k - 1] - 2 * r[k] + r[k + 1]
        shift = 0.5 * (r[k - 1] - r[k + 1]) / den if den != 0 else 0.0
    return float((lags[k] + shift) / fs_hz)
