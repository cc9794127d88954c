"""Regenerates docs/diagnose_results.md: what `fdi diagnose` names on the measured cases of
docs/diagnose.md, with the held-out gaps, the noise floor and the sizes read, against the
truth each simulator hid.

Run: ``python studies/diagnose_results.py [-o docs/diagnose_results.md] [SECTION ...]``.
Sections (default: the first five; 8.4 minutes on two cores shared with other jobs, 13.6
at a load average of 5; all seven 18 at that load):

- ``examples``: the §V model with each hidden effect of the library and one parameter
  changed, with a model file and with ``--fit-linear``, on acceleration, velocity and
  position outputs; the closed-loop stage, the positioning drive and the Duffing
  oscillator (`tests/diagnose_cases.py`, the records of the diagnose tests);
- ``rig``: the simulated pneumatic rig with its shipped model file, one fault each
  (`diagnose_cases.rig_recording`, the records of `tests/test_diagnose_rig.py`);
- ``variants``: four random rig variants with their own identified models, eight faults
  each, under OpenBLAS's Haswell kernel and under SkylakeX (where the CPU has AVX-512),
  compared cell by cell (`diagnose_rig_variants.py`, `diagnose_kernel_agreement.py`);
- ``mechanics``, ``duffing``: the §V model and the Duffing oscillator under other
  excitations (`diagnose_excitation_sweep.py`; under a minute each);
- ``rig-excitations`` (not by default, 3 minutes): the rig under two other excitations;
- ``silverbox`` (not by default, 2 minutes): the Silverbox-like records of
  `silverbox_like.py` at β 0.01 and 0.02.

A progress bar goes to stderr. Every row is one blind `run_diagnose` call: the workflow
sees the recording and the nominal model (or fits its own); the truth is only printed.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import fdi_daemon  # noqa: F401  (first: as `fdi diagnose` does, before NumPy loads)

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "studies"))

# isort: split
import numpy as np  # noqa: E402
from scipy import signal  # noqa: E402

#: the named effect's size shown beside its name: (physical key, label, unit), first found
SIZES = (
    ("coulomb_level", "F_c", "N"),
    ("coulomb_level_input_equivalent", "F_c", "V"),
    ("gain_ratio", "×", ""),
    ("mass_ratio", "×", ""),
    ("stiffness_ratio", "×", ""),
    ("damping_change_per_s", "Δ(c/m)", "/s"),
    ("dead_time_s", "τ", "s"),
    ("half_width", "w", ""),
    ("level", "L", ""),
    ("gap", "g", ""),
    ("offset", "", ""),
    ("offset_input_equivalent", "", "V"),
    ("cubic_coefficient", "k₃", ""),
    ("cubic_coefficient_input_equivalent", "k₃", ""),
)


@dataclass(frozen=True)
class Case:
    """One row: ``run()`` returns `run_diagnose`'s arguments (u, y, fs, kind, b, a)."""

    label: str
    truth: str
    run: Callable[[], tuple]


def size(effect) -> str:
    """The named effect with its size (`SIZES`)."""
    for key, label, unit in SIZES:
        value = effect.physical.get(key)
        if isinstance(value, float) and math.isfinite(value):
            if key == "dead_time_s":
                return f"{effect.named_as} ({1e3 * value:.2f} ms)"
            unit = effect.physical.get(f"{key}_unit", unit)
            text = f"{label} {value:.4g}" if label else f"{value:.4g}"
            return f"{effect.named_as} ({text}{' ' + unit if unit else ''})"
    return effect.named_as


def floor_text(floor) -> str:
    return "unknown" if floor is None else f"{floor:.4f}"


def diagnose_row(case: Case) -> list[str]:
    """One blind diagnosis: the row of a results table."""
    from fdi_daemon.diagnose.workflow import run_diagnose

    started = time.perf_counter()
    u, y, fs, kind, b, a = case.run()
    r = run_diagnose(u, y, fs, kind, b, a)
    named = ", ".join(size(e) for e in r.selection.named) or "—"
    ties = "; ".join(" or ".join(t["effects"]) for t in r.ambiguous)
    return [
        case.label,
        case.truth,
        named + (f" (ambiguous: {ties})" if ties else ""),
        r.info["form"],
        f"{r.gap_before:.4f}",
        f"{r.gap_after:.4f}",
        floor_text(r.info["noise_floor"]["floor"]),
        f"{time.perf_counter() - started:.0f}",
    ]


