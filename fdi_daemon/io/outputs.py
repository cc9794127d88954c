"""Writing what a command produces: PNG figures and JSON reports, with one-line errors.

`check_outputs` vets a command's output paths before the work starts, `replaced_atomically`
writes a file so that a failed or interrupted write leaves the old one (or none) in place.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import stat
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

from fdi_daemon.errors import UserError


def pyplot() -> Any:
    """matplotlib.pyplot on the Agg backend (files only, no screen needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def check_outputs(
    outputs: Mapping[str, str | Path | None],
    inputs: Iterable[str | Path | None] | Mapping[str, str | Path | None] = (),
    plots: Iterable[str] = (),
    rewrites: Mapping[str, str | Path | None] | None = None,
    new_dirs: bool = False,
) -> None:
    """Refuse, before any work, output paths that cannot be written or would destroy an input.

    outputs: option -> path (None: not asked for); inputs: files the command reads (or a
    mapping name -> file, the name then said in the error); plots: the options of
    ``outputs`` that are figures (their ending must name a format matplotlib writes);
    rewrites: option -> the one input it may replace (``-o`` = ``--model``); new_dirs: the
    outputs' directories need not exist yet (their writer makes them). Each output's
    directory must exist, no output may be a directory, another input, or another output. A
    UserError names the option.
    """
    given = {option: Path(path) for option, path in outputs.items() if path is not None}
    named = inputs.items() if isinstance(inputs, Mapping) else ((None, p) for p in inputs)
    read = [(name, Path(path)) for name, path in named if path is not None]
    rewrites = rewrites or {}
    seen: dict[Path, str] = {}
    for option, path in given.items():
        if path.is_dir():
            raise UserError(f"{option} {path}: is a directory, not a file")
        if path.exists() and not path.is_file():
            continue  # a device, a pipe (/dev/null, /dev/stdout), a socket: never read back
        if not new_dirs and not path.resolve().parent.is_dir():
            raise UserError(
                f"{option} {path}: cannot write there: directory {path.parent} does not exist"
            )
        allowed = rewrites.get(option)
        for name, source in read:
            if same_file(path, source) and not (allowed and same_file(source, Path(allowed))):
                also = f" ({name})" if name else "" if str(source) == str(path) else f" ({source})"
                raise UserError(
                    f"{option} {path}: is also an input of this command{also}; "
                    f"writing it would destroy it"
                )
        key = path.resolve()
        if key in seen:
            raise UserError(f"{option} and {seen[key]} name the same file {path}")
        seen[key] = option
        if option in plots:
            _check_plot_format(path, option)


def same_file(a: Path, b: Path) -> bool:
    """Two paths name one file (the same path resolved, or hard links to one file)."""
    try:
        return a.resolve() == b.resolve() or (a.exists() and b.exists() and a.samefile(b))
    except OSError:
        return False


def _check_plot_format(path: Path, what: str) -> None:
    """A figure file's ending must name a format matplotlib can write (png, pdf, svg, ...)."""
    from matplotlib.backend_bases import FigureCanvasBase

    suffix = path.suffix.lower().lstrip(".")
    formats = FigureCanvasBase.get_supported_filetypes()
    if suffix and suffix not in formats:
        raise UserError(
            f"{what} {path}: cannot write a plot as .{suffix} (use e.g. .png, .pdf or .svg)"
        )


@contextlib.contextmanager
def replaced_atomically(path: str | Path) -> Iterator[Path]:
    """A temporary path next to ``path`` to write; renamed onto ``path`` when the block ends
    normally, removed when it raises (an error, Ctrl-C): a failed or interrupted write never
    leaves a truncated file nor spoils the one there before, whose permissions the new one
    keeps. A path that is there but no regular file (a device, a pipe) is written in place;
    a symlink's target is replaced."""
    path = Path(path)
    if path.exists() and not path.is_file():
        yield path
        return
    path = Path(os.path.realpath(path))
    tmp = path.with_name(f".tmp{os.getpid()}.{path.name}")  # same ending: same format
    try:
        yield tmp
        if path.exists():  # the file replaced keeps its permissions
            os.chmod(tmp, stat.S_IMODE(path.stat().st_mode))
        os.replace(tmp, path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()


def save_figure(fig: Any, path: str | Path, dpi: int = 110) -> Path:
    """Write ``fig`` as PNG and close it; an unwritable path is a UserError."""
    path = Path(path)
    try:
        _check_plot_format(path, "plot")
        fig.savefig(path, dpi=dpi)
    except OSError as exc:
        raise UserError(f"{path}: cannot write the plot: {exc.strerror or exc}") from None
    finally:
        pyplot().close(fig)
    return path


def finite_or_none(value: float | None) -> float | None:
    """``value`` as a float if it is finite, else None (JSON has no NaN or infinity)."""
    return float(value) if value is not None and math.isfinite(value) else None


def json_safe(value: Any) -> Any:
    """The value with NaN/inf replaced by None and numpy scalars made plain (strict JSON)."""
    if isinstance(value, float):
        return finite_or_none(value)
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, (str, int, bool)) or value is None:
        return value
    item = getattr(value, "item", None)  # numpy scalar
    if item is not None and getattr(value, "ndim", 1) == 0:
        return json_safe(item())
    tolist = getattr(value, "tolist", None)  # numpy array
    if tolist is not None:
        return json_safe(tolist())
    return str(value)


def write_json(path: str | Path, data: Any, indent: int = 2) -> Path:
    """Write ``data`` as strict JSON text (`json_safe`: NaN and infinities become null)
    ending in a newline; an unwritable path is a UserError."""
    path = Path(path)
    try:
        with open(path, "w", encoding="utf-8") as fh:
            json.dump(json_safe(data), fh, indent=indent, allow_nan=False)
            fh.write("\n")
    except OSError as exc:
        raise UserError(f"{path}: cannot write: {exc.strerror or exc}") from None
    return path
