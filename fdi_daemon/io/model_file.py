"""The model file (YAML): what `identify` and `signature` write and the monitor reads.

Keys (DESIGN.md; more are welcome, these keep their meaning):
- ``fs``: sampling rate in Hz;
- ``plant: {b: [b0..bn], a: [1, a1..an]}``: Ĝ = B/A in powers of q⁻¹ (eq. 1, b0 = 0);
- ``fault_filter: {b: [...], f: [1, ...], nk: 0, gamma_f: x, band_hz: [lo, hi]}``: G_e = B/F
  (eq. 8), γ_f (eq. 11) and the frequencies (Hz) of the calibration they were fitted on
  (optional: models made before it was recorded have none); optionally
  ``drift: {b: [...], f: [1, ...], nk: 0, gamma: x, highpass_hz: hz}``, the growing-fault
  path's own G_e and γ, fitted with the velocity's high-pass at ``highpass_hz``
  (`fdi signature --drift-highpass-hz`; docs/detector.md §3, "Growing friction");
- ``velocity``: settings of the velocity estimator (high-pass + integrator), kept as a mapping;
- ``detector``: detector settings, kept as a mapping;
- ``provenance``: where the model came from (source hash, date, fit metrics);
- ``effects`` (from `fdi diagnose -o`) and ``baseline`` (the commissioning baseline), kept
  as they are.

An unknown key close to a known one (``gama_f``, ``detectr``) is a typo and refused with
the suggestion; any other unknown top-level key is kept with a warning (the file may be
shared with other tools); a missing required key is named as missing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from fdi_daemon.errors import ConfigError
from fdi_daemon.io.known_keys import split_known
from fdi_daemon.io.outputs import replaced_atomically
from fdi_daemon.io.plain import plain_data
from fdi_daemon.io.yaml_file import read_yaml

SECTIONS = ("fs", "plant", "fault_filter", "velocity", "detector", "provenance")
KNOWN_KEYS = (*SECTIONS, "effects", "baseline")  # these two are kept in FdiModel.extra


@dataclass
class FaultFilter:
    """G_e(q) = q^-nk B(q)/F(q) (eq. 8) and the signature ratio γ_f (eq. 11)."""

    b: np.ndarray
    f: np.ndarray
    nk: int = 0
    gamma_f: float | None = 0.0  # None: not identified (the cost's minimum at the grid edge)
    #: the span (Hz) of the calibration's excitation that G_e and γ_f were fitted on
    #: (`ident.signature.calibration_band_hz`); None: not recorded (a model made before)
    band_hz: tuple[float, float] | None = None
    #: the growing-fault path's own signature (None: it uses this one)
    drift: DriftFilter | None = None


@dataclass
class DriftFilter:
    """The growing-fault path's signature: G_e = q^-nk B/F (eq. 8) fitted at γ (eq. 11, its
    least-cost γ) with the high-pass velocity estimator's cut-off at ``highpass_hz`` (Hz),
    lower than the monitor's, so that sign v̂ is right at 1–3 Hz (docs/detector.md §3)."""

    b: np.ndarray
    f: np.ndarray
    nk: int
    gamma: float
    highpass_hz: float


