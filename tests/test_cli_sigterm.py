"""SIGTERM to an fdi command (a user's `kill`, `timeout`, a service manager) stops it as
Ctrl-C does: the processes it started are stopped, one line says so, exit 143."""

from __future__ import annotations

import signal

import pytest

from fdi_daemon.cli import main
from process_support import start_fdi, survivors, wait_for_children


@pytest.mark.parametrize("started", [1, 2], ids=["while the device starts",
                                               "with device and daemon running"])
def test_sigterm_stops_the_command_and_the_processes_it_started(tmp_path, started):
    # `fdi bench` runs a simulated device and a daemon as subprocesses for its end-to-end
    # part; Python's default for SIGTERM ended the bench at once and left both running, and
    # a SIGTERM while the device was still starting left the device behind (it then wrote
    # its address into the closed pipe: "cannot serve the modbus-tcp device: Broken pipe")
    proc = start_fdi("bench", "--quick", cwd=tmp_path)
    seen = wait_for_children(proc, started, command="fdi_daemon")
    proc.send_signal(signal.SIGTERM)  # the bench itself, not its process group
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signal.SIGTERM, (proc.returncode, err)
    assert "Traceback" not in err, err
    assert err.strip().splitlines()[-1] == "fdi bench: terminated"
    assert survivors(seen) == []


def test_a_command_leaves_the_sigterm_handler_as_it_found_it(tmp_path, capsys):
    before = signal.getsignal(signal.SIGTERM)
    assert main(["replay", str(tmp_path / "missing.csv"), "--model",
                 str(tmp_path / "missing.yaml")]) != 0
    assert signal.getsignal(signal.SIGTERM) is before
