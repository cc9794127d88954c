"""The force loop (`diagnose.force`), the noise floor and dead time (`diagnose.floor`), and
the inverse-dynamics force balance (`diagnose.inverse`) against independent references."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from fdi_daemon.diagnose.effects import Context
from fdi_daemon.diagnose.floor import delay_by_correlation, noise_floor, repeated_input
from fdi_daemon.diagnose.force import ForceLoop
from fdi_daemon.diagnose.inverse import (
    baseline,
    measured_motion,
    noise_sigma,
)
from fdi_daemon.diagnose.inverse import (
    noise_floor as inverse_noise_floor,
)
from fdi_daemon.diagnose.signals import StateChain, make_split

FS = 256.0
A = np.array([1.0, -1.6, 0.8])  # a stable resonance


def _loop(n_kind=0):
    chain = StateChain(n_kind, FS, 0.2).coefficients
    cols = [(0, 0.0), (2, 0.05), (3, 0.0), (5, 0.0)]  # sign v, Stribeck, x³, x
    nums = np.array([[0.01, -0.02, 0.01], [0.02, 0.01, -0.01], [5.0, 1.0, 0.0], [0.1, 0.05, 0.0]])
    return ForceLoop(A, cols, nums, chain)


@pytest.mark.parametrize("n_kind", [0, 1, 2])
def test_force_loop_step_chunks_and_whole_array_agree(n_kind):
    rng = np.random.default_rng(3)
    y_ff = 0.05 * rng.standard_normal(600)
    whole = _loop(n_kind)
    y_whole = whole.run(y_ff)
    single = _loop(n_kind)
    y_single = np.array([single.step(float(v)) for v in y_ff])
    chunked = _loop(n_kind)
    cuts = np.sort(rng.choice(np.arange(1, len(y_ff)), 9, replace=False))
    y_chunks = np.concatenate([chunked.run(c) for c in np.split(y_ff, cuts)])
    np.testing.assert_allclose(y_single, y_whole, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(y_chunks, y_whole, rtol=1e-12, atol=1e-15)
    for s1, s2 in zip(single.state, whole.state):
        np.testing.assert_allclose(s1, s2, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("n_kind", [0, 1, 2])
def test_force_loop_contract_holds_through_stick_slip(n_kind):
    # dry friction that opposes the motion (negative b_0): the mass sticks at times
    cols = [(0, 0.0), (2, 0.05), (1, 0.0)]  # sign v, Stribeck excess, v
    scale = 0.01 if n_kind == 2 else 1.0  # within a step a force moves a position little
    nums = scale * np.array([[-0.3, 0.2, 0.0], [-0.2, 0.1, 0.0], [0.0, -0.5, 0.0]])
    chain = StateChain(n_kind, FS, 0.2).coefficients
    y_ff = 2.0 * np.sin(2 * np.pi * 1.5 * np.arange(700) / FS)
    whole = ForceLoop(A, cols, nums, chain)
    y_whole, phi, _ = whole.trace(y_ff)
    single = ForceLoop(A, cols, nums, chain)
    y_single = np.array([single.step(float(v)) for v in y_ff])
    np.testing.assert_allclose(y_single, y_whole, rtol=1e-12, atol=1e-15)
    for s1, s2 in zip(single.state, whole.state):
        np.testing.assert_allclose(s1, s2, rtol=1e-12, atol=1e-15)
    held = np.abs(phi[:, 0]) < 1.0
    assert held.sum() > 5  # it did stick ...
    assert (~held).sum() > 100  # ... and slide


def _mass_with_coulomb(drive_amplitude):
    """a = F_drive/m − (F_c/m)·s on a free mass (acceleration output, F_c/m = 1 m/s²):
    1 s of a 2 Hz drive, then 1 s without."""
    loop = ForceLoop(np.array([1.0]), [(0, 0.0)], [[-1.0]], StateChain(0, FS, 0.2).coefficients)
    t = np.arange(512) / FS
    drive = np.where(t < 1.0, drive_amplitude * np.sin(2 * np.pi * 2.0 * t), 0.0)
    accel, phi, velocity = loop.trace(drive)
    return drive, accel, phi[:, 0], velocity


def test_coulomb_friction_holds_a_mass_that_the_drive_cannot_break_away():
    drive, accel, s, velocity = _mass_with_coulomb(0.8)  # below F_c/m
    np.testing.assert_allclose(accel, 0.0, atol=1e-12)  # friction equals the drive
    np.testing.assert_allclose(s, drive, atol=1e-12)  # s = F_drive/F_c, inside [−1, 1]
    np.testing.assert_array_equal(velocity, 0.0)


def test_coulomb_friction_breaks_away_slides_and_brings_the_mass_to_rest():
    drive, accel, s, velocity = _mass_with_coulomb(2.0)
    np.testing.assert_allclose(accel, drive - s, atol=1e-12)
    assert np.all(np.abs(s) <= 1.0)
    # at rest until the drive exceeds the friction (2 sin = 1)
    first = int(np.argmax(accel != 0.0))
    assert drive[first - 1] <= 1.0 < drive[first]
    # sliding: friction at its full level, against the motion at the start or the end of
    # the step; at a reversal that the friction cannot hold, at most one sample per
    # reversal where the per-sample fixed point ends on the other sign
    sliding = velocity != 0.0
    np.testing.assert_array_equal(np.abs(s[sliding]), 1.0)
    before = np.r_[0.0, velocity[:-1]]
    against = (s == np.sign(velocity)) | (s == np.sign(before))
    assert np.sum(~against[sliding]) <= np.sum(velocity * before < 0)
    assert np.sum(velocity * before < 0) >= 2  # it did reverse
    # without drive the friction stops the mass and holds it (no chatter about v = 0)
    stopped = int(np.argmax((np.arange(accel.size) > FS) & (accel == 0.0)))
    assert FS < stopped < 1.5 * FS
    np.testing.assert_array_equal(accel[stopped:], 0.0)
    np.testing.assert_array_equal(s[stopped + 1 :], 0.0)
    np.testing.assert_array_equal(velocity[stopped:], 0.0)


def test_a_linear_force_in_the_loop_is_the_closed_loop_filter():
    # position output (x = y), force θ·x through B/A with b0 = 0: y = A/(A − θB) y_ff
    theta, b = -0.3, np.array([0.0, 0.5, 0.2])
    loop = ForceLoop(A, [(5, 0.0)], [theta * b], StateChain(2, FS, 0.2).coefficients)
    y_ff = np.random.default_rng(4).standard_normal(800)
    expected = signal.lfilter(A, A - theta * b, y_ff)
    np.testing.assert_allclose(loop.run(y_ff), expected, rtol=1e-10, atol=1e-12)


def _periodic(n_periods=6, sigma=0.05, seed=5, realisations=1):
    """``realisations`` random inputs of 512 samples, each repeated ``n_periods`` times,
    through a first-order filter, with white noise σ on the output."""
    rng = np.random.default_rng(seed)
    period = 512
    u = np.concatenate(
        [np.tile(rng.standard_normal(period), n_periods) for _ in range(realisations)]
    )
    y_clean = signal.lfilter([0.2, 0.1], [1.0, -0.7], u)
    return u, y_clean, y_clean + sigma * rng.standard_normal(u.size)


@pytest.mark.parametrize("n_periods, realisations", [(6, 1), (2, 4), (3, 3)])
def test_periodic_floor_is_the_period_to_period_noise(n_periods, realisations):
    # one input repeated, or several realisations repeated each (as a multisine benchmark
    # records them): the samples whose input repeats give the noise
    u, y_clean, y = _periodic(n_periods, realisations=realisations)
    period, repeating = repeated_input(u, 50, settle=60)
    assert period == 512
    expected = [
        k
        for r in range(realisations)
        for k in range(r * n_periods * 512 + 60 - 1, (r * n_periods + n_periods - 1) * 512)
    ]
    np.testing.assert_array_equal(repeating, expected)
    test = slice(2 * len(u) // 3, None)
    floor = noise_floor(y, y - y_clean, u, FS, warmup=60, test=test)
    assert floor["method"] == "periodic"
    assert floor["floor"] == pytest.approx(0.05 / np.std(y[test]), rel=0.1)


def test_an_input_that_does_not_repeat_has_no_period():
    u = np.random.default_rng(11).standard_normal(6 * 512)
    assert repeated_input(u, 50) is None
    u, *_ = _periodic(1, realisations=6)  # six realisations of one period each
    assert repeated_input(u, 50) is None


def test_spectrum_floor_is_the_white_noise_above_the_input_band():
    rng = np.random.default_rng(6)
    n = 8192
    u = signal.lfilter(*signal.butter(4, 10.0, fs=FS), rng.standard_normal(n))
    y_clean = signal.lfilter([0.2, 0.1], [1.0, -0.7], u)
    y = y_clean + 0.01 * rng.standard_normal(n)
    test = slice(2 * n // 3, None)
    floor = noise_floor(y, y - y_clean, u, FS, warmup=0, test=test)
    assert floor["method"] == "spectrum"
    assert floor["floor"] == pytest.approx(0.01 / np.std(y[test]), rel=0.15)


def test_dead_time_by_correlation():
    rng = np.random.default_rng(7)
    n = 4096
    y0 = signal.lfilter(*signal.butter(4, 20.0, fs=FS), rng.standard_normal(n))
    # a 3.4-sample delay, applied exactly in the frequency domain
    f = np.fft.rfftfreq(n)
    y = np.fft.irfft(np.fft.rfft(y0) * np.exp(-2j * np.pi * f * 3.4), n)
    assert delay_by_correlation(y, y0, FS, 20) * FS == pytest.approx(3.4, abs=0.15)


@pytest.mark.parametrize("lag", [0, 3])
def test_force_balance_recovers_mass_damping_and_the_motions_lag(lag):
    # M v̇ = u − c v, exact for a held force: v[k+1] = d v[k] + (1 − d)/c u[k]; the
    # velocity recorded ``lag`` samples late (a drive's filter and computation)
    mass, damping, fs = 8.0, 40.0, 500.0
    d = np.exp(-damping / mass / fs)
    rng = np.random.default_rng(8)
    u = signal.lfilter(*signal.butter(2, 5.0, fs=fs), 50 * rng.standard_normal(20000)) + 30.0
    v = signal.lfilter([0.0, (1 - d) / damping], [1.0, -d], u)
    v = np.concatenate([np.full(lag, v[0]), v[: len(v) - lag]])
    base = baseline(u, v, "velocity", fs, make_split(len(u), 200))
    assert base["lag"] == lag
    assert base["coefficients"]["mass"] == pytest.approx(mass, rel=0.01)
    assert base["coefficients"]["damping"] == pytest.approx(damping, rel=0.01)


def test_the_floor_of_a_quantised_velocity_is_unknown():
    # an encoder's differences (1 µm at 1 kHz) of moves with rests: the velocity is exactly
    # 0 at rest, so its noise cannot be read from its second differences (not a floor of 0)
    t = np.arange(20000) / 1000.0
    x = np.round(0.1 * np.clip(np.sin(2 * np.pi * 0.5 * t), -0.5, 0.5) / 1e-6) * 1e-6
    v = np.diff(x, prepend=x[0]) * 1000.0
    lp = signal.butter(2, 20.0, fs=1000.0)
    floor = inverse_noise_floor(
        v, "velocity", v, v, {"mass": 1.0, "damping": 1.0}, lp, 1000.0, slice(10000, None)
    )
    assert floor["floor"] is None
    assert "unknown" in floor["method"]


def test_noise_sigma_ignores_a_smooth_motion():
    rng = np.random.default_rng(9)
    t = np.arange(20000) / 500.0
    v = 0.2 * np.sin(2 * np.pi * 1.3 * t) + 3e-4 * rng.standard_normal(t.size)
    assert noise_sigma(v) == pytest.approx(3e-4, rel=0.05)


def test_the_noise_of_a_motion_with_fast_content_is_read_above_the_input_band():
    # a position driven to 80 Hz at 610 Hz is not smooth from sample to sample: its second
    # differences are mostly motion (the Silverbox-like record at 80 Hz read σ = 0.04 V for
    # 0.1 mV, and its force balance was "at the floor"); above the input band only the
    # noise is left
    rng = np.random.default_rng(6)
    fs, sigma = 610.35, 1e-3
    u = signal.lfilter(*signal.butter(8, 80.0, fs=fs), rng.standard_normal(60000))
    y = signal.lfilter(*signal.butter(2, 60.0, fs=fs), u) + sigma * rng.standard_normal(u.size)
    floor = inverse_noise_floor(
        y,
        "position",
        u,
        u,
        {"mass": 1.0, "damping": 1.0, "stiffness": 1.0},
        signal.butter(2, 100.0, fs=fs),
        fs,
        slice(20000, None),
    )
    assert noise_sigma(y) > 10 * sigma
    assert floor["output_noise"] == pytest.approx(sigma, rel=0.1)


@pytest.mark.parametrize("kind", ["velocity", "position"])
def test_the_floor_is_the_output_noise_through_the_force_balance(kind):
    # reference: the force-balance terms of the noise alone (a Monte-Carlo run), against the
    # floor read from a noisy smooth motion; a position's noise is differenced twice for the
    # acceleration, so the same σ gives a floor about fs/ω_L times a velocity's
    rng = np.random.default_rng(4)
    fs, sigma = 1000.0, 2e-6
    t = np.arange(60000) / fs
    noise = sigma * rng.standard_normal(t.size)
    motion = 0.01 * np.sin(2 * np.pi * 0.7 * t) + 0.004 * np.sin(2 * np.pi * 2.3 * t)
    coefficients = {"mass": 95.0, "damping": 200.0} | (
        {"stiffness": 3000.0} if kind == "position" else {}
    )
    lp = signal.butter(2, 20.0, fs=fs)
    terms = measured_motion(noise, kind, fs)
    balance = [terms["a"], terms["v"]] + ([terms["x"]] if kind == "position" else [])
    noise_force = signal.lfilter(*lp, sum(c * b for c, b in zip(coefficients.values(), balance)))
    target = 50.0 + 30.0 * np.sin(2 * np.pi * 1.1 * t)
    test = slice(20000, None)
    expected = float(np.std(noise_force[test]) / np.std(target[test]))
    floor = inverse_noise_floor(motion + noise, kind, target, target, coefficients, lp, fs, test)
    assert floor["floor"] == pytest.approx(expected, rel=0.05)
    assert floor["output_noise"] == pytest.approx(sigma, rel=0.05)


@pytest.mark.parametrize(
    "change,expected",
    [
        ({"stiffness_n_per_m": 0.8 * 987.0}, "stiffness"),
        ({"damping_n_s_per_m": 6.3 + 3.0}, "damping"),
        ({"mass_kg": 1.25}, "mass"),
        ({"mass_kg": 0.8}, "mass"),
        ({"stiffness_n_per_m": 987.0 * 1.0001}, "none"),
    ],
)
def test_mode_shift_reads_the_mode_of_a_system_whose_change_we_chose(change, expected):
    # position output (x = y): the loop's denominator is Â − B_x, so B_x = Â₀ − Â₁ makes
    # it the exact ZOH denominator of the changed §V model, whose mode is known in closed
    # form (ZOH maps poles exactly, z = e^{sT}); the input filter's pair (20 Hz, ζ 0.7)
    # is in Â too and must not be taken for the mechanics'
    from types import SimpleNamespace

    from fdi_daemon.diagnose.force import mode_shift
    from hil_sim.msd import MsdParams, friction_tf

    nominal, changed = MsdParams(), MsdParams(**change)
    a0, a1 = friction_tf(nominal)[1], friction_tf(changed)[1]
    ctx = SimpleNamespace(
        chain=StateChain(2, FS, 0.2).coefficients, a_dom=a0, split=make_split(int(40 * FS), 0)
    )
    out = mode_shift(ctx, a0 - a1)

    def mode(p):
        w = np.sqrt(p.stiffness_n_per_m / p.mass_kg)
        return w / (2 * np.pi), p.damping_n_s_per_m / (2 * np.sqrt(p.stiffness_n_per_m * p.mass_kg))

    assert (out["resonance_hz_nominal"], out["damping_ratio_nominal"]) == pytest.approx(
        mode(nominal), rel=1e-6
    )
    assert (out["resonance_hz"], out["damping_ratio"]) == pytest.approx(mode(changed), rel=1e-6)
    assert out["stiffness_ratio"] == pytest.approx(  # ω₁²/ω₀²
        (changed.stiffness_n_per_m / changed.mass_kg)
        / (nominal.stiffness_n_per_m / nominal.mass_kg),
        rel=1e-6,
    )
    assert out["damping_change_per_s"] == pytest.approx(  # Δ(c/m)
        changed.damping_n_s_per_m / changed.mass_kg - nominal.damping_n_s_per_m / nominal.mass_kg,
        rel=1e-6,
        abs=1e-9,
    )
    assert out["mode_change"] == expected
    if expected == "mass":
        assert out["mass_ratio"] == pytest.approx(changed.mass_kg / nominal.mass_kg, rel=1e-6)


def test_a_long_records_parameter_search_sees_the_force_balance_of_its_own_samples():
    # a long record's parameters are searched on its first samples (`Context.head`); in the
    # inverse-dynamics form the force balance's columns must be cut with them (a 131 072-
    # sample oscillator record failed with "operands could not be broadcast")
    n, head = 1000, 300
    ctx = Context(
        u=np.zeros(n),
        v=np.zeros(n),
        x=np.zeros(n),
        y0=np.zeros(n),
        target=np.zeros(n),
        a_dom=np.ones(1),
        b_dom=np.ones(1),
        split=make_split(n, 10),
        fs_hz=100.0,
        output_kind="velocity",
        ref_hz=1.0,
        max_delay_samples=1,
        form="inverse_dynamics",
        base_columns=np.arange(2.0 * n).reshape(n, 2),
    )
    cut = ctx.head(head)
    assert cut.base_columns.shape == (head, 2)
    assert np.array_equal(cut.base_columns, ctx.base_columns[:head])
    assert cut.split.train_end == head


@pytest.mark.parametrize("mean_x,possible", [(0.3, False), (0.0, True)])
def test_a_force_that_is_mostly_a_constant_acceleration_is_not_a_force_of_the_motion(
    mean_x, possible
):
    # the mean acceleration of a bounded motion is zero: a force effect whose output is
    # mostly its mean is a sensor's offset (`force.STEADY_SHARE`). A cubic spring on a
    # position that sits at 0.3 with a small swing, against one that swings about 0
    from types import SimpleNamespace

    from fdi_daemon.diagnose.effects import FittedEffect
    from fdi_daemon.diagnose.force import force_report

    n = int(20 * FS)
    swing = 0.02 if mean_x else 1.0
    x = mean_x + swing * np.sin(2 * np.pi * 3.0 * np.arange(n) / FS)
    ctx = SimpleNamespace(
        chain=StateChain(0, FS, 0.2).coefficients, a_dom=A, split=make_split(n, 0)
    )
    b = np.array([0.1, 0.05, 0.0])
    eff = FittedEffect("cubic_stiffness", None, [b], n_linear=3)
    out = force_report(eff, ctx, np.zeros(n), (x**3)[:, None], np.zeros(n), b)
    # the output's mean square against its energy, the output filtered by scipy
    steady = signal.lfilter(b, A, x**3)
    expected = np.mean(steady[ctx.split.fit]) ** 2 / np.mean(steady[ctx.split.fit] ** 2)
    assert out["steady_share"] == pytest.approx(expected, rel=1e-9)
    assert (out["steady_share"] > 0.9) == (not possible)
    assert out["plausible"] is possible
