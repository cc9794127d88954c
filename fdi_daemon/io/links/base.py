"""The link interface, the reconnecting wrapper and the factory.

A link delivers `Sample`s from one data source. The daemon never talks to a bare link: it
wraps it in `ReconnectingLink`, whose ``read`` never raises; a dropped link turns into a
``link_lost`` event, reconnect attempts with capped exponential backoff (never a busy loop),
and a ``link_restored`` event. Sequence gaps and duplicates are *not* judged here: the
service sees ``Sample.seq`` and reports ``data_gap`` through the monitor.

Counters (``counters()``) are cumulative over reconnects, so a test can check that what it
injected (corrupted frames, lost samples, disconnects) equals what was counted.
"""

from __future__ import annotations

import abc
import contextlib
import time
from collections.abc import Callable, Mapping
from typing import Any

from fdi_daemon.errors import ConfigError
from fdi_daemon.io.known_keys import close_match
from fdi_daemon.io.sample import Sample


class LinkError(OSError):
    """The link cannot be opened or has dropped (device gone, port closed, timeout)."""


class SeqUnwrapper:
    """Turn a device's wrapping unsigned counter (u32 by default) into a growing integer.

    A step of less than half the counter range forward is a forward step; anything else is
    a backward step (a restarted device), kept as a backward jump so the service sees it.
    The first value is taken as is.
    """

    def __init__(self, bits: int = 32) -> None:
        self.modulus = 1 << bits
        self._last_raw: int | None = None
        self._value = 0

    def __call__(self, raw: int) -> int:
        if self._last_raw is None:
            self._value = raw
        else:
            step = (raw - self._last_raw) % self.modulus
            if step >= self.modulus // 2:
                step -= self.modulus
            self._value += step
        self._last_raw = raw
        return self._value


