"""A closed-loop electromechanical positioning stage: motor force in, velocity out.

    M v̇ = F − F_v v − F_c sign(v) − F_0 + w        (a mass on a linear guide, no spring)
    F   = K_p (r − v_m) + K_i ∫(r − v_m) dt          (PI velocity loop on the measured velocity)
    v_m = v + n                                     (velocity sensor with white noise)

F_c: Coulomb friction (N), F_0: a constant force (cable, gravity on a small tilt) (N),
w: a white force disturbance (N). The reference r is a random-phase multisine velocity, or a
periodic one (``periods`` repeats of the same multisine). The plant integrates force into
velocity: a free-run simulation of a linear model of it drifts.

With ``loop="position"`` (`simulate_stage`) a position loop closes around the velocity loop,
as on a machine that moves from point to point (`move_reference`: trapezoidal-velocity moves
with rests between them, where the load is held by its friction):

    r   = K_x (q_ref − x_m) + q̇_ref                (P position loop, velocity feed-forward)
    x_m = encoder position (quantised), v_m = (x_m[k] − x_m[k−1])/T

`POSITIONER` has the sizes of a ball-screw drive (95 kg, 20 N of Coulomb friction, 1 kHz).

Integration: ``substeps`` internal steps per sample with the time-stepping Coulomb law of
`hil_sim.msd` (the mass sticks when the friction available can stop it within the step).
The controller runs at the sample rate (zero-order hold of F). Deterministic for a seed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fdi_daemon.io.recordings import Recording


@dataclass(frozen=True)
class StageParams:
    mass_kg: float = 8.0
    viscous_n_s_per_m: float = 40.0
    coulomb_n: float = 20.0
    offset_n: float = 1.0
    kp_n_s_per_m: float = 400.0
    ki_n_per_m: float = 4000.0
    velocity_noise_m_s: float = 2e-4  # standard deviation
    force_noise_n: float = 0.5  # standard deviation of the force disturbance
    fs_hz: float = 500.0
    substeps: int = 10
    kx_per_s: float = 40.0  # position loop: velocity reference per metre of error (1/s)
    encoder_resolution_m: float = 1e-6


#: a ball-screw positioning drive under a position loop (``loop="position"``)
POSITIONER = StageParams(
    mass_kg=95.0,
    viscous_n_s_per_m=200.0,
    coulomb_n=20.0,
    offset_n=-3.0,
    kp_n_s_per_m=6000.0,
    ki_n_per_m=0.0,
    force_noise_n=1.0,
    fs_hz=1000.0,
)


def velocity_reference(
    duration_s: float,
    fs_hz: float,
    f_lo_hz: float = 0.2,
    f_hi_hz: float = 8.0,
    rms_m_s: float = 0.15,
    seed: int = 0,
    periods: int = 1,
    n_tones: int = 20,
) -> np.ndarray:
    """Random-phase multisine velocity reference; ``periods`` > 1 repeats one period."""
    n_total = int(round(duration_s * fs_hz))
    n_period = n_total // periods
    rng = np.random.default_rng(seed)
    t = np.arange(n_period) / fs_hz
    # tones on the period's frequency grid, so that the repeats join without a step
    df = fs_hz / n_period
    bins = np.unique(np.round(np.geomspace(f_lo_hz, f_hi_hz, n_tones) / df).astype(int))
    bins = bins[bins > 0]
    phases = rng.uniform(0.0, 2 * np.pi, bins.size)
    r = np.sin(2 * np.pi * (bins[:, None] * df) * t[None, :] + phases[:, None]).sum(axis=0)
    r *= rms_m_s / np.sqrt(np.mean(r * r))
    return np.tile(r, periods)


def move_reference(
    duration_s: float,
    fs_hz: float,
    stroke_m: float = 0.2,
    v_max_m_s: float = 0.25,
    a_max_m_s2: float = 2.0,
    rest_s: tuple[float, float] = (0.2, 0.8),
    seed: int = 0,
) -> np.ndarray:
    """Position reference (m) of point-to-point moves: a rest of a random length in
    ``rest_s``, then a move to a random point of the stroke with a trapezoidal velocity
    (acceleration ``a_max``, a random top speed up to ``v_max``), and so on."""
    rng = np.random.default_rng(seed)
    n = int(round(duration_s * fs_hz))
    q = np.empty(n)
    i, here = 0, 0.0
    while i < n:
        rest = int(rng.uniform(*rest_s) * fs_hz)
        q[i : i + rest] = here
        i += rest
        if i >= n:
            break
        there = rng.uniform(0.0, stroke_m)
        length = abs(there - here)
        speed = min(rng.uniform(0.3, 1.0) * v_max_m_s, math.sqrt(length * a_max_m_s2))
        t_acc = speed / a_max_m_s2
        t_end = t_acc + length / speed if speed > 0 else 0.0
        t = np.arange(int(t_end * fs_hz) + 1) / fs_hz
        covered = np.where(
            t < t_acc,
            0.5 * a_max_m_s2 * t**2,
            np.where(
                t < t_end - t_acc,
                speed * (t - 0.5 * t_acc),
                length - 0.5 * a_max_m_s2 * (t_end - t) ** 2,
            ),
        )
        m = min(t.size, n - i)
        q[i : i + m] = here + math.copysign(1.0, there - here) * covered[:m]
        i += t.size
        here = there
    return q


def simulate_stage(
    p: StageParams, reference: np.ndarray, seed: int = 0, loop: str = "velocity"
) -> Recording:
    """Closed-loop run; columns ``t``, ``force`` (N, controller output), ``vel`` (m/s,
    measured), with ``loop="position"`` also ``pos`` (m, the encoder), and the truth
    ``vel_true``, ``friction_true`` (N). ``reference``: velocity (m/s) or, with
    ``loop="position"``, position (m)."""
    if loop not in ("velocity", "position"):
        raise ValueError(f"loop must be 'velocity' or 'position', not {loop!r}")
    rng = np.random.default_rng(seed)
    n = len(reference)
    v_noise = rng.normal(0.0, p.velocity_noise_m_s, n)
    w_noise = rng.normal(0.0, p.force_noise_n, n)
    h = 1.0 / (p.fs_hz * p.substeps)
    decay = math.exp(-p.viscous_n_s_per_m / p.mass_kg * h)
    # v(t+h) = decay v + gain (F_total), exact for a held force on a mass with viscous damping
    gain = (1.0 - decay) / p.viscous_n_s_per_m if p.viscous_n_s_per_m > 0 else h / p.mass_kg
    v = x = 0.0
    x_before = 0.0  # the encoder's last reading (position loop)
    integral = 0.0
    force = np.empty(n)
    vel_meas = np.empty(n)
    pos_meas = np.empty(n)
    vel_true = np.empty(n)
    fric = np.empty(n)
    for i in range(n):
        if loop == "position":
            xm = round(x / p.encoder_resolution_m) * p.encoder_resolution_m
            vm = (xm - x_before) * p.fs_hz
            x_before = xm
            ahead = reference[min(i + 1, n - 1)] - reference[i]
            target = p.kx_per_s * (reference[i] - xm) + ahead * p.fs_hz
        else:
            xm, vm, target = x, v + v_noise[i], reference[i]
        err = target - vm
        f_cmd = p.kp_n_s_per_m * err + p.ki_n_per_m * integral
        integral += err / p.fs_hz
        force[i] = f_cmd
        vel_meas[i] = vm
        pos_meas[i] = xm
        vel_true[i] = v
        f_drive = f_cmd - p.offset_n + w_noise[i]
        f_used = 0.0
        for _ in range(p.substeps):
            free = decay * v + gain * f_drive
            f_stop = free / gain  # friction that would stop the mass at the end of the step
            f = f_stop if abs(f_stop) <= p.coulomb_n else math.copysign(p.coulomb_n, free)
            x += 0.5 * h * (v + free - gain * f)  # trapezoid over the step
            v = free - gain * f
            f_used += f
        fric[i] = f_used / p.substeps
    cols = {
        "t": np.arange(n) / p.fs_hz,
        "force": force,
        "vel": vel_meas,
        "vel_true": vel_true,
        "friction_true": fric,
    }
    if loop == "position":
        cols["pos"] = pos_meas
    return Recording(
        cols, {"fs": repr(float(p.fs_hz)), "source": "hil_sim.stage", "seed": str(seed)}
    )
