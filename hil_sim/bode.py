"""Bode plot of the simulated rig, v_in -> accel, estimated from chirp recordings (Fig. 3).

The estimate is the Welch H1 of `fdi_daemon.ident.spectral` (the identification tooling's;
not duplicated here). Regenerate the documented plot with

    python -m hil_sim.bode docs/bode_sim_rig.png \
        configs/scenarios/ident_chirp_long.yaml configs/scenarios/bode_sweep.yaml
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from fdi_daemon.io.outputs import pyplot, save_figure
from fdi_daemon.io.recordings import Recording

SEGMENT_SAMPLES = 1024


def rig_response(rec: Recording, segment_samples: int = SEGMENT_SAMPLES):
    """FrequencyResponse (freq_hz, G, coherence) of v_in -> accel for one recording."""
    from fdi_daemon.ident.spectral import welch_h1

    return welch_h1(rec.v_in, rec.accel, rec.fs, segment_samples)


def slope_db_per_decade(freq_hz: np.ndarray, G: np.ndarray, f_lo: float, f_hi: float) -> float:
    """Least-squares slope of 20·log10|G| against log10 f over [f_lo, f_hi] (dB/decade)."""
    band = (freq_hz >= f_lo) & (freq_hz <= f_hi)
    return float(np.polyfit(np.log10(freq_hz[band]), 20.0 * np.log10(np.abs(G[band])), 1)[0])


def plot_bode(
    path: str | Path, curves: list[tuple[str, object]], min_coherence: float = 0.5
) -> Path:
    """Magnitude, phase and coherence of each (label, FrequencyResponse); points with
    coherence below ``min_coherence`` are drawn faint."""
    plt = pyplot()

    fig, (ax_m, ax_p, ax_c) = plt.subplots(
        3, 1, figsize=(8, 9), sharex=True, gridspec_kw={"height_ratios": [3, 2, 1]}
    )
    for (label, fr), color in zip(curves, ("C0", "C1", "C2", "C3")):
        f, G, coh = fr.freq_hz, fr.G, fr.coherence
        keep = f > 0
        f, G, coh = f[keep], G[keep], coh[keep]
        good = coh >= min_coherence
        mag = 20.0 * np.log10(np.maximum(np.abs(G), 1e-12))
        phase = np.degrees(np.unwrap(np.angle(G)))
        ax_m.semilogx(f, np.where(good, mag, np.nan), color=color, label=label)
        ax_m.semilogx(f, mag, color=color, alpha=0.2)
        ax_p.semilogx(f, np.where(good, phase, np.nan), color=color)
        ax_c.semilogx(f, coh, color=color)
    ref_f = np.array([0.5, 10.0])
    ref_mag = 20.0 * np.log10(ref_f / 10.0) + _level_at(curves[0][1], 10.0)
    ax_m.semilogx(ref_f, ref_mag, "k--", lw=1, label="+20 dB/decade")
    ax_m.set_ylabel("|G| (dB re 1 (m/s²)/V)")
    ax_m.set_title("Simulated rig: valve voltage v_in -> load acceleration (cf. paper Fig. 3)")
    ax_m.legend(loc="lower center", fontsize=8)
    ax_p.set_ylabel("phase (deg)")
    ax_c.set_ylabel("coherence")
    ax_c.set_ylim(0, 1.05)
    ax_c.set_xlabel("frequency (Hz)")
    for ax in (ax_m, ax_p, ax_c):
        ax.grid(True, which="both", alpha=0.3)
        ax.set_xlim(0.3, 128)
    fig.tight_layout()
    return save_figure(fig, path)


def _level_at(fr, freq_hz: float) -> float:
    i = int(np.argmin(np.abs(fr.freq_hz - freq_hz)))
    # the low-frequency asymptote extrapolated from 1..3 Hz
    band = (fr.freq_hz >= 1.0) & (fr.freq_hz <= 3.0)
    level = np.mean(20 * np.log10(np.abs(fr.G[band])) - 20 * np.log10(fr.freq_hz[band] / freq_hz))
    return float(level if np.isfinite(level) else 20 * np.log10(abs(fr.G[i])))


def main(argv: list[str] | None = None) -> int:
    from hil_sim.scenarios import load_scenario, simulate

    parser = argparse.ArgumentParser(
        prog="python -m hil_sim.bode", description=__doc__.split("\n")[0]
    )
    parser.add_argument("output", help="PNG to write")
    parser.add_argument("scenarios", nargs="+", help="chirp scenario YAML files")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    curves = []
    for name in args.scenarios:
        scenario = load_scenario(name)
        fr = rig_response(simulate(scenario, seed=args.seed))
        curves.append((f"{scenario.name}: {scenario.description}", fr))
        slope = slope_db_per_decade(fr.freq_hz, fr.G, 1.0, 6.0)
        peak = int(np.argmax(np.abs(fr.G) * (fr.freq_hz < 30)))
        print(
            f"{scenario.name}: slope 1-6 Hz {slope:+.1f} dB/dec, peak "
            f"{20 * np.log10(abs(fr.G[peak])):.1f} dB at {fr.freq_hz[peak]:.2f} Hz"
        )
        for f in (1.0, 10.0, 20.0, 30.0):
            i = int(np.argmin(np.abs(fr.freq_hz - f)))
            print(
                f"  |G({f:g} Hz)| = {20 * np.log10(abs(fr.G[i])):.1f} dB, "
                f"phase {np.degrees(np.angle(fr.G[i])):.0f} deg, coherence {fr.coherence[i]:.2f}"
            )
    print(f"wrote {plot_bode(args.output, curves)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
