"""Where the daemon's results go: event log, stdout/journald, status socket, Modbus status.

None of these runs on the sample loop's thread. The loop hands items to a `Worker` (a
thread with a bounded queue for non-critical items, which are dropped and counted when
the queue is full, and an unbounded lane for alarms, which are never dropped), publishes
status snapshots to a `StatusBoard`, and the two servers answer from the board.

- `EventLog`: JSON Lines, append-only; every line is flushed, alarm lines are also
  fsynced, and the file is fsynced at least once a second otherwise. Lines are events
  stamped by `stamp_event` (``time``: RFC 3339 wall clock; ``schema``).
  fsynced, and the file is fsynced at least once a second otherwise. Before each line it
  checks that its path still names the open file (logrotate renamed or removed it: the
  file is reopened, no reload needed); ``reopen()`` does it on request (SIGUSR1).
- `StdoutLog`: one clear line per event; under journald (``$JOURNAL_STREAM`` set) each line
  starts with a ``<N>`` syslog priority so that ``journalctl -p warning`` finds alarms.
- `StatusSocketServer`: a Unix stream socket (mode 0660). On connect the server sends one
  JSON line (the latest status snapshot, TEAM.md schema); every line the client sends
  afterwards is answered with one more; the server closes when the client does. A line
  that is a JSON object with a ``request`` (acknowledge, shelve, unshelve) is answered with
  the request's JSON result instead (`StatusSocketServer.requests`).
- `ModbusStatusServer`: Modbus TCP (pymodbus), bound to 127.0.0.1 unless configured;
  registers in `STATUS_REGISTERS`, documented in ``docs/status_registers.md``.
"""

from __future__ import annotations

import asyncio
import collections
import errno
import json
import logging
import math
import os
import socket
import sys
import threading
import time
from collections.abc import Callable
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from pymodbus.client.mixin import ModbusClientMixin
from pymodbus.constants import ExcCodes
from pymodbus.pdu import ExceptionResponse, ReadCoilsRequest

from fdi_daemon.alarms.lifecycle import LIFECYCLE_KINDS
from fdi_daemon.detect.events import ALARM_KINDS as EVENT_ALARM_KINDS
from fdi_daemon.detect.events import EVENT_SCHEMA
from fdi_daemon.io.outputs import json_safe

if TYPE_CHECKING:
    from pymodbus.server import ModbusTcpServer

log = logging.getLogger("fdi.sinks")

#: events that are alarms: fsynced at once, never dropped, logged as warnings
ALARM_KINDS = frozenset(EVENT_ALARM_KINDS) | frozenset(LIFECYCLE_KINDS)
#: syslog priorities for the journald prefix
PRIORITY = {
    "fault_detected": 4,
    "friction_isolated": 4,
    "other_fault": 4,
    "link_lost": 4,
    "cleared": 5,
    "link_restored": 5,
    "data_gap": 5,
    "bad_sample": 5,
    "calibrated": 6,
    "alarm_raised": 4,
    "alarm_priority": 4,
    "alarm_acknowledged": 5,
    "alarm_shelved": 5,
    "alarm_unshelved": 5,
    "alarm_returned": 5,
}


#: longest ``by`` / ``why`` text of a socket request kept in the event log (characters)
REQUEST_TEXT_MAX = 200


def _text(value: Any) -> str:
    """A request's free text, one line, at most `REQUEST_TEXT_MAX` characters."""
    return " ".join(str(value).split())[:REQUEST_TEXT_MAX] if isinstance(value, str) else ""


def _requester(value: Any) -> str:
    """Who asked on the status socket: the request's ``by`` (`fdi alarm --by`), marked as
    coming through the socket."""
    who = _text(value)
    return f"{who} (status socket)" if who else "status socket"


def json_line(value: Any) -> str:
    return json.dumps(json_safe(value), allow_nan=False, separators=(",", ":")) + "\n"


def rfc3339(epoch_s: float) -> str:
    """UTC wall-clock time as RFC 3339 with microseconds: ``2026-11-23T18:00:00.123456Z``."""
    return datetime.fromtimestamp(epoch_s, timezone.utc).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


