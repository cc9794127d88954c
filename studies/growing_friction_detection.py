"""Detection delay of friction that grows: from nothing to half the signature's size,
linearly over 1 s (bearing supply 80 -> 62 %, `ramp_spec`), under two operations at 1–9 Hz, on the default simulated rig
(shipped model) and two rig variants (each with its own model from `fdi identify` and
`fdi signature`, as `tests/test_detect_other_rig.py` makes them); and the paper's test
cases and a fault-free record on the same models (docs/detector.md §3, "Growing friction").
Run: ``python studies/growing_friction_detection.py [default|v0|v1 ...]`` (a minute or two
per rig); ``python studies/growing_friction_detection.py tail`` prints the fault-free
excursion tail the threshold's τ comes from (about 3 minutes; ``tail v0 v1 v2``: on those
variants, each with its model from README step 2 with ``--drift-highpass-hz 0.5``); ``... during`` the ramp with
another fault stepped in during the drift path's episode (`faults_during_episode`);
``... lowcut HZ [default|v0|v1|v2 ...]`` the same, on seeds 4-9, with every rig's signature
made by README step 2 with ``--highpass-hz HZ`` (the whole monitor on that cut-off;
`step2_models`); ``... drift HZ [default|v0|v1|v2 ...]`` with README step 2's
``--drift-highpass-hz HZ`` (the growing-fault path alone on it; docs/detector.md §3, "The
1–3 Hz ramp without position"); ``... peaks HZ [default|v0|v1|v2 ...]`` the same models,
the drift CUSUM's peak over the 1.5 s after the onset divided by h, with the alarm out of
reach (`ramp_peak`). ``tail`` measures the shipped model, whose signature has its drift
path on 0.5 Hz (README step 2).

Prints per rig, operation and seed the first `fault_detected` after the onset (delay in s,
its path) and what followed, before the path (``drift_shift_level: 0``) and with it; for
the default rig also the test cases' detection delays and the fault-free hours' episodes.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

ONSET_S = 8.0
RAMP_S = 1.0
#: bearing supply at which the block's lift equals its weight (8 psi of 69 kPa): contact below
CONTACT_SUPPLY = 55.0e3 / 69.0e3
#: the signature's fault (configs/scenarios/signature_calibration.yaml)
SIGNATURE_SUPPLY = 0.45
RAMP_STEPS_PER_S = 64
SEEDS = (4, 5)
#: the seeds of ``lowcut`` (where the CUSUM's margin over h is thin)
LOWCUT_SEEDS = (4, 5, 6, 7, 8, 9)
OPERATIONS = {
    "three-tone 2.5/6/8.5 Hz": [
        {"kind": "multisine", "amplitudes_v": [0.6, 0.5, 0.4], "frequencies_hz": [2.5, 6.0, 8.5]}
    ],
    "low 1.2/2/2.9 Hz": [
        {"kind": "multisine", "amplitudes_v": [0.5, 0.5, 0.5], "frequencies_hz": [1.2, 2.0, 2.9]}
    ],
}


def ramp_spec(operation, rig=None, onset_s=ONSET_S, ramp_s=RAMP_S, duration_s=16.0, size=0.5):
    """A scenario dict: friction grows linearly from 0 to ``size`` calibrated faults over
    ``ramp_s`` from ``onset_s`` under ``operation`` (an excitation list).

    The simulated bearing touches down once its supply falls below ``CONTACT_SUPPLY`` (lift
    = weight) and its normal force, hence the friction, grows linearly below that; the
    signature's fault (supply 45 %) is size 1. The supply therefore steps from
    ``CONTACT_SUPPLY`` down in ``RAMP_STEPS_PER_S`` events a second (the scenario's
    ``drift`` is updated once a second only, which would make a 1 s ramp a step)."""
    end = CONTACT_SUPPLY - size * (CONTACT_SUPPLY - SIGNATURE_SUPPLY)
    steps = max(1, int(round(ramp_s * RAMP_STEPS_PER_S)))
    events = [{"t_s": 0.0, "bearing_supply": 1.0}]
    for k in range(steps + 1):
        frac = k / steps
        events.append(
            {
                "t_s": onset_s + frac * ramp_s,
                "bearing_supply": CONTACT_SUPPLY + frac * (end - CONTACT_SUPPLY),
            }
        )
    spec = {
        "name": "growing_friction",
        "duration_s": duration_s,
        "centring_gain_v_per_m": 30.0,
        "excitation": operation,
        "events": events,
    }
    if rig:
        spec["rig"] = dict(rig)
    return spec


def models(names=("default", "v0", "v1")):
    """rig name -> (rig overrides, model)."""
    import contextlib
    import io

    from conftest_detect import sim_rig_model
    from test_detect_other_rig import model_of, rig_variant

    out = {}
    for name in names:
        if name == "default":
            out[name] = ({}, sim_rig_model())
            continue
        rig = rig_variant(int(name[1:]))
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            out[name] = (rig, model_of(rig, Path(tempfile.mkdtemp(prefix=f"growing_{name}_"))))
    return out


def step2_models(option: tuple[str, ...], names=("default", "v0", "v1")):
    """rig name -> (rig overrides, model): README step 2's `fdi signature` (six-carrier
    paired calibration) with ``option`` on the rig's own recordings, on the shipped plant
    (default rig) or the rig's own from `fdi identify` (`paired_carriers_calibration`);
    e.g. ``("--highpass-hz", "0.5")``, ``("--drift-highpass-hz", "0.5")``."""
    from conftest_detect import MODEL
    from friction_level_variants import _record
    from paired_carriers_calibration import (
        CALIBRATION,
        carrier_windows,
        paired_signature,
        plant_model,
    )
    from test_detect_other_rig import rig_variant

    from fdi_daemon.io.model_file import load_model

    out = {}
    for name in names:
        rig = {} if name == "default" else rig_variant(int(name[1:]))
        root = Path(tempfile.mkdtemp(prefix=f"growing_step2_{name}_"))
        recs = {rec: root / f"{rec}.npz" for rec in ("ident_chirp", "ident_chirp_long")}
        recs[CALIBRATION] = root / f"{CALIBRATION}.npz"
        for rec in recs if name != "default" else (CALIBRATION,):
            _record(rig, rec, recs[rec])
        plant = MODEL if name == "default" else plant_model(recs, root / "plant.yaml")
        model = paired_signature(
            recs[CALIBRATION], plant, carrier_windows(), root / "m.yaml", *option
        )
        out[name] = (rig, load_model(model))
    return out


def without_drift_path(model):
    """The model as before the growing-fault path (``drift_shift_level: 0``)."""
    import copy

    before = copy.deepcopy(model)
    before.detector = {**(before.detector or {}), "drift_shift_level": 0.0}
    return before


def first_after(events, kind, t0):
    return next((e for e in events if e["kind"] == kind and e["t"] >= t0), None)


def replay(model, spec, seed=4):
    from fdi_daemon.detect.monitor import Monitor
    from hil_sim.scenarios import scenario_from_dict, simulate

    rec = simulate(scenario_from_dict(spec), seed=seed)
    return Monitor(model).run(rec, trace_every=len(rec))[0]


def measure_ramp(model, rig, operation, seed=4):
    events = replay(model, ramp_spec(operation, rig), seed)
    early = [e for e in events if e["kind"] == "fault_detected" and e["t"] < ONSET_S]
    det = first_after(events, "fault_detected", ONSET_S)
    iso = first_after(events, "friction_isolated", ONSET_S)
    return {
        "false_before": len(early),
        "delay_s": None if det is None else det["t"] - ONSET_S,
        "path": None if det is None else det.get("path"),
        "isolated_s": None if iso is None else iso["t"] - ONSET_S,
        "kinds": [e["kind"] for e in events if e["kind"] != "calibrated"],
    }


def fmt(m):
    d = "none" if m["delay_s"] is None else f"{m['delay_s']:.2f} s ({m['path']})"
    i = "-" if m["isolated_s"] is None else f"{m['isolated_s']:.2f} s"
    later = ", ".join(k for k in m["kinds"][1:]) or "-"
    return f"{d}, then {later}, isolated {i}, {m['false_before']} before onset"


def excursion_tail(seed: int = 7, levels=(25, 40, 50, 63, 100, 201), model=None, rig=None):
    """The fault-free CUSUM's excursions (runs of S > 0) on an hour of changing operation
    that no test replays (seed 7), the model (default: the shipped one) with the alarm out
    of reach: how many peak above each level (the threshold's basis, docs/detector.md). One
    `Monitor.step` a sample, about 3 minutes. ``rig``: the hour played on a rig variant
    (its overrides)."""
    import copy

    import numpy as np
    import yaml
    from conftest_detect import SCENARIOS, scenario_recording, sim_rig_model

    from fdi_daemon.detect.monitor import Monitor
    from fdi_daemon.io.sample import Sample
    from hil_sim.scenarios import scenario_from_dict, simulate

    model = copy.deepcopy(sim_rig_model() if model is None else model)
    model.detector = {**(model.detector or {}), "drift_correlation_samples": 10**6}
    if rig:
        spec = yaml.safe_load((SCENARIOS / "fault_free_hour.yaml").read_text())
        spec["rig"] = {**spec.get("rig", {}), **rig}
        rec = simulate(scenario_from_dict(spec), seed=seed)
    else:
        rec = scenario_recording("fault_free_hour", seed=seed)
    position = np.asarray(rec.columns["position"], dtype=float)
    mon = Monitor(model)
    peaks, peak = [], 0.0
    for k in range(len(rec)):
        sample = Sample(k, float(rec.t[k]), float(rec.v_in[k]), float(rec.accel[k]), position[k])
        mon.step(sample)
        s = mon.detector.drift_statistic
        if s > 0.0:
            peak = max(peak, s)
        elif peak > 0.0:
            peaks.append(peak)
            peak = 0.0
    p = np.array(peaks + ([peak] if peak > 0.0 else []))
    print(f"fault-free hour seed {seed}: {p.size} excursions, largest {p.max():.1f}")
    for level in levels:
        print(f"  above {level}: {int((p > level).sum())}")


def ramp_peak(model, rig, operation, seed=4, within_s=1.5):
    """The drift CUSUM's largest value over ``within_s`` after the ramp's onset, over h,
    with the alarm out of reach (``drift_correlation_samples`` 10⁶; the fast and level
    paths as they are); and its largest before the onset (absolute)."""
    import copy

    from fdi_daemon.detect.monitor import Monitor
    from fdi_daemon.io.sample import Sample
    from hil_sim.scenarios import scenario_from_dict, simulate

    h = Monitor(model).detector.drift_threshold
    model = copy.deepcopy(model)
    model.detector = {**(model.detector or {}), "drift_correlation_samples": 10**6}
    rec = simulate(scenario_from_dict(ramp_spec(operation, rig, duration_s=10.0)), seed=seed)
    mon = Monitor(model)
    after = before = 0.0
    for k in range(len(rec)):
        t = float(rec.t[k])
        mon.step(Sample(k, t, float(rec.v_in[k]), float(rec.accel[k])))
        s = mon.detector.drift_statistic
        if t < ONSET_S:
            before = max(before, s)
        elif t <= ONSET_S + within_s:
            after = max(after, s)
    return after / h, before


#: faults stepped in at 12 s, during the drift path's episode of the three-tone ramp
FAULTS_DURING_EPISODE = (
    ("accel_bias", 0.3),
    ("accel_bias", 1.0),
    ("accel_bias", 2.0),
    ("valve_gain", 0.6),
    ("valve_gain", 0.3),
    ("supply_pressure", 0.5),
)


def faults_during_episode(seed: int = 4, fault_t_s: float = 12.0):
    """The three-tone ramp (default rig, shipped model, 16 s) with another fault stepped in
    at ``fault_t_s``, after the drift path's raise: the events, and the residual test's
    peak T over the second after the step (the evidence an episode of the drift path
    waits for before the isolation timeout counts, docs/detector.md §3)."""
    import numpy as np
    from conftest_detect import sim_rig_model

    from fdi_daemon.detect.monitor import Monitor
    from hil_sim.scenarios import scenario_from_dict, simulate

    for fault, value in FAULTS_DURING_EPISODE:
        spec = ramp_spec(OPERATIONS["three-tone 2.5/6/8.5 Hz"], duration_s=16.0)
        spec["events"].append({"t_s": fault_t_s, "fault": fault, "value": value})
        rec = simulate(scenario_from_dict(spec), seed=seed)
        events, trace = Monitor(sim_rig_model()).run(rec)
        after = (trace.t >= fault_t_s) & (trace.t < fault_t_s + 1.0)
        shown = [f"{e['kind']} {e['t']:.2f} s" for e in events if e["kind"] != "calibrated"]
        peak = float(np.nanmax(trace.statistic[after]))
        print(f"{fault} {value}: T peak {peak:.1f}; " + ", ".join(shown), flush=True)


def main(argv):
    if argv[:1] == ["tail"]:
        if len(argv) == 1:
            excursion_tail()
        for name, (rig, model) in step2_models(("--drift-highpass-hz", "0.5"), argv[1:]).items():
            print(f"{name} (README step 2 with --drift-highpass-hz 0.5):", end=" ")
            excursion_tail(model=model, rig=rig)
        return
    if argv[:1] == ["during"]:
        faults_during_episode()
        return
    if argv[:1] == ["peaks"]:
        peaks = step2_models(("--drift-highpass-hz", argv[1]), tuple(argv[2:]) or ("default",))
        for name, (rig, model) in peaks.items():
            for op_name, op in OPERATIONS.items():
                got = [ramp_peak(model, rig, op, seed) for seed in LOWCUT_SEEDS]
                shown = " ".join(f"{a:.2f}" for a, _ in got)
                print(
                    f"| {name} | {op_name} | peak/h seeds 4-9: {shown} | "
                    f"before onset max {max(b for _, b in got):.0f} |",
                    flush=True,
                )
        return
    option = {"lowcut": "--highpass-hz", "drift": "--drift-highpass-hz"}.get(
        argv[0] if argv else ""
    )
    lowcut = option is not None
    names = tuple(argv[2 * lowcut :]) or ("default", "v0", "v1")
    built = step2_models((option, argv[1]), names) if option else models(names)
    for name, (rig, model) in built.items():
        for op_name, op in OPERATIONS.items():
            for seed in LOWCUT_SEEDS if lowcut else SEEDS:
                before = measure_ramp(without_drift_path(model), rig, op, seed)
                after = measure_ramp(model, rig, op, seed)
                print(f"| {name} | {op_name} | {seed} | {fmt(before)} | {fmt(after)} |", flush=True)
        if name == "default":
            checks(model)


def checks(model):
    """The paper's test cases (detection delay before/after) and fault-free hours."""
    from conftest_detect import scenario_recording

    from fdi_daemon.detect.monitor import Monitor

    for case, fault_s in (("test_case_1", 3.05), ("test_case_2", 2.9)):
        for label, m in (("before", without_drift_path(model)), ("after", model)):
            events = Monitor(m).run(scenario_recording(case))[0]
            det = first_after(events, "fault_detected", 0.0)
            print(f"{case} {label}: detected +{1000 * (det['t'] - fault_s):.1f} ms ({det['path']})")
    for seed in (0, 1, 2):
        rec = scenario_recording("fault_free_hour", seed=seed)
        events = Monitor(model).run(rec, trace_every=len(rec))[0]
        raised = [e for e in events if e["kind"] == "fault_detected"]
        print(f"fault-free hour seed {seed}: {len(raised)} alarm episode(s)", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
