"""The friction level with the high-pass and the model-based velocity on the simulated rig
and its variants (docs/detector.md §4a). Run: ``python studies/friction_level_variants.py
[default|v0|v1|velsrc ...]`` (about a minute per rig).

Per rig: `fdi identify` on its chirps; `fdi signature` as shipped (high-pass velocity,
signature_calibration.yaml) and with ``--velocity-method model_observer`` and
``position_observer`` on the paired calibration run; the models replay test cases 1
and 2 and the steady fault under changing
operation; the level is the reported `friction_level` (`detect.friction_level`). Truths from
the simulator: a fault's size is the mean air-bearing contact force
after the fault over the calibration fault's (Coulomb force μ·N relative to the signature's).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[1]
SCENARIOS = REPO / "configs" / "scenarios"
if str(REPO / "tests") not in sys.path:  # the rig variants and README step 2's windows
    sys.path.insert(0, str(REPO / "tests"))
CASES = (
    ("test_case_1", 3.05, 1.5),
    ("test_case_2", 2.9, 1.5),
    ("steady_friction_changing_operation", 20.0, 10.0),
)


def variants() -> dict[str, dict]:
    from test_detect_other_rig import rig_variant

    return {
        "default": {},
        "v0": rig_variant(0),
        "v1": rig_variant(1),
        "velsrc": {
            "bearing_mass_kg": 0.6,
            "piston_rod_mass_kg": 0.2,
            "viscous_damping_n_s_per_m": 150.0,
        },
    }


def _record(rig, name, out):
    from fdi_daemon.io.recordings import write_recording
    from hil_sim.scenarios import scenario_from_dict, simulate

    spec = yaml.safe_load((SCENARIOS / f"{name}.yaml").read_text())
    spec["rig"] = {**spec.get("rig", {}), **rig}
    rec = simulate(scenario_from_dict(spec))
    write_recording(out, rec)
    return rec


def _fdi(*argv):
    import contextlib
    import io

    from fdi_daemon.cli import main

    quiet = io.StringIO()
    with contextlib.redirect_stdout(quiet), contextlib.redirect_stderr(quiet):
        code = main([str(a) for a in argv])
    if code != 0:
        raise SystemExit(f"fdi {' '.join(map(str, argv))} failed:\n{quiet.getvalue()}")


def paired_signature(record, model, out, method: str):
    """`fdi signature` on the paired calibration run ``record`` as README step 2 makes it
    (reference pass 1-21 s, fault window 22-42 s, low-pass 10 Hz) with ``--velocity-method
    method``: ``model``'s plant with that signature, written to ``out`` (returned)."""
    from conftest_detect import PAIRED_SIGNATURE_WINDOWS

    _fdi(
        "signature",
        record,
        "--model",
        model,
        *PAIRED_SIGNATURE_WINDOWS,
        "--velocity-method",
        method,
        "-o",
        out,
    )
    return out


def measure(name: str, rig: dict, root: Path) -> list[str]:
    from fdi_daemon.io.model_file import load_model

    names = (
        "ident_chirp",
        "ident_chirp_long",
        "signature_calibration",
        "signature_calibration_paired",
    ) + tuple(c[0] for c in CASES)
    recs = {n: _record(rig, n, root / f"{n}.npz") for n in names}
    _fdi(
        "identify",
        root / "ident_chirp.npz",
        "-o",
        root / "plant.yaml",
        "--validate",
        root / "ident_chirp_long.npz",
    )
    _fdi(
        "signature",
        root / "signature_calibration.npz",
        "--model",
        root / "plant.yaml",
        "--fault-window",
        "11:40",
        "-o",
        root / "highpass.yaml",
    )
    paired_signature(
        root / "signature_calibration_paired.npz",
        root / "plant.yaml",
        root / "observer.yaml",
        "model_observer",
    )
    paired_signature(
        root / "signature_calibration_paired.npz",
        root / "plant.yaml",
        root / "position.yaml",
        "position_observer",
    )
    cal = recs["signature_calibration_paired"]
    calibrated = np.mean(cal.columns["contact_force"][cal.t >= 22.0])
    lines = []
    for velocity in ("highpass", "observer", "position"):
        model = load_model(root / f"{velocity}.yaml")
        sig = model.provenance["signature"]
        lines.append(
            f"{name} {velocity}: gamma_f {model.fault_filter.gamma_f} "
            f"interval {sig['cost_profile']['interval_99']} "
            f"VAF {sig['fault_filter_vaf_percent_full_band']:.1f} %"
        )
        lines.extend(case_lines(model, recs, calibrated))
    return lines


def case_lines(model, recs: dict, calibrated: float) -> list[str]:
    """One line per case of CASES replayed with ``model``: detection, decision, episodes,
    the reported level's median against the truth (contact force over ``calibrated``)
    and its 5th/95th percentiles."""
    from fdi_daemon.detect.monitor import Monitor

    lines = []
    for case, fault_t, after in CASES:
        rec = recs[case]
        events, trace = Monitor(model).run(rec)
        truth = np.mean(rec.columns["contact_force"][rec.t >= fault_t + 0.5]) / calibrated
        det = next((e for e in events if e["kind"] == "fault_detected"), None)
        iso = next((e for e in events if e["kind"] in ("friction_isolated", "other_fault")), None)
        level = trace.friction_level[
            (trace.t >= fault_t + after) & np.isfinite(trace.friction_level)
        ]
        head = (
            f"  {case}: detected "
            f"{None if det is None else round(1000 * (det['t'] - fault_t))} ms, "
            f"{None if iso is None else iso['kind']} "
            f"{None if iso is None else round(iso['t'] - fault_t, 2)} s, episodes "
            f"{sum(e['kind'] == 'fault_detected' for e in events)}, cleared "
            f"{sum(e['kind'] == 'cleared' for e in events)}"
        )
        if level.size == 0:
            lines.append(f"{head}, no level")
            continue
        med = np.median(level)
        lo, hi = np.percentile(level, [5, 95])
        lines.append(
            f"{head}, level {med:.3f} (truth {truth:.3f}, "
            f"{100 * (med / truth - 1):+.0f} %), 5th/95th {100 * (lo / med - 1):+.0f}/"
            f"{100 * (hi / med - 1):+.0f} %"
        )
    return lines


if __name__ == "__main__":
    rigs = variants()
    for name in sys.argv[1:] or list(rigs):
        with tempfile.TemporaryDirectory() as tmp:
            print("\n".join(measure(name, rigs[name], Path(tmp))), flush=True)
