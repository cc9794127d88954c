"""The simulated rig: frozen parameters, explicit state, per-sample `step` and batch `run`.

`Rig.step(v)` and `Rig.run(array)` call the same compiled kernel and draw process and sensor
noise from one stream consumed in fixed blocks, so any chunking of the input gives bit-equal
outputs and the same final state.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hil_sim.rig import kernel as K
from hil_sim.rig.chambers import orifice_flow
from hil_sim.rig.params import (
    C_ACCEL_BIAS,
    C_ACCEL_DROPOUT,
    C_ACCEL_RANGE,
    C_BEARING_SUPPLY,
    C_CENTRING,
    C_SUPPLY,
    C_TEMPERATURE,
    C_VALVE_GAIN,
    P_ATM,
    P_B,
    P_FLOW_CONST,
    P_NOZZLE_AREA,
    P_PHI_LAM,
    P_PR_LAM,
    P_SUPPLY,
    P_SUPPLY_AREA,
    RigParams,
    new_controls,
    pack_params,
)

#: fault name -> (control index, neutral value, meaning)
FAULTS: dict[str, tuple[int, float, str]] = {
    "accel_bias": (C_ACCEL_BIAS, 0.0, "extra accelerometer bias (m/s²)"),
    "valve_gain": (C_VALVE_GAIN, 1.0, "valve gain as a fraction of nominal"),
    "supply_pressure": (C_SUPPLY, 1.0, "supply pressure as a fraction of nominal"),
    "accel_dropout": (C_ACCEL_DROPOUT, 0.0, "1: accelerometer reads 0 (broken cable)"),
    "accel_saturation": (C_ACCEL_RANGE, 1.0, "accelerometer range as a fraction of nominal"),
}

#: recording column name -> kernel output column, in recording order after t, seq
OUTPUT_COLUMNS: dict[str, int] = {
    "v_in": K.O_V_IN,
    "accel": K.O_ACCEL,
    "position": K.O_POSITION,
    "friction_force": K.O_FRICTION,
    "seal_friction_force": K.O_SEAL_FRICTION,
    "contact_force": K.O_CONTACT,
    "bearing_pressure": K.O_BEARING_P,
    "position_true": K.O_POSITION_TRUE,
    "velocity_true": K.O_VELOCITY,
    "accel_true": K.O_ACCEL_TRUE,
    "valve_drive": K.O_DRIVE,
    "p1": K.O_P1,
    "p2": K.O_P2,
    "stuck": K.O_STUCK,
}

NOISE_BLOCK_SAMPLES = 4096


@dataclass(frozen=True, slots=True)
class RigOutput:
    """One 256 Hz sample. Sensor readings as the DAQ sees them (v_in, accel, position) and
    ground truth: friction forces (N), fault_active (1 while the bearing is in contact),
    other_fault_active (1 while a non-friction fault is set), bearing_supply (fraction)."""

    seq: int
    t: float
    v_in: float
    accel: float
    position: float
    friction_force: float
    seal_friction_force: float
    contact_force: float
    bearing_pressure: float
    position_true: float
    velocity_true: float
    accel_true: float
    valve_drive: float
    p1: float
    p2: float
    stuck: float
    fault_active: float
    other_fault_active: float
    bearing_supply: float


class NoiseStream:
    """Standard normal draws (samples × channels) from one seeded generator, produced in
    fixed blocks so the sequence does not depend on how callers chunk their requests."""

    def __init__(self, seed: int, channels: int, block_samples: int = NOISE_BLOCK_SAMPLES):
        self._rng = np.random.default_rng(seed)
        self._channels = channels
        self._block_samples = block_samples
        self._block = np.empty((0, channels))
        self._pos = 0

    def take(self, n: int) -> np.ndarray:
        parts = []
        need = n
        while need > 0:
            if self._pos >= len(self._block):
                self._block = self._rng.standard_normal((self._block_samples, self._channels))
                self._pos = 0
            got = min(need, len(self._block) - self._pos)
            parts.append(self._block[self._pos : self._pos + got])
            self._pos += got
            need -= got
        if not parts:
            return np.empty((0, self._channels))
        return parts[0] if len(parts) == 1 else np.concatenate(parts)


def null_pressure_pa(packed: np.ndarray, supply_fraction: float, temperature_k: float) -> float:
    """Chamber pressure (Pa abs) where supply inflow equals nozzle bleed at centred flapper."""
    args = (packed[P_FLOW_CONST], temperature_k, packed[P_B], packed[P_PR_LAM], packed[P_PHI_LAM])
    p_sup = packed[P_SUPPLY] * supply_fraction
    lo, hi = packed[P_ATM], p_sup
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        net = orifice_flow(p_sup, mid, packed[P_SUPPLY_AREA], *args) - orifice_flow(
            mid, packed[P_ATM], packed[P_NOZZLE_AREA], *args
        )
        if net > 0.0:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def compile_kernel(params: RigParams | None = None) -> None:
    """Compile the physics kernel now (or load it from numba's cache), on a throwaway rig.

    Compiling takes seconds on a fresh install and holds the interpreter: a real-time device
    must do it before it starts serving, not on its first tick."""
    Rig(params, seed=0).run(np.zeros(1))


class Rig:
    """The nonlinear servo-pneumatic rig sampled at ``params.fs_hz``.

    Starts at rest at mid-stroke, chambers at the valve's null pressure, bearing floating.
    """

    def __init__(self, params: RigParams | None = None, seed: int = 0):
        self.params = params if params is not None else RigParams()
        self.seed = int(seed)
        self._packed = pack_params(self.params)
        self._controls = new_controls(self.params)
        self._faults = {name: neutral for name, (_, neutral, _) in FAULTS.items()}
        self._supply_drift = 1.0
        self._noise = NoiseStream(self.seed, K.N_NOISE)
        self.seq = 0
        self.state = np.zeros(K.N_STATE)
        p0 = null_pressure_pa(self._packed, 1.0, self.params.temperature_k)
        self.state[K.S_P1] = p0
        self.state[K.S_P2] = p0
        self.state[K.S_STUCK] = 1.0
        self.state[K.S_PB] = self.params.bearing_supply_pa

    # ------------------------------------------------------------ fault schedule
    def set_bearing_supply(self, fraction: float) -> None:
        """Air-bearing supply as a fraction of nominal: 1 floats (no friction), lower -> contact."""
        self._controls[C_BEARING_SUPPLY] = _finite_nonneg("bearing supply", fraction)

    def set_fault(self, name: str, value: float) -> None:
        """Set a non-friction fault (see `FAULTS`); its neutral value switches it off."""
        if name not in FAULTS:
            raise ValueError(f"unknown fault {name!r} (known: {', '.join(FAULTS)})")
        check = _finite if name == "accel_bias" else _finite_nonneg
        self._faults[name] = check(name, value)
        self._apply_controls()

    def set_supply_drift(self, fraction: float) -> None:
        """Slow drift of the supply pressure (fraction of nominal); multiplies any
        ``supply_pressure`` fault."""
        self._supply_drift = _finite_nonneg("supply drift", fraction)
        self._apply_controls()

    def set_temperature(self, kelvin: float) -> None:
        """Air temperature (K) of supply and chambers."""
        self._controls[C_TEMPERATURE] = _finite_nonneg("temperature", kelvin)

    def set_centring(self, gain_v_per_m: float) -> None:
        """Weak position-centring term: the valve sees v_in - gain·LVDT (0 switches it off)."""
        self._controls[C_CENTRING] = _finite_nonneg("centring gain", gain_v_per_m)

    @property
    def bearing_supply(self) -> float:
        return float(self._controls[C_BEARING_SUPPLY])

    def fault(self, name: str) -> float:
        """Current value of a non-friction fault."""
        return self._faults[name]

    @property
    def other_fault_active(self) -> bool:
        return any(self._faults[name] != neutral for name, (_, neutral, _) in FAULTS.items())

    def _apply_controls(self) -> None:
        for name, (index, _, _) in FAULTS.items():
            self._controls[index] = self._faults[name]
        self._controls[C_SUPPLY] = self._faults["supply_pressure"] * self._supply_drift

    # ------------------------------------------------------------ simulation
    @property
    def t(self) -> float:
        """Time (s) of the next sample."""
        return self.seq / self.params.fs_hz

    def run(self, v_in: np.ndarray) -> dict[str, np.ndarray]:
        """Advance over len(v_in) samples of valve voltage (V); columns as in a recording."""
        u = np.ascontiguousarray(v_in, dtype=np.float64).reshape(-1)
        if not np.all(np.isfinite(u)):
            raise ValueError("valve voltage must be finite")
        first, out = self._advance(u)
        n = len(u)
        seq = np.arange(first, first + n, dtype=np.int64)
        cols: dict[str, np.ndarray] = {"t": seq / self.params.fs_hz}
        for name, j in OUTPUT_COLUMNS.items():
            cols[name] = out[:, j].copy()
        cols["seq"] = seq
        cols["fault_active"] = (cols["contact_force"] > 0.0).astype(np.float64)
        cols["other_fault_active"] = np.full(n, float(self.other_fault_active))
        cols["bearing_supply"] = np.full(n, self.bearing_supply)
        return cols

    def step(self, v_in_volts: float) -> RigOutput:
        """One sample: read the sensors at t, then hold ``v_in_volts`` until the next sample."""
        u = float(v_in_volts)
        if not math.isfinite(u):
            raise ValueError("valve voltage must be finite")
        seq, out = self._advance(np.array([u]))
        row = out[0].tolist()
        values = {name: row[j] for name, j in OUTPUT_COLUMNS.items()}
        return RigOutput(
            seq=seq,
            t=seq / self.params.fs_hz,
            fault_active=1.0 if values["contact_force"] > 0.0 else 0.0,
            other_fault_active=float(self.other_fault_active),
            bearing_supply=self.bearing_supply,
            **values,
        )

    def _advance(self, u: np.ndarray) -> tuple[int, np.ndarray]:
        """Run the kernel over ``u``; returns (seq of the first sample, output matrix)."""
        out = np.empty((len(u), K.N_OUT))
        K.run_samples(self.state, self._packed, self._controls, u, self._noise.take(len(u)), out)
        first = self.seq
        self.seq += len(u)
        return first, out


def _finite(name: str, value: float) -> float:
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return value


def _finite_nonneg(name: str, value: float) -> float:
    value = _finite(name, value)
    if value < 0.0:
        raise ValueError(f"{name} must be >= 0, got {value!r}")
    return value
