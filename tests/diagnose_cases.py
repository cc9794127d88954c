"""Shared, cached data for the diagnose tests: the §V model with one hidden effect each,
machines like the real ones, and the simulated pneumatic rig with one fault each."""

from __future__ import annotations

import os
from functools import cache
from pathlib import Path

import numpy as np
from scipy import signal

from fdi_daemon.blas_kernel import cpu_flags
from hil_sim.msd import MsdParams, multisine, nominal_tf, simulate_recording

FS = 256.0
DURATION_S = 24.0


def has_avx512() -> bool:
    """Whether this CPU has AVX-512 (OpenBLAS's SkylakeX kernel)."""
    return "avx512f" in cpu_flags()


def openblas_environment(kernel: str | None) -> dict[str, str]:
    """This process's environment for a child whose only difference is OpenBLAS's kernel
    ``kernel`` (None: OpenBLAS's own choice): with OpenBLAS's own thread count, whatever an
    xdist worker or a Dask nanny left in the variables (`run_diagnose` holds its BLAS to one
    thread itself). OpenBLAS reads the kernel when it loads, so each kernel needs a process."""
    dropped = ("OPENBLAS_CORETYPE", "OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")
    env = {k: v for k, v in os.environ.items() if k not in dropped}
    if kernel is not None:
        env["OPENBLAS_CORETYPE"] = kernel
    return env


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


@cache
def recording(effect: str | None, seed: int = 2, duration_s: float = DURATION_S):
    """A recording of the §V model (multisine 0.3–12 Hz, 0.5 V RMS) with ``effect`` hidden."""
    effects = {} if effect is None else {effect: HIDDEN[effect]}
    u = multisine(duration_s, FS, 0.3, 12.0, 0.5, seed=1)
    return simulate_recording(MsdParams(effects=effects, **NOISE), u, seed=seed)


def nominal_model() -> tuple[np.ndarray, np.ndarray]:
    """Ĝ of the §V model without any effect (exact ZOH discretisation)."""
    return nominal_tf(MsdParams())


# ---------------------------------------------------------------- machines like the real ones

#: the closed-loop stage (hil_sim.stage): 60 s at 500 Hz, six periods of a multisine
STAGE_DURATION_S = 60.0


@cache
def stage_recording(coulomb_n: float = 20.0, offset_n: float = 1.0, seed: int = 2):
    """A PI velocity loop around a mass with Coulomb friction and a constant force; the
    recording's columns are ``force`` and ``vel`` (not the recording contract's names)."""
    from hil_sim.stage import StageParams, simulate_stage, velocity_reference

    p = StageParams(coulomb_n=coulomb_n, offset_n=offset_n)
    r = velocity_reference(STAGE_DURATION_S, p.fs_hz, seed=1, periods=6)
    return simulate_stage(p, r, seed=seed)


#: the positioning drive (hil_sim.stage.POSITIONER): 24.8 s at 1 kHz of point-to-point moves
POSITIONER_DURATION_S = 24.8


@cache
def positioner_recording(coulomb_n: float = 20.0, offset_n: float = -3.0, seed: int = 2):
    """A ball-screw drive under a position loop (P position, P velocity on the encoder's
    differences), moving from point to point with rests between the moves (the load held
    by its friction a third of the time); columns ``force``, ``vel``, ``pos``."""
    from dataclasses import replace

    from hil_sim.stage import POSITIONER, move_reference, simulate_stage

    p = replace(POSITIONER, coulomb_n=coulomb_n, offset_n=offset_n)
    q = move_reference(POSITIONER_DURATION_S, p.fs_hz, seed=1)
    return simulate_stage(p, q, seed=seed, loop="position")


#: the ratio each named linear change reports
NAMED_RATIOS = {
    "mass_change": "mass_ratio",
    "stiffness_change": "stiffness_ratio",
    "gain_fault": "gain_ratio",
    "viscous_friction": "damping_change_per_s",
}


def noise_input(
    duration_s: float,
    corner_hz: float,
    rms: float,
    seed: int = 5,
    fs_hz: float = FS,
    low_hz: float | None = None,
):
    """Gaussian noise at fs_hz low-passed at corner_hz (4th-order Butterworth; band-passed
    from low_hz when given: no content at DC to drift an integrating plant), scaled to rms."""
    band, kind = (corner_hz, "lowpass") if low_hz is None else ([low_hz, corner_hz], "bandpass")
    u = signal.lfilter(
        *signal.butter(4, band, btype=kind, fs=fs_hz),
        np.random.default_rng(seed).standard_normal(int(duration_s * fs_hz)),
    )
    return u * rms / np.std(u)


@cache
def duffing_recording(k3_n_per_m3: float = 3e5, seed: int = 2, noise_hz: float | None = None):
    """A Duffing oscillator: the §V mass-spring-damper driven directly by the input (no
    input filter) with a cubic spring (≈ 60 % of the linear force at the peaks); 40 s of a
    0.3–12 Hz multisine at 1 V RMS, or with ``noise_hz`` of Gaussian noise low-passed there
    (4th-order Butterworth, seed 5, 1 V RMS); position out (0.5 mm uniform noise)."""
    effects = {"cubic_stiffness": {"k3_n_per_m3": k3_n_per_m3}} if k3_n_per_m3 else {}
    u = (
        multisine(40.0, FS, 0.3, 12.0, 1.0, seed=1)
        if noise_hz is None
        else noise_input(40.0, noise_hz, 1.0)
    )
    return simulate_recording(
        MsdParams(input_filter_hz=None, effects=effects, **NOISE), u, seed=seed
    )


