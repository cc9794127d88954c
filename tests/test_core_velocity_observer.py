"""ModelVelocityObserver: v̂ = L·x̂̈ + V·(ẍ − x̂̈); streaming contract, settings, a known system."""

import math

import numpy as np
import pytest
from scipy.signal import butter, lfilter

from fdi_daemon.core.velocity import VelocityEstimator
from fdi_daemon.core.velocity_observer import (
    ModelVelocityObserver,
    trusted_from_hz,
    velocity_from_settings,
    velocity_setting_names,
)

FS = 256.0


def _signals(n=5000, seed=0):
    rng = np.random.default_rng(seed)
    xhat = np.cumsum(rng.normal(size=n)) * 0.01 + rng.normal(size=n)
    accel = xhat + 0.2 * rng.normal(size=n) + 0.05  # model error and an offset
    return accel, xhat


def test_matches_independent_reference():
    """scipy: first-order Butterworth high-pass + trapezoid on x̂̈, and 2nd-order on r."""
    accel, xhat = _signals()

    def integral(x, hp_hz, order):
        b, a = butter(order, hp_hz, btype="high", fs=FS)
        hp = lfilter(b, a, x)
        return np.cumsum((hp + np.concatenate([[0.0], hp[:-1]])) / (2 * FS))

    ref = integral(xhat, 0.02, 1) + integral(accel - xhat, 0.5, 2)
    v = ModelVelocityObserver(FS).run(accel, xhat)
    np.testing.assert_allclose(v, ref, rtol=1e-8, atol=1e-8 * np.max(np.abs(ref)))


def test_streaming_contract():
    """step, random chunks and the whole array: same output and the same final state."""
    accel, xhat = _signals()
    whole = ModelVelocityObserver(FS)
    ref = whole.run(accel, xhat)
    one = ModelVelocityObserver(FS)
    stepped = np.array([one.step(a, x) for a, x in zip(accel, xhat)])
    np.testing.assert_allclose(stepped, ref, rtol=1e-12, atol=1e-15)
    chunked = ModelVelocityObserver(FS)
    rng = np.random.default_rng(1)
    cuts = np.sort(rng.choice(np.arange(1, accel.size), size=30, replace=False))
    parts = [chunked.run(a, x) for a, x in zip(np.split(accel, cuts), np.split(xhat, cuts))]
    np.testing.assert_allclose(np.concatenate(parts), ref, rtol=1e-12, atol=1e-15)
    for obs in (one, chunked):
        for s, r in zip(obs.state, whole.state):
            np.testing.assert_allclose(s, r, rtol=1e-12, atol=1e-15)
    one.reset()
    assert all(not np.any(s) for s in one.state)


def test_true_velocity_of_a_known_system():
    """The paper's §V mass-spring-damper (exact Ĝ), 1–8 Hz multisine: the simulator's true
    velocity. The observer is right in sign and size; the high-pass estimate is not."""
    from hil_sim.msd import MsdParams, MsdSimulator, multisine, nominal_tf

    params = MsdParams(accel_noise_width=0.02)
    out = MsdSimulator(params, seed=0).run(multisine(30.0, FS, 1.0, 8.0, 0.7, seed=3))
    plant_b, plant_a = nominal_tf(params)
    xhat = lfilter(plant_b, plant_a, out["v_in"])
    truth = out["velocity_true"]
    settled = slice(int(5 * FS), None)
    moving = np.abs(truth[settled]) > 0.05 * np.max(np.abs(truth))

    def sign_right(v):
        return float(np.mean((np.sign(v[settled]) == np.sign(truth[settled]))[moving]))

    def rel_error(v):
        return float(np.sqrt(np.mean((v - truth)[settled] ** 2) / np.mean(truth[settled] ** 2)))

    observed = ModelVelocityObserver(FS).run(out["accel"], xhat)
    highpass = VelocityEstimator(FS).run(out["accel"])
    assert sign_right(observed) > 0.995
    assert rel_error(observed) < 0.03
    assert sign_right(highpass) < 0.97  # the 1 Hz high-pass leads 39–90° at 1–2 Hz
    assert rel_error(highpass) > 0.2


