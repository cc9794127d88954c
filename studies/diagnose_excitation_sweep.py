"""`fdi diagnose` under excitations other than the tests' multisine (docs/diagnose_results.md).
Run: ``python studies/diagnose_excitation_sweep.py [mechanics] [duffing] [rig]`` (all three
by default; under a minute each for mechanics and duffing, about three for the rig, on two
shared cores).

mechanics: the §V model with its nominal model file, one parameter changed (mass × 0.8 and
× 1.25, spring × 0.8, damper × 1.5), 24 s, under band-limited Gaussian noise to 15 Hz, a
0.3–4 Hz multisine (below the 5 Hz mode) and a 3–8 Hz multisine (0.5 V RMS), acceleration
and position outputs. duffing: the Duffing oscillator of `diagnose_cases.duffing_recording`
(no model file: a fitted linear baseline), k₃ 3·10⁴, 10⁵ and 3·10⁵ N/m³, under the 0.3–12 Hz
multisine, 15 Hz noise and a 0.3–4 Hz multisine (40 s, 1 V RMS), position output.
rig: the simulated pneumatic rig with its model file (`diagnose_cases.rig_recording`, 0.8 V
RMS, 40 s), fault-free and with one effect (a pure Coulomb friction of 1 N and of 3.4 N,
an accelerometer bias, a valve gain, a payload, the supply pressure, the air bearing's
contact friction, the four drive effects), under the excitations of `RIG_EXCITATIONS` other
than the tests' multisine: band-passed noise 1–15 Hz and a 2–25 Hz multisine.
Prints the names, the held-out gap before and after, the noise floor, the form and the ratios,
sizes or the k₃ read (N/m³).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def outcome(r, label: str, read: dict) -> dict:
    """A case's diagnosis as the sweeps yield it."""
    return {
        "case": label,
        "named": r.named,
        "gap_before": r.gap_before,
        "gap_after": r.gap_after,
        "floor": r.info["noise_floor"]["floor"],
        "form": r.info["form"],
        "read": read,
        "ambiguous": [tie["effects"] for tie in r.ambiguous],
    }


def mechanics_cases():
    """The §V model with one parameter changed, under three excitations, two outputs:
    yields `outcome` with ``read`` the ratio (or Δ(c/m)) of each named linear change."""
    from fdi_daemon.diagnose.workflow import run_diagnose
    from hil_sim.msd import MsdParams, multisine, simulate_recording
    from tests.diagnose_cases import FS, NAMED_RATIOS, NOISE, noise_input, nominal_model

    b, a = nominal_model()
    inputs = {
        "noise 15 Hz": noise_input(24.0, 15.0, 0.5),
        "multisine 0.3-4 Hz": multisine(24.0, FS, 0.3, 4.0, 0.5, seed=1),
        "multisine 3-8 Hz": multisine(24.0, FS, 3.0, 8.0, 0.5, seed=1),
    }
    changes = [
        ("mass_kg", 0.8),
        ("mass_kg", 1.25),
        ("stiffness_n_per_m", 0.8),
        ("damping_n_s_per_m", 1.5),
    ]
    for label, u in inputs.items():
        for parameter, ratio in changes:
            value = ratio * getattr(MsdParams(), parameter)
            rec = simulate_recording(MsdParams(**{parameter: value}, **NOISE), u, seed=2)
            for kind, column in (("acceleration", "accel"), ("position", "position")):
                r = run_diagnose(rec.v_in, rec[column], FS, kind, b, a)
                read = {
                    e.named_as: round(float(e.physical[NAMED_RATIOS[e.named_as]]), 3)
                    for e in r.selection.named
                    if e.named_as in NAMED_RATIOS
                }
                yield outcome(r, f"{label}, {parameter} x {ratio:g}, {kind}", read)


