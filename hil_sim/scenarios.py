"""Scenario files (YAML): what the simulated rig does, and their simulation into a Recording.

Schema (unknown keys are errors naming the key; see docs/sim_rig.md):

    name: test_case_1                 # optional, default: the file name
    description: "..."                # optional
    duration_s: 6.0                   # required
    seed: 0                           # optional default seed (--seed overrides)
    rig: {seal_coulomb_n: 0.1, ...}   # optional overrides of RigParams fields
    centring_gain_v_per_m: 30         # optional weak position-centring term (0 = off)
    excitation: [ {kind: sine, amplitude_v: 1.4, frequency_hz: 8}, ... ]   # hil_sim.excitation
    events:                           # optional, switched at the first sample at/after t_s
      - {t_s: 3.05, bearing_supply: 0.65}
      - {t_s: 2.0, fault: accel_bias, value: 0.5}
    drift:                            # optional slow profiles, piecewise linear, updated 1/s
      supply_pressure: {times_s: [0, 1800, 3600], values: [1.0, 0.97, 1.0]}
      temperature_k: {times_s: [...], values: [...]}
      bearing_supply: {times_s: [...], values: [...]}
    fault_window_s: [4.0, 10.0]       # optional: where the induced friction fault is settled
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field, fields, replace
from pathlib import Path

import numpy as np

from fdi_daemon.errors import ConfigError
from fdi_daemon.io.recordings import Recording
from fdi_daemon.io.yaml_file import read_yaml
from hil_sim.excitation import (
    COMMON_KEYS,
    RANDOM_KINDS,
    SEGMENT_KEYS,
    build_program,
    piecewise_linear,
)
from hil_sim.rig import FAULTS, Rig, RigParams
from hil_sim.rig.params import validate_params

TOP_KEYS = {
    "name",
    "description",
    "duration_s",
    "seed",
    "rig",
    "centring_gain_v_per_m",
    "excitation",
    "events",
    "drift",
    "fault_window_s",
}
DRIFT_KEYS = {"supply_pressure", "temperature_k", "bearing_supply"}
DRIFT_UPDATE_S = 1.0
CHUNK_SAMPLES = 2560

#: recording column order: the DESIGN.md contract first, then ground truth
FIRST_COLUMNS = ("t", "v_in", "accel", "position", "seq")


@dataclass
class Scenario:
    """A validated scenario; ``path`` is where it was read from (None if built in code)."""

    name: str
    duration_s: float
    excitation: list[dict]
    description: str = ""
    seed: int = 0
    rig: RigParams = field(default_factory=RigParams)
    centring_gain_v_per_m: float = 0.0
    events: list[dict] = field(default_factory=list)
    drift: dict[str, dict] = field(default_factory=dict)
    fault_window_s: tuple[float, float] | None = None
    path: Path | None = None


# ----------------------------------------------------------------------------- loading


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario YAML file; a mistake raises a one-line ConfigError."""
    path = Path(path)
    return scenario_from_dict(read_yaml(path, "scenario"), path=path)


def scenario_from_dict(data, path: Path | None = None) -> Scenario:
    """Validate a scenario mapping (as read from YAML)."""
    where = f"{path}: " if path else ""
    if not isinstance(data, dict):
        raise ConfigError(f"{where}a scenario must be a mapping of keys")
    _no_unknown(data, TOP_KEYS, "", where)
    if "duration_s" not in data:
        raise ConfigError(f"{where}missing key 'duration_s'")
    if "excitation" not in data:
        raise ConfigError(f"{where}missing key 'excitation'")
    scenario = Scenario(
        name=_str(data.get("name", path.stem if path else "scenario"), "name", where),
        description=_str(data.get("description", ""), "description", where),
        duration_s=_positive(data["duration_s"], "duration_s", where),
        seed=_int(data.get("seed", 0), "seed", where),
        rig=_rig(data.get("rig", {}), where),
        centring_gain_v_per_m=_number(
            data.get("centring_gain_v_per_m", 0.0), "centring_gain_v_per_m", where, minimum=0.0
        ),
        excitation=_excitation(data["excitation"], where),
        events=_events(data.get("events", []), where),
        drift=_drift(data.get("drift", {}), where),
        path=path,
    )
    if "fault_window_s" in data:
        scenario.fault_window_s = _window(data["fault_window_s"], where)
    return scenario


