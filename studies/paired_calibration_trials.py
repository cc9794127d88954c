"""Paired calibrations tried for the shipped model (issue 43): carriers where the rig runs, the
amplitudes it runs at, G_e's order, the low-pass (docs/identification.md, "Paired
calibrations tried for the shipped model"). Run: ``python studies/paired_calibration_trials.py
[--hours]`` (about 9 minutes with ``--hours`` on the shared 2-core machine at load 7;
``--hours`` adds the fault-free hours of seeds 0 and 1 for every model).

Each trial is a paired scenario built as ``signature_calibration_paired_carriers.yaml`` is (a
1 s lead-in, then each carrier stepped through the amplitudes, 2.5 s each; played fault-free,
then with the bearing supply at 45 %), and `fdi signature --reference-window --fault-window
--lowpass-hz --orders` on the plant of README's "made by" block (`fdi identify` on the
chirps, seed 0). Each model, and the shipped configs/model_sim_rig.yaml, replays the
recordings of studies/paired_carriers_calibration.py (seed 0) with its measurements: the
levels are `fdi replay --summary`'s `friction_level_final` against the simulator's contact
force over the calibration fault's. The last column is what the final level carries from
before the fault: the reported level over the last second before each test case's onset
(Ĝ's error and the seal's friction projected on the signature; `Monitor.run`), and the
test cases' final levels less it against the truth.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
from pathlib import Path

from paired_carriers_calibration import CASES, REPO, STEADY, _fdi, _summary, record

SIX = (6.0, 7.0, 8.0, 9.0, 10.0, 11.4)
WHERE_IT_RUNS = (6.0, 7.0, 8.0, 9.0)
STEPS = (1.0, 1.5, 2.0, 2.5)
#: label, carriers (Hz), amplitude steps (V), scenario seed, --orders, --lowpass-hz
TRIALS = (
    ("six carriers (committed scenario)", SIX, STEPS, 0, "4:3:0", 10.0),
    ("six carriers, G_e [6 5 0]", SIX, STEPS, 0, "6:5:0", 10.0),
    ("six carriers, G_e [8 7 0]", SIX, STEPS, 0, "8:7:0", 10.0),
    ("six carriers, low-pass 14 Hz", SIX, STEPS, 0, "4:3:0", 14.0),
    ("six carriers, seed 1", SIX, STEPS, 1, "4:3:0", 10.0),
    ("6, 7, 8, 9 Hz", WHERE_IT_RUNS, STEPS, 0, "4:3:0", 10.0),
    ("6, 7, 8, 9 Hz, G_e [6 5 0]", WHERE_IT_RUNS, STEPS, 0, "6:5:0", 10.0),
    ("6, 7, 8, 9 Hz, G_e [8 7 0]", WHERE_IT_RUNS, STEPS, 0, "8:7:0", 10.0),
    ("6, 7, 8, 9 Hz, seed 1", WHERE_IT_RUNS, STEPS, 1, "4:3:0", 10.0),
    ("6, 7, 8, 9 Hz, G_e [6 5 0], seed 1", WHERE_IT_RUNS, STEPS, 1, "6:5:0", 10.0),
    ("6, 7, 8, 9 Hz at 0.8-1.6 V", WHERE_IT_RUNS, (0.8, 1.0, 1.3, 1.6), 0, "4:3:0", 10.0),
    ("6, 7, 8, 9 Hz at 1.0-1.6 V", WHERE_IT_RUNS, (1.0, 1.2, 1.4, 1.6), 0, "4:3:0", 10.0),
    ("6, 7, 8, 8, 9 Hz, G_e [6 5 0]", (6.0, 7.0, 8.0, 8.0, 9.0), STEPS, 0, "6:5:0", 10.0),
    ("6, 8 Hz", (6.0, 8.0), STEPS, 0, "4:3:0", 10.0),
)
#: the simulator's level of each fault, as `paired_carriers_calibration.truths()` prints it
TRUTH = {"test_case_1": 0.424, "test_case_2": 2.296, STEADY[0]: 1.000}


def paired_spec(carriers, steps, seed: int) -> tuple[dict, str, str]:
    """(scenario, --reference-window, --fault-window): the carriers stepped through ``steps``
    after a 1 s lead-in, fault-free, then again with the bearing supply at 45 %."""
    one_pass = [
        {"kind": "sine", "amplitude_v": steps[0], "frequency_hz": carriers[0], "duration_s": 1.0}
    ]
    for hz in carriers:
        one_pass += [
            {"kind": "sine", "amplitude_v": v, "frequency_hz": hz, "duration_s": 2.5} for v in steps
        ]
    length = 1.0 + 2.5 * len(steps) * len(carriers)
    spec = {
        "name": "paired_trial",
        "duration_s": 2 * length,
        "seed": seed,
        "centring_gain_v_per_m": 30.0,
        "excitation": one_pass + one_pass,
        "events": [{"t_s": length, "bearing_supply": 0.45}],
    }
    return spec, f"1:{length:g}", f"{length + 1:g}:{2 * length:g}"


def trial_model(trial, plant: Path, root: Path, index: int) -> Path:
    from fdi_daemon.io.recordings import write_recording
    from hil_sim.scenarios import scenario_from_dict, simulate

    _, carriers, steps, seed, orders, lowpass = trial
    spec, reference, fault = paired_spec(carriers, steps, seed)
    calibration = write_recording(root / f"trial{index}.npz", simulate(scenario_from_dict(spec)))
    out = root / f"trial{index}.yaml"
    shutil.copy(plant, out)
    _fdi(
        "signature", calibration, "--model", out, "--reference-window", reference,
        "--fault-window", fault, "--lowpass-hz", lowpass, "--orders", orders, "-o", out,
    )  # fmt: skip
    return out


def offsets(model: Path, recs: dict[str, Path]) -> list[float]:
    """The reported level over the last second before each test case's onset (median)."""
    import numpy as np

    from fdi_daemon.detect.monitor import Monitor
    from fdi_daemon.io.model_file import load_model
    from fdi_daemon.io.recordings import read_recording

    out = []
    for case, onset in CASES:
        rec = read_recording(recs[case])
        _, trace = Monitor(load_model(model)).run(rec)
        level = np.asarray(trace.friction_level)
        t = np.asarray(rec.t)[: len(level)]
        out.append(float(np.median(level[(t >= onset - 1.0) & (t < onset) & np.isfinite(level)])))
    return out


