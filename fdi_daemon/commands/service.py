"""`fdi service install`: write the systemd unit for this install's `fdi` and say what next.

ExecStart= names the running install's ``fdi`` (a venv or pipx works, not only
/usr/local/bin), Documentation= its installed docs/service.md. ``--instance RIG`` writes the
template ``fdi@.service`` (one daemon per rig); ``--user`` a unit for the user's manager
(~/.config/systemd/user). The unit text is `fdi_daemon.service.systemd_unit`'s.
"""

from __future__ import annotations

import argparse
import os
import re
from pathlib import Path

from fdi_daemon.errors import UserError

HELP = "install the daemon as a systemd service (writes the unit for this install's fdi)"

#: a systemd instance name: letters, digits and :_.- (no @ or /)
_INSTANCE = re.compile(r"^[A-Za-z0-9:_.\-]+$")


def configure(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    install = sub.add_parser(
        "install",
        help="write fdi.service (or fdi@.service with --instance) and print the next commands",
        description=HELP,
    )
    install.add_argument(
        "--user", action="store_true", help="a unit for `systemctl --user` (no root needed)"
    )
    install.add_argument(
        "--instance",
        metavar="RIG",
        help="one daemon per rig: write the template fdi@.service; RIG names the config "
        "(/etc/fdi/RIG.yaml, with --user ~/.config/fdi/RIG.yaml)",
    )
    install.add_argument(
        "--unit-dir",
        "--prefix",
        dest="unit_dir",
        type=Path,
        metavar="DIR",
        help="folder to write the unit to (default /etc/systemd/system, with --user "
        "$XDG_CONFIG_HOME/systemd/user)",
    )
    install.add_argument(
        "--allow-ip",
        action="append",
        default=[],
        metavar="ADDR",
        help="an address or prefix the daemon may talk to besides localhost (field device, "
        "MQTT broker, Prometheus); repeat it; 'any' lifts the IP filter",
    )
    install.add_argument(
        "--no-serial",
        dest="serial",
        action="store_false",
        help="the rig's link is Modbus TCP or a replay: no serial ports, no device nodes "
        "(PrivateDevices=yes, a lower systemd-analyze security exposure)",
    )
    install.add_argument(
        "--force", action="store_true", help="replace a unit file that differs from this one"
    )
    install.add_argument(
        "--dry-run", action="store_true", help="print the unit and where it would go; write nothing"
    )


def default_unit_dir(user: bool) -> Path:
    """systemd's folder for units the administrator (or the user) installs."""
    if not user:
        return Path("/etc/systemd/system")
    xdg = os.environ.get("XDG_CONFIG_HOME", "")
    base = Path(xdg) if xdg and Path(xdg).is_absolute() else Path.home() / ".config"
    return base / "systemd" / "user"


def next_steps(user: bool, instance: str | None, config: str) -> list[str]:
    """The commands that take the written unit into service."""
    sudo = "" if user else "sudo "
    scope = " --user" if user else ""
    unit = f"fdi@{instance}" if instance else "fdi"
    return [
        f"put the rig config at {config} (its model path relative to it)",
        f"{sudo}systemctl{scope} daemon-reload",
        f"{sudo}systemctl{scope} enable --now {unit}",
        f"journalctl{scope} -u {unit} -f",
    ]


def run(args: argparse.Namespace) -> int:
    from fdi_daemon.service.systemd_unit import (
        UnitSpec,
        allow_list,
        installed_docs,
        installed_fdi,
        render_unit,
        unit_name,
    )

    instance = args.instance
    if instance is not None and not _INSTANCE.match(instance):
        raise UserError(f"--instance {instance!r}: a rig name is letters, digits and : _ . - only")
    spec = UnitSpec(
        fdi=installed_fdi(),
        docs=installed_docs(),
        template=instance is not None,
        user=args.user,
        allow_ip=allow_list(args.allow_ip),
        serial=args.serial,
    )
    if args.user and spec.allow_ip:
        raise UserError("--allow-ip: a user manager cannot filter IP traffic (leave --user out)")
    text = render_unit(spec)
    target = ((args.unit_dir or default_unit_dir(args.user)) / unit_name(spec.template)).absolute()
    config_dir = "~/.config/fdi" if args.user else "/etc/fdi"
    config = f"{config_dir}/{instance or 'rig'}.yaml"
    if args.dry_run:
        print(f"# {target} (dry run, nothing written)")
        print(text, end="")
        return 0
    _write(target, text, args.force)
    print(f"wrote {target} (ExecStart={spec.fdi})")
    print("next:")
    for step in next_steps(args.user, instance, config):
        print(f"  {step}")
    return 0


def _write(target: Path, text: str, force: bool) -> None:
    """Write the unit; one that differs is replaced only with --force."""
    try:
        if target.is_file() and target.read_text() != text and not force:
            raise UserError(
                f"{target} exists and differs from this unit; --force replaces it "
                "(--dry-run shows the new one)"
            )
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(text)
    except PermissionError:
        raise UserError(
            f"{target}: permission denied; run it with sudo, or install for your user "
            "with --user, or name another folder with --unit-dir"
        ) from None
    except OSError as exc:
        raise UserError(f"{target}: {exc.strerror}") from None
