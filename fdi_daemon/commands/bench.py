"""`fdi bench`: speed of the monitor against plain baselines, of the simulator and of the
identification; a table on screen and JSON."""

from __future__ import annotations

import argparse
from typing import Any

HELP = "measure the monitor (per tick, batch, against baselines), the simulator and identification"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", metavar="FILE", help="also write the numbers as JSON")
    parser.add_argument(
        "--quick",
        action="store_true",
        help="a rough figure of every number in well under a minute (20 s measured on a "
        "2-core machine busy with other work, load 5; the first run after installing or "
        "upgrading also compiles the kernels, 1-3 min more): the monitor per tick on 5 000 samples and in batch on 200 000, "
        "the simulator on 30 s, identification once, replay of a 10-minute file (rates "
        "scaled to an hour), no 24 h memory peak and no daemon end to end unless --e2e; "
        "same JSON keys as the full run. Each stage's table is printed when it is measured, "
        "progress on stderr",
    )
    parser.add_argument(
        "--e2e",
        action="store_true",
        help="with --quick: also the daemon end to end (fdi sim serve + fdi run, minutes)",
    )
    parser.add_argument(
        "--skip-e2e",
        action="store_true",
        help="leave out the daemon end to end (latency, CPU, memory; runs "
        "fdi sim serve + fdi run for a few minutes)",
    )