def _no_unknown(mapping: dict, allowed, prefix: str, where: str) -> None:
    for key in mapping:
        if key not in allowed:
            raise ConfigError(
                f"{where}unknown key '{prefix}{key}' (allowed: {', '.join(sorted(allowed))})"
            )


def _number(value, key: str, where: str, minimum: float | None = None) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"{where}key '{key}' must be a finite number, got {value!r}")
    if minimum is not None and value < minimum:
        raise ConfigError(f"{where}key '{key}' must be >= {minimum:g}, got {value!r}")
    return float(value)


def _positive(value, key: str, where: str) -> float:
    value = _number(value, key, where)
    if value <= 0:
        raise ConfigError(f"{where}key '{key}' must be > 0, got {value!r}")
    return value


def _int(value, key: str, where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ConfigError(f"{where}key '{key}' must be a whole number >= 0, got {value!r}")
    return value


def _str(value, key: str, where: str) -> str:
    if not isinstance(value, str):
        raise ConfigError(f"{where}key '{key}' must be text, got {value!r}")
    return value


def _numbers(value, key: str, where: str, length: int | None = None) -> list[float]:
    if not isinstance(value, list) or not value:
        raise ConfigError(f"{where}key '{key}' must be a non-empty list of numbers")
    out = [_number(v, key, where) for v in value]
    if length is not None and len(out) != length:
        raise ConfigError(f"{where}key '{key}' must hold {length} numbers, got {len(out)}")
    return out


def _rig(value, where: str) -> RigParams:
    if not isinstance(value, dict):
        raise ConfigError(f"{where}key 'rig' must be a mapping of RigParams fields")
    names = {f.name for f in fields(RigParams)}
    _no_unknown(value, names, "rig.", where)
    for key, v in value.items():
        _number(v, f"rig.{key}", where)
    try:
        params = replace(RigParams(), **value)
        validate_params(params)
    except ValueError as exc:
        raise ConfigError(f"{where}key 'rig': {exc}") from None
    return params


def _excitation(value, where: str) -> list[dict]:
    if isinstance(value, dict):
        value = [value]
    if not isinstance(value, list) or not value:
        raise ConfigError(f"{where}key 'excitation' must be a segment or a list of segments")
    segments = []
    for i, seg in enumerate(value):
        prefix = f"excitation[{i}]."
        if not isinstance(seg, dict):
            raise ConfigError(f"{where}key 'excitation[{i}]' must be a mapping")
        kind = seg.get("kind")
        if kind not in SEGMENT_KEYS:
            raise ConfigError(
                f"{where}key '{prefix}kind' must be one of {', '.join(SEGMENT_KEYS)}, got {kind!r}"
            )
        required, optional = SEGMENT_KEYS[kind]
        _no_unknown(seg, required | optional | COMMON_KEYS, prefix, where)
        for key in sorted(required):
            if key not in seg:
                raise ConfigError(f"{where}missing key '{prefix}{key}' for a {kind} segment")
        if "duration_s" not in seg and i != len(value) - 1:
            raise ConfigError(
                f"{where}key '{prefix}duration_s' is needed on every segment but the last"
            )
        segments.append(_segment(seg, prefix, where))
    return segments


def _segment(seg: dict, prefix: str, where: str) -> dict:
    out = {"kind": seg["kind"]}
    lists = {"amplitudes_v", "frequencies_hz", "phases_deg", "levels_v"}
    ranges = {"amplitude_v", "frequency_hz", "segment_s"} if seg["kind"] == "random" else set()
    for key, value in seg.items():
        name = prefix + key
        if key == "kind":
            continue
        if key == "alternate_sign":
            if not isinstance(value, bool):
                raise ConfigError(f"{where}key '{name}' must be true or false")
            out[key] = value
        elif key == "kinds":
            if (
                not isinstance(value, list)
                or not value
                or any(k not in RANDOM_KINDS for k in value)
            ):
                raise ConfigError(
                    f"{where}key '{name}' must list some of {', '.join(RANDOM_KINDS)}"
                )
            out[key] = list(value)
        elif key in ranges:
            lo, hi = _numbers(value, name, where, length=2)
            if not 0 <= lo <= hi:
                raise ConfigError(f"{where}key '{name}' must be [low, high] with 0 <= low <= high")
            out[key] = (lo, hi)
        elif key in lists:
            out[key] = _numbers(value, name, where)
        elif key in {"duration_s", "period_s", "hold_s"}:
            out[key] = _positive(value, name, where)
        elif key in {"frequency_hz", "f0_hz", "f1_hz"}:
            out[key] = _number(value, name, where, minimum=0.0)
        else:
            out[key] = _number(value, name, where)
    if seg["kind"] == "multisine":
        n = len(out["frequencies_hz"])
        if len(out["amplitudes_v"]) != n or len(out.get("phases_deg", [0] * n)) != n:
            raise ConfigError(
                f"{where}keys '{prefix}amplitudes_v', '{prefix}frequencies_hz' "
                "(and phases_deg) must have the same length"
            )
    if seg["kind"] == "random" and out["segment_s"][0] <= 0:
        raise ConfigError(f"{where}key '{prefix}segment_s' must be > 0")
    return out


def _events(value, where: str) -> list[dict]:
    if not isinstance(value, list):
        raise ConfigError(f"{where}key 'events' must be a list")
    events = []
    for i, ev in enumerate(value):
        prefix = f"events[{i}]."
        if not isinstance(ev, dict):
            raise ConfigError(f"{where}key 'events[{i}]' must be a mapping")
        if "t_s" not in ev:
            raise ConfigError(f"{where}missing key '{prefix}t_s'")
        t = _number(ev["t_s"], prefix + "t_s", where, minimum=0.0)
        if "bearing_supply" in ev:
            _no_unknown(ev, {"t_s", "bearing_supply"}, prefix, where)
            events.append(
                {
                    "t_s": t,
                    "bearing_supply": _number(
                        ev["bearing_supply"], prefix + "bearing_supply", where, minimum=0.0
                    ),
                }
            )
        elif "fault" in ev:
            _no_unknown(ev, {"t_s", "fault", "value"}, prefix, where)
            if ev["fault"] not in FAULTS:
                raise ConfigError(
                    f"{where}key '{prefix}fault' must be one of "
                    f"{', '.join(FAULTS)}, got {ev['fault']!r}"
                )
            if "value" not in ev:
                raise ConfigError(f"{where}missing key '{prefix}value'")
            minimum = None if ev["fault"] == "accel_bias" else 0.0
            events.append(
                {
                    "t_s": t,
                    "fault": ev["fault"],
                    "value": _number(ev["value"], prefix + "value", where, minimum),
                }
            )
        else:
            raise ConfigError(f"{where}key 'events[{i}]' needs 'bearing_supply' or 'fault'")
    return sorted(events, key=lambda e: e["t_s"])


def _drift(value, where: str) -> dict[str, dict]:
    if not isinstance(value, dict):
        raise ConfigError(f"{where}key 'drift' must be a mapping")
    _no_unknown(value, DRIFT_KEYS, "drift.", where)
    out = {}
    for name, prof in value.items():
        prefix = f"drift.{name}."
        if not isinstance(prof, dict):
            raise ConfigError(f"{where}key 'drift.{name}' must be a mapping with times_s, values")
        _no_unknown(prof, {"times_s", "values"}, prefix, where)
        for key in ("times_s", "values"):
            if key not in prof:
                raise ConfigError(f"{where}missing key '{prefix}{key}'")
        times = _numbers(prof["times_s"], prefix + "times_s", where)
        values = _numbers(prof["values"], prefix + "values", where, length=len(times))
        if any(b <= a for a, b in zip(times, times[1:])):
            raise ConfigError(f"{where}key '{prefix}times_s' must increase")
        if any(v <= 0 for v in values):
            raise ConfigError(f"{where}key '{prefix}values' must be > 0")
        out[name] = {"times_s": times, "values": values}
    return out


def _window(value, where: str) -> tuple[float, float]:
    t0, t1 = _numbers(value, "fault_window_s", where, length=2)
    if not 0 <= t0 < t1:
        raise ConfigError(f"{where}key 'fault_window_s' must be [t0, t1] with 0 <= t0 < t1")
    return t0, t1


# ----------------------------------------------------------------------------- simulating


#: memory a simulation holds per sample at its peak (the columns while they are joined)
BYTES_PER_SAMPLE = 400


def _memory_bytes() -> int | None:
    """This machine's physical memory, where the system tells it."""
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def simulate(
    scenario: Scenario,
    seed: int | None = None,
    duration_s: float | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> Recording:
    """Run the scenario on a fresh `Rig`; returns the recording with ground truth.

    seed: rig noise and random excitation (default: the scenario's seed); duration_s
    overrides the scenario's; progress(done_samples, total_samples) is called per chunk.
    """
    seed = scenario.seed if seed is None else int(seed)
    duration = scenario.duration_s if duration_s is None else float(duration_s)
    fs = scenario.rig.fs_hz
    n = int(round(duration * fs))
    if n < 2:
        raise ConfigError(f"duration {duration:g} s gives fewer than 2 samples")
    memory = _memory_bytes()
    if memory is not None and n * BYTES_PER_SAMPLE > memory:
        raise ConfigError(
            f"duration {duration:g} s: the recording would need about "
            f"{n * BYTES_PER_SAMPLE / 1e9:.3g} GB of memory, more than this "
            f"machine has ({memory / 1e9:.3g} GB); simulate shorter pieces"
        )
    excitation = build_program(scenario.excitation, fs, n, np.random.default_rng([seed, 0x5EED]))
    rig = Rig(scenario.rig, seed=seed)
    rig.set_centring(scenario.centring_gain_v_per_m)
    event_index = [int(math.ceil(ev["t_s"] * fs - 1e-9)) for ev in scenario.events]
    boundaries = set(range(0, n, CHUNK_SAMPLES)) | {i for i in event_index if i < n}
    if scenario.drift:
        boundaries |= set(range(0, n, int(round(DRIFT_UPDATE_S * fs))))
    edges = sorted(boundaries) + [n]
    parts: list[dict[str, np.ndarray]] = []
    next_event = 0
    for start, stop in zip(edges[:-1], edges[1:]):
        _apply_drift(rig, scenario.drift, start / fs)
        while next_event < len(scenario.events) and event_index[next_event] <= start:
            _apply_event(rig, scenario.events[next_event])
            next_event += 1
        parts.append(rig.run(excitation[start:stop]))
        if progress is not None:
            progress(stop, n)
    columns = {name: np.concatenate([p[name] for p in parts]) for name in parts[0]}
    ordered = {name: columns[name] for name in FIRST_COLUMNS}
    ordered.update({k: v for k, v in columns.items() if k not in ordered})
    ordered["seq"] = ordered["seq"].astype(np.int64)
    return Recording(ordered, _metadata(scenario, seed, duration, fs))


def _apply_drift(rig: Rig, drift: dict[str, dict], t: float) -> None:
    for name, prof in drift.items():
        value = float(piecewise_linear(t, prof["times_s"], prof["values"]))
        if name == "supply_pressure":
            rig.set_supply_drift(value)
        elif name == "temperature_k":
            rig.set_temperature(value)
        else:
            rig.set_bearing_supply(value)


def _apply_event(rig: Rig, event: dict) -> None:
    if "bearing_supply" in event:
        rig.set_bearing_supply(event["bearing_supply"])
    else:
        rig.set_fault(event["fault"], event["value"])


def _metadata(scenario: Scenario, seed: int, duration: float, fs: float) -> dict[str, str]:
    meta = {
        "fs": f"{fs:g}",
        "scenario": scenario.name,
        "seed": str(seed),
        "duration_s": f"{duration:g}",
        "source": "hil_sim nonlinear servo-pneumatic rig",
        "substeps": str(scenario.rig.substeps),
        "centring_gain_v_per_m": f"{scenario.centring_gain_v_per_m:g}",
        "events": json.dumps(scenario.events, separators=(",", ":")),
        "ground_truth": "friction_force (N, air bearing), seal_friction_force (N), "
        "contact_force (N), fault_active (bearing in contact), "
        "other_fault_active, bearing_supply (fraction)",
    }
    if scenario.path is not None:
        meta["scenario_file"] = str(scenario.path)
    friction = [
        ev["t_s"] for ev in scenario.events if "bearing_supply" in ev and ev["bearing_supply"] < 1.0
    ]
    if friction:
        meta["friction_fault_t"] = f"{friction[0]:g}"
    other = [
        ev for ev in scenario.events if "fault" in ev and ev["value"] != FAULTS[ev["fault"]][1]
    ]
    if other:
        meta["other_fault_t"] = f"{other[0]['t_s']:g}"
        meta["other_fault"] = other[0]["fault"]
    if scenario.fault_window_s is not None:
        meta["fault_window"] = f"{scenario.fault_window_s[0]:g}:{scenario.fault_window_s[1]:g}"
    return meta