def duffing_cases():
    """The Duffing oscillator (a fitted linear baseline), three k₃ under three excitations:
    yields `outcome` with ``read`` {"k3_n_per_m3": k₃ read} (nan: no cubic spring named)."""
    from fdi_daemon.diagnose.workflow import run_diagnose
    from hil_sim.msd import MsdParams, multisine, simulate_recording
    from tests.diagnose_cases import FS, NOISE, noise_input

    inputs = {
        "multisine 0.3-12 Hz": multisine(40.0, FS, 0.3, 12.0, 1.0, seed=1),
        "noise 15 Hz": noise_input(40.0, 15.0, 1.0),
        "multisine 0.3-4 Hz": multisine(40.0, FS, 0.3, 4.0, 1.0, seed=1),
    }
    for k3 in (3e4, 1e5, 3e5):
        for label, u in inputs.items():
            params = MsdParams(
                input_filter_hz=None, effects={"cubic_stiffness": {"k3_n_per_m3": k3}}, **NOISE
            )
            rec = simulate_recording(params, u, seed=2)
            r = run_diagnose(rec.v_in, rec["position"], FS, "position")
            cubic = next((e.physical for e in r.selection.named if e.name == "cubic_stiffness"), {})
            # both forms size k₃ in input units (V per m³): times the input's gain, N/m³
            read = params.gain_n_per_v * cubic.get(
                "cubic_coefficient_input_equivalent", cubic.get("cubic_coefficient", math.nan)
            )
            yield outcome(r, f"k3 {k3:.0e}, {label}", {"k3_n_per_m3": float(read)})


def rig_cases():
    """The pneumatic rig with its model file, fault-free and with one effect each, under the
    two excitations unlike the tests' multisine: yields `outcome` with ``read`` the sizes
    of the named effects."""
    from fdi_daemon.diagnose.workflow import run_diagnose
    from tests.diagnose_cases import (
        NAMED_RATIOS,
        RIG_EXCITATIONS,
        RIG_FS,
        RIG_INPUT_EFFECTS,
        rig_model,
        rig_recording,
    )

    def pure(coulomb_n: float) -> dict:  # the rod seal's friction, static = Coulomb
        return {"variant": (("seal_coulomb_n", coulomb_n), ("seal_static_n", coulomb_n))}

    b, a = rig_model()
    cases = {
        "fault-free": {},
        "Coulomb 1 N": pure(1.0),
        "Coulomb 3.4 N": pure(3.4),
        "accel bias 0.5": {"fault": "accel_bias", "value": 0.5},
        "valve gain 0.8": {"fault": "valve_gain", "value": 0.8},
        "payload +0.5 kg": {"variant": (("bearing_mass_kg", 1.5),)},
        "supply 0.8": {"fault": "supply_pressure", "value": 0.8},
        "bearing supply 0.75": {"fault": "bearing_supply", "value": 0.75},
        **{effect: {"input_effect": effect} for effect in RIG_INPUT_EFFECTS},
    }
    for excitation in list(RIG_EXCITATIONS)[1:]:
        for label, case in cases.items():
            u, y = rig_recording(rms_v=0.8, duration_s=40.0, excitation=excitation, **case)
            r = run_diagnose(u, y, RIG_FS, "acceleration", b, a)
            read = {
                f"{e.named_as}:{key}": round(float(e.physical[key]), 4)
                for e in r.selection.named
                for key in (
                    NAMED_RATIOS.get(e.named_as),
                    "dead_time_s",
                    "half_width",
                    "level",
                    "gap",
                    "offset",
                )
                if key in e.physical and isinstance(e.physical[key], float)
            }
            yield outcome(r, f"{excitation}, {label}", read)


def show(case: dict) -> str:
    """One case as the script prints it."""
    return (
        f"{case['case']}: {case['named']} {case['gap_before']:.4f} -> {case['gap_after']:.4f} "
        f"(floor {'unknown' if case['floor'] is None else format(case['floor'], '.4f')}), "
        f"form {case['form']}, {case['read']}"
    )


PARTS = {"mechanics": mechanics_cases, "duffing": duffing_cases, "rig": rig_cases}


if __name__ == "__main__":
    sys.path.insert(0, str(REPO))
    parts = sys.argv[1:] or ["mechanics", "duffing", "rig"]
    for part in parts:
        for case in PARTS[part]():
            print(show(case), flush=True)
