"""The shipped model of the simulated rig against one made with a paired calibration of
several carriers (issue 43; docs/identification.md, "A paired calibration with six
carriers"). Run: ``python studies/paired_carriers_calibration.py [MODEL.yaml ...]``
(a few minutes on the shared 2-core machine).

Records the scenarios with `fdi sim record` (seed 0; the fault-free hour with seeds 0 and 1),
makes the candidate model exactly as README's "made by" block does with
``signature_calibration_paired_carriers.yaml`` (`fdi identify` on the chirps, then
`fdi signature --reference-window 1:61 --fault-window 62:122 --lowpass-hz 10`), and the
same with the paired 6 Hz run of README step 2; replays each recording with
`fdi replay --summary` under every model: configs/model_sim_rig.yaml as committed
(``shipped``), the two paired ones and any MODEL.yaml given. The levels are the summary's
`friction_level_final`; the truth column is the simulator's contact force ratio.
One table, a column per model. The simulator's true γ is 3.33 s/m
(`conftest_ident.true_gamma`).
"""

from __future__ import annotations

import contextlib
import io
import json
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SCENARIOS = REPO / "configs" / "scenarios"
CALIBRATION = "signature_calibration_paired_carriers"
CASES = (("test_case_1", 3.05), ("test_case_2", 2.9))
STEADY = ("steady_friction_changing_operation", 20.0)


def _fdi(*argv) -> str:
    from fdi_daemon.cli import main

    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
        code = main([str(a) for a in argv])
    if code != 0:
        raise SystemExit(f"fdi {' '.join(map(str, argv))} failed:\n{out.getvalue()}")
    return out.getvalue()


def record(root: Path) -> dict[str, Path]:
    recs = {}
    for name in ("ident_chirp", "ident_chirp_long", CALIBRATION, *(c for c, _ in CASES), STEADY[0]):
        recs[name] = root / f"{name}.npz"
        _fdi("sim", "record", SCENARIOS / f"{name}.yaml", "-o", recs[name])
    for seed in (0, 1):
        recs[f"hour{seed}"] = root / f"fault_free_hour_{seed}.npz"
        _fdi(
            "sim", "record", SCENARIOS / "fault_free_hour.yaml", "--seed", seed,
            "-o", recs[f"hour{seed}"],
        )  # fmt: skip
    return recs


def make_model(recs: dict[str, Path], calibration: str, windows: tuple[str, str], out: Path):
    """`fdi identify` on the chirps, then `fdi signature` on a paired ``calibration``
    (reference window, fault window), as README's "made by" block."""
    return paired_signature(recs[calibration], plant_model(recs, out), windows, out)


def plant_model(recs: dict[str, Path], out: Path) -> Path:
    """README's `fdi identify` on the chirps, written to ``out`` (returned)."""
    _fdi("identify", recs["ident_chirp"], "--validate", recs["ident_chirp_long"], "-o", out)
    return out


def paired_signature(rec: Path, model: Path, windows: tuple[str, str], out: Path, *options: str):
    """README's `fdi signature` on a paired run ``rec`` with ``model``'s plant (and
    ``options`` more), written to ``out`` (returned)."""
    _fdi(
        "signature", rec, "--model", model, "--reference-window", windows[0],
        "--fault-window", windows[1], "--lowpass-hz", "10", *options, "-o", out,
    )  # fmt: skip
    return out


def carrier_windows() -> tuple[str, str]:
    """Reference window (1 s to the fault) and fault window of the carriers' scenario."""
    import yaml

    spec = yaml.safe_load((SCENARIOS / f"{CALIBRATION}.yaml").read_text())
    onset = spec["events"][0]["t_s"]
    lo, hi = spec["fault_window_s"]
    return f"1:{onset:g}", f"{lo:g}:{hi:g}"


def truths() -> list[str]:
    """The simulator's friction level of each fault: mean air-bearing contact force from
    0.5 s after onset over the calibration fault's (both calibrations cut the supply to
    45 %), as studies/friction_level_variants.py."""
    import numpy as np

    from hil_sim.scenarios import load_scenario, simulate

    cal = simulate(load_scenario(SCENARIOS / f"{CALIBRATION}.yaml"))
    start = float(carrier_windows()[1].split(":")[0])
    ref = np.mean(cal.columns["contact_force"][cal.t >= start])
    out = {}
    for case, onset in (*CASES, STEADY):
        rec = simulate(load_scenario(SCENARIOS / f"{case}.yaml"))
        out[case] = np.mean(rec.columns["contact_force"][rec.t >= onset + 0.5]) / ref
    return [f"{out[c]:.3f}" for c in (CASES[0][0], CASES[1][0], STEADY[0])]


