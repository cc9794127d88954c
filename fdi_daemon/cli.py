"""The `fdi` command line: one subcommand per job.

Each subcommand lives in `fdi_daemon/commands/<name>.py` and provides
``HELP`` (one line), ``configure(parser)`` and ``run(args) -> int``. Command modules keep
heavy imports inside ``run`` so that ``fdi --help`` stays fast.
"""

from __future__ import annotations

import argparse
import importlib
import os
import re
import signal
import sys
import threading

from fdi_daemon import __version__
from fdi_daemon.errors import UserError

#: subcommand name -> module under fdi_daemon.commands
COMMANDS: dict[str, str] = {
    "run": "run",
    "identify": "identify",
    "signature": "signature",
    "dashboard": "dashboard",
    "sim": "sim",
    "diagnose": "diagnose",
    "replay": "replay",
    "fleet-replay": "fleet_replay",
    "bench": "bench",
    "trend": "trend",
    "baseline": "baseline",
    "service": "service",
    "alarm": "alarm",
    "convert": "convert",
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="fdi",
        description="On-line Coulomb/viscous friction fault detection and isolation.",
    )
    parser.add_argument("--version", action="version", version=f"fdi {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name, module_name in COMMANDS.items():
        module = importlib.import_module(f"fdi_daemon.commands.{module_name}")
        p = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.configure(p)
        p.set_defaults(_run=module.run)
    return parser


#: a value that starts with a minus sign and a digit: a negative number, range or list
_NEGATIVE_VALUE = re.compile(r"^-\.?\d")


def attach_negative_values(argv: list[str]) -> list[str]:
    """``--option -5:10`` as ``--option=-5:10``: argparse takes a token that starts with a
    minus sign for an option unless it is a plain negative number, so a range like
    ``--fault-window -5:10`` would be "expected one argument"."""
    out: list[str] = []
    for token in argv:
        if out and out[-1].startswith("--") and "=" not in out[-1] and _NEGATIVE_VALUE.match(token):
            out[-1] = f"{out[-1]}={token}"
        else:
            out.append(token)
    return out


class Terminated(Exception):
    """SIGTERM during a command: raised in the main thread so that the command unwinds as
    on Ctrl-C, stopping the processes it started and closing its files (Python's default
    for SIGTERM ends the process at once and leaves its children running)."""


#: seconds after which a SIGTERM that came during an import is delivered again
TERMINATE_RETRY_S = 0.05


def _deliver_again(signum) -> None:
    """Send ``signum`` to this process again in TERMINATE_RETRY_S."""
    threading.Timer(TERMINATE_RETRY_S, os.kill, (os.getpid(), signum)).start()


def _terminate(signum, frame):
    """Raise `Terminated`, except inside the import machinery: an exception raised there
    breaks the module being imported (numpy prints its own traceback and fails with
    "numpy._core.multiarray failed to import"). There the signal is sent again a moment
    later, once the import is done."""
    while frame is not None:
        if frame.f_code.co_filename.startswith("<frozen importlib"):
            _deliver_again(signum)
            return
        frame = frame.f_back
    raise Terminated


def _unraisable_terminated(hook):
    """``hook`` (a `sys.unraisablehook`), except for a `Terminated` that could not
    propagate: raised where Python drops exceptions (a ctypes callback, such as llvmlite's
    object cache while numba compiles; a ``__del__``), it printed a traceback and the
    signal was lost. It is not printed, and the signal is sent again a moment later."""

    def handle(unraisable):
        if isinstance(unraisable.exc_value, Terminated):
            _deliver_again(signal.SIGTERM)
            return
        hook(unraisable)

    return handle


def _on_sigterm(handler):
    """Install ``handler`` for SIGTERM (main thread only); returns the one it replaces.
    Commands with their own handling (`fdi run`, `fdi sim serve`) install theirs over it."""
    if threading.current_thread() is not threading.main_thread():
        return None
    return signal.signal(signal.SIGTERM, handler)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(attach_negative_values(sys.argv[1:] if argv is None else argv))
    previous = _on_sigterm(_terminate)
    previous_hook = sys.unraisablehook
    if previous is not None:
        sys.unraisablehook = _unraisable_terminated(previous_hook)
    try:
        return int(args._run(args) or 0)
    except UserError as exc:
        print(f"fdi {args.command}: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print(f"fdi {args.command}: interrupted", file=sys.stderr)
        return 130
    except Terminated:
        print(f"fdi {args.command}: terminated", file=sys.stderr)
        return 128 + signal.SIGTERM
    except BrokenPipeError:
        return 0
    finally:
        if previous is not None:
            _on_sigterm(previous)
            sys.unraisablehook = previous_hook


if __name__ == "__main__":
    sys.exit(main())
