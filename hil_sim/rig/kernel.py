"""The fixed-step rig kernel: plain numeric code over float64 arrays, compiled by numba.

One call advances the rig over ``n`` DAQ samples. Per sample k the DAQ first reads the
sensors at t_k (so accel[k] depends on v_in up to k-1, as eq. (1) assumes with b0 = 0), then
the valve voltage v_in[k] is held for ``substeps`` fixed internal steps (zero-order hold).
Set ``NUMBA_DISABLE_JIT=1`` to run the same code as pure Python.
"""

from fdi_daemon.core.compiled import jit
from hil_sim.rig.chambers import chamber_volumes, orifice_flow, pressure_rate
from hil_sim.rig.friction import contact_force, end_stop_force, mechanics_step
from hil_sim.rig.params import (
    C_ACCEL_BIAS,
    C_ACCEL_DROPOUT,
    C_ACCEL_RANGE,
    C_BEARING_SUPPLY,
    C_CENTRING,
    C_SUPPLY,
    C_TEMPERATURE,
    C_VALVE_GAIN,
    P_ACC_BIAS,
    P_ACC_NOISE,
    P_ACC_RANGE,
    P_ACC_W,
    P_ADC_NOISE,
    P_ADC_RANGE,
    P_AREA,
    P_ATM,
    P_B,
    P_BEARING_ALPHA,
    P_BEARING_P,
    P_BEARING_VISC,
    P_BEARING_VS,
    P_C_LIN,
    P_DEAD_VOLUME,
    P_DT,
    P_ES_C,
    P_ES_K,
    P_FLAPPER_MAX,
    P_FLOW_CONST,
    P_FORCE_NOISE,
    P_HALF_STROKE,
    P_LEAK,
    P_LEVELS,
    P_LIFT_AREA,
    P_LVDT_NOISE,
    P_LVDT_RANGE,
    P_MASS,
    P_MU_K,
    P_MU_S,
    P_N,
    P_NOZZLE_AREA,
    P_PHI_LAM,
    P_PR_LAM,
    P_R,
    P_SEAL_FC,
    P_SEAL_FS,
    P_SEAL_VS,
    P_SUBSTEPS,
    P_SUPPLY,
    P_SUPPLY_AREA,
    P_VALVE_K,
    P_VALVE_W,
    P_VALVE_Z,
    P_WEIGHT,
)
from hil_sim.rig.sensors import accel_filter_step, accel_reading, adc
from hil_sim.rig.valve import flapper_step, nozzle_areas

# state vector
S_XF = 0  # flapper travel (fraction of gap)
S_VF = 1  # flapper velocity (1/s)
S_P1 = 2  # chamber 1 pressure, abs (Pa)
S_P2 = 3  # chamber 2 pressure, abs (Pa)
S_X = 4  # position (m), 0 = mid-stroke
S_V = 5  # velocity (m/s)
S_STUCK = 6  # 1 while the mass sticks
S_PB = 7  # bearing pocket pressure, gauge (Pa)
S_ACC = 8  # true acceleration of the last internal step (m/s²)
S_ACC_Y = 9  # accelerometer filter output (m/s²)
S_ACC_YD = 10  # its derivative
S_F_SEAL = 11  # seal friction of the last internal step (N)
S_F_BEAR = 12  # bearing friction of the last internal step (N)
S_NORMAL = 13  # bearing contact normal force (N)
N_STATE = 14

# output columns per sample
O_ACCEL = 0  # accelerometer reading (m/s²)
O_POSITION = 1  # LVDT reading (m)
O_V_IN = 2  # valve-voltage ADC reading (V)
O_DRIVE = 3  # valve voltage applied over the sample (V), excitation + centring
O_POSITION_TRUE = 4
O_VELOCITY = 5
O_ACCEL_TRUE = 6
O_FRICTION = 7  # air-bearing friction force (N)
O_SEAL_FRICTION = 8  # rod-seal friction force (N)
O_CONTACT = 9  # bearing contact normal force (N)
O_BEARING_P = 10  # bearing pocket pressure, gauge (Pa)
O_P1 = 11
O_P2 = 12
O_STUCK = 13
N_OUT = 14

# noise channels (standard normal draws per sample)
N_FORCE = 0
N_ACCEL = 1
N_LVDT = 2
N_ADC = 3
N_NOISE = 4


