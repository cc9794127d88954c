"""`fdi baseline`: the fault-free friction level per operating condition (commissioning)."""

from __future__ import annotations

import argparse

from fdi_daemon.io.columns import add_columns_option

HELP = "store the fault-free friction level per operating condition in the model (commissioning)"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "recording",
        metavar="REC",
        help="fault-free recording of the rig's normal, changing operation (minutes)",
    )
    parser.add_argument(
        "--model", required=True, metavar="MODEL.yaml", help="model file with plant and signature"
    )
    parser.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="MODEL.yaml",
        help="model file to write (may equal --model)",
    )
    parser.add_argument(
        "--min-seconds",
        type=float,
        default=20.0,
        help="valid (moving) data each velocity bin must hold (default %(default)s)",
    )
    parser.add_argument(
        "--max-bins",
        type=int,
        default=8,
        help="at most this many velocity-RMS bins (default %(default)s)",
    )
    add_columns_option(parser)


def run(args: argparse.Namespace) -> int:
    import math

    from fdi_daemon.commands.identify import load_io
    from fdi_daemon.detect.baseline import QUANTITIES, fit_baseline
    from fdi_daemon.detect.monitor import Monitor
    from fdi_daemon.errors import UserError
    from fdi_daemon.ident import provenance
    from fdi_daemon.io.model_file import load_model, save_model
    from fdi_daemon.io.outputs import check_outputs
    from fdi_daemon.io.recordings import same_rate

    if not (math.isfinite(args.min_seconds) and args.min_seconds > 0) or args.max_bins < 1:
        raise UserError("--min-seconds must be a finite number > 0 and --max-bins >= 1")
    check_outputs(
        {"--output": args.output}, (args.recording, args.model), rewrites={"--output": args.model}
    )
    model = load_model(args.model)
    rec, v_in, accel = load_io(args.recording, args.columns)
    if not same_rate(rec.fs, model.fs):
        raise UserError(
            f"{args.recording}: fs = {rec.fs:g} Hz but the model has fs = {model.fs:g} Hz"
        )
    model.extra.pop("baseline", None)  # a new baseline replaces the old one
    monitor = Monitor(model)
    pipeline = monitor.pipeline
    batch = pipeline.run(v_in, accel, position=monitor.position_column(rec))
    quantities = {"coulomb": pipeline.thetas(batch)[0], "level": pipeline.levels(batch)}
    try:
        bins = fit_baseline(quantities, batch.v_rms, model.fs, args.min_seconds, args.max_bins)
    except ValueError as exc:
        raise UserError(f"{args.recording}: {exc}") from None
    valid_s = sum(b["seconds"] for b in bins)  # the windows where both are measured
    model.extra["baseline"] = {
        "bins": bins,
        "binned_by": "window velocity RMS (m/s)",
        "quantities": QUANTITIES,
        "provenance": {
            **provenance.source_entry(args.recording, provenance.command_line("baseline", args)),
            "samples": int(len(v_in)),
            "valid_seconds": valid_s,
        },
    }
    # the fault-free recording replayed against its own baseline: it must stay silent
    events, _ = Monitor(model).run(rec)
    episodes = sum(e["kind"] == "fault_detected" for e in events)
    model.extra["baseline"]["provenance"]["alarm_episodes_on_source"] = int(episodes)
    save_model(args.output, model)
    print(
        f"baseline          : {len(bins)} bin(s) of the window velocity RMS, "
        f"{valid_s:.0f} s of valid windows"
    )
    for b in bins:
        lo, hi = b["v_rms_mps"]
        print(
            f"  v_rms {1000 * lo:7.1f} .. {1000 * hi:7.1f} mm/s: level {b['level_median']:+.3f}"
            f" (σ {b['level_sigma']:.3f}, 5-95 % {b['level_p5_p95'][0]:+.3f}.."
            f"{b['level_p5_p95'][1]:+.3f}), θ1 {b['coulomb_median']:+.3f} "
            f"(σ {b['coulomb_sigma']:.3f}), {b['seconds']:.0f} s"
        )
    print(f"check             : {episodes} alarm episode(s) replaying the source against it")
    print(f"model written     : {args.output}")
    return 0
