"""Replay one recording through the monitor: the one code path of `fdi replay` and
`fdi fleet-replay`.

`replay_recording` loads the model, reads the recording (gaps and duplicates reported, not
refused), checks that both have the same rate, runs the monitor, runs the alarm lifecycle
over its events and level readings as the daemon would (`fdi_daemon.alarms.replay`) and
summarizes (`fdi_daemon.detect.summary.replay_summary`). How the monitor runs is the caller's choice:
by default the batch path `Monitor.run` (the whole file at once); ``stream=True`` reads a
Parquet file piece by piece (`run_pieces`, flat memory on a day-long file); `fdi replay`
passes its own runner for the progress bar, the real-time pacing or the dashboard.
`summary_row` turns the summary into one row of the fleet table.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

#: (monitor, recording, stride) -> (events, trace); the trace's ``every`` divides ``stride``,
#: the samples between two level readings of the alarm lifecycle
Runner = Callable[[Any, Any, int], tuple[list[dict[str, Any]], Any]]

#: columns of the fleet table, in order (docs/fleet.md)
ROW_COLUMNS = (
    "file",
    "model",
    "samples",
    "fs",
    "alarm_episodes",
    "alarms",
    "alarm_peak_priority",
    "first_detection_t",
    "isolated_t",
    "classification",
    "friction_level_final",
    "gaps",
    "missing_samples",
    "bad_samples",
    "fdi_version",
    "model_sha256",
    "error",
)


@dataclass
class Replay:
    """What one replay produced (the monitor keeps its final state for plots)."""

    recording: Any  # fdi_daemon.io.recordings.Recording
    monitor: Any  # fdi_daemon.detect.monitor.Monitor
    events: list[dict[str, Any]]
    trace: Any  # fdi_daemon.detect.monitor.MonitorTrace
    summary: dict[str, Any]


def run_batch(monitor, rec, stride: int):
    """The batch path, traced only where the alarm lifecycle reads the level."""
    return monitor.run(rec, trace_every=stride)


def run_pieces(monitor, stream, stride: int, progress=None):
    """`Monitor.run` over a `RecordingStream` piece by piece (the streaming contract of
    `Monitor.run`: the events and trace of one run over the whole); (events, trace)."""
    import numpy as np

    from fdi_daemon.detect.monitor import TRACE_NAMES, MonitorTrace

    events: list[dict[str, Any]] = []
    # the trace's rows go into arrays made once for the whole file (at most one row per
    # `stride` samples kept), not into a list of small pieces: small arrays that live on
    # between each piece's large temporary ones fragmented the heap (RSS grew by some
    # 10 bytes per sample over a day)
    size = -(-stream.rows // stride) + 1
    arrays = {
        name: np.empty(size, dtype=np.int8 if name == "state" else float) for name in TRACE_NAMES
    }
    done = rows = 0
    for piece in stream.pieces():
        done += len(piece)
        new, trace = monitor.run(piece, trace_every=stride, final=done >= stream.rows)
        events.extend(new)
        n = len(trace.t)
        if rows + n > size:  # more rows than samples/stride: duplicates traced one by one
            size = 2 * (rows + n)
            arrays = {k: np.resize(v, size) for k, v in arrays.items()}
        for name in TRACE_NAMES:
            arrays[name][rows : rows + n] = getattr(trace, name)
        rows += n
        del trace, piece
        if progress is not None:
            progress(done, stream.rows)
    if done < stream.rows:  # cannot happen with a file that does not change under us
        events.extend(monitor.finish())
    return events, MonitorTrace(every=stride, **{k: v[:rows] for k, v in arrays.items()})


def replay_recording(
    recording: str | Path,
    model_path: str | Path,
    runner: Runner = run_batch,
    columns: Mapping[str, str] | None = None,
    alarm_settings=None,
    status_period_s: float | None = None,
    stream: bool = False,
    progress: Callable[[int, int], None] | None = None,
    model=None,
) -> Replay:
    """Replay ``recording`` with the model file ``model_path``; UserError on bad input.

    columns: fdi name -> the file's column name (``--columns``), as `read_recording` takes.
    alarm_settings (`AlarmSettings`, default its defaults) and status_period_s (default
    the daemon's) set the alarm lifecycle as the daemon's config would.
    stream: a Parquet recording that names its rate is read and replayed piece by piece
    (`open_stream`; memory stays flat on a day-long file) through the batch path, not
    ``runner``; `Replay.recording` is then None. progress(samples done, total) after each
    piece. model: the loaded model file (`FdiModel`) when the caller has it already.
    """
    import numpy as np

    from fdi_daemon.alarms.replay import STATUS_PERIOD_S, alarm_events, merge_events, status_stride
    from fdi_daemon.detect.monitor import Monitor
    from fdi_daemon.detect.summary import replay_summary
    from fdi_daemon.errors import UserError
    from fdi_daemon.io.model_file import load_model
    from fdi_daemon.io.recordings import open_stream, read_recording, same_rate

    if model is None:
        model = load_model(model_path)
    pieces = open_stream(recording, columns) if stream else None
    if pieces is None:
        rec = read_recording(recording, strict=False, columns=columns)
        fs, samples = rec.fs, len(rec)
    else:
        rec, fs, samples = None, pieces.fs, pieces.rows
    if not same_rate(fs, model.fs):
        raise UserError(f"{recording}: sampled at {fs:g} Hz but the model is for {model.fs:g} Hz")
    monitor = Monitor(model)
    stride = status_stride(model.fs, status_period_s or STATUS_PERIOD_S)
    if rec is None:
        events, trace = run_pieces(monitor, pieces, stride, progress)
    else:
        events, trace = runner(monitor, rec, stride)
    events = merge_events(events, alarm_events(monitor, events, trace, stride, alarm_settings))
    snap = monitor.snapshot()
    levels = trace.friction_level[np.isfinite(trace.friction_level)]
    summary = replay_summary(
        events,
        samples,
        model.fs,
        monitor.settings.method,
        (snap["theta1"], snap["theta2"]),
        float(levels[-1]) if levels.size else None,
    )
    return Replay(rec, monitor, events, trace, summary)


def summary_row(
    file: str,
    model: str | None,
    summary: dict[str, Any] | None = None,
    error: str | None = None,
    model_sha256: str | None = None,
) -> dict[str, Any]:
    """One row of the fleet table from a replay summary, or from the error that stopped it;
    the row names the fdi version that replayed and the model file's SHA-256."""
    from fdi_daemon import __version__

    s = summary or {}
    return {
        "file": file,
        "model": model,
        "samples": s.get("samples"),
        "fs": s.get("fs"),
        "alarm_episodes": s.get("alarm_episodes"),
        "alarms": s.get("alarms"),
        "alarm_peak_priority": s.get("alarm_peak_priority"),
        "first_detection_t": s.get("first_detection_t"),
        "isolated_t": s.get("isolated_t"),
        "classification": s.get("classification"),
        "friction_level_final": s.get("friction_level_final"),
        "gaps": (s.get("event_counts") or {}).get("data_gap", 0) if summary else None,
        "missing_samples": s.get("missing_samples"),
        "bad_samples": s.get("bad_samples"),
        "fdi_version": __version__,
        "model_sha256": model_sha256,
        "error": error,
    }


def replay_row(file: str, model: str | None) -> dict[str, Any]:
    """Replay one file and return its row; a bad file gives a row with its error, never
    an exception (runs on a Dask worker)."""
    from fdi_daemon.errors import UserError

    if model is None:
        return summary_row(file, None, error="no model: the model map has no pattern for this file")
    try:
        digest = model_sha256(model)
    except OSError as exc:
        return summary_row(file, model, error=f"{model}: cannot read the model: {exc.strerror}")
    try:
        loaded = cached_model(model)
        replay = replay_recording(file, model, stream=True, model=loaded)
        return summary_row(file, model, replay.summary, None, digest)
    except UserError as exc:
        return summary_row(file, model, error=str(exc), model_sha256=digest)
    except Exception as exc:  # a bug in fdi on one file must not stop the fleet
        return summary_row(
            file,
            model,
            error=f"internal error: {type(exc).__name__}: {exc}",
            model_sha256=digest,
        )


def cached_model(path: str):
    """The model file loaded once per worker process for each version of the file (its
    size and modification time): a fleet's files share a few models."""
    stat = Path(path).stat()
    return _model_of_version(str(Path(path).resolve()), stat.st_size, stat.st_mtime_ns)


@functools.lru_cache(maxsize=64)
def _model_of_version(path: str, size: int, mtime_ns: int):
    from fdi_daemon.io.model_file import load_model

    return load_model(path)


def warm_worker() -> bool:
    """Import the monitor and load its compiled kernels from numba's cache (or compile
    them) in this process, once: `fdi fleet-replay` runs it on every worker before the
    files, so no file pays for it."""
    from fdi_daemon.detect.monitor import Monitor
    from fdi_daemon.io.model_file import load_model

    Monitor(load_model(DEFAULT_MODEL)).warm_up()
    return True


#: the simulated rig's model, shipped with fdi (any model loads the same kernels)
DEFAULT_MODEL = str(Path(__file__).resolve().parents[1] / "data" / "model_sim_rig.yaml")


def model_sha256(path: str) -> str:
    """The SHA-256 of a model file, hashed once per worker for each version of the file
    (its size and modification time)."""
    stat = Path(path).stat()
    return _file_sha256_of_version(str(Path(path).resolve()), stat.st_size, stat.st_mtime_ns)


@functools.lru_cache(maxsize=256)
def _file_sha256_of_version(path: str, size: int, mtime_ns: int) -> str:
    from fdi_daemon.ident.provenance import file_sha256

    return file_sha256(path)
