"""PNG figures of the identification steps (matplotlib, Agg backend).

- `plot_identification`: Bode magnitude and phase of the estimate G(ω) and the fitted Ĝ
  (the paper's Fig. 4) with the fitted band shaded, the coherence, and, when validation data
  are given, measured against simulated acceleration, whole and a zoom of a few periods;
- `plot_signature`: the residual against the filtered friction signal G_e x_f (Fig. 8),
  its RMS over the whole window and a zoom, and the cost profile over γ with its 99 %
  interval.

Legends sit above the axes (right-aligned, titles left), off the data.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fdi_daemon.io.outputs import pyplot, save_figure


def _legend_above(ax, ncol: int = 2) -> None:
    ax.legend(
        loc="lower right",
        bbox_to_anchor=(1.0, 1.0),
        ncol=ncol,
        fontsize=8,
        frameon=False,
        borderaxespad=0.2,
    )


def phase_on_model_branch(G: np.ndarray, model: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Phases in degrees: the model's unwrapped, and the data's taken within ±180° of the
    model's at each frequency. Unwrapping noisy data where the coherence is gone (above the
    excited band) climbs by thousands of degrees and flattens the band that matters."""
    model_deg = np.degrees(np.unwrap(np.angle(model)))
    diff = np.angle(G * np.exp(-1j * np.radians(model_deg)))  # wrapped to (-π, π]
    return model_deg, model_deg + np.degrees(diff)


def zoom_window(t: np.ndarray, error: np.ndarray, span_s: float) -> np.ndarray:
    """Mask of the `span_s` long stretch where the RMS of `error` is largest."""
    n = len(t)
    width = max(2, min(n, int(round(span_s / max(float(np.median(np.diff(t))), 1e-12)))))
    energy = np.convolve(np.asarray(error, dtype=float) ** 2, np.ones(width), mode="valid")
    start = int(np.argmax(energy))
    mask = np.zeros(n, dtype=bool)
    mask[start : start + width] = True
    return mask


def plot_identification(
    path: str | Path,
    fr,
    model_response: np.ndarray,
    band_hz: tuple[float, float],
    validation: dict | None = None,
    title: str = "",
    zoom_s: float = 0.5,
) -> Path:
    """Fig. 4 (+ coherence, + validation time series when given: whole, and a `zoom_s`
    long stretch where the simulation misses most)."""
    return save_figure(
        identification_figure(fr, model_response, band_hz, validation, title, zoom_s), path
    )


def identification_figure(
    fr,
    model_response: np.ndarray,
    band_hz: tuple[float, float],
    validation: dict | None = None,
    title: str = "",
    zoom_s: float = 0.5,
):
    """The figure of `plot_identification` (not yet saved)."""
    plt = pyplot()
    rows = 5 if validation is not None else 3
    fig, axes = plt.subplots(rows, 1, figsize=(8, 2.5 * rows), constrained_layout=True)
    f = fr.freq_hz
    sel = f > 0
    shown = sel & (f <= min(f[-1], max(4 * band_hz[1], band_hz[1] + 10)))
    ax_mag, ax_ph, ax_coh = axes[:3]
    ax_mag.loglog(f[shown], np.abs(fr.G[shown]), ".", ms=3, color="0.4", label="data G(ω)")
    ax_mag.loglog(f[shown], np.abs(model_response[shown]), "-", color="C0", label="model Ĝ")
    ax_mag.set_ylabel("|G| (m/s² per V)")
    _legend_above(ax_mag)
    model_deg, data_deg = phase_on_model_branch(fr.G[shown], model_response[shown])
    ax_ph.semilogx(f[shown], data_deg, ".", ms=3, color="0.4")
    ax_ph.semilogx(f[shown], model_deg, "-", color="C0")
    ax_ph.set_ylabel("phase (deg)")
    ax_ph.set_title("phase; data taken within ±180° of the model's", loc="left", fontsize=9)
    lo, hi = np.floor(np.min(data_deg) / 90) * 90, np.ceil(np.max(data_deg) / 90) * 90
    ax_ph.set_yticks(np.arange(lo, hi + 1, 90 if hi - lo <= 720 else 180))
    ax_coh.semilogx(f[shown], fr.coherence[shown], color="C2")
    ax_coh.set_ylim(0, 1.05)
    ax_coh.set_ylabel("coherence γ²")
    ax_coh.set_xlabel("frequency (Hz)")
    for ax in (ax_mag, ax_ph, ax_coh):
        ax.axvspan(band_hz[0], band_hz[1], color="C1", alpha=0.12, lw=0)
        ax.grid(True, which="both", alpha=0.3)
    ax_mag.set_title(title or "Frequency response (shaded: fitted band)", loc="left", fontsize=10)
    if validation is not None:
        t, y, y_sim = validation["t"], validation["y"], validation["y_sim"]
        zoom = zoom_window(t, y - y_sim, zoom_s)
        ax_all, ax_zoom = axes[3], axes[4]
        for ax, sel in ((ax_all, slice(None)), (ax_zoom, zoom)):
            ax.plot(t[sel], y[sel], color="0.4", lw=0.6 if ax is ax_all else 1.0, label="measured")
            ax.plot(
                t[sel],
                y_sim[sel],
                color="C0",
                lw=0.6 if ax is ax_all else 1.0,
                label=f"simulated (fit {validation['fit_percent']:.1f} %)",
            )
            ax.set_xlabel("t (s)")
            ax.set_ylabel("accel (m/s²)")
            ax.grid(True, alpha=0.3)
        ax_all.plot(t, y - y_sim, color="C3", lw=0.5, label="measured − simulated")
        ax_all.axvspan(t[zoom][0], t[zoom][-1], color="C1", alpha=0.35, lw=0, label="zoom")
        _legend_above(ax_all, ncol=4)
        _legend_above(ax_zoom)
        ax_all.set_title(validation.get("label", "validation"), loc="left", fontsize=9)
        ax_zoom.set_title(
            f"zoom: the {zoom_s:g} s where the simulation misses most", loc="left", fontsize=9
        )
    return fig