@dataclass
class FdiModel:
    """Everything the monitor needs about one rig."""

    fs: float
    plant_b: np.ndarray
    plant_a: np.ndarray
    fault_filter: FaultFilter | None = None
    velocity: dict[str, Any] = field(default_factory=dict)
    detector: dict[str, Any] = field(default_factory=dict)
    provenance: dict[str, Any] = field(default_factory=dict)
    extra: dict[str, Any] = field(default_factory=dict)

    def signature_gamma(self) -> float:
        """γ of the signature (1, γ) that G_e was fitted at (eq. 11): γ_f, or where γ_f is not
        identified the least-cost γ of `fdi signature`'s grid (0 if the model does not say)."""
        ff = self.fault_filter
        if ff is not None and ff.gamma_f is not None:
            return float(ff.gamma_f)
        signature = self.provenance.get("signature")
        gamma = signature.get("gamma_at_least_cost") if isinstance(signature, dict) else None
        if isinstance(gamma, bool) or not isinstance(gamma, (int, float)):
            return 0.0
        return float(gamma) if math.isfinite(gamma) else 0.0

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "fs": float(self.fs),
            "plant": {"b": _floats(self.plant_b), "a": _floats(self.plant_a)},
        }
        if self.fault_filter is not None:
            ff = self.fault_filter
            out["fault_filter"] = {
                "b": _floats(ff.b),
                "f": _floats(ff.f),
                "nk": int(ff.nk),
                "gamma_f": None if ff.gamma_f is None else float(ff.gamma_f),
            }
            if ff.band_hz is not None:
                out["fault_filter"]["band_hz"] = [float(v) for v in ff.band_hz]
            if ff.drift is not None:
                d = ff.drift
                out["fault_filter"]["drift"] = {
                    "b": _floats(d.b),
                    "f": _floats(d.f),
                    "nk": int(d.nk),
                    "gamma": float(d.gamma),
                    "highpass_hz": float(d.highpass_hz),
                }
        for key in ("velocity", "detector", "provenance"):
            value = getattr(self, key)
            if value:
                out[key] = plain_data(value)
        out.update(plain_data(self.extra))
        return out


def _floats(values: np.ndarray) -> list[float]:
    return [float(v) for v in np.asarray(values, dtype=float)]


def save_model(path: str | Path, model: FdiModel) -> Path:
    """Write the model as YAML (keys in the documented order)."""
    path = Path(path)
    try:  # whole or not at all: -o may name the model read, which a failed write must keep
        with replaced_atomically(path) as target, open(target, "w", encoding="utf-8") as fh:
            yaml.safe_dump(model.to_dict(), fh, sort_keys=False, default_flow_style=None)
    except OSError as exc:
        raise ConfigError(f"{path}: cannot write model: {exc.strerror or exc}") from None
    return path


def load_model(path: str | Path) -> FdiModel:
    """Read and validate a model file; errors name the file and the key."""
    data = read_yaml(path, "model")
    return model_from_dict(data, str(path))


def model_from_dict(data: Any, source: str = "model") -> FdiModel:
    """Validate a parsed model mapping (see the module docstring for the keys)."""
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: a model file must be a mapping with keys fs, plant, ...")
    split_known(data, KNOWN_KEYS, source, noun="key", fate="keeping")
    _require(data, ("fs", "plant"), source)
    fs = _positive(data, "fs", source)
    plant = _section(data, "plant", ("b", "a"), ("b", "a"), source)
    plant_b = _coefficients(plant, "b", f"{source}: plant")
    plant_a = _coefficients(plant, "a", f"{source}: plant", monic=True)
    fault_filter = None
    if data.get("fault_filter") is not None:
        ff = _section(
            data,
            "fault_filter",
            ("b", "f", "nk", "gamma_f", "band_hz", "drift"),
            ("b", "f"),
            source,
        )
        nk = _delay(ff, f"{source}: fault_filter")
        gamma = ff.get("gamma_f", 0.0)
        if gamma is not None:
            _finite(gamma, f"{source}: fault_filter.gamma_f", " or null")
        fault_filter = FaultFilter(
            b=_coefficients(ff, "b", f"{source}: fault_filter"),
            f=_coefficients(ff, "f", f"{source}: fault_filter", monic=True),
            nk=nk,
            gamma_f=None if gamma is None else float(gamma),
            band_hz=_band(ff.get("band_hz"), f"{source}: fault_filter.band_hz"),
            drift=_drift(ff, f"{source}: fault_filter"),
        )
    sections = {
        key: _mapping(data, key, source, required=False)
        for key in ("velocity", "detector", "provenance")
    }
    extra = {k: v for k, v in data.items() if k not in SECTIONS}
    return FdiModel(
        fs=fs, plant_b=plant_b, plant_a=plant_a, fault_filter=fault_filter, extra=extra, **sections
    )


