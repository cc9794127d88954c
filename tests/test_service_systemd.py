"""The systemd unit: notify type, watchdog, restart, user, directories, hardening."""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

UNIT = Path(__file__).resolve().parents[1] / "systemd" / "fdi.service"


def directives():
    found: dict[str, list[str]] = {}
    for line in UNIT.read_text().splitlines():
        line = line.strip()
        if line and not line.startswith(("#", "[")):
            key, _, value = line.partition("=")
            found.setdefault(key, []).append(value)
    return found


def test_unit_has_the_required_settings():
    d = directives()
    assert d["Type"] == ["notify"]
    assert int(d["WatchdogSec"][0]) > 0
    assert d["Restart"] == ["on-failure"]
    assert d["DynamicUser"] == ["yes"] and "dialout" in d["SupplementaryGroups"][0]
    for key in ("StateDirectory", "LogsDirectory", "RuntimeDirectory"):
        assert d[key] == ["fdi"]
    for key in ("NoNewPrivileges", "ProtectHome", "PrivateTmp"):
        assert d[key] == ["yes"], key
    assert d["ProtectSystem"] == ["strict"]
    assert set(d["RestrictAddressFamilies"][0].split()) == {"AF_UNIX", "AF_INET", "AF_INET6"}
    assert d["DevicePolicy"] == ["closed"] and any("ttyUSB" in v for v in d["DeviceAllow"])
    assert "fdi run --config" in d["ExecStart"][0]
    assert "HUP" in d["ExecReload"][0]


@pytest.mark.skipif(shutil.which("systemd-analyze") is None,
                    reason="systemd-analyze is not installed")
def test_systemd_analyze_verify_passes(tmp_path):
    # verify checks that ExecStart's program exists: point it at this environment's fdi
    fdi = shutil.which("fdi") or sys.executable
    unit = tmp_path / "fdi.service"
    unit.write_text(UNIT.read_text().replace("/usr/local/bin/fdi", fdi))
    result = subprocess.run(["systemd-analyze", "verify", str(unit)], capture_output=True,
                            text=True, timeout=120, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "fdi.service" not in result.stderr, result.stderr  # no warnings about the unit
