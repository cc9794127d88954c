"""Provenance of an identified model: which file, when, by which command."""

from __future__ import annotations

import hashlib
import shlex
from datetime import datetime, timezone
from pathlib import Path


def file_sha256(path: str | Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def utc_now_iso() -> str:
    return datetime.now(timezone.utc).replace(microsecond=0).isoformat()


def source_entry(path: str | Path, command: list[str]) -> dict:
    """{source, source_sha256, date_utc, command} for a model's provenance."""
    return {
        "source": str(path),
        "source_sha256": file_sha256(path),
        "date_utc": utc_now_iso(),
        "command": " ".join(shlex.quote(part) for part in command),
    }


def command_line(command: str, args, positional: tuple[str, ...] = ("recording",)) -> list[str]:
    """The command as it could be retyped: positionals, then every option that is set."""
    values = {k: v for k, v in vars(args).items() if k not in ("command", "_run")}
    parts = ["fdi", command] + [str(values.pop(name)) for name in positional]
    for key, value in values.items():
        if value is None or value is False:
            continue
        flag = "--" + key.replace("_", "-")
        parts += [flag] if value is True else [flag, str(value)]
    return parts