def run(args: argparse.Namespace) -> int:
    import platform
    import time

    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from fdi_daemon.errors import UserError
    from fdi_daemon.io.outputs import check_outputs, write_json

    check_outputs({"--json": args.json})  # it failed after minutes of measuring
    console = Console()
    results: dict = {
        "machine": {
            "python": platform.python_version(),
            "processor": platform.processor() or platform.machine(),
            "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        }
    }
    stages = [
        ("monitor: per-tick step, batch replay and baselines", "monitor"),
        ("simulator", "sim"),
        ("identification", "ident"),
        ("replay of files (1 s, an hour as CSV and Parquet, a day)", "replay"),
    ]
    if args.e2e and args.skip_e2e:
        raise UserError("--e2e and --skip-e2e contradict each other")
    if args.e2e and not args.quick:
        raise UserError("--e2e is for --quick (the full run includes it unless --skip-e2e)")
    skipped = (
        "--skip-e2e"
        if args.skip_e2e
        else "--quick without --e2e"
        if args.quick and not args.e2e
        else None
    )
    if skipped is None:
        stages.append(("daemon end to end: fdi sim serve + fdi run", "e2e"))
    # progress on stderr (which stage, how long so far); each table as soon as it is measured
    progress = Progress(
        TextColumn("bench {task.completed:.0f}/{task.total:.0f}: {task.description}"),
        BarColumn(),
        TimeElapsedColumn(),
        console=Console(stderr=True),
        transient=True,
    )
    with progress:
        task = progress.add_task(stages[0][0], total=len(stages))
        for description, key in stages:
            progress.update(task, description=description + " ...")
            results[key] = _measure(key, args.quick, results)
            for table in _tables(key, results):
                console.print(table)
            progress.advance(task)
    if skipped is not None:  # the key stays, saying why it has no figures
        results["e2e"] = {"skipped": f"left out ({skipped})"}
    if args.json:
        write_json(args.json, results)
    return 0


def _measure(key: str, quick: bool, results: dict) -> dict:
    """One stage's figures (``--quick``: smaller samples); the replay stage reads the monitor's
    batch rate from ``results`` and adds the archive's figures to it."""
    if key == "monitor":
        from fdi_daemon.bench.monitor import bench_monitor

        if quick:
            return bench_monitor(
                step_samples=5_000, batch_samples=200_000, baseline_samples=1_500, incident_s=300.0
            )
        return bench_monitor()
    if key == "sim":
        from fdi_daemon.bench.sim import bench_sim

        return bench_sim(duration_s=30.0) if quick else bench_sim()
    if key == "ident":
        from fdi_daemon.bench.ident import bench_ident

        return bench_ident(repeats=1 if quick else 3)
    if key == "replay":
        from fdi_daemon.bench.e2e import default_model_path
        from fdi_daemon.bench.replay import bench_replay

        short: dict[str, Any] = (
            {"base_s": 20.0, "repeats": 1, "day": False, "span_s": 600.0, "warm_up": False}
            if quick
            else {}
        )
        replay = bench_replay(
            default_model_path(), results["monitor"]["batch_samples_per_s"], **short
        )
        results["archive"] = {"bytes_per_rig_hour": replay.pop("archive_bytes_per_rig_hour")}
        return replay
    from fdi_daemon.bench.e2e import bench_e2e

    return bench_e2e(quick=quick)


def _tables(key: str, results: dict) -> list:
    """The tables of one stage."""
    if key == "monitor":
        return [_monitor_table(results["monitor"]), _reference_table(results["monitor"])]
    if key == "sim":
        return [_sim_table(results["sim"])]
    if key == "ident":
        return [_ident_table(results["ident"])]
    if key == "replay":
        return [_replay_table(results["replay"], results["archive"])]
    from fdi_daemon.bench.e2e import e2e_table

    return [e2e_table(results["e2e"])]


def _monitor_table(m: dict):
    from rich.table import Table

    table = Table(title=f"monitor (256 Hz tick budget: {m['tick_budget_us']:.0f} µs)")
    for col in ("measure", "fdi", "baseline", "ratio", "target"):
        table.add_column(col, justify="right" if col != "measure" else "left")
    s, b = m["step_us"], m["baseline_step_us"]
    table.add_row(
        "per-tick step p50 (µs)",
        f"{s['p50']:.1f}",
        f"{b['p50']:.1f}",
        f"{m['step_speedup_p50']:.1f}x",
        f"<= {m['targets']['step_p50_us']:.0f}",
    )
    table.add_row(
        "per-tick step p99 (µs)",
        f"{s['p99']:.1f}",
        f"{b['p99']:.1f}",
        f"{b['p99'] / s['p99']:.1f}x",
        "",
    )
    table.add_row("per-tick step max (µs)", f"{s['max']:.1f}", f"{b['max']:.1f}", "", "")
    table.add_row(
        "per-tick step CPU p50 (µs)",
        f"{m['step_cpu_us_p50']:.1f}",
        f"{m['baseline_step_cpu_us_p50']:.1f}",
        f"{m['baseline_step_cpu_us_p50'] / m['step_cpu_us_p50']:.1f}x",
        "",
    )
    table.add_row(
        "batch replay (samples/s)",
        f"{m['batch_samples_per_s']:,.0f}",
        f"{m['baseline_samples_per_s']:,.0f}",
        f"{m['batch_speedup']:.0f}x",
        f">= {m['targets']['batch_samples_per_s']:,.0f}",
    )
    table.add_row(
        "batch replay CPU (samples/CPU-s)", f"{m['batch_samples_per_cpu_s']:,.0f}", "", "", ""
    )
    return table


def _reference_table(m: dict):
    """The monitor against the compiled chain without detector, and incident replay."""
    from rich.table import Table

    tg = m["targets"]
    table = Table(title="monitor against the compiled chain without detector (CPU time)")
    for col in ("measure", "fdi", "reference", "ratio", "target"):
        table.add_column(col, justify="right" if col != "measure" else "left")
    table.add_row(
        "per-tick CPU p50 (µs)",
        f"{m['step_cpu_us_p50']:.1f}",
        f"{m['reference_step_cpu_us_p50']:.1f}",
        f"{m['step_cpu_over_reference']:.1f}x",
        f"<= {tg['step_cpu_over_reference_max']:g}x",
    )
    table.add_row(
        f"batch (samples/CPU-s; median of {len(m['batch_cpu_share_by_pair'])} side-by-side passes)",
        f"{m['batch_samples_per_cpu_s']:,.0f}",
        f"{m['reference_samples_per_cpu_s']:,.0f}",
        f"{m['batch_cpu_share_of_reference']:.2f}",
        f">= {tg['batch_cpu_share_of_reference_min']:g}",
    )
    if "incident_replay" in m:
        table.add_row(
            "incident replay (samples/CPU-s; ref: quiet)",
            f"{m['incident_replay_samples_per_cpu_s']:,.0f}",
            f"{m['quiet_replay_samples_per_cpu_s']:,.0f}",
            f"{m['incident_over_quiet_cpu']:.2f}",
            f">= {tg['incident_over_quiet_cpu_min']:g}",
        )
    return table


def _sim_table(sim: dict):
    from rich.table import Table

    table = Table(title="simulated rig")
    table.add_column("measure")
    table.add_column("value", justify="right")
    table.add_row("simulated s per wall s", f"{sim['sim_s_per_wall_s']:.1f}")
    table.add_row("one simulated hour (wall s)", f"{sim['hour_wall_s']:.1f}")
    table.add_row("bare kernel (simulated s per wall s)", f"{sim['kernel_sim_s_per_wall_s']:.1f}")
    table.add_row("numba JIT", str(sim["jit"]))
    return table


def _ident_table(ident: dict):
    from rich.table import Table

    table = Table(title="identification")
    table.add_column("measure")
    table.add_column("value", justify="right")
    table.add_column("target", justify="right")
    table.add_row(
        "identify, 1024 samples (s)",
        f"{ident['identify_1024_samples_s']:.2f}",
        f"< {ident['identify_target_s']:g}",
    )
    table.add_row(
        f"signature grid, {ident['signature_grid_points']} points (s)",
        f"{ident['signature_grid_1024_samples_s']:.2f}",
        f"< {ident['signature_target_s']:g}",
    )
    return table


def _replay_table(r: dict, archive: dict):
    from rich.table import Table

    table = Table(title="fdi replay of files (best wall time, fresh process)")
    for col in ("measure", "value", "target"):
        table.add_column(col, justify="right" if col != "measure" else "left")
    table.add_row(
        "fixed cost: 1 s recording",
        f"{r['fixed_cost_s']:.2f} s = {r['fixed_cost_ratio']:.2f}x import numpy+scipy.signal+yaml",
        "≤ 1.4x",
    )
    timed = "hour" if r.get("span_s", 3600.0) >= 3600.0 else f"{r['span_s'] / 60:g} min"
    for fmt, share in (("csv", 0.2), ("parquet", 0.4)):
        rate = r[f"hour_{fmt}_samples_per_s"]
        table.add_row(
            f"{timed} from {fmt}: marginal rate",
            "within the timing noise (run without --quick)"
            if rate is None
            else f"{rate / 1e6:.2f} M/s = {r[f'share_of_batch_{fmt}']:.0%} of batch",
            f"≥ {share:.0%}",
        )
    table.add_row("archive per rig-hour", f"{archive['bytes_per_rig_hour'] / 1e6:.1f} MB", "≤ 8 MB")
    if "day_peak_rss_mib" in r:
        table.add_row("day replay peak RSS", f"{r['day_peak_rss_mib']:.0f} MiB", "≤ 300 MiB")
    table.add_row(
        "load average (1, 5, 15 min)", ", ".join(f"{x:.1f}" for x in r["load_average"]), ""
    )
    return table
