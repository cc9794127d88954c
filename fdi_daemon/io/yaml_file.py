"""Reading a YAML file (model, rig config, scenario) with one-line errors that name it."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from fdi_daemon.errors import ConfigError


def read_yaml(path: str | Path, what: str) -> Any:
    """Parse ``path``; ``what`` names the kind of file in errors ("model", "config", ...).

    A missing, unreadable or invalid file raises a ConfigError naming the file (and the line
    of a YAML syntax error). The parsed value is returned as it is: validating its shape is
    the caller's job.
    """
    path = Path(path)
    try:
        with open(path, encoding="utf-8") as fh:
            return yaml.safe_load(fh)
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such {what} file") from None
    except IsADirectoryError:
        raise ConfigError(f"{path}: is a directory, not a {what} file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read {what} file: {exc}") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        raise ConfigError(f"{path}: not valid YAML{where}") from None