def stamp_event(event: dict, now: float | None = None) -> dict:
    """The event as written out (event log, MQTT): ``time`` and ``schema`` added.

    ``time`` is the wall clock when the event is written, except for link events, which
    carry the wall clock (epoch s) at which the link layer noticed the loss or restore.
    ``t`` and ``kind`` stay as the monitor made them.
    """
    when = event.get("time")
    if not isinstance(when, (int, float)) or isinstance(when, bool):
        when = time.time() if now is None else now
    return {**event, "time": rfc3339(when), "schema": EVENT_SCHEMA}


# ----------------------------------------------------------------------------- worker


class Worker:
    """A thread that runs ``handler(item)`` for queued items, never blocking the producer.

    ``put(item)``: non-critical, dropped (and counted in ``dropped``) when ``maxsize`` items
    are waiting. ``put(item, critical=True)``: never dropped (alarms; they are rare).
    Critical items are handled before waiting non-critical ones.
    """

    def __init__(self, name: str, handler: Callable[[Any], None], maxsize: int) -> None:
        self.name = name
        self.handler = handler
        self.maxsize = maxsize
        self.dropped = 0
        self.handled = 0
        self.errors = 0
        self._normal: collections.deque = collections.deque()
        self._critical: collections.deque = collections.deque()
        self._cond = threading.Condition()
        self._stop = False
        self._thread = threading.Thread(target=self._run, name=f"fdi-{name}", daemon=True)
        self._thread.start()

    def put(self, item: Any, critical: bool = False) -> bool:
        with self._cond:
            if critical:
                self._critical.append(item)
            elif len(self._normal) >= self.maxsize:
                self.dropped += 1
                return False
            else:
                self._normal.append(item)
            self._cond.notify()
        return True

    def pending(self) -> int:
        with self._cond:
            return len(self._normal) + len(self._critical)

    def _run(self) -> None:
        while True:
            with self._cond:
                while not (self._critical or self._normal or self._stop):
                    self._cond.wait()
                if self._critical:
                    item = self._critical.popleft()
                elif self._normal:
                    item = self._normal.popleft()
                else:
                    return  # stop requested and nothing left
            try:
                self.handler(item)
                self.handled += 1
            except Exception:  # a sink failure must not kill the worker; it is logged
                self.errors += 1
                log.exception("%s: handling an item failed", self.name)

    def close(self, timeout_s: float = 10.0) -> None:
        """Handle what is queued, then stop the thread."""
        with self._cond:
            self._stop = True
            self._cond.notify()
        self._thread.join(timeout_s)
        if self._thread.is_alive():
            log.error("%s: did not finish its queue within %.0f s", self.name, timeout_s)


# ----------------------------------------------------------------------------- event log


class EventLog:
    """JSON Lines event log: append, flush every line, fsync alarms (and ≥ once a second)."""

    def __init__(self, path: str | Path, fsync_period_s: float = 1.0) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fh = open(self.path, "a", encoding="utf-8")
        self.fsync_period_s = fsync_period_s
        self._last_fsync = time.monotonic()
        self.written = 0
        self.reopened = 0

    def _rotated(self) -> bool:
        """True when the path no longer names the open file (renamed or removed)."""
        try:
            on_disk = os.stat(self.path)
        except FileNotFoundError:
            return True
        here = os.fstat(self._fh.fileno())
        return (on_disk.st_dev, on_disk.st_ino) != (here.st_dev, here.st_ino)

    def reopen(self) -> None:
        """Close the open file (flushed, fsynced) and open the path again (append)."""
        self.close()
        self._fh = open(self.path, "a", encoding="utf-8")
        self.reopened += 1
        log.info("event log %s reopened", self.path)

    def write(self, event: dict) -> None:
        if self._rotated():
            self.reopen()
        self._fh.write(json_line(event))
        self._fh.flush()
        self.written += 1
        now = time.monotonic()
        if event.get("kind") in ALARM_KINDS or now - self._last_fsync >= self.fsync_period_s:
            os.fsync(self._fh.fileno())
            self._last_fsync = now

    def close(self) -> None:
        if not self._fh.closed:
            self._fh.flush()
            os.fsync(self._fh.fileno())
            self._fh.close()


