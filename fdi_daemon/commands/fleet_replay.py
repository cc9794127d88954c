"""`fdi fleet-replay`: replay many recordings, each with its rig's model, on Dask."""

from __future__ import annotations

import argparse
import os
import sys
import time

HELP = "replay many recordings (each with its rig's model) on a Dask cluster: one row per file"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "recordings",
        metavar="DIR_OR_GLOB",
        help="a folder of recordings (.csv, .csv.gz, .npz, .mat, .parquet) or a glob "
        "pattern (quote it; ** recurses)",
    )
    which = parser.add_mutually_exclusive_group(required=True)
    which.add_argument("--model", metavar="MODEL.yaml", help="one model for every recording")
    which.add_argument(
        "--model-map",
        metavar="MAP.yaml",
        help="YAML mapping of file names or glob patterns to model files (docs/fleet.md)",
    )
    parser.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="address of a dask.distributed scheduler (e.g. tcp://host:8786); "
        "default: a local cluster on this machine (127.0.0.1 only)",
    )
    parser.add_argument(
        "--workers",
        type=int,
        metavar="N",
        help="worker processes of the local cluster (default: CPU count)",
    )
    parser.add_argument(
        "--progress",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="a progress bar over files and samples on stderr (default: when stderr is a terminal)",
    )
    parser.add_argument(
        "--out",
        metavar="RESULTS.csv|.parquet",
        help="write the table (.parquet needs pyarrow); default: print it",
    )


def run(args: argparse.Namespace) -> int:
    from fdi_daemon.errors import UserError
    from fdi_daemon.fleet.cluster import dask_client, replay_fleet, warm_workers
    from fdi_daemon.fleet.inputs import ModelMap, find_recordings
    from fdi_daemon.fleet.table import write_table
    from fdi_daemon.io.outputs import check_outputs

    if args.scheduler is not None and args.workers is not None:
        raise UserError("--workers sizes the local cluster; a --scheduler has its own workers")
    workers = (os.cpu_count() or 1) if args.workers is None else args.workers
    if workers < 1:
        raise UserError(f"--workers {workers}: needs at least 1")
    if args.out is not None and not args.out.lower().endswith((".csv", ".parquet")):
        raise UserError(f"--out {args.out}: the results table is written as .csv or .parquet")
    models = ModelMap.single(args.model) if args.model else ModelMap.load(args.model_map)
    files = find_recordings(args.recordings)
    check_outputs({"--out": args.out}, files)
    # absolute paths: a --scheduler's workers resolve a relative one in their own folder
    jobs = [(os.path.abspath(file), _absolute(models.model_for(file))) for file in files]

    shown = sys.stderr.isatty() if args.progress is None else args.progress
    progress, (files_task, samples_task) = _progress(len(jobs), shown)

    def on_row(row: dict) -> None:
        progress.advance(files_task)
        progress.advance(samples_task, row["samples"] or 0)

    started = time.monotonic()
    with dask_client(args.scheduler, workers) as client, progress:
        warm_workers(client)
        ready = time.monotonic()
        rows = replay_fleet(jobs, client, on_row=on_row)
        done = time.monotonic()
    if args.out is not None:
        write_table(args.out, rows)
    else:
        _print_table(rows)
    errors = sum(row["error"] is not None for row in rows)
    alarms = sum(bool(row["alarm_episodes"]) for row in rows)
    recorded_s = sum(row["samples"] / row["fs"] for row in rows if row["samples"])
    samples = sum(row["samples"] or 0 for row in rows)
    busy_s = max(done - ready, 1e-9)
    print(
        f"{len(rows)} recording(s): {alarms} with alarms, {errors} with errors"
        + (f"; table in {args.out}" if args.out else "")
    )
    print(
        f"{recorded_s:.0f} s of recordings replayed in {done - ready:.1f} s "
        f"({recorded_s / busy_s:.0f}x real time, {samples / busy_s / 1e6:.2f} M samples/s, "
        f"{len(rows) / busy_s:.1f} files/s) after "
        f"{ready - started:.1f} s to start (or reach) the cluster and load the kernels"
    )
    return 1 if rows and errors == len(rows) else 0


def _absolute(path: str | None) -> str | None:
    return None if path is None else os.path.abspath(path)


def _progress(total: int, shown: bool):
    """A transient bar on stderr with two rows: files (of ``total``) and samples replayed
    (their total is known as files finish); hidden unless ``shown``."""
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeRemainingColumn,
    )

    progress = Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeRemainingColumn(),
        console=Console(stderr=True),
        transient=True,
        disable=not shown,
    )
    files = progress.add_task("fleet replay: files", total=total)
    samples = progress.add_task("samples", total=None)
    return progress, (files, samples)


def _print_table(rows: list[dict]) -> None:
    from pathlib import Path

    from rich.console import Console
    from rich.table import Table

    table = Table(
        "file",
        "model",
        "samples",
        "episodes",
        "first detection s",
        "classification",
        "friction level",
        "gaps",
    )
    for row in rows:
        det, level = row["first_detection_t"], row["friction_level_final"]
        table.add_row(
            Path(row["file"]).name,
            Path(row["model"]).name if row["model"] else "-",
            _cell(row["samples"]),
            _cell(row["alarm_episodes"]),
            "-" if det is None else f"{det:.4f}",
            row["classification"] or "-",
            "-" if level is None else f"{level:.4g}",
            _cell(row["gaps"]),
        )
    # piped: as wide as the names need (a terminal's width would cut them)
    console = Console() if sys.stdout.isatty() else Console(width=100_000)
    console.print(table)
    for row in rows:
        if row["error"] is not None:
            console.print(f"error: {row['error']}", highlight=False, soft_wrap=True)


def _cell(value) -> str:
    return "-" if value is None else str(value)
