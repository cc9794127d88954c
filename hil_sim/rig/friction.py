"""Friction of the moving mass: rod seal (always present) and air bearing (the fault).

Rod seal: Coulomb + Stribeck (a little stiction), present before any fault.
Air bearing: lift = pocket pressure × effective area; when lift falls below the block weight
the surplus weight becomes a contact normal force N, and the contact adds
    F = N·(μk + (μs - μk)·exp(-(v/vs)²))·sign(v) + N·c_v·v.
Stick-slip uses an explicit stick state with a breakaway test (see `mechanics_step`).
"""

import math

from fdi_daemon.core.compiled import jit


@jit(nrt=True)
def contact_force(bearing_pa, weight_n, lift_area_m2):
    """Normal force (N) of the block on the surface for a gauge pocket pressure."""
    return max(0.0, weight_n - bearing_pa * lift_area_m2)


@jit(nrt=True)
def stribeck_level(speed, coulomb, static, stribeck_velocity):
    """Magnitude of dry friction at |v| = speed: Coulomb plus an exponentially fading excess."""
    r = speed / stribeck_velocity
    return coulomb + (static - coulomb) * math.exp(-r * r)


@jit(nrt=True)
def mechanics_step(
    x,
    v,
    stuck,
    f_drive,
    mass,
    dt,
    seal_fc,
    seal_fs,
    seal_vs,
    normal_n,
    mu_k,
    mu_s,
    bearing_vs,
    visc_per_n,
):
    """One semi-implicit Euler step of m·ẍ = F_drive - F_seal - F_bearing with stick-slip.

    f_drive: every non-friction force (pressure, bumpers, linear damping, process noise) (N).
    Stuck: the mass stays at rest while |F_drive| <= breakaway (seal static + μs·N); friction
    then equals F_drive. Sliding: friction opposes v (or F_drive when v = 0); when v would
    cross zero within the step and |F_drive| <= breakaway, the mass sticks at v = 0.
    Returns (x, v, stuck, accel, seal_friction, bearing_friction).
    """
    breakaway = seal_fs + mu_s * normal_n
    if stuck and abs(f_drive) <= breakaway:
        if breakaway > 0.0:
            share = mu_s * normal_n / breakaway
        else:
            share = 0.0
        return x, 0.0, True, 0.0, f_drive * (1.0 - share), f_drive * share
    if v > 0.0:
        s = 1.0
    elif v < 0.0:
        s = -1.0
    elif f_drive >= 0.0:
        s = 1.0
    else:
        s = -1.0
    speed = abs(v)
    f_seal = s * stribeck_level(speed, seal_fc, seal_fs, seal_vs)
    f_bear = (
        s * normal_n * stribeck_level(speed, mu_k, mu_s, bearing_vs) + normal_n * visc_per_n * v
    )
    a = (f_drive - f_seal - f_bear) / mass
    v_new = v + a * dt
    if v_new * s <= 0.0 and abs(f_drive) <= breakaway:
        # the velocity reaches zero within the step and the drive cannot break away: stick
        return x, 0.0, True, 0.0, f_seal, f_bear
    return x + v_new * dt, v_new, False, a, f_seal, f_bear


@jit(nrt=True)
def end_stop_force(x, v, half_stroke, stiffness, damping):
    """Force (N) of the damped elastomer bumpers; pushes only, zero inside the stroke."""
    if x > half_stroke:
        return min(0.0, -stiffness * (x - half_stroke) - damping * v)
    if x < -half_stroke:
        return max(0.0, stiffness * (-half_stroke - x) - damping * v)
    return 0.0
