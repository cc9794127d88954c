"""Does another velocity for sign(v̂) find the 1 s half-size friction ramp under 1.2/2/2.9 Hz
operation? (issue 43; docs/detector.md §3, "Growing friction", and §4a). Run:
``python studies/growing_friction_velocity.py [default|v0|v1 ...] [--hours] [--tail]`` (one
to two minutes per rig; ``--hours`` adds the fault-free hours of seeds 0–2 for every model
on every rig, 10–60 s each; ``--tail`` the fault-free excursion tail of the
drift path's CUSUM (`growing_friction_detection.excursion_tail`, seed 7) for the position
model matched to ``POSITION_SHIFT`` on the default rig, about 3 minutes).

Per rig (`studies/growing_friction_detection.py`'s: the default with the shipped model, the
variants with their own `fdi identify` + `fdi signature`), the high-pass model against
models whose signature `fdi signature` made with ``--velocity-method model_observer`` and
``position_observer`` on the paired calibration run (on the same rig's plant from `fdi
identify`, as `studies/friction_level_variants.py` makes them; the whole monitor then runs on
that velocity), and the position one with the drift path matched to a smaller shift
(``drift_shift_level`` ``POSITION_SHIFT``). Per model, operation and seed: the first
`fault_detected` after the onset (delay, path), the peak of the drift path's CUSUM S from
the onset to the end where nothing was detected (else "crossed") against its threshold h,
and θ1 (eq. 17, the sliding window's Coulomb coefficient, with every alarm path out of
reach) as read after the ramp: its median over 9.5–14 s less its median over 4–8 s (the
fault's size is 0.5); then the paper's test cases (default rig).
"""

from __future__ import annotations

import copy
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))
sys.path.insert(0, str(REPO / "studies"))

SEEDS = (4, 5)
#: the drift path's matched shift δ tried with the position-fused velocity (default 0.3):
#: after the ramp θ1 reads 0.10–0.19 under 1.2/2/2.9 Hz, below δ/2 = 0.15, where S falls
POSITION_SHIFT = 0.2
#: θ1 before the onset and after the ramp (s)
BEFORE_S, AFTER_S = (4.0, 8.0), (9.5, 14.0)


def paired_models(rig: dict, root: Path, methods: tuple[str, ...]) -> dict:
    """velocity method -> model: the rig's plant from `fdi identify` with a signature `fdi
    signature --velocity-method <method>` made on the rig's paired calibration run."""
    from friction_level_variants import _fdi, _record, paired_signature

    from fdi_daemon.io.model_file import load_model

    for rec in ("ident_chirp", "ident_chirp_long", "signature_calibration_paired"):
        _record(rig, rec, root / f"{rec}.npz")
    _fdi(
        "identify",
        root / "ident_chirp.npz",
        "-o",
        root / "plant.yaml",
        "--validate",
        root / "ident_chirp_long.npz",
    )
    models = {}
    for method in methods:
        models[method] = load_model(
            paired_signature(
                root / "signature_calibration_paired.npz",
                root / "plant.yaml",
                root / f"{method}.yaml",
                method,
            )
        )
    return models


def with_shift(model, shift: float):
    """A copy of the model whose drift path is matched to ``shift`` calibrated faults."""
    tuned = copy.deepcopy(model)
    tuned.detector = {**(tuned.detector or {}), "drift_shift_level": shift}
    return tuned


def build_models(name: str, root: Path) -> tuple[dict, dict]:
    """(rig overrides, label -> model): the high-pass model of
    `growing_friction_detection.models`, the paired run's observer models, and the
    position one matched to ``POSITION_SHIFT``."""
    import growing_friction_detection as G

    rig, highpass = G.models((name,))[name]
    models = {"high-pass": highpass}
    models.update(paired_models(rig, root, ("model_observer", "position_observer")))
    tuned = with_shift(models["position_observer"], POSITION_SHIFT)
    models[f"position_observer, drift_shift_level {POSITION_SHIFT}"] = tuned
    return rig, models


