"""The fleet table (one row per recording) as CSV or Parquet."""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from fdi_daemon.errors import UserError
from fdi_daemon.fleet.replay_one import ROW_COLUMNS

#: Parquet column types (pyarrow type names); CSV writes an empty cell for a missing value
PARQUET_TYPES = {
    "file": "string",
    "model": "string",
    "samples": "int64",
    "fs": "float64",
    "alarm_episodes": "int64",
    "alarms": "int64",
    "alarm_peak_priority": "int64",
    "first_detection_t": "float64",
    "isolated_t": "float64",
    "classification": "string",
    "friction_level_final": "float64",
    "gaps": "int64",
    "missing_samples": "int64",
    "bad_samples": "int64",
    "fdi_version": "string",
    "model_sha256": "string",
    "error": "string",
}


def write_table(path: str | Path, rows: Sequence[dict[str, Any]]) -> None:
    """Write the rows to ``path``: ``.csv`` or ``.parquet`` (needs pyarrow)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".parquet"):
        raise UserError(f"{path}: the results table is written as .csv or .parquet")
    try:
        if suffix == ".csv":
            with open(path, "w", newline="", encoding="utf-8") as fh:
                writer = csv.DictWriter(fh, fieldnames=ROW_COLUMNS)
                writer.writeheader()
                writer.writerows(rows)
        else:
            _write_parquet(path, rows)
    except OSError as exc:
        raise UserError(f"{path}: cannot write the results: {exc.strerror or exc}") from None


def _write_parquet(path: Path, rows: Sequence[dict[str, Any]]) -> None:
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise UserError(
            f"{path}: writing Parquet needs pyarrow: pip install 'fdi[fleet]' (or write .csv)"
        ) from None
    from fdi_daemon import __version__

    schema = pa.schema(
        [(name, getattr(pa, PARQUET_TYPES[name])()) for name in ROW_COLUMNS],
        metadata={"fdi_version": __version__},
    )
    pq.write_table(pa.Table.from_pylist(list(rows), schema=schema), path)