class Link(abc.ABC):
    """One data source. ``read`` returns whatever arrived within ``timeout_s`` (maybe [])."""

    kind: str = "link"

    #: a finite source (a replay without looping) sets this once everything was delivered
    finished: bool = False

    @abc.abstractmethod
    def open(self) -> None:
        """Connect; raises LinkError on failure."""

    @abc.abstractmethod
    def read(self, timeout_s: float) -> list[Sample]:
        """Samples that arrived, oldest first; raises LinkError when the link drops."""

    @abc.abstractmethod
    def close(self) -> None:
        """Disconnect; safe to call twice."""

    @abc.abstractmethod
    def counters(self) -> dict[str, int]:
        """Cumulative counts since construction: at least ``samples``."""

    def describe(self) -> str:
        """Where this link reads from, for log lines and the status snapshot."""
        return self.kind

    def __enter__(self) -> Link:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class ReconnectingLink(Link):
    """Wrap links made by ``factory``: reconnect with capped exponential backoff.

    Backoff: after a failed attempt the next waits ``backoff_initial_s``, doubling up to
    ``backoff_max_s``; it resets once a new connection has delivered samples. An outage is one
    ``link_lost`` and one ``link_restored``; the link counts as restored when samples arrive
    again, not when the port reopens (a stalled device that accepts connections is still down). A connected
    link that delivers nothing for ``stall_timeout_s`` (None: never) counts as lost.
    ``read`` never raises for link trouble and never spins: while down it sleeps until the
    next attempt or ``timeout_s``, whichever is first.
    """

    def __init__(
        self,
        factory: Callable[[], Link],
        backoff_initial_s: float = 0.1,
        backoff_max_s: float = 5.0,
        stall_timeout_s: float | None = 3.0,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
        kind: str | None = None,
    ) -> None:
        if not backoff_initial_s > 0 or backoff_max_s < backoff_initial_s:
            raise ValueError("need 0 < backoff_initial_s <= backoff_max_s")
        self._factory = factory
        self.backoff_initial_s = float(backoff_initial_s)
        self.backoff_max_s = float(backoff_max_s)
        self.stall_timeout_s = stall_timeout_s
        self._clock = clock
        self._sleep = sleep
        self._link: Link | None = None
        self._kind = kind  # known before the first connection when given
        self._where = ""
        self._closed_totals: dict[str, int] = {}
        self._events: list[dict[str, Any]] = []
        self._delay_s = self.backoff_initial_s
        self._next_attempt = 0.0
        self._down_since: float | None = None  # monotonic time the current outage began
        self._down_attempts = 0
        self._last_data = 0.0
        self._delivered_since_connect = False
        self._last_t: float | None = None
        self._stats = {"connect_attempts": 0, "connects": 0, "disconnects": 0, "stalls": 0}
        self._stopped = False

    # ------------------------------------------------------------------ interface
    @property
    def kind(self) -> str:  # type: ignore[override]
        return self._kind or "link"

    @property
    def connected(self) -> bool:
        return self._link is not None

    @property
    def finished(self) -> bool:  # type: ignore[override]
        return self._link is not None and self._link.finished

    def describe(self) -> str:
        return self._where or self.kind

    def open(self) -> None:
        """Try once to connect now; failure is not raised but starts the backoff."""
        self._stopped = False
        self._try_connect(self._clock())

    def read(self, timeout_s: float) -> list[Sample]:
        now = self._clock()
        if self._link is None:
            if self._stopped:
                return []
            if now < self._next_attempt:
                self._sleep(max(0.0, min(timeout_s, self._next_attempt - now)))
                return []
            if not self._try_connect(now):
                self._sleep(max(0.0, min(timeout_s, self._next_attempt - self._clock())))
                return []
        assert self._link is not None
        try:
            samples = self._link.read(timeout_s)
        except OSError as exc:  # LinkError and the transport's own OSErrors
            self._lose(f"{type(exc).__name__}: {exc}")
            return []
        now = self._clock()
        if samples:
            self._last_data = now
            self._last_t = samples[-1].t
            if not self._delivered_since_connect:
                self._delivered_since_connect = True
                self._delay_s = self.backoff_initial_s
                if self._down_since is not None:  # restored only once data flow again
                    self._event(
                        "link_restored",
                        down_s=round(now - self._down_since, 3),
                        attempts=self._down_attempts,
                    )
                    self._down_since = None
                    self._down_attempts = 0
        elif (
            self.stall_timeout_s is not None
            and not self._link.finished
            and now - self._last_data > self.stall_timeout_s
        ):
            self._stats["stalls"] += 1
            self._lose(f"no samples for {self.stall_timeout_s:g} s")
        return samples

    def close(self) -> None:
        self._stopped = True
        self._drop_link()

    def counters(self) -> dict[str, int]:
        totals = dict(self._closed_totals)
        if self._link is not None:
            for key, value in self._link.counters().items():
                totals[key] = totals.get(key, 0) + value
        totals.update(self._stats)
        totals["connected"] = int(self._link is not None)
        return totals

    def events(self) -> list[dict[str, Any]]:
        """Drain the pending ``link_lost`` / ``link_restored`` events (oldest first)."""
        out, self._events = self._events, []
        return out

    # ------------------------------------------------------------------ internals
    def _try_connect(self, now: float) -> bool:
        self._stats["connect_attempts"] += 1
        self._down_attempts += 1
        link = None
        try:
            link = self._factory()
            self._kind = link.kind
            self._where = link.describe()
            link.open()
        except OSError as exc:
            if link is not None:
                with contextlib.suppress(OSError):
                    link.close()
            if self._down_since is None:  # the first attempt failed: an outage from the start
                self._down_since = now
                self._event("link_lost", reason=f"{type(exc).__name__}: {exc}")
            self._next_attempt = self._clock() + self._delay_s
            self._delay_s = min(self._delay_s * 2.0, self.backoff_max_s)
            return False
        self._link = link
        self._stats["connects"] += 1
        self._last_data = self._clock()
        self._delivered_since_connect = False
        return True

    def _lose(self, reason: str) -> None:
        self._drop_link()
        self._stats["disconnects"] += 1
        now = self._clock()
        if self._down_since is None:  # a reconnect that never delivered is the same outage
            self._down_since = now
            self._down_attempts = 0
            self._event("link_lost", reason=reason)
        self._next_attempt = now + self._delay_s
        self._delay_s = min(self._delay_s * 2.0, self.backoff_max_s)

    def _drop_link(self) -> None:
        if self._link is None:
            return
        link, self._link = self._link, None
        for key, value in link.counters().items():
            self._closed_totals[key] = self._closed_totals.get(key, 0) + value
        with contextlib.suppress(OSError):  # closing a dead link: nothing more to release
            link.close()

    def _event(self, kind: str, **extra: Any) -> None:
        self._events.append(
            {
                "t": self._last_t,
                "kind": kind,
                "link": self.kind,
                "where": self._where,
                "time": time.time(),
                **extra,
            }
        )


# ------------------------------------------------------------------------ factory

#: config keys per link kind -> (type, default); REQUIRED marks keys without a default
REQUIRED = object()
_WORD_ORDERS = ("big", "little")
_MODBUS_COMMON: dict[str, tuple[type | tuple[type, ...], Any]] = {
    "device_id": (int, 1),
    "word_order": (str, "big"),
    "input_base": (int, 0),
    "poll_interval_s": ((int, float), 0.01),
    "timeout_s": ((int, float), 1.0),
}
LINK_KEYS: dict[str, dict[str, tuple[type | tuple[type, ...], Any]]] = {
    "serial": {"port": (str, REQUIRED), "baudrate": (int, 115200), "fs_hz": ((int, float), 256.0)},
    "modbus-tcp": {"host": (str, "127.0.0.1"), "port": (int, 502), **_MODBUS_COMMON},
    "modbus-rtu": {"port": (str, REQUIRED), "baudrate": (int, 115200), **_MODBUS_COMMON},
    "replay": {
        "path": (str, REQUIRED),
        "realtime": (bool, True),
        "speed": ((int, float), 1.0),
        "loop": (bool, False),
    },
    "sim": {"scenario": ((str, type(None)), None), "seed": (int, 0), "realtime": (bool, True)},
}
RECONNECT_KEYS: dict[str, tuple[type | tuple[type, ...], Any]] = {
    "backoff_initial_s": ((int, float), 0.1),
    "backoff_max_s": ((int, float), 5.0),
    "stall_timeout_s": ((int, float, type(None)), 3.0),
}


