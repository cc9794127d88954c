"""Speed of `fdi fleet-replay` on a local Dask cluster (issue 45).

One recording of the simulated rig's changing operation (`bench.replay`'s, ``span_s`` long,
archived to Parquet by the recorder's own `archive_csv`) is copied to ``files`` names (one
task per file, as a fleet's archive of one rig-hour per file) and replayed by the fleet's
own code (`dask_client`, `warm_workers`, `replay_fleet`) with 1 worker, then with 2. Each
time is the replay alone: the cluster is started and every worker has loaded the compiled
kernels first (the command reports that start-up apart too).

- ``one_worker_s`` / ``two_workers_s``: wall time of the ``files`` replays; their ratio
  ``two_over_one`` (target >= 1.5; it needs two free cores: ``cpu_count`` and
  ``load_average`` say whether the machine had them);
- ``per_file_overhead_s``: wall time per file of ``short_files`` 1 s Parquet files on
  one worker (target <= 0.05 s);
- ``samples_per_s_two_workers``: the fleet's throughput with 2 workers.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path


def _replay_s(workers: int, *job_lists: Sequence[tuple[str, str | None]]) -> list[float]:
    """Wall time (s) of replaying each of ``job_lists`` in turn on one fresh local cluster
    of ``workers``, once every worker has loaded the kernels; every row must be without
    error."""
    from fdi_daemon.fleet.cluster import dask_client, replay_fleet, warm_workers

    times = []
    with dask_client(None, workers) as client:
        client.wait_for_workers(workers)
        warm_workers(client)
        for jobs in job_lists:
            t0 = time.perf_counter()
            rows = replay_fleet(jobs, client)
            times.append(time.perf_counter() - t0)
            failed = [row["error"] for row in rows if row.get("error")]
            if failed:
                raise RuntimeError(f"fleet bench: {len(failed)} file(s) failed: {failed[0]}")
    return times


def bench_fleet(
    model: Path,
    files: int = 24,
    span_s: float = 3600.0,
    short_files: int = 41,
    base_s: float = 60.0,
    seed: int = 0,
) -> dict:
    """The figures of the module docstring."""
    from fdi_daemon.bench.replay import _recording
    from fdi_daemon.io.model_file import load_model
    from fdi_daemon.io.recordings import write_recording
    from fdi_daemon.service.recorder import archive_csv

    fs = load_model(model).fs
    with tempfile.TemporaryDirectory(prefix="fdi-bench-fleet-") as tmp:
        folder = Path(tmp)
        rec = _recording(base_s, span_s, fs, seed)
        first = archive_csv(write_recording(folder / "rig-00.csv", rec))
        short = archive_csv(
            write_recording(folder / "one_s.csv", rec.samples(slice(0, int(round(fs)))))
        )
        assert first is not None and short is not None
        long_jobs = [(str(first), str(model))]
        for k in range(1, files):
            copy = shutil.copyfile(first, folder / f"rig-{k:02d}.parquet")
            long_jobs.append((str(copy), str(model)))
        short_jobs = []
        for k in range(short_files):
            copy = shutil.copyfile(short, folder / f"short-{k:02d}.parquet")
            short_jobs.append((str(copy), str(model)))
        one, short_s = _replay_s(1, long_jobs, short_jobs)
        (two,) = _replay_s(2, long_jobs)
        overhead = short_s / short_files
    return {
        "files": files,
        "span_s": span_s,
        "one_worker_s": one,
        "two_workers_s": two,
        "two_over_one": one / two,
        "samples_per_s_two_workers": files * len(rec) / two,
        "short_files": short_files,
        "per_file_overhead_s": overhead,
        "cpu_count": os.cpu_count(),
        "load_average": os.getloadavg(),
    }
