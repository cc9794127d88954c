"""`fdi bench`: speed of the monitor against plain baselines, of the simulator and of the
identification; a table on screen and JSON."""

from __future__ import annotations

import argparse

HELP = "measure the monitor (per tick, batch, against baselines), the simulator and identification"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", metavar="FILE", help="also write the numbers as JSON")
    parser.add_argument(
        "--quick", action="store_true", help="smaller samples (a rough figure in a few seconds)"
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

    from fdi_daemon.bench.ident import bench_ident
    from fdi_daemon.bench.monitor import bench_monitor
    from fdi_daemon.bench.sim import bench_sim
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
    with console.status("monitor: per-tick step, batch replay and baselines ..."):
        results["monitor"] = (
            bench_monitor(
                step_samples=5_000, batch_samples=200_000, baseline_samples=1_500, incident_s=300.0
            )
            if args.quick
            else bench_monitor()
        )
    with console.status("simulator ..."):
        results["sim"] = bench_sim(duration_s=30.0) if args.quick else bench_sim()
    with console.status("identification ..."):
        results["ident"] = bench_ident(repeats=1 if args.quick else 3)
    with console.status("replay of files (1 s, an hour as CSV and Parquet, a day) ..."):
        from fdi_daemon.bench.e2e import default_model_path
        from fdi_daemon.bench.replay import bench_replay

        replay = bench_replay(
            default_model_path(),
            results["monitor"]["batch_samples_per_s"],
            **({"base_s": 20.0, "repeats": 1, "day": False} if args.quick else {}),
        )
        results["archive"] = {"bytes_per_rig_hour": replay.pop("archive_bytes_per_rig_hour")}
        results["replay"] = replay
    if not args.skip_e2e:
        from fdi_daemon.bench.e2e import bench_e2e

        with console.status("daemon end to end: fdi sim serve + fdi run ..."):
            results["e2e"] = bench_e2e(quick=args.quick)
    console.print(_monitor_table(results["monitor"]))
    console.print(_reference_table(results["monitor"]))
    console.print(_sim_table(results["sim"]))
    console.print(_ident_table(results["ident"]))
    console.print(_replay_table(results["replay"], results["archive"]))
    if "e2e" in results:
        from fdi_daemon.bench.e2e import e2e_table

        console.print(e2e_table(results["e2e"]))
    if args.json:
        write_json(args.json, results)
    return 0


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
    for fmt, share in (("csv", 0.2), ("parquet", 0.4)):
        table.add_row(
            f"hour from {fmt}: marginal rate",
            f"{r[f'hour_{fmt}_samples_per_s'] / 1e6:.2f} M/s = "
            f"{r[f'share_of_batch_{fmt}']:.0%} of batch",
            f"≥ {share:.0%}",
        )
    table.add_row("archive per rig-hour", f"{archive['bytes_per_rig_hour'] / 1e6:.1f} MB", "≤ 8 MB")
    if "day_peak_rss_mib" in r:
        table.add_row("day replay peak RSS", f"{r['day_peak_rss_mib']:.0f} MiB", "≤ 300 MiB")
    table.add_row(
        "load average (1, 5, 15 min)", ", ".join(f"{x:.1f}" for x in r["load_average"]), ""
    )
    return table