@jit(nrt=True)
def substep(s, p, c, u_v, f_noise):
    """Advance the state vector ``s`` by one internal step with valve voltage ``u_v``."""
    dt = p[P_DT]
    xf, vf = flapper_step(
        s[S_XF],
        s[S_VF],
        u_v,
        p[P_VALVE_K] * c[C_VALVE_GAIN],
        p[P_VALVE_W],
        p[P_VALVE_Z],
        p[P_FLAPPER_MAX],
        dt,
    )
    s[S_XF] = xf
    s[S_VF] = vf

    # air bearing: first-order pocket pressure, contact below the lift-off pressure
    s[S_PB] += p[P_BEARING_ALPHA] * (c[C_BEARING_SUPPLY] * p[P_BEARING_P] - s[S_PB])
    normal = contact_force(s[S_PB], p[P_WEIGHT], p[P_LIFT_AREA])
    s[S_NORMAL] = normal

    # chambers
    temp = c[C_TEMPERATURE]
    gas_rt = p[P_R] * temp
    p_sup = p[P_SUPPLY] * c[C_SUPPLY]
    p_atm = p[P_ATM]
    p1 = s[S_P1]
    p2 = s[S_P2]
    x = s[S_X]
    v = s[S_V]
    area = p[P_AREA]
    k = p[P_FLOW_CONST]
    b = p[P_B]
    lam = p[P_PR_LAM]
    phi_lam = p[P_PHI_LAM]
    ae1, ae2 = nozzle_areas(xf, p[P_NOZZLE_AREA])
    a_sup = p[P_SUPPLY_AREA]
    leak = p[P_LEAK] * (p1 - p2)
    m1 = (
        orifice_flow(p_sup, p1, a_sup, k, temp, b, lam, phi_lam)
        - orifice_flow(p1, p_atm, ae1, k, temp, b, lam, phi_lam)
        - leak
    )
    m2 = (
        orifice_flow(p_sup, p2, a_sup, k, temp, b, lam, phi_lam)
        - orifice_flow(p2, p_atm, ae2, k, temp, b, lam, phi_lam)
        + leak
    )
    vol1, vol2 = chamber_volumes(x, area, p[P_HALF_STROKE], p[P_DEAD_VOLUME])
    s[S_P1] = p1 + dt * pressure_rate(p1, vol1, area * v, m1, gas_rt, p[P_N])
    s[S_P2] = p2 + dt * pressure_rate(p2, vol2, -area * v, m2, gas_rt, p[P_N])

    # mechanics with stick-slip
    f_drive = (
        area * (p1 - p2)
        - p[P_C_LIN] * v
        + f_noise
        + end_stop_force(x, v, p[P_HALF_STROKE], p[P_ES_K], p[P_ES_C])
    )
    x, v, stuck, acc, f_seal, f_bear = mechanics_step(
        x,
        v,
        s[S_STUCK] > 0.5,
        f_drive,
        p[P_MASS],
        dt,
        p[P_SEAL_FC],
        p[P_SEAL_FS],
        p[P_SEAL_VS],
        normal,
        p[P_MU_K],
        p[P_MU_S],
        p[P_BEARING_VS],
        p[P_BEARING_VISC],
    )
    s[S_X] = x
    s[S_V] = v
    s[S_STUCK] = 1.0 if stuck else 0.0
    s[S_ACC] = acc
    s[S_F_SEAL] = f_seal
    s[S_F_BEAR] = f_bear

    y, yd = accel_filter_step(s[S_ACC_Y], s[S_ACC_YD], acc, p[P_ACC_W], dt)
    s[S_ACC_Y] = y
    s[S_ACC_YD] = yd


@jit(nrt=True)
def run_samples(s, p, c, u_exc, noise, out):
    """Advance over len(u_exc) samples; write one row of ``out`` (``O_*``) per sample.

    s: state (``S_*``, updated in place); p: packed params; c: controls; u_exc: excitation
    voltage per sample (V); noise: standard normals (n × N_NOISE); out: (n × N_OUT).
    The valve sees u_exc[k] - centring_gain·LVDT[k].
    """
    levels = p[P_LEVELS]
    nsub = int(p[P_SUBSTEPS])
    for k in range(u_exc.shape[0]):
        lvdt = adc(s[S_X] + p[P_LVDT_NOISE] * noise[k, N_LVDT], p[P_LVDT_RANGE], levels)
        u_v = u_exc[k] - c[C_CENTRING] * lvdt
        out[k, O_ACCEL] = accel_reading(
            s[S_ACC_Y],
            p[P_ACC_BIAS] + c[C_ACCEL_BIAS],
            p[P_ACC_NOISE] * noise[k, N_ACCEL],
            p[P_ACC_RANGE],
            c[C_ACCEL_RANGE],
            c[C_ACCEL_DROPOUT],
            levels,
        )
        out[k, O_POSITION] = lvdt
        out[k, O_V_IN] = adc(u_v + p[P_ADC_NOISE] * noise[k, N_ADC], p[P_ADC_RANGE], levels)
        out[k, O_DRIVE] = u_v
        out[k, O_POSITION_TRUE] = s[S_X]
        out[k, O_VELOCITY] = s[S_V]
        out[k, O_ACCEL_TRUE] = s[S_ACC]
        out[k, O_FRICTION] = s[S_F_BEAR]
        out[k, O_SEAL_FRICTION] = s[S_F_SEAL]
        out[k, O_CONTACT] = s[S_NORMAL]
        out[k, O_BEARING_P] = s[S_PB]
        out[k, O_P1] = s[S_P1]
        out[k, O_P2] = s[S_P2]
        out[k, O_STUCK] = s[S_STUCK]
        f_noise = p[P_FORCE_NOISE] * noise[k, N_FORCE]
        for _ in range(nsub):
            substep(s, p, c, u_v, f_noise)
