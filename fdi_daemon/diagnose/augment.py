"""The augmented model: Ĝ plus the fitted effects, as a streaming block and as a model file.

    ŷ₀ = Lⁿ Ĝ(q) u                    (eq. 1; the measured quantity's domain, ŷ₀ = â for n = 0)
    v, x = states(ŷ₀)                 (simulated velocity and position, `signals.StateChain`)
    ŷ  = ŷ₀ + Σ_e Σ_j G_ej(q) φ_ej(u, v, x, ŷ₀) + Σ_s θ_s φ_s(ŷ₀)     (dynamic, static effects)

Everything is fed forward from the input u — stable filters and static maps, so the
augmented model is stable whatever was fitted — and ``AugmentedPlant`` has the step/run
interface of an IIR block (``step(v_in) -> ŷ``): the monitor can use it as its nominal
model in place of Ĝ. The model file keeps ``plant`` (Ĝ, acceleration) and adds a top-level
``effects`` mapping::

    effects:
      output_kind: acceleration        # domain the effects were fitted in
      highpass_hz: 0.12                # f_hp of the state integrators and of Lⁿ
      domain_plant: {b: [..], a: [..]} # velocity/position only: the model simulated there
      items:
        - {name: coulomb_friction, coefficients: [[b0, .., bn]], physical: {...}}
        - {name: dead_zone, param: {name: half_width, value: 0.05}, centre: 0.01,
           coefficients: [[...]]}          # centre: operating point of a static map
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fdi_daemon.core.iir import IIRFilter
from fdi_daemon.diagnose import signals
from fdi_daemon.diagnose.effects import SPECS, FittedEffect, regressor_param, stored_param
from fdi_daemon.diagnose.force import LOOPED, ForceLoop, kinds
from fdi_daemon.errors import ConfigError
from fdi_daemon.io.model_file import FdiModel


class AugmentedPlant:
    """Streaming simulation of Ĝ plus effects (frozen parameters, explicit state)."""

    def __init__(
        self,
        fs_hz: float,
        plant_b,
        plant_a,
        output_kind: str = "acceleration",
        highpass_hz: float = 1.0,
        effects: list[FittedEffect] | None = None,
        domain: tuple | None = None,
        force_loop: bool = True,
    ) -> None:
        """plant_b/plant_a: Ĝ (acceleration); domain: (b, a) of the model in the measured
        quantity's domain when it was fitted there (default Lⁿ Ĝ). force_loop: force effects
        in feedback with the augmented motion (`force`); False: fed forward from the nominal
        motion (model files written before the loop existed)."""
        if output_kind not in signals.OUTPUT_KINDS:
            raise ValueError(f"output_kind must be one of {', '.join(signals.OUTPUT_KINDS)}")
        self.fs_hz = float(fs_hz)
        self.output_kind = output_kind
        self.highpass_hz = float(highpass_hz)
        self.plant_b = np.asarray(plant_b, dtype=float)
        self.plant_a = np.asarray(plant_a, dtype=float)
        self.effects = list(effects or [])
        n = signals.OUTPUT_KINDS[output_kind]
        self._n = n
        b_dom, a_dom = (
            domain
            if domain is not None and n
            else signals.domain_plant(plant_b, plant_a, n, highpass_hz, fs_hz)
        )
        self.b_dom, self.a_dom = np.asarray(b_dom, float), np.asarray(a_dom, float)
        self._plant = IIRFilter(self.b_dom, self.a_dom)
        self._chain = signals.StateChain(n, fs_hz, highpass_hz)
        self.force_loop = bool(force_loop)
        looped = [e for e in self.effects if force_loop and e.name in LOOPED]
        self._fed = [e for e in self.effects if e not in looped]
        self._blocks = [self._block(eff) for eff in self._fed]
        self._loop = None
        if looped:
            cols = [c for e in looped for c in kinds(e.name, e.param)]
            nums = [b for e in looped for b in e.coefficients]
            self._loop = ForceLoop(self.a_dom, cols, nums, self._chain.coefficients)
        # per fed-forward effect: it acts on the measured output, after the force loop (the
        # motion is the plant's): a sensor's effect where there is a loop
        self._at_sensor = [self._loop is not None and SPECS[e.name].at_sensor for e in self._fed]

    def _block(self, eff: FittedEffect):
        spec = SPECS[eff.name]
        outs: list[IIRFilter] | list[float]
        if spec.dynamic:
            outs = [IIRFilter(b, self.a_dom) for b in eff.coefficients]
        else:
            outs = [float(g) for g in np.atleast_1d(eff.coefficients[0])]
        return [eff.regressor(self.a_dom), spec.dynamic, outs]

    # -- streaming --------------------------------------------------------------------------

    def step(self, v_in: float) -> float:
        """One sample: the augmented model's output."""
        y0 = self._plant.step(v_in)
        v, x = self._chain.step(y0)
        y, sensed = y0, 0.0
        for at_sensor, (reg, dynamic, outs) in zip(self._at_sensor, self._blocks):
            phis = reg.step(v_in, v, x, y0)
            # the effect's columns summed first, then added, as `run_signals` does
            part = (
                sum(filt.step(phi) for filt, phi in zip(outs, phis))
                if dynamic
                else sum(gain * phi for gain, phi in zip(outs, phis))
            )
            if at_sensor:
                sensed += part
            else:
                y += part
        return (y if self._loop is None else self._loop.step(y)) + sensed

    def run(self, v_in: np.ndarray) -> np.ndarray:
        """A whole array, continuing from the current state."""
        return self.run_signals(v_in)["y"]

    def run_signals(self, v_in: np.ndarray) -> dict[str, np.ndarray]:
        """`run`, also returning ŷ₀, v, x and each effect's contribution."""
        u = np.asarray(v_in, dtype=float)
        y0 = self._plant.run(u)
        v, x = self._chain.run(y0)
        y, sensed = y0.copy(), np.zeros_like(y0)
        parts: dict[str, np.ndarray] = {}
        for eff, at_sensor, (reg, dynamic, outs) in zip(self._fed, self._at_sensor, self._blocks):
            phis = reg.run(u, v, x, y0)
            part = np.zeros_like(y0)
            for j, out in enumerate(outs):
                part += out.run(phis[:, j]) if dynamic else out * phis[:, j]
            parts[eff.name] = part
            if at_sensor:
                sensed += part
            else:
                y += part
        if self._loop is not None:
            y_ff = y
            y = self._loop.run(y_ff)
            parts["force_loop"] = y - y_ff
        y = y + sensed
        return {"y0": y0, "v": v, "x": x, "y": y, "parts": parts}

    def reset(self) -> None:
        """Zero every state (filters and regressor memories), as after construction."""
        self._plant.reset()
        self._chain.reset()
        for eff, block in zip(self._fed, self._blocks):
            block[0] = eff.regressor(self.a_dom)
            if block[1]:
                for f in block[2]:
                    f.reset()
        if self._loop is not None:
            self._loop.reset()

    @property
    def state(self) -> list[Any]:
        """All internal states (filters and regressor memories), for comparisons."""
        out: list[Any] = [self._plant.state, *self._chain.state]
        for reg, dynamic, outs in self._blocks:
            out.append(getattr(reg, "state", None))
            if dynamic:
                out.extend(f.state for f in outs)
        if self._loop is not None:
            out.extend(self._loop.state)
        return out

    # -- model file --------------------------------------------------------------------------

    def to_extra(self) -> dict[str, Any]:
        """The ``effects`` mapping of the model file."""
        out = {
            "output_kind": self.output_kind,
            "highpass_hz": self.highpass_hz,
            "force_loop": self.force_loop,
        }
        if self._n:
            out["domain_plant"] = {
                "b": [float(c) for c in self.b_dom],
                "a": [float(c) for c in self.a_dom],
            }
        out["items"] = _items(self.effects, self.fs_hz)
        return out

    @classmethod
    def from_model(cls, model) -> AugmentedPlant:
        """Build from an `FdiModel` (plain Ĝ when the model has no ``effects``)."""
        section = model.extra.get("effects")
        if not section:
            return cls(model.fs, model.plant_b, model.plant_a)
        where = "model: effects"
        if not isinstance(section, dict) or not isinstance(section.get("items", []), list):
            raise ConfigError(f"{where} must be a mapping with a list 'items'")
        kind = section.get("output_kind", "acceleration")
        if kind not in signals.OUTPUT_KINDS:
            raise ConfigError(
                f"{where}.output_kind must be one of {', '.join(signals.OUTPUT_KINDS)}"
            )
        try:
            hp = float(section.get("highpass_hz", 1.0))
        except (TypeError, ValueError):
            raise ConfigError(f"{where}.highpass_hz must be a number") from None
        if not (0 < hp < model.fs / 2):
            raise ConfigError(f"{where}.highpass_hz must lie in (0, fs/2)")
        domain = None
        if section.get("domain_plant") is not None:
            dp = section["domain_plant"]
            try:
                domain = (np.asarray(dp["b"], dtype=float), np.asarray(dp["a"], dtype=float))
            except (KeyError, TypeError, ValueError):
                raise ConfigError(f"{where}.domain_plant must hold lists b and a") from None
        effects = _parse_items(section.get("items", []), model.fs, f"{where}.items")
        loop = section.get("force_loop", False)
        if not isinstance(loop, bool):
            raise ConfigError(f"{where}.force_loop must be true or false")
        try:
            return cls(model.fs, model.plant_b, model.plant_a, kind, hp, effects, domain, loop)
        except ValueError as exc:  # e.g. a mode line on a plant without a pole pair
            raise ConfigError(f"{where}: {exc}") from None


