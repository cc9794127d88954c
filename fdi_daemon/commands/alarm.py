"""`fdi alarm list|ack|shelve|unshelve`: the alarm lifecycle's operator requests over a
running daemon's status socket (who, when and why land in its event log)."""

from __future__ import annotations

import argparse

from fdi_daemon.errors import UserError

HELP = (
    "show, acknowledge, shelve or unshelve a running daemon's alarm "
    "(over its status socket; the daemon logs who and why)"
)


def duration_s(text: str) -> float:
    """``90``, ``90s``, ``30m``, ``8h``, ``1d`` as seconds (> 0), for argparse."""
    from fdi_daemon.dashboard.operator import parse_duration

    try:
        return parse_duration(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("action", choices=["list", "ack", "shelve", "unshelve"])
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--connect", metavar="SOCKET", help="the daemon's status socket")
    where.add_argument(
        "--state-dir",
        metavar="DIR",
        help="the state folder of the daemon (`fdi run --state-dir`); its status socket",
    )
    parser.add_argument(
        "--config", metavar="RIG.yaml", help="take the status socket path from this rig config"
    )
    parser.add_argument(
        "--by", metavar="WHO", default=None, help="who asks (default: your login name)"
    )
    parser.add_argument("--reason", metavar="WHY", default="", help="why (kept in the event log)")
    parser.add_argument(
        "--for",
        dest="duration_s",
        type=duration_s,
        metavar="DURATION",
        help="shelve for this long: 90s, 30m, 8h (ISA-18.2: shelving always ends; at most "
        "alarms.max_shelve_s)",
    )


def socket_path(args: argparse.Namespace) -> str:
    if args.connect:
        return str(args.connect)
    from fdi_daemon.service.config import load_config

    config = load_config(args.config)
    if args.state_dir is not None:
        config.service["state_dir"] = str(args.state_dir)
    path = config.output_path(config.sinks["status_socket"])
    if path is None:
        raise UserError(f"{config.source}: sinks.status_socket is null: no socket to ask")
    return str(path)


def run(args: argparse.Namespace) -> int:
    from fdi_daemon.dashboard.client import DaemonUnreachable, StatusConnection
    from fdi_daemon.dashboard.operator import alarm_line, alarm_request, outcome, requester

    if args.action == "shelve" and args.duration_s is None:
        raise UserError("shelve needs --for DURATION (e.g. --for 30m)")
    if args.action != "shelve" and args.duration_s is not None:
        raise UserError(f"--for is for shelve only, not {args.action}")
    path = socket_path(args)
    who = requester(args.by)
    try:
        with StatusConnection(path, timeout_s=5.0) as connection:
            if args.action == "list":
                print(alarm_line(connection.request().get("alarm") or {}))
                return 0
            answer = connection.ask(alarm_request(args.action, who, args.reason, args.duration_s))
    except DaemonUnreachable as exc:
        raise UserError(
            f"no daemon answers on the status socket {path} ({exc}); is `fdi run` running?"
        ) from None
    ok, line = outcome(args.action, who, answer)
    if not ok:
        raise UserError(line)
    print(line)
    return 0
