"""The recordings of a fleet replay and the model of each (docs/fleet.md).

A *model map* is a YAML mapping from file names or glob patterns to model files::

    rig-07-2026-11-02.csv: models/rig07_after_repair.yaml   # one file (exact name)
    "rig-07-*": models/rig07.yaml
    "line-b/*/rig-1?-*.csv": models/line_b.yaml             # the end of the path
    "*": models/default.yaml                                # everything else

Keys are matched against the end of the file's path, one path component per component of
the key (``pathlib.PurePath.match``): a key without "/" matches the file name, ``*`` does not
cross "/". Keys without glob characters (exact names) are tried first, then the patterns in
the order of the file; the first match wins. Model paths are relative to the map file. A
recording that matches nothing gets a row with an error.
"""

from __future__ import annotations

import glob
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from fdi_daemon.errors import ConfigError, UserError
from fdi_daemon.io.recordings import SUFFIXES

#: file endings of the recording formats read in a folder
RECORDING_SUFFIXES = SUFFIXES
_GLOB_CHARS = frozenset("*?[")


def find_recordings(dir_or_glob: str) -> list[str]:
    """The recordings in a folder (its recording files, not its subfolders) or matched by a
    glob (``**`` recurses), sorted; UserError when there are none."""
    path = Path(dir_or_glob)
    if path.is_dir():
        found = [
            str(p)
            for p in path.iterdir()
            if p.is_file() and p.name.lower().endswith(RECORDING_SUFFIXES)
        ]
    elif _GLOB_CHARS & set(dir_or_glob):
        found = [p for p in glob.glob(dir_or_glob, recursive=True) if Path(p).is_file()]
    elif path.is_file():
        found = [dir_or_glob]
    else:
        raise UserError(f"{dir_or_glob}: no such folder or file, and not a glob pattern")
    if not found:
        raise UserError(
            f"{dir_or_glob}: no recordings found "
            f"(a folder is searched for {', '.join(RECORDING_SUFFIXES)})"
        )
    return sorted(found)


@dataclass(frozen=True)
class ModelMap:
    """File names and glob patterns -> model files (see the module docstring)."""

    source: str
    entries: tuple[tuple[str, str], ...]  # (key, model path), in the file's order

    @classmethod
    def single(cls, model: str) -> ModelMap:
        """Every recording with the same model (``--model``)."""
        if not Path(model).is_file():
            raise UserError(f"{model}: no such model file")
        return cls("--model", (("*", model),))

    @classmethod
    def load(cls, path: str | Path) -> ModelMap:
        from fdi_daemon.io.yaml_file import read_yaml

        data = read_yaml(path, "model map")
        if not isinstance(data, dict) or not data:
            raise ConfigError(
                f"{path}: a model map is a mapping of file names or glob "
                f"patterns to model files, e.g. '\"rig-07-*\": rig07.yaml'"
            )
        base = Path(path).parent
        entries = []
        for key, model in data.items():
            if not isinstance(key, str) or not isinstance(model, str) or not model:
                raise ConfigError(
                    f"{path}: {key!r}: expected a pattern and a model file path, got {model!r}"
                )
            model_path = base / model
            if not model_path.is_file():
                raise ConfigError(f"{path}: {key}: model file {model_path} does not exist")
            entries.append((key, str(model_path)))
        return cls(str(path), tuple(entries))

    def model_for(self, recording: str) -> str | None:
        """The model file of a recording, or None when no key matches."""
        path = PurePosixPath(Path(recording).as_posix())
        exact = [(k, m) for k, m in self.entries if not _GLOB_CHARS & set(k)]
        patterns = [(k, m) for k, m in self.entries if _GLOB_CHARS & set(k)]
        return next((model for key, model in exact + patterns if path.match(key)), None)
