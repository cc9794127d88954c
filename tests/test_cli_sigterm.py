"""SIGTERM to an fdi command (a user's `kill`, `timeout`, a service manager) stops it as
Ctrl-C does: the processes it started are stopped, one line says so, exit 143."""

from __future__ import annotations

import signal

import pytest
from process_support import start_fdi, survivors, wait_for_children

from fdi_daemon.cli import main


@pytest.mark.slow  # starts the device and the daemon
@pytest.mark.parametrize(
    "started", [1, 2], ids=["while the device starts", "with device and daemon running"]
)
def test_sigterm_stops_the_command_and_the_processes_it_started(tmp_path, started):
    # `fdi bench` runs a simulated device and a daemon as subprocesses for its end-to-end
    # part; Python's default for SIGTERM ended the bench at once and left both running, and
    # a SIGTERM while the device was still starting left the device behind (it then wrote
    # its address into the closed pipe: "cannot serve the modbus-tcp device: Broken pipe")
    proc = start_fdi("bench", "--quick", "--e2e", cwd=tmp_path)
    seen = wait_for_children(proc, started, command="fdi_daemon")
    proc.send_signal(signal.SIGTERM)  # the bench itself, not its process group
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signal.SIGTERM, (proc.returncode, err)
    assert "Traceback" not in err, err
    assert err.strip().splitlines()[-1] == "fdi bench: terminated"
    assert survivors(seen) == []


def test_a_command_leaves_the_sigterm_handler_as_it_found_it(tmp_path, capsys):
    before = signal.getsignal(signal.SIGTERM)
    assert (
        main(["replay", str(tmp_path / "missing.csv"), "--model", str(tmp_path / "missing.yaml")])
        != 0
    )
    assert signal.getsignal(signal.SIGTERM) is before


def _words_printed(tmp_path, prelude: str, action: str) -> list[str]:
    """Run, in a fresh interpreter with a command's SIGTERM handling (as `main` installs
    it), ``prelude`` and then ``action`` (which sends SIGTERM to itself), then 5 s of sleep:
    the words printed ("terminated" when the signal ended it). No traceback is printed."""
    import subprocess
    import sys

    script = (
        "import signal, sys, time\n"
        "from fdi_daemon.cli import Terminated, _terminate, _unraisable_terminated\n"
        "signal.signal(signal.SIGTERM, _terminate)\n"
        "sys.unraisablehook = _unraisable_terminated(sys.unraisablehook)\n"
        + prelude
        + "try:\n"
        + "".join(f"    {line}\n" for line in action.splitlines())
        + "    time.sleep(5)\n"
        "    print('not terminated', flush=True)\n"
        "except Terminated:\n"
        "    print('terminated', flush=True)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script], cwd=tmp_path, capture_output=True, text=True, timeout=30
    )
    assert "Traceback" not in done.stderr, done.stderr
    return done.stdout.split()


def test_a_sigterm_during_an_import_ends_the_command_after_the_import(tmp_path):
    # raised inside the import machinery, `Terminated` broke the module being imported: a
    # SIGTERM to `fdi sim serve` while it imported numpy printed numpy's traceback and
    # "numpy._core.multiarray failed to import". The signal is delivered again after it
    (tmp_path / "slow_module.py").write_text(
        "import os, signal, time\n"
        "os.kill(os.getpid(), signal.SIGTERM)\n"
        "time.sleep(0.3)\n"
        "print('imported', flush=True)\n"
    )
    assert _words_printed(tmp_path, "", "import slow_module") == ["imported", "terminated"]


def test_a_sigterm_in_a_callback_from_c_ends_the_command_without_a_traceback(tmp_path):
    # a SIGTERM that arrived while numba compiled (llvmlite calls back into Python through
    # ctypes) raised `Terminated` where ctypes drops exceptions: "Exception ignored on
    # calling ctypes callback function", a traceback reached the user and the signal was
    # lost. It is delivered again after it; here libc's qsort calls back into Python
    prelude = (
        "import ctypes, ctypes.util, os\n"
        "libc = ctypes.CDLL(ctypes.util.find_library('c'))\n"
        "CMP = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.POINTER(ctypes.c_int),\n"
        "                       ctypes.POINTER(ctypes.c_int))\n"
        "def compare(a, b):\n"
        "    os.kill(os.getpid(), signal.SIGTERM)\n"
        "    time.sleep(0.01)\n"
        "    return a[0] - b[0]\n"
        "values = (ctypes.c_int * 2)(2, 1)\n"
    )
    action = (
        "libc.qsort(values, 2, ctypes.sizeof(ctypes.c_int), CMP(compare))\n"
        "print('sorted', flush=True)"
    )
    assert _words_printed(tmp_path, prelude, action) == ["sorted", "terminated"]
