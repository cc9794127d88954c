"""IIR filter block y = B(q⁻¹)/A(q⁻¹) x with explicit state (Ĝ of eq. 1, G_e of eq. 8).

Transposed direct form II, exactly the recursion of ``scipy.signal.lfilter``::

    y[k]    = b0 x[k] + z0
    z_i     = z_{i+1} + b_{i+1} x[k] - a_{i+1} y[k]     (i = 0 .. n-2)
    z_{n-1} = b_n x[k] - a_n y[k]

Coefficients are frozen at construction and normalised so that a0 = 1 (b and a are padded
with zeros to a common length n + 1). ``step`` works on plain Python floats (the daemon calls
it once per 256 Hz tick); ``run`` filters a whole array with ``lfilter(b, a, x, zi=state)``
and leaves the block in the state the same samples fed one at a time would have left it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

__all__ = ["IIRFilter", "frequency_response"]


#: filter coefficients: a sequence or a 1-D array
Coeffs = Sequence[float] | npt.NDArray[np.float64]


class IIRFilter:
    """A frozen B/A filter with a state vector of length ``order``."""

    __slots__ = ("_b", "_a", "_b_arr", "_a_arr", "_z", "_n", "_taps", "_b0", "_bn", "_an")

    def __init__(self, b: Coeffs, a: Coeffs = (1.0,), state: Sequence[float] | None = None) -> None:
        b_arr = np.atleast_1d(np.asarray(b, dtype=float))
        a_arr = np.atleast_1d(np.asarray(a, dtype=float))
        if b_arr.ndim != 1 or a_arr.ndim != 1 or b_arr.size == 0 or a_arr.size == 0:
            raise ValueError("b and a must be non-empty 1-D coefficient sequences")
        if not (np.all(np.isfinite(b_arr)) and np.all(np.isfinite(a_arr))):
            raise ValueError("filter coefficients must be finite")
        if a_arr[0] == 0.0:
            raise ValueError("a[0] must be non-zero")
        b_arr = b_arr / a_arr[0]
        a_arr = a_arr / a_arr[0]
        n: int = max(b_arr.size, a_arr.size) - 1
        self._b_arr = np.concatenate([b_arr, np.zeros(n + 1 - b_arr.size)])
        self._a_arr = np.concatenate([a_arr, np.zeros(n + 1 - a_arr.size)])
        self._b_arr.flags.writeable = False
        self._a_arr.flags.writeable = False
        self._n = n
        self._b = [float(v) for v in self._b_arr]
        self._a = [float(v) for v in self._a_arr]
        self._b0 = self._b[0]
        self._bn = self._b[n] if n else 0.0
        self._an = self._a[n] if n else 0.0
        # (i, b_{i+1}, a_{i+1}) for the middle delays, precomputed for step()
        self._taps = tuple((i, self._b[i + 1], self._a[i + 1]) for i in range(n - 1))
        self._z = [0.0] * n
        if state is not None:
            self.state = state

    @property
    def b(self) -> np.ndarray:
        """Numerator, normalised (read-only)."""
        return self._b_arr

    @property
    def a(self) -> np.ndarray:
        """Denominator, normalised so that a[0] = 1 (read-only)."""
        return self._a_arr

    @property
    def order(self) -> int:
        """Length of the state vector."""
        return self._n

    @property
    def state(self) -> np.ndarray:
        """A copy of the state vector (the ``zi``/``zf`` of ``lfilter``)."""
        return np.array(self._z, dtype=float)

    @state.setter
    def state(self, value: Coeffs) -> None:
        arr = np.asarray(value, dtype=float).reshape(-1)
        if arr.size != self._n:
            raise ValueError(f"state must have {self._n} elements, got {arr.size}")
        self._z = [float(v) for v in arr]

    def reset(self) -> None:
        """Zero the state."""
        self._z = [0.0] * self._n

    def step(self, x: float) -> float:
        """Filter one sample; returns y[k] as a Python float."""
        z = self._z
        if not z:
            return self._b0 * x
        y = self._b0 * x + z[0]
        for i, bi, ai in self._taps:
            z[i] = z[i + 1] + bi * x - ai * y
        z[-1] = self._bn * x - self._an * y
        return y

    def run(self, x: np.ndarray) -> np.ndarray:
        """Filter an array, continuing from (and updating) the state."""
        x = np.asarray(x, dtype=float)
        if x.ndim != 1:
            raise ValueError("run() takes a 1-D array")
        if not self._n:
            out: np.ndarray = self._b0 * x
            return out
        if x.size == 0:
            empty: np.ndarray = x.copy()
            return empty
        from scipy.signal import lfilter  # here: its import is slow (core/filter_design.py)

        y, zf = lfilter(self._b_arr, self._a_arr, x, zi=np.array(self._z, dtype=float))
        self._z = zf.tolist()
        return np.asarray(y)

    def __repr__(self) -> str:
        return f"IIRFilter(b={self._b}, a={self._a})"


def frequency_response(
    b: npt.ArrayLike, a: npt.ArrayLike, freq_hz: npt.ArrayLike, fs_hz: float
) -> Any:
    """B(e^{jω})/A(e^{jω}) at ``freq_hz`` (Hz; a number or an array) for coefficients in
    powers of z⁻¹."""
    zinv = np.exp(-2j * np.pi * np.asarray(freq_hz) / fs_hz)
    return np.polyval(np.asarray(b)[::-1], zinv) / np.polyval(np.asarray(a)[::-1], zinv)
