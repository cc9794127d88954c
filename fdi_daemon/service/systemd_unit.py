"""The systemd unit of the daemon, written for the `fdi` of this install.

One text for every case: the system service ``fdi.service``, the per-rig template
``fdi@.service`` (instance name = rig) and their ``--user`` variants. ``systemd/`` in the
repository holds the two system units rendered for ``/usr/local/bin/fdi`` (what ``sudo pip
install .`` gives); `fdi service install` renders them with the real path of the running
``fdi`` (venv, pipx) instead. See docs/service.md, "As a systemd service".

A user manager cannot switch users, set groups, filter devices or IP traffic (cgroup BPF),
nor, without unprivileged user namespaces, build the mount sandbox: ``--user`` units keep
the seccomp-based hardening (NoNewPrivileges, SystemCallFilter, RestrictAddressFamilies ...)
and leave the rest out.
"""

from __future__ import annotations

import ipaddress
import shutil
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from fdi_daemon.errors import UserError

__all__ = ["UnitSpec", "render_unit", "unit_name", "installed_fdi", "installed_docs", "SHIPPED_FDI"]

#: the ExecStart program of the units shipped in systemd/ (``sudo pip install .``)
SHIPPED_FDI = "/usr/local/bin/fdi"
#: where ``sudo pip install .`` puts docs/service.md (pyproject's data-files)
SHIPPED_DOCS = "/usr/local/share/doc/fdi/service.md"
#: IPAddressAllow= words systemd knows besides addresses and prefixes
IP_WORDS = ("any", "localhost", "link-local", "multicast")


@dataclass(frozen=True)
class UnitSpec:
    """What varies between installs: the program, the docs file, the kind of unit."""

    fdi: str  #: absolute path of the ``fdi`` console script
    docs: str | None  #: absolute path of service.md, or None (no Documentation= line)
    template: bool = False  #: ``fdi@.service``, one daemon per rig (%i)
    user: bool = False  #: for the user manager (``systemctl --user``)
    allow_ip: tuple[str, ...] = field(default_factory=tuple)  #: IPAddressAllow= beyond localhost
    serial: bool = True  #: may open serial ports (False: PrivateDevices=yes, no dialout group)


def unit_name(template: bool) -> str:
    return "fdi@.service" if template else "fdi.service"


def check_allow_ip(value: str) -> str:
    """An IPAddressAllow= entry: an address, a prefix (10.0.0.0/8) or one of `IP_WORDS`."""
    if value in IP_WORDS:
        return value
    try:
        return str(ipaddress.ip_address(value))
    except ValueError:
        pass
    try:
        return str(ipaddress.ip_network(value, strict=False))
    except ValueError:
        raise UserError(
            f"--allow-ip {value!r}: not an IP address, a prefix like 10.0.0.0/8, "
            f"or one of {', '.join(IP_WORDS)}"
        ) from None


def installed_fdi() -> str:
    """The ``fdi`` console script of this install: beside the running Python (a venv or
    pipx keeps both in one bin folder), else the one on PATH."""
    beside = Path(sys.executable).parent / "fdi"
    if beside.is_file():
        return str(beside.absolute())
    found = shutil.which("fdi")
    if found is None:
        raise UserError(
            f"no fdi program beside {sys.executable} nor on PATH; install the package "
            "(pip install .) and run `fdi service install` from that install"
        )
    return str(Path(found).absolute())


def installed_docs() -> str | None:
    """docs/service.md of this install: ``<prefix>/share/doc/fdi/service.md`` (pip
    installs it there), else the source tree's (an editable install), else None."""
    for candidate in (
        Path(sys.prefix) / "share" / "doc" / "fdi" / "service.md",
        Path(__file__).resolve().parents[2] / "docs" / "service.md",
    ):
        if candidate.is_file():
            return str(candidate)
    return None


def _header(spec: UnitSpec) -> list[str]:
    scope = " --user" if spec.user else ""
    sudo = "" if spec.user else "sudo "
    if spec.template:
        return [
            "# fdi@.service: one fdi daemon per rig on one host; the instance name is the rig",
            '# (see docs/service.md, "Many rigs on one host"). Written by',
            f"# `fdi service install{scope} --instance RIG`, which prints the next steps:",
            f"#   {sudo}systemctl{scope} daemon-reload",
            f"#   {sudo}systemctl{scope} enable --now fdi@press3 fdi@press4 ...",
        ]
    return [
        "# fdi: on-line friction fault detection next to the rig (see docs/service.md).",
        f"# Written by `fdi service install{scope}`, which prints the next steps:",
        f"#   {sudo}systemctl{scope} daemon-reload && {sudo}systemctl{scope} enable --now fdi",
    ]


def _config_path(spec: UnitSpec) -> str:
    """/etc/fdi/... for the system manager; %E (= $XDG_CONFIG_HOME) for a user's."""
    base = "%E/fdi" if spec.user else "/etc/fdi"
    return f"{base}/%i.yaml" if spec.template else f"{base}/rig.yaml"


