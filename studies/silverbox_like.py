"""A Silverbox-like record (docs/diagnose_results.md) and what `fdi diagnose` makes of it.

An electronic Duffing oscillator recorded as the Silverbox benchmark is:

    ÿ + 2ζω₀ ẏ + ω₀² y + k₃ y³ = ω₀² u        (60 Hz, ζ 0.05; u = V1, y = V2 in volts)

so k₃/ω₀² is the cubic coefficient in V per V³ that `cubic_stiffness` reports as its input
equivalent. The record: 40 000 samples of an "arrow" (Gaussian noise low-passed at 200 Hz
whose amplitude rises linearly), then ten realisations of an odd random-phase multisine to
200 Hz (``--band``), each one period of 8192 samples after 475 transient samples (the
period's end), 131 072 samples at 610.35 Hz in all; 0.1 mV of position noise. The strength
β = k₃ y²_rms/ω₀² (y_rms of the multisine part). Run as a script:

    python studies/silverbox_like.py 0.01 0.02 [--band 80]   # two minutes per record
"""

from __future__ import annotations

import argparse

import fdi_daemon  # noqa: F401  (first: it pins the BLAS kernel before NumPy loads)

# isort: split
import numpy as np
from scipy import signal

from hil_sim.msd import MsdParams, simulate_recording

FS = 610.35
F0_HZ, ZETA = 60.0, 0.05
W0 = 2 * np.pi * F0_HZ
PERIOD, TRANSIENT, REALISATIONS, ARROW = 8192, 475, 10, 40_000
LENGTH = 131_072
U_RMS_V = 0.1
#: the arrow's tip drives the output this many times the multisine part's RMS
ARROW_TIP = 1.6


def odd_multisine(seed: int, band_hz: float = 200.0) -> np.ndarray:
    """One period of an odd random-phase multisine to band_hz, unit RMS."""
    rng = np.random.default_rng(seed)
    lines = np.arange(1, int(band_hz * PERIOD / FS) + 1, 2)
    spectrum = np.zeros(PERIOD // 2 + 1, complex)
    spectrum[lines] = np.exp(2j * np.pi * rng.uniform(size=lines.size))
    u = np.fft.irfft(spectrum, PERIOD)
    return u / np.std(u)


def excitation(
    seed: int = 1, band_hz: float = 200.0, realisations: int = REALISATIONS
) -> np.ndarray:
    """V1: the arrow, the realisations (each preceded by its period's last 475 samples),
    with all ten, zeros to the benchmark's 131 072 samples."""
    rng = np.random.default_rng(seed)
    noise = signal.lfilter(*signal.butter(6, band_hz, fs=FS), rng.standard_normal(ARROW))
    arrow = noise / np.std(noise) * np.linspace(0.0, 1.0, ARROW)
    parts = []
    for r in range(realisations):
        period = odd_multisine(seed * 100 + r, band_hz)
        parts.append(np.concatenate([period[-TRANSIENT:], period]))
    multi = np.concatenate(parts)
    # the arrow's tip (its last 2000 samples) at ARROW_TIP times the multisine's RMS, in u:
    # the oscillator is nearly linear, so the output follows
    arrow *= ARROW_TIP / np.std(arrow[-2000:])
    u = np.concatenate([arrow, multi]) * U_RMS_V
    tail = LENGTH - u.size if realisations == REALISATIONS else 0
    return np.concatenate([u, np.zeros(tail)])


def params(k3: float) -> MsdParams:
    effects = {"cubic_stiffness": {"k3_n_per_m3": k3}} if k3 else {}
    return MsdParams(
        mass_kg=1.0,
        stiffness_n_per_m=W0**2,
        damping_n_s_per_m=2 * ZETA * W0,
        gain_n_per_v=W0**2,
        input_filter_hz=None,
        fs_hz=FS,
        substeps=8,
        position_noise_width=0.1e-3 * np.sqrt(12.0),
        effects=effects,
    )


def record(beta: float, seed: int = 1, band_hz: float = 200.0, realisations: int = REALISATIONS):
    """(V1, V2 = position, the true cubic coefficient in V per V³); k₃ gives the strength
    β on the linear oscillator's multisine part."""
    u = excitation(seed, band_hz, realisations)
    y = simulate_recording(params(0.0), u, seed=seed)["position"][
        ARROW : ARROW + realisations * PERIOD
    ]
    k3 = beta * W0**2 / float(np.mean(y**2))
    rec = simulate_recording(params(k3), u, seed=seed)
    return rec.v_in, rec["position"], k3 / W0**2


def diagnose_record(beta: float, band_hz: float = 200.0) -> dict:
    """`run_diagnose` on the record of strength ``beta`` (a fitted linear baseline, position
    out): names, gaps, floor, the input-equivalent sizes of the named effects and the true
    cubic coefficient (V per V³)."""
    from fdi_daemon.diagnose.workflow import run_diagnose

    u, y, truth = record(beta, band_hz=band_hz)
    result = run_diagnose(u, y, FS, "position")
    return {
        "beta": beta,
        "band_hz": band_hz,
        "named": result.named,
        "gap_before": result.gap_before,
        "gap_after": result.gap_after,
        "floor": result.info["noise_floor"]["floor"],
        "sizes": {
            e.name: {
                k: round(v, 4) for k, v in e.physical.items() if k.endswith("input_equivalent")
            }
            for e in result.selection.named
        },
        "k3_truth": truth,
    }


def main(betas: list[float], band_hz: float) -> None:
    for beta in betas:
        r = diagnose_record(beta, band_hz)
        print(
            f"beta {beta}, band {band_hz:g} Hz: named {r['named']}, gap "
            f"{r['gap_before']:.4f} -> {r['gap_after']:.4f} "
            f"(floor {r['floor']}), "
            f"sizes {r['sizes']}, k3 truth {r['k3_truth']:.4f} V/V^3",
            flush=True,
        )


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("beta", type=float, nargs="*", default=[0.01, 0.02])
    parser.add_argument("--band", type=float, default=200.0, help="multisine band, Hz")
    args = parser.parse_args()
    main(args.beta, args.band)