ROW_HEAD = ["case", "truth", "named (size read)", "form", "gap before", "gap after", "floor", "s"]


# ------------------------------------------------------------------------------ the cases


def msd_cases() -> Iterator[Case]:
    """The §V model (1 kg, 5 Hz, ζ 0.1, 20 Hz input filter, 10 N/V; 24 s of a 0.3–12 Hz
    multisine at 0.5 V RMS), its exact friction-free model unless --fit-linear."""
    from tests.diagnose_cases import FS, HIDDEN, changed_recording, nominal_model, recording

    b, a = nominal_model()
    column = {"acceleration": "accel", "velocity": "velocity", "position": "position"}

    def hidden(effect, kind="acceleration", model=True):
        def run():
            rec = recording(effect)
            return rec.v_in, rec[column[kind]], FS, kind, *((b, a) if model else (None, None))

        return run

    def changed(parameter, ratio, kind="acceleration"):
        def run():
            rec = changed_recording(parameter, ratio)
            return rec.v_in, rec[column[kind]], FS, kind, b, a

        return run

    def truth(effect):
        return ", ".join(f"{k} {v:g}" for k, v in HIDDEN[effect].items()) if effect else "—"

    for effect in [None, *sorted(HIDDEN)]:
        yield Case(f"§V {effect or '(none)'}", truth(effect), hidden(effect))
    for parameter, ratio in (
        ("stiffness_n_per_m", 0.8),
        ("stiffness_n_per_m", 1.2),
        ("mass_kg", 0.8),
        ("mass_kg", 1.25),
        ("gain_n_per_v", 1.2),
    ):
        yield Case(f"§V {parameter} × {ratio:g}", f"× {ratio:g}", changed(parameter, ratio))
    for kind in ("velocity", "position"):
        for ratio in (0.8, 1.25):
            yield Case(
                f"§V mass_kg × {ratio:g}, {kind}", f"× {ratio:g}", changed("mass_kg", ratio, kind)
            )
    for kind, effect in (
        ("velocity", "coulomb_friction"),
        ("position", "dead_zone"),
        ("velocity", None),
    ):
        yield Case(f"§V {effect or '(none)'}, {kind}", truth(effect), hidden(effect, kind))
    for effect in (None, "input_saturation"):
        yield Case(
            f"§V {effect or '(none)'}, --fit-linear", truth(effect), hidden(effect, model=False)
        )


def machine_cases() -> Iterator[Case]:
    """The closed-loop stage, the positioning drive and the Duffing oscillator, each with a
    fitted linear baseline (--fit-linear)."""
    from tests.diagnose_cases import (
        FS,
        arrow_recording,
        duffing_recording,
        positioner_recording,
        stage_recording,
    )

    def stage(coulomb_n, offset_n):
        def run():
            rec = stage_recording(coulomb_n, offset_n)
            return rec["force"], rec["vel"], rec.fs, "velocity", None, None

        return run

    def positioner(coulomb_n, offset_n, column="vel", kind="velocity", filtered=False):
        def run():
            rec = positioner_recording(coulomb_n, offset_n)
            y = rec[column]
            if filtered:  # the drive's velocity through a 2nd-order 100 Hz low-pass
                y = signal.lfilter(*signal.butter(2, 100.0, fs=rec.fs), y)
            return rec["force"], y, rec.fs, kind, None, None

        return run

    def duffing(k3, noise_hz=None, arrow=False):
        def run():
            rec = arrow_recording(k3) if arrow else duffing_recording(k3, noise_hz=noise_hz)
            return rec.v_in, rec["position"], FS, "position", None, None

        return run

    yield Case("stage, velocity out", "F_c 20 N, offset 1 N", stage(20.0, 1.0))
    yield Case("stage without friction", "—", stage(0.0, 0.0))
    yield Case("positioner, velocity out", "F_c 20 N, offset −3 N", positioner(20.0, -3.0))
    yield Case(
        "positioner, position out",
        "F_c 20 N, offset −3 N",
        positioner(20.0, -3.0, "pos", "position"),
    )
    yield Case(
        "positioner, velocity low-passed 100 Hz",
        "F_c 20 N, offset −3 N",
        positioner(20.0, -3.0, filtered=True),
    )
    yield Case("positioner without friction", "—", positioner(0.0, 0.0))
    yield Case("Duffing, 0.3–12 Hz multisine", "k₃ 3e5 N/m³ (3e4 V/m³)", duffing(3e5))
    yield Case("Duffing, 15 Hz noise", "k₃ 1e5 N/m³ (1e4 V/m³)", duffing(1e5, noise_hz=15.0))
    yield Case("Duffing, arrow + 3 multisines", "k₃ 3e5 N/m³ (3e4 V/m³)", duffing(3e5, arrow=True))
    yield Case("linear oscillator (Duffing k₃ 0)", "—", duffing(0.0))