def test_response_with_an_exact_and_a_missing_model():
    """Exact model: the leaky integral (lead atan(f_leak/f)); no model: the residual path."""
    obs = ModelVelocityObserver(FS, leak_hz=0.02, highpass_hz=0.5)
    for f in (0.5, 2.0, 8.0):
        h = obs.response(f)
        half_wt = math.pi * f / FS  # the trapezoid rule's frequency warping
        expected = half_wt / math.tan(half_wt) / math.hypot(1.0, 0.02 / f)
        assert abs(h) == pytest.approx(expected, rel=1e-3)
        assert math.degrees(np.angle(h)) == pytest.approx(
            math.degrees(math.atan(0.02 / f)), abs=0.05
        )
    residual_only = VelocityEstimator(FS, highpass_hz=0.5, highpass_order=2)
    assert math.degrees(np.angle(obs.response(2.0, model_error=1.0))) == pytest.approx(
        residual_only.phase_lead_deg(2.0), abs=1e-6
    )


def test_settings_round_trip_and_method_selection():
    obs = velocity_from_settings({"method": "model_observer", "leak_hz": 0.05}, FS)
    assert isinstance(obs, ModelVelocityObserver) and obs.needs_model
    again = velocity_from_settings(obs.settings(), FS)
    assert again.settings() == obs.settings()
    # no method: today's estimator, with today's settings exactly
    old = {
        "fs_hz": FS,
        "highpass_hz": 1.0,
        "highpass_order": 3,
        "integrator": "trapezoid",
        "lead_compensation_hz": None,
    }
    est = velocity_from_settings(old, FS)
    assert isinstance(est, VelocityEstimator) and not est.needs_model
    assert est.settings() == old
    np.testing.assert_array_equal(est.b, VelocityEstimator(FS).b)
    assert isinstance(velocity_from_settings({"method": "highpass"}, FS), VelocityEstimator)
    assert set(velocity_setting_names()) >= {"method", "leak_hz", "highpass_hz", "fs_hz"}


@pytest.mark.parametrize(
    "settings, message",
    [
        ({"method": "kalman"}, "method must be one of"),
        ({"method": "model_observer", "leak_hz": 0.6}, "leak_hz must lie in"),
        ({"method": "model_observer", "leak_hz": -1}, "leak_hz must lie in"),
        ({"leak_hz": 0.02}, "leak_hz does not belong to method highpass"),
        ({"crossover_hz": 5.0}, "crossover_hz does not belong to method highpass"),
        ({"method": "position_observer", "crossover_hz": 100.0}, "crossover_hz must lie in"),
        ({"method": "position_observer", "leak_hz": 0.1}, "unknown velocity setting"),
        ({"method": "model_observer", "fs_hz": 100.0}, "disagrees"),
    ],
)
def test_bad_settings_are_refused(settings, message):
    with pytest.raises(ValueError, match=message):
        velocity_from_settings(settings, FS)


def _butterworth_highpass_lead_deg(f_hz, fc_hz, order=3):
    """Phase of the bilinear Butterworth high-pass at f (the trapezoid integrator is exactly
    -90°, so this is the estimator's lead): the analog prototype at the warped frequency."""
    w = math.tan(math.pi * f_hz / FS) / math.tan(math.pi * fc_hz / FS)
    poles = [np.exp(1j * math.pi * (2 * k + order + 1) / (2 * order)) for k in range(order)]
    h = np.prod([1.0 / (1.0 / (1j * w) - p) for p in poles]) * np.prod([-p for p in poles])
    return math.degrees(np.angle(h))


def test_trusted_from_hz_is_where_the_phase_error_falls_below_its_bound():
    """High-pass (1 Hz, order 3): the analog prototype's lead is 30° there and above 30° 3 %
    below; the observer: atan(f_leak/f) = 30° at f = f_leak/tan 30°; position: nowhere."""
    hp = velocity_from_settings({}, FS)
    f30 = trusted_from_hz(hp, 30.0)
    assert 3.5 < f30 < 4.3
    assert _butterworth_highpass_lead_deg(f30, 1.0) == pytest.approx(30.0, abs=0.5)
    assert _butterworth_highpass_lead_deg(0.97 * f30, 1.0) > 30.0
    assert _butterworth_highpass_lead_deg(f30, 1.0) == pytest.approx(
        hp.phase_lead_deg(f30), abs=1e-6
    )
    obs = velocity_from_settings({"method": "model_observer", "leak_hz": 0.02}, FS)
    assert trusted_from_hz(obs, 30.0) == pytest.approx(0.02 / math.tan(math.radians(30)), rel=0.02)
    assert trusted_from_hz(velocity_from_settings({"method": "position_observer"}, FS), 30.0) == 0.0