def _validated(config: Mapping[str, Any], keys: dict[str, Any], where: str) -> dict[str, Any]:
    out = {}
    for key in config:
        if key not in keys:
            close = close_match(key, keys)
            hint = f"did you mean {close!r}?" if close else f"known: {', '.join(sorted(keys))}"
            raise ConfigError(f"{where}.{key}: unknown key ({hint})")
    for key, (types, default) in keys.items():
        if key not in config:
            if default is REQUIRED:
                raise ConfigError(f"{where}.{key}: required")
            out[key] = default
            continue
        value = config[key]
        bad_bool = isinstance(value, bool) and bool not in (
            types if isinstance(types, tuple) else (types,)
        )
        if bad_bool or not isinstance(value, types):
            names = "/".join(t.__name__ for t in (types if isinstance(types, tuple) else (types,)))
            raise ConfigError(f"{where}.{key}: expected {names}, got {value!r}")
        out[key] = value
    return out


def link_settings(
    config: Mapping[str, Any], where: str = "link"
) -> tuple[str, dict[str, Any], dict[str, Any]]:
    """Validate a link config mapping: (kind, link settings, reconnect settings)."""
    if not isinstance(config, Mapping):
        raise ConfigError(f"{where}: expected a mapping")
    kind = config.get("kind")
    if kind not in LINK_KEYS:
        raise ConfigError(f"{where}.kind: {kind!r} is not one of {', '.join(LINK_KEYS)}")
    body = {k: v for k, v in config.items() if k not in ("kind", "reconnect")}
    settings = _validated(body, LINK_KEYS[kind], where)
    reconnect = _validated(config.get("reconnect") or {}, RECONNECT_KEYS, f"{where}.reconnect")
    if "word_order" in settings and settings["word_order"] not in _WORD_ORDERS:
        raise ConfigError(f"{where}.word_order: {settings['word_order']!r} is not big or little")
    if kind == "modbus-tcp" and not 0 < settings["port"] <= 65535:
        raise ConfigError(f"{where}.port: {settings['port']} is not a TCP port (1..65535)")
    if "device_id" in settings and not 0 <= settings["device_id"] <= 247:
        raise ConfigError(f"{where}.device_id: {settings['device_id']} is not in 0..247")
    for key in ("poll_interval_s", "timeout_s", "speed", "fs_hz"):
        if key in settings and not settings[key] > 0:
            raise ConfigError(f"{where}.{key}: must be > 0")
    if not 0 < reconnect["backoff_initial_s"] <= reconnect["backoff_max_s"]:
        raise ConfigError(f"{where}.reconnect: need 0 < backoff_initial_s <= backoff_max_s")
    return kind, settings, reconnect


def make_link(config: Mapping[str, Any], where: str = "link", fs_hz: float | None = None) -> Link:
    """Build one (unopened) link from a config mapping with ``kind`` and its settings;
    ``fs_hz``: the rate the monitor runs at, which a replayed recording must have."""
    kind, s, _ = link_settings(config, where)
    if kind == "serial":
        from fdi_daemon.io.links.serial_link import SerialLink

        return SerialLink(s["port"], baudrate=s["baudrate"], fs_hz=float(s["fs_hz"]))
    if kind in ("modbus-tcp", "modbus-rtu"):
        from fdi_daemon.io.links.modbus_link import ModbusLink

        common = dict(
            device_id=s["device_id"],
            word_order=s["word_order"],
            input_base=s["input_base"],
            poll_interval_s=float(s["poll_interval_s"]),
            timeout_s=float(s["timeout_s"]),
        )
        if kind == "modbus-tcp":
            return ModbusLink.tcp(s["host"], s["port"], **common)
        return ModbusLink.rtu(s["port"], baudrate=s["baudrate"], **common)
    if kind == "replay":
        from fdi_daemon.io.links.replay_link import ReplayLink

        return ReplayLink(
            s["path"], realtime=s["realtime"], speed=float(s["speed"]), loop=s["loop"], fs_hz=fs_hz
        )
    from fdi_daemon.io.links.sim_link import SimLink

    return SimLink(scenario=s["scenario"], seed=s["seed"], realtime=s["realtime"])


def make_reconnecting_link(
    config: Mapping[str, Any], where: str = "link", fs_hz: float | None = None
) -> ReconnectingLink:
    """``ReconnectingLink`` around ``make_link(config, where, fs_hz)``, backoff from
    ``config["reconnect"]``."""
    kind, _, reconnect = link_settings(config, where)
    return ReconnectingLink(lambda: make_link(config, where, fs_hz), kind=kind, **reconnect)
