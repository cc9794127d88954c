"""Replay figure in the style of the paper's Figs. 5–7 (one PNG).

Rows: measured acceleration with the fault marks (detection, and the recording's ground
truth onset when it has a ``fault_active`` column); θ1 and θ2 (eq. 17) with the calibrated
band (dashed) and the signature values 1 and γ_f (dotted); the acceleration residual
(eq. 3, Fig. 7); the detector's statistic against its threshold.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from fdi_daemon.detect.monitor import MonitorTrace
from fdi_daemon.io.outputs import pyplot, save_figure

__all__ = ["plot_replay"]

_MAX_POINTS = 20000


def _thin(n: int) -> slice:
    return slice(None, None, max(1, n // _MAX_POINTS))


def plot_replay(path: str | Path, trace: MonitorTrace, events: list[dict[str, Any]],
                gamma_f: float, band: dict[str, list[float]] | None, threshold: float,
                fault_onset_t: float | None = None, title: str = "") -> Path:
    """Write the figure; returns its path."""
    plt = pyplot()

    path = Path(path)
    sl = _thin(trace.t.size)
    t = trace.t[sl]
    fig, axes = plt.subplots(5, 1, figsize=(10, 11), sharex=True)
    ax_a, ax_1, ax_2, ax_r, ax_s = axes
    ax_a.plot(t, trace.accel[sl], lw=0.6, color="tab:blue")
    ax_a.set_ylabel("ẍ (m/s²)")
    ax_a.set_title(title or "Measured acceleration and friction model parameters")
    marks = [("fault_detected", "tab:red", "detected"),
             ("friction_isolated", "tab:green", "friction isolated"),
             ("other_fault", "tab:orange", "other fault"),
             ("cleared", "tab:gray", "cleared")]
    for kind, colour, label in marks:
        times = [e["t"] for e in events if e["kind"] == kind]
        for i, tt in enumerate(times):
            for ax in axes:
                ax.axvline(tt, color=colour, lw=0.9, ls="-", alpha=0.7,
                           label=label if (ax is ax_a and i == 0) else None)
    if fault_onset_t is not None:
        for ax in axes:
            ax.axvline(fault_onset_t, color="k", lw=1.0, ls="--",
                       label="fault onset (ground truth)" if ax is ax_a else None)
    for ax, values, name, sig, key in ((ax_1, trace.theta1, "θ1 (Coulomb)", 1.0, "theta1"),
                                       (ax_2, trace.theta2, "θ2 (viscous)", gamma_f, "theta2")):
        ax.plot(t, values[sl], lw=0.8, color="tab:purple")
        ax.axhline(sig, color="tab:green", ls=":", lw=1.2, label="signature")
        if band is not None:
            lo, hi = band[key]
            ax.axhline(lo, color="k", ls="--", lw=0.8, label="band")
            ax.axhline(hi, color="k", ls="--", lw=0.8)
        finite = values[np.isfinite(values)]
        if finite.size:
            lo_q, hi_q = np.percentile(finite, [1, 99])
            span = [min(lo_q, sig), max(hi_q, sig)]
            pad = 0.15 * (span[1] - span[0] or 1.0)
            ax.set_ylim(span[0] - pad, span[1] + pad)
        ax.set_ylabel(name)
        ax.legend(loc="upper left", fontsize=7)
    ax_r.plot(t, trace.residual[sl], lw=0.6, color="tab:brown")
    ax_r.set_ylabel("residual ẍ_r (m/s²)")
    stat = trace.statistic[sl]
    ax_s.semilogy(t, np.where(stat > 0, stat, np.nan), lw=0.6, color="tab:blue")
    ax_s.axhline(threshold, color="tab:red", ls="--", lw=0.8, label="threshold")
    ax_s.set_ylabel("statistic")
    ax_s.set_xlabel("t (s)")
    ax_s.legend(loc="upper left", fontsize=7)
    handles, labels = ax_a.get_legend_handles_labels()
    if handles:
        ax_a.legend(loc="upper left", fontsize=7)
    fig.tight_layout()
    return save_figure(fig, path)
