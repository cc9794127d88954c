"""The diagnose tests' session fixture: a diagnosis computed once per test run.

Tests that diagnose the same recording with the same arguments (a named effect's test and
its size's, a CLI run and its rerun against the augmented model) share one result; it is
kept on disk (tests/disk_cache.py) so that the xdist workers share it too: a worker asking
for a diagnosis that another is computing waits for it under the file lock.
"""

from __future__ import annotations

import hashlib
import inspect
import pickle

import cloudpickle  # the result's regressor blocks hold lambdas, which pickle refuses
import numpy as np
import pytest
import scipy

from tests.disk_cache import cached_build


def arguments_digest(function, *args, **kwargs) -> str:
    """sha256 of a call's arguments, bound to ``function``'s signature with its defaults (a
    positional and a keyword call are the same call): arrays by dtype, shape and content,
    the rest by value; with NumPy's and SciPy's versions."""
    bound = inspect.signature(function).bind(*args, **kwargs)
    bound.apply_defaults()
    h = hashlib.sha256(f"numpy {np.__version__} scipy {scipy.__version__}".encode())
    for name, value in bound.arguments.items():
        h.update(f"\0{name}=".encode())
        if value is None or isinstance(value, (str, bool, int, float, np.generic)):
            h.update(repr(value.item() if isinstance(value, np.generic) else value).encode())
        else:
            array = np.ascontiguousarray(value)
            h.update(f"{array.dtype.str}{array.shape}".encode() + array.tobytes())
    return h.hexdigest()


@pytest.fixture(scope="session")
def diagnosis(request):
    """`run_diagnose` (without ``progress``) computed once per test run for the same
    arguments (`arguments_digest`) and code; every call returns its own copy."""
    from fdi_daemon.diagnose.workflow import run_diagnose

    def diagnose(*args, **kwargs):
        def build(out):
            (out / "result.pkl").write_bytes(cloudpickle.dumps(run_diagnose(*args, **kwargs)))

        digest = arguments_digest(run_diagnose, *args, **kwargs)
        folder = cached_build(request.config, f"diagnosis-{digest[:20]}", [], build)
        return pickle.loads((folder / "result.pkl").read_bytes())

    return diagnose
