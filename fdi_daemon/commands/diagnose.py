"""`fdi diagnose`: where the model and the measurement disagree, which effect is missing."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING, Any

from fdi_daemon.io.columns import add_columns_option

if TYPE_CHECKING:
    import numpy as np

    from fdi_daemon.diagnose.workflow import DiagnoseResult
    from fdi_daemon.io.model_file import FdiModel

HELP = "find where a model and a recording disagree, name the missing effect, add it"

OUTPUT_COLUMNS = {"acceleration": "accel", "velocity": "velocity", "position": "position"}


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "recording", metavar="REC", help="recording (.csv, .csv.gz, .npz, .mat, .parquet)"
    )
    src = parser.add_mutually_exclusive_group(required=True)
    src.add_argument("--model", metavar="MODEL.yaml", help="model file with the nominal Ĝ")
    src.add_argument(
        "--fit-linear",
        action="store_true",
        help="fit a linear output-error baseline on the first 2/3 of the recording",
    )
    parser.add_argument(
        "--order",
        type=int,
        default=None,
        help="order of the --fit-linear baseline (default: chosen from the data among 2, 4, 6, 8)",
    )
    parser.add_argument("--input", default="v_in", metavar="COL", help="input column (v_in)")
    parser.add_argument(
        "--output",
        default=None,
        metavar="COL",
        help="output column (default: accel, velocity or position by kind)",
    )
    parser.add_argument(
        "--output-kind",
        default="acceleration",
        choices=("acceleration", "velocity", "position"),
        help="what the output column measures (default acceleration)",
    )
    parser.add_argument(
        "--form",
        default="auto",
        choices=("auto", "simulation", "inverse_dynamics"),
        help="how effects are tested: a free-run simulation, or the force "
        "balance on the measured motion (velocity/position outputs; for "
        "integrating or closed-loop plants); auto: inverse_dynamics when "
        "the free run drifts, both forms (the one whose effects explain "
        "more kept) for a velocity or position output otherwise "
        "(default auto)",
    )
    add_columns_option(parser)
    parser.add_argument(
        "--fs",
        type=float,
        default=None,
        metavar="HZ",
        help="sample rate of a recording without a time column t (t = k/fs "
        "is made; with a t column the two must agree)",
    )
    parser.add_argument("--json", metavar="REPORT.json", help="write the report as JSON")
    parser.add_argument("--plot", metavar="FILE.png", help="measured vs simulated, error maps")
    parser.add_argument(
        "-o", "--out", metavar="AUGMENTED_MODEL.yaml", help="write the model with the added effects"
    )


def run(args: argparse.Namespace) -> int:
    """Check the options, read the recording (and --model), diagnose, report; returns 0
    (bad input: `UserError`)."""
    _check_options(args)
    u, y, fs = _read_signals(args)
    model = _nominal_model(args, fs) if args.model else None
    result = _run_workflow(args, u, y, fs, model)
    report = _write_report(args, result)
    if args.out:
        _write_augmented_model(args, result, report, model, fs)
    return 0


def _check_options(args: argparse.Namespace) -> None:
    """--order and --fs in range; the outputs writable, none destroying an input (`check_outputs`)."""
    import numpy as np

    from fdi_daemon.commands.identify import MAX_ORDER
    from fdi_daemon.errors import UserError
    from fdi_daemon.io.outputs import check_outputs

    if args.order is not None and not 1 <= args.order <= MAX_ORDER:
        raise UserError(f"--order must be 1..{MAX_ORDER}, got {args.order}")
    check_outputs(
        {"--json": args.json, "--plot": args.plot, "-o": args.out},
        (args.recording, args.model),
        plots=("--plot",),
        rewrites={"-o": args.model},
    )
    if args.fs is not None and not (np.isfinite(args.fs) and args.fs > 0):
        raise UserError(f"--fs must be a positive sample rate in Hz, got {args.fs:g}")


def _read_signals(args: argparse.Namespace) -> tuple[np.ndarray, np.ndarray, float]:
    """The recording's input u and output y, checked long and varied enough to diagnose,
    and its sample rate (Hz)."""
    import numpy as np

    from fdi_daemon.errors import UserError
    from fdi_daemon.io.recordings import fit_column, read_recording

    out_col = args.output or OUTPUT_COLUMNS[args.output_kind]
    # only the time and the two columns used are required (real data name them freely)
    rec = read_recording(
        args.recording, required=("t", args.input, out_col), columns=args.columns, fs_hz=args.fs
    )  # every missing column named at once
    u = fit_column(rec, args.input, args.recording)
    y = fit_column(rec, out_col, args.recording)
    min_samples = max(256, 40 * ((args.order or 8) + 2))
    if len(u) < min_samples:
        raise UserError(
            f"{args.recording}: {len(u)} samples; diagnose needs at least "
            f"{min_samples} (2/3 to fit, 1/3 held out)"
        )
    if np.ptp(u) == 0.0:
        raise UserError(
            f"{args.recording}: input column {args.input} is constant: nothing excites the model"
        )
    if np.ptp(y) == 0.0:
        raise UserError(f"{args.recording}: output column {out_col} is constant")
    return u, y, rec.fs


def _nominal_model(args: argparse.Namespace, fs: float) -> FdiModel:
    """The --model file, at the recording's rate ``fs`` (Hz); a note on stderr when it holds
    effects of an earlier diagnosis (its plant alone is the nominal model)."""
    from fdi_daemon.diagnose.effects import BASE_TERMS
    from fdi_daemon.errors import UserError
    from fdi_daemon.io.model_file import load_model
    from fdi_daemon.io.recordings import same_rate

    model = load_model(args.model)
    if not same_rate(fs, model.fs):
        raise UserError(
            f"{args.model}: model fs = {model.fs:g} Hz but {args.recording} is sampled at {fs:g} Hz"
        )
    section = model.extra.get("effects")
    items = section.get("items") if isinstance(section, dict) else None
    held = [
        e["name"]
        for e in items or []
        if isinstance(e, dict) and "name" in e and e["name"] not in BASE_TERMS
    ]
    if held:  # an augmented model (`-o`): its plant is the nominal model here
        print(
            f"fdi diagnose: note: {args.model} holds effects ({', '.join(held)}) from an "
            f"earlier diagnosis; they are not part of the nominal model here (its plant "
            f"is), and -o writes the effects found now in their place",
            file=sys.stderr,
        )
    return model


def _run_workflow(
    args: argparse.Namespace, u: np.ndarray, y: np.ndarray, fs: float, model: FdiModel | None
) -> DiagnoseResult:
    """The diagnosis of u → y (fs in Hz) against the model's plant (or a fitted linear
    baseline without one), with a spinner on stderr naming the effect tried."""
    from rich.console import Console
    from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    from fdi_daemon.diagnose.workflow import run_diagnose

    plant_b, plant_a = (model.plant_b, model.plant_a) if model is not None else (None, None)
    with Progress(
        SpinnerColumn(),
        TextColumn("{task.description}"),
        TimeElapsedColumn(),
        console=Console(stderr=True),
        transient=True,
    ) as progress:
        task = progress.add_task("fitting candidate effects", total=None)
        return run_diagnose(
            u,
            y,
            fs,
            args.output_kind,
            plant_b,
            plant_a,
            order=args.order,
            form=args.form,
            progress=lambda name: progress.update(task, description=f"tried {name}"),
        )


def _write_report(args: argparse.Namespace, result: DiagnoseResult) -> dict[str, Any]:
    """The report: its summary on stdout, --json and --plot where asked; returns it."""
    from fdi_daemon.diagnose.report import build_report, summary_lines
    from fdi_daemon.io.outputs import write_json

    report = build_report(result, source=str(args.recording))
    for line in summary_lines(report):
        print(line)
    if args.json:
        write_json(args.json, report, indent=1)
    if args.plot:
        from fdi_daemon.diagnose.plots import plot_diagnosis

        plot_diagnosis(result, report, args.plot)
    return report


def _write_augmented_model(
    args: argparse.Namespace,
    result: DiagnoseResult,
    report: dict[str, Any],
    model: FdiModel | None,
    fs: float,
) -> None:
    """-o: the nominal model (or the fitted baseline at ``fs``, Hz) with the effects found
    and the diagnosis in its provenance; refused for effects of the inverse-dynamics form."""
    from fdi_daemon.errors import UserError
    from fdi_daemon.io.model_file import FdiModel, save_model

    if result.ctx.form == "inverse_dynamics":
        raise UserError(
            f"-o {args.out}: effects tested in the inverse-dynamics form (a force "
            f"balance on the measured motion) cannot be simulated; use --form "
            f"simulation to write an augmented model"
        )
    provenance = dict(model.provenance) if model is not None else {}
    provenance["diagnose"] = {
        "recording": str(args.recording),
        "baseline": result.info["baseline"],
        "effects": result.named,
        "gap_before": report["gap_before"],
        "gap_after": report["gap_after"],
    }
    if model is not None:
        out = FdiModel(
            fs=model.fs,
            plant_b=model.plant_b,
            plant_a=model.plant_a,
            fault_filter=model.fault_filter,
            velocity=model.velocity,
            detector=model.detector,
            provenance=provenance,
            extra=dict(model.extra),
        )
    else:
        out = FdiModel(
            fs=fs,
            plant_b=result.info["plant_b"],
            plant_a=result.info["plant_a"],
            provenance=provenance,
        )
    out.extra["effects"] = result.plant.to_extra()
    save_model(args.out, out)
    print(f"augmented model written to {args.out}")