def _directories(spec: UnitSpec) -> list[str]:
    sub = "fdi/%i" if spec.template else "fdi"
    lines = []
    if not spec.user:
        lines += ["# Dedicated transient user; serial ports through the dialout group."]
        lines += ["DynamicUser=yes", "SupplementaryGroups=dialout"]
        if not spec.serial:
            lines[-3:] = ["# Dedicated transient user.", "DynamicUser=yes"]
    lines += [
        "# Relative output paths in the config land in $STATE_DIRECTORY"
        + (" (/var/lib/" + sub + ")" if not spec.user else " (%S/" + sub + ")")
        + ":",
        "# events.jsonl, recordings/, state.json, trend.sqlite. The status socket can go to",
        "# $RUNTIME_DIRECTORY" + (f" (/run/{sub})" if not spec.user else f" (%t/{sub})") + ".",
        f"StateDirectory={sub}",
        "StateDirectoryMode=0750",
        f"LogsDirectory={sub}",
        f"RuntimeDirectory={sub}",
        "RuntimeDirectoryMode=0750",
        "# The compiled kernels (numba's cache; the install tree may be read-only).",
        f"CacheDirectory={sub}",
        "ConfigurationDirectory=fdi",
        "# Files the daemon writes: owner read/write, group read, nobody else.",
        "UMask=0027",
    ]
    return lines


def _sandbox(spec: UnitSpec) -> list[str]:
    """Mount namespace, device and IP filters: system manager only."""
    if spec.user:
        return []
    allow = " ".join(("localhost",) + spec.allow_ip)
    return [
        "ProtectSystem=strict",
        "ProtectHome=yes",
        "PrivateTmp=yes",
        "ProtectKernelTunables=yes",
        "ProtectKernelModules=yes",
        "ProtectKernelLogs=yes",
        "ProtectControlGroups=yes",
        "ProtectClock=yes",
        "ProtectHostname=yes",
        "ProtectProc=invisible",
        "# /proc shows processes only (no /proc/sys, /proc/meminfo ...).",
        "ProcSubset=pid",
        "PrivateMounts=yes",
        "CapabilityBoundingSet=",
        "AmbientCapabilities=",
        "# IP traffic: loopback plus the field devices, brokers and scrapers allowed at",
        "# install (`fdi service install --allow-ip 10.1.2.0/24`); everything else dropped.",
        "IPAddressDeny=any",
        f"IPAddressAllow={allow}",
        *_devices(spec),
    ]


def _devices(spec: UnitSpec) -> list[str]:
    if not spec.serial:
        return [
            "# No device nodes but /dev/null and the like (`--no-serial`).",
            "PrivateDevices=yes",
        ]
    return [
        "# Devices: only serial ports (USB adapters and on-board UARTs).",
        "DevicePolicy=closed",
        "DeviceAllow=char-ttyUSB rw",
        "DeviceAllow=char-ttyACM rw",
        "DeviceAllow=char-ttyS rw",
    ]


def render_unit(spec: UnitSpec) -> str:
    """The unit file's text for ``spec``."""
    rig = ", rig %i" if spec.template else ""
    state = "this rig's own" if spec.template else "StateDirectory"
    lines = [
        *_header(spec),
        "[Unit]",
        f"Description=fdi friction fault detection and isolation daemon{rig}",
    ]
    if spec.docs is not None:
        lines.append(f"Documentation=file://{spec.docs}")
    if not spec.user:
        lines += ["Wants=network-online.target", "After=network-online.target"]
    lines += [
        "",
        "[Service]",
        "Type=notify",
        "NotifyAccess=main",
        f"ExecStart={spec.fdi} run --config {_config_path(spec)}",
        "ExecReload=/bin/kill -HUP $MAINPID",
        "# The loop pings the watchdog every WatchdogSec/2 while it runs, samples or not: a hung",
        "# daemon is restarted, a dead field link is not (it is a status and a link_lost event;",
        "# the daemon reconnects with its own backoff). The alarm state survives the restart",
        f"# (state.json in {state}).",
        "WatchdogSec=30",
        "TimeoutStartSec=60",
        "TimeoutStopSec=20",
        "Restart=on-failure",
        "RestartSec=5",
        "",
        *_directories(spec),
        "",
        "# Hardening",
        "NoNewPrivileges=yes",
        *_sandbox(spec),
        "RestrictAddressFamilies=AF_UNIX AF_INET AF_INET6",
        "RestrictNamespaces=yes",
        "RestrictRealtime=yes",
        "RestrictSUIDSGID=yes",
        "LockPersonality=yes",
        "# MemoryDenyWriteExecute stays off: numba's JIT needs writable+executable pages.",
        "SystemCallArchitectures=native",
        "SystemCallFilter=@system-service",
        "SystemCallFilter=~@privileged @resources",
        "# A filtered call fails with EPERM instead of killing the daemon (libraries probe some).",
        "SystemCallErrorNumber=EPERM",
        "",
        "[Install]",
        f"WantedBy={'default.target' if spec.user else 'multi-user.target'}",
    ]
    return "\n".join(lines) + "\n"


def shipped_spec(template: bool) -> UnitSpec:
    """The spec of systemd/fdi.service and systemd/fdi@.service (``sudo pip install .``)."""
    return UnitSpec(fdi=SHIPPED_FDI, docs=SHIPPED_DOCS, template=template)


def allow_list(values: Sequence[str]) -> tuple[str, ...]:
    """--allow-ip values checked, in order, without repeats."""
    return tuple(dict.fromkeys(check_allow_ip(v) for v in values))
