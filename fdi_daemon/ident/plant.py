"""The plant identification workflow of §III: data -> G(ω) -> band -> Ĝ = B/A -> validation.

Everything that depends on the data is chosen from the data and reported: the lag window
(`spectral.select_lag_window`), the band (`spectral.informative_band`) and the start
(`rational_fit`: Levy or Sanathanan–Koerner, whichever refines to the lower cost).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fdi_daemon.ident import rational_fit, spectral, stable_poly, validation

METHODS = ("blackman-tukey", "welch")


@dataclass
class PlantIdentification:
    fs_hz: float
    response: spectral.FrequencyResponse  # G(ω) estimate on its grid
    band_hz: tuple[float, float]
    fit: rational_fit.RationalFit
    choices: dict  # what was chosen and how (for the report and provenance)

    def model_response(self) -> np.ndarray:
        return self.fit.response(self.response.freq_hz, self.fs_hz)

    def band_mask(self) -> np.ndarray:
        f = self.response.freq_hz
        return (f >= self.band_hz[0]) & (f <= self.band_hz[1])


def estimate_response(
    u: np.ndarray,
    y: np.ndarray,
    fs_hz: float,
    method: str = "blackman-tukey",
    lag_samples: int | None = None,
    lag_window: str = "hann",
) -> tuple[spectral.FrequencyResponse, dict]:
    """G(ω) by Blackman–Tukey (M chosen from the data unless given) or Welch H1."""
    choices: dict = {"method": method}
    if method == "welch":
        fr = spectral.welch_h1(u, y, fs_hz)
        choices.update(fr.settings)
        return fr, choices
    if method != "blackman-tukey":
        raise ValueError(f"unknown method {method!r} (use {' or '.join(METHODS)})")
    if lag_samples is None:
        lag_samples, table = spectral.select_lag_window(u, y, fs_hz, lag_window)
        choices["lag_samples_rule"] = "least estimated bias^2 + variance over candidates"
        choices["lag_candidates"] = [
            {k: (round(v, 6) if isinstance(v, float) else v) for k, v in row.items()}
            for row in table
        ]
    else:
        choices["lag_samples_rule"] = "given"
    fr = spectral.blackman_tukey(u, y, fs_hz, int(lag_samples), lag_window)
    choices.update(
        {
            "lag_samples": int(lag_samples),
            "lag_window": lag_window,
            "effective_averages": fr.settings["effective_averages"],
        }
    )
    return fr, choices


def identify_plant(
    u: np.ndarray,
    y: np.ndarray,
    fs_hz: float,
    order: int = 4,
    method: str = "blackman-tukey",
    lag_samples: int | None = None,
    lag_window: str = "hann",
    band_hz: tuple[float, float] | None = None,
    min_coherence: float = 0.8,
    input_floor_db: float = -20.0,
    output_floor_db: float = -20.0,
) -> PlantIdentification:
    """Fit Ĝ = B/A (eq. 1) to the spectral estimate with W = 1/|G| (eq. 2) on the band."""
    fr, choices = estimate_response(u, y, fs_hz, method, lag_samples, lag_window)
    if band_hz is None:
        band_hz = spectral.informative_band(fr, min_coherence, input_floor_db, output_floor_db)
        choices["band_rule"] = (
            f"excited span (input spectrum within {-input_floor_db:g} dB of its peak), ends "
            f"trimmed to coherence >= {min_coherence:g} and input-driven output within "
            f"{-output_floor_db:g} dB of its peak; excited points fitted"
        )
    else:
        choices["band_rule"] = "given"
    choices["band_hz"] = [float(band_hz[0]), float(band_hz[1])]
    f = fr.freq_hz
    sel = (f >= band_hz[0]) & (f <= band_hz[1]) & fr.excited(input_floor_db) & (np.abs(fr.G) > 0)
    if sel.sum() < 2 * order:
        raise ValueError(
            f"band {band_hz[0]:g}-{band_hz[1]:g} Hz holds {int(sel.sum())} "
            f"frequency points; order {order} needs at least {2 * order}"
        )
    radius = stable_poly.record_pole_radius(len(u))
    fit = rational_fit.fit_rational(f[sel], fr.G[sel], fs_hz, order, max_pole_radius=radius)
    choices.update(
        {
            "max_pole_radius": radius,
            "start": fit.start,
            "sk_iterations": fit.sk_iterations,
            "reflected_poles": fit.reflected_poles,
            "fit_points": int(sel.sum()),
        }
    )
    return PlantIdentification(fs_hz, fr, (float(band_hz[0]), float(band_hz[1])), fit, choices)


def validate_plant(
    ident: PlantIdentification, u: np.ndarray, y: np.ndarray, band_count: int = 4
) -> dict:
    """Fit %, residual–input correlation and per-band relative error on (u, y)."""
    y = np.asarray(y, dtype=float)
    y_sim = validation.simulate(ident.fit.b, ident.fit.a, u, y)
    corr = validation.residual_input_correlation(y - y_sim, u)
    lag = ident.choices.get("lag_samples")
    if lag is not None and lag > len(u) // 4:
        lag = None  # a shorter validation record: choose its own lag window
    fr, _ = estimate_response(
        u, y, ident.fs_hz, "blackman-tukey", lag, ident.choices.get("lag_window", "hann")
    )
    edges = list(np.linspace(ident.band_hz[0], ident.band_hz[1], band_count + 1))
    edges[-1] = np.nextafter(edges[-1], np.inf)
    bands = validation.band_errors(
        fr.freq_hz, fr.G, ident.fit.response(fr.freq_hz, ident.fs_hz), edges
    )
    return {
        "fit_percent": validation.fit_percent(y, y_sim),
        "y_sim": y_sim,
        "xcorr": corr,
        "band_errors": bands,
    }
