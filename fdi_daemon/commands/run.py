"""`fdi run`: the daemon next to the rig (link -> monitor -> alarms, status, recordings)."""

from __future__ import annotations

import argparse

HELP = "run the monitoring daemon (default: the built-in simulated rig with a friction fault)"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--config",
        metavar="RIG.yaml",
        help="rig config (default: the embedded simulated rig over a real "
        "Modbus TCP link, a friction fault after 20 s)",
    )
    parser.add_argument(
        "--duration",
        type=float,
        metavar="S",
        help="stop after S seconds of wall-clock time (default: run until SIGTERM or Ctrl-C)",
    )
    parser.add_argument(
        "--dashboard",
        action="store_true",
        help="show the live dashboard in this terminal (q, or the terminal "
        "going away, stops the daemon; what it prints meanwhile is kept "
        "in STATE_DIR/dashboard-output.log)",
    )
    parser.add_argument(
        "--state-dir",
        metavar="DIR",
        help="base of the relative output paths (event log, recordings, status "
        "socket); default: the config's service.state_dir, else "
        "$STATE_DIRECTORY under systemd, else $XDG_STATE_HOME/fdi "
        "(~/.local/state/fdi)",
    )
    parser.add_argument(
        "--log-level",
        choices=("debug", "info", "warning", "error"),
        default="info",
        help="daemon log level on stderr (default %(default)s)",
    )


def run(args: argparse.Namespace) -> int:
    import logging

    from fdi_daemon.errors import UserError
    from fdi_daemon.service.daemon import Daemon, setup_logging

    if args.duration is not None and not args.duration > 0:
        raise UserError(f"--duration must be a positive number of seconds (got {args.duration:g})")
    setup_logging(getattr(logging, args.log_level.upper()))
    daemon = Daemon(
        args.config,
        echo=lambda text: print(text, flush=True),
        state_dir=args.state_dir,
        hangup_stops=args.dashboard,
    )
    if args.dashboard:
        import signal

        from fdi_daemon.dashboard.app import Frame, run_alongside

        held = daemon.load_config().state_dir / "dashboard-output.log"
        # the daemon takes SIGHUP as "stop" while it runs; the kernel's second SIGHUP (the
        # terminal's session leader exiting) may come during the shutdown, when the
        # daemon's handlers are gone: it must not cut the shutdown short
        signal.signal(signal.SIGHUP, signal.SIG_IGN)
        return run_alongside(
            lambda: daemon.run(args.duration),
            lambda: Frame(daemon.board.snapshot()),
            held_output=held,
            request_stop=daemon.stop,
        )
    return daemon.run(args.duration)
