"""Drive the simulated rig in real time: one sample per 1/fs on the monotonic clock.

`RealtimeRig.advance(now)` steps the rig over every tick that has come due since `start`
(a late caller gets a burst, never a skipped tick: the physics stays continuous and the
consumers' buffers decide what survives). The excitation is one period of valve voltage
played in a loop; the fault schedule is a list of timed settings (applied at the first
sample at or after their time, as `hil_sim.scenarios.simulate` does) plus changes made
while running (`set_bearing_supply`, `set_fault`: thread-safe, applied at the next tick).
`realtime_rig(scenario, seed)` builds one from a scenario: over the scenario's duration its
samples equal ``simulate(scenario, seed)`` (scenario drift profiles are not played).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np


def rig_faults() -> dict:
    """The rig's non-friction faults: name -> (control index, neutral value, meaning)."""
    from hil_sim.rig import FAULTS

    return FAULTS


#: names a fault schedule or a fault-control register may set
FAULT_NAMES = (
    "bearing_supply",
    "accel_bias",
    "valve_gain",
    "supply_pressure",
    "accel_dropout",
    "accel_saturation",
)


@dataclass(frozen=True)
class ScheduledFault:
    """Set fault ``name`` (one of FAULT_NAMES) to ``value`` at sample time ``t_s``."""

    t_s: float
    name: str
    value: float


@dataclass(frozen=True, slots=True)
class DeviceSample:
    """One tick as the DAQ device publishes it (seq counts from 0 at device start)."""

    seq: int
    t: float
    v_in: float
    accel: float
    position: float
    saturated: bool
    fault_injected: bool


class RealtimeRig:
    """A `hil_sim.rig.Rig` advanced by the wall clock at its sampling rate."""

    def __init__(
        self,
        rig,
        excitation: np.ndarray,
        schedule: Sequence[ScheduledFault] = (),
        clock: Callable[[], float] = time.monotonic,
        max_ticks_per_call: int = 2560,
    ) -> None:
        for item in schedule:
            if item.name not in FAULT_NAMES:
                raise ValueError(f"unknown fault {item.name!r} (known: {', '.join(FAULT_NAMES)})")
        self.rig = rig
        self.fs_hz = float(rig.params.fs_hz)
        self.excitation = np.asarray(excitation, dtype=float).reshape(-1)
        if not len(self.excitation) or not np.all(np.isfinite(self.excitation)):
            raise ValueError("the excitation must be a non-empty array of finite volts")
        # (tick, name, value), applied before the tick is stepped
        self._schedule = sorted(
            (
                (max(0, math.ceil(f.t_s * self.fs_hz - 1e-9)), f.name, float(f.value))
                for f in schedule
            ),
            key=lambda item: item[0],
        )
        self._clock = clock
        self.max_ticks_per_call = int(max_ticks_per_call)
        self._t0: float | None = None
        self._lock = threading.Lock()
        self._pending: dict[str, float] = {}
        self._faults = {name: self._current(name) for name in FAULT_NAMES}
        self._neutral = {
            "bearing_supply": 1.0,
            **{name: neutral for name, (_, neutral, _) in rig_faults().items()},
        }

    # ------------------------------------------------------------------ faults
    def set_bearing_supply(self, fraction: float) -> None:
        self.set_fault("bearing_supply", fraction)

    def set_fault(self, name: str, value: float) -> None:
        """Change a fault while running; checked now, applied before the next tick."""
        if name not in FAULT_NAMES:
            raise ValueError(f"unknown fault {name!r} (known: {', '.join(FAULT_NAMES)})")
        value = float(value)
        if not math.isfinite(value) or (value < 0 and name != "accel_bias"):
            raise ValueError(f"{name} = {value!r} is out of range")
        with self._lock:
            self._pending[name] = value

    def faults(self) -> dict[str, float]:
        """Fault settings as applied to the rig (pending changes included)."""
        with self._lock:
            return {**self._faults, **self._pending}

    def _current(self, name: str) -> float:
        return self.rig.bearing_supply if name == "bearing_supply" else self.rig.fault(name)

    def _apply(self, name: str, value: float) -> None:
        if name == "bearing_supply":
            self.rig.set_bearing_supply(value)
        else:
            self.rig.set_fault(name, value)
        self._faults[name] = value

    @property
    def fault_injected(self) -> bool:
        """True while any fault setting (pending changes included) differs from neutral."""
        faults = self.faults()
        return any(faults[name] != neutral for name, neutral in self._neutral.items())

    # ------------------------------------------------------------------ time
    def start(self, now: float | None = None) -> None:
        """Tick 0 is due at ``now``."""
        self._t0 = self._clock() if now is None else now

    @property
    def tick0_time(self) -> float:
        """Monotonic time at which tick 0 was due; tick k is due at tick0_time + k / fs.
        (CLOCK_MONOTONIC is shared by all processes of the machine: another process can
        measure a sample's latency from it.)"""
        assert self._t0 is not None, "start() first"
        return self._t0

    @property
    def next_tick_time(self) -> float:
        """Monotonic time at which the next tick is due."""
        assert self._t0 is not None, "start() first"
        return self._t0 + self.rig.seq / self.fs_hz

    def due(self, now: float | None = None) -> int:
        """Ticks due at ``now`` and not stepped yet."""
        assert self._t0 is not None, "start() first"
        now = self._clock() if now is None else now
        return max(0, math.floor((now - self._t0) * self.fs_hz) + 1 - self.rig.seq)

    def advance(self, now: float | None = None) -> list[DeviceSample]:
        """Step the rig over the due ticks (at most ``max_ticks_per_call``)."""
        n = min(self.due(now), self.max_ticks_per_call)
        out: list[DeviceSample] = []
        while n > 0:
            with self._lock:
                pending, self._pending = self._pending, {}
            for name, value in pending.items():
                self._apply(name, value)
            chunk = n
            while self._schedule and self._schedule[0][0] <= self.rig.seq:
                _, name, value = self._schedule.pop(0)
                self._apply(name, value)
            if self._schedule:  # stop the chunk at the next scheduled change
                chunk = min(chunk, self._schedule[0][0] - self.rig.seq)
            out.extend(self._step(chunk))
            n -= chunk
        return out

    def _step(self, n: int) -> list[DeviceSample]:
        ticks = (self.rig.seq + np.arange(n)) % len(self.excitation)
        cols = self.rig.run(self.excitation[ticks])
        limit = self.rig.params.accel_range_m_per_s2 * self.rig.fault("accel_saturation")
        lsb = 2.0 * self.rig.params.accel_range_m_per_s2 / 65536.0
        saturated = np.abs(cols["accel"]) >= limit - 1.5 * lsb
        injected = self.fault_injected
        return [
            DeviceSample(
                int(cols["seq"][i]),
                float(cols["t"][i]),
                float(cols["v_in"][i]),
                float(cols["accel"][i]),
                float(cols["position"][i]),
                bool(saturated[i]),
                injected,
            )
            for i in range(n)
        ]


