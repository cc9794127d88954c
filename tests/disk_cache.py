"""Expensive session fixtures built once and kept on disk, shared by pytest-xdist workers.

A product (a folder of files) is named by the hash of its inputs' contents and of the code
that makes it (every ``.py`` of fdi_daemon and hil_sim), kept in pytest's cache folder
(``.pytest_cache/d/fixtures``), and built under a file lock so that two workers never build
the same thing at once: the second waits and reads the first one's result.
"""

from __future__ import annotations

import hashlib
import shutil
from collections.abc import Callable, Iterable
from pathlib import Path

import pytest
from filelock import FileLock

ROOT = Path(__file__).resolve().parents[1]
CODE_PACKAGES = ("fdi_daemon", "hil_sim")


def code_digest() -> str:
    """sha256 of the names and contents of the code that builds the fixtures."""
    h = hashlib.sha256()
    for package in CODE_PACKAGES:
        for f in sorted((ROOT / package).rglob("*.py")):
            h.update(f.relative_to(ROOT).as_posix().encode() + b"\0" + f.read_bytes())
    return h.hexdigest()


def _fixtures_folder(config: pytest.Config) -> Path:
    """pytest's cache folder for the products; the same folder where the cache plugin is off
    (``-p no:cacheprovider``)."""
    cache = getattr(config, "cache", None)
    if cache is not None:
        return Path(cache.mkdir("fixtures"))
    root = Path(config.rootpath) / ".pytest_cache" / "d" / "fixtures"
    root.mkdir(parents=True, exist_ok=True)
    return root


def cached_build(
    config: pytest.Config, name: str, inputs: Iterable[Path], build: Callable[[Path], None]
) -> Path:
    """The folder ``build(folder)`` fills, for these input files and this code; built once."""
    h = hashlib.sha256(name.encode() + b"\0" + code_digest().encode())
    for path in inputs:
        h.update(b"\0" + Path(path).read_bytes())
    root = _fixtures_folder(config)
    final = root / f"{name}-{h.hexdigest()[:16]}"
    with FileLock(str(final) + ".lock"):
        if not final.exists():
            for stale in root.glob(f"{name}-*"):
                if stale.is_dir():
                    shutil.rmtree(stale, ignore_errors=True)
            partial = root / f".{final.name}.partial"
            shutil.rmtree(partial, ignore_errors=True)
            partial.mkdir()
            build(partial)
            partial.rename(final)
    return final
