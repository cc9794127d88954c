"""Physical parameters of the simulated servo-pneumatic rig, and their packing for the kernel.

`RigParams` holds every physical constant with its unit. `pack_params` turns it into the flat
float64 vector the compiled kernel reads through the ``P_*`` indices below; `new_controls`
builds the small vector of quantities that change while the rig runs (fault switches,
bearing supply, drift of supply pressure and temperature), read through ``C_*``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

GAS_CONSTANT_J_PER_KG_K = 287.05
GRAVITY_M_PER_S2 = 9.81


@dataclass(frozen=True)
class RigParams:
    """Servo-pneumatic cylinder (through-rod, 25 mm bore, 100 mm stroke) on an air-bearing load.

    Valve: a flapper-nozzle stage; the flapper is a damped second-order beam driven by the
    valve voltage (travel normalised to the nozzle gap, saturating at ``flapper_travel_max``).
    Each chamber is fed from supply through a fixed orifice and bleeds to atmosphere through
    its nozzle, whose curtain area shrinks as the flapper approaches it.
    """

    # --- sampling and integration
    fs_hz: float = 256.0
    """DAQ sample rate (Hz)."""
    substeps: int = 16
    """Fixed internal integration steps per sample (16 -> 4096 Hz, dt = 244 µs)."""

    # --- cylinder geometry
    bore_m: float = 0.025
    """Piston diameter (m)."""
    rod_diameter_m: float = 0.010
    """Rod diameter (m); through-rod cylinder, so both chambers see the same annulus."""
    stroke_m: float = 0.100
    """Full stroke (m); x = 0 is mid-stroke, end stops at ±stroke/2."""
    dead_volume_m3: float = 5.0e-6
    """Dead volume per chamber (ports, tubing to the valve) (m³)."""

    # --- air
    supply_pressure_pa: float = 6.0e5
    """Nominal absolute supply pressure (Pa)."""
    atmosphere_pa: float = 101325.0
    """Exhaust (ambient) absolute pressure (Pa)."""
    temperature_k: float = 293.15
    """Nominal supply/chamber air temperature (K)."""
    polytropic_index: float = 1.2
    """Polytropic exponent n of the chamber process (1 isothermal .. 1.4 adiabatic)."""
    heat_ratio: float = 1.4
    """Ratio of specific heats κ of air (sets the sonic flow constant)."""
    discharge_coefficient: float = 0.8
    """Orifice discharge coefficient Cd (-)."""
    critical_pressure_ratio: float = 0.45
    """ISO 6358 critical pressure ratio b (-): flow is choked for p_down/p_up <= b."""
    laminar_pressure_ratio: float = 0.995
    """Above this pressure ratio the ISO 6358 ellipse is replaced by a linear (laminar) end."""
    piston_leak_kg_per_s_pa: float = 1.0e-10
    """Laminar leakage across the piston seal, mass flow per pressure difference (kg/(s·Pa))."""

    # --- valve
    valve_bandwidth_hz: float = 10.0
    """Natural frequency of the flapper (damped beam) (Hz)."""
    valve_damping: float = 0.7
    """Damping ratio of the flapper (-)."""
    valve_gain_per_v: float = 0.30
    """Static flapper travel per valve volt, as a fraction of the nozzle gap (1/V)."""
    flapper_travel_max: float = 0.9
    """Flapper travel limit (fraction of the nozzle gap): the valve saturates here."""
    nozzle_area_m2: float = 3.5e-7
    """Nozzle curtain area at centred flapper (m²) (1 mm nozzle, 0.11 mm gap)."""
    supply_orifice_area_m2: float = 2.0e-7
    """Fixed supply orifice area per chamber (m²) (0.5 mm diameter)."""

    # --- moving mass and linear damping
    piston_rod_mass_kg: float = 0.35
    """Piston and rod mass (kg)."""
    bearing_mass_kg: float = 1.0
    """Air-bearing block (with accelerometer and LVDT core) mass (kg)."""
    viscous_damping_n_s_per_m: float = 45.0
    """Linear damping of seals and air film (N·s/m); part of the friction-free plant."""
    end_stop_stiffness_n_per_m: float = 2.0e5
    """Stiffness of the elastomer end-stop bumpers (N/m)."""
    end_stop_damping_n_s_per_m: float = 300.0
    """Damping of the end-stop bumpers (N·s/m)."""
    force_noise_n: float = 0.03
    """Process noise: standard deviation of a random force held over each sample (N)."""

    # --- rod-seal friction (present before any fault)
    seal_coulomb_n: float = 0.06
    """Rod/piston seal Coulomb friction (N)."""
    seal_static_n: float = 0.12
    """Rod/piston seal static (breakaway) friction (N)."""
    seal_stribeck_velocity_m_per_s: float = 0.002
    """Stribeck velocity of the seal friction (m/s)."""

    # --- air bearing
    bearing_supply_pa: float = 69.0e3
    """Nominal bearing supply pressure, gauge (Pa) (10 psi, as in the paper)."""
    bearing_contact_pressure_pa: float = 55.0e3
    """Gauge bearing pressure at which lift equals the block weight (Pa) (8 psi)."""
    bearing_time_constant_s: float = 0.015
    """First-order time constant of the bearing pocket pressure (s)."""
    bearing_mu_kinetic: float = 0.30
    """Kinetic (Coulomb) friction coefficient of aluminium on aluminium in contact (-)."""
    bearing_mu_static: float = 0.33
    """Static friction coefficient in contact (-); close to kinetic: low stick."""
    bearing_stribeck_velocity_m_per_s: float = 0.002
    """Stribeck velocity of the contact friction (m/s)."""
    bearing_viscous_per_n: float = 1.0
    """Viscous friction per newton of contact force ((N·s/m)/N)."""

    # --- sensors
    accel_range_m_per_s2: float = 50.0
    """Accelerometer full scale ±range (m/s²); 16-bit ADC over ±range."""
    accel_bandwidth_hz: float = 150.0
    """Accelerometer (with signal conditioning) second-order bandwidth (Hz)."""
    accel_noise_m_per_s2: float = 0.02
    """Accelerometer white noise, standard deviation per sample (m/s²)."""
    accel_bias_m_per_s2: float = 0.01
    """Accelerometer bias before any fault (m/s²)."""
    lvdt_range_m: float = 0.05
    """LVDT full scale ±range (m); 16-bit ADC over ±range."""
    lvdt_noise_m: float = 2.0e-6
    """LVDT noise, standard deviation (m)."""
    adc_range_v: float = 10.0
    """Valve-voltage ADC full scale ±range (V); 16 bit."""
    adc_noise_v: float = 1.0e-3
    """Valve-voltage ADC noise, standard deviation (V)."""
    adc_bits: int = 16
    """Resolution of every ADC channel (bits)."""

    @property
    def piston_area_m2(self) -> float:
        """Annular piston area seen by each chamber (m²)."""
        return math.pi / 4.0 * (self.bore_m**2 - self.rod_diameter_m**2)

    @property
    def moving_mass_kg(self) -> float:
        return self.piston_rod_mass_kg + self.bearing_mass_kg

    @property
    def bearing_lift_area_m2(self) -> float:
        """Effective area turning bearing pressure into lift (m²): weight / contact pressure."""
        return self.bearing_mass_kg * GRAVITY_M_PER_S2 / self.bearing_contact_pressure_pa


def validate_params(params: RigParams) -> None:
    """Raise ValueError naming the first field that is not a finite, positive number."""
    for f in fields(params):
        value = getattr(params, f.name)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"rig parameter {f.name} must be a number, got {value!r}")
        if not math.isfinite(value) or value <= 0:
            if f.name == "accel_bias_m_per_s2" and math.isfinite(value):
                continue
            raise ValueError(f"rig parameter {f.name} must be a positive number, got {value!r}")
    if params.substeps != int(params.substeps):
        raise ValueError("rig parameter substeps must be a whole number")
    if params.rod_diameter_m >= params.bore_m:
        raise ValueError("rig parameter rod_diameter_m must be smaller than bore_m")
    if not params.critical_pressure_ratio < params.laminar_pressure_ratio < 1.0:
        raise ValueError(
            "rig parameter laminar_pressure_ratio must lie between critical_pressure_ratio and 1"
        )
    if params.flapper_travel_max >= 1.0:
        raise ValueError("rig parameter flapper_travel_max must be below 1 (nozzle closed)")
    if params.bearing_mu_static < params.bearing_mu_kinetic:
        raise ValueError("rig parameter bearing_mu_static must be >= bearing_mu_kinetic")
    if params.seal_static_n < params.seal_coulomb_n:
        raise ValueError("rig parameter seal_static_n must be >= seal_coulomb_n")


# ---------------------------------------------------------------- packed parameter vector
P_DT = 0  # internal step (s)
P_SUBSTEPS = 1
P_AREA = 2  # piston area (m²)
P_HALF_STROKE = 3
P_DEAD_VOLUME = 4
P_SUPPLY = 5  # nominal supply, abs (Pa)
P_ATM = 6
P_R = 7  # gas constant
P_N = 8  # polytropic index
P_FLOW_CONST = 9  # Cd * sqrt(κ/R) * (2/(κ+1))^((κ+1)/(2(κ-1)))
P_B = 10  # critical pressure ratio
P_PR_LAM = 11
P_PHI_LAM = 12  # ISO 6358 flow function at the laminar ratio
P_LEAK = 13
P_VALVE_W = 14  # rad/s
P_VALVE_Z = 15
P_VALVE_K = 16
P_FLAPPER_MAX = 17
P_NOZZLE_AREA = 18
P_SUPPLY_AREA = 19
P_MASS = 20
P_C_LIN = 21
P_ES_K = 22
P_ES_C = 23
P_FORCE_NOISE = 24
P_SEAL_FC = 25
P_SEAL_FS = 26
P_SEAL_VS = 27
P_BEARING_P = 28  # nominal bearing supply, gauge (Pa)
P_BEARING_ALPHA = 29  # 1 - exp(-dt/tau)
P_WEIGHT = 30  # bearing block weight (N)
P_LIFT_AREA = 31
P_MU_K = 32
P_MU_S = 33
P_BEARING_VS = 34
P_BEARING_VISC = 35
P_ACC_RANGE = 36
P_ACC_W = 37
P_ACC_NOISE = 38
P_ACC_BIAS = 39
P_LVDT_RANGE = 40
P_LVDT_NOISE = 41
P_ADC_RANGE = 42
P_ADC_NOISE = 43
P_LEVELS = 44  # 2**bits
N_PARAMS = 45

# ---------------------------------------------------------------- run-time controls
C_BEARING_SUPPLY = 0  # fraction of nominal bearing supply (1 = floating)
C_SUPPLY = 1  # supply pressure fraction (fault x drift)
C_TEMPERATURE = 2  # air temperature (K)
C_VALVE_GAIN = 3  # valve gain fraction (fault)
C_ACCEL_BIAS = 4  # extra accelerometer bias (fault) (m/s²)
C_ACCEL_DROPOUT = 5  # 1: accelerometer reads 0
C_ACCEL_RANGE = 6  # accelerometer range fraction (fault)
C_CENTRING = 7  # position-centring gain (V/m), 0 = off
N_CONTROLS = 8


def flow_function(pressure_ratio: float, b: float) -> float:
    """ISO 6358 subsonic flow function φ(p_down/p_up) for the sonic conductance form."""
    if pressure_ratio <= b:
        return 1.0
    return math.sqrt(1.0 - ((pressure_ratio - b) / (1.0 - b)) ** 2)


def pack_params(params: RigParams) -> np.ndarray:
    """The flat float64 vector the kernel reads (indices ``P_*``)."""
    validate_params(params)
    p = np.zeros(N_PARAMS)
    dt = 1.0 / (params.fs_hz * params.substeps)
    kappa = params.heat_ratio
    sonic = math.sqrt(kappa / GAS_CONSTANT_J_PER_KG_K) * (2.0 / (kappa + 1.0)) ** (
        (kappa + 1.0) / (2.0 * (kappa - 1.0))
    )
    p[P_DT] = dt
    p[P_SUBSTEPS] = params.substeps
    p[P_AREA] = params.piston_area_m2
    p[P_HALF_STROKE] = params.stroke_m / 2.0
    p[P_DEAD_VOLUME] = params.dead_volume_m3
    p[P_SUPPLY] = params.supply_pressure_pa
    p[P_ATM] = params.atmosphere_pa
    p[P_R] = GAS_CONSTANT_J_PER_KG_K
    p[P_N] = params.polytropic_index
    p[P_FLOW_CONST] = params.discharge_coefficient * sonic
    p[P_B] = params.critical_pressure_ratio
    p[P_PR_LAM] = params.laminar_pressure_ratio
    p[P_PHI_LAM] = flow_function(params.laminar_pressure_ratio, params.critical_pressure_ratio)
    p[P_LEAK] = params.piston_leak_kg_per_s_pa
    p[P_VALVE_W] = 2.0 * math.pi * params.valve_bandwidth_hz
    p[P_VALVE_Z] = params.valve_damping
    p[P_VALVE_K] = params.valve_gain_per_v
    p[P_FLAPPER_MAX] = params.flapper_travel_max
    p[P_NOZZLE_AREA] = params.nozzle_area_m2
    p[P_SUPPLY_AREA] = params.supply_orifice_area_m2
    p[P_MASS] = params.moving_mass_kg
    p[P_C_LIN] = params.viscous_damping_n_s_per_m
    p[P_ES_K] = params.end_stop_stiffness_n_per_m
    p[P_ES_C] = params.end_stop_damping_n_s_per_m
    p[P_FORCE_NOISE] = params.force_noise_n
    p[P_SEAL_FC] = params.seal_coulomb_n
    p[P_SEAL_FS] = params.seal_static_n
    p[P_SEAL_VS] = params.seal_stribeck_velocity_m_per_s
    p[P_BEARING_P] = params.bearing_supply_pa
    p[P_BEARING_ALPHA] = 1.0 - math.exp(-dt / params.bearing_time_constant_s)
    p[P_WEIGHT] = params.bearing_mass_kg * GRAVITY_M_PER_S2
    p[P_LIFT_AREA] = params.bearing_lift_area_m2
    p[P_MU_K] = params.bearing_mu_kinetic
    p[P_MU_S] = params.bearing_mu_static
    p[P_BEARING_VS] = params.bearing_stribeck_velocity_m_per_s
    p[P_BEARING_VISC] = params.bearing_viscous_per_n
    p[P_ACC_RANGE] = params.accel_range_m_per_s2
    p[P_ACC_W] = 2.0 * math.pi * params.accel_bandwidth_hz
    p[P_ACC_NOISE] = params.accel_noise_m_per_s2
    p[P_ACC_BIAS] = params.accel_bias_m_per_s2
    p[P_LVDT_RANGE] = params.lvdt_range_m
    p[P_LVDT_NOISE] = params.lvdt_noise_m
    p[P_ADC_RANGE] = params.adc_range_v
    p[P_ADC_NOISE] = params.adc_noise_v
    p[P_LEVELS] = float(2 ** int(params.adc_bits))
    return p


def new_controls(params: RigParams) -> np.ndarray:
    """Run-time controls at their neutral (fault-free, nominal) values (indices ``C_*``)."""
    c = np.zeros(N_CONTROLS)
    c[C_BEARING_SUPPLY] = 1.0
    c[C_SUPPLY] = 1.0
    c[C_TEMPERATURE] = params.temperature_k
    c[C_VALVE_GAIN] = 1.0
    c[C_ACCEL_BIAS] = 0.0
    c[C_ACCEL_DROPOUT] = 0.0
    c[C_ACCEL_RANGE] = 1.0
    c[C_CENTRING] = 0.0
    return c