def _items(effects: list[FittedEffect], fs_hz: float) -> list[dict[str, Any]]:
    """Model-file items of a list of effects."""
    items = []
    for eff in effects:
        spec = SPECS[eff.name]
        item: dict[str, Any] = {"name": eff.name}
        if eff.param is not None:
            item["param"] = {
                "name": spec.param,
                "value": float(stored_param(spec, eff.param, fs_hz)),
            }
        if eff.centre != 0.0:
            item["centre"] = float(eff.centre)
        item["coefficients"] = [[float(c) for c in np.atleast_1d(co)] for co in eff.coefficients]
        if eff.physical:
            item["physical"] = {
                k: (
                    float(v)
                    if isinstance(v, (int, float, np.floating)) and not isinstance(v, bool)
                    else v
                )
                for k, v in eff.physical.items()
            }
        items.append(item)
    return items


def _parse_items(raw: Any, fs_hz: float, where: str) -> list[FittedEffect]:
    """Effects from model-file items; errors name the key."""
    if not isinstance(raw, list):
        raise ConfigError(f"{where} must be a list")
    effects = []
    for k, item in enumerate(raw):
        name = item.get("name") if isinstance(item, dict) else None
        if name not in SPECS:
            raise ConfigError(f"{where}[{k}].name: unknown effect {name!r}")
        spec = SPECS[name]
        param = None
        if spec.param is not None:
            try:
                param = regressor_param(spec, float(item["param"]["value"]), fs_hz)
            except (KeyError, TypeError, ValueError):
                raise ConfigError(f"{where}[{k}].param.value missing or not a number") from None
        try:
            coefs = [np.asarray(c, dtype=float) for c in item["coefficients"]]
        except (KeyError, TypeError, ValueError):
            raise ConfigError(f"{where}[{k}].coefficients must be lists of numbers") from None
        if name == "dead_time" and len(coefs) == 1 and coefs[0].size > 1:
            raise ConfigError(
                f"{where}[{k}]: a dead_time written by an older fdi diagnose "
                f"(a filtered input term); run fdi diagnose again"
            )
        centre = item.get("centre", 0.0)
        if isinstance(centre, bool) or not isinstance(centre, (int, float)):
            raise ConfigError(f"{where}[{k}].centre must be a number")
        effects.append(
            FittedEffect(
                name,
                param,
                coefs,
                n_linear=sum(c.size for c in coefs),
                physical=dict(item.get("physical", {})),
                centre=float(centre),
            )
        )
    return effects


def nominal_plant(model: FdiModel) -> IIRFilter | AugmentedPlant:
    """The monitor's nominal model x̂̈ = plant.step(v_in): Ĝ, or Ĝ plus the model's effects.

    Effects fitted on a velocity or position output predict that quantity, not the
    acceleration the monitor compares with: such a model is refused.
    """
    section = model.extra.get("effects")
    if not section:
        return IIRFilter(model.plant_b, model.plant_a)
    plant = AugmentedPlant.from_model(model)
    if plant.output_kind != "acceleration":
        raise ConfigError(
            f"model effects were fitted on {plant.output_kind}; the monitor "
            f"needs effects fitted on acceleration (fdi diagnose "
            f"--output-kind acceleration)"
        )
    return plant
