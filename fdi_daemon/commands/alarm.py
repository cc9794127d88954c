"""`fdi alarm list|ack|shelve|unshelve`: the alarm lifecycle's operator requests over a
running daemon's status socket (who, when and why land in its event log)."""

from __future__ import annotations

import argparse
import re
import time
from typing import Any

from fdi_daemon.errors import UserError

HELP = (
    "show, acknowledge, shelve or unshelve a running daemon's alarm "
    "(over its status socket; the daemon logs who and why)"
)

#: ``--for`` units (seconds each)
_DURATION_UNITS = {"s": 1.0, "m": 60.0, "h": 3600.0, "d": 86400.0}
_DURATION = re.compile(r"^\s*(\d+(?:\.\d*)?|\.\d+)\s*([smhd]?)\s*$")

#: the socket's name for each action of the command line
_REQUESTS = {"ack": "acknowledge", "shelve": "shelve", "unshelve": "unshelve"}


def duration_s(text: str) -> float:
    """``90``, ``90s``, ``30m``, ``8h``, ``1d`` as seconds (> 0)."""
    match = _DURATION.match(text)
    if match is None or float(match.group(1)) <= 0:
        raise argparse.ArgumentTypeError(
            f"not a duration: {text!r} (a positive number with s, m, h or d, e.g. 30m)"
        )
    return float(match.group(1)) * _DURATION_UNITS[match.group(2) or "s"]


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


def alarm_line(alarm: dict[str, Any]) -> str:
    """The alarm section of a snapshot in one line."""
    if not alarm:
        return "alarm: none (this daemon keeps no alarm)"
    if alarm.get("state", "normal") == "normal" and not alarm.get("alarm_id"):
        return "alarm: normal (no alarm since the state began)"
    started = alarm.get("started")
    since = (
        time.strftime("%Y-%m-%d %H:%M:%S %z", time.localtime(started))
        if isinstance(started, (int, float))
        else "?"
    )
    text = (
        f"alarm #{alarm.get('alarm_id')}: {str(alarm.get('state')).replace('_', ' ')}, "
        f"P{alarm.get('priority')} (peak P{alarm.get('peak_priority')}), since {since}"
    )
    level = alarm.get("level")
    if isinstance(level, (int, float)):
        text += f", level {level:.3g} above the baseline"
    until = alarm.get("shelved_until")
    if isinstance(until, (int, float)) and until > time.time():
        text += f", shelved until {time.strftime('%H:%M:%S', time.localtime(until))}"
    return text


def run(args: argparse.Namespace) -> int:
    import getpass

    from fdi_daemon.dashboard.client import DaemonUnreachable, StatusConnection

    if args.action == "shelve" and args.duration_s is None:
        raise UserError("shelve needs --for DURATION (e.g. --for 30m)")
    if args.action != "shelve" and args.duration_s is not None:
        raise UserError(f"--for is for shelve only, not {args.action}")
    path = socket_path(args)
    who = args.by if args.by is not None else getpass.getuser()
    try:
        with StatusConnection(path, timeout_s=5.0) as connection:
            if args.action == "list":
                print(alarm_line(connection.request().get("alarm") or {}))
                return 0
            answer = connection.ask(
                {
                    "request": _REQUESTS[args.action],
                    "by": who,
                    "why": args.reason,
                    "duration_s": args.duration_s,
                }
            )
    except DaemonUnreachable as exc:
        raise UserError(
            f"no daemon answers on the status socket {path} ({exc}); is `fdi run` running?"
        ) from None
    if not answer.get("ok"):
        raise UserError(f"{args.action} refused: {answer.get('error')}")
    print(f"{answer.get('result')} by {who}; {alarm_line(answer.get('alarm') or {})}")
    return 0
