"""Column mapping: read recordings whose columns are named by another tool.

``--columns t=time,v_in=u,accel=y`` maps the recording contract's names (left) to the
file's column names (right). Every command that reads a recording takes the same option
(`add_columns_option`) and hands the parsed mapping to `read_recording(columns=...)`.
"""

from __future__ import annotations

import argparse

from fdi_daemon.errors import UserError

__all__ = ["add_columns_option", "columns_argument", "parse_columns"]

HELP = (
    "map the recording's column names to fdi's, e.g. t=time,v_in=u,accel=y "
    "(fdi name = file column; names not mapped are used as they are)"
)


def parse_columns(spec: str | None) -> dict[str, str]:
    """``"t=time,v_in=u"`` -> ``{"t": "time", "v_in": "u"}``; a malformed spec is a UserError."""
    if spec is None or not spec.strip():
        return {}
    mapping: dict[str, str] = {}
    for part in spec.split(","):
        name, sep, column = (s.strip() for s in part.partition("="))
        if not sep or not name or not column:
            raise UserError(
                f"--columns: {part.strip()!r} is not NAME=COLUMN (example: t=time,v_in=u,accel=y)"
            )
        if name in mapping:
            raise UserError(f"--columns: {name} is mapped twice")
        mapping[name] = column
    sources = list(mapping.values())
    twice = sorted({c for c in sources if sources.count(c) > 1})
    if twice:
        raise UserError(f"--columns: column {twice[0]!r} is mapped to more than one name")
    return mapping


def columns_argument(mapping: dict[str, str] | None) -> str:
    """The ``--columns`` option that gives ``mapping`` back (`parse_columns`' inverse), with
    a leading space, for a command line suggested to the user; empty when nothing is mapped."""
    if not mapping:
        return ""
    return " --columns " + ",".join(f"{name}={column}" for name, column in mapping.items())


def add_columns_option(parser: argparse.ArgumentParser) -> None:
    """The shared ``--columns`` option; its value arrives parsed (a dict) in ``args.columns``."""
    parser.add_argument("--columns", metavar="NAME=COL,...", type=_parse_arg, default={}, help=HELP)


def _parse_arg(spec: str) -> dict[str, str]:
    try:
        return parse_columns(spec)
    except UserError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("--columns: ")) from None
