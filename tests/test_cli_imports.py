"""Commands that do not run the monitor never import numba (its import alone is a large
part of a command's start): checked in a fresh interpreter, on sys.modules."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

PROBE = """
import sys
from fdi_daemon.cli import main
try:
    code = main(sys.argv[1:])
except SystemExit as exc:
    code = exc.code
print("numba" in sys.modules, code)
"""


@pytest.mark.parametrize(
    "argv",
    [
        ["--help"],
        ["replay", "--help"],
        ["convert", "IN.csv", "OUT.parquet"],
    ],
    ids=["help", "replay-help", "convert"],
)
def test_commands_that_do_not_run_the_monitor_never_import_numba(tmp_path, argv):
    (tmp_path / "IN.csv").write_text("# fs: 256\nt,v_in,accel\n0,1,2\n0.00390625,1,2\n")
    done = subprocess.run(
        [sys.executable, "-c", PROBE, *argv],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
        env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"},
    )
    last = done.stdout.strip().splitlines()[-1]
    assert last == "False 0", done.stdout[-500:] + done.stderr[-2000:]


SLOW_IMPORTS = ("scipy.signal", "matplotlib", "dask", "pydantic", "pyarrow")

PROBE_SLOW = """
import sys
from fdi_daemon.cli import main
code = main(sys.argv[1:])
print(sorted(m for m in %r if m in sys.modules), code)
"""


def test_replay_of_a_short_file_imports_none_of_the_slow_packages(tmp_path):
    """The fixed cost of `fdi replay` (issue 45): the monitor needs numba and numpy, not
    scipy.signal (core/filter_design.py), the plots, Dask, pydantic or (for a short CSV)
    pyarrow."""
    rows = "".join(f"{k / 256:.9f},{k},0.5,0.1\n" for k in range(512))
    (tmp_path / "IN.csv").write_text("# fs: 256\nt,seq,v_in,accel\n" + rows)
    model = REPO / "fdi_daemon" / "data" / "model_sim_rig.yaml"
    done = subprocess.run(
        [
            sys.executable,
            "-c",
            PROBE_SLOW % (SLOW_IMPORTS,),
            "replay",
            "IN.csv",
            "--model",
            str(model),
        ],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=600,
        env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"},
    )
    assert done.stdout.strip().splitlines()[-1] == "[] 0", done.stdout[-500:] + done.stderr[-2000:]


def test_the_probe_sees_numba_when_the_monitor_runs(tmp_path):
    """The counter-check: the same probe reports numba once the monitor is imported."""
    code = PROBE.replace("from fdi_daemon.cli import main", "import fdi_daemon.detect.monitor")
    code = code.replace("code = main(sys.argv[1:])", "code = 0")
    done = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=300,
        env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"},
    )
    assert done.stdout.strip().splitlines()[-1] == "True 0", done.stderr[-2000:]
