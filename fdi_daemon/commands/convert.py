"""`fdi convert`: a recording from one format into another (CSV, .csv.gz, npz, mat, Parquet)."""

from __future__ import annotations

import argparse

from fdi_daemon.io.columns import add_columns_option

HELP = (
    "convert a recording between .csv, .csv.gz, .npz, .mat and .parquet "
    "(the same checks as every reader; gaps and duplicates are kept and reported)"
)


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("source", metavar="IN", help="recording to read")
    parser.add_argument("target", metavar="OUT", help="recording to write (format by its ending)")
    add_columns_option(parser)
    parser.add_argument(
        "--fs",
        type=float,
        metavar="HZ",
        help="sampling rate (Hz) of a recording without a time column: t = k / HZ is written",
    )


def run(args: argparse.Namespace) -> int:
    import sys

    from fdi_daemon.io.outputs import check_outputs
    from fdi_daemon.io.recordings import check_format, read_recording, write_recording

    check_format(args.target)
    check_outputs({"OUT": args.target}, {"IN": args.source})
    rec = read_recording(args.source, strict=False, columns=args.columns, fs_hz=args.fs)
    if "fs" not in rec.meta:  # the rate found is written, so the output says it
        rec.meta["fs"] = f"{rec.fs:.10g}"
    write_recording(args.target, rec)
    assert rec.sampling is not None
    if not rec.sampling.ok:
        print(f"{args.source}: kept as recorded: {rec.sampling.summary()}", file=sys.stderr)
    print(f"{args.target}: {len(rec)} samples at {rec.fs:g} Hz, columns {', '.join(rec.columns)}")
    return 0