def rig_cases() -> Iterator[Case]:
    """The simulated pneumatic rig (`hil_sim.rig.Rig`, seed 4) with its shipped model file,
    one fault from the start; a 1–12 Hz multisine of 0.8 V RMS for 40 s unless stated."""
    from hil_sim.rig import RigParams
    from tests.diagnose_cases import RIG_FS, rig_model, rig_recording

    b, a = rig_model()
    nominal = RigParams()
    strong = {"rms_v": 0.8, "duration_s": 40.0}
    small = {"rms_v": 0.4, "duration_s": 30.0}

    def case(label, truth, excitation=strong, **kwargs):
        def run():
            u, y = rig_recording(**kwargs, **excitation)
            return u, y, RIG_FS, "acceleration", b, a

        tag = "" if excitation is strong else " (0.4 V, 30 s)"
        return Case(label + tag, truth, run)

    def seal(coulomb_n, static_n):
        return (("seal_coulomb_n", coulomb_n), ("seal_static_n", static_n))

    yield case("fault-free", f"the seal's friction ({nominal.seal_coulomb_n:g} N)")
    yield case("accelerometer bias", "0.3 m/s²", small, fault="accel_bias", value=0.3)
    yield case("accelerometer bias", "0.5 m/s²", fault="accel_bias", value=0.5)
    yield case("accelerometer range × 0.05", "a clip", fault="accel_saturation", value=0.05)
    for supply in (0.75, 0.65, 0.55):
        yield case(
            f"bearing supply {supply:.0%}", "contact friction", fault="bearing_supply", value=supply
        )
    yield case("valve gain 70 %", "× 0.7", fault="valve_gain", value=0.7)
    yield case("valve gain 85 %", "× 0.85", fault="valve_gain", value=0.85)
    yield case("valve gain 130 %", "× 1.3", small, fault="valve_gain", value=1.3)
    for added_kg in (0.5, -0.3):
        mass = nominal.bearing_mass_kg + added_kg
        ratio = RigParams(bearing_mass_kg=mass).moving_mass_kg / nominal.moving_mass_kg
        yield case(
            f"payload {added_kg:+g} kg", f"mass × {ratio:.3f}", variant=(("bearing_mass_kg", mass),)
        )
    yield case("supply pressure 80 %", "a softer air spring", fault="supply_pressure", value=0.8)
    yield case(
        "supply pressure 80 %", "a softer air spring", small, fault="supply_pressure", value=0.8
    )
    yield case("supply pressure 115 %", "a stiffer air spring", fault="supply_pressure", value=1.15)
    for effect, truth in (
        ("dead_time", "7.81 ms + the model's lag"),
        ("dead_zone", "w 0.15 V"),
        ("input_saturation", "L 1.2 V"),
        ("backlash", "g 0.2 V"),
    ):
        yield case(f"drive: {effect}", truth, input_effect=effect)
    for factor in (1.5, 2.0, 3.0):
        damping = nominal.viscous_damping_n_s_per_m
        yield case(
            f"load damping × {factor:g}",
            f"Δ(c/m) +{(factor - 1) * damping / nominal.moving_mass_kg:.1f} /s",
            variant=(("viscous_damping_n_s_per_m", damping * factor),),
        )
    yield case("seal Coulomb 1 N, static 1.2 N", "friction", variant=seal(1.0, 1.2))
    yield case("seal Coulomb 3 N, static 3.5 N", "friction", variant=seal(3.0, 3.5))
    for coulomb_n, excitation in ((0.5, strong), (0.5, small), (3.4, strong), (3.4, small)):
        yield case(
            f"seal pure Coulomb {coulomb_n:g} N",
            "friction, static = Coulomb",
            excitation,
            variant=seal(coulomb_n, coulomb_n),
        )


