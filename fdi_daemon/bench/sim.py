"""Speed of the nonlinear simulated rig: simulated seconds per wall-clock second.

Measured on changing fault-free operation (random sines/multisines/chirps, supply and
temperature drift, position centring), i.e. the work of `fdi sim record
configs/scenarios/fault_free_hour.yaml`, after a short warm-up run that loads or compiles
the numba kernel. With ``NUMBA_DISABLE_JIT=1`` the same kernel runs as pure Python.
"""

from __future__ import annotations

import os
import time

HOUR_S = 3600.0


def bench_sim(duration_s: float = 300.0, seed: int = 0) -> dict:
    """Simulate ``duration_s`` of changing operation; returns the measured speeds.

    Keys: simulated_s, wall_s, sim_s_per_wall_s, hour_wall_s (projected wall time of one
    simulated hour), kernel_sim_s_per_wall_s (the bare kernel on one long array), jit,
    substeps, internal_step_us, warmup_s (kernel load/compile).
    """
    import numpy as np

    from hil_sim.rig import Rig
    from hil_sim.scenarios import Scenario, simulate

    scenario = Scenario(
        name="bench_changing_operation",
        duration_s=duration_s,
        excitation=[
            {
                "kind": "random",
                "amplitude_v": (0.3, 1.6),
                "frequency_hz": (1.0, 12.0),
                "segment_s": (5.0, 60.0),
            }
        ],
        centring_gain_v_per_m=30.0,
        drift={
            "supply_pressure": {"times_s": [0.0, HOUR_S], "values": [1.0, 0.97]},
            "temperature_k": {"times_s": [0.0, HOUR_S], "values": [293.0, 303.0]},
        },
    )
    t0 = time.perf_counter()
    simulate(scenario, seed=seed, duration_s=1.0)
    warmup = time.perf_counter() - t0

    t0 = time.perf_counter()
    simulate(scenario, seed=seed)
    wall = time.perf_counter() - t0

    rig = Rig(scenario.rig, seed=seed)
    fs = scenario.rig.fs_hz
    u = 0.8 * np.sin(2.0 * np.pi * 5.0 * np.arange(int(duration_s * fs)) / fs)
    t0 = time.perf_counter()
    rig.run(u)
    kernel_wall = time.perf_counter() - t0

    return {
        "simulated_s": duration_s,
        "wall_s": wall,
        "sim_s_per_wall_s": duration_s / wall,
        "hour_wall_s": HOUR_S * wall / duration_s,
        "kernel_sim_s_per_wall_s": duration_s / kernel_wall,
        "jit": os.environ.get("NUMBA_DISABLE_JIT", "0") in ("", "0"),
        "substeps": scenario.rig.substeps,
        "internal_step_us": 1e6 / (fs * scenario.rig.substeps),
        "warmup_s": warmup,
    }