#: the device's scenario when none is given: the paper's test case 1 (1.4 V, 8 Hz sine)
DEFAULT_SCENARIO = {
    "name": "device_default",
    "duration_s": 60.0,
    "centring_gain_v_per_m": 30.0,
    "excitation": [{"kind": "sine", "amplitude_v": 1.4, "frequency_hz": 8.0}],
}


def realtime_rig(
    scenario=None,
    seed: int | None = None,
    faults: Sequence[ScheduledFault] = (),
    clock: Callable[[], float] = time.monotonic,
) -> RealtimeRig:
    """A real-time rig playing ``scenario`` (a `Scenario`, a YAML path, or None for
    `DEFAULT_SCENARIO`) with its events plus ``faults``; the excitation loops."""
    from hil_sim.excitation import build_program
    from hil_sim.rig import Rig
    from hil_sim.rig.rig import compile_kernel
    from hil_sim.scenarios import Scenario, load_scenario, scenario_from_dict

    if scenario is None:
        scenario = scenario_from_dict(DEFAULT_SCENARIO)
    elif not isinstance(scenario, Scenario):
        scenario = load_scenario(scenario)
    seed = scenario.seed if seed is None else int(seed)
    fs = scenario.rig.fs_hz
    program = build_program(
        scenario.excitation,
        fs,
        int(round(scenario.duration_s * fs)),
        np.random.default_rng([seed, 0x5EED]),
    )
    compile_kernel(scenario.rig)  # before the device serves: no multi-second first tick
    rig = Rig(scenario.rig, seed=seed)
    rig.set_centring(scenario.centring_gain_v_per_m)
    schedule = [
        ScheduledFault(ev["t_s"], "bearing_supply", ev["bearing_supply"])
        if "bearing_supply" in ev
        else ScheduledFault(ev["t_s"], ev["fault"], ev["value"])
        for ev in scenario.events
    ]
    return RealtimeRig(rig, program, [*schedule, *faults], clock=clock)