# ------------------------------------------------------------------------------ the sections


def table(head: list[str], rows: list[list[str]]) -> list[str]:
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    return out + ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]


def rows_section(title: str, intro: str, cases: list[Case], tick) -> list[str]:
    rows = []
    for case in cases:
        rows.append(diagnose_row(case))
        tick(case.label)
    return [f"## {title}", "", intro, "", *table(ROW_HEAD, rows), ""]


def variants_section(tick) -> list[str]:
    from diagnose_kernel_agreement import GAP_SHARE, compare, kernels, sweep

    pair = kernels()
    names = [k or "OpenBLAS's own" for k in pair]
    with ThreadPoolExecutor(2) as pool:
        one, other = pool.map(
            lambda k: sweep(
                k, ["0", "1", "2", "3"], lambda c: tick(f"{c['variant']} {c['fault']}")
            ),
            pair,
        )
    compared = compare(one, other)
    rows = []
    for c, cell in one.items():
        v = compared.get(c, {})
        ratios = ", ".join(f"{k} {x:g}" for k, x in cell["ratios"].items())
        b = other.get(c)
        rows.append(
            [
                cell["variant"],
                f"{cell['fault']} {cell['value']:g}",
                cell["truth"] or "—",
                ", ".join(cell["named"]) + (f" ({ratios})" if ratios else ""),
                f"{cell['gap_before']:.4f}",
                f"{cell['gap_after']:.4f}",
                floor_text(cell["floor"]),
                "same" if v.get("same") else (", ".join(b["named"]) if b else "—"),
                "—"
                if b is None
                else f"{b['gap_after']:.4f}" + (" (apart)" if v.get("apart") else ""),
                "yes" if v.get("right_one") else "**no**",
            ]
        )
    count = {k: sum(v[k] for v in compared.values()) for k in next(iter(compared.values()))}
    head = [
        "variant",
        "fault",
        "truth",
        f"named ({names[0]})",
        "gap before",
        "gap after",
        "floor",
        f"named ({names[1]})",
        f"gap after ({names[1]})",
        "as the physics says",
    ]
    return [
        "## Rig variants, under two BLAS kernels",
        "",
        "Four random variants of the rig (`tests/test_detect_other_rig.rig_variant`: another load "
        "mass, damping, valve, seal and contact friction), each with its own `fdi identify` model "
        "from its identification chirp; one fault each from the start of a 40 s, 0.8 V RMS "
        "multisine (`python studies/diagnose_rig_variants.py`). Each sweep runs in a process of "
        f"its own under `OPENBLAS_CORETYPE={pair[0]}` and "
        f"{'`OPENBLAS_CORETYPE=' + pair[1] + '`' if pair[1] else 'OpenBLAS’s own choice'} "
        "(`python studies/diagnose_kernel_agreement.py`). “As the physics says”: the fault's own "
        "effect named, beside it only the seal's friction (`diagnose_kernel_agreement.EXPECTED`; "
        "under the first kernel).",
        "",
        *table(head, rows),
        "",
        f"**{len(compared)} cells: the same names under both kernels in {count['same']}, gaps "
        f"after more than {GAP_SHARE:.0%} apart in {count['apart']}; named as the physics says "
        f"in {count['right_one']} ({names[0]}) and {count['right_other']} ({names[1]}).**",
        "",
    ]


def sweep_section(title: str, intro: str, cases: Callable[[], Iterator[dict]], total: int, tick):
    rows = []
    for case in cases():
        tick(case["case"])  # done
        read = ", ".join(f"{k} {v:.4g}" for k, v in case["read"].items() if math.isfinite(v))
        ties = "; ".join(" or ".join(t) for t in case["ambiguous"])
        rows.append(
            [
                case["case"],
                ", ".join(case["named"]) or "—",
                read or "—",
                case["form"] + (f"; ambiguous: {ties}" if ties else ""),
                f"{case['gap_before']:.4f}",
                f"{case['gap_after']:.4f}",
                floor_text(case["floor"]),
            ]
        )
    head = ["case", "named", "read", "form", "gap before", "gap after", "floor"]
    return [f"## {title}", "", intro, "", *table(head, rows), ""]


