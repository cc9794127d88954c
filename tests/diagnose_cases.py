"""Shared, cached data for the diagnose tests: the §V model with one hidden effect each."""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from hil_sim.msd import MsdParams, multisine, nominal_tf, simulate_recording

FS = 256.0
DURATION_S = 24.0

#: the hidden effect of each case, sized to matter against the measurement noise
HIDDEN = {
    "coulomb_friction": {"force_n": 0.5},
    "viscous_friction": {"coefficient_n_s_per_m": 2.0},
    "stribeck_friction": {"coulomb_n": 0.3, "static_n": 1.0, "stribeck_velocity_m_s": 0.1},
    "cubic_stiffness": {"k3_n_per_m3": 3e5},
    "dead_time": {"delay_s": 0.012},
    "input_saturation": {"level_v": 0.6},
    "output_saturation": {"level_m_s2": 10.0},
    "dead_zone": {"half_width_v": 0.1},
    "backlash": {"gap_v": 0.1},
    "sensor_offset": {"offset_m_s2": 1.0},
}

NOISE = dict(accel_noise_width=0.2, velocity_noise_width=0.01, position_noise_width=5e-4)


@lru_cache(maxsize=None)
def recording(effect: str | None, seed: int = 2, duration_s: float = DURATION_S):
    """A recording of the §V model (multisine 0.3–12 Hz, 0.5 V RMS) with ``effect`` hidden."""
    effects = {} if effect is None else {effect: HIDDEN[effect]}
    u = multisine(duration_s, FS, 0.3, 12.0, 0.5, seed=1)
    return simulate_recording(MsdParams(effects=effects, **NOISE), u, seed=seed)


def nominal_model() -> tuple[np.ndarray, np.ndarray]:
    """Ĝ of the §V model without any effect (exact ZOH discretisation)."""
    return nominal_tf(MsdParams())
