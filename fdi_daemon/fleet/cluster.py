"""The rows of many recordings, computed on a Dask cluster (``dask.distributed``).

By default a `LocalCluster` on this machine: worker processes (one thread each, so the
numba kernels of different files run in parallel), scheduler and workers listening on
127.0.0.1 only, no dashboard. With a scheduler address, the workers of that cluster do the
work: they need fdi installed and must see the recordings and model files at the same paths.
"""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Callable, Sequence
from typing import Any

from fdi_daemon.errors import UserError
from fdi_daemon.fleet.replay_one import replay_row, summary_row, warm_worker

INSTALL_HINT = "pip install 'fdi[fleet]'"


def _distributed():
    try:
        import dask.distributed as dd
    except ImportError:
        raise UserError(f"fleet replay needs dask.distributed: {INSTALL_HINT}") from None
    return dd


@contextlib.contextmanager
def dask_client(scheduler: str | None, workers: int):
    """A client of the given scheduler, or of a fresh local cluster of ``workers`` processes."""
    dd = _distributed()
    if scheduler is not None:
        try:
            client = dd.Client(scheduler, timeout="10s")
        except (OSError, TimeoutError, ValueError) as exc:
            raise UserError(f"cannot reach the Dask scheduler at {scheduler}: {exc}") from None
        with client:
            yield client
        return
    import dask  # installed with dask.distributed

    environ = dict(os.environ)  # as it was before the nannies set theirs (`_restore_environ`)
    # a file that kills its worker kills it again on every retry: no retries on the cluster
    # (`replay_fleet` runs each failed file once more alone), so such a file costs two worker
    # restarts instead of eight
    no_retries = {"distributed.scheduler.allowed-failures": 0}
    with _sigint_ignored(), dask.config.set(no_retries):  # Ctrl-C is the parent's job
        cluster = dd.LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=None,
            # no dashboard, yet the scheduler's HTTP server took port
            # 8787 (and warned "already in use" beside another run)
            scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},
            # a worker's errors are its files' rows; Ctrl-C under load made a busy worker
            # log "Failed to communicate with scheduler during heartbeat" with a traceback
            silence_logs=logging.CRITICAL,
        )
    _restore_environ(environ)
    interrupted = False
    try:
        with dd.Client(cluster) as client:
            try:
                yield client
            except KeyboardInterrupt:
                # the scheduler's errors about the work dropped ("Couldn't gather keys ...
                # forgotten") are the interrupt's doing: the user sees one line
                interrupted = True
                logging.disable(logging.ERROR)
                raise
    finally:
        with _sigint_ignored():  # a second Ctrl-C must not cut the workers' shutdown short
            cluster.close()
        _restore_environ(environ)  # again: a nanny that restarted its worker set them again
        if interrupted:
            logging.disable(logging.NOTSET)


def _restore_environ(saved: dict[str, str]) -> None:
    """This process's environment back to ``saved``.

    Each nanny of a `LocalCluster` sets its ``pre-spawn-environ`` (``OPENBLAS_NUM_THREADS=1``,
    ``OMP_NUM_THREADS=1``, ``MALLOC_TRIM_THRESHOLD_``) in its own process, which is this one,
    so that the worker it spawns inherits them (distributed.yaml: "this leaks variables into
    the nanny process"). Left there, every program this process started afterwards ran its
    BLAS on one thread: a test worker that had run a fleet replay started diagnoses that
    named other effects (issue 42: a diagnosis still depends on the BLAS thread count)."""
    for name in set(os.environ) - set(saved):
        del os.environ[name]
    os.environ.update(saved)


@contextlib.contextmanager
def _sigint_ignored():
    """SIGINT ignored while the local cluster starts (or stops) its worker processes.

    Ctrl-C reaches every process of the terminal's foreground group: each worker printed
    its own KeyboardInterrupt traceback while `fdi fleet-replay` stopped cleanly. An ignored
    signal stays ignored in a spawned process (and Python then installs no handler), so the
    workers leave Ctrl-C to the parent, which closes the cluster and stops them.
    """
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def warm_workers(client) -> None:
    """Every worker imports the monitor and loads the compiled kernels once, before the
    files (`warm_worker`); a worker that cannot is left to fail its files with a row."""
    with contextlib.suppress(Exception):
        client.run(warm_worker)


def replay_fleet(
    jobs: Sequence[tuple[str, str | None]],
    client,
    on_row: Callable[[dict[str, Any]], None] | None = None,
    task: Callable[[str, str | None], dict[str, Any]] = replay_row,
) -> list[dict[str, Any]]:
    """One row per ``(recording, model file or None)``, in the order of ``jobs``.

    Every file is one ``task(file, model)`` (`replay_row`, which never raises). A task
    that fails anyway (its worker process died, on every retry Dask made) is run once more
    alone on the cluster: a worker killed by one file also fails the tasks it held, and
    those then succeed. A file whose task fails alone too gives a row with the error.
    ``on_row(row)`` is called as each row is final.
    """
    dd = _distributed()
    files = [file for file, _ in jobs]
    models = [model for _, model in jobs]
    futures = client.map(task, files, models, pure=False)
    position = {future.key: i for i, future in enumerate(futures)}
    rows: list[dict[str, Any]] = [{} for _ in jobs]
    failed = []
    for future in dd.as_completed(futures):
        i = position[future.key]
        try:
            rows[i] = future.result()
        except Exception:  # the task itself never raises: its worker died
            failed.append(i)
            continue
        finally:
            future.release()
        if on_row is not None:
            on_row(rows[i])
    for i in sorted(failed):
        alone = client.submit(task, files[i], models[i], pure=False)
        try:
            rows[i] = alone.result()
        except Exception as exc:
            rows[i] = summary_row(
                files[i], models[i], error=f"worker failed: {type(exc).__name__}: {exc}"
            )
        finally:
            alone.release()
        if on_row is not None:
            on_row(rows[i])
    return rows