# ----------------------------------------------------------------------------- stdout


def journald_attached() -> bool:
    """True when stdout is a journald stream (systemd sets ``$JOURNAL_STREAM``)."""
    stream = os.environ.get("JOURNAL_STREAM")
    if not stream:
        return False
    try:
        st = os.fstat(sys.stdout.fileno())
    except (OSError, ValueError):
        return False
    return stream == f"{st.st_dev}:{st.st_ino}"


def format_event(event: dict) -> str:
    """One human line for an event: sample time, kind, the numbers that matter (a value
    that was not measured, None, is left out)."""
    kind = str(event.get("kind", "?"))
    t = event.get("t")
    when = f"t={t:10.3f} s" if isinstance(t, (int, float)) else "t=         - s"
    parts = [when, f"{kind.upper().replace('_', ' '):<17}"]
    for key, label, unit in (("theta1", "θ1", ""), ("theta2", "θ2", " s/m")):  # θ2 as γ_f
        value = event.get(key)
        if isinstance(value, (int, float)) and math.isfinite(value):
            parts.append(f"{label}={value:+.4g}{unit}")
    for key, value in event.items():
        if (
            key in ("t", "kind", "theta1", "theta2", "time")
            or value is None
            or isinstance(value, (dict, list))
        ):
            continue
        if isinstance(value, float):
            value = f"{value:.4g}"
        parts.append(f"{key}={value}")
    return "  ".join(parts)


class StdoutLog:
    """Event lines on a text stream, with ``<N>`` priority prefixes under journald."""

    def __init__(self, stream: TextIO | None = None, priorities: bool | None = None) -> None:
        self.stream = stream or sys.stdout
        self.priorities = journald_attached() if priorities is None else priorities

    def write(self, event: dict) -> None:
        prefix = f"<{PRIORITY.get(str(event.get('kind')), 6)}>" if self.priorities else ""
        try:
            self.stream.write(prefix + format_event(event) + "\n")
            self.stream.flush()
        except BrokenPipeError:
            pass  # nobody reads stdout any more; the event log still has the line


class PriorityFormatter(logging.Formatter):
    """Log records as ``<N>message`` (journald) or ``time level message`` (a terminal)."""

    LEVELS = {
        logging.CRITICAL: 2,
        logging.ERROR: 3,
        logging.WARNING: 4,
        logging.INFO: 6,
        logging.DEBUG: 7,
    }

    def __init__(self, priorities: bool) -> None:
        super().__init__(
            "%(message)s" if priorities else "%(asctime)s %(levelname)s %(name)s: %(message)s"
        )
        self.priorities = priorities

    def format(self, record: logging.LogRecord) -> str:
        text = super().format(record)
        if self.priorities:
            return f"<{self.LEVELS.get(record.levelno, 6)}>" + text.replace("\n", " | ")
        return text


# ----------------------------------------------------------------------------- status board


