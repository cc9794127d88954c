"""Modbus TCP / RTU link: polls the DAQ register map of ``fdi_daemon.io.modbus_map``.

Each poll reads the header and the 13 newest FIFO slots in one request (atomic on the
device); when the poller is further behind it reads deeper slots, 15 per request, until it
has every sample since the last one it delivered or reaches the end of the FIFO. Samples
are delivered once each, oldest first. Samples that fell out of the FIFO before they could
be read show as a jump in ``Sample.seq`` (and in the ``samples_lost`` counter); a counter
that goes backwards (device restarted behind a gateway) restarts delivery at the newest
sample (``counter_resets``).

pymodbus 3.16 sync clients (``device_id=``; word order from the config; byte order within a
register is always big endian). Any Modbus or transport error raises `LinkError`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from fdi_daemon.io import modbus_map as mm
from fdi_daemon.io.links.base import Link, LinkError, SeqUnwrapper
from fdi_daemon.io.sample import Sample

_U32 = 1 << 32


def _behind(newest_raw: int, seq_raw: int) -> int:
    """How many samples ``seq_raw`` is older than ``newest_raw`` (negative: newer), mod 2**32."""
    behind = (newest_raw - seq_raw) % _U32
    return behind - _U32 if behind >= _U32 // 2 else behind


class ModbusLink(Link):
    """Poll the register map through a pymodbus sync client made by ``client_factory``."""

    def __init__(
        self,
        kind: str,
        where: str,
        client_factory: Callable[[], Any],
        *,
        device_id: int = 1,
        word_order: mm.WordOrder = "big",
        input_base: int = 0,
        poll_interval_s: float = 0.01,
        timeout_s: float = 1.0,
    ) -> None:
        if word_order not in ("big", "little"):
            raise ValueError(f"word order {word_order!r} is not 'big' or 'little'")
        self.kind = kind
        self._where = where
        self._client_factory = client_factory
        self.device_id = int(device_id)
        self.word_order: mm.WordOrder = word_order
        self.input_base = int(input_base)
        self.poll_interval_s = float(poll_interval_s)
        self.timeout_s = float(timeout_s)
        self._client: Any = None
        self._header: mm.Header | None = None
        self._scales = (1.0, 1.0, 1.0)
        self._unwrap = SeqUnwrapper(32)
        self._last_seq: int | None = None  # unwrapped seq of the last delivered sample
        self._next_poll = 0.0
        self._counts = {
            "samples": 0,
            "polls": 0,
            "requests": 0,
            "samples_lost": 0,
            "fifo_overruns": 0,
            "counter_resets": 0,
        }

    # ------------------------------------------------------------------ constructors
    @classmethod
    def tcp(cls, host: str, port: int, **kwargs: Any) -> ModbusLink:
        from pymodbus.client import ModbusTcpClient

        timeout_s = float(kwargs.get("timeout_s", 1.0))
        return cls(
            "modbus-tcp",
            f"modbus-tcp {host}:{port}",
            lambda: ModbusTcpClient(
                host, port=port, timeout=timeout_s, retries=1, reconnect_delay=0.0
            ),
            **kwargs,
        )

    @classmethod
    def rtu(cls, port: str, baudrate: int = 115200, **kwargs: Any) -> ModbusLink:
        from pymodbus.client import ModbusSerialClient
        from pymodbus.framer import FramerType

        timeout_s = float(kwargs.get("timeout_s", 1.0))
        return cls(
            "modbus-rtu",
            f"modbus-rtu {port} @ {baudrate} Bd",
            lambda: ModbusSerialClient(
                port,
                framer=FramerType.RTU,
                baudrate=baudrate,
                timeout=timeout_s,
                retries=1,
                reconnect_delay=0.0,
            ),
            **kwargs,
        )

    # ------------------------------------------------------------------ Link
    def describe(self) -> str:
        return f"{self._where} id {self.device_id} ({self.word_order} word order)"

    @property
    def header(self) -> mm.Header | None:
        """The header read at open (fs, FIFO depth, scales)."""
        return self._header

    def open(self) -> None:
        self._client = self._client_factory()
        if not self._client.connect():
            self._client = None
            raise LinkError(f"cannot connect to {self._where}")
        regs = self._read(0, mm.HEADER_REGS)
        header = mm.decode_header(regs, self.word_order)
        if header.map_version != mm.MAP_VERSION or header.words_per_sample != mm.WORDS_PER_SAMPLE:
            self.close()
            raise LinkError(
                f"{self._where}: register map version {header.map_version} with "
                f"{header.words_per_sample} words per sample is not supported "
                f"(expected {mm.MAP_VERSION}, {mm.WORDS_PER_SAMPLE}); "
                "check input_base and device_id"
            )
        if header.fs_hz <= 0 or header.fifo_depth <= 0:
            self.close()
            raise LinkError(f"{self._where}: implausible header {header}")
        self._header = header
        self._scales = (header.v_in_scale, header.accel_scale, header.position_scale)

    def read(self, timeout_s: float) -> list[Sample]:
        if self._client is None:
            raise LinkError(f"{self._where} is not open")
        wait = self._next_poll - time.monotonic()
        if wait > 0:
            time.sleep(min(wait, max(0.0, timeout_s)))
            if wait > timeout_s:
                return []
        self._next_poll = time.monotonic() + self.poll_interval_s
        return self.poll()

    def close(self) -> None:
        if self._client is not None:
            client, self._client = self._client, None
            client.close()

    def counters(self) -> dict[str, int]:
        return dict(self._counts)

    # ------------------------------------------------------------------ polling
    def poll(self) -> list[Sample]:
        """One poll now: every sample since the last delivered one that is still in the FIFO."""
        assert self._header is not None
        self._counts["polls"] += 1
        first = min(mm.SLOTS_IN_FIRST_READ, self._header.fifo_depth)
        regs = self._read(0, mm.slot_address(first))
        header = mm.decode_header(regs, self.word_order)
        if header.sample_counter == 0 and header.fifo_valid == 0:
            return []
        newest_raw = (header.sample_counter - 1) % _U32
        newest = self._unwrap(header.sample_counter) - 1
        if self._last_seq is not None and newest < self._last_seq:
            self._counts["counter_resets"] += 1
            self._last_seq = None
        valid = min(header.fifo_valid, header.fifo_depth)
        got: dict[int, mm.SlotSample] = {}
        self._collect(
            mm.decode_slots(
                regs[mm.HEADER_REGS : mm.slot_address(min(first, valid))],
                self.word_order,
                self._scales,
            ),
            newest_raw,
            newest,
            got,
        )
        if self._last_seq is None:
            self._last_seq = newest - 1  # start live: deliver the newest sample only
        start, filled = first, valid  # filled: FIFO slots that hold a sample, a lower bound
        while got and min(got) > self._last_seq + 1 and start < filled:
            count = min(mm.SLOTS_PER_READ, header.fifo_depth - start)
            block = mm.decode_slots(
                self._read(mm.slot_address(start), count * mm.WORDS_PER_SAMPLE),
                self.word_order,
                self._scales,
            )
            # Slot `start` holds a sample (start < filled); how much newer it is than what
            # sat there when the header was read is how far the FIFO has moved on since.
            published = start - _behind(newest_raw, block[0].seq)
            filled = min(valid + published, header.fifo_depth)
            self._collect(block[: filled - start], newest_raw, newest, got)
            start += count
        wanted = sorted(seq for seq in got if seq > self._last_seq)
        if wanted and wanted[0] > self._last_seq + 1:
            self._counts["fifo_overruns"] += 1
            self._counts["samples_lost"] += wanted[0] - self._last_seq - 1
        fs = float(header.fs_hz)
        out = [
            Sample(seq, seq / fs, got[seq].v_in, got[seq].accel, got[seq].position)
            for seq in wanted
        ]
        if out:
            self._last_seq = out[-1].seq
        self._counts["samples"] += len(out)
        return out

    @staticmethod
    def _collect(
        slots: list[mm.SlotSample], newest_raw: int, newest: int, got: dict[int, mm.SlotSample]
    ) -> None:
        for slot in slots:
            behind = _behind(newest_raw, slot.seq)
            if behind < 0:
                continue  # written after the header was read: the next poll takes it
            got[newest - behind] = slot

    def _read(self, offset: int, count: int) -> list[int]:
        from pymodbus.exceptions import ModbusException

        self._counts["requests"] += 1
        try:
            rr = self._client.read_input_registers(
                self.input_base + offset, count=count, device_id=self.device_id
            )
        except (ModbusException, OSError) as exc:
            self.close()
            raise LinkError(f"{self._where}: {exc}") from None
        if rr.isError():
            self.close()
            raise LinkError(
                f"{self._where}: device answered {rr} to a read of {count} "
                f"input registers at {self.input_base + offset}"
            )
        return list(rr.registers)
