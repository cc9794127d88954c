"""The paper's numerical validation model (§V): a linear mass-spring-damper with friction faults.

    m ẍ = F − k x − c ẋ − F_f                                  (eq. 4–5)
    F   = gain · H_in(s) v_in        H_in: optional 2nd-order low-pass (a valve, say)
    F_f = F_c sign(ẋ) + c_v ẋ        Coulomb and/or viscous fault from ``fault_time_s`` on (eq. 7)

Uniformly distributed noise (full width ``*_noise_width``, i.e. U[−w/2, w/2]) is added to the
measured acceleration, velocity and position, as in §V.

On top of the paper's model, a library of *hideable* physical effects (always on, for the
``fdi diagnose`` tests; DESIGN.md names): ``coulomb_friction`` {force_n},
``viscous_friction`` {coefficient_n_s_per_m}, ``stribeck_friction`` {coulomb_n, static_n,
stribeck_velocity_m_s}, ``cubic_stiffness`` {k3_n_per_m3}, ``dead_time`` {delay_s},
``input_saturation`` {level_v}, ``output_saturation`` {level_m_s2},
``dead_zone`` {half_width_v}, ``backlash`` {gap_v} (play operator on the input),
``sensor_offset`` {offset_m_s2}. Input effects act on v_in in this order: dead time, dead
zone, backlash, saturation; output effects on the measured acceleration: offset, noise,
clipping.

Integration: fixed internal step h = 1/(fs·substeps). The linear part is discretised exactly
(zero-order hold, matrix exponential), so without nonlinear effects the sampled acceleration
equals the exact discrete-time solution. Friction is a force held over each internal step and
chosen implicitly (time-stepping Coulomb law): if the friction available can stop the mass
within the step it sticks (velocity exactly 0 at the end of the step), else it slides with
friction opposing the motion. This is stable and accurate through stick-slip. The cubic spring
force is held over the step (explicit). Deterministic for a given seed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import expm

from fdi_daemon.core.compiled import jit
from fdi_daemon.io.recordings import Recording

EFFECT_NAMES = (
    "coulomb_friction",
    "viscous_friction",
    "stribeck_friction",
    "cubic_stiffness",
    "dead_time",
    "input_saturation",
    "output_saturation",
    "dead_zone",
    "backlash",
    "sensor_offset",
)

#: the parameter keys each effect takes
EFFECT_KEYS: dict[str, tuple[str, ...]] = {
    "coulomb_friction": ("force_n",),
    "viscous_friction": ("coefficient_n_s_per_m",),
    "stribeck_friction": ("coulomb_n", "static_n", "stribeck_velocity_m_s"),
    "cubic_stiffness": ("k3_n_per_m3",),
    "dead_time": ("delay_s",),
    "input_saturation": ("level_v",),
    "output_saturation": ("level_m_s2",),
    "dead_zone": ("half_width_v",),
    "backlash": ("gap_v",),
    "sensor_offset": ("offset_m_s2",),
}


@dataclass
class MsdParams:
    """Physical parameters of the §V model (SI units; input in volts)."""

    mass_kg: float = 1.0
    stiffness_n_per_m: float = 987.0  # 5 Hz natural frequency with 1 kg
    damping_n_s_per_m: float = 6.3  # damping ratio 0.1
    gain_n_per_v: float = 10.0
    input_filter_hz: float | None = 20.0  # None: the input drives the force directly
    input_filter_damping: float = 0.7
    fs_hz: float = 256.0
    substeps: int = 8
    # §V faults, switched on at fault_time_s
    fault_time_s: float = math.inf
    coulomb_n: float = 0.0
    viscous_n_s_per_m: float = 0.0
    # measurement noise, full width of the uniform distribution
    accel_noise_width: float = 0.0
    velocity_noise_width: float = 0.0
    position_noise_width: float = 0.0
    effects: dict[str, dict[str, float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name, params in self.effects.items():
            if name not in EFFECT_KEYS:
                raise ValueError(f"unknown effect {name!r} (known: {', '.join(EFFECT_NAMES)})")
            missing = [k for k in EFFECT_KEYS[name] if k not in params]
            if missing:
                raise ValueError(f"effect {name}: missing {', '.join(missing)}")
        if self.substeps < 1 or self.fs_hz <= 0 or self.mass_kg <= 0:
            raise ValueError("fs_hz, mass_kg must be positive and substeps >= 1")


def state_space(p: MsdParams, extra_damping: float = 0.0) -> tuple[np.ndarray, ...]:
    """Continuous (A, B_u, B_f, C_a, D_a): states [filter z1, z2,] x, ẋ; B_f: force on the mass.

    C_a, D_a give the acceleration ẍ = C_a s + D_a u (without friction).
    """
    m, k, c = p.mass_kg, p.stiffness_n_per_m, p.damping_n_s_per_m + extra_damping
    if p.input_filter_hz is None:
        a = np.array([[0.0, 1.0], [-k / m, -c / m]])
        bu = np.array([0.0, p.gain_n_per_v / m])
        bf = np.array([0.0, 1.0 / m])
        return a, bu, bf, a[1].copy(), bu[1]
    w = 2 * math.pi * p.input_filter_hz
    z = p.input_filter_damping
    a = np.array(
        [
            [0.0, 1.0, 0.0, 0.0],
            [-w * w, -2 * z * w, 0.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
            [p.gain_n_per_v / m, 0.0, -k / m, -c / m],
        ]
    )
    bu = np.array([0.0, w * w, 0.0, 0.0])
    bf = np.array([0.0, 0.0, 0.0, 1.0 / m])
    return a, bu, bf, a[3].copy(), 0.0


def _zoh(a: np.ndarray, b: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    n, nb = a.shape[0], b.shape[1]
    big = np.zeros((n + nb, n + nb))
    big[:n, :n] = a * h
    big[:n, n:] = b * h
    e = expm(big)
    return e[:n, :n], e[:n, n:]


def nominal_tf(p: MsdParams) -> tuple[np.ndarray, np.ndarray]:
    """Exact ZOH discretisation (b, a in q⁻¹) of v_in -> ẍ without any effect or fault."""
    a, bu, _, ca, da = state_space(p)
    return _zoh_tf(a, bu, ca, da, p.fs_hz)


def friction_tf(p: MsdParams) -> tuple[np.ndarray, np.ndarray]:
    """Exact ZOH discretisation (b, a in q⁻¹) of a force on the mass (N) -> ẍ, eq. (6).

    The §V system's exact friction filter of eq. (11) is G_e = −coulomb_n · b/a with
    γ_f = viscous_n_s_per_m / coulomb_n (friction opposes the motion)."""
    a, _, bf, ca, _ = state_space(p)
    return _zoh_tf(a, bf, ca, 1.0 / p.mass_kg, p.fs_hz)


def _zoh_tf(a, b, c, d, fs_hz) -> tuple[np.ndarray, np.ndarray]:
    from scipy.signal import cont2discrete, ss2tf

    ad, bd, cd, dd, _ = cont2discrete(
        (a, b[:, None], c[None, :], np.array([[d]])), 1.0 / fs_hz, method="zoh"
    )
    num, den = ss2tf(ad, bd, cd, dd)
    return np.asarray(num[0], dtype=float), np.asarray(den, dtype=float)


def _input_chain(v_in: np.ndarray, p: MsdParams) -> np.ndarray:
    """The held input of every internal step after dead time, dead zone, backlash, saturation."""
    return input_effects(
        np.repeat(np.asarray(v_in, dtype=float), p.substeps), p.effects, p.fs_hz * p.substeps
    )


def input_effects(u: np.ndarray, effects: dict, rate_hz: float) -> np.ndarray:
    """The input samples ``u`` (V, at ``rate_hz``) after the input effects among
    ``effects`` (name -> parameters, as `MsdParams.effects`), in the order a drive meets
    them: dead time, dead zone, backlash, saturation. Other effects are not applied."""
    u = np.asarray(u, dtype=float)
    if "dead_time" in effects:
        d = int(round(effects["dead_time"]["delay_s"] * rate_hz))
        if d > 0:
            u = np.concatenate([np.full(d, u[0]), u[:-d]])
    if "dead_zone" in effects:
        w = effects["dead_zone"]["half_width_v"]
        u = np.sign(u) * np.maximum(np.abs(u) - w, 0.0)
    if "backlash" in effects:
        half = 0.5 * effects["backlash"]["gap_v"]
        out = np.empty_like(u)
        y = u[0]
        for i, x in enumerate(u.tolist()):
            if x - y > half:
                y = x - half
            elif y - x > half:
                y = x + half
            out[i] = y
        u = out
    if "input_saturation" in effects:
        level = effects["input_saturation"]["level_v"]
        u = np.clip(u, -level, level)
    return u


@jit(nrt=True)
def _integrate(
    ad,
    bdu,
    bdf,
    ca,
    da,
    u_sub,
    substeps,
    fault_step,
    mass_kg,
    coulomb_n,
    coulomb_fault_n,
    viscous_n_s_per_m,
    viscous_fault_n_s_per_m,
    stribeck,
    k3_n_per_m3,
    accel,
    vel,
    pos,
    friction,
):
    """The time-stepping integration of the module docstring: ``ad``… hold the ZOH matrices
    before ([0]) and from ([1]) ``fault_step`` on, ``u_sub`` the held input of every
    internal step, ``stribeck`` (coulomb_n, static_n, stribeck_velocity_m_s) or a NaN
    velocity for none; fills ``accel, vel, pos, friction`` at the samples (the states the
    step starts from, and the friction force F_f of eq. 5 held over it)."""
    ns = ad.shape[1]
    ix, iv = ns - 2, ns - 1
    s = np.zeros(ns)
    free = np.zeros(ns)
    j = 0
    for i in range(accel.size):
        faulty = 1 if i >= fault_step else 0
        c_friction = viscous_n_s_per_m + (viscous_fault_n_s_per_m if faulty else 0.0)
        fc_fault = coulomb_fault_n if faulty else 0.0
        for sub in range(substeps):
            u = u_sub[j]
            j += 1
            x, v = s[ix], s[iv]
            f_ext = -k3_n_per_m3 * x * x * x
            fmax = coulomb_n + fc_fault
            if not math.isnan(stribeck[2]):
                fmax += stribeck[0] + (stribeck[1] - stribeck[0]) * math.exp(
                    -((v / stribeck[2]) ** 2)
                )
            for r in range(ns):
                acc = 0.0
                for q in range(ns):
                    acc += ad[faulty, r, q] * s[q]
                free[r] = acc + bdu[faulty, r] * u + bdf[faulty, r] * f_ext
            f = 0.0
            if fmax > 0.0:
                f_stop = -free[iv] / bdf[faulty, iv]
                f = f_stop if abs(f_stop) <= fmax else -math.copysign(fmax, free[iv])
            if sub == 0:
                acc = 0.0
                for q in range(ns):
                    acc += ca[faulty, q] * s[q]
                accel[i] = acc + da[faulty] * u + (f + f_ext) / mass_kg
                vel[i] = v
                pos[i] = x
                friction[i] = -f + c_friction * v
            for r in range(ns):
                s[r] = free[r] + bdf[faulty, r] * f


class MsdSimulator:
    """Simulates the §V model; ``run(v_in)`` returns every signal sampled at ``fs_hz``."""

    def __init__(self, params: MsdParams | None = None, seed: int = 0) -> None:
        self.params = params if params is not None else MsdParams()
        self.seed = seed

    def run(self, v_in: np.ndarray) -> dict[str, np.ndarray]:
        p = self.params
        eff = p.effects
        v_in = np.asarray(v_in, dtype=float)
        n = v_in.size
        h = 1.0 / (p.fs_hz * p.substeps)
        viscous_effect = eff.get("viscous_friction", {}).get("coefficient_n_s_per_m", 0.0)
        # [0]: before the fault, [1]: from the fault on (its viscous part in the damping)
        ad, bdu, bdf, ca, da = [], [], [], [], []
        for extra in (viscous_effect, viscous_effect + p.viscous_n_s_per_m):
            a, bu, bf, c_a, d_a = state_space(p, extra)
            a_d, b_d = _zoh(a, np.column_stack([bu, bf]), h)
            ad.append(a_d), bdu.append(b_d[:, 0]), bdf.append(b_d[:, 1]), ca.append(c_a)
            da.append(d_a)
        strib = eff.get("stribeck_friction")
        fault_step = math.ceil(p.fault_time_s * p.fs_hz) if math.isfinite(p.fault_time_s) else n + 1
        accel, vel, pos, friction = (np.empty(n) for _ in range(4))
        _integrate(
            np.array(ad),
            np.array(bdu),
            np.array(bdf),
            np.array(ca),
            np.array(da, dtype=float),
            _input_chain(v_in, p),
            p.substeps,
            fault_step,
            p.mass_kg,
            eff.get("coulomb_friction", {}).get("force_n", 0.0),
            p.coulomb_n,
            viscous_effect,
            p.viscous_n_s_per_m,
            np.array(
                [strib["coulomb_n"], strib["static_n"], strib["stribeck_velocity_m_s"]]
                if strib is not None
                else [0.0, 0.0, math.nan]
            ),
            eff.get("cubic_stiffness", {}).get("k3_n_per_m3", 0.0),
            accel,
            vel,
            pos,
            friction,
        )
        rng = np.random.default_rng(self.seed)
        accel_meas = accel + _uniform(rng, p.accel_noise_width, n)
        vel_meas = vel + _uniform(rng, p.velocity_noise_width, n)
        pos_meas = pos + _uniform(rng, p.position_noise_width, n)
        if "sensor_offset" in eff:
            accel_meas = accel_meas + eff["sensor_offset"]["offset_m_s2"]
        if "output_saturation" in eff:
            level = eff["output_saturation"]["level_m_s2"]
            accel_meas = np.clip(accel_meas, -level, level)
        return {
            "t": np.arange(n) / p.fs_hz,
            "v_in": v_in.copy(),
            "accel": accel_meas,
            "velocity": vel_meas,
            "position": pos_meas,
            "accel_true": accel,
            "velocity_true": vel,
            "position_true": pos,
            "friction_force": friction,
            "fault_active": (np.arange(n) >= fault_step).astype(float),
        }

    def record(self, v_in: np.ndarray, with_velocity: bool = True) -> Recording:
        """A `Recording` (DESIGN.md columns ``t, v_in, accel, position[, velocity]`` + truth)."""
        cols = self.run(v_in)
        if not with_velocity:
            del cols["velocity"]
        cols["seq"] = np.arange(len(cols["t"]), dtype=np.int64)
        meta = {
            "fs": repr(float(self.params.fs_hz)),
            "source": "hil_sim.msd",
            "seed": str(self.seed),
            "effects": ",".join(sorted(self.params.effects)) or "none",
        }
        return Recording(cols, meta)


def _uniform(rng: np.random.Generator, width: float, n: int) -> np.ndarray:
    """U[−width/2, width/2] noise (zeros, without drawing, when width is 0)."""
    if width <= 0.0:
        return np.zeros(n)
    return rng.uniform(-0.5 * width, 0.5 * width, n)


def multisine(
    duration_s: float,
    fs_hz: float,
    f_lo_hz: float,
    f_hi_hz: float,
    rms_v: float,
    seed: int = 0,
    n_tones: int = 40,
) -> np.ndarray:
    """Random-phase multisine (log-spaced tones in [f_lo, f_hi]) with the given RMS."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(round(duration_s * fs_hz))) / fs_hz
    freqs = np.geomspace(f_lo_hz, f_hi_hz, n_tones)
    phases = rng.uniform(0.0, 2 * np.pi, n_tones)
    u = np.sin(2 * np.pi * freqs[:, None] * t[None, :] + phases[:, None]).sum(axis=0)
    return u * (rms_v / np.sqrt(np.mean(u * u)))


def simulate_recording(
    params: MsdParams, v_in: np.ndarray, seed: int = 0, with_velocity: bool = True
) -> Recording:
    """Convenience: ``MsdSimulator(params, seed).record(v_in)``."""
    return MsdSimulator(params, seed).record(v_in, with_velocity)
