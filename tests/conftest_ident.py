"""Shared data for the identification tests: known discrete systems and simulated recordings.

Known systems have coefficients chosen here (not estimated anywhere); simulated-rig and
mass-spring-damper recordings are made once per session.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from fdi_daemon.io.recordings import Recording, write_recording
from tests.disk_cache import ROOT, cached_build

FS = 256.0

#: the known plant: a differentiator-like 4th-order system with a 8 Hz resonance (b0 = 0)
PLANT_POLES = np.array(
    [0.85 * np.exp(2j * np.pi * 8 / FS), 0.85 * np.exp(-2j * np.pi * 8 / FS), 0.9, 0.6]
)
PLANT_ZEROS = np.array([1.0, -0.5, 0.3])
PLANT_GAIN = 0.05

#: the known [4 3 0] output-error filter
OE_B = np.array([-0.10, 0.06, -0.04, -0.02])
OE_F = np.real(np.poly([0.9 * np.exp(0.3j), 0.9 * np.exp(-0.3j), 0.7]))


def plant() -> tuple[np.ndarray, np.ndarray]:
    """(b, a) of the known plant in powers of q⁻¹, b0 = 0."""
    b = PLANT_GAIN * np.concatenate([[0.0], np.real(np.poly(PLANT_ZEROS))])
    return b, np.real(np.poly(PLANT_POLES))


def chirp(n_samples: int, f1_hz: float = 20.0, amplitude: float = 0.7, phase: float = 0.0):
    t = np.arange(n_samples) / FS
    return amplitude * signal.chirp(t, 0.0, t[-1], f1_hz, phi=phase)


def plant_output(u: np.ndarray, noise_fraction: float, seed: int) -> np.ndarray:
    """Known plant driven by u, plus white noise of noise_fraction × std(output)."""
    b, a = plant()
    y = signal.lfilter(b, a, u)
    rng = np.random.default_rng(seed)
    return y + noise_fraction * np.std(y) * rng.standard_normal(len(y))


def plant_recording(path, n_samples: int, seed: int, noise_fraction: float = 0.02):
    """A chirp recording of the known plant (columns t, v_in, accel; fs in the metadata)."""
    u = chirp(n_samples, phase=37.0 * seed)
    rec = Recording(
        {"t": np.arange(n_samples) / FS, "v_in": u, "accel": plant_output(u, noise_fraction, seed)},
        {"fs": "256"},
    )
    write_recording(path, rec)
    return path


def signature_data(
    gamma: float, kind: str, noise_fraction: float, seed: int = 2, n_samples: int = 1024
) -> tuple[np.ndarray, np.ndarray]:
    """(residual, velocity) with residual = G_e(sign v + γ v) + noise, G_e = OE_B/OE_F.

    kind "sweep": a chirp 2..8 Hz whose amplitude grows 0.03..0.1 m/s (identifying);
    kind "sine": one 8 Hz sine of 0.08 m/s (not identifying).
    """
    t = np.arange(n_samples) / FS
    if kind == "sweep":
        v = 0.1 * (0.3 + 0.7 * t / t[-1]) * np.sin(2 * np.pi * (2.0 * t + 0.75 * t**2))
    elif kind == "sine":
        v = 0.08 * np.sin(2 * np.pi * 8.0 * t)
    else:
        raise ValueError(kind)
    r = signal.lfilter(OE_B, OE_F, np.sign(v) + gamma * v)
    rng = np.random.default_rng(seed)
    return r + noise_fraction * np.std(r) * rng.standard_normal(n_samples), v


def match_roots(estimated: np.ndarray, true: np.ndarray) -> float:
    """Largest distance between each true root and its nearest estimated root."""
    estimated = np.asarray(estimated)
    return float(max(np.min(np.abs(estimated - r)) for r in true))


# ---------------------------------------------------------------- session recordings

SIM_SCENARIOS = (
    "ident_chirp",
    "ident_chirp_long",
    "signature_calibration_paired",
    "test_case_1",
    "test_case_2",
)


@pytest.fixture(scope="session")
def sim_recordings(request):
    """CSV recordings of the simulated rig: the scenarios above and ident_chirp with seed 1
    (built once per code version, shared by the xdist workers: tests/disk_cache.py)."""
    from hil_sim.scenarios import load_scenario, simulate

    scenarios = {name: ROOT / f"configs/scenarios/{name}.yaml" for name in SIM_SCENARIOS}

    def build(out):
        for name, path in scenarios.items():
            write_recording(out / f"{name}.csv", simulate(load_scenario(path)))
        chirp = load_scenario(scenarios["ident_chirp"])
        write_recording(out / "ident_chirp_seed1.csv", simulate(chirp, seed=1))

    out = cached_build(request.config, "sim_recordings", scenarios.values(), build)
    return {name: out / f"{name}.csv" for name in (*SIM_SCENARIOS, "ident_chirp_seed1")}


@pytest.fixture(scope="session")
def sim_model(sim_recordings, request):
    """Plant model of the simulated rig made by `fdi identify` on ident_chirp (built once per
    code version, shared by the xdist workers)."""
    from fdi_daemon.cli import main

    def build(out):
        assert (
            main(["identify", str(sim_recordings["ident_chirp"]), "-o", str(out / "model.yaml")])
            == 0
        )

    chirp = sim_recordings["ident_chirp"]
    return cached_build(request.config, "sim_model", [chirp], build) / "model.yaml"


def true_gamma(rec, t0: float, t1: float, min_speed_m_s: float = 0.01) -> float:
    """γ_f from the simulator's ground truth: friction ≈ α sign(v) + β v fitted on the
    sliding samples of the window (not stuck, |v| above min_speed, i.e. past the Stribeck
    region), γ_f = β/α."""
    sel = (rec.t >= t0) & (rec.t < t1)
    v = rec["velocity_true"][sel]
    force = rec["friction_force"][sel]
    sliding = np.abs(v) > min_speed_m_s
    if "stuck" in rec.columns:
        sliding &= rec["stuck"][sel] == 0
    coef = np.linalg.lstsq(
        np.column_stack([np.sign(v[sliding]), v[sliding]]), force[sliding], rcond=None
    )[0]
    return float(coef[1] / coef[0])


@pytest.fixture(scope="session")
def msd_recordings(tmp_path_factory):
    """The paper's §V model (hil_sim.msd): a friction-free chirp, a validation chirp and an
    8 Hz sine stepped through six amplitudes with a Coulomb 0.5 N + viscous 1.0 N·s/m fault
    from 1 s (γ_f = 2 s/m)."""
    from hil_sim import msd

    out = tmp_path_factory.mktemp("msd")
    fs = FS
    clean = msd.MsdParams(accel_noise_width=0.02)
    t = np.arange(1024) / fs
    chirp_u = 0.7 * np.sin(np.pi * 20.0 / t[-1] * t**2)
    t2 = np.arange(2048) / fs
    chirp_val = 0.5 * np.sin(np.pi * 20.0 / t2[-1] * t2**2 + 1.0)
    fault = msd.MsdParams(
        accel_noise_width=0.02, fault_time_s=1.0, coulomb_n=0.5, viscous_n_s_per_m=1.0
    )
    t3 = np.arange(int(6 * fs)) / fs
    amplitude = 0.3 + 1.2 * (np.floor(t3) % 6) / 5
    paths = {
        "chirp": write_recording(out / "chirp.csv", msd.simulate_recording(clean, chirp_u, 1)),
        "chirp_val": write_recording(
            out / "chirp_val.csv", msd.simulate_recording(clean, chirp_val, 2)
        ),
        "amp_steps": write_recording(
            out / "amp_steps.csv",
            msd.simulate_recording(fault, amplitude * np.sin(2 * np.pi * 8.0 * t3), 5),
        ),
    }
    paths["gamma_true"] = fault.viscous_n_s_per_m / fault.coulomb_n
    return paths
