"""Shared pytest configuration: one BLAS thread per process, plots never need a screen; the
session fixtures of the conftest_<area> modules are registered here (their helpers are
imported where used)."""

import os

# One OpenBLAS thread per test process (read when NumPy loads OpenBLAS, so before anything
# imports NumPy; the xdist workers and the tests' subprocesses inherit it). The diagnose fits
# are many small matrix products, SVDs and least squares, on which OpenBLAS's threads spin:
# a gram matrix X'X (6800 x 40) took 25 times the CPU with 2 threads, two diagnoses 58 s of
# CPU instead of 11 s (and 5 times the wall time beside other work), with the same results
# bit for bit (`fdi diagnose` on 8 cases of tests/diagnose_cases.py). A value set is kept.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

# isort: split
import fdi_daemon  # noqa: E402, F401  (first: it pins the BLAS kernel before NumPy loads)

# isort: split
import matplotlib  # noqa: E402
import pytest  # noqa: E402

matplotlib.use("Agg")

pytest_plugins = ["conftest_diagnose", "conftest_ident", "conftest_sim", "mqtt_support"]


def pytest_collection_modifyitems(items):
    """The `slow` tests first (in their order; the rest after them in theirs): the long
    diagnoses start first and the xdist workers end on short tests, not one of them on a
    long test while the other has nothing left."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)


@pytest.fixture(autouse=True)
def private_state_home(tmp_path_factory, monkeypatch):
    """`fdi run` without a state dir writes under $XDG_STATE_HOME/fdi: a test's daemon (and
    the subprocesses it starts) must never touch the user's ~/.local/state/fdi."""
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path_factory.mktemp("xdg_state")))
