"""`fdi diagnose`: where the model and the measurement disagree, which effect is missing."""

from __future__ import annotations

import argparse
import sys

from fdi_daemon.io.columns import add_columns_option

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
    import numpy as np

    from fdi_daemon.commands.identify import MAX_ORDER
    from fdi_daemon.diagnose.effects import BASE_TERMS
    from fdi_daemon.errors import UserError
    from fdi_daemon.io.model_file import FdiModel, load_model, save_model
    from fdi_daemon.io.outputs import check_outputs, write_json
    from fdi_daemon.io.recordings import fit_column, read_recording, same_rate

    if args.order is not None and not 1 <= args.order <= MAX_ORDER:
        raise UserError(f"--order must be 1..{MAX_ORDER}, got {args.order}")
    check_outputs(
        {"--json": args.json, "--plot": args.plot, "-o": args.out},
        (args.recording, args.model),
        plots=("--plot",),
        rewrites={"-o": args.model},
    )
    out_col = args.output or OUTPUT_COLUMNS[args.output_kind]
    # only the time and the two columns used are required (real data name them freely)
    if args.fs is not None and not (np.isfinite(args.fs) and args.fs > 0):
        raise UserError(f"--fs must be a positive sample rate in Hz, got {args.fs:g}")
    rec = read_recording(
        args.recording, required=("t", args.input, out_col), columns=args.columns, fs_hz=args.fs
    )  # every missing column named at once
    fs = rec.fs
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
    model = None
    plant_b = plant_a = None
    if args.model:
        model = load_model(args.model)
        if not same_rate(fs, model.fs):
            raise UserError(
                f"{args.model}: model fs = {model.fs:g} Hz but {args.recording} "
                f"is sampled at {fs:g} Hz"
            )
        plant_b, plant_a = model.plant_b, model.plant_a
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

    from rich.console import Console
    from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    from fdi_daemon.diagnose.report import build_report, summary_lines
    from fdi_daemon.diagnose.workflow import run_diagnose

    with Progress(
        SpinnerColumn(),
        TextColumn("{task.description}"),
        TimeElapsedColumn(),
        console=Console(stderr=True),
        transient=True,
    ) as progress:
        task = progress.add_task("fitting candidate effects", total=None)
        result = run_diagnose(
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
    report = build_report(result, source=str(args.recording))
    for line in summary_lines(report):
        print(line)
    if args.json:
        write_json(args.json, report, indent=1)
    if args.plot:
        from fdi_daemon.diagnose.plots import plot_diagnosis

        plot_diagnosis(result, report, args.plot)
    if args.out and result.ctx.form == "inverse_dynamics":
        raise UserError(
            f"-o {args.out}: effects tested in the inverse-dynamics form (a force "
            f"balance on the measured motion) cannot be simulated; use --form "
            f"simulation to write an augmented model"
        )
    if args.out:
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
    return 0