def silverbox_section(tick) -> list[str]:
    from silverbox_like import diagnose_record

    rows = []
    for beta in (0.01, 0.02):
        r = diagnose_record(beta)
        tick(f"Silverbox-like β {beta}")
        k3 = r["sizes"].get("cubic_stiffness", {}).get("cubic_coefficient_input_equivalent")
        rows.append(
            [
                f"β {beta}",
                f"{r['k3_truth']:.4f}",
                ", ".join(r["named"]) or "—",
                "—" if k3 is None else f"{k3:.4f}",
                f"{r['gap_before']:.4f}",
                f"{r['gap_after']:.4f}",
                floor_text(r["floor"]),
            ]
        )
    head = ["record", "k₃ truth (V/V³)", "named", "k₃ read", "gap before", "gap after", "floor"]
    intro = (
        "An electronic Duffing oscillator recorded as the Silverbox benchmark is (60 Hz, ζ 0.05, "
        "610.35 Hz; an arrow, then ten odd multisine realisations to 200 Hz; position out, 0.1 mV "
        "noise; `python studies/silverbox_like.py 0.01 0.02`), `--fit-linear`."
    )
    return ["## Silverbox-like records", "", intro, "", *table(head, rows), ""]


def sections() -> dict[str, tuple[int, Callable]]:
    """name -> (rows, function(tick) -> Markdown lines)."""
    from diagnose_excitation_sweep import PARTS

    examples = [*msd_cases(), *machine_cases()]
    rig = list(rig_cases())
    return {
        "examples": (
            len(examples),
            lambda tick: rows_section(
                "The §V model and machines like the real ones",
                "`tests/diagnose_cases.py`: the §V model (1 kg, 5 Hz, ζ 0.1, a 20 Hz input filter, "
                "10 N/V; 24 s of a 0.3–12 Hz multisine at 0.5 V RMS; acceleration out unless "
                "stated) with one hidden effect or one parameter changed, its exact friction-free "
                "model as the model file unless `--fit-linear`; the closed-loop stage (PI velocity "
                "loop, 60 s at 500 Hz), the positioning drive (position loop, point-to-point moves, "
                "24.8 s at 1 kHz) and the Duffing oscillator (the §V mechanics without input filter, "
                "40 s, position out), each `--fit-linear`. Sizes: friction and offsets in input "
                "units (V per unit of the regressor on the §V model, N in the force balance), "
                "ratios of the named parameter, Δ(c/m) the damping added per unit mass.",
                examples,
                tick,
            ),
        ),
        "rig": (
            len(rig),
            lambda tick: rows_section(
                "The simulated pneumatic rig",
                "`hil_sim.rig.Rig` (seed 4) after 1 s at rest, a 1–12 Hz multisine (seed 3), one "
                "fault from the start; the shipped `configs/model_sim_rig.yaml` as the model file "
                "(`fdi identify` on the fault-free identification chirp); "
                "`tests.diagnose_cases.rig_recording`. The rig's rod seal has a little Coulomb "
                "friction (0.06 N) before any fault, which may rightly be named beside the fault. "
                "A friction's input equivalent on this valve-driven rig carries the valve path's "
                "phase: a size, not a signed level.",
                rig,
                tick,
            ),
        ),
        "variants": (64, variants_section),
        "mechanics": (
            24,
            lambda tick: sweep_section(
                "The §V model under other excitations",
                "`python studies/diagnose_excitation_sweep.py mechanics`: one parameter changed, "
                "band-limited noise to 15 Hz and 0.3–4 Hz and 3–8 Hz multisines, 24 s.",
                PARTS["mechanics"],
                24,
                tick,
            ),
        ),
        "duffing": (
            9,
            lambda tick: sweep_section(
                "The Duffing oscillator under other excitations",
                "`python studies/diagnose_excitation_sweep.py duffing`: k₃ 3·10⁴, 10⁵, 3·10⁵ N/m³ "
                "(read: N/m³), 40 s at 1 V RMS, `--fit-linear`, position out.",
                PARTS["duffing"],
                9,
                tick,
            ),
        ),
        "rig-excitations": (
            24,
            lambda tick: sweep_section(
                "The rig under other excitations",
                "`python studies/diagnose_excitation_sweep.py rig`: band-passed noise 1–15 Hz and "
                "a 2–25 Hz multisine, 0.8 V RMS, 40 s, the shipped model file.",
                PARTS["rig"],
                24,
                tick,
            ),
        ),
        "silverbox": (2, silverbox_section),
    }


