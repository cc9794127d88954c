"""The rig config's JSON Schema for editors, generated from `config_models.RigFile`.

``fdi_daemon/data/config.schema.json`` is this module's output (a test keeps them equal);
after changing a model, regenerate it with::

    python -m fdi_daemon.service.config_schema            # writes the file
    python -m fdi_daemon.service.config_schema --check    # exit 1 if the file is stale

In a config file, ``# yaml-language-server: $schema=<path or URL of the file>`` lets an editor
with the YAML language server (VS Code's YAML extension, Neovim, ...) complete keys, show
each key's doc line and flag unknown keys and wrong types while typing.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from fdi_daemon.service.config_models import RigFile

__all__ = ["SCHEMA_PATH", "schema_text"]

SCHEMA_PATH = Path(__file__).resolve().parents[1] / "data" / "config.schema.json"


def schema_text() -> str:
    """The JSON Schema (draft 2020-12) of a rig config file, as the file holds it."""
    schema = {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        **RigFile.model_json_schema(),
    }
    return json.dumps(schema, indent=2, ensure_ascii=False) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if the file is stale")
    args = parser.parse_args(argv)
    text = schema_text()
    if args.check:
        stale = not SCHEMA_PATH.is_file() or SCHEMA_PATH.read_text() != text
        print(f"{SCHEMA_PATH}: {'stale' if stale else 'up to date'}")
        return 1 if stale else 0
    SCHEMA_PATH.write_text(text)
    print(f"wrote {SCHEMA_PATH}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
