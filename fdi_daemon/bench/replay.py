"""Speed of `fdi replay` on files, and the size of the recorder's archive (issue 45).

A recording of the simulated rig's changing operation (``fault_free_hour``, ``base_s``
simulated, then repeated with a continuous counter and clock up to an hour) is written as
the recorder's CSV journal and archived to Parquet by the recorder's own `archive_csv`.
Each figure is the best of ``repeats`` wall-clock runs of ``fdi replay`` in a fresh
process (what a user waits for):

- ``fixed_cost_s``: a 1 s recording; ``import_baseline_s``: ``import numpy, scipy.signal,
  yaml`` alone; their ratio ``fixed_cost_ratio`` (target ≤ 1.4);
- ``hour_csv_samples_per_s`` / ``hour_parquet_samples_per_s``: the marginal rate, (hour
  samples - 1 s samples) / (hour time - 1 s time); divided by the monitor's batch rate of
  the same run they are ``share_of_batch_csv`` / ``share_of_batch_parquet``;
- ``archive_bytes_per_rig_hour``: the Parquet file of the hour;
- ``day_peak_rss_mib`` (when ``day=True``): peak resident memory of ``fdi replay`` on 24 h.

``span_s`` shorter than an hour (``fdi bench --quick``) times a recording of that length
instead: the rates are its marginal rates, ``hour_*_s`` and the sizes are scaled to an hour
(rougher: the marginal time is shorter against the fixed cost), and the Parquet rate is taken
against the fixed cost of a 1 s Parquet file (``fixed_cost_parquet_s``: importing its reader
would otherwise swamp ten minutes); a marginal time within the noise of one run
(`MIN_MARGINAL_S`) gives ``null`` rather than a rate.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HOUR_S = 3600.0
DAY_S = 24 * HOUR_S


def _wall_s(argv: list[str], repeats: int) -> float:
    """Best wall time (s) of ``argv`` run ``repeats`` times; it must succeed."""
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        subprocess.run(argv, check=True, capture_output=True, timeout=3600)
        best = min(best, time.perf_counter() - t0)
    return best


def _replay_argv(recording: Path, model: Path) -> list[str]:
    return [sys.executable, "-m", "fdi_daemon", "replay", str(recording), "--model", str(model)]


def _peak_rss_mib(argv: list[str]) -> float:
    """Peak resident memory (MiB) of one run of ``argv``: its VmHWM (Linux), read every
    20 ms while it runs. Not the children's ru_maxrss: a child started from this process
    (large, holding the day's recording) counted the parent's pages until it exec'd, and
    the day's replay "peaked" at the bench's own 2.9 GiB."""
    import re

    child = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    status = Path(f"/proc/{child.pid}/status")
    peak_kib = 0
    while child.poll() is None:
        try:
            found = re.search(r"VmHWM:\s*(\d+)", status.read_text())
        except OSError:
            found = None
        if found:
            peak_kib = max(peak_kib, int(found.group(1)))
        time.sleep(0.02)
    if child.returncode:
        raise subprocess.CalledProcessError(child.returncode, argv)
    return peak_kib / 1024.0


def _recording(base_s: float, duration_s: float, fs_hz: float, seed: int):
    """The recorder's columns for ``duration_s``: ``base_s`` of simulation, repeated."""
    import numpy as np

    from fdi_daemon.io.recordings import Recording
    from hil_sim.scenarios import load_scenario, simulate

    scenario = (
        Path(__file__).resolve().parents[2] / "configs" / "scenarios" / "fault_free_hour.yaml"
    )
    base = simulate(load_scenario(scenario), seed=seed, duration_s=base_s)
    n = int(round(duration_s * fs_hz))
    reps = -(-n // len(base))
    cols = {
        "seq": np.arange(n, dtype=np.int64),
        "t": np.arange(n) / fs_hz,
        **{k: np.tile(np.asarray(base[k]), reps)[:n] for k in ("v_in", "accel", "position")},
    }
    return Recording(cols, {"fs": f"{fs_hz:g}", "source": "fdi bench"})


#: a shorter marginal time than this is within the timing noise of one run of a process
MIN_MARGINAL_S = 0.25


def _rate(samples: int, seconds: float, to_hour: float) -> float | None:
    """Marginal samples per second; None when a short span (``to_hour`` > 1, --quick) left
    a marginal time within the noise."""
    if to_hour > 1 and seconds < MIN_MARGINAL_S:
        return None
    return samples / seconds


def _hour_s(
    span_s: float, fixed: float, hour_marginal: int, rate: float | None, to_hour: float
) -> float | None:
    """The replay time of an hour: measured, or from the fixed cost and the marginal rate."""
    if to_hour == 1:
        return span_s
    return None if rate is None else fixed + hour_marginal / rate


def bench_replay(
    model: Path,
    batch_samples_per_s: float,
    base_s: float = 60.0,
    repeats: int = 3,
    day: bool = True,
    seed: int = 0,
    span_s: float = HOUR_S,
    warm_up: bool = True,
) -> dict:
    """The figures of the module docstring; ``batch_samples_per_s``: the monitor's batch
    rate measured in the same run; ``span_s``: the length of the timed recording (scaled to
    an hour); ``warm_up``: one untimed replay first (False when the kernels are known to be
    in numba's cache already, e.g. after the monitor stage)."""
    from fdi_daemon.io.model_file import load_model
    from fdi_daemon.io.recordings import write_recording
    from fdi_daemon.service.recorder import archive_csv

    fs = load_model(model).fs
    out: dict = {}
    with tempfile.TemporaryDirectory(prefix="fdi-bench-replay-") as tmp:
        folder = Path(tmp)
        hour = _recording(base_s, span_s, fs, seed)
        second = hour.samples(slice(0, int(round(fs))))
        one_s = write_recording(folder / "one_s.csv", second)
        hour_csv = write_recording(folder / "rec-hour.csv", hour)
        journal = write_recording(folder / "rec-archive.csv", hour)
        hour_parquet = archive_csv(journal)
        assert hour_parquet is not None
        if warm_up:  # untimed: loads (on a fresh install, compiles) the kernels into the cache
            subprocess.run(
                _replay_argv(one_s, model), check=True, capture_output=True, timeout=3600
            )
        if day:
            day_rec = _recording(base_s, DAY_S, fs, seed)
            day_file = write_recording(folder / "day.parquet", day_rec)
            del day_rec
            out["day_peak_rss_mib"] = _peak_rss_mib(_replay_argv(day_file, model))
        baseline = _wall_s([sys.executable, "-c", "import numpy, scipy.signal, yaml"], repeats)
        fixed = _wall_s(_replay_argv(one_s, model), repeats)
        csv_s = _wall_s(_replay_argv(hour_csv, model), repeats)
        parquet_s = _wall_s(_replay_argv(hour_parquet, model), repeats)
        parquet_fixed = fixed
        if span_s < HOUR_S:  # reading Parquet's own fixed cost would swamp a short span
            one_s_parquet = archive_csv(write_recording(folder / "one_s-archive.csv", second))
            assert one_s_parquet is not None
            parquet_fixed = _wall_s(_replay_argv(one_s_parquet, model), repeats)
            out["fixed_cost_parquet_s"] = parquet_fixed
        marginal = len(hour) - len(second)
        to_hour = HOUR_S / span_s  # 1 unless --quick
        hour_marginal = round(HOUR_S * fs) - len(second)
        csv_rate = _rate(marginal, csv_s - fixed, to_hour)
        parquet_rate = _rate(marginal, parquet_s - parquet_fixed, to_hour)
        out.update(
            {
                "span_s": span_s,
                "fixed_cost_s": fixed,
                "import_baseline_s": baseline,
                "fixed_cost_ratio": fixed / baseline,
                "hour_csv_s": _hour_s(csv_s, fixed, hour_marginal, csv_rate, to_hour),
                "hour_parquet_s": _hour_s(
                    parquet_s, parquet_fixed, hour_marginal, parquet_rate, to_hour
                ),
                "hour_csv_samples_per_s": csv_rate,
                "hour_parquet_samples_per_s": parquet_rate,
                "archive_bytes_per_rig_hour": round(os.path.getsize(hour_parquet) * to_hour),
                "csv_bytes_per_rig_hour": round(os.path.getsize(hour_csv) * to_hour),
                "batch_samples_per_s": batch_samples_per_s,
            }
        )
    for fmt in ("csv", "parquet"):
        rate = out[f"hour_{fmt}_samples_per_s"]
        out[f"share_of_batch_{fmt}"] = None if rate is None else rate / batch_samples_per_s
    out["load_average"] = os.getloadavg()
    return out
