"""The reference for `fdi bench`: the paper's chain compiled, without any detector.

Eqs. (1), (3), (15)–(17) as one numba kernel: Ĝ, the velocity estimator, the two G_e
filters (transposed direct form II, the recursion of ``scipy.signal.lfilter``), the six
window sums of eq. (17) (added and removed per tick, recomputed exactly every N ticks so
they never drift) and the 2×2 solve. No checks, no NaN handling, no decisions: the
arithmetic a tick cannot do without. ``step`` is one compiled call per sample from Python
(what the daemon's loop would pay), ``run`` one call over arrays (what a replay would pay).
The monitor's figures in `fdi bench` are ratios against these two, measured in the same run.
It is compiled as the monitor's kernels are (`core.compiled.jit`: without numba's runtime,
no reference counts on its arrays), so the ratios compare arithmetic with arithmetic.
"""

from __future__ import annotations

import math

import numpy as np

from fdi_daemon.core.compiled import jit

__all__ = ["ReferenceChain"]

#: filters of the chain, in the rows of the coefficient arrays
PLANT, VELOCITY, GE_SIGN, GE_VELOCITY = range(4)


@jit(inline=True)
def _iir(b, a, z, x):
    """One sample through row ``b``/``a`` (a[0] = 1) with state ``z`` (transposed DF-II)."""
    n = z.shape[0]
    y = b[0] * x + z[0]
    for i in range(n - 1):
        z[i] = z[i + 1] + b[i + 1] * x - a[i + 1] * y
    z[n - 1] = b[n] * x - a[n] * y
    return y


@jit(inline=True)
def _accumulate(sums, q1, q2, qy, weight):
    """Add (weight 1) or remove (weight -1) one sample's products to the six sums."""
    sums[0] += weight * q1 * q1
    sums[1] += weight * q1 * q2
    sums[2] += weight * q2 * q2
    sums[3] += weight * q1 * qy
    sums[4] += weight * q2 * qy
    sums[5] += weight * qy * qy


@jit
def _tick(b, a, z, ring, sums, idx, v_in, accel, out):
    """One sample of the chain; θ in out[0], out[1] (NaN until the window is full)."""
    xhat = _iir(b[PLANT], a[PLANT], z[PLANT], v_in)
    r = accel - xhat
    v = _iir(b[VELOCITY], a[VELOCITY], z[VELOCITY], accel)
    s = 1.0 if v > 0.0 else (-1.0 if v < 0.0 else 0.0)
    g1 = _iir(b[GE_SIGN], a[GE_SIGN], z[GE_SIGN], s)
    g2 = _iir(b[GE_VELOCITY], a[GE_VELOCITY], z[GE_VELOCITY], v)
    n = ring.shape[0]
    pos = idx[0]
    if idx[1] == n:  # drop the oldest sample's products
        _accumulate(sums, ring[pos, 0], ring[pos, 1], ring[pos, 2], -1.0)
    else:
        idx[1] += 1
    ring[pos, 0], ring[pos, 1], ring[pos, 2] = g1, g2, r
    _accumulate(sums, g1, g2, r, 1.0)
    pos += 1
    if pos == n:  # exact refresh once per window: no drift
        pos = 0
        for j in range(6):
            sums[j] = 0.0
        for k in range(n):
            _accumulate(sums, ring[k, 0], ring[k, 1], ring[k, 2], 1.0)
    idx[0] = pos
    det = sums[0] * sums[2] - sums[1] * sums[1]
    if idx[1] < n or det <= 0.0:
        out[0] = math.nan
        out[1] = math.nan
    else:
        out[0] = (sums[2] * sums[3] - sums[1] * sums[4]) / det
        out[1] = (sums[0] * sums[4] - sums[1] * sums[3]) / det


@jit
def _run(b, a, z, ring, sums, idx, v_in, accel, theta1, theta2, out):
    for k in range(v_in.shape[0]):
        _tick(b, a, z, ring, sums, idx, v_in[k], accel[k], out)
        theta1[k] = out[0]
        theta2[k] = out[1]


class ReferenceChain:
    """Ĝ, velocity, G_e ×2 and eq. (17) over ``window_samples``, compiled (see module doc).

    filters: four (b, a) pairs in the order plant, velocity, G_e (sign), G_e (velocity).
    """

    def __init__(self, filters, window_samples: int) -> None:
        width = max(max(len(b), len(a)) for b, a in filters)
        self.b = np.zeros((4, width))
        self.a = np.zeros((4, width))
        for row, (b, a) in enumerate(filters):
            a0 = float(a[0])
            self.b[row, : len(b)] = np.asarray(b, dtype=float) / a0
            self.a[row, : len(a)] = np.asarray(a, dtype=float) / a0
        self.z = np.zeros((4, width - 1))
        self.ring = np.zeros((int(window_samples), 3))
        self.sums = np.zeros(6)
        self.idx = np.zeros(2, dtype=np.int64)
        self.out = np.empty(2)

    @classmethod
    def from_model(cls, model, window_samples: int) -> ReferenceChain:
        """The chain of a monitor built on ``model`` (its Ĝ, velocity estimator and G_e)."""
        from fdi_daemon.core.iir import IIRFilter
        from fdi_daemon.core.velocity import VelocityEstimator
        from fdi_daemon.detect.pipeline import Pipeline

        pl = Pipeline(model, window_samples)
        # the reference chain is that of Ĝ and the high-pass velocity estimator
        assert isinstance(pl.plant, IIRFilter) and isinstance(pl.velocity, VelocityEstimator)
        return cls(
            [
                (pl.plant.b, pl.plant.a),
                (pl.velocity.b, pl.velocity.a),
                (pl.ge_sign.b, pl.ge_sign.a),
                (pl.ge_velocity.b, pl.ge_velocity.a),
            ],
            window_samples,
        )

    def step(self, v_in: float, accel: float) -> None:
        """One compiled call for one sample; θ in ``out``."""
        _tick(self.b, self.a, self.z, self.ring, self.sums, self.idx, v_in, accel, self.out)

    def run(self, v_in: np.ndarray, accel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One compiled call over arrays; θ per sample."""
        theta1 = np.empty(len(v_in))
        theta2 = np.empty(len(v_in))
        _run(
            self.b,
            self.a,
            self.z,
            self.ring,
            self.sums,
            self.idx,
            np.ascontiguousarray(v_in, dtype=float),
            np.ascontiguousarray(accel, dtype=float),
            theta1,
            theta2,
            self.out,
        )
        return theta1, theta2
