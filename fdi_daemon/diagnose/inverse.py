"""The inverse-dynamics form of the test, for integrating and closed-loop plants.

A free-run simulation of a linear model of an integrating plant (force in, velocity out) or
of closed-loop data drifts: a small error in an integrator's input piles up, and under
feedback the input itself answers the output's noise. Then the effects are tested on the
force balance of the moving mass instead, with the *measured* motion:

    L u = M L a + c L v [+ k L x]  +  Σ_e θ_e L φ_e(v, x)        (per sample, least squares)

u the input (a force, or proportional to one), v and x the measured velocity and position,
a = D v the backward-difference acceleration, L a second-order Butterworth low-pass applied
to both sides (the equation holds for any L applied to every term; L keeps the noise that D
amplifies out of the fit). The baseline is M, c (and k for a position output), fitted on the
training part, with u delayed by the lag of the measured motion (`baseline`); the effects'
θ are forces in input units: Coulomb level F_c (sign v), Stribeck excess, cubic spring k₃
(x³, position output only), a constant force F_0 (1).
The gap is the held-out NRMSE of L u: how much of the force the model does not explain.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

from fdi_daemon.diagnose import signals
from fdi_daemon.diagnose.effects import friction_form
from fdi_daemon.diagnose.floor import quiet_variance

#: effects that can be tested in this form (forces on the mass from the measured motion)
INVERSE_CANDIDATES = ("coulomb_friction", "stribeck_friction", "cubic_stiffness", "force_offset")


def lowpass(u: np.ndarray, fs_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """L: 2nd-order Butterworth at twice the frequency below which 98 % of the input power
    lies (at most fs/8)."""
    x = np.asarray(u, float) - np.mean(u)
    f, pxx = signal.welch(x, fs=fs_hz, nperseg=min(len(x), 2048))
    cum = np.cumsum(pxx) / np.sum(pxx) if np.sum(pxx) > 0 else np.linspace(0, 1, f.size)
    f_hi = float(f[min(np.searchsorted(cum, 0.98), f.size - 1)])
    cut = min(max(2.0 * f_hi, 4.0 * fs_hz / len(x)), fs_hz / 8.0)
    return signal.butter(2, cut, fs=fs_hz)


def measured_motion(y: np.ndarray, output_kind: str, fs_hz: float) -> dict[str, np.ndarray]:
    """a, v (and x) over each sample interval [k, k+1], where the held input u[k] acts:
    velocity output: a = (v[k+1] − v[k])/T, v = (v[k+1] + v[k])/2; position output:
    v = (x[k+1] − x[k])/T, a = (x[k+1] − 2x[k] + x[k−1])/T², x = (x[k+1] + x[k])/2.
    The last sample repeats its neighbour."""
    y = np.asarray(y, float)
    ahead = np.append(y[1:], y[-1])
    if output_kind == "velocity":
        return {"a": (ahead - y) * fs_hz, "v": 0.5 * (ahead + y), "x": None}
    if output_kind == "position":
        behind = np.insert(y[:-1], 0, y[0])
        x = 0.5 * (ahead + y)
        return {
            "a": (ahead - 2.0 * y + behind) * fs_hz**2,
            "v": (ahead - y) * fs_hz,
            "x": x - np.mean(x),
        }
    raise ValueError("the inverse-dynamics form needs a velocity or position output")


def noise_sigma(y: np.ndarray) -> float:
    """σ of white noise on a measured signal (a velocity or a position), from the median
    absolute second difference (σ√6 for white noise; a smooth motion hardly contributes)."""
    d2 = np.diff(np.asarray(y, float), 2)
    return 1.4826 * float(np.median(np.abs(d2 - np.median(d2)))) / np.sqrt(6.0)


def at_rest(v: np.ndarray) -> np.ndarray:
    """Samples where the velocity is within 3σ of its noise (`noise_sigma`): at rest,
    friction is whatever holds the mass."""
    return np.abs(v) <= 3.0 * noise_sigma(v)


def settle_samples(b: np.ndarray, a: np.ndarray) -> int:
    """Samples holding 99 % of L's impulse-response energy."""
    h = signal.lfilter(b, a, np.r_[1.0, np.zeros(4095)])
    return int(np.searchsorted(np.cumsum(h * h) / np.sum(h * h), 0.99)) + 1


#: the measured motion may lag the input by up to this many samples (a sensor's filter, a
#: drive's computation): found, not assumed (`baseline`)
MAX_LAG_SAMPLES = 8


