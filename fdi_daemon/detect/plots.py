"""Replay figure in the style of the paper's Figs. 5–7 (one PNG).

Rows: measured acceleration with the fault marks (detection, and the recording's ground
truth onset when it has a ``fault_active`` column); θ1 and θ2 (eq. 17) with the calibrated
band (shaded, edges dashed) and the signature values 1 and γ_f (dotted); the acceleration
residual (eq. 3, Fig. 7); the detector's statistic against its threshold. Every row marks the
calibration period (whatever happens there is learnt as normal, so a fault already present
raises no alarm: the figure says so when the ground truth shows one) and the data gaps.
Legends sit to the right of the rows, off the data.
"""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Any

import numpy as np

from fdi_daemon.detect.monitor import MonitorTrace
from fdi_daemon.io.outputs import pyplot, save_figure

__all__ = ["plot_replay", "replay_figure", "calibration_spans", "gap_spans"]

_MAX_POINTS = 20000
CALIBRATION_NOTE = (
    "calibrated on these data: a fault present here is learnt as normal, so it raises no alarm"
)


def _thin(n: int) -> slice:
    return slice(None, None, max(1, n // _MAX_POINTS))


def _sample_period(trace: MonitorTrace) -> float:
    """Seconds per recorded sample (the trace keeps every ``every``-th)."""
    if trace.t.size < 2:
        return 0.0
    return float(np.median(np.diff(trace.t))) / max(1, trace.every)


def _broken_at_gaps(t: np.ndarray, *series: np.ndarray) -> tuple[np.ndarray, ...]:
    """`t` and `series` with a NaN after every step longer than 1.5 sample periods, so that
    no line is drawn across a data gap."""
    if t.size < 2:
        return (t, *series)
    after = np.flatnonzero(np.diff(t) > 1.5 * np.median(np.diff(t))) + 1
    return tuple(np.insert(np.asarray(x, dtype=float), after, np.nan) for x in (t, *series))


def calibration_spans(events: list[dict[str, Any]], period_s: float) -> list[tuple[float, float]]:
    """(start, end) in s of each calibration: the ``samples`` before a ``calibrated`` event."""
    return [
        (e["t"] - e.get("samples", 0) * period_s, e["t"])
        for e in events
        if e["kind"] == "calibrated"
    ]


def gap_spans(events: list[dict[str, Any]], period_s: float) -> list[tuple[float, float]]:
    """(start, end) in s of each data gap: ``missing_samples`` before the ``data_gap`` event."""
    return [
        (e["t"] - (e.get("missing_samples", 0) + 1) * period_s, e["t"])
        for e in events
        if e["kind"] == "data_gap"
    ]


#: θ2 "departs" from γ_f·θ1 when their median relative difference, where θ1 reads a fault
#: (above half a calibrated fault), exceeds this
DEPARTURE = 0.5


def _departs_from_signature(theta1: np.ndarray, theta2: np.ndarray, gamma_f: float) -> bool:
    """Whether θ2 leaves the signature's line γ_f·θ1 while θ1 reads a fault."""
    faulty = np.isfinite(theta1) & np.isfinite(theta2) & (theta1 > 0.5)
    if not faulty.any() or gamma_f == 0:
        return False
    along = gamma_f * theta1[faulty]
    return bool(np.median(np.abs(theta2[faulty] - along) / np.abs(along)) > DEPARTURE)


def replay_figure(
    trace: MonitorTrace,
    events: list[dict[str, Any]],
    gamma_f: float,
    band: dict[str, list[float]] | None,
    threshold: float,
    fault_onset_t: float | None = None,
    title: str = "",
) -> Any:
    """The figure (matplotlib Figure, not yet saved)."""
    plt = pyplot()
    sl = _thin(trace.t.size)
    t, accel, theta1, theta2, residual, stat, level = _broken_at_gaps(
        trace.t[sl],
        trace.accel[sl],
        trace.theta1[sl],
        trace.theta2[sl],
        trace.residual[sl],
        trace.statistic[sl],
        trace.friction_level[sl],
    )
    period_s = _sample_period(trace)
    fig, axes = plt.subplots(5, 1, figsize=(11, 11.5), sharex=True, constrained_layout=True)
    ax_a, ax_1, ax_2, ax_r, ax_s = axes
    ax_a.plot(t, accel, lw=0.6, color="tab:blue", label="ẍ measured")
    ax_a.set_ylabel("ẍ (m/s²)")
    n_alarms = sum(e["kind"] == "fault_detected" for e in events)
    ax_a.set_title(
        (title or "Measured acceleration and friction model parameters")
        + ("" if n_alarms else "  —  no alarm")
    )

    calibrations = calibration_spans(events, period_s)
    gaps = gap_spans(events, period_s)
    for ax in axes:
        for i, (t0, t1) in enumerate(calibrations):
            ax.axvspan(
                t0,
                t1,
                color="tab:cyan",
                alpha=0.15,
                lw=0,
                label="calibration (learnt as normal)" if i == 0 else None,
            )
        for i, (t0, t1) in enumerate(gaps):
            ax.axvspan(
                t0,
                t1,
                facecolor="none",
                edgecolor="0.3",
                hatch="///",
                lw=0,
                label="data gap" if i == 0 else None,
            )
    marks = [
        ("fault_detected", "tab:red", "detected"),
        ("friction_isolated", "tab:green", "friction isolated"),
        ("other_fault", "tab:orange", "other fault"),
        ("cleared", "tab:gray", "cleared"),
    ]
    for kind, colour, label in marks:
        times = [e["t"] for e in events if e["kind"] == kind]
        for i, tt in enumerate(times):
            for ax in axes:
                ax.axvline(
                    tt, color=colour, lw=0.9, ls="-", alpha=0.7, label=label if i == 0 else None
                )
    if fault_onset_t is not None:
        for ax in axes:
            ax.axvline(fault_onset_t, color="k", lw=1.0, ls="--", label="fault onset (truth)")
        if any(fault_onset_t < t1 for _, t1 in calibrations):  # in the margin, off the data
            ax_a.text(
                1.01,
                0.0,
                textwrap.fill(CALIBRATION_NOTE, 34),
                transform=ax_a.transAxes,
                ha="left",
                va="bottom",
                fontsize=7.5,
                color="tab:red",
            )

    # the reported friction level (calibrated faults) beside θ1, in the dashboard's magenta
    ax_1.plot(
        t,
        level,
        lw=1.6,
        color="magenta",
        label="friction level: the reported reading\n(θ held to the signature (1, γ_f))",
    )
    # where the free fit leaves the signature's line θ2 = γ_f·θ1, say why (docs/detector.md)
    ax_2.plot(t, gamma_f * theta1, lw=0.8, ls="--", color="tab:gray", label="γ_f·θ1")
    departs = _departs_from_signature(theta1, theta2, gamma_f)
    if departs:
        ax_2.text(
            0.01,
            0.04,
            "θ2 departs from γ_f·θ1: g1 and g2 are nearly collinear under few tones, so the\n"
            "free fit slides along their valley; read the friction level (panel above)",
            transform=ax_2.transAxes,
            fontsize=7,
            va="bottom",
            bbox={"facecolor": "white", "alpha": 0.8, "lw": 0},
        )
    for ax, values, name, sig, key, unit in (
        (ax_1, theta1, "θ1 (Coulomb), friction level\n(calibrated faults)", 1.0, "theta1", ""),
        (ax_2, theta2, "θ2 (viscous, s/m)", gamma_f, "theta2", " s/m"),
    ):
        ax.plot(t, values, lw=0.8, color="tab:purple", label=name.split()[0])
        ax.axhline(sig, color="tab:green", ls=":", lw=1.2, label=f"signature {sig:.3g}{unit}")
        span = list(band[key]) if band is not None else []
        shown = np.concatenate([values, level]) if ax is ax_1 else values
        finite = shown[np.isfinite(shown)]
        if finite.size:
            lo_q, hi_q = np.percentile(finite, [1, 99])
            limits = [min(lo_q, sig, *span), max(hi_q, sig, *span)]
            pad = 0.15 * (limits[1] - limits[0] or 1.0)
            ax.set_ylim(limits[0] - pad, limits[1] + pad)
        if span:
            lo, hi = span
            ax.axhspan(
                lo, hi, color="gold", alpha=0.45, lw=0, zorder=0, label=f"band [{lo:.3g}, {hi:.3g}]"
            )
            y0, y1 = ax.get_ylim()
            if hi - lo < 0.02 * (y1 - y0):  # narrower than it could be seen: a strip that can
                ax.axhline((lo + hi) / 2, color="gold", lw=5, alpha=0.8, zorder=0)
            ax.axhline(lo, color="k", ls="--", lw=0.6)
            ax.axhline(hi, color="k", ls="--", lw=0.6)
        ax.set_ylabel(name)
    ax_r.plot(t, residual, lw=0.6, color="tab:brown", label="residual")
    ax_r.set_ylabel("residual ẍ_r (m/s²)")
    ax_s.semilogy(t, np.where(stat > 0, stat, np.nan), lw=0.6, color="tab:blue", label="statistic")
    ax_s.axhline(threshold, color="tab:red", ls="--", lw=0.8, label=f"threshold {threshold:g}")
    ax_s.set_ylabel("statistic, mean (e/σ)²")
    ax_s.set_xlabel("t (s)")
    shared = {
        "calibration (learnt as normal)",
        "data gap",
        "fault onset (truth)",
        *(label for _, _, label in marks),
    }
    for ax in axes:  # the marks every row shares: in the top row's legend only
        keep: dict[str, Any] = {}
        for handle, label in zip(*ax.get_legend_handles_labels()):
            if ax is ax_a or label not in shared:
                keep.setdefault(label, handle)
        ax.legend(
            keep.values(),
            keep.keys(),
            loc="upper left",
            bbox_to_anchor=(1.01, 1.0),
            fontsize=7,
            frameon=False,
        )
    return fig


def plot_replay(
    path: str | Path,
    trace: MonitorTrace,
    events: list[dict[str, Any]],
    gamma_f: float,
    band: dict[str, list[float]] | None,
    threshold: float,
    fault_onset_t: float | None = None,
    title: str = "",
) -> Path:
    """Write the figure (`replay_figure`); returns its path."""
    return save_figure(
        replay_figure(trace, events, gamma_f, band, threshold, fault_onset_t, title), path
    )
