"""A linear change of the mechanics, read as one parameter of the nominal mode.

The mechanics of eq. (6), m ẍ + c ẋ + k x = F, per unit mass: the mode s² + (c/m) s + k/m
with gain 1/m on the force. Its pole pair is the least damped pair of Â (`nominal_pole`).
A change of one parameter moves the mode along one line and leaves the rest of Ĝ as it is:

| line (`LINES`) | the mode becomes                          | gain on the force | parameter r  |
|----------------|-------------------------------------------|-------------------|--------------|
| damping        | s² + r (c/m) s + k/m                       | 1                 | c₁/c₀        |
| stiffness      | s² + (c/m) s + r k/m                       | 1                 | k₁/k₀        |
| mass           | s² + (c/m) s / r + (k/m) / r               | 1 / r             | m₁/m₀        |

so the changed response is ŷ_r = g P(q)/P_r(q) ŷ₀, P and P_r the pair's polynomials in
q⁻¹ (poles mapped by z = e^{sT}), g the continuous ratio's DC gain (r for the spring's
position, 1/r for the mass's acceleration at high frequency follow from it). The regressor
of a line is φ = ŷ_r − ŷ₀ (`ModeLineRegressor`): a pure change enters with coefficient 1.
Unlike the loop's free spring (`force.in_the_loop`), a line has no free numerator: it cannot
bend the mode towards another parameter's reading, and a gain change, which moves no pole,
is not on any line.
"""

from __future__ import annotations

import cmath

import numpy as np

from fdi_daemon.core.iir import IIRFilter
from fdi_daemon.diagnose.regressors import Regressor

#: the three lines and the effect each stands for when named (`effects.SPECS`: ``mode_*``)
LINES = {"damping": "viscous_friction", "stiffness": "stiffness_change", "mass": "mass_change"}


def nominal_pole(a: np.ndarray) -> complex | None:
    """The least damped pole of the polynomial ``a`` in z⁻¹ (upper half plane, z), the
    nominal mechanical mode; None when ``a`` has no complex pair."""
    z = np.roots(np.asarray(a, float)).astype(complex)
    pairs = [p for p in z if p.imag > 0 and p != 0]
    if not pairs:
        return None
    return min(pairs, key=lambda p: -cmath.log(p).real / abs(cmath.log(p)))


def _moved(pole: complex, line: str, ratio: float) -> tuple[float, float, float]:
    """((c/m) T, (k/m) T², gain on the force) of the nominal pair ``pole`` (z) moved along
    ``line`` by ``ratio`` (module docstring). Per sample, s T = ln z: the sampling rate is
    not needed."""
    s0 = cmath.log(pole)
    damping, stiffness = -2.0 * s0.real, abs(s0) ** 2
    if line == "damping":
        return damping * ratio, stiffness, 1.0
    if line == "stiffness":
        return damping, stiffness * ratio, 1.0
    if line == "mass":
        return damping / ratio, stiffness / ratio, 1.0 / ratio
    raise ValueError(f"unknown mode line {line!r}")


def pair_filter(pole: complex, line: str, ratio: float) -> tuple[np.ndarray, np.ndarray]:
    """(b, a) of g P(q)/P_r(q), the nominal pair ``pole`` moved along ``line`` by ``ratio``,
    with the DC gain of the continuous ratio, g (k₀/m₀)/(k₁/m₁)."""
    damping, stiffness, gain = _moved(pole, line, ratio)
    moved = np.exp(np.roots([1.0, damping, stiffness]).astype(complex))
    p0 = np.real(np.poly([pole, pole.conjugate()]))
    p1 = np.real(np.poly(moved))
    dc = gain * (abs(cmath.log(pole)) ** 2 / stiffness) * (np.sum(p1) / np.sum(p0))
    return dc * p0, p1


def mode_report(pole: complex, line: str, ratio: float, fs_hz: float) -> dict:
    """The nominal and the moved mode in physical units: undamped resonance (Hz), damping
    ratio, and the change of damping per unit mass Δ(c/m) (1/s)."""
    s0 = cmath.log(pole)
    damping, stiffness, _ = _moved(pole, line, ratio)
    return {
        "resonance_hz_nominal": abs(s0) * fs_hz / (2 * np.pi),
        "resonance_hz": np.sqrt(stiffness) * fs_hz / (2 * np.pi),
        "damping_ratio_nominal": -s0.real / abs(s0),
        "damping_ratio": damping / (2.0 * np.sqrt(stiffness)),
        "damping_change_per_s": (damping + 2.0 * s0.real) * fs_hz,
    }


class ModeLineRegressor(Regressor):
    """φ = ŷ_r − ŷ₀: the nominal response with its mode moved along one line (module
    docstring); a streaming block (`run` and `step` give the same)."""

    def __init__(self, line: str, ratio: float, a_dom: np.ndarray) -> None:
        pole = nominal_pole(a_dom)
        if pole is None:
            raise ValueError("the nominal model has no pole pair: no mode to move")
        self.filter = IIRFilter(*pair_filter(pole, line, ratio))

    @property
    def state(self):
        return self.filter.state

    def run(self, u, v, x, y0):
        y0 = np.asarray(y0, float)
        return (self.filter.run(y0) - y0)[:, None]

    def step(self, u, v, x, y0):
        return [self.filter.step(float(y0)) - float(y0)]
