"""Shared, expensive data for the monitor tests (cached per session).

The model is the one shipped for the simulated rig, configs/model_sim_rig.yaml (made with
`fdi identify` and `fdi signature`); the scenarios are those of configs/scenarios.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SCENARIOS = REPO / "configs" / "scenarios"
MODEL = REPO / "configs" / "model_sim_rig.yaml"
FS_HZ = 256.0
#: `fdi signature`'s windows for the paired calibration run, as README step 2 gives them
PAIRED_SIGNATURE_WINDOWS = (
    "--fault-window",
    "22:42",
    "--reference-window",
    "1:21",
    "--lowpass-hz",
    "10",
)


@functools.cache
def scenario_recording(name: str, seed: int = 0, duration_s: float | None = None):
    """A scenario of configs/scenarios simulated once per session."""
    from hil_sim.scenarios import load_scenario, simulate

    return simulate(load_scenario(SCENARIOS / f"{name}.yaml"), seed=seed, duration_s=duration_s)


@functools.cache
def sim_rig_model():
    """FdiModel of the simulated rig (configs/model_sim_rig.yaml)."""
    from fdi_daemon.io.model_file import load_model

    return load_model(MODEL)


def model_copy(**changes):
    """A fresh copy of the sim-rig model with some fields replaced (e.g. detector={...})."""
    import copy

    model = copy.deepcopy(sim_rig_model())
    for key, value in changes.items():
        setattr(model, key, value)
    return model


def msd_system(
    fault_time_s: float = float("inf"),
    duration_s: float = 8.0,
    seed: int = 0,
    coulomb_n: float = 0.5,
    viscous: float = 2.0,
):
    """The paper's §V system with exact Ĝ and G_e: (model, recording)."""
    from fdi_daemon.io.model_file import FaultFilter, FdiModel
    from fdi_daemon.io.recordings import Recording
    from hil_sim.msd import MsdParams, MsdSimulator, friction_tf, nominal_tf

    params = MsdParams(
        fault_time_s=fault_time_s,
        coulomb_n=coulomb_n,
        viscous_n_s_per_m=viscous,
        accel_noise_width=0.02,
    )
    num, den = friction_tf(params)
    plant_b, plant_a = nominal_tf(params)
    model = FdiModel(
        fs=FS_HZ,
        plant_b=plant_b,
        plant_a=plant_a,
        fault_filter=FaultFilter(b=-coulomb_n * num, f=den, nk=0, gamma_f=viscous / coulomb_n),
        velocity={"lead_compensation_hz": 8.0},
    )
    t = np.arange(int(duration_s * FS_HZ)) / FS_HZ
    out = MsdSimulator(params, seed).run(1.4 * np.sin(2 * np.pi * 8.0 * t))
    cols = {k: out[k] for k in ("t", "v_in", "accel", "fault_active")}
    cols["seq"] = np.arange(t.size, dtype=np.int64)
    return model, Recording(cols, {"fs": str(FS_HZ)})


#: random operation of the changing-operation cases: 0.3-1.6 V, 1-12 Hz, segments of 5-60 s
CHANGING_OPERATION = {
    "kind": "random",
    "amplitude_v": [0.3, 1.6],
    "frequency_hz": [1.0, 12.0],
    "segment_s": [5.0, 60.0],
}


def changing_operation_spec(events: list[dict], duration_s: float) -> dict:
    """A scenario of CHANGING_OPERATION with ``events`` (hil_sim's scenario mapping)."""
    return {
        "name": "changing",
        "duration_s": duration_s,
        "excitation": [dict(CHANGING_OPERATION)],
        "events": events,
    }


def first_event(events, kind):
    return next((e for e in events if e["kind"] == kind), None)