def _summary(rec: Path, model: Path, root: Path) -> dict:
    out = root / "summary.json"
    _fdi("replay", rec, "--model", model, "--summary", out)
    return json.loads(out.read_text())


def _steady_level_band(rec: Path, model: Path, root: Path) -> str:
    """Median (5th-95th percentile) of the reported level from 10 s after the onset,
    from `fdi replay --trace`."""
    import numpy as np

    trace = root / "trace.csv"
    _fdi("replay", rec, "--model", model, "--trace", trace)
    d = np.genfromtxt(trace, delimiter=",", names=True)
    level = d["friction_level"][(d["t"] >= STEADY[1] + 10.0) & np.isfinite(d["friction_level"])]
    lo, med, hi = np.percentile(level, [5, 50, 95])
    return f"{med:.3f} ({lo:.2f}-{hi:.2f})"


def column(model: Path, recs: dict[str, Path], root: Path) -> list[str]:
    from fdi_daemon.io.model_file import load_model

    fdi_model = load_model(model)
    if fdi_model.fault_filter is None:
        raise SystemExit(f"{model}: no fault_filter (run `fdi signature` first)")
    gamma = fdi_model.fault_filter.gamma_f
    profile = fdi_model.provenance["signature"]["cost_profile"]
    lo, hi = profile["interval_99"]
    # models made before the status was stored carry only the profile's flat flag
    status = fdi_model.provenance["signature"].get("gamma_f_status") or (
        "flat" if profile.get("flat") else "identified"
    )
    rows = [f"{'-' if gamma is None else f'{gamma:.2f}'} ({lo:.1f}-{hi:.1f})", str(status)]
    for case, onset in CASES:
        s = _summary(recs[case], model, root)
        det = s["first_detection_t"]
        rows.append(f"{'-' if det is None else round(1000 * (det - onset))} ms")
        rows.append(f"{s['friction_level_final']:.3f}")
    s = _summary(recs[STEADY[0]], model, root)
    other = s["other_fault_t"]
    rows.append("none" if other is None else f"yes, {other - STEADY[1]:.1f} s after onset")
    iso = s["isolated_t"]
    rows.append("-" if iso is None else f"{iso - STEADY[1]:.2f} s")
    rows.append(f"{s['alarm_episodes']} / {s['event_counts'].get('cleared', 0)} cleared")
    rows.append(f"{s['friction_level_final']:.3f}")
    rows.append(_steady_level_band(recs[STEADY[0]], model, root))
    rows.append(
        " / ".join(
            str(_summary(recs[f"hour{seed}"], model, root)["alarm_episodes"]) for seed in (0, 1)
        )
    )
    return rows


ROWS = (
    "γ_f (99 % interval), truth 3.33",
    "γ_f status",
    "test case 1: detected after onset",
    "test case 1: friction level (final)",
    "test case 2: detected after onset",
    "test case 2: friction level (final)",
    "steady fault, changing operation: other_fault?",
    "  time to friction_isolated after onset",
    "  alarm episodes / cleared",
    "  friction level (final)",
    "  friction level from 10 s after onset: median (5-95 %)",
    "fault-free hour, seeds 0 / 1: alarm episodes",
)


def main(extra: list[str]) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        recs = record(root)
        _fdi(
            "sim", "record", SCENARIOS / "signature_calibration_paired.yaml",
            "-o", root / "paired_6hz.npz",
        )  # fmt: skip
        recs["paired_6hz"] = root / "paired_6hz.npz"
        models = {
            "shipped": REPO / "configs" / "model_sim_rig.yaml",
            "paired 6 Hz": make_model(
                recs, "paired_6hz", ("1:21", "22:42"), root / "paired_6hz.yaml"
            ),
            "paired carriers": make_model(
                recs, CALIBRATION, carrier_windows(), root / "paired_carriers.yaml"
            ),
        }
        models.update({Path(m).stem: Path(m) for m in extra})
        cols = {name: column(path, recs, root) for name, path in models.items()}
    truth = truths()
    cols = {"truth": ["3.33", "", "", truth[0], "", truth[1], "", "", "", truth[2], "", ""], **cols}
    print("| | " + " | ".join(cols) + " |")
    print("|---|" + "---|" * len(cols))
    for i, row in enumerate(ROWS):
        print(f"| {row} | " + " | ".join(c[i] for c in cols.values()) + " |")


if __name__ == "__main__":
    main(sys.argv[1:])
