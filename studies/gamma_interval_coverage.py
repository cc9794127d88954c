"""Does γ_f's 99 % interval hold the simulator's true ratio? (docs/identification.md,
"How well γ_f is known"). Run: ``python studies/gamma_interval_coverage.py [--rigs 4]
[--seeds 3] [--excitations ...] [--highpass-hz HZ]`` (15–40 s per calibration run; the
default 36 runs: about 15 minutes).

Calibration runs: rigs (the default rig, then `tests/test_detect_other_rig.py`'s seeded
variants 0, 1, ...) × scenario seeds × the documented excitations (``--excitations`` picks):

- *six carriers*: README step 2, `configs/scenarios/signature_calibration_paired_carriers.yaml`
  (sines at 6, 7, 8, 9, 10, 11.4 Hz each stepped through 1.0–2.5 V, fault-free then with the
  fault), ``--reference-window 1:61 --fault-window 62:122 --lowpass-hz 10``;
- *paired*: the same with one 6 Hz carrier, `signature_calibration_paired.yaml`
  (``--reference-window 1:21 --fault-window 22:42 --lowpass-hz 10``);
- *four tones*: one amplitude, 2, 3.3, 5 and 8 Hz at 0.45 V each, bearing supply 45 % from
  4 s (`test_detect_friction_level.LOW_FREQUENCY_CALIBRATION`), ``--fault-window 5:20``.

Per rig the plant comes from `fdi identify` on its own chirp; `fdi signature` then runs as a
user runs it (a plant-only model: ``--velocity-method auto``). The truth is
`conftest_ident.true_gamma`: the simulator's friction force ≈ α sign v + β v fitted on the
window's sliding samples, γ = β/α (the rig's bearing_viscous_per_n / bearing_mu_kinetic,
3.33 s/m on the default rig). Each line: γ_f, its 99 % interval, status, truth, held or not;
then the share of runs whose interval holds the truth, per excitation and overall.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SCENARIOS = REPO / "configs" / "scenarios"

#: (name, fdi signature options) of the documented calibration excitations
EXCITATIONS: dict[str, tuple[str, ...]] = {
    "six carriers": (
        "--reference-window", "1:61", "--fault-window", "62:122", "--lowpass-hz", "10",
    ),
    "paired": ("--reference-window", "1:21", "--fault-window", "22:42", "--lowpass-hz", "10"),
    "four tones": ("--fault-window", "5:20"),
}  # fmt: skip
#: the scenario file of each paired excitation (the four tones are a test's mapping)
SCENARIO_FILES = {
    "six carriers": "signature_calibration_paired_carriers.yaml",
    "paired": "signature_calibration_paired.yaml",
}


@dataclass(frozen=True)
class CalibrationRun:
    """One `fdi signature` result against the simulator's truth (γ in s/m)."""

    rig: str
    excitation: str
    seed: int
    gamma_f: float | None
    interval: tuple[float, float]
    status: str
    truth: float
    profile_interval: tuple[float, float]  # the likelihood-ratio part alone
    bootstrap_interval: tuple[float, float]  # the block bootstrap part alone

    @property
    def held(self) -> bool:
        """The 99 % interval holds the true ratio."""
        return self.holds(self.interval)

    def holds(self, interval: tuple[float, float]) -> bool:
        """interval holds the true ratio."""
        return interval[0] <= self.truth <= interval[1]

    def line(self) -> str:
        gamma = "null" if self.gamma_f is None else f"{self.gamma_f:5.2f}"
        return (
            f"{self.rig:<10} {self.excitation:<10} seed {self.seed}: gamma_f {gamma}, 99 % "
            f"{self.interval[0]:5.2f} .. {self.interval[1]:5.2f}, {self.status:<22} truth "
            f"{self.truth:4.2f}  {'held' if self.held else 'MISSED'} (profile "
            f"{self.profile_interval[0]:.2f}..{self.profile_interval[1]:.2f}, bootstrap "
            f"{self.bootstrap_interval[0]:.2f}..{self.bootstrap_interval[1]:.2f})"
        )


def _paths() -> None:
    for folder in (REPO, REPO / "tests"):
        if str(folder) not in sys.path:
            sys.path.insert(0, str(folder))


def rigs(count: int) -> dict[str, dict[str, float]]:
    """The default rig and the first count − 1 seeded variants (RigParams overrides)."""
    _paths()
    from test_detect_other_rig import rig_variant

    return {"default": {}, **{f"variant{i}": rig_variant(i) for i in range(count - 1)}}


def _fdi(*argv: object) -> None:
    from fdi_daemon.cli import main

    quiet = io.StringIO()
    with contextlib.redirect_stdout(quiet), contextlib.redirect_stderr(quiet):
        code = main([str(a) for a in argv])
    if code != 0:
        raise SystemExit(f"fdi {' '.join(map(str, argv))} failed:\n{quiet.getvalue()}")


def _scenario(excitation: str, rig: dict[str, float]) -> dict:
    import yaml
    from test_detect_friction_level import LOW_FREQUENCY_CALIBRATION

    if excitation in SCENARIO_FILES:
        spec = yaml.safe_load((SCENARIOS / SCENARIO_FILES[excitation]).read_text())
    else:
        spec = dict(LOW_FREQUENCY_CALIBRATION)
    return {**spec, "rig": {**spec.get("rig", {}), **rig}}


