"""Flapper-nozzle servo valve: the flapper as a damped second-order beam with travel limits.

The flapper travel ``xf`` is normalised to the nozzle gap. Nozzle 1 sees the gap
``1 - xf`` and nozzle 2 the gap ``1 + xf``: moving the flapper towards nozzle 1 throttles
chamber 1's bleed to atmosphere, so its pressure rises.
"""

from fdi_daemon.core.compiled import jit


@jit(nrt=True)
def flapper_step(xf, vf, u_v, gain_per_v, w_rad_s, zeta, travel_max, dt):
    """One semi-implicit Euler step of ẍf = ω²(K·u - xf) - 2ζω·ẋf with a hard travel stop.

    Returns the new (xf, vf). At a stop the velocity into the stop is removed.
    """
    acc = w_rad_s * w_rad_s * (gain_per_v * u_v - xf) - 2.0 * zeta * w_rad_s * vf
    vf = vf + dt * acc
    xf = xf + dt * vf
    if xf > travel_max:
        xf = travel_max
        if vf > 0.0:
            vf = 0.0
    elif xf < -travel_max:
        xf = -travel_max
        if vf < 0.0:
            vf = 0.0
    return xf, vf


@jit(nrt=True)
def nozzle_areas(xf, nozzle_area_m2):
    """Curtain areas (m²) of the two exhaust nozzles for flapper travel ``xf``."""
    return nozzle_area_m2 * (1.0 - xf), nozzle_area_m2 * (1.0 + xf)
