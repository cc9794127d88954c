"""The systemd unit: notify type, watchdog, restart, user, directories, hardening."""

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from fdi_daemon.service.systemd_unit import render_unit, shipped_spec, unit_name

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
    assert d["ProcSubset"] == ["pid"] and d["UMask"] == ["0027"]
    assert d["IPAddressDeny"] == ["any"] and d["IPAddressAllow"] == ["localhost"]


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
    assert _exposure(tmp_path / "fdi@press3.service") == single <= 1.3


def _install(tmp_path: Path, *options: str) -> Path:
    """`fdi service install OPTIONS --unit-dir tmp_path` in-process; the unit written."""
    from fdi_daemon.cli import main

    assert main(["service", "install", *options, "--unit-dir", str(tmp_path)]) == 0
    (unit,) = tmp_path.glob("fdi*.service")
    return unit


def _verify(unit: Path, name: str, user: bool, tmp_path: Path) -> subprocess.CompletedProcess:
    # a user manager needs a runtime folder even offline
    env = {**os.environ, "XDG_RUNTIME_DIR": str(tmp_path)}
    return subprocess.run(
        ["systemd-analyze", "verify", *(["--user"] if user else []), name],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=unit.parent,
        env=env,
    )


def test_the_shipped_units_are_the_rendered_ones():
    """systemd/*.service are `render_unit` for /usr/local/bin/fdi: one text, never edited apart."""
    for template in (False, True):
        spec = shipped_spec(template)
        assert (UNIT.parent / unit_name(template)).read_text() == render_unit(spec)


@pytest.mark.parametrize(
    "options, name, user",
    [
        ((), "fdi.service", False),
        (("--instance", "press3"), "fdi@press3.service", False),
        (("--user",), "fdi.service", True),
        (("--user", "--instance", "press3"), "fdi@press3.service", True),
    ],
)
def test_install_writes_a_unit_for_this_fdi_that_verifies(tmp_path, capsys, options, name, user):
    unit = _install(tmp_path, *options)
    d = directives(unit)
    fdi = d["ExecStart"][0].split()[0]
    assert Path(fdi).is_file() and Path(fdi).parent == Path(sys.executable).parent
    docs = d["Documentation"][0].removeprefix("file://")
    assert Path(docs).is_file() and Path(docs).name == "service.md"
    assert ("--user" in capsys.readouterr().out) == user  # the next commands printed
    if user:
        assert d["WantedBy"] == ["default.target"] and "DynamicUser" not in d
        assert "%E/fdi/" in d["ExecStart"][0]
    if shutil.which("systemd-analyze") is None:
        pytest.skip("systemd-analyze is not installed")
    result = _verify(unit, name, user, tmp_path)
    assert result.returncode == 0, result.stderr
    assert "fdi" not in result.stderr, result.stderr  # no warnings about the unit


def test_install_allow_list_and_serial_option(tmp_path):
    d = directives(_install(tmp_path, "--allow-ip", "10.1.2.0/24", "--allow-ip", "192.168.0.7"))
    assert d["IPAddressDeny"] == ["any"]
    assert d["IPAddressAllow"] == ["localhost 10.1.2.0/24 192.168.0.7"]
    assert "DeviceAllow" in d and "PrivateDevices" not in d
    d = directives(_install(tmp_path, "--no-serial", "--force"))
    assert d["PrivateDevices"] == ["yes"] and "DeviceAllow" not in d
    assert "SupplementaryGroups" not in d


@pytest.mark.parametrize(
    "options, message",
    [
        (("--allow-ip", "10.1.2.300"), "--allow-ip '10.1.2.300': not an IP address"),
        (("--instance", "a/b"), "--instance 'a/b': a rig name is"),
        (("--user", "--allow-ip", "10.0.0.1"), "a user manager cannot filter IP"),
    ],
)
def test_install_refuses_bad_options_in_one_line(tmp_path, capsys, options, message):
    from fdi_daemon.cli import main

    assert main(["service", "install", *options, "--unit-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not list(tmp_path.iterdir())


def test_install_replaces_a_different_unit_only_with_force(tmp_path, capsys):
    from fdi_daemon.cli import main

    unit = _install(tmp_path)
    unit.write_text(unit.read_text().replace("WatchdogSec=30", "WatchdogSec=60"))
    assert main(["service", "install", "--unit-dir", str(tmp_path)]) == 2
    assert "differs" in capsys.readouterr().err and "WatchdogSec=60" in unit.read_text()
    _install(tmp_path, "--force")
    assert "WatchdogSec=30" in unit.read_text()
    assert main(["service", "install", "--unit-dir", str(tmp_path)]) == 0  # same text: fine
    assert main(["service", "install", "--dry-run", "--unit-dir", str(tmp_path / "x")]) == 0
    assert "ExecStart=" in capsys.readouterr().out and not (tmp_path / "x").exists()


@pytest.mark.skipif(
    shutil.which("systemd-analyze") is None, reason="systemd-analyze is not installed"
)
@pytest.mark.parametrize("options, most", [((), 1.3), (("--no-serial",), 1.2)])
def test_exposure_of_an_installed_unit(tmp_path, options, most):
    """`systemd-analyze security` (systemd 252, offline): 1.3 with serial ports, 1.1 without
    (docs/service.md); the rest is what the daemon needs (network, AF_UNIX, numba's W+X)."""
    exposure = _exposure(_install(tmp_path, *options))
    if exposure is None:
        pytest.skip("this systemd-analyze has no offline security check")
    assert exposure <= most
