"""The friction trend figure of ``fdi trend --plot`` (one PNG).

Top: the friction level per minute (mean; min-max as a band) in units of the signature,
against the fault-free baseline (dashed) and the alarm steps above it (dotted), with the
time of each priority rise marked. Bottom: the alarm priority (0 none, 1..n steps) and the
valve command RMS, the operating condition.
"""

from __future__ import annotations

from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from fdi_daemon.io.outputs import pyplot, save_figure

__all__ = ["plot_trend"]

STEP_COLOURS = ("tab:olive", "tab:orange", "tab:red", "tab:purple", "tab:brown")


def _to_end(values: np.ndarray) -> np.ndarray:
    """Per-row values with the last repeated: a step drawn to the end of the last period."""
    return np.append(values, values[-1:])


def plot_trend(
    path: str | Path, data: dict[str, np.ndarray], steps: list[float], title: str = ""
) -> Path:
    plt = pyplot()
    import matplotlib.dates as mdates

    t = np.array([datetime.fromtimestamp(x, timezone.utc) for x in data["time_unix"]])
    # each row covers [time_unix, time_unix + period_s): the band is drawn as steps over
    # those periods (a wedge between two minutes' points was not a min-max of anything)
    ends = [
        datetime.fromtimestamp(x, timezone.utc)
        for x in data["time_unix"][-1:] + data["period_s"][-1:]
    ]
    edges = np.concatenate([t, np.array(ends, dtype=object)])
    few = t.size <= 120
    fig, (ax, ax_p) = plt.subplots(
        2, 1, figsize=(11, 6.5), sharex=True, gridspec_kw={"height_ratios": [3, 1.3]}
    )
    ax.fill_between(
        edges,
        np.append(data["level_min"], data["level_min"][-1:]),
        np.append(data["level_max"], data["level_max"][-1:]),
        step="post",
        color="tab:blue",
        alpha=0.18,
        lw=0,
        label="level min-max per row's period",
    )
    ax.plot(
        t + (edges[1:] - t) / 2,
        data["level_mean"],
        color="tab:blue",
        lw=0.8,
        marker="o" if few else None,
        ms=3,
        label="level, mean per row's period",
    )
    base = data["baseline"]
    has_base = np.isfinite(base).any()
    reference = np.where(np.isfinite(base), base, 0.0)
    if has_base:
        ax.step(
            edges,
            _to_end(base),
            where="post",
            color="k",
            ls="--",
            lw=1.0,
            label="fault-free baseline",
        )
    for i, step in enumerate(steps):
        colour = STEP_COLOURS[i % len(STEP_COLOURS)]
        ax.step(
            edges,
            _to_end(reference + step),
            where="post",
            color=colour,
            ls=":",
            lw=1.2,
            label=f"alarm step {i + 1}: +{step:g}" + (" above baseline" if has_base else ""),
        )
    priority = data["priority"]
    rises = np.flatnonzero(np.diff(priority) > 0) + 1
    if priority.size and priority[0] > 0:
        rises = np.concatenate([[0], rises])
    for k, i in enumerate(rises.tolist()):
        ax.axvline(
            t[i],
            color=STEP_COLOURS[(int(priority[i]) - 1) % len(STEP_COLOURS)],
            lw=1.0,
            alpha=0.8,
            label="priority rises" if k == 0 else None,
        )
        ax_p.axvline(t[i], color="0.6", lw=0.6)
    ax.set_ylabel("friction level (units of the signature)")
    ax.set_title(title or "Friction trend")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    ax_p.step(
        edges, _to_end(priority), where="post", color="tab:red", lw=1.2, label="alarm priority"
    )
    ax_p.set_ylabel("alarm priority")
    ax_p.set_yticks(range(0, len(steps) + 1))
    ax_p.set_ylim(-0.2, len(steps) + 0.3)
    ax_c = ax_p.twinx()
    command = np.asarray(data["command_rms_v"], dtype=float)
    recorded = bool(np.isfinite(command).any())
    ax_c.plot(
        t,
        command,
        color="tab:gray",
        lw=0.5,
        alpha=0.7,
        label="valve command RMS" if recorded else "valve command RMS (none recorded)",
    )
    ax_c.set_ylabel("command RMS (V)")
    lines = ax_p.get_legend_handles_labels()
    more = ax_c.get_legend_handles_labels()
    ax_p.legend(
        lines[0] + more[0],
        lines[1] + more[1],
        loc="upper left",
        bbox_to_anchor=(1.13, 1.0),  # clear of the command axis' label
        fontsize=8,
        frameon=False,
    )
    locator = mdates.AutoDateLocator(minticks=3, maxticks=9)
    ax_p.xaxis.set_major_locator(locator)  # labels as fine as the span needs, none repeated
    ax_p.xaxis.set_major_formatter(mdates.ConciseDateFormatter(locator))
    ax_p.set_xlabel("time (UTC)")
    fig.tight_layout()
    return save_figure(fig, path)
