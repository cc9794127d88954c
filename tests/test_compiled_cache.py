"""numba's cache of the compiled kernels (`core.compiled.jit`), with real caching in fresh
processes: a kernel that calls a kernel and reads a constant of another module is compiled
afresh when only that other module changes (numba alone would load the stale code)."""

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from fdi_daemon.core.compiled import JIT_ENABLED

pytestmark = pytest.mark.skipif(not JIT_ENABLED, reason="the kernels are not compiled")

REPO = Path(__file__).resolve().parents[1]

CALLER = """\
from fdi_daemon.core.compiled import jit
from kpkg.callee import OFFSET, scaled


@jit
def kernel(x):
    return scaled(x) + OFFSET
"""

CALLEE = """\
from fdi_daemon.core.compiled import jit

OFFSET = {offset}


@jit
def scaled(x):
    return {factor} * x
"""

RUN = "from kpkg.caller import kernel; print(kernel(1.0), sum(kernel.stats.cache_hits.values()))"


def _package(tmp_path: Path, factor: float, offset: float) -> Path:
    package = tmp_path / "kpkg"
    package.mkdir(exist_ok=True)
    (package / "__init__.py").write_text("")
    (package / "caller.py").write_text(CALLER)
    (package / "callee.py").write_text(CALLEE.format(factor=factor, offset=offset))
    return package


def _run(tmp_path: Path, **env: str) -> tuple[float, int]:
    """kernel(1.0) in a new process, and how many of its signatures came from the cache."""
    environ = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    environ.update(PYTHONPATH=f"{tmp_path}{os.pathsep}{REPO}", PYTHONDONTWRITEBYTECODE="1", **env)
    out = subprocess.run(
        [sys.executable, "-c", RUN],
        env=environ,
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    ).stdout.split()
    return float(out[0]), int(out[1])


def test_a_change_to_a_called_module_compiles_its_callers_afresh(tmp_path):
    package = _package(tmp_path, factor=2.0, offset=0.5)
    assert _run(tmp_path) == (2.5, 0)
    assert _run(tmp_path) == (2.5, 1)  # loaded from the cache
    _package(tmp_path, factor=3.0, offset=0.25)  # only callee.py changes
    assert _run(tmp_path) == (3.25, 0)
    assert _run(tmp_path) == (3.25, 1)
    # the caches of the earlier sources are gone: one folder per kernel module's imports
    # is left (the caller's reach the callee, the callee's only itself)
    assert len(list((package / "__pycache__").glob("numba-*"))) == 2


def test_a_change_outside_a_kernels_imports_keeps_it_cached(tmp_path):
    package = _package(tmp_path, factor=2.0, offset=0.5)
    (package / "workflow.py").write_text("STEPS = 1\n")  # imported by no kernel module
    assert _run(tmp_path) == (2.5, 0)
    (package / "workflow.py").write_text("STEPS = 2\n")
    assert _run(tmp_path) == (2.5, 1)  # loaded, not compiled again
    (package / "callee.py").write_text(CALLEE.format(factor=2.0, offset=0.5) + "# edited\n")
    assert _run(tmp_path) == (2.5, 0)  # the callee is among the caller's imports


def test_numba_cache_dir_is_honoured(tmp_path):
    package = _package(tmp_path, factor=2.0, offset=0.5)
    cache = tmp_path / "cache"
    assert _run(tmp_path, NUMBA_CACHE_DIR=str(cache)) == (2.5, 0)
    assert len(list(cache.glob("numba-*/*/*.nbi"))) == 2  # caller and callee
    assert not (package / "__pycache__").exists()


def test_cache_files_of_the_old_scheme_are_removed(tmp_path):
    # numba's own locator wrote kernels beside the sources (__pycache__/*.nbi, *.nbc);
    # they are never read again once the sources' folder is in use
    package = _package(tmp_path, factor=2.0, offset=0.5)
    legacy = package / "__pycache__"
    legacy.mkdir()
    old = [legacy / "caller.kernel-6.py311.nbi", legacy / "caller.kernel-6.py311.1.nbc"]
    for f in old:
        f.write_bytes(b"stale")
    keep = legacy / "caller.cpython-311.pyc"
    keep.write_bytes(b"bytecode")
    assert _run(tmp_path) == (2.5, 0)
    assert not any(f.exists() for f in old)
    assert keep.exists()


def test_processes_starting_together_compile_a_kernel_once(tmp_path):
    # two processes call the kernel at the same moment on a fresh cache (the daemon and the
    # device simulator after an install, the test workers): one compiles, the other waits
    # for its lock and loads what the first one saved (without the lock both compiled)
    _package(tmp_path, factor=2.0, offset=0.5)
    go = tmp_path / "go"
    environ = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    environ.update(PYTHONPATH=f"{tmp_path}{os.pathsep}{REPO}", PYTHONDONTWRITEBYTECODE="1")
    procs = []
    for k in range(2):
        ready = tmp_path / f"ready{k}"
        code = (
            "import os, time\n"
            "from kpkg.caller import kernel\n"
            f"open({str(ready)!r}, 'w').close()\n"
            f"while not os.path.exists({str(go)!r}): time.sleep(0.002)\n"
            + RUN.partition(";")[2].strip()
        )
        procs.append(
            subprocess.Popen(
                [sys.executable, "-c", code], env=environ, stdout=subprocess.PIPE, text=True
            )
        )
    deadline = time.monotonic() + 120
    while not all((tmp_path / f"ready{k}").exists() for k in range(2)):
        assert time.monotonic() < deadline and all(p.poll() is None for p in procs)
        time.sleep(0.01)
    go.touch()
    outs = sorted(p.communicate(timeout=120)[0].split()[1] for p in procs)
    assert [p.returncode for p in procs] == [0, 0]
    assert outs == ["0", "1"]  # compiled by one, loaded from the cache by the other
