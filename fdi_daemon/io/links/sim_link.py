"""Sim link: the simulated rig in-process, no transport (the only link importing hil_sim).

``realtime=True`` paces samples on the monotonic clock at the rig's rate; ``realtime=False``
delivers ``chunk_samples`` per ``read`` as fast as the rig computes them. The scenario's
events are the fault schedule; ``set_fault`` changes faults while running.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

from fdi_daemon.io.links.base import Link
from fdi_daemon.io.sample import Sample

if TYPE_CHECKING:
    from hil_sim.devices.realtime import RealtimeRig


class SimLink(Link):
    kind = "sim"

    def __init__(
        self,
        scenario: str | None = None,
        seed: int = 0,
        realtime: bool = True,
        chunk_samples: int = 256,
    ) -> None:
        self.scenario = scenario
        self.seed = int(seed)
        self.realtime = realtime
        self.chunk_samples = int(chunk_samples)
        self.rt: RealtimeRig | None = None
        self._samples = 0

    def describe(self) -> str:
        return f"sim {self.scenario or 'default scenario'} seed {self.seed}"

    def open(self) -> None:
        from hil_sim.devices.realtime import realtime_rig

        self.rt = realtime_rig(self.scenario, seed=self.seed)
        self.rt.start()

    def set_fault(self, name: str, value: float) -> None:
        """Change a fault of the running rig (``bearing_supply`` or a `Rig.set_fault` name)."""
        assert self.rt is not None, "open() first"
        self.rt.set_fault(name, value)

    def read(self, timeout_s: float) -> list[Sample]:
        rt = self.rt
        assert rt is not None, "open() first"
        if self.realtime:
            wait = rt.next_tick_time - time.monotonic()
            if wait > 0:
                time.sleep(min(wait, max(0.0, timeout_s)))
            batch = rt.advance()
        else:
            batch = rt.advance(rt.next_tick_time + (self.chunk_samples - 1) / rt.fs_hz)
        self._samples += len(batch)
        return [Sample(s.seq, s.t, s.v_in, s.accel, s.position) for s in batch]

    def close(self) -> None:
        self.rt = None

    def counters(self) -> dict[str, int]:
        return {"samples": self._samples}
