"""Non-parametric frequency-response estimates G(ω) from input u to output y (§III-B).

- `blackman_tukey`: correlation estimates, a Hann or Hamming lag window of length M and a
  Fourier transform, as MATLAB's ``spa``; G = Φ_yu/Φ_u.
- `welch_h1`: averaged, windowed segments (scipy.signal.csd); G = P_uy/P_uu (H1) and the
  magnitude-squared coherence.
- `select_lag_window`: M chosen from the data by a plug-in bias/variance balance.
- `informative_band`: the contiguous band where the input carries energy and the coherence is
  high, i.e. where the estimate is worth fitting.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import signal

LAG_WINDOWS = ("hann", "hamming")

#: frequencies where the input-driven output |G|²Φ_u is this far below its peak carry too
#: little of the output to be worth fitting (or to decide the lag window)
OUTPUT_FLOOR_DB = -20.0


@dataclass
class FrequencyResponse:
    """A frequency-response estimate on a grid of frequencies (Hz)."""

    freq_hz: np.ndarray
    G: np.ndarray
    coherence: np.ndarray  # magnitude-squared coherence on freq_hz
    input_psd: np.ndarray  # Welch Φ_u on freq_hz (used relatively, to find the excited band)
    method: str
    settings: dict = field(default_factory=dict)
    #: Φ_u at the estimate's own resolution (Blackman–Tukey): where the input really is, e.g.
    #: the lines of a multisine, which the averaged `input_psd` smears
    resolved_input_psd: np.ndarray | None = None

    def excited(self, input_floor_db: float = -20.0) -> np.ndarray:
        """Grid points whose input spectrum (at the estimate's resolution) is within
        `input_floor_db` of its peak."""
        psd = self.input_psd if self.resolved_input_psd is None else self.resolved_input_psd
        return informative_mask(self.freq_hz, np.ones_like(self.freq_hz), psd, 0.0, input_floor_db)


def _demeaned(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    return x - x.mean()


def lag_window(kind: str, lag_samples: int) -> np.ndarray:
    """Lag window w(τ) for τ = -M..M (w(0) = 1, w(±M) = 0 for Hann)."""
    tau = np.arange(-lag_samples, lag_samples + 1)
    if kind == "hann":
        return 0.5 * (1.0 + np.cos(np.pi * tau / lag_samples))
    if kind == "hamming":
        return 0.54 + 0.46 * np.cos(np.pi * tau / lag_samples)
    raise ValueError(f"unknown lag window {kind!r} (use {' or '.join(LAG_WINDOWS)})")


def _covariances(a: np.ndarray, b: np.ndarray, lag_samples: int) -> np.ndarray:
    """R_ab(τ) = (1/N) Σ_t a(t+τ) b(t) for τ = -M..M (biased estimate, as spa)."""
    n = len(a)
    nfft = int(2 ** np.ceil(np.log2(2 * n)))
    cross = np.fft.irfft(np.fft.rfft(a, nfft) * np.conj(np.fft.rfft(b, nfft)), nfft) / n
    return np.concatenate([cross[nfft - lag_samples :], cross[: lag_samples + 1]])


def _bt_spectra(u, y, lag_samples, window, nfft):
    w = lag_window(window, lag_samples)
    spectra = []
    for a, b in ((y, u), (u, u), (y, y)):
        r = _covariances(a, b, lag_samples) * w
        # place τ = 0 at index 0, negative lags wrapped to the end
        buf = np.zeros(nfft)
        buf[: lag_samples + 1] = r[lag_samples:]
        buf[nfft - lag_samples :] = r[:lag_samples]
        spectra.append(np.fft.rfft(buf))
    phi_yu, phi_u, phi_y = spectra
    return phi_yu, np.real(phi_u), np.real(phi_y)


def welch_segment_samples(n_samples: int) -> int:
    """Welch segment length: N/8 (at least 8 averages with 50 % overlap), 32..1024 samples."""
    return int(np.clip(2 ** np.floor(np.log2(max(n_samples, 2) / 8)), 32, 1024))


def smooth_input_psd(u: np.ndarray, fs_hz: float, freq_hz: np.ndarray) -> np.ndarray:
    """Welch PSD of the input (segments of `welch_segment_samples`) on the grid freq_hz.

    Used only to tell excited from unexcited frequencies: averaged, so that the chi-square
    scatter of a raw or lightly smoothed periodogram of a random input does not fragment the
    band.
    """
    nper = min(welch_segment_samples(len(u)), len(u))
    f, p_uu = signal.welch(_demeaned(u), fs=fs_hz, nperseg=nper)
    return np.interp(freq_hz, f, p_uu)


def welch_h1(
    u: np.ndarray, y: np.ndarray, fs_hz: float, segment_samples: int | None = None
) -> FrequencyResponse:
    """H1 estimate G = P_uy/P_uu and coherence by Welch averaging (Hann, 50 % overlap)."""
    u, y = _demeaned(u), _demeaned(y)
    nper = segment_samples or welch_segment_samples(len(u))
    nper = min(nper, len(u))
    f, p_uy = signal.csd(u, y, fs=fs_hz, nperseg=nper)
    _, p_uu = signal.welch(u, fs=fs_hz, nperseg=nper)
    _, p_yy = signal.welch(y, fs=fs_hz, nperseg=nper)
    G, coh = _ratio_and_coherence(p_uy, p_uu, p_yy)
    return FrequencyResponse(
        f, G, coh, p_uu, "welch", {"segment_samples": int(nper), "overlap": 0.5, "window": "hann"}
    )


def _ratio_and_coherence(p_uy, p_uu, p_yy):
    tiny = np.finfo(float).tiny
    ok = (p_uu > tiny) & (p_yy > tiny)
    G = np.zeros_like(p_uy, dtype=complex)
    coh = np.zeros(len(p_uu))
    G[ok] = p_uy[ok] / p_uu[ok]
    coh[ok] = np.clip(np.abs(p_uy[ok]) ** 2 / (p_uu[ok] * p_yy[ok]), 0.0, 1.0)
    return G, coh


def blackman_tukey(
    u: np.ndarray,
    y: np.ndarray,
    fs_hz: float,
    lag_samples: int,
    window: str = "hann",
    nfft: int | None = None,
) -> FrequencyResponse:
    """Blackman–Tukey estimate G = Φ_yu/Φ_u with a lag window of M = lag_samples (as ``spa``).

    The grid has nfft/2 + 1 points from 0 to fs/2 (default nfft: the next power of two
    >= max(N, 4M)). The coherence |Φ_yu|²/(Φ_u Φ_y) uses the same lag window, i.e. about
    N/(Σw²) effective averages (5 for M = N/4 with a Hann window): it is biased upwards
    for short records, but unlike a short-segment Welch coherence it is not spoiled by
    leakage on lightly damped resonances or by the non-stationarity of a chirp.
    """
    u, y = _demeaned(u), _demeaned(y)
    n = len(u)
    if not 2 <= lag_samples < n:
        raise ValueError(f"lag window of {lag_samples} samples needs 2 <= M < N = {n}")
    if nfft is None:
        nfft = int(2 ** np.ceil(np.log2(max(n, 4 * lag_samples))))
    phi_yu, phi_u, phi_y = _bt_spectra(u, y, lag_samples, window, nfft)
    G, coh = _ratio_and_coherence(phi_yu, phi_u, phi_y)
    freq = np.fft.rfftfreq(nfft, 1.0 / fs_hz)
    averages = 1.0 / relative_variance_factor(window, lag_samples, n)
    return FrequencyResponse(
        freq,
        G,
        coh,
        smooth_input_psd(u, fs_hz, freq),
        "blackman-tukey",
        {
            "lag_samples": int(lag_samples),
            "lag_window": window,
            "nfft": int(nfft),
            "effective_averages": round(averages, 2),
        },
        resolved_input_psd=np.maximum(phi_u, 0.0) / fs_hz,
    )


def relative_variance_factor(window: str, lag_samples: int, n_samples: int) -> float:
    """(1/N) Σ w(τ)²: Var Ĝ / |G|² = factor · (1 - γ²)/γ² (Ljung, System Identification §6.4)."""
    return float(np.sum(lag_window(window, lag_samples) ** 2) / n_samples)


def select_lag_window(
    u: np.ndarray,
    y: np.ndarray,
    fs_hz: float,
    window: str = "hann",
    band_hz: tuple[float, float] | None = None,
) -> tuple[int, list[dict]]:
    """Choose the lag window M from the data: the candidate with the least estimated error.

    Candidates are powers of two from 16 to N/2. For each M the relative mean-square error
    of Ĝ_M over the excited frequencies (input spectrum at the finest resolution within 20 dB
    of its peak, input-driven output within 20 dB of its peak; or `band_hz`) is
    estimated as bias² + variance: the bias of a lag-window estimate falls as 1/M², so
    bias(M) ≈ 4/3·(Ĝ_M − Ĝ_2M); the variance is (1/N)Σw²·(1 − γ²)/γ² with the coherence of
    the same lag window (floored at 0.05); both averaged over the band. Returns (M, per-candidate table).
    """
    n = len(u)
    candidates = [2**k for k in range(4, 20) if 2**k <= n // 2]
    if not candidates:
        raise ValueError(f"{n} samples are too few for a lag-window estimate (need >= 32)")
    partner = {m: min(2 * m, n - 1) for m in candidates}
    nfft = int(2 ** np.ceil(np.log2(max(n, 4 * partner[candidates[-1]]))))
    estimates = {
        m: blackman_tukey(u, y, fs_hz, m, window, nfft)
        for m in sorted(set(candidates) | set(partner.values()))
    }
    finest = estimates[partner[candidates[-1]]]
    f = finest.freq_hz
    if band_hz is None:
        mask = finest.excited()
        response = np.abs(finest.G) ** 2 * finest.resolved_input_psd
        if mask.any():
            mask &= response >= np.max(response[mask]) * 10.0 ** (OUTPUT_FLOOR_DB / 10.0)
    else:
        mask = (f >= band_hz[0]) & (f <= band_hz[1])
    mask &= np.abs(finest.G) > 0
    if not mask.any():
        raise ValueError("the output does not respond to the input at any excited frequency")
    table = []
    for m in candidates:
        g_m, g_2m = estimates[m].G[mask], estimates[partner[m]].G[mask]
        ratio = (1.0 - (m / partner[m]) ** 2) or 1.0  # bias ∝ 1/M²: 3/4 for M -> 2M
        scale = np.maximum(np.abs(g_2m), 1e-12 * np.max(np.abs(g_2m)))
        bias2 = np.mean((np.abs(g_m - g_2m) / scale / ratio) ** 2)
        # coherence floored at 0.05: a few points without signal must not decide alone
        coh = np.clip(estimates[m].coherence[mask], 0.05, 1.0)
        var = float(np.mean(relative_variance_factor(window, m, n) * (1.0 - coh) / coh))
        table.append(
            {"lag_samples": m, "bias2": float(bias2), "variance": var, "mse": float(bias2 + var)}
        )
    best = min(table, key=lambda row: row["mse"])
    return int(best["lag_samples"]), table


def informative_mask(
    freq_hz: np.ndarray,
    coherence: np.ndarray,
    input_psd: np.ndarray,
    min_coherence: float = 0.8,
    input_floor_db: float = -20.0,
) -> np.ndarray:
    """Frequencies (> 0) where Φ_u is within `input_floor_db` of its peak and γ² >= min."""
    peak = np.max(input_psd[freq_hz > 0]) if np.any(freq_hz > 0) else 0.0
    floor = peak * 10.0 ** (input_floor_db / 10.0)
    return (freq_hz > 0) & (input_psd >= floor) & (coherence >= min_coherence)


def informative_band(
    fr: FrequencyResponse,
    min_coherence: float = 0.8,
    input_floor_db: float = -20.0,
    output_floor_db: float = OUTPUT_FLOOR_DB,
    max_hz: float | None = None,
) -> tuple[float, float]:
    """The band worth fitting, as (lo_hz, hi_hz).

    From the lowest to the highest excited frequency (input spectrum within
    `input_floor_db` of its peak: a chirp's sweep, or the span of a multisine's tones), the
    ends trimmed to the first and last excited point where the coherence is >=
    `min_coherence` and the input-driven output spectrum |G|²Φ_u is within `output_floor_db`
    of its peak (where the response is too small to matter in the output, its relative error
    is not worth buying with the rest of the band). Coherence dips inside the band are kept:
    with the input excited there they come from smoothing bias at a sharp resonance, not from
    noise, and that is where the model most needs data. Fit only the excited points of the
    band (`informative_mask` with min_coherence 0). Raises ValueError when nothing is left.
    """
    f = fr.freq_hz
    excited = informative_mask(f, np.ones_like(f), fr.input_psd, 0.0, input_floor_db)
    if max_hz is not None:
        excited &= f <= max_hz
    good = np.flatnonzero(excited)
    if good.size:
        response = np.abs(fr.G[good]) ** 2 * fr.input_psd[good]
        floor = np.max(response) * 10.0 ** (output_floor_db / 10.0)
        good = good[(fr.coherence[good] >= min_coherence) & (response >= floor)]
    if good.size < 2:
        raise ValueError(
            f"no informative band: coherence >= {min_coherence} with input within "
            f"{-input_floor_db:g} dB of its peak holds at {good.size} frequency point(s)"
        )
    return float(f[good[0]]), float(f[good[-1]])