def _err(level: float, case: str) -> str:
    return f"{level:.3f} ({100 * (level / TRUTH[case] - 1):+.1f} %)"


def row(label: str, model: Path, recs: dict[str, Path], root: Path, hours: bool) -> str:
    from fdi_daemon.io.model_file import load_model

    fdi_model = load_model(model)
    signature = fdi_model.provenance["signature"]
    profile = signature["cost_profile"]
    lo, hi = profile["interval_99"]
    gamma = fdi_model.fault_filter.gamma_f
    # models made before the status was stored carry only the profile's flat flag
    status = signature.get("gamma_f_status") or ("flat" if profile.get("flat") else "identified")
    cells = [label, f"{'-' if gamma is None else f'{gamma:.2f}'} ({lo:.1f}-{hi:.1f})", status]
    for case, onset in CASES:
        s = _summary(recs[case], model, root)
        cells.append(
            f"{round(1000 * (s['first_detection_t'] - onset))} ms, "
            f"{_err(s['friction_level_final'], case)}"
        )
    s = _summary(recs[STEADY[0]], model, root)
    cells.append(
        f"{'' if s['other_fault_t'] is None else 'other_fault, '}"
        f"{s['isolated_t'] - STEADY[1]:.2f} s, {s['alarm_episodes']}/"
        f"{s['event_counts'].get('cleared', 0)}, {_err(s['friction_level_final'], STEADY[0])}"
    )
    finals = [_summary(recs[case], model, root)["friction_level_final"] for case, _ in CASES]
    before = offsets(model, recs)
    cells.append(
        " / ".join(
            f"{b:+.3f}: {100 * ((f - b) / TRUTH[c] - 1):+.1f} %"
            for b, f, (c, _) in zip(before, finals, CASES, strict=True)
        )
    )
    if hours:
        episodes = [_summary(recs[f"hour{k}"], model, root)["alarm_episodes"] for k in (0, 1)]
        cells.append(" / ".join(map(str, episodes)))
    return "| " + " | ".join(cells) + " |"


def main(hours: bool) -> None:
    head = [
        "model", "γ_f (99 %)", "status", "TC1: detected, level (truth 0.424)",
        "TC2: detected, level (truth 2.296)",
        "steady fault: isolated after, episodes/cleared, level (truth 1)",
        "level before TC1 / TC2: final less it",
    ] + (["fault-free hour 0 / 1: episodes"] if hours else [])  # fmt: skip
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head), flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        recs = record(root)
        plant = root / "plant.yaml"
        _fdi("identify", recs["ident_chirp"], "--validate", recs["ident_chirp_long"], "-o", plant)
        shipped = REPO / "configs" / "model_sim_rig.yaml"
        print(row("shipped (`signature_calibration.yaml`)", shipped, recs, root, hours), flush=True)
        for index, trial in enumerate(TRIALS):
            model = trial_model(trial, plant, root, index)
            print(row(trial[0], model, recs, root, hours), flush=True)


if __name__ == "__main__":
    main("--hours" in sys.argv[1:])
