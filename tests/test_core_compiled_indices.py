"""The kernels compile with every integer index taken as given (`core.compiled`: numba's
wrap-around of a negative index is left out, so a negative index would read outside its
array, as a positive one past the end always could). Under ``NUMBA_BOUNDSCHECK=1`` numba
checks every index, and a negative one raises: the kernels are run that way here, on the
paths a monitor takes (quiet, episode, isolation, bad samples, gaps) and in the simulated
rig, in a process of their own with a cache of their own."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def _python(code: str, tmp_path: Path, boundscheck: bool) -> subprocess.CompletedProcess:
    env = {
        **os.environ,
        "PYTHONPATH": f"{tmp_path}{os.pathsep}{REPO}",
        "NUMBA_BOUNDSCHECK": "1" if boundscheck else "0",
        "NUMBA_CACHE_DIR": str(tmp_path / ("cache-checked" if boundscheck else "cache")),
    }
    if boundscheck:
        # without LLVM's optimisations (measured 51 -> 39 s of CPU; numba cannot cache a
        # bounds-checked kernel, so every run compiles them): a bounds check is part of the
        # program's meaning, which no optimisation level changes (an optimiser drops only a
        # check it proves can never fail)
        env["NUMBA_OPT"] = "0"
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        env=env,
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=900,
    )


def test_an_index_is_taken_as_given_and_bounds_checks_catch_a_negative_one(tmp_path):
    package = tmp_path / "indexpkg"
    package.mkdir()
    (package / "__init__.py").write_text(
        textwrap.dedent("""
        from fdi_daemon.core.compiled import jit

        @jit
        def at(a, k):
            return a[k]
    """)
    )
    # a view into a larger array: index -1 reads the element before the view (4.0, inside
    # the base array's memory) where a wrap-around would read the view's last one (9.0)
    code = """
        import numpy as np
        from indexpkg import at
        a = np.arange(10.0)[5:]
        print(at(a, 3))
        try:
            print(at(a, -1))
        except IndexError:
            print("IndexError")
    """
    plain = _python(code, tmp_path, boundscheck=False)
    checked = _python(code, tmp_path, boundscheck=True)
    assert plain.returncode == 0 and checked.returncode == 0, plain.stderr + checked.stderr
    assert plain.stdout.split() == ["8.0", "4.0"]  # not wrapped around to 9.0
    assert checked.stdout.split() == ["8.0", "IndexError"]


@pytest.mark.slow  # compiles every kernel afresh, bounds-checked (numba caches none)
def test_the_kernels_index_inside_their_arrays_under_bounds_checks(tmp_path):
    code = f"""
        import math, sys
        import numpy as np
        sys.path.insert(0, {str(REPO / "tests")!r})
        from conftest_detect import scenario_recording, sim_rig_model
        from fdi_daemon.bench.reference_chain import ReferenceChain
        from fdi_daemon.detect.monitor import Monitor
        from fdi_daemon.io.recordings import Recording
        from fdi_daemon.io.sample import Sample

        rec = scenario_recording("test_case_2", seed=0, duration_s=6.0)  # the rig's kernels
        monitor = Monitor(sim_rig_model())
        monitor.warm_up()
        events, _ = monitor.run(rec)
        kinds = [e["kind"] for e in events]
        assert "friction_isolated" in kinds, kinds
        # per sample, with a NaN, a duplicate and a gap
        cols = rec.columns
        stepper = Monitor(sim_rig_model())
        for k in range(600):
            accel = math.nan if k == 300 else float(cols["accel"][k])
            seq = k if k < 400 else k + 5
            stepper.step(Sample(seq, float(cols["t"][k]), float(cols["v_in"][k]), accel))
        stepper.step(Sample(seq, float(cols["t"][599]), 0.0, 0.0))
        model = sim_rig_model()
        ref = ReferenceChain.from_model(model, monitor.detector.window_samples)
        ref.run(np.asarray(cols["v_in"][:2000]), np.asarray(cols["accel"][:2000]))
        print("ok", len(events))
    """
    done = _python(code, tmp_path, boundscheck=True)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.split()[0] == "ok"
