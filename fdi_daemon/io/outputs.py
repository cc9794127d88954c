"""Writing what a command produces: PNG figures and JSON reports, with one-line errors."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from fdi_daemon.errors import UserError


def pyplot():
    """matplotlib.pyplot on the Agg backend (files only, no screen needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path: str | Path, dpi: int = 110) -> Path:
    """Write ``fig`` as PNG and close it; an unwritable path is a UserError."""
    path = Path(path)
    try:
        fig.savefig(path, dpi=dpi)
    except OSError as exc:
        raise UserError(f"{path}: cannot write the plot: {exc.strerror or exc}") from None
    finally:
        pyplot().close(fig)
    return path


def write_json(path: str | Path, data: Any, indent: int = 2) -> Path:
    """Write ``data`` as JSON text ending in a newline; an unwritable path is a UserError."""
    path = Path(path)
    try:
        with open(path, "w", encoding="utf-8") as fh:
            json.dump(data, fh, indent=indent)
            fh.write("\n")
    except OSError as exc:
        raise UserError(f"{path}: cannot write: {exc.strerror or exc}") from None
    return path
