"""Shared pytest configuration: OpenBLAS threads that do not spin, a share of the cores per
xdist worker and one worker more than cores (`-n auto`), the monitor compiled while the
workers start, plots never need a screen; the session fixtures of the conftest_<area>
modules are registered here (their helpers are imported where used)."""

import inspect
import os
import subprocess
import sys

# OpenBLAS's idle threads sleep at once instead of spinning for about 2^28 cycles after
# each call (read when NumPy loads OpenBLAS, so before anything imports NumPy; the xdist
# workers and the tests' subprocesses inherit it). The diagnose fits are many small matrix
# products, SVDs and least squares: two diagnoses took 58 s of CPU with the spinning threads
# and 20 s without, with the same results bit for bit. A value set is kept.
os.environ.setdefault("OPENBLAS_THREAD_TIMEOUT", "4")

# An xdist worker's BLAS gets its share of the cores, as scikit-learn's conftest gives it:
# two workers on two cores each with OpenBLAS's two threads are four threads on two cores
# (the diagnose tests: 437 s of CPU on two threads a worker, 347 s on one). Set in the
# environment before NumPy loads, so the tests' subprocesses inherit it; a value set is kept.
# (xdist sets the worker count before it loads this file.)
if "PYTEST_XDIST_WORKER_COUNT" in os.environ:
    _cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    _share = (_cores or 1) // int(os.environ["PYTEST_XDIST_WORKER_COUNT"])
    os.environ.setdefault("OPENBLAS_NUM_THREADS", str(max(1, _share)))

# isort: split
import fdi_daemon  # noqa: E402, F401  (first: it pins the BLAS kernel before NumPy loads)

# isort: split
import matplotlib  # noqa: E402
import pytest  # noqa: E402

matplotlib.use("Agg")

pytest_plugins = ["conftest_diagnose", "conftest_ident", "conftest_sim", "mqtt_support"]


def pytest_xdist_auto_num_workers(config):
    """``-n auto``: one worker more than the machine has cores (`PYTEST_XDIST_AUTO_NUM_WORKERS`
    overrides). About a quarter of the suite's test time is spent waiting on real time (a
    daemon's 256 Hz loop, a broker restart, a link's reconnect), when a worker uses no core;
    the extra worker's tests run meanwhile. On the 2-core CI machine, with a BLAS thread a
    worker (above): 439 s on three workers against 539 s on two."""
    if os.environ.get("PYTEST_XDIST_AUTO_NUM_WORKERS"):
        return None  # xdist's own hook reads it
    from xdist.plugin import pytest_xdist_auto_num_workers as cores  # xdist's core count

    return cores(config) + 1


_MONITOR_COMPILE = pytest.StashKey[subprocess.Popen]()


def pytest_configure(config):
    """An xdist run's controller compiles the monitor's kernels into numba's cache in a
    process of its own (`fleet.replay_one.warm_worker`) while its workers start and collect:
    after a change that reaches them the compile takes 30–50 s on one core, and the
    workers' first tests that start a daemon, a replay or the benchmark would otherwise all
    wait on one worker's compile (`core.compiled`'s lock) with a core idle. Ended with the
    run (a compile cut short leaves numba's cache as it was: it writes each file whole)."""
    if getattr(config.option, "numprocesses", None) and not hasattr(config, "workerinput"):
        config.stash[_MONITOR_COMPILE] = subprocess.Popen(
            [
                sys.executable,
                "-c",
                "from fdi_daemon.fleet.replay_one import warm_worker; warm_worker()",
            ],
            cwd=config.rootpath,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )


def pytest_unconfigure(config):
    compile_process = config.stash.get(_MONITOR_COMPILE, None)
    if compile_process is not None:
        compile_process.terminate()
        compile_process.wait()


def pytest_itemcollected(item):
    """A test that asks for a diagnosis (the `diagnosis` fixture among its arguments) is
    `slow`: each diagnosis takes seconds to minutes, so the inner loop (``-m "not slow"``)
    leaves it out. (test_diagnose_cli's autouse fixture holds it for every test, and marks
    its diagnosing tests itself.)"""
    function = getattr(item, "function", None)
    if function is not None and "diagnosis" in inspect.signature(function).parameters:
        item.add_marker(pytest.mark.slow)


def pytest_collection_modifyitems(items):
    """The modules that hold `slow` tests first, whole (a module's fixtures are built once
    per worker as before; the modules' order and their tests' kept): the long diagnoses
    start first and the xdist workers end on short tests, not one of them on a long test
    while the other has nothing left."""
    slow = {item.path for item in items if item.get_closest_marker("slow")}
    items.sort(key=lambda item: item.path not in slow)


@pytest.fixture(autouse=True)
def private_state_home(tmp_path_factory, monkeypatch):
    """`fdi run` without a state dir writes under $XDG_STATE_HOME/fdi: a test's daemon (and
    the subprocesses it starts) must never touch the user's ~/.local/state/fdi."""
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path_factory.mktemp("xdg_state")))


@pytest.fixture(scope="session")
def compiled_kernel_cache():
    """The monitor's kernels compiled into numba's cache before a test starts a daemon in
    a subprocess: the first run after a change to the package compiles (40–200 s on a
    loaded 2-core machine), which a test's wall-clock wait for MONITORING must not pay.
    One process compiles, the others load (`core.compiled`'s lock)."""
    from fdi_daemon.fleet.replay_one import warm_worker

    warm_worker()
