"""The daemon's state file: what must survive a restart or a reload (the alarm, counters).

One JSON object, ``{"format": "fdi-state", "version": 1, "model": <model identity>,
"written": unix s, "alarm": AlarmLifecycle.to_dict(), "event_counts": {kind: n}}``.

Written atomically (a temporary file in the same folder, flush, fsync, rename over the old
one, fsync the folder): after a crash or a power loss the file is the old or the new
version, never a mix. Read back only when it is whole and was written for the same model:
a corrupt file, or one whose ``model`` differs, is refused with one log line and moved
aside (``state.json.refused``), and the daemon starts fresh.

The model identity is the SHA-256 of the parts of the model that give the friction level
its unit (``fs``, ``plant``, ``fault_filter``; canonical JSON): editing detector settings,
the provenance or a baseline keeps an alarm, a new identification or signature does not.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
from pathlib import Path
from typing import Any

from fdi_daemon.io.model_file import FdiModel

__all__ = ["model_identity", "write_state", "read_state", "STATE_FORMAT", "STATE_VERSION"]

log = logging.getLogger("fdi.state")
STATE_FORMAT = "fdi-state"
STATE_VERSION = 1


def model_identity(model: FdiModel) -> str:
    """SHA-256 (hex) of the model's fs, plant and fault filter (see the module doc)."""
    data = model.to_dict()
    core = {key: data.get(key) for key in ("fs", "plant", "fault_filter")}
    text = json.dumps(core, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def write_state(path: str | Path, state: dict[str, Any]) -> None:
    """Write ``state`` (plus format and version) atomically; OSError if the disk fails."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    text = json.dumps(
        {"format": STATE_FORMAT, "version": STATE_VERSION, **state},
        allow_nan=False,
        separators=(",", ":"),
    )
    tmp = path.with_name(f".{path.name}.tmp")
    with open(tmp, "w", encoding="utf-8") as fh:
        fh.write(text + "\n")
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)
    fd = os.open(path.parent, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def read_state(path: str | Path, model: str) -> dict[str, Any] | None:
    """The stored state if it is whole and for ``model`` (identity), else None (logged)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        return None
    except OSError as exc:
        log.error(
            "state file %s: cannot read it (%s); starting with a fresh state",
            path,
            exc.strerror or exc,
        )
        return None
    try:
        data = json.loads(text)
        if not isinstance(data, dict) or data.get("format") != STATE_FORMAT:
            raise ValueError("not an fdi state file")
        if data.get("version") != STATE_VERSION:
            raise ValueError(f"version {data.get('version')!r}, expected {STATE_VERSION}")
    except ValueError as exc:  # json.JSONDecodeError is a ValueError
        _refuse(path, f"corrupt ({exc})")
        return None
    if data.get("model") != model:
        _refuse(path, "written for another model (fs, plant or fault filter differ)")
        return None
    return data


def _refuse(path: Path, why: str) -> None:
    aside = path.with_name(path.name + ".refused")
    try:
        os.replace(path, aside)
    except OSError:
        aside = path
    log.warning(
        "state file %s %s: refused, starting with a fresh state (kept as %s)", path, why, aside.name
    )
    return None
