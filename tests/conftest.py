"""Shared pytest configuration: plots never need a screen; the session fixtures of the
conftest_<area> modules are registered here (their helpers are imported where used)."""

import fdi_daemon  # noqa: F401  (first: it pins the BLAS kernel before NumPy loads)

# isort: split
import matplotlib
import pytest

matplotlib.use("Agg")

pytest_plugins = ["conftest_ident", "conftest_sim", "mqtt_support"]


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
