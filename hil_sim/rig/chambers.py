"""Cylinder chambers: orifice mass flow (ISO 6358) and polytropic pressure dynamics.

Mass flow through an orifice of area A from p_up to p_down (ISO 6358 sonic-conductance form):
    ṁ = Cd·A·p_up·sqrt(κ/(R·T))·(2/(κ+1))^((κ+1)/(2(κ-1))) · φ(p_down/p_up),
    φ = 1 (choked, ratio <= b),  φ = sqrt(1 - ((ratio - b)/(1 - b))²) (subsonic).
The ellipse has an infinite slope at ratio -> 1; above ``laminar_ratio`` it is replaced by a
straight line to zero (laminar end), which keeps the fixed-step integration well posed.
Chamber pressure, polytropic with index n:  dp/dt = n/V · (R·T·ṁ - p·dV/dt).
"""

import math

from fdi_daemon.core.compiled import jit


@jit(nrt=True)
def orifice_flow(p_up, p_down, area_m2, flow_const, temperature_k, b, laminar_ratio, phi_laminar):
    """Mass flow (kg/s) from p_up to p_down, negative when the flow runs the other way."""
    sign = 1.0
    if p_down > p_up:
        p_up, p_down = p_down, p_up
        sign = -1.0
    if p_up <= 0.0 or area_m2 <= 0.0:
        return 0.0
    ratio = p_down / p_up
    if ratio <= b:
        phi = 1.0
    elif ratio < laminar_ratio:
        z = (ratio - b) / (1.0 - b)
        phi = math.sqrt(1.0 - z * z)
    else:
        phi = phi_laminar * (1.0 - ratio) / (1.0 - laminar_ratio)
    return sign * flow_const * area_m2 * p_up * phi / math.sqrt(temperature_k)


@jit(nrt=True)
def chamber_volumes(x_m, area_m2, half_stroke_m, dead_volume_m3):
    """Volumes (m³) of chamber 1 (grows with x) and chamber 2, never below half the dead volume."""
    v1 = dead_volume_m3 + area_m2 * (half_stroke_m + x_m)
    v2 = dead_volume_m3 + area_m2 * (half_stroke_m - x_m)
    floor = 0.5 * dead_volume_m3
    return max(v1, floor), max(v2, floor)


@jit(nrt=True)
def pressure_rate(p_pa, volume_m3, dvolume_dt, mass_flow_in, gas_rt, polytropic_n):
    """dp/dt (Pa/s) of a chamber: n/V·(R·T·ṁ - p·dV/dt)."""
    return polytropic_n / volume_m3 * (gas_rt * mass_flow_in - p_pa * dvolume_dt)
