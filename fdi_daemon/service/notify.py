"""sd_notify: tell systemd that the daemon is ready, alive, stopping, and what it does.

Speaks the protocol directly (no libsystemd): one AF_UNIX datagram per message to the
socket named by ``$NOTIFY_SOCKET``; a leading ``@`` names an abstract-namespace socket.
Without ``NOTIFY_SOCKET`` (not started by systemd) every call is a no-op. A failed send is
logged (once per kind of failure, then counted), never silently swallowed.

The watchdog (``WatchdogSec=`` in the unit, ``$WATCHDOG_USEC`` here) is fed by the loop
every half period for as long as it runs, samples or not: it means "the process and its
loop are alive". A field link that delivers nothing is a status and a ``link_lost`` event,
not a reason for systemd to restart the daemon.
"""

from __future__ import annotations

import logging
import os
import socket

log = logging.getLogger("fdi.notify")


class Notifier:
    """One datagram socket to systemd's notify socket (or nothing outside systemd)."""

    def __init__(self, address: str | None = None) -> None:
        address = os.environ.get("NOTIFY_SOCKET") if address is None else address
        self.address = address or None
        self.sent = 0
        self.errors = 0
        self._sock: socket.socket | None = None
        self._logged: set[str] = set()
        if self.address is not None:
            if not (self.address.startswith("/") or self.address.startswith("@")):
                log.error(
                    "NOTIFY_SOCKET=%r is neither a path nor an abstract '@' name; "
                    "sd_notify disabled",
                    self.address,
                )
                self.address = None
            else:
                self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)

    @property
    def enabled(self) -> bool:
        return self._sock is not None

    def _target(self) -> str | bytes:
        assert self.address is not None
        if self.address.startswith("@"):
            return b"\0" + self.address[1:].encode()
        return self.address

    def send(self, *fields: str) -> bool:
        """Send ``KEY=value`` fields as one message; True when delivered."""
        if self._sock is None:
            return False
        message = "\n".join(fields).encode()
        try:
            self._sock.sendto(message, self._target())
        except OSError as exc:
            self.errors += 1
            kind = type(exc).__name__
            if kind not in self._logged:
                self._logged.add(kind)
                log.error(
                    "sd_notify to %s failed: %s (further %s failures are counted, not logged)",
                    self.address,
                    exc,
                    kind,
                )
            return False
        self.sent += 1
        return True

    def ready(self, status: str | None = None) -> bool:
        return self.send("READY=1", *([f"STATUS={status}"] if status else []))

    def watchdog(self) -> bool:
        return self.send("WATCHDOG=1")

    def status(self, text: str) -> bool:
        return self.send(f"STATUS={text}")

    def reloading(self) -> bool:
        return self.send("RELOADING=1")

    def stopping(self, status: str | None = None) -> bool:
        return self.send("STOPPING=1", *([f"STATUS={status}"] if status else []))

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None


def watchdog_period_s(environ: dict[str, str] | None = None) -> float | None:
    """Half the watchdog timeout systemd asked for (``$WATCHDOG_USEC``), or None.

    ``$WATCHDOG_PID``, when set, must be our pid (else the watchdog is someone else's).
    """
    env = os.environ if environ is None else environ
    usec = env.get("WATCHDOG_USEC")
    if not usec:
        return None
    pid = env.get("WATCHDOG_PID")
    if pid and pid != str(os.getpid()):
        return None
    try:
        value = int(usec)
    except ValueError:
        log.error("WATCHDOG_USEC=%r is not a whole number; watchdog pings disabled", usec)
        return None
    return value / 2e6 if value > 0 else None
