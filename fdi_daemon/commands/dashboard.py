"""`fdi dashboard`: the terminal dashboard attached to a running daemon's status socket."""

from __future__ import annotations

import argparse

from fdi_daemon.commands.alarm import duration_s
from fdi_daemon.errors import UserError

HELP = (
    "show a running daemon's live status (state, θ plots, link health, alarms); "
    "keys: a acknowledge, s shelve, u unshelve the alarm, q quit"
)


def _refresh_hz(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not 1.0 <= value <= 60.0:
        raise argparse.ArgumentTypeError("must be between 1 and 60 Hz")
    return value


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--connect",
        metavar="SOCKET",
        help="the daemon's status socket (default: the one `fdi run` uses "
        "with --config, or with its embedded default config)",
    )
    parser.add_argument(
        "--config", metavar="RIG.yaml", help="take the status socket path from this rig config"
    )
    parser.add_argument(
        "--refresh-hz",
        type=_refresh_hz,
        default=10.0,
        metavar="HZ",
        help="screen refresh rate (default 10)",
    )
    parser.add_argument(
        "--once",
        action="store_true",
        help="print one frame and exit (a text capture; size from --width/"
        "--height); no daemon: one line naming the socket, exit 2",
    )
    parser.add_argument(
        "--by",
        metavar="WHO",
        default=None,
        help="who acknowledges or shelves with the keys (default: your login name)",
    )
    parser.add_argument(
        "--shelve-for",
        type=duration_s,
        default=1800.0,
        metavar="DURATION",
        help="shelving offered by the s key when Enter is pressed at its 'how long' "
        "(default 30m; the daemon allows at most alarms.max_shelve_s)",
    )
    parser.add_argument("--width", type=int, default=None, help="frame width for --once")
    parser.add_argument("--height", type=int, default=None, help="frame height for --once")


def default_socket_path(config_path: str | None) -> str:
    """The status socket of `fdi run [--config config_path]` (sinks.status_socket)."""
    from fdi_daemon.service.config import load_config

    config = load_config(config_path)
    path = config.output_path(config.sinks["status_socket"])
    if path is None:
        raise UserError(
            f"{config.source}: sinks.status_socket is null (status socket "
            "disabled), so there is nothing to connect to"
        )
    return str(path)


def run(args: argparse.Namespace) -> int:
    from rich.console import Console

    from fdi_daemon.dashboard.app import run_dashboard
    from fdi_daemon.dashboard.client import SocketProvider
    from fdi_daemon.dashboard.operator import AlarmKeys, requester
    from fdi_daemon.dashboard.render import render

    path = args.connect or default_socket_path(args.config)
    provider = SocketProvider(path)
    try:
        if args.once:
            console = Console(width=args.width, height=args.height)
            frame = provider()
            if frame.snapshot is None:
                raise UserError(
                    f"no daemon answers on the status socket {path} "
                    f"({provider.last_error}); is `fdi run` running?"
                )
            console.print(render(frame.snapshot, frame.notice))
            return 0 if frame.notice is None else 1
        keys = AlarmKeys(provider.ask, requester(args.by), shelve_for_s=args.shelve_for)
        run_dashboard(provider, refresh_hz=args.refresh_hz, controls=keys)
        return 0
    finally:
        provider.close()
