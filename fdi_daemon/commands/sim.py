"""`fdi sim`: the simulated servo-pneumatic rig (hil_sim) as a recording generator.

Sub-subcommands: ``record`` (scenario YAML -> recording with ground truth) and ``serve``
(the rig as a fake DAQ device: Modbus TCP, Modbus RTU on a pty, serial frames on a pty).
"""

from __future__ import annotations

import argparse
import math

HELP = "the simulated pneumatic rig: record scenarios to recordings, serve it as a device"

#: simulated seconds above which `record` shows a progress bar
PROGRESS_MIN_S = 120.0


def configure(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="sim_command", metavar="SUBCOMMAND")
    sub.required = True
    rec = sub.add_parser(
        "record",
        help="simulate a scenario and write a recording (with ground truth)",
        description="Simulate a scenario (configs/scenarios/*.yaml) on the nonlinear rig and "
        "write a recording: t, v_in, accel, position, seq plus ground-truth "
        "columns (friction_force, seal_friction_force, fault_active, ...).",
    )
    rec.add_argument("scenario", metavar="SCENARIO.yaml", help="scenario file")
    rec.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="REC",
        help="recording to write (.csv, .csv.gz, .npz, .mat or .parquet)",
    )
    rec.add_argument(
        "--seed",
        type=int,
        default=None,
        help="seed of rig noise and random excitation (default: the scenario's)",
    )
    rec.add_argument(
        "--duration",
        type=float,
        default=None,
        metavar="S",
        help="simulated seconds (default: the scenario's duration_s)",
    )
    rec.add_argument("--quiet", action="store_true", help="no progress bar or summary line")
    rec.set_defaults(_sim_run=run_record)
    configure_serve(sub)


def run(args: argparse.Namespace) -> int:
    return args._sim_run(args)


def run_record(args: argparse.Namespace) -> int:
    import sys
    import time

    from fdi_daemon.errors import UserError
    from fdi_daemon.io.outputs import check_outputs
    from fdi_daemon.io.recordings import check_format, write_recording
    from hil_sim.scenarios import load_scenario, simulate

    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise UserError(f"--duration must be a positive number of seconds, got {args.duration}")
    if args.seed is not None and args.seed < 0:
        raise UserError(f"--seed must be >= 0, got {args.seed}")
    scenario = load_scenario(args.scenario)
    check_outputs({"-o": args.output}, (args.scenario,))  # before a long simulation
    check_format(args.output)
    duration = scenario.duration_s if args.duration is None else args.duration
    start = time.perf_counter()
    if args.quiet or duration < PROGRESS_MIN_S:
        recording = simulate(scenario, seed=args.seed, duration_s=args.duration)
    else:
        from rich.progress import (
            BarColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

        with Progress(
            TextColumn(f"simulating {scenario.name}"),
            BarColumn(),
            TextColumn("{task.percentage:>3.0f}%"),
            TimeElapsedColumn(),
            TimeRemainingColumn(),
            transient=True,
        ) as bar:
            task = bar.add_task("sim", total=1.0)
            recording = simulate(
                scenario,
                seed=args.seed,
                duration_s=args.duration,
                progress=lambda done, total: bar.update(task, completed=done / total),
            )
    wall = time.perf_counter() - start
    path = write_recording(args.output, recording)
    if not args.quiet:
        print(
            f"wrote {path}: {len(recording)} samples, {duration:g} s simulated in "
            f"{wall:.2f} s ({duration / max(wall, 1e-9):.0f}x real time), "
            f"seed {recording.meta['seed']}",
            file=sys.stderr,
        )
    return 0


def configure_serve(sub) -> None:
    srv = sub.add_parser(
        "serve",
        help="serve the rig in real time as a Modbus or serial device",
        description="Run the simulated rig at 256 Hz and serve it as a DAQ device (protocols: "
        "docs/protocols.md). The first stdout line says where to connect "
        "(HOST:PORT or the pty path); then JSON-lines commands on stdin change "
        "faults, e.g. {\"set\": {\"bearing_supply\": 0.35}}. Serves until "
        "SIGTERM or SIGINT.",
    )
    how = srv.add_mutually_exclusive_group(required=True)
    how.add_argument(
        "--modbus-tcp", metavar="HOST:PORT", help="Modbus TCP server (port 0 picks a free port)"
    )
    how.add_argument("--modbus-rtu", action="store_true", help="Modbus RTU on a new pty")
    how.add_argument("--serial", action="store_true", help="binary frames on a new pty")
    srv.add_argument(
        "--scenario",
        metavar="FILE",
        default=None,
        help="scenario YAML (default: 1.4 V 8 Hz sine, the paper's case 1)",
    )
    srv.add_argument("--seed", type=int, default=None, help="rig noise seed")
    srv.add_argument(
        "--link",
        metavar="PATH",
        default=None,
        help="also keep a symlink PATH to the pty (stable across restarts)",
    )
    srv.add_argument("--device-id", type=int, default=1, help="Modbus device id (default 1)")
    srv.add_argument(
        "--word-order",
        choices=("big", "little"),
        default="big",
        help="word order of 32-bit values (default big)",
    )
    srv.add_argument(
        "--fifo-depth", type=int, default=256, help="samples kept in the Modbus FIFO (default 256)"
    )
    srv.set_defaults(_sim_run=run_serve)


def run_serve(args: argparse.Namespace) -> int:
    import sys

    from fdi_daemon.errors import UserError
    from fdi_daemon.io.outputs import check_outputs
    from hil_sim.devices import SimulatedDevice, realtime_rig
    from hil_sim.devices.serve import parse_host_port, serve_until_signalled

    if args.seed is not None and args.seed < 0:
        raise UserError(f"--seed must be >= 0, got {args.seed}")
    check_outputs({"--link": args.link})
    host, port = "127.0.0.1", 0
    if args.modbus_tcp is not None:
        try:
            host, port = parse_host_port(args.modbus_tcp)
        except ValueError as exc:
            raise UserError(f"--modbus-tcp: {exc}") from None
    transport = "modbus-tcp" if args.modbus_tcp else "modbus-rtu" if args.modbus_rtu else "serial"
    try:
        device = SimulatedDevice(
            transport,
            realtime_rig(args.scenario, seed=args.seed),
            host=host,
            port=port,
            link_path=args.link,
            device_id=args.device_id,
            word_order=args.word_order,
            fifo_depth=args.fifo_depth,
        )
        serve_until_signalled(device, sys.stdin, sys.stdout)
    except (ValueError, OSError, RuntimeError) as exc:
        raise UserError(f"cannot serve the {transport} device: {exc}") from None
    return 0
