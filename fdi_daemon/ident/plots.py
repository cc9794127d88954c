"""PNG figures of the identification steps (matplotlib, Agg backend).

- `plot_identification`: Bode magnitude and phase of the estimate G(ω) and the fitted Ĝ
  (the paper's Fig. 4) with the fitted band shaded, the coherence, and, when validation data
  are given, measured against simulated acceleration;
- `plot_signature`: the residual against the filtered friction signal G_e x_f (Fig. 8),
  whole window and a zoom, and the cost profile over γ with its 99 % interval.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fdi_daemon.io.outputs import pyplot, save_figure


def plot_identification(path: str | Path, fr, model_response: np.ndarray,
                        band_hz: tuple[float, float], validation: dict | None = None,
                        title: str = "") -> Path:
    """Fig. 4 (+ coherence, + validation time series when given)."""
    plt = pyplot()
    rows = 4 if validation is not None else 3
    fig, axes = plt.subplots(rows, 1, figsize=(8, 2.6 * rows), constrained_layout=True)
    f = fr.freq_hz
    sel = f > 0
    shown = sel & (f <= min(f[-1], max(4 * band_hz[1], band_hz[1] + 10)))
    ax_mag, ax_ph, ax_coh = axes[:3]
    ax_mag.loglog(f[shown], np.abs(fr.G[shown]), ".", ms=3, color="0.4", label="data G(ω)")
    ax_mag.loglog(f[shown], np.abs(model_response[shown]), "-", color="C0",
                  label="model Ĝ")
    ax_mag.set_ylabel("|G| (m/s² per V)")
    ax_mag.legend(loc="best")
    ax_ph.semilogx(f[shown], np.degrees(np.unwrap(np.angle(fr.G[shown]))), ".", ms=3,
                   color="0.4")
    ax_ph.semilogx(f[shown], np.degrees(np.unwrap(np.angle(model_response[shown]))), "-",
                   color="C0")
    ax_ph.set_ylabel("phase (deg)")
    ax_coh.semilogx(f[shown], fr.coherence[shown], color="C2")
    ax_coh.set_ylim(0, 1.05)
    ax_coh.set_ylabel("coherence γ²")
    ax_coh.set_xlabel("frequency (Hz)")
    for ax in (ax_mag, ax_ph, ax_coh):
        ax.axvspan(band_hz[0], band_hz[1], color="C1", alpha=0.12, lw=0)
        ax.grid(True, which="both", alpha=0.3)
    ax_mag.set_title(title or "Frequency response: data and fitted model (shaded: fitted band)")
    if validation is not None:
        ax = axes[3]
        ax.plot(validation["t"], validation["y"], color="0.4", lw=0.8, label="measured")
        ax.plot(validation["t"], validation["y_sim"], color="C0", lw=0.8,
                label=f"simulated (fit {validation['fit_percent']:.1f} %)")
        ax.set_xlabel("t (s)")
        ax.set_ylabel("accel (m/s²)")
        ax.set_title(validation.get("label", "validation"))
        ax.legend(loc="upper right")
        ax.grid(True, alpha=0.3)
    return save_figure(fig, path)


def plot_signature(path: str | Path, t: np.ndarray, residual: np.ndarray, result,
                   title: str = "", zoom_s: float = 1.0) -> Path:
    """Fig. 8 (residual vs G_e x_f: whole window and its last `zoom_s` seconds) and the γ
    cost profile with its 99 % interval."""
    plt = pyplot()
    fig, (ax_t, ax_z, ax_g) = plt.subplots(3, 1, figsize=(8, 9), constrained_layout=True)
    model = result.fit.y_sim
    zoom = t >= t[-1] - zoom_s
    for ax, sel in ((ax_t, slice(None)), (ax_z, zoom)):
        ax.plot(t[sel], residual[sel], "--", color="0.35", lw=0.9,
                label="acceleration residual")
        ax.plot(t[sel], model[sel], "-", color="C0", lw=1.0,
                label=f"G_e x_f, γ_f = {result.gamma_f:.3g}")
        ax.set_xlabel("t (s)")
        ax.set_ylabel("m/s²")
        ax.grid(True, alpha=0.3)
    ax_t.legend(loc="upper right")
    ax_t.set_title(title or f"Residual and filtered friction signal (paper Fig. 8): "
                            f"{result.info.get('fit_percent', float('nan')):.1f} % explained")
    ax_z.set_title(f"last {zoom_s:g} s of the window")
    rel = result.relative_cost()
    ax_g.plot(result.grid, rel, "o-", ms=3, color="C0")
    ax_g.axvspan(result.interval[0], result.interval[1], color="C1", alpha=0.15, lw=0,
                 label="99 % interval")
    ax_g.axvline(result.gamma_f, color="C3", lw=1, label=f"γ_f = {result.gamma_f:.3g}")
    ax_g.set_xlabel("γ")
    ax_g.set_ylabel("SSE(γ) / SSE(γ_f)")
    ax_g.set_title("cost profile" + ("  —  FLAT: γ_f not identifiable" if result.flat else ""))
    ax_g.legend(loc="best")
    ax_g.grid(True, alpha=0.3)
    return save_figure(fig, path)