SECTIONS = ("examples", "rig", "variants", "mechanics", "duffing", "rig-excitations", "silverbox")
DEFAULT = SECTIONS[:5]


# ------------------------------------------------------------------------------ the header


def git(*args: str) -> str:
    return subprocess.run(
        ["git", "-C", str(REPO), *args], capture_output=True, text=True, check=False
    ).stdout.strip()


def environment() -> list[str]:
    import scipy.linalg  # noqa: F401  (loads SciPy's own OpenBLAS)
    from threadpoolctl import threadpool_info

    blas = sorted(
        {
            f"{i.get('internal_api')} {i.get('version')} ({i.get('architecture')} kernel)"
            for i in threadpool_info()
            if i.get("user_api") == "blas"
        }
    )
    cpu = next(
        (
            line.split(":", 1)[1].strip()
            for line in Path("/proc/cpuinfo").read_text().splitlines()
            if line.startswith("model name")
        ),
        platform.processor(),
    )
    return [
        f"Python {platform.python_version()}, NumPy {np.__version__}, SciPy {scipy.__version__}; "
        f"BLAS: {'; '.join(blas)}; `OPENBLAS_CORETYPE` "
        f"{os.environ.get('OPENBLAS_CORETYPE', 'unset')}",
        f"CPU: {cpu}, {os.cpu_count()} cores (shared with other jobs)",
    ]


def code_state() -> str:
    """The commit, and whether tracked files outside docs/ differ from it."""
    dirty = git("status", "--porcelain", "--untracked-files=no", "--", ".", ":!docs")
    return git("rev-parse", "--short", "HEAD") + (" with uncommitted changes" if dirty else "")


def header(chosen: list[str], seconds: dict[str, float], command: str, commit: str) -> list[str]:
    total = sum(seconds.values())
    took = ", ".join(f"{name} {s / 60:.1f} min" for name, s in seconds.items())
    return [
        "# `fdi diagnose`: measured cases (generated)",
        "",
        "Generated by `" + command + "`; do not edit by hand. What the method is and what the "
        "columns mean: [diagnose.md](diagnose.md). Gaps are the held-out NRMSE (the last third of "
        "each record); the floor is the noise floor's NRMSE (§2 there).",
        "",
        f"- commit {commit}, {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC",
        *(f"- {line}" for line in environment()),
        f"- sections: {', '.join(chosen)}; took {total / 60:.1f} min ({took})",
        *(
            [f"- not run here: {', '.join(s for s in SECTIONS if s not in chosen)}"]
            if set(SECTIONS) - set(chosen)
            else []
        ),
        "",
    ]


def main(argv: list[str] | None = None) -> None:
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    parser = argparse.ArgumentParser(description="regenerate docs/diagnose_results.md")
    parser.add_argument("sections", nargs="*", help=f"default: {' '.join(DEFAULT)}")
    parser.add_argument("-o", "--out", default=str(REPO / "docs" / "diagnose_results.md"))
    args = parser.parse_args(argv)
    available = sections()
    chosen = args.sections or list(DEFAULT)
    unknown = [s for s in chosen if s not in available]
    if unknown:
        parser.error(f"unknown section {unknown}; choose from {', '.join(available)}")
    commit = code_state()
    body: list[str] = []
    seconds: dict[str, float] = {}
    progress = Progress(
        TextColumn("{task.description:<48}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=Console(stderr=True),
    )
    with progress:
        task = progress.add_task("", total=sum(available[s][0] for s in chosen))

        def tick(label: str) -> None:
            progress.update(task, description=label[:48])
            progress.advance(task)

        for name in chosen:
            started = time.perf_counter()
            body += available[name][1](tick)
            seconds[name] = time.perf_counter() - started
    command = "python studies/diagnose_results.py" + "".join(f" {s}" for s in args.sections)
    Path(args.out).write_text("\n".join(header(chosen, seconds, command, commit) + body))
    print(f"wrote {args.out} in {sum(seconds.values()) / 60:.1f} min", file=sys.stderr)


if __name__ == "__main__":
    main()
