"""Alarm episodes of friction that creeps in, is there from the start, or never comes, on the
simulated rig (issue 13's checks; docs/detector.md §4b). Run:
``python studies/creeping_friction_episodes.py [highpass|observer ...]`` (several minutes).

Models: the shipped one (high-pass velocity, `fdi_daemon/data/model_sim_rig.yaml`) and one
from `fdi signature --velocity-method model_observer` on the paired calibration run; each
without and with a baseline from `fdi baseline` on ten fault-free minutes of changing
operation (seed 7, unlike the fault-free hour replayed below, seed 0).

Recordings (changing operation: random sines, multisines and chirps, 0.8–1.6 V, 1–9 Hz):
- creeping friction: the air-bearing supply falls from 100 % to 62 % (about half the
  signature's fault) over 10 minutes (30-minute recording) or one hour (2 hours), starting
  at a third of the recording, and stays;
- friction from the start: bearing supply 45 % (the signature's fault) and 62 %, 20 s;
- the fault-free hour (`configs/scenarios/fault_free_hour.yaml`).

Per case: the detector's episodes (`fault_detected`) and `cleared` events, the first
detection and isolation relative to the fault's start, and the alarm lifecycle's alarms
(`alarm_raised`) as the daemon would show them (`fdi_daemon.alarms.replay`).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SCENARIOS = REPO / "configs" / "scenarios"
OPERATION = [
    {
        "kind": "random",
        "amplitude_v": [0.8, 1.6],
        "frequency_hz": [1.0, 9.0],
        "segment_s": [5.0, 40.0],
    }
]


def _creep(ramp_s: float, record_s: float, supply: float = 0.62):
    start = record_s / 3.0
    return {
        "name": f"creep_{ramp_s:.0f}s",
        "duration_s": record_s,
        "seed": 3,
        "centring_gain_v_per_m": 30.0,
        "excitation": OPERATION,
        "drift": {
            "bearing_supply": {
                "times_s": [0.0, start, start + ramp_s, record_s],
                "values": [1.0, 1.0, supply, supply],
            }
        },
    }, start


def _from_start(supply: float):
    return {
        "name": f"from_start_{supply}",
        "duration_s": 20.0,
        "seed": 0,
        "centring_gain_v_per_m": 30.0,
        "excitation": [
            {
                "kind": "multisine",
                "amplitudes_v": [0.6, 0.5, 0.4],
                "frequencies_hz": [3.3, 5.0, 8.0],
            }
        ],
        "events": [{"t_s": 0.0, "bearing_supply": supply}],
    }, 0.0


def cases():
    import yaml

    ff = yaml.safe_load((SCENARIOS / "fault_free_hour.yaml").read_text())
    return {
        "creep 10 min": _creep(600.0, 1800.0),
        "creep 1 h": _creep(3600.0, 7200.0),
        "from start 45 %": _from_start(0.45),
        "from start 62 %": _from_start(0.62),
        "fault-free hour": (ff, None),
    }


def _fdi(*argv):
    from fdi_daemon.cli import main

    if main([str(a) for a in argv]) != 0:
        raise SystemExit(f"fdi {' '.join(map(str, argv))} failed")


def models(root: Path, names) -> dict:
    """{label: model} for each velocity in ``names``, without and with a baseline."""
    from fdi_daemon.io.model_file import load_model
    from fdi_daemon.io.recordings import write_recording
    from fdi_daemon.service.config import default_config_path
    from hil_sim.scenarios import load_scenario, simulate

    shipped = default_config_path().with_name("model_sim_rig.yaml")
    paths = {"highpass": shipped}
    if "observer" in names:
        # after fdi_daemon, which pins OpenBLAS's kernel before NumPy loads (blas_kernel)
        from friction_level_variants import paired_signature

        paired = write_recording(
            root / "paired.npz",
            simulate(load_scenario(SCENARIOS / "signature_calibration_paired.yaml")),
        )
        paths["observer"] = paired_signature(
            paired, shipped, root / "observer.yaml", "model_observer"
        )
    ff = write_recording(
        root / "ff10.npz",
        simulate(load_scenario(SCENARIOS / "fault_free_hour.yaml"), seed=7, duration_s=600.0),
    )
    out = {}
    for name in names:
        out[name] = load_model(paths[name])
        _fdi("baseline", ff, "--model", paths[name], "-o", root / f"{name}_baseline.yaml")
        out[f"{name} + baseline"] = load_model(root / f"{name}_baseline.yaml")
    return out


def measure(label: str, model, case: str, rec, fault_t) -> str:
    from fdi_daemon.alarms.replay import alarm_events, status_stride
    from fdi_daemon.detect.monitor import Monitor

    stride = status_stride(model.fs)
    monitor = Monitor(model)
    events, trace = monitor.run(rec, trace_every=stride)
    alarms = alarm_events(monitor, events, trace, stride)
    kinds = [e["kind"] for e in events]

    def first(*names):
        e = next((e for e in events if e["kind"] in names), None)
        if e is None:
            return "never"
        rel = e["t"] - (fault_t or 0.0)
        return f"{e['kind']} {'+' if fault_t is not None else 't='}{rel:.2f} s"

    raised = [e for e in alarms if e["kind"] == "alarm_raised"]
    return (
        f"{case:16s} {label:20s} episodes {kinds.count('fault_detected'):3d} "
        f"cleared {kinds.count('cleared'):3d}  detected {first('fault_detected'):28s} "
        f"isolated {first('friction_isolated', 'other_fault'):32s} "
        f"lifecycle alarms {len(raised)}"
    )


if __name__ == "__main__":
    from hil_sim.scenarios import scenario_from_dict, simulate

    names = sys.argv[1:] or ["highpass", "observer"]
    with tempfile.TemporaryDirectory() as tmp:
        labelled = models(Path(tmp), names)
        for case, (spec, fault_t) in cases().items():
            rec = simulate(scenario_from_dict(spec))
            for label, model in labelled.items():
                print(measure(label, model, case, rec, fault_t), flush=True)
