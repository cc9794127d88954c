"""The commissioning baseline: the fault-free friction level per operating condition.

`fdi baseline` replays a fault-free recording of the rig's normal operation and stores, in
the model file's ``baseline`` key, the friction level θ1 (eq. 17 over the sliding window) in
bins of the window's velocity RMS (the operating condition the monitor knows on every tick):
per bin its median and a robust spread σ = 1.4826·MAD, with the 5th/95th percentiles and
the time it holds. Bins are quantiles of the data, as many as hold ``min_seconds`` each (at
most ``max_bins``). The monitor then compares θ1 with the bin of the current velocity RMS
from its first valid window on: θ1 above median + max(``friction_min_level``, k·σ) is
friction, whatever the calibration learnt (friction present when monitoring starts).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from fdi_daemon.errors import ConfigError

__all__ = ["Baseline", "fit_baseline", "MAD_TO_SIGMA"]

MAD_TO_SIGMA = 1.4826  # σ of a normal distribution from its median absolute deviation


@dataclass(frozen=True)
class Baseline:
    """Fault-free θ1 per velocity-RMS bin; ``edges_mps`` has one more entry than the bins."""

    edges_mps: np.ndarray
    median: np.ndarray
    sigma: np.ndarray

    def bin_index(self, v_rms_mps: np.ndarray | float) -> np.ndarray:
        """The bin of each velocity RMS (the nearest bin outside the stored range)."""
        return np.clip(np.searchsorted(self.edges_mps, v_rms_mps, side="right") - 1,
                       0, len(self.median) - 1)

    @classmethod
    def from_mapping(cls, mapping: Mapping[str, Any], source: str = "model") -> "Baseline":
        try:
            bins = list(mapping["bins"])
            edges = [float(b["v_rms_mps"][0]) for b in bins] + [float(bins[-1]["v_rms_mps"][1])]
            median = [float(b["level_median"]) for b in bins]
            sigma = [float(b["level_sigma"]) for b in bins]
        except (KeyError, TypeError, IndexError, ValueError):
            raise ConfigError(f"{source}: baseline must hold bins with v_rms_mps [lo, hi], "
                              "level_median and level_sigma (written by `fdi baseline`)") from None
        values = np.array(edges + median + sigma)
        if not bins or not np.all(np.isfinite(values)) or np.any(np.diff(edges) <= 0) \
                or min(sigma) < 0:
            raise ConfigError(f"{source}: baseline bins must be finite, ordered, with σ >= 0")
        return cls(np.array(edges), np.array(median), np.array(sigma))


def fit_baseline(level: np.ndarray, v_rms_mps: np.ndarray, fs_hz: float,
                 min_seconds: float = 20.0, max_bins: int = 8) -> list[dict[str, Any]]:
    """Bins of the fault-free level (finite samples only); ValueError when fewer than
    ``min_seconds`` of valid windows exist."""
    ok = np.isfinite(level) & np.isfinite(v_rms_mps)
    level, v_rms = np.asarray(level)[ok], np.asarray(v_rms_mps)[ok]
    per_bin = int(math.ceil(min_seconds * fs_hz))
    count = min(max_bins, level.size // per_bin)
    if count < 1:
        raise ValueError(f"the recording holds {level.size / fs_hz:.1f} s of valid windows "
                         f"(the rig moving); at least {min_seconds:g} s are needed")
    edges = np.unique(np.quantile(v_rms, np.linspace(0.0, 1.0, count + 1)))
    bins = []
    for i, (lo, hi) in enumerate(zip(edges[:-1], edges[1:])):
        last = i == len(edges) - 2
        sel = (v_rms >= lo) & ((v_rms <= hi) if last else (v_rms < hi))
        x = level[sel]
        if x.size == 0:
            continue
        med = float(np.median(x))
        p5, p95 = np.percentile(x, [5, 95])
        bins.append({"v_rms_mps": [float(lo), float(hi)],
                     "level_median": med,
                     "level_sigma": float(MAD_TO_SIGMA * np.median(np.abs(x - med))),
                     "level_p5_p95": [float(p5), float(p95)],
                     "seconds": float(x.size / fs_hz)})
    return bins
