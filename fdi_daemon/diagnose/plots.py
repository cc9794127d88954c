"""`fdi diagnose --plot`: measured vs simulated before/after, and where the error sat."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fdi_daemon.io.outputs import pyplot, save_figure


def plot_diagnosis(result, report: dict, path: str | Path) -> Path:
    plt = pyplot()

    ctx = result.ctx
    fs = ctx.fs_hz
    t = np.arange(len(ctx.u)) / fs
    y = result.y_measured
    e0 = y - result.y_before
    e1 = y - result.y_after
    fig, axes = plt.subplots(4, 1, figsize=(11, 13))
    # 1. a held-out window around the worst held-out segment
    test_start = ctx.split.train_end
    seg = [r for r in report["regions"] if r["kind"] == "time" and r["t0"] * fs >= test_start]
    centre = int(seg[0]["t0"] * fs) if seg else test_start
    span = int(min(2 * fs, len(t) - test_start))
    i0 = max(test_start, min(centre, len(t) - span))
    w = slice(i0, i0 + span)
    ax = axes[0]
    ax.plot(t[w], y[w], "k", lw=1.2, label="measured")
    ax.plot(t[w], result.y_before[w], "C3", lw=1, label=f"nominal (gap {result.gap_before:.3g})")
    named = ", ".join(result.named) or "no effect added"
    ax.plot(t[w], result.y_after[w], "C2--", lw=1,
            label=f"+ {named} (gap {result.gap_after:.3g})")
    ax.set_title(f"held-out data ({ctx.output_kind})")
    ax.set_xlabel("t (s)")
    ax.legend(loc="upper right", fontsize=8)
    # 2. the error over the whole record, top segments shaded
    ax = axes[1]
    ax.plot(t, e0, "C3", lw=0.6, label="error before")
    ax.plot(t, e1, "C2", lw=0.6, label="error after")
    for r in report["regions"]:
        if r["kind"] == "time":
            ax.axvspan(r["t0"], r["t1"], color="C1", alpha=0.15)
    ax.axvline(test_start / fs, color="k", ls=":", lw=1)
    ax.text(test_start / fs, ax.get_ylim()[1], " held out", va="top", fontsize=8)
    ax.set_title("simulation error (shaded: largest-error segments)")
    ax.set_xlabel("t (s)")
    ax.legend(loc="upper right", fontsize=8)
    # 3. error against the state that explains most of it
    ax = axes[2]
    states = result.where_before["states"]
    best = states[0]
    values = {"velocity": ctx.v, "position": ctx.x, "input": ctx.u}[best["variable"]]
    stride = max(1, len(values) // 5000)
    ax.plot(values[::stride], e0[::stride], ".", ms=1.5, color="C3", alpha=0.4, label="before")
    ax.plot(values[::stride], e1[::stride], ".", ms=1.5, color="C2", alpha=0.4, label="after")
    centres = [0.5 * (b["range"][0] + b["range"][1]) for b in best["bins"]]
    ax.plot(centres, [b["mean"] for b in best["bins"]], "k-o", ms=3, label="bin mean (before)")
    ax.set_xlabel(f"simulated {best['variable']}")
    ax.set_ylabel("error")
    ax.set_title(f"error against {best['variable']} "
                 f"(bin means explain {100 * best['explained']:.0f} % of its variance)")
    ax.legend(loc="upper right", fontsize=8)
    # 4. spectra
    ax = axes[3]
    sp0 = result.where_before["spectrum"]
    sp1 = result.where_after["spectrum"]
    ax.semilogy(sp0["f_hz"], sp0["output_psd"], "k", lw=1, label="measured output")
    ax.semilogy(sp0["f_hz"], sp0["error_psd"], "C3", lw=1, label="error before")
    ax.semilogy(sp1["f_hz"], sp1["error_psd"], "C2", lw=1, label="error after")
    ax.set_xlabel("f (Hz)")
    ax.set_ylabel("PSD")
    ax.set_title("error spectrum")
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    return save_figure(fig, path, dpi=90)
