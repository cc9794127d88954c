"""Speed of the offline identification (targets of issue 3): `identify` on 1024 samples in
< 2 s and the 51-point signature grid in < 30 s.

Data: a known 4th-order discrete plant (8 Hz resonance, differentiating zero) driven by the
paper's 0.7 V 0–20 Hz chirp, 1024 samples with 2 % output noise; and a 1024-sample fault
window whose residual is a known [4 3 0] G_e applied to sign(v) + 3 v (v: a 2–8 Hz sweep with
growing amplitude) with 5 % noise. Timed: the whole numerical path of each command (spectral
estimate with the automatic lag window and band, Levy/SK + LM fit, validation; both γ sweeps,
refinement, profile), without file I/O.
"""

from __future__ import annotations

import time

import numpy as np
from scipy import signal

FS_HZ = 256.0
N_SAMPLES = 1024


def _plant_data(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    poles = [
        0.85 * np.exp(2j * np.pi * 8 / FS_HZ),
        0.85 * np.exp(-2j * np.pi * 8 / FS_HZ),
        0.9,
        0.6,
    ]
    a = np.real(np.poly(poles))
    b = 0.05 * np.concatenate([[0.0], np.real(np.poly([1.0, -0.5, 0.3]))])
    t = np.arange(N_SAMPLES) / FS_HZ
    u = 0.7 * signal.chirp(t, 0.0, t[-1], 20.0)
    y = signal.lfilter(b, a, u)
    return u, y + 0.02 * np.std(y) * rng.standard_normal(N_SAMPLES)


def _signature_data(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    f = np.real(np.poly([0.9 * np.exp(0.3j), 0.9 * np.exp(-0.3j), 0.7]))
    b = np.array([-0.10, 0.06, -0.04, -0.02])
    t = np.arange(N_SAMPLES) / FS_HZ
    v = 0.1 * (0.3 + 0.7 * t / t[-1]) * np.sin(2 * np.pi * (2.0 * t + 0.75 * t**2))
    r = signal.lfilter(b, f, np.sign(v) + 3.0 * v)
    return r + 0.05 * np.std(r) * rng.standard_normal(N_SAMPLES), v


def bench_ident(repeats: int = 3) -> dict:
    """Best-of-`repeats` wall times (s) of identify and of the 51-point signature grid."""
    from fdi_daemon.ident import plant, signature

    rng = np.random.default_rng(0)
    u, y = _plant_data(rng)
    residual, velocity = _signature_data(rng)
    identify_s, grid_s = [], []
    ident = result = None
    for _ in range(max(1, repeats)):
        start = time.perf_counter()
        ident = plant.identify_plant(u, y, FS_HZ)
        plant.validate_plant(ident, u, y)
        identify_s.append(time.perf_counter() - start)
        start = time.perf_counter()
        result = signature.estimate_signature(residual, velocity, signature.gamma_grid())
        grid_s.append(time.perf_counter() - start)
    assert ident is not None and result is not None  # the loop runs at least once
    return {
        "identify_1024_samples_s": min(identify_s),
        "identify_target_s": 2.0,
        "signature_grid_points": int(len(result.grid)),
        "signature_grid_1024_samples_s": min(grid_s),
        "signature_target_s": 30.0,
        "signature_oe_evaluations": int(result.evaluations),
        "identify_lag_samples": int(ident.choices["lag_samples"]),
        "signature_gamma_f": float(result.gamma_f),
    }
