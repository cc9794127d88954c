"""Sensors as the DAQ sees them: range limits and 16-bit quantisation over the range."""

import math

from fdi_daemon.core.compiled import jit


@jit(nrt=True)
def adc(value, full_scale, levels):
    """Clip to ±full_scale and quantise to ``levels`` codes over the range (mid-tread)."""
    lsb = 2.0 * full_scale / levels
    code = math.floor(value / lsb + 0.5)
    top = levels / 2.0 - 1.0
    if code > top:
        code = top
    elif code < -levels / 2.0:
        code = -levels / 2.0
    return code * lsb


@jit(nrt=True)
def accel_filter_step(y, yd, a_true, w_rad_s, dt):
    """One semi-implicit step of the accelerometer's 2nd-order Butterworth response."""
    ydd = w_rad_s * w_rad_s * (a_true - y) - 1.4142135623730951 * w_rad_s * yd
    yd = yd + dt * ydd
    y = y + dt * yd
    return y, yd


@jit(nrt=True)
def accel_reading(y, bias, noise, full_scale, range_fraction, dropout, levels):
    """Accelerometer sample: filtered acceleration + bias + noise, saturating at the
    (possibly reduced) sensor range, then the 16-bit ADC over the nominal range.
    A dropout (broken cable) reads 0."""
    if dropout > 0.5:
        return 0.0
    limit = full_scale * range_fraction
    value = y + bias + noise
    if value > limit:
        value = limit
    elif value < -limit:
        value = -limit
    return adc(value, full_scale, levels)