def ramp_run(model, rig, operation, seed: int) -> dict:
    """One ramp, one `Monitor.step` a sample (the CUSUM S is read every tick)."""
    import growing_friction_detection as G

    from fdi_daemon.detect.monitor import Monitor
    from fdi_daemon.io.sample import Sample
    from hil_sim.scenarios import scenario_from_dict, simulate

    rec = simulate(scenario_from_dict(G.ramp_spec(operation, rig, duration_s=14.0)), seed=seed)
    position = np.asarray(rec.columns["position"], dtype=float)
    mon = Monitor(model)
    events, drift = [], np.zeros(len(rec))
    for k in range(len(rec)):
        sample = Sample(k, float(rec.t[k]), float(rec.v_in[k]), float(rec.accel[k]), position[k])
        events.extend(mon.step(sample))
        drift[k] = mon.detector.drift_statistic
    t = np.asarray(rec.t)
    det = G.first_after(events, "fault_detected", G.ONSET_S)
    end = len(rec) if det is None else int(np.searchsorted(t, det["t"])) + 1
    after_onset = slice(int(np.searchsorted(t, G.ONSET_S)), end)
    return {
        "delay": None if det is None else det["t"] - G.ONSET_S,
        "path": None if det is None else det.get("path"),
        "peak": float(drift[after_onset].max()),
        "h": mon.detector.drift_threshold,
        "kinds": [e["kind"] for e in events if e["kind"] != "calibrated"],
    }


def theta1_reading(model, rig, operation, seed: int) -> float:
    """θ1 after the ramp less θ1 before it, from the batch run's trace (the model's
    fault-free episode-less θ: with the alarm paths out of reach)."""
    import growing_friction_detection as G

    from fdi_daemon.detect.monitor import Monitor
    from hil_sim.scenarios import scenario_from_dict, simulate

    quiet = copy.deepcopy(model)
    quiet.detector = {
        **(quiet.detector or {}),
        "threshold": 1e12,
        "slow_persistence_s": 1e6,
        "drift_shift_level": 0.0,
    }
    rec = simulate(scenario_from_dict(G.ramp_spec(operation, rig, duration_s=14.0)), seed=seed)
    _, trace = Monitor(quiet).run(rec)
    t = np.asarray(trace.t)
    th = np.asarray(trace.theta1)

    def median(span):
        return float(np.nanmedian(th[(t >= span[0]) & (t < span[1])]))

    return median(AFTER_S) - median(BEFORE_S)


def fault_free_hour(rig: dict, seed: int):
    """`configs/scenarios/fault_free_hour.yaml` (changing operation, 1–9 Hz) on the rig."""
    import yaml
    from test_detect_other_rig import SCENARIOS

    from hil_sim.scenarios import scenario_from_dict, simulate

    spec = yaml.safe_load((SCENARIOS / "fault_free_hour.yaml").read_text())
    spec["rig"] = {**spec.get("rig", {}), **rig}
    return simulate(scenario_from_dict(spec), seed=seed)


def main(argv: list[str]) -> None:
    import growing_friction_detection as G
    from conftest_detect import scenario_recording

    from fdi_daemon.detect.monitor import Monitor

    names = [a for a in argv if not a.startswith("--")] or ["default", "v0", "v1"]
    print("| rig | velocity | operation | seed | detected | CUSUM peak / h | θ1 after − before |")
    print("|---|---|---|---|---|---|---|")
    for rig_name in names:
        root = Path(tempfile.mkdtemp(prefix=f"growing_velocity_{rig_name}_"))
        rig, models = build_models(rig_name, root)
        for name, model in models.items():
            for op_name, op in G.OPERATIONS.items():
                for seed in SEEDS:
                    m = ramp_run(model, rig, op, seed)
                    d = "none" if m["delay"] is None else f"+{m['delay']:.2f} s ({m['path']})"
                    later = ", ".join(m["kinds"][1:]) or "-"
                    th = theta1_reading(model, rig, op, seed)
                    peak = "crossed" if m["delay"] is not None else f"{m['peak']:.0f}"
                    print(
                        f"| {rig_name} | {name} | {op_name} | {seed} | {d}, then {later} | "
                        f"{peak} / {m['h']:.0f} | {th:.3f} |",
                        flush=True,
                    )
            if "--hours" in argv:
                for seed in (0, 1, 2):
                    rec = fault_free_hour(rig, seed)
                    events = Monitor(model).run(rec, trace_every=len(rec))[0]
                    raised = [e for e in events if e["kind"] == "fault_detected"]
                    print(
                        f"{rig_name} {name} fault-free hour seed {seed}: {len(raised)} episode(s)",
                        flush=True,
                    )
            if rig_name != "default":
                continue
            for case, fault_s in (("test_case_1", 3.05), ("test_case_2", 2.9)):
                events = Monitor(model).run(scenario_recording(case))[0]
                kinds = [e["kind"] for e in events if e["kind"] != "calibrated"]
                det = G.first_after(events, "fault_detected", 0.0)
                delay = "none" if det is None else f"+{1000 * (det['t'] - fault_s):.1f} ms"
                print(f"{name} {case}: {delay}, {kinds}", flush=True)
            if "--tail" in argv and name.endswith(str(POSITION_SHIFT)):
                G.excursion_tail(model=model)


if __name__ == "__main__":
    main(sys.argv[1:])