def _require(data: dict[str, Any], keys: tuple[str, ...], where: str) -> None:
    missing = [key for key in keys if key not in data]
    if missing:
        raise ConfigError(
            f"{where}: missing required key{'s' * (len(missing) > 1)} {', '.join(missing)}"
        )


def _section(
    data: dict[str, Any],
    key: str,
    known: tuple[str, ...],
    required: tuple[str, ...],
    source: str,
    where: str | None = None,
) -> dict[str, Any]:
    """A mapping whose keys are checked: typos refused, other unknown keys ignored with a
    warning, required ones present (``where``: how errors name it, ``source: key`` unless
    given, e.g. a nested section's dotted path)."""
    where = where or f"{source}: {key}"
    section, _ = split_known(_mapping(data, key, source, required=True), known, where, noun="key")
    _require(section, required, where)
    return section


def _finite(value: Any, where: str, alternative: str = "") -> float:
    """A finite number (``alternative``: what else the message says is allowed)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"{where} must be a finite number{alternative}")
    return float(value)


def _delay(section: dict[str, Any], where: str) -> int:
    """G_e's delay nk (samples), a whole number >= 0 (0 when absent)."""
    nk = section.get("nk", 0)
    if not isinstance(nk, int) or isinstance(nk, bool) or nk < 0:
        raise ConfigError(f"{where}.nk must be a whole number >= 0")
    return nk


def _drift(fault_filter: dict[str, Any], where: str) -> DriftFilter | None:
    """``fault_filter.drift`` (the growing-fault path's signature), None when absent."""
    if fault_filter.get("drift") is None:
        return None
    keys = ("b", "f", "nk", "gamma", "highpass_hz")
    d = _section(fault_filter, "drift", keys, keys[:2] + keys[3:], where, f"{where}.drift")
    where = f"{where}.drift"
    gamma = _finite(d["gamma"], f"{where}.gamma")
    hz = d["highpass_hz"]
    if isinstance(hz, bool) or not isinstance(hz, (int, float)) or not 0 < hz < math.inf:
        raise ConfigError(f"{where}.highpass_hz must be a positive number of Hz")
    return DriftFilter(
        b=_coefficients(d, "b", where),
        f=_coefficients(d, "f", where, monic=True),
        nk=_delay(d, where),
        gamma=gamma,
        highpass_hz=float(hz),
    )


def _band(value: Any, where: str) -> tuple[float, float] | None:
    """A frequency band [lo, hi] in Hz, 0 < lo <= hi, or None when absent (null)."""
    if value is None:
        return None
    if (
        not isinstance(value, list)
        or len(value) != 2
        or any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in value)
        or not (math.isfinite(value[1]) and 0 < value[0] <= value[1])
    ):
        raise ConfigError(f"{where} must be [lo, hi] in Hz with 0 < lo <= hi (got {value!r})")
    return float(value[0]), float(value[1])


def _positive(data: dict[str, Any], key: str, source: str) -> float:
    value = data.get(key)
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float))
        or not (math.isfinite(value) and value > 0)
    ):
        raise ConfigError(f"{source}: {key} must be a positive number (got {value!r})")
    return float(value)


def _mapping(data: dict[str, Any], key: str, source: str, required: bool) -> dict[str, Any]:
    value = data.get(key)
    if value is None and not required:
        return {}
    if not isinstance(value, dict):
        raise ConfigError(f"{source}: {key} must be a mapping")
    return value


def _coefficients(section: dict[str, Any], key: str, where: str, monic: bool = False) -> np.ndarray:
    value = section.get(key)
    if (
        not isinstance(value, list)
        or not value
        or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
    ):
        raise ConfigError(f"{where}.{key} must be a non-empty list of numbers")
    arr = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise ConfigError(f"{where}.{key} holds a non-finite coefficient")
    if monic and arr[0] != 1.0:
        raise ConfigError(f"{where}.{key} must start with 1 (monic denominator)")
    return arr
