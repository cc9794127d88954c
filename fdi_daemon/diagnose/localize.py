"""Where the nominal model's simulation error e = y − ŷ₀ sits: in time, in state, in frequency.

- time: the record cut into segments (1 s, or 1/40 of the record if longer), ranked by RMS
  error; each with its ratio to the median segment;
- state: e binned by simulated velocity (signed, so a friction step at v = 0 shows as a
  jump of the bin means), position and input level (8 quantile bins each); ``explained`` is
  the share of e's variance carried by the bin means (η², correlation ratio): large when the
  error is a function of that state;
- frequency: Welch spectra of e and of y; the bands (third-octave) with the largest share of
  error power, with the error-to-output ratio there; the residual–input cross-correlation on
  the held-out part with its 99 % band (`ident.validation`); whiteness of e by the
  Ljung–Box test over 25 lags.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import signal, stats

from fdi_daemon.ident.validation import residual_input_correlation

N_BINS = 8
N_TOP = 5
LJUNG_BOX_LAGS = 25


def time_segments(e: np.ndarray, fs_hz: float, top: int = N_TOP) -> list[dict]:
    n = len(e)
    seg = max(int(round(fs_hz)), n // 40, 2)
    rows = []
    for start in range(0, n - seg + 1, seg):
        rows.append((float(np.sqrt(np.mean(e[start : start + seg] ** 2))), start))
    if not rows:
        return []
    median = float(np.median([r for r, _ in rows])) or 1.0
    rows.sort(reverse=True)
    return [
        {
            "kind": "time",
            "t0": s / fs_hz,
            "t1": (s + seg) / fs_hz,
            "rms": r,
            "ratio_to_median": r / median,
        }
        for r, s in rows[:top]
    ]


def state_bins(e: np.ndarray, values: np.ndarray, name: str, signed: bool = False) -> dict:
    """Mean and RMS of e per quantile bin of ``values``; η² = share of variance in bin means."""
    values = np.asarray(values, float)
    if signed:
        levels = np.linspace(0, 1, N_BINS // 2 + 1)
        neg = np.quantile(values[values < 0], levels)[:-1] if np.any(values < 0) else []
        pos = np.quantile(values[values > 0], levels)[1:] if np.any(values > 0) else []
        edges = np.unique(np.concatenate([neg, [0.0], pos]))
    else:
        edges = np.unique(np.quantile(values, np.linspace(0, 1, N_BINS + 1)))
    if edges.size < 2:
        return {"kind": "state", "variable": name, "explained": 0.0, "bins": []}
    idx = np.clip(np.searchsorted(edges, values, side="right") - 1, 0, edges.size - 2)
    total = float(np.sum((e - e.mean()) ** 2)) or 1.0
    between = 0.0
    bins: list[dict[str, Any]] = []
    for k in range(edges.size - 1):
        sel = idx == k
        if not sel.any():
            continue
        mean = float(e[sel].mean())
        between += sel.sum() * (mean - e.mean()) ** 2
        bins.append(
            {
                "range": [float(edges[k]), float(edges[k + 1])],
                "mean": mean,
                "rms": float(np.sqrt(np.mean(e[sel] ** 2))),
                "samples": int(sel.sum()),
            }
        )
    worst = max(bins, key=lambda b: b["rms"])
    return {
        "kind": "state",
        "variable": name,
        "explained": float(between / total),
        "worst_range": worst["range"],
        "worst_rms": worst["rms"],
        "bins": bins,
    }


def frequency_bands(e: np.ndarray, y: np.ndarray, fs_hz: float, top: int = 3) -> tuple[list, dict]:
    nper = min(len(e), 1024)
    f, p_e = signal.welch(e, fs=fs_hz, nperseg=nper)
    _, p_y = signal.welch(y, fs=fs_hz, nperseg=nper)
    lo = max(f[1], fs_hz / nper)
    edges = [lo]
    while edges[-1] * 2 ** (1 / 3) < fs_hz / 2:
        edges.append(edges[-1] * 2 ** (1 / 3))
    edges.append(fs_hz / 2)
    total = float(np.sum(p_e[1:])) or 1.0
    bands: list[dict[str, Any]] = []
    for f0, f1 in zip(edges[:-1], edges[1:]):
        sel = (f >= f0) & (f < f1)
        if not sel.any():
            continue
        pe, py = float(np.sum(p_e[sel])), float(np.sum(p_y[sel]))
        bands.append(
            {
                "kind": "frequency",
                "f0": float(f0),
                "f1": float(f1),
                "error_power_fraction": pe / total,
                "error_to_output": math.sqrt(pe / py) if py > 0 else math.inf,
            }
        )
    bands.sort(key=lambda b: -b["error_power_fraction"])
    spectrum = {"f_hz": f, "error_psd": p_e, "output_psd": p_y}
    return bands[:top], spectrum


def whiteness(e: np.ndarray, lags: int = LJUNG_BOX_LAGS) -> dict:
    """Ljung–Box Q over ``lags`` autocorrelations; small p: the error is not white."""
    x = np.asarray(e, float) - np.mean(e)
    n = len(x)
    var = float(x @ x)
    if var == 0.0 or n <= lags + 1:
        return {"ljung_box_q": 0.0, "lags": lags, "p_value": 1.0, "white": True}
    rho = np.array([float(x[k:] @ x[:-k]) / var for k in range(1, lags + 1)])
    q = float(n * (n + 2) * np.sum(rho**2 / (n - np.arange(1, lags + 1))))
    p = float(stats.chi2.sf(q, lags))
    return {"ljung_box_q": q, "lags": lags, "p_value": p, "white": bool(p >= 0.01)}


def localize(
    e: np.ndarray,
    y: np.ndarray,
    u: np.ndarray,
    v: np.ndarray,
    x: np.ndarray,
    fs_hz: float,
    test: slice,
) -> dict:
    """All three views; ``regions`` is the ranked list the report carries."""
    segments = time_segments(e, fs_hz)
    states = [
        state_bins(e, v, "velocity", signed=True),
        state_bins(e, x, "position"),
        state_bins(e, u, "input"),
    ]
    bands, spectrum = frequency_bands(e, y, fs_hz)
    max_lag = int(min(max(25, round(0.1 * fs_hz)), len(e[test]) // 4))
    xc = residual_input_correlation(e[test], u[test], max_lag=max_lag)
    states_sorted = sorted(states, key=lambda s: -s["explained"])
    regions = (
        segments + [{k: v for k, v in s.items() if k != "bins"} for s in states_sorted] + bands
    )
    return {
        "regions": regions,
        "states": states_sorted,
        "spectrum": spectrum,
        "cross_correlation": {
            "max_abs": xc["max_abs"],
            "bound_99": xc["bound"],
            "fraction_outside": xc["fraction_outside"],
            "lags": xc["lags"],
            "r": xc["r"],
        },
        "whiteness": whiteness(e[test]),
    }
