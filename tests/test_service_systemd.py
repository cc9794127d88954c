"""The systemd unit: notify type, watchdog, restart, user, directories, hardening."""

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

UNIT = Path(__file__).resolve().parents[1] / "systemd" / "fdi.service"
TEMPLATE = UNIT.with_name("fdi@.service")


def directives(unit: Path = UNIT):
    found: dict[str, list[str]] = {}
    for line in unit.read_text().splitlines():
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
    for key in ("StateDirectory", "LogsDirectory", "RuntimeDirectory", "CacheDirectory"):
        assert d[key] == ["fdi"]
    for key in ("NoNewPrivileges", "ProtectHome", "PrivateTmp"):
        assert d[key] == ["yes"], key
    assert d["ProtectSystem"] == ["strict"]
    assert set(d["RestrictAddressFamilies"][0].split()) == {"AF_UNIX", "AF_INET", "AF_INET6"}
    assert d["DevicePolicy"] == ["closed"] and any("ttyUSB" in v for v in d["DeviceAllow"])
    assert "fdi run --config" in d["ExecStart"][0]
    assert "HUP" in d["ExecReload"][0]


@pytest.mark.skipif(
    shutil.which("systemd-analyze") is None, reason="systemd-analyze is not installed"
)
def test_systemd_analyze_verify_passes(tmp_path):
    # verify checks that ExecStart's program exists: point it at this environment's fdi
    fdi = shutil.which("fdi") or sys.executable
    unit = tmp_path / "fdi.service"
    unit.write_text(UNIT.read_text().replace("/usr/local/bin/fdi", fdi))
    result = subprocess.run(
        ["systemd-analyze", "verify", str(unit)],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
    )
    assert result.returncode == 0, result.stderr
    assert "fdi.service" not in result.stderr, result.stderr  # no warnings about the unit


def test_template_unit_is_the_service_with_per_rig_config_and_directories():
    """fdi@.service: everything of fdi.service (hardening included), but per rig (%i)."""
    single, template = directives(), directives(TEMPLATE)
    per_rig = {
        "Description",
        "ExecStart",
        "StateDirectory",
        "LogsDirectory",
        "RuntimeDirectory",
        "CacheDirectory",
    }
    assert {k: v for k, v in template.items() if k not in per_rig} == {
        k: v for k, v in single.items() if k not in per_rig
    }
    assert template["ExecStart"] == ["/usr/local/bin/fdi run --config /etc/fdi/%i.yaml"]
    for key in ("StateDirectory", "LogsDirectory", "RuntimeDirectory", "CacheDirectory"):
        assert template[key] == ["fdi/%i"], key
    assert "%i" in template["Description"][0]


def _installed_copy(unit: Path, folder: Path) -> Path:
    """The unit in ``folder`` with ExecStart pointing at this environment's fdi."""
    fdi = shutil.which("fdi") or sys.executable
    copy = folder / unit.name
    copy.write_text(unit.read_text().replace("/usr/local/bin/fdi", fdi))
    return copy


@pytest.mark.skipif(
    shutil.which("systemd-analyze") is None, reason="systemd-analyze is not installed"
)
def test_systemd_analyze_verify_passes_for_a_rig_instance(tmp_path):
    _installed_copy(TEMPLATE, tmp_path)
    result = subprocess.run(
        ["systemd-analyze", "verify", str(tmp_path / "fdi@press3.service")],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
    )
    assert result.returncode == 0, result.stderr
    assert "fdi@" not in result.stderr, result.stderr  # no warnings about the unit


def _exposure(unit: Path) -> float | None:
    result = subprocess.run(
        ["systemd-analyze", "security", "--offline=yes", str(unit)],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=unit.parent,
    )
    match = re.search(r"Overall exposure level for \S+: ([0-9.]+)", result.stdout)
    return float(match.group(1)) if match else None


@pytest.mark.skipif(
    shutil.which("systemd-analyze") is None, reason="systemd-analyze is not installed"
)
def test_a_rig_instance_is_as_hardened_as_the_single_service(tmp_path):
    single = _exposure(_installed_copy(UNIT, tmp_path))
    if single is None:
        pytest.skip("this systemd-analyze has no offline security check")
    _installed_copy(TEMPLATE, tmp_path)
    assert _exposure(tmp_path / "fdi@press3.service") == single <= 1.7