def moving_rms(x: np.ndarray, width: int) -> np.ndarray:
    """RMS over a centred window of `width` samples (shorter at the ends)."""
    x2 = np.asarray(x, dtype=float) ** 2
    kernel = np.ones(max(1, width))
    return np.sqrt(
        np.convolve(x2, kernel, mode="same") / np.convolve(np.ones_like(x2), kernel, mode="same")
    )


def plot_signature(
    path: str | Path,
    t: np.ndarray,
    residual: np.ndarray,
    result,
    title: str = "",
    zoom_s: float = 1.0,
    residual_label: str = "acceleration residual r",
    velocity: str = "",
) -> Path:
    """Fig. 8 and the γ cost profile (`signature_figure`); returns the path."""
    return save_figure(
        signature_figure(t, residual, result, title, zoom_s, residual_label, velocity=velocity),
        path,
    )


def signature_figure(
    t: np.ndarray,
    residual: np.ndarray,
    result,
    title: str = "",
    zoom_s: float = 1.0,
    residual_label: str = "acceleration residual r",
    rms_s: float = 0.25,
    velocity: str = "",
):
    """Fig. 8 as the RMS over `rms_s` of the fitted residual (as it was filtered for the fit:
    `residual_label`), of G_e x_f and of their difference over the whole window (the traces
    themselves would be a solid block), the traces over the last `zoom_s` seconds, and the
    cost profile over γ (s/m) with its 99 % interval; `velocity` names the estimate x_f was
    made with (in the default title)."""
    plt = pyplot()
    fig, (ax_t, ax_z, ax_g) = plt.subplots(3, 1, figsize=(8, 9.5), constrained_layout=True)
    model = result.fit.y_sim
    gamma_text = f"γ_f = {result.gamma_f:.3g} s/m"
    fs = 1.0 / float(np.median(np.diff(t)))
    width = int(round(rms_s * fs))
    ax_t.plot(t, moving_rms(residual, width), color="0.35", lw=1.0, label=residual_label)
    ax_t.plot(t, moving_rms(model, width), color="C0", lw=1.0, label=f"G_e x_f, {gamma_text}")
    ax_t.plot(
        t, moving_rms(residual - model, width), color="C3", lw=1.0, label="unexplained (difference)"
    )
    zoom = t >= t[-1] - zoom_s
    ax_t.axvspan(t[zoom][0], t[-1], color="C1", alpha=0.25, lw=0, label="zoom below")
    ax_t.set_ylabel(f"RMS over {rms_s:g} s (m/s²)")
    ax_t.set_ylim(bottom=0)
    ax_z.plot(t[zoom], residual[zoom], "--", color="0.35", lw=0.9, label=residual_label)
    ax_z.plot(t[zoom], model[zoom], "-", color="C0", lw=1.0, label=f"G_e x_f, {gamma_text}")
    ax_z.set_ylabel("m/s²")
    for ax in (ax_t, ax_z):
        ax.set_xlabel("t (s)")
        ax.grid(True, alpha=0.3)
    _legend_above(ax_t)  # above its axes: below, it sat under the t axis's label
    _legend_above(ax_z)
    fig.suptitle(  # the figure's title, so that the first panel's legend has the row above it
        title
        or f"Residual and filtered friction signal (paper Fig. 8): "
        f"{result.info.get('fit_percent', float('nan')):.1f} % explained"
        + (f", velocity {velocity}" if velocity else ""),
        x=0.01,
        ha="left",
        fontsize=10,
    )
    ax_z.set_title(f"last {zoom_s:g} s of the window", loc="left", fontsize=9)
    rel = result.relative_cost()
    ax_g.plot(result.grid, rel, "o-", ms=3, color="C0", label="cost")
    ax_g.axvspan(
        result.interval[0], result.interval[1], color="C1", alpha=0.15, lw=0, label="99 % interval"
    )
    ax_g.axvline(result.gamma_f, color="C3", lw=1, label=gamma_text)
    ax_g.set_xlabel("γ (s/m)")
    ax_g.set_ylabel("SSE(γ) / SSE(γ_f)")
    ax_g.set_title(
        "cost profile"
        + {
            "flat": "  —  FLAT: γ_f not identifiable",
            "poorly identified": "  —  γ_f POORLY IDENTIFIED (wide 99 % interval)",
            "not identified (edge)": "  —  γ_f NOT IDENTIFIED: least cost at the grid's end",
        }.get(result.status, ""),
        loc="left",
        fontsize=9,
    )
    _legend_above(ax_g, ncol=3)
    ax_g.grid(True, alpha=0.3)
    return fig