class StatusBoard:
    """The latest status snapshot, readable from any thread."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._snapshot: dict[str, Any] = {"time": time.time(), "state": "starting"}
        self._line = json_line(self._snapshot).encode()
        self.updates = 0

    def publish(self, snapshot: dict[str, Any]) -> None:
        line = json_line(snapshot).encode()
        with self._lock:
            self._snapshot = snapshot
            self._line = line
            self.updates += 1

    def snapshot(self) -> dict[str, Any]:
        with self._lock:
            return self._snapshot

    def line(self) -> bytes:
        with self._lock:
            return self._line


# ----------------------------------------------------------------------------- status socket


class StatusSocketServer:
    """Unix stream socket: one JSON snapshot line per request line (see module doc)."""

    CLIENT_TIMEOUT_S = 30.0

    def __init__(
        self,
        path: str | Path,
        board: StatusBoard,
        mode: int = 0o660,
        requests: Callable[[dict[str, Any]], dict[str, Any]] | None = None,
    ) -> None:
        self.path = Path(path)
        self.board = board
        self.requests_handler = requests
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if self.path.is_socket():
            self.path.unlink()  # a stale socket from a previous run
        elif self.path.exists():  # bind would say "Address already in use"
            raise FileExistsError(
                errno.EEXIST,
                "a file of that name is there, not a socket (left as it is)",
                str(self.path),
            )
        self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM | socket.SOCK_CLOEXEC)
        self._sock.bind(str(self.path))
        os.chmod(self.path, mode)
        self._sock.listen(8)
        self._sock.settimeout(0.2)
        self._stop = threading.Event()
        self.requests = 0
        self._thread = threading.Thread(target=self._serve, name="fdi-status-socket", daemon=True)
        self._thread.start()

    def _serve(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self._sock.accept()
            except TimeoutError:
                continue
            except OSError as exc:
                if not self._stop.is_set():
                    log.error("status socket %s: accept failed: %s", self.path, exc)
                    time.sleep(0.2)
                continue
            threading.Thread(
                target=self._client, args=(conn,), name="fdi-status-client", daemon=True
            ).start()

    def _client(self, conn: socket.socket) -> None:
        conn.settimeout(self.CLIENT_TIMEOUT_S)
        buffer = b""
        try:
            with conn:
                self.requests += 1  # counted before the answer, which the client may act on
                conn.sendall(self.board.line())
                while not self._stop.is_set():
                    chunk = conn.recv(4096)
                    if not chunk:
                        return
                    buffer += chunk
                    while b"\n" in buffer:
                        line, buffer = buffer.split(b"\n", 1)
                        self.requests += 1
                        conn.sendall(self._answer(line))
                    if len(buffer) > 65536:
                        return  # not a status client
        except (TimeoutError, ConnectionError, BrokenPipeError):
            return
        except OSError as exc:
            log.warning("status socket client: %s", exc)

    def _answer(self, line: bytes) -> bytes:
        """The snapshot, or the result of a ``{"request": ...}`` line."""
        if not line.lstrip().startswith(b"{"):
            return self.board.line()
        try:
            request = json.loads(line)
            action = request["request"]
        except (ValueError, TypeError, KeyError):
            return json_line(
                {
                    "ok": False,
                    "error": "a request is a JSON object with "
                    "\"request\": acknowledge | shelve | "
                    "unshelve",
                }
            ).encode()
        if self.requests_handler is None:
            return json_line({"ok": False, "error": "this daemon takes no requests"}).encode()
        duration = request.get("duration_s")
        return json_line(
            self.requests_handler(
                {
                    "request": action,
                    "duration_s": duration,
                    "by": _requester(request.get("by")),
                    "why": _text(request.get("why")),
                }
            )
        ).encode()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self._sock.close()
        try:
            self.path.unlink()
        except FileNotFoundError:
            pass


# ----------------------------------------------------------------------------- Modbus status

#: state name -> code in register `state`
STATE_CODES = {
    "starting": 0,
    "calibrating": 1,
    "monitoring": 2,
    "fault_detected": 3,
    "friction_isolated": 4,
    "other_fault": 5,
}

#: (name, first register, type, meaning). Types: u16; u32/f32 in 2 registers and f64 in 4,
#: high word first; bytes within a register big endian (Modbus). NaN: value not available.
STATUS_REGISTERS: tuple[tuple[str, int, str, str], ...] = (
    ("map_version", 0, "u16", "version of this register map (2)"),
    (
        "state",
        1,
        "u16",
        "0 starting, 1 calibrating, 2 monitoring, 3 fault_detected, "
        "4 friction_isolated, 5 other_fault",
    ),
    ("link_connected", 2, "u16", "1 while the data link is up"),
    ("heartbeat", 3, "u16", "+1 at every status refresh (10 Hz by default), wraps at 65536"),
    ("alarm_active", 4, "u16", "1 while an alarm is raised and not shelved"),
    ("theta1", 5, "f32", "θ1 estimate (Coulomb term, eq. 15)"),
    ("theta2", 7, "f32", "θ2 estimate (viscous term, eq. 15)"),
    ("friction_level", 9, "f32", "friction level from the monitor"),
    ("statistic", 11, "f32", "detection statistic"),
    ("threshold", 13, "f32", "detection threshold"),
    ("residual_rms", 15, "f32", "RMS of the model residual, m/s²"),
    ("t", 17, "f64", "sample time of the last sample, s"),
    ("samples", 21, "u32", "samples received"),
    ("gaps", 23, "u32", "data gaps (sequence jumps)"),
    ("crc_errors", 25, "u32", "frames rejected by the link (CRC)"),
    ("bad_samples", 27, "u32", "samples rejected as bad"),
    ("deadline_misses", 29, "u32", "ticks finished later than service.deadline_s"),
    ("tick_latency_p99_us", 31, "u32", "p99 of the per-tick latency, µs"),
    ("fault_detected_count", 33, "u32", "fault_detected events since start"),
    ("friction_isolated_count", 35, "u32", "friction_isolated events since start"),
    ("other_fault_count", 37, "u32", "other_fault events since start"),
    ("link_lost_count", 39, "u32", "link_lost events since start"),
    ("uptime_s", 41, "u32", "seconds since the daemon started"),
    ("dropped_outputs", 43, "u32", "non-critical sink items dropped (queue full)"),
    (
        "baseline_level",
        45,
        "f32",
        "fault-free friction level of the model's baseline, "
        "units of the signature (NaN: the model has none)",
    ),
    (
        "alarm_state",
        47,
        "u16",
        "0 normal, 1 unacknowledged, 2 acknowledged, 3 returned unacknowledged, 4 shelved",
    ),
    ("alarm_priority", 48, "u16", "0 none, 1..3: alarm steps crossed (alarms.steps)"),
    ("alarm_id", 49, "u32", "number of the current (or last) alarm; +1 at every new alarm"),
    (
        "alarm_command",
        51,
        "u16",
        "write 1 = acknowledge, 2 = unshelve (if alarms.allow_remote_acknowledge); reads 0",
    ),
    (
        "shelve_minutes",
        52,
        "u16",
        "write N = shelve the alarm N minutes; reads the minutes of shelving left",
    ),
)
STATUS_REGISTER_COUNT = 53
#: writable registers: name -> address
COMMAND_REGISTERS = {"alarm_command": 51, "shelve_minutes": 52}
_SIZES = {"u16": 1, "u32": 2, "f32": 2, "f64": 4}
_DATATYPE = ModbusClientMixin.DATATYPE
#: register type -> pymodbus data type (its conversion: high word first, big-endian bytes)
_DATATYPES = {
    "u16": _DATATYPE.UINT16,
    "u32": _DATATYPE.UINT32,
    "f32": _DATATYPE.FLOAT32,
    "f64": _DATATYPE.FLOAT64,
}


def status_values(snapshot: dict[str, Any], heartbeat: int) -> dict[str, float | int]:
    """The register values from a status snapshot (TEAM.md schema)."""
    link = snapshot.get("link") or {}
    monitor = snapshot.get("monitor") or {}
    counters = snapshot.get("counters") or {}
    state = snapshot.get("state", "starting")
    latency = link.get("tick_latency_us") or {}
    alarm = snapshot.get("alarm")
    shelved_until = (alarm or {}).get("shelved_until")
    return {
        "map_version": 2,
        "state": STATE_CODES.get(state, 0),
        "link_connected": int(bool(link.get("connected"))),
        "heartbeat": heartbeat,
        "alarm_active": (
            int(bool(alarm.get("annunciated")))
            if alarm
            else int(state in ("fault_detected", "friction_isolated", "other_fault"))
        ),
        "theta1": monitor.get("theta1"),
        "theta2": monitor.get("theta2"),
        "friction_level": monitor.get("friction_level"),
        "statistic": monitor.get("statistic"),
        "threshold": monitor.get("threshold"),
        "residual_rms": monitor.get("residual_rms"),
        "t": snapshot.get("t"),
        "samples": link.get("samples", 0),
        "gaps": link.get("gaps", 0),
        "crc_errors": link.get("crc_errors", 0),
        "bad_samples": link.get("bad_samples", 0),
        "deadline_misses": link.get("deadline_misses", 0),
        "tick_latency_p99_us": latency.get("p99"),
        "fault_detected_count": counters.get("fault_detected", 0),
        "friction_isolated_count": counters.get("friction_isolated", 0),
        "other_fault_count": counters.get("other_fault", 0),
        "link_lost_count": counters.get("link_lost", 0),
        "uptime_s": snapshot.get("uptime_s", 0),
        "dropped_outputs": snapshot.get("dropped_outputs", 0),
        "baseline_level": (alarm or {}).get("baseline_level"),
        "alarm_state": (alarm or {}).get("state_code", 0),
        "alarm_priority": (alarm or {}).get("priority", 0),
        "alarm_id": (alarm or {}).get("alarm_id", 0),
        "alarm_command": 0,
        "shelve_minutes": (
            math.ceil(max(0.0, shelved_until - snapshot.get("time", 0)) / 60)
            if isinstance(shelved_until, (int, float))
            else 0
        ),
    }


def encode_status(values: dict[str, Any]) -> list[int]:
    """The register block (STATUS_REGISTER_COUNT words) for `status_values` output."""
    regs = [0] * STATUS_REGISTER_COUNT
    for name, address, kind, _ in STATUS_REGISTERS:
        value = values.get(name)
        if kind in ("f32", "f64"):
            value = math.nan if not isinstance(value, (int, float)) else float(value)
        else:
            value = 0 if not isinstance(value, (int, float)) or not math.isfinite(value) else value
            value = min(max(int(value), 0), (1 << (16 * _SIZES[kind])) - 1)
        words = ModbusClientMixin.convert_to_registers(value, _DATATYPES[kind], "big")
        regs[address : address + len(words)] = words
    return regs


def decode_status(regs: list[int]) -> dict[str, float | int]:
    """Inverse of `encode_status` (what an independent client does with the map)."""
    out: dict[str, float | int] = {}
    for name, address, kind, _ in STATUS_REGISTERS:
        words = list(regs[address : address + _SIZES[kind]])
        value = ModbusClientMixin.convert_from_registers(words, _DATATYPES[kind], "big")
        assert isinstance(value, (int, float))  # one value of a numeric type
        out[name] = value
    return out


#: the unit id of a Modbus TCP server "addressed directly" (Modbus Messaging on TCP/IP
#: Implementation Guide, 4.4.2: the IP address selects the server, the unit id is 0xFF)
DIRECT_DEVICE_ID = 255


class _RefusedReadCoils(ReadCoilsRequest):
    """Function code 1 answered with exception 1 (illegal function): the map has no bits.

    Registered as the server's decoder entry for the code (pymodbus ``custom_pdu``), so the
    refusal comes before any address check, as the Modbus specification orders them.
    """

    async def datastore_update(self, context, device_id):
        return ExceptionResponse(self.function_code, ExcCodes.ILLEGAL_FUNCTION)


class _RefusedReadDiscreteInputs(_RefusedReadCoils):
    """Function code 2, refused like function code 1."""

    function_code = 2


class ModbusStatusServer:
    """Modbus TCP server of the status registers (holding and input registers alike).

    Every read refreshes the block from the status board, so a client always sees the
    latest snapshot. Register writes (function codes 6, 16) to a read-only register, or of
    more than one register, are refused with exception 2 (illegal data address); only one
    of `COMMAND_REGISTERS` at a time is writable, and only when ``requests`` is given:
    1 to ``alarm_command`` acknowledges, 2 unshelves, N > 0 to ``shelve_minutes`` shelves
    for N minutes; a value the alarm refuses is answered with exception 3 (illegal data
    value). Coil writes (5, 15) and bit reads (1, 2) are refused with exception 1 (illegal
    function): the map has no bits. Answers the configured device id and 255 (addressed
    directly); any other id gets exception 11.
    """

    def __init__(
        self,
        board: StatusBoard,
        host: str = "127.0.0.1",
        port: int = 5020,
        device_id: int = 1,
        requests: Callable[[dict[str, Any]], dict[str, Any]] | None = None,
    ) -> None:
        self.board = board
        self.requests_handler = requests
        self.host = host
        self.device_id = device_id
        self.port = port
        self.reads = 0
        self._loop = asyncio.new_event_loop()
        self._server: ModbusTcpServer | None = None
        self._started = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="fdi-modbus-status", daemon=True)
        self._thread.start()
        self._started.wait(15.0)
        if self._error is not None:
            raise OSError(f"Modbus status server on {host}:{port}: {self._error}")
        if self._server is None:
            raise OSError(f"Modbus status server on {host}:{port} did not start")

    @staticmethod
    async def _other_device(function_code, start_address, address, count, registers, set_values):
        """Requests to any other device id: 'gateway target failed to respond'."""
        return ExcCodes.GATEWAY_NO_RESPONSE

    async def _refresh(self, function_code, start_address, address, count, registers, set_values):
        if set_values is not None:  # registers are written with 6 and 16 only (not coils)
            if function_code not in (6, 16):
                return ExcCodes.ILLEGAL_FUNCTION
            return self._command(address, list(set_values))
        values = status_values(self.board.snapshot(), self.board.updates & 0xFFFF)
        registers[:STATUS_REGISTER_COUNT] = encode_status(values)
        self.reads += 1
        return None

    def _command(self, address: int, values: list[int]):
        """A write to the command registers (see the class docstring)."""
        commands = {COMMAND_REGISTERS["alarm_command"]: {1: "acknowledge", 2: "unshelve"}}
        if (
            self.requests_handler is None
            or len(values) != 1
            or address not in COMMAND_REGISTERS.values()
        ):
            return ExcCodes.ILLEGAL_ADDRESS
        value = int(values[0])
        if address == COMMAND_REGISTERS["shelve_minutes"]:
            request = {"request": "shelve", "duration_s": 60.0 * value} if value > 0 else None
        else:
            action = commands[address].get(value)
            request = None if action is None else {"request": action, "duration_s": None}
        if request is None:
            return ExcCodes.ILLEGAL_VALUE
        answer = self.requests_handler({**request, "by": "modbus"})
        if not answer.get("ok"):
            log.info("Modbus alarm request %s refused: %s", request["request"], answer.get("error"))
            return ExcCodes.ILLEGAL_VALUE
        return None

    def _run(self) -> None:
        asyncio.set_event_loop(self._loop)
        try:
            self._loop.run_until_complete(self._start())
        except BaseException as exc:  # reported to the constructor
            self._error = exc
            self._started.set()
            return
        self._started.set()
        self._loop.run_forever()
        self._loop.run_until_complete(self._loop.shutdown_asyncgens())
        self._loop.close()

    async def _start(self) -> None:
        from pymodbus.server import ModbusTcpServer
        from pymodbus.simulator import DataType, SimData, SimDevice

        def block() -> list:
            return [SimData(0, count=STATUS_REGISTER_COUNT, values=0, datatype=DataType.REGISTERS)]

        served = dict.fromkeys((self.device_id, DIRECT_DEVICE_ID))
        devices = [SimDevice(id=i, simdata=block(), action=self._refresh) for i in served]
        if 0 not in served:  # pymodbus answers unknown ids from device 0
            devices.append(SimDevice(id=0, simdata=block(), action=self._other_device))
        server = ModbusTcpServer(
            devices,
            address=(self.host, self.port),
            custom_pdu=[_RefusedReadCoils, _RefusedReadDiscreteInputs],
        )
        await server.serve_forever(background=True)
        if server.transport is None:
            raise OSError("cannot listen (address in use?)")
        self.port = server.transport.sockets[0].getsockname()[1]  # type: ignore[attr-defined]  # an asyncio.Server
        self._server = server

    def close(self) -> None:
        if self._server is not None and self._loop.is_running():
            fut = asyncio.run_coroutine_threadsafe(self._server.shutdown(), self._loop)
            try:
                fut.result(5.0)
            except Exception as exc:  # closing anyway; say why it was not clean
                log.warning("Modbus status server shutdown: %s", exc)
            self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(5.0)
