"""Signals of the diagnose workflow: the comparison domain, the data split, the state chain.

Output kinds. The model file's Ĝ maps v_in to acceleration. A rig may measure velocity
(n = 1) or position (n = 2) instead; then model and measurement are compared in the
measured quantity after the same DC block on both sides:

    measured:  y_f = Hⁿ y,       H(q) = (1 − q⁻¹)/(1 − p q⁻¹)   (first-order DC block)
    model:     ŷ   = Lⁿ Ĝ v_in,  L(q) = (T/2)(1 + q⁻¹)/(1 − p q⁻¹)  (leaky trapezoid)

with p = exp(−2π f_hp T). A sampled velocity obeys (1 − q⁻¹) v = (T/2)(1 + q⁻¹) a to
second order (trapezoid rule), so H v = L a: both sides see the same filter and the
comparison is fair; the leaky pole keeps an integrated offset from drifting. For n = 0
nothing is filtered (so a sensor offset stays visible). The cut-off f_hp is chosen from the data (`highpass_from_input`).

States for the effects (velocity v, position x) come from the *simulated* output
(`StateChain`), not from the measurement: the effect regressors then never contain the
measured output (which would turn the model into a one-step predictor and let any effect
"explain" a coloured residual). Integrations use `core.velocity`'s estimator (first-order
high-pass at f_hp, trapezoid integrator).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal

from fdi_daemon.core.velocity import VelocityEstimator

OUTPUT_KINDS = {"acceleration": 0, "velocity": 1, "position": 2}

#: fraction of the record used to fit (the rest is held out for scoring)
TRAIN_FRACTION = 2.0 / 3.0


def leaky_pole(highpass_hz: float, fs_hz: float) -> float:
    return math.exp(-2.0 * math.pi * highpass_hz / fs_hz)


def measured_transform(n: int, highpass_hz: float, fs_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """(b, a) of Hⁿ, the DC block applied to a measured velocity (n=1) or position (n=2)."""
    p = leaky_pole(highpass_hz, fs_hz)
    b, a = np.array([1.0]), np.array([1.0])
    for _ in range(n):
        b = np.convolve(b, [1.0, -1.0])
        a = np.convolve(a, [1.0, -p])
    return b, a


def domain_plant(
    b_acc: np.ndarray, a_acc: np.ndarray, n: int, highpass_hz: float, fs_hz: float
) -> tuple[np.ndarray, np.ndarray]:
    """Lⁿ Ĝ: the model in the measured quantity's domain (L the leaky trapezoid integrator)."""
    p = leaky_pole(highpass_hz, fs_hz)
    b, a = np.asarray(b_acc, float), np.asarray(a_acc, float)
    for _ in range(n):
        b = np.convolve(b, [0.5, 0.5]) / fs_hz
        a = np.convolve(a, [1.0, -p])
    return b, a


def acceleration_plant(
    b_dom: np.ndarray, a_dom: np.ndarray, n: int, highpass_hz: float, fs_hz: float
) -> tuple[np.ndarray, np.ndarray]:
    """Ĝ in acceleration from a model of the measured quantity: B/A · ((1 − p q⁻¹)/T)ⁿ.

    The exact inverse of the trapezoid L would put a pole at z = −1; the backward difference
    is used instead (stable, half a sample of lag per integration). Only the model file's
    ``plant`` and the simulated states use it; the output is simulated with B/A itself.
    """
    p = leaky_pole(highpass_hz, fs_hz)
    b, a = np.asarray(b_dom, float), np.asarray(a_dom, float)
    for _ in range(n):
        b = np.convolve(b, [1.0, -p]) * fs_hz
    return b, a


