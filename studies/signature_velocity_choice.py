"""Which velocity `fdi signature --velocity-method auto` keeps, and what the levels are then
(docs/identification.md, "Choosing the velocity by the fit"). Run:
``python studies/signature_velocity_choice.py [default|v0|v1|velsrc|variant0..variant7 ...]``
(about two minutes per rig).

Per rig (`studies/friction_level_variants.py`'s): `fdi identify` on its chirps, then
`fdi signature` with ``--velocity-method auto`` (the default for a plant-only model) and
with ``highpass`` on two calibration runs: the shipped one (`signature_calibration.yaml`,
``--fault-window 11:40``) and issue 12's procedure (four equal tones at 2, 3.3, 5 and 8 Hz,
bearing supply 45 % from 4 s, ``--fault-window 5:20``; `test_detect_friction_level`'s
``LOW_FREQUENCY_CALIBRATION``). Each model replays test cases 1 and 2 and the steady fault;
the level is the reported `friction_level`'s median against the simulator's contact force
relative to the calibration's. The four-tone models also replay the non-friction faults of
`tests/test_detect_other_rig.py` (64 s each): the decisions they get.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def measure(name: str, rig: dict, root: Path) -> list[str]:
    from friction_level_variants import CASES, _fdi, _record, case_lines
    from test_detect_friction_level import LOW_FREQUENCY_CALIBRATION
    from test_detect_other_rig import NON_FRICTION, _kinds, record

    from fdi_daemon.io.model_file import load_model
    from fdi_daemon.io.recordings import write_recording
    from hil_sim.scenarios import scenario_from_dict, simulate

    recs = {
        n: _record(rig, n, root / f"{n}.npz")
        for n in ("ident_chirp", "ident_chirp_long", "signature_calibration")
        + tuple(c[0] for c in CASES)
    }
    non_friction = {fault: record(rig, fault, duration_s=64.0) for fault in NON_FRICTION}
    low = simulate(scenario_from_dict({**LOW_FREQUENCY_CALIBRATION, "rig": rig}))
    write_recording(root / "low_frequency.npz", low)
    _fdi(
        "identify",
        root / "ident_chirp.npz",
        "-o",
        root / "plant.yaml",
        "--validate",
        root / "ident_chirp_long.npz",
    )
    runs = (
        ("shipped", recs["signature_calibration"], "11:40", 11.0),
        ("four tones", low, "5:20", 5.0),
    )
    lines = []
    for run, cal, window, fault_from in runs:
        source = root / ("signature_calibration.npz" if run == "shipped" else "low_frequency.npz")
        calibrated = np.mean(cal.columns["contact_force"][cal.t >= fault_from])
        for choice in ("auto", "highpass"):
            out = root / f"{run}-{choice}.yaml".replace(" ", "_")
            _fdi(
                "signature",
                source,
                "--model",
                root / "plant.yaml",
                "--fault-window",
                window,
                "--velocity-method",
                choice,
                "-o",
                out,
            )
            model = load_model(out)
            sig = model.provenance["signature"]
            lines.append(
                f"{name} {run} {choice}: keeps {model.velocity.get('method', 'highpass')}"
                f", VAF by velocity {sig['vaf_percent_by_velocity']}, gamma_f "
                f"{model.fault_filter.gamma_f}"
            )
            lines.extend(case_lines(model, recs, calibrated))
            if run == "four tones":
                lines.extend(
                    f"  {fault}: {[kind for kind, _ in _kinds(model, faulty)]}"
                    for fault, faulty in non_friction.items()
                )
    return lines


if __name__ == "__main__":
    sys.path.insert(0, str(REPO / "tests"))
    from friction_level_variants import variants
    from test_detect_other_rig import rig_variant

    rigs = {**variants(), **{f"variant{i}": rig_variant(i) for i in range(8)}}
    for rig_name in sys.argv[1:] or list(rigs):
        with tempfile.TemporaryDirectory() as tmp:
            print("\n".join(measure(rig_name, rigs[rig_name], Path(tmp))), flush=True)
