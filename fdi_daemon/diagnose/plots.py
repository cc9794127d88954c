"""`fdi diagnose --plot`: measured vs simulated before/after, and where the error sat."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fdi_daemon.io.outputs import pyplot, save_figure

#: unit of the compared quantity by output kind (the inverse-dynamics form compares the input)
UNITS = {"acceleration": "m/s²", "velocity": "m/s", "position": "m"}
STATE_UNITS = {"velocity": "m/s", "position": "m", "input": "input units"}
LEGEND = dict(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, borderaxespad=0.0)


def plot_diagnosis(result, report: dict, path: str | Path) -> Path:
    """Four panels; legends sit right of the axes, off the traces; "before" is drawn over
    "after" (thin, translucent) so that neither hides the other."""
    plt = pyplot()

    fig, axes = plt.subplots(4, 1, figsize=(13, 13))
    _held_out_panel(axes[0], result, report)
    _error_panel(axes[1], result, report)
    _state_panel(axes[2], result)
    _spectrum_panel(axes[3], result, report)
    fig.tight_layout()
    return save_figure(fig, path, dpi=90)


def _compared(ctx) -> tuple[bool, str, str]:
    """(inverse dynamics?, the unit of the compared quantity, its name): the output, or in
    the inverse-dynamics form the low-passed input L u."""
    inverse = ctx.form == "inverse_dynamics"
    unit = "input units" if inverse else UNITS[ctx.output_kind]
    return inverse, unit, "L u" if inverse else ctx.output_kind


def _held_out_panel(ax, result, report: dict) -> None:
    """1. A held-out window (2 s at most) around the worst held-out segment: measured,
    after and before."""
    ctx = result.ctx
    inverse, unit, quantity = _compared(ctx)
    fs = ctx.fs_hz
    t = np.arange(len(ctx.u)) / fs
    y = result.y_measured
    test_start = ctx.split.train_end
    seg = [r for r in report["regions"] if r["kind"] == "time" and r["t0"] * fs >= test_start]
    centre = int(seg[0]["t0"] * fs) if seg else test_start
    span = int(min(2 * fs, len(t) - test_start))
    i0 = max(test_start, min(centre, len(t) - span))
    w = slice(i0, i0 + span)
    named = ", ".join(result.named) or "no effect added"
    ax.plot(t[w], y[w], "k", lw=1.6, label="measured", zorder=1)
    ax.plot(
        t[w],
        result.y_after[w],
        "C2",
        lw=1.2,
        label=f"+ {named} (gap {result.gap_after:.3g})",
        zorder=2,
    )
    ax.plot(
        t[w],
        result.y_before[w],
        "C3--",
        lw=1.0,
        alpha=0.8,
        label=f"nominal (gap {result.gap_before:.3g})",
        zorder=3,
    )
    ax.set_title(
        "held-out data: low-passed input against the force balance (0: at rest, left out)"
        if inverse
        else f"held-out data: {quantity}"
    )
    ax.set_xlabel("t (s)")
    ax.set_ylabel(f"{quantity} ({unit})")
    ax.legend(**LEGEND)


def _error_panel(ax, result, report: dict) -> None:
    """2. The error before and after over the whole record, the largest-error segments
    shaded, the start of the held-out part marked."""
    ctx = result.ctx
    inverse, unit, _ = _compared(ctx)
    fs = ctx.fs_hz
    t = np.arange(len(ctx.u)) / fs
    test_start = ctx.split.train_end
    e0 = result.y_measured - result.y_before
    e1 = result.y_measured - result.y_after
    ax.plot(t, e1, "C2", lw=0.6, label="error after", zorder=1)
    ax.plot(t, e0, "C3", lw=0.5, alpha=0.6, label="error before", zorder=2)
    for r in report["regions"]:
        if r["kind"] == "time":
            ax.axvspan(r["t0"], r["t1"], color="C1", alpha=0.15)
    ax.axvline(test_start / fs, color="k", ls=":", lw=1)
    ax.text(test_start / fs, ax.get_ylim()[1], " held out", va="top", fontsize=8)
    ax.set_title(
        ("force-balance" if inverse else "simulation") + " error (shaded: largest-error segments)"
    )
    ax.set_xlabel("t (s)")
    ax.set_ylabel(f"error ({unit})")
    ax.legend(**LEGEND)


def _state_panel(ax, result) -> None:
    """3. The error against the state that explains most of it (`localize`), with the
    bin means before."""
    ctx = result.ctx
    inverse, unit, _ = _compared(ctx)
    e0 = result.y_measured - result.y_before
    e1 = result.y_measured - result.y_after
    best = result.where_before["states"][0]
    values = {"velocity": ctx.v, "position": ctx.x, "input": ctx.u}[best["variable"]]
    stride = max(1, len(values) // 5000)
    ax.plot(
        values[::stride], e1[::stride], ".", ms=1.5, color="C2", alpha=0.4, label="after", zorder=1
    )
    ax.plot(
        values[::stride], e0[::stride], ".", ms=1.2, color="C3", alpha=0.3, label="before", zorder=2
    )
    centres = [0.5 * (b["range"][0] + b["range"][1]) for b in best["bins"]]
    ax.plot(centres, [b["mean"] for b in best["bins"]], "k-o", ms=3, label="bin mean (before)")
    source = "measured" if inverse else "simulated"
    ax.set_xlabel(f"{source} {best['variable']} ({STATE_UNITS[best['variable']]})")
    ax.set_ylabel(f"error ({unit})")
    ax.set_title(
        f"error against {best['variable']} "
        f"(bin means explain {100 * best['explained']:.0f} % of its variance)"
    )
    ax.legend(**LEGEND)


def _spectrum_panel(ax, result, report: dict) -> None:
    """4. The spectra of the measured output and of the error before and after, with the
    noise floor as a white density (not in the inverse-dynamics form)."""
    ctx = result.ctx
    inverse, unit, _ = _compared(ctx)
    sp0 = result.where_before["spectrum"]
    sp1 = result.where_after["spectrum"]
    ax.semilogy(sp0["f_hz"], sp0["output_psd"], "k", lw=1, label="measured output")
    ax.semilogy(sp1["f_hz"], sp1["error_psd"], "C2", lw=1, label="error after", zorder=1)
    ax.semilogy(
        sp0["f_hz"], sp0["error_psd"], "C3", lw=0.8, alpha=0.7, label="error before", zorder=2
    )
    floor = report.get("noise_floor", {}).get("floor")
    if floor is not None and not inverse:
        # the floor as a white density: floor² var(y) spread over 0..fs/2
        y = result.y_measured
        level = (floor * float(np.std(y[ctx.split.train_end :]))) ** 2 / (ctx.fs_hz / 2)
        ax.axhline(level, color="0.4", ls=":", lw=1, label="noise floor (white)")
    ax.set_xlabel("f (Hz)")
    ax.set_ylabel(f"PSD (({unit})²/Hz)")
    ax.set_title("error spectrum")
    ax.legend(**LEGEND)