def highpass_from_input(u: np.ndarray, fs_hz: float) -> float:
    """DC-block cut-off from the data: a fifth of the frequency below which 2 % of the input's
    (mean-removed) power lies, and at least 3 cycles over the record."""
    u = np.asarray(u, float) - np.mean(u)
    n = len(u)
    nper = min(n, max(256, 2 ** int(math.floor(math.log2(max(n // 4, 2))))))
    f, pxx = signal.welch(u, fs=fs_hz, nperseg=nper)
    f, pxx = f[1:], pxx[1:]
    if not np.any(pxx > 0):
        return 3.0 * fs_hz / n
    cum = np.cumsum(pxx) / np.sum(pxx)
    f_low = float(f[np.searchsorted(cum, 0.02)])
    return float(min(max(f_low / 5.0, 3.0 * fs_hz / n), fs_hz / 20.0))


def state_estimator(fs_hz: float, highpass_hz: float) -> VelocityEstimator:
    """The integrator used for v from â and x from v (first-order DC block, trapezoid)."""
    return VelocityEstimator(
        fs_hz, highpass_hz=highpass_hz, highpass_order=1, integrator="trapezoid"
    )


class StateChain:
    """Velocity v and position x from a simulated output s of kind n (0, 1, 2), streaming.

    n = 0 (acceleration): v = V s, x = V v;  n = 1 (velocity): v = s, x = V s;
    n = 2 (position): x = s, v = (s[k] − s[k−1])/T. V: `state_estimator`. The simulated
    output is noise-free, so the backward difference is harmless.
    """

    def __init__(self, n: int, fs_hz: float, highpass_hz: float) -> None:
        self.n = n
        self.fs_hz = float(fs_hz)
        self._first = state_estimator(fs_hz, highpass_hz)
        self._second = state_estimator(fs_hz, highpass_hz)
        self._prev = 0.0

    def step(self, s: float) -> tuple[float, float]:
        if self.n == 0:
            v = self._first.step(s)
            return v, self._second.step(v)
        if self.n == 1:
            return s, self._first.step(s)
        v = (s - self._prev) * self.fs_hz
        self._prev = s
        return v, s

    def run(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        s = np.asarray(s, dtype=float)
        if self.n == 0:
            v = self._first.run(s)
            return v, self._second.run(v)
        if self.n == 1:
            return s.copy(), self._first.run(s)
        if s.size == 0:
            return s.copy(), s.copy()
        v = np.diff(s, prepend=self._prev) * self.fs_hz
        self._prev = float(s[-1])
        return v, s.copy()

    def reset(self) -> None:
        self._first.reset()
        self._second.reset()
        self._prev = 0.0

    @property
    def state(self) -> list:
        return [self._first.state, self._second.state, self._prev]

    @property
    def coefficients(self) -> tuple[int, np.ndarray, np.ndarray, float]:
        """(n, b, a, fs) of the chain, for the force loop's kernel (`force.ForceLoop`)."""
        return self.n, self._first.b, self._first.a, self.fs_hz


def settle_samples(a: np.ndarray, limit: int) -> int:
    """Samples for the slowest pole of 1/A to decay to 1 %, at most ``limit``."""
    radius = float(np.max(np.abs(np.roots(a)))) if len(a) > 1 else 0.0
    if radius <= 0.0:
        return 0
    if radius >= 1.0:
        return limit
    return int(min(limit, math.ceil(math.log(0.01) / math.log(radius))))


@dataclass
class Split:
    """Index ranges: ``fit`` (after a warm-up) and ``test`` (held out)."""

    warmup: int
    train_end: int
    n: int

    @property
    def fit(self) -> slice:
        return slice(self.warmup, self.train_end)

    @property
    def test(self) -> slice:
        return slice(self.train_end, self.n)


def make_split(n: int, warmup: int) -> Split:
    train_end = int(round(n * TRAIN_FRACTION))
    warmup = min(warmup, train_end // 4)
    return Split(warmup=warmup, train_end=train_end, n=n)


def nrmse(y: np.ndarray, y_hat: np.ndarray) -> float:
    """‖y − ŷ‖ / ‖y − mean(y)‖ (the DESIGN.md ``gap_metric``)."""
    spread = float(np.linalg.norm(y - np.mean(y)))
    if spread == 0.0:
        return math.inf
    return float(np.linalg.norm(y - y_hat) / spread)