def plant_model(rig: dict[str, float], root: Path) -> Path:
    """`fdi identify` on the rig's own chirp (seed 0): a plant-only model, as after step 1."""
    from fdi_daemon.io.recordings import write_recording
    from hil_sim.scenarios import scenario_from_dict, simulate

    spec = _scenario("paired", rig)  # only for its rig mapping
    chirp = {**_chirp_spec(), "rig": spec["rig"]}
    write_recording(root / "chirp.npz", simulate(scenario_from_dict(chirp)))
    _fdi("identify", root / "chirp.npz", "-o", root / "plant.yaml")
    return root / "plant.yaml"


def _chirp_spec() -> dict:
    import yaml

    return yaml.safe_load((SCENARIOS / "ident_chirp.yaml").read_text())


def calibrate(
    rig_name: str,
    rig: dict[str, float],
    excitation: str,
    seed: int,
    plant: Path,
    root: Path,
    extra: Sequence[str] = (),
) -> CalibrationRun:
    """Simulate one calibration run, `fdi signature` it (with the excitation's options and
    ``extra`` ones), compare with the truth."""
    from conftest_ident import true_gamma

    from fdi_daemon.io.model_file import load_model
    from fdi_daemon.io.recordings import write_recording
    from hil_sim.scenarios import scenario_from_dict, simulate

    options = EXCITATIONS[excitation]
    rec = simulate(scenario_from_dict(_scenario(excitation, rig)), seed=seed)
    path = write_recording(root / f"cal-{excitation.replace(' ', '_')}-{seed}.npz", rec)
    out = root / "signature.yaml"
    _fdi("signature", path, "--model", plant, *options, *extra, "-o", out)
    t0, t1 = (float(x) for x in options[options.index("--fault-window") + 1].split(":"))
    model = load_model(out)
    if model.fault_filter is None:
        raise SystemExit(f"{out}: fdi signature wrote no fault_filter")
    prov = model.provenance["signature"]
    profile = prov["cost_profile"]
    low, high = profile["interval_99"]
    return CalibrationRun(
        rig=rig_name,
        excitation=excitation,
        seed=seed,
        gamma_f=model.fault_filter.gamma_f,
        interval=(float(low), float(high)),
        status=str(prov["gamma_f_status"]),
        truth=true_gamma(rec, t0, t1),
        profile_interval=_pair(profile["interval_99_profile"]),
        bootstrap_interval=_pair(profile["interval_99_bootstrap"]),
    )


def _pair(values: Sequence[float]) -> tuple[float, float]:
    return float(values[0]), float(values[1])


def coverage(runs: Sequence[CalibrationRun], part: str = "interval") -> dict[str, float]:
    """Share of runs whose interval (``part``: "interval", the reported one, or
    "profile_interval" / "bootstrap_interval" alone) holds the truth, per excitation and
    "all"."""

    def held(run: CalibrationRun) -> bool:
        return run.holds(getattr(run, part))

    shares = {
        name: sum(held(r) for r in runs if r.excitation == name)
        / max(1, sum(r.excitation == name for r in runs))
        for name in {r.excitation for r in runs}
    }
    shares["all"] = sum(held(r) for r in runs) / max(1, len(runs))
    return shares


def study(
    rig_count: int,
    seeds: Sequence[int],
    root: Path,
    excitations: Sequence[str] = tuple(EXCITATIONS),
    extra: Sequence[str] = (),
) -> list[CalibrationRun]:
    """Every (rig, seed, excitation) run, printed as it finishes; ``extra``: more `fdi
    signature` options for every run."""
    _paths()
    runs = []
    for rig_name, rig in rigs(rig_count).items():
        folder = root / rig_name
        folder.mkdir(parents=True, exist_ok=True)
        plant = plant_model(rig, folder)
        for seed in seeds:
            for excitation in excitations:
                run = calibrate(rig_name, rig, excitation, seed, plant, folder, extra)
                print(run.line(), flush=True)
                runs.append(run)
    return runs


def main(argv: Sequence[str] | None = None) -> None:
    import tempfile

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rigs", type=int, default=4, help="default rig + variants (4)")
    parser.add_argument("--seeds", type=int, default=3, help="scenario seeds 0.. (3)")
    parser.add_argument(
        "--excitations", nargs="+", choices=list(EXCITATIONS), default=list(EXCITATIONS)
    )
    parser.add_argument(
        "--highpass-hz",
        type=float,
        help="the velocity's high-pass cut-off for every run (default: fdi signature's)",
    )
    args = parser.parse_args(argv)
    extra = () if args.highpass_hz is None else ("--highpass-hz", str(args.highpass_hz))
    with tempfile.TemporaryDirectory() as tmp:
        runs = study(args.rigs, range(args.seeds), Path(tmp), args.excitations, extra)
    for part, label in (
        ("interval", "99 % interval"),
        ("profile_interval", "its profile part alone"),
        ("bootstrap_interval", "its block bootstrap part alone"),
    ):
        shares = coverage(runs, part)
        print(
            f"{label} holds the truth in {100 * shares['all']:.0f} % of {len(runs)} runs ("
            + ", ".join(f"{name}: {100 * shares[name]:.0f} %" for name in args.excitations)
            + ")"
        )


if __name__ == "__main__":
    main()
