"""The commissioning baseline: the fault-free friction per operating condition.

`fdi baseline` replays a fault-free recording of the rig's normal operation and stores, in
the model file's ``baseline`` key, per bin of the window's velocity RMS (the operating
condition the monitor knows on every tick) two quantities of the sliding window: the
Coulomb coefficient θ1 of eq. (17) (``coulomb_*``: the level path's evidence of friction)
and the friction level (``level_*``: what the monitor reports; `QUANTITIES`). Per bin and
quantity: its median and a robust spread σ = 1.4826·MAD, with the 5th/95th percentiles; and
the time the bin holds. Bins are quantiles of the data, as many as hold ``min_seconds`` each
(at most ``max_bins``). The monitor then compares θ1 with the bin of the current velocity
RMS from its first valid window on: θ1 above median + max(``friction_min_level``, k·σ) is
friction, whatever the calibration learnt (friction present when monitoring starts); the
alarm lifecycle reads the reported level above the bin's fault-free level.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from fdi_daemon.errors import ConfigError

__all__ = ["Baseline", "fit_baseline", "QUANTITIES", "MAD_TO_SIGMA"]

MAD_TO_SIGMA = 1.4826  # σ of a normal distribution from its median absolute deviation
#: what a baseline's two quantities are (its ``quantities`` key)
QUANTITIES = {
    "coulomb": "theta1 of eq. (17) over the sliding window (1 = the calibrated fault)",
    "level": "the friction level over the sliding window: the residual's "
    "least-squares multiple of the calibrated signature's regressor "
    "g1 + gamma g2 (1 = the calibrated fault)",
}


@dataclass(frozen=True)
class Baseline:
    """Fault-free θ1 (median, σ) and friction level (median) per velocity-RMS bin;
    ``edges_mps`` has one more entry than the bins."""

    edges_mps: np.ndarray
    coulomb_median: np.ndarray
    coulomb_sigma: np.ndarray
    level_median: np.ndarray

    def bin_index(self, v_rms_mps: np.ndarray | float) -> np.ndarray:
        """The bin of each velocity RMS (the nearest bin outside the stored range)."""
        return np.clip(
            np.searchsorted(self.edges_mps, v_rms_mps, side="right") - 1,
            0,
            len(self.level_median) - 1,
        )

    @classmethod
    def from_mapping(cls, mapping: Mapping[str, Any], source: str = "model") -> Baseline:
        try:
            bins = list(mapping["bins"])
            edges = [float(b["v_rms_mps"][0]) for b in bins] + [float(bins[-1]["v_rms_mps"][1])]
            columns = [
                [float(b[key]) for b in bins]
                for key in ("coulomb_median", "coulomb_sigma", "level_median")
            ]
        except (KeyError, TypeError, IndexError, ValueError):
            raise ConfigError(
                f"{source}: baseline must hold bins with v_rms_mps [lo, hi], "
                "coulomb_median, coulomb_sigma and level_median (written by "
                "`fdi baseline`; run it again on a baseline of an older fdi)"
            ) from None
        values = np.array(edges + [v for column in columns for v in column])
        if (
            not bins
            or not np.all(np.isfinite(values))
            or np.any(np.diff(edges) <= 0)
            or min(columns[1]) < 0
        ):
            raise ConfigError(f"{source}: baseline bins must be finite, ordered, with σ >= 0")
        return cls(np.array(edges), *(np.array(column) for column in columns))


def fit_baseline(
    quantities: Mapping[str, np.ndarray],
    v_rms_mps: np.ndarray,
    fs_hz: float,
    min_seconds: float = 20.0,
    max_bins: int = 8,
) -> list[dict[str, Any]]:
    """Bins of the fault-free ``quantities`` (name: per-sample values; the samples where all
    are finite): per bin ``{name}_median``, ``{name}_sigma``, ``{name}_p5_p95``; ValueError
    when fewer than ``min_seconds`` of valid windows exist."""
    ok = np.isfinite(v_rms_mps)
    for values in quantities.values():
        ok &= np.isfinite(values)
    v_rms = np.asarray(v_rms_mps)[ok]
    per_bin = int(math.ceil(min_seconds * fs_hz))
    count = min(max_bins, v_rms.size // per_bin)
    if count < 1:
        raise ValueError(
            f"the recording holds {v_rms.size / fs_hz:.1f} s of valid windows "
            f"(the rig moving); at least {min_seconds:g} s are needed"
        )
    edges = np.unique(np.quantile(v_rms, np.linspace(0.0, 1.0, count + 1)))
    bins = []
    for i, (lo, hi) in enumerate(zip(edges[:-1], edges[1:])):
        last = i == len(edges) - 2
        sel = (v_rms >= lo) & ((v_rms <= hi) if last else (v_rms < hi))
        if not sel.any():
            continue
        one: dict[str, Any] = {"v_rms_mps": [float(lo), float(hi)]}
        for name, values in quantities.items():
            x = np.asarray(values)[ok][sel]
            med = float(np.median(x))
            p5, p95 = np.percentile(x, [5, 95])
            one[f"{name}_median"] = med
            one[f"{name}_sigma"] = float(MAD_TO_SIGMA * np.median(np.abs(x - med)))
            one[f"{name}_p5_p95"] = [float(p5), float(p95)]
        one["seconds"] = float(sel.sum() / fs_hz)
        bins.append(one)
    return bins
