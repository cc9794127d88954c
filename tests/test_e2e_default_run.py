"""`fdi run` with no config: a newcomer sees the friction fault detected and isolated."""

import json
import re
import subprocess
import sys

import pytest

from fdi_daemon.service.config import load_config

DEFAULT = load_config()


@pytest.mark.slow
@pytest.mark.skipif(
    not DEFAULT.model_path.exists(),
    reason=f"{DEFAULT.model_path.name} is not in fdi_daemon/data yet",
)
@pytest.mark.usefixtures("compiled_kernel_cache")
def test_default_run_detects_the_scheduled_friction_fault(tmp_path, monkeypatch):
    monkeypatch.delenv("STATE_DIRECTORY", raising=False)
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "xdg"))
    (fault,) = DEFAULT.simulated_device["faults"]
    result = subprocess.run(
        [sys.executable, "-m", "fdi_daemon", "run", "--duration", str(fault["at_s"] + 25.0)],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=tmp_path,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    out = result.stdout
    times = {}
    for kind in ("FAULT DETECTED", "FRICTION ISOLATED"):
        match = re.search(rf"t=\s*([0-9.]+) s\s+{kind}", out)
        assert match, f"no {kind} line in\n{out}"
        times[kind] = float(match.group(1))
    assert fault["at_s"] <= times["FAULT DETECTED"] <= times["FRICTION ISOLATED"]
    assert times["FRICTION ISOLATED"] <= fault["at_s"] + 10.0
    events = [
        json.loads(line)
        for line in (tmp_path / "xdg" / "fdi" / "events.jsonl").read_text().splitlines()
    ]
    kinds = [e["kind"] for e in events]
    assert "fault_detected" in kinds and "friction_isolated" in kinds
    assert not [
        e
        for e in events
        if e["kind"] in ("fault_detected", "other_fault") and e["t"] < fault["at_s"]
    ], "false alarm before the fault"
    assert re.search(r"fdi run: \d+ samples", out)
