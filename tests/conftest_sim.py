"""Shared simulated data for the hil_sim tests (session-scoped, computed once)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from hil_sim.rig import Rig
from hil_sim.scenarios import load_scenario, simulate

SCENARIOS = Path(__file__).resolve().parent.parent / "configs" / "scenarios"
FS = 256.0


def scenario_path(name: str) -> Path:
    return SCENARIOS / f"{name}.yaml"


def sine(amplitude_v: float, frequency_hz: float, seconds: float) -> np.ndarray:
    return amplitude_v * np.sin(2 * np.pi * frequency_hz * np.arange(int(seconds * FS)) / FS)


def h1_response(u: np.ndarray, y: np.ndarray, segment: int = 1024):
    """Independent reference estimate (scipy): f, H1 = P_uy/P_uu, coherence."""
    f, p_uy = signal.csd(u - u.mean(), y - y.mean(), fs=FS, nperseg=segment)
    _, p_uu = signal.welch(u - u.mean(), fs=FS, nperseg=segment)
    _, coh = signal.coherence(u, y, fs=FS, nperseg=segment)
    return f, p_uy / p_uu, coh


@pytest.fixture(scope="session")
def sweep_recording():
    """Two fault-free 0-50 Hz chirps (1.0 V, 20 s each) from configs/scenarios/bode_sweep."""
    return simulate(load_scenario(scenario_path("bode_sweep")), seed=3, duration_s=40.0)


@pytest.fixture(scope="session")
def test_case_recordings():
    return {
        name: simulate(load_scenario(scenario_path(name)), seed=1)
        for name in ("test_case_1", "test_case_2")
    }


def run_sine_with_supply(
    amplitude_v: float,
    supply: float,
    seed: int = 0,
    frequency_hz: float = 8.0,
    seconds: float = 4.0,
):
    """Sine run; the bearing supply changes to `supply` at half time. Returns (pre, post)."""
    rig = Rig(seed=seed)
    u = sine(amplitude_v, frequency_hz, seconds)
    half = len(u) // 2
    pre = rig.run(u[:half])
    rig.set_bearing_supply(supply)
    post = rig.run(u[half:])
    return pre, post