def baseline(u, y, output_kind: str, fs_hz: float, split: signals.Split) -> dict:
    """The linear force balance fitted on the training part, and what the effect fits
    need: ``target`` (L u), ``y0`` (its linear prediction), ``columns`` (L a, L v [, L x]),
    the filter, the motion and ``lag``: the samples (0 … MAX_LAG_SAMPLES) by which the
    measured motion lags the input, the one whose balance (with a Coulomb friction and a
    constant force) fits the training part best; the target is then L u[k − lag] (a
    velocity filtered in the drive lags its force).

    Samples at rest (`at_rest`) and those L is still settling from them take no part in
    any fit or gap: their rows are zeroed in the target and every column (``moving``)."""
    b, a = lowpass(u, fs_hz)
    motion = measured_motion(y, output_kind, fs_hz)
    names = ["mass", "damping"] + (["stiffness"] if motion["x"] is not None else [])
    raw = [motion["a"], motion["v"]] + ([motion["x"]] if motion["x"] is not None else [])
    rest = at_rest(motion["v"]).astype(float)
    moving = np.convolve(rest, np.ones(settle_samples(b, a)))[: rest.size] == 0
    cols = np.column_stack([signal.lfilter(b, a, c) for c in raw]) * moving[:, None]
    filtered_u = signal.lfilter(b, a, np.asarray(u, float))
    fit = split.fit
    # the lag is read with a Coulomb friction and a constant force beside the mass and the
    # damping: left out, their force decides the lag (under feedback the force answers the
    # motion, so a shifted force can stand in for the friction)
    forces = [np.sign(motion["v"]), np.ones_like(motion["v"])]
    timing = np.column_stack([cols] + [signal.lfilter(b, a, f) * moving for f in forces])
    targets = [
        np.concatenate([np.full(lag, filtered_u[0]), filtered_u[: len(u) - lag]]) * moving
        for lag in range(MAX_LAG_SAMPLES + 1)
    ]
    shifted = np.column_stack([t[fit] for t in targets])  # one solve for every lag
    sse = np.sum(
        (shifted - timing[fit] @ np.linalg.lstsq(timing[fit], shifted, rcond=None)[0]) ** 2, axis=0
    )
    lag = int(np.argmin(sse))
    target = targets[lag]
    coef, *_ = np.linalg.lstsq(cols[fit], target[fit], rcond=None)
    return {
        "lp": (b, a),
        "target": target,
        "y0": cols @ coef,
        "columns": cols,
        "moving": moving,
        "names": names,
        "lag": lag,
        "coefficients": dict(zip(names, (float(c) for c in coef))),
        "v": motion["v"],
        "x": motion["x"] if motion["x"] is not None else np.zeros_like(motion["v"]),
    }


def physical(name: str, theta: np.ndarray, param: float | None, ctx=None) -> dict:
    """Forces in input units; the Coulomb level must be positive and a Stribeck excess
    leave a positive friction at rest (`effects.friction_form`); the force balance's mass
    positive and its damping not negative."""
    out: dict = {}
    if name == "force_balance":
        values = [ctx.inverse_base[k] + float(t) for k, t in zip(ctx.inverse_base, theta)]
        out.update(zip(ctx.inverse_base, values))
        out["plausible"] = bool(values[0] > 0 and values[1] >= 0)
    elif name == "stribeck_friction":
        assert param is not None  # its velocity is searched
        out["stribeck_velocity"] = float(param)
        out["stribeck_velocity_unit"] = "velocity units"
        out["coulomb_level"], out["stribeck_excess"] = float(theta[0]), float(theta[1])
        out["plausible"] = bool(theta[0] > 0) and friction_form(out, *theta[:2])
    elif name == "coulomb_friction":
        out["coulomb_level"] = float(theta[0])
        out["plausible"] = bool(theta[0] > 0)
    elif name == "cubic_stiffness":
        out["cubic_coefficient"] = float(theta[0])
        out["plausible"] = True
    else:
        out["offset"] = float(theta[0])
        out["plausible"] = True
    return out


def noise_floor(
    y_raw: np.ndarray,
    output_kind: str,
    u: np.ndarray,
    target: np.ndarray,
    coefficients: dict,
    lp: tuple,
    fs_hz: float,
    test: slice,
) -> dict:
    """The part of L u that the force balance cannot explain because the motion is
    measured with noise: white noise σ on the measured output (velocity or position)
    through the balance's own differences (`measured_motion`: M a + c v [+ k x]) and L, as
    an NRMSE of L u. σ is the smaller of two bounds that the motion can only raise: its
    second differences (`noise_sigma`; a motion with content near fs/4 is not smooth there)
    and the output's power density above the input band (`floor.quiet_variance`; none when
    the input fills the band)."""
    sigma = noise_sigma(y_raw)
    quiet, _ = quiet_variance(u, y_raw, fs_hz, test)
    if quiet is not None:
        sigma = min(sigma, math.sqrt(quiet))
    if sigma <= 1e-9 * float(np.std(y_raw)):  # over half the second differences are 0 (to
        # rounding): a quantised or held output, whose noise this cannot measure
        return {
            "floor": None,
            "output_noise": sigma,
            "method": f"{output_kind} noise through the force balance: unknown, the "
            f"{output_kind}'s second differences are mostly zero (quantised "
            "or held)",
        }
    pulse = np.zeros(4096)
    pulse[2] = 1.0  # one noise sample, as every motion term sees it
    motion = measured_motion(pulse, output_kind, fs_hz)
    terms = [motion["a"], motion["v"]] + ([motion["x"]] if motion["x"] is not None else [])
    h = signal.lfilter(*lp, sum(c * t for c, t in zip(coefficients.values(), terms)))
    # the gap's NRMSE runs over every held-out row, the rows at rest being zero on both sides
    live = float(np.mean(target[test] != 0))
    spread = float(np.std(target[test]))
    return {
        "floor": float(sigma * np.sqrt(float(h @ h) * live) / spread) if spread > 0 else None,
        "method": f"{output_kind} noise through the force balance",
        "output_noise": float(sigma),
    }
