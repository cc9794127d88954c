"""Validation of an identified plant on data not used for fitting.

- `simulate`: ŷ = B/A u with the initial state estimated by least squares (the recording need
  not start at rest) and the means of y and ŷ removed (a sensor offset is not dynamics);
- `fit_percent`: 100·(1 − ‖y − ŷ‖/‖y − ȳ‖), MATLAB ``compare``'s NRMSE fit;
- `residual_input_correlation`: normalised cross-correlation of the simulation error with
  the input and its 99 % confidence band ±2.576/√N (error uncorrelated with the input =
  the dynamics are captured);
- `band_errors`: relative error |Ĝ − G|/|G| per frequency band.
"""

from __future__ import annotations

import numpy as np
from scipy import signal

#: two-sided 99 % quantile of the standard normal distribution
Z_99 = 2.5758293035489


def free_responses(a: np.ndarray, n_samples: int) -> np.ndarray:
    """Columns: the responses of 1/A to a unit pulse at t = 0..n-1 (n = order of A).

    Any initial state of an order-n filter adds a combination of these columns.
    """
    order = len(a) - 1
    basis = np.zeros((n_samples, order))
    pulse = np.zeros(n_samples)
    for k in range(min(order, n_samples)):
        pulse[:] = 0.0
        pulse[k] = 1.0
        basis[:, k] = signal.lfilter([1.0], a, pulse)
    return basis


def simulate(
    b: np.ndarray,
    a: np.ndarray,
    u: np.ndarray,
    y: np.ndarray | None = None,
) -> np.ndarray:
    """Simulated output B/A u; with `y`, the initial state and mean that fit y best are added."""
    u = np.asarray(u, dtype=float)
    y_sim = signal.lfilter(b, a, u)
    if y is None:
        return y_sim
    y = np.asarray(y, dtype=float)
    basis = np.column_stack([free_responses(a, len(u)), np.ones(len(u))])
    coef = np.linalg.lstsq(basis, y - y_sim, rcond=None)[0]
    return y_sim + basis @ coef


def fit_percent(y: np.ndarray, y_sim: np.ndarray) -> float:
    """100·(1 − NRMSE) with NRMSE = ‖y − ŷ‖/‖y − mean(y)‖."""
    y = np.asarray(y, dtype=float)
    spread = np.linalg.norm(y - y.mean())
    if spread == 0:
        raise ValueError("output is constant: fit % is undefined")
    return float(100.0 * (1.0 - np.linalg.norm(y - y_sim) / spread))


def residual_input_correlation(
    residual: np.ndarray,
    u: np.ndarray,
    max_lag: int = 25,
) -> dict:
    """r_eu(τ) for τ = -max_lag..max_lag, normalised, with the 99 % band ±2.576/√N."""
    e = np.asarray(residual, dtype=float) - np.mean(residual)
    x = np.asarray(u, dtype=float) - np.mean(u)
    n = len(e)
    norm = np.sqrt(np.sum(e * e) * np.sum(x * x))
    full = signal.correlate(e, x, mode="full", method="fft")
    mid = n - 1
    lags = np.arange(-max_lag, max_lag + 1)
    r = full[mid - max_lag : mid + max_lag + 1] / norm if norm > 0 else np.zeros(len(lags))
    bound = Z_99 / np.sqrt(n)
    return {
        "lags": lags,
        "r": r,
        "bound": float(bound),
        "max_abs": float(np.max(np.abs(r))),
        "fraction_outside": float(np.mean(np.abs(r) > bound)),
    }


def band_errors(
    freq_hz: np.ndarray, G_data: np.ndarray, G_model: np.ndarray, edges_hz: list[float]
) -> list[dict]:
    """RMS relative error |Ĝ − G|/|G| in each band [edges[i], edges[i+1])."""
    out = []
    mag = np.abs(G_data)
    for lo, hi in zip(edges_hz[:-1], edges_hz[1:]):
        sel = (freq_hz >= lo) & (freq_hz < hi) & (mag > 0)
        if not sel.any():
            continue
        rel = np.abs(G_model[sel] - G_data[sel]) / mag[sel]
        out.append(
            {
                "band_hz": [float(lo), float(hi)],
                "rms_relative_error": float(np.sqrt(np.mean(rel**2))),
                "points": int(sel.sum()),
            }
        )
    return out