@cache
def arrow_recording(k3_n_per_m3: float = 1.5e5, seed: int = 2):
    """A Duffing oscillator recorded as nonlinear benchmarks are (the Silverbox): 20 s of
    an "arrow" (Gaussian noise low-passed at 12 Hz whose amplitude rises linearly to
    1.7 V RMS) then three realisations of a 0.3–12 Hz multisine, 8 s each at 1 V RMS; the
    §V model without input filter, position out. The arrow's tip drives the spring harder
    than anything after it."""
    rising = noise_input(20.0, 12.0, 1.0) * np.linspace(0.0, 1.0, int(20.0 * FS))
    rising *= 1.7 / np.std(rising[-int(2.0 * FS) :])
    u = np.concatenate(
        [rising] + [multisine(8.0, FS, 0.3, 12.0, 1.0, seed=s) for s in (11, 12, 13)]
    )
    return simulate_recording(
        MsdParams(
            input_filter_hz=None, effects={"cubic_stiffness": {"k3_n_per_m3": k3_n_per_m3}}, **NOISE
        ),
        u,
        seed=seed,
    )


@cache
def changed_recording(parameter: str, ratio: float, seed: int = 2):
    """The §V model whose ``parameter`` (an `MsdParams` field: the actuator's
    ``gain_n_per_v``, the spring's ``stiffness_n_per_m``, the load's ``mass_kg``) is
    ``ratio`` times the nominal one; the nominal model is not changed."""
    u = multisine(DURATION_S, FS, 0.3, 12.0, 0.5, seed=1)
    value = ratio * getattr(MsdParams(), parameter)
    return simulate_recording(MsdParams(**{parameter: value}, **NOISE), u, seed=seed)


# ---------------------------------------------------------------- the pneumatic rig (hil_sim.rig)

#: the rig's nominal model: `fdi identify` on the fault-free identification chirp
#: (configs/scenarios/ident_chirp.yaml; provenance in the file)
RIG_MODEL = Path(__file__).resolve().parents[1] / "configs" / "model_sim_rig.yaml"
RIG_FS = 256.0


def rig_model() -> tuple[np.ndarray, np.ndarray]:
    from fdi_daemon.io.model_file import load_model

    model = load_model(RIG_MODEL)
    return model.plant_b, model.plant_a


#: input effects hidden between the recorded command and the rig's valve (`rig_recording`):
#: two samples of dead time at 256 Hz, a dead zone, a saturation and a backlash of the drive
RIG_INPUT_EFFECTS = {
    "dead_time": {"delay_s": 2 / RIG_FS},
    "dead_zone": {"half_width_v": 0.15},
    "input_saturation": {"level_v": 1.2},
    "backlash": {"gap_v": 0.2},
}


#: the rig's command signals (duration s, RMS V) -> V at RIG_FS: the tests' multisine, and
#: two unlike it (a random signal, and a multisine reaching past the model's 18.75 Hz band)
#: that keep the piston off its end stops (no content at DC: the cylinder integrates)
RIG_EXCITATIONS = {
    "multisine 1-12 Hz": lambda d, rms: multisine(d, RIG_FS, 1.0, 12.0, rms, seed=3),
    "noise 1-15 Hz": lambda d, rms: noise_input(d, 15.0, rms, fs_hz=RIG_FS, low_hz=1.0),
    "multisine 2-25 Hz": lambda d, rms: multisine(d, RIG_FS, 2.0, 25.0, rms, seed=3),
}


@cache
def rig_recording(
    fault: str | None = None,
    value: float = 0.0,
    rms_v: float = 0.4,
    duration_s: float = 30.0,
    variant: tuple[tuple[str, float], ...] = (),
    input_effect: str | None = None,
    excitation: str = "multisine 1-12 Hz",
):
    """(v_in, accel) of the simulated pneumatic rig (`hil_sim.rig.Rig`, seed 4) driven by
    ``excitation`` (`RIG_EXCITATIONS`) of ``rms_v`` after 1 s at rest, with ``fault``
    switched on from the start: ``bearing_supply`` (a fraction of nominal: below ≈ 0.8 the
    block touches and Coulomb contact friction acts on the load) or one of
    `hil_sim.rig.FAULTS`. variant: `RigParams` overrides, as (name, value) pairs (a rig
    with other physics). input_effect: one of `RIG_INPUT_EFFECTS`, acting on the command
    before the valve; the recorded v_in is the command (as measured)."""
    from hil_sim.msd import input_effects
    from hil_sim.rig import Rig, RigParams

    rig = Rig(RigParams(**dict(variant)), seed=4)
    if fault == "bearing_supply":
        rig.set_bearing_supply(value)
    elif fault is not None:
        rig.set_fault(fault, value)
    rig.run(np.zeros(int(RIG_FS)))
    command = RIG_EXCITATIONS[excitation](duration_s, rms_v)
    hidden = {input_effect: RIG_INPUT_EFFECTS[input_effect]} if input_effect else {}
    applied = input_effects(command, hidden, RIG_FS)
    out = rig.run(applied)
    # the rig measures the voltage its valve gets (with the converter's error): recorded is
    # the command with that error, the effect hidden between them
    return command + (out["v_in"] - applied), out["accel"]
