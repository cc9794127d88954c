"""`fdi replay --trace FILE`: the monitor's trace as a table engineers load into their tools.

Columns (DESIGN.md "Replay trace"): ``t`` (s), ``theta1``, ``theta2`` (eq. 17, or the
episode's own fit during an alarm), ``friction_level`` (1 = the calibrated fault: the median
θ1 of the last seconds of windows where θ1 measures friction, `detect.friction_level`),
``statistic`` (the detector's test statistic) and ``state`` (the detector state's name).
NaN where a quantity is not estimated (the rig at rest, windows not full).

- ``.npz``: one array per column, ``state`` as strings (``np.load`` needs no pickle);
- anything else: CSV with a header row.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from fdi_daemon.detect.detector import STATES
from fdi_daemon.errors import UserError

if TYPE_CHECKING:
    from fdi_daemon.detect.monitor import MonitorTrace

__all__ = ["TRACE_COLUMNS", "trace_columns", "write_trace"]

TRACE_COLUMNS = ("t", "theta1", "theta2", "friction_level", "statistic", "state")


def trace_columns(trace: MonitorTrace, every: int = 1) -> dict[str, np.ndarray]:
    """The columns of a `MonitorTrace`, every ``every``-th of its rows."""
    rows = slice(None, None, int(every))
    names = np.asarray(STATES)
    return {
        "t": trace.t[rows],
        "theta1": trace.theta1[rows],
        "theta2": trace.theta2[rows],
        "friction_level": trace.friction_level[rows],
        "statistic": trace.statistic[rows],
        "state": names[trace.state[rows].astype(int)],
    }


def write_trace(path: str | Path, trace: MonitorTrace, every: int = 1) -> Path:
    """Write the trace to ``path`` (.npz or CSV); a file that cannot be written: UserError."""
    path = Path(path)
    columns = trace_columns(trace, every)
    try:
        if path.suffix.lower() == ".npz":
            np.savez(path, **columns)  # type: ignore[arg-type]  # numpy's stub types **kwds as allow_pickle
        else:
            text = [np.char.mod("%.10g", columns[name]) for name in TRACE_COLUMNS[:-1]]
            table = np.column_stack([*text, columns["state"]])
            with open(path, "w", encoding="utf-8", newline="") as fh:
                fh.write(",".join(TRACE_COLUMNS) + "\n")
                np.savetxt(fh, table, fmt="%s", delimiter=",")
    except OSError as exc:
        raise UserError(f"{path}: cannot write the trace: {exc.strerror or exc}") from None
    return path
