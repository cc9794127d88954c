"""VelocityEstimator: high-pass + integrator, streaming contract, settings round trip."""

import math

import numpy as np
import pytest
from scipy.signal import butter, lfilter

from fdi_daemon.core.velocity import VelocityEstimator

FS = 256.0


def test_matches_highpass_then_trapezoid_integrator_reference():
    """Independent reference: scipy Butterworth high-pass, then cumulative trapezoid."""
    rng = np.random.default_rng(0)
    accel = rng.normal(size=4000) + 0.3  # with an offset
    b, a = butter(3, 1.0, btype="high", fs=FS)
    hp = lfilter(b, a, accel)
    ref = np.cumsum((hp + np.concatenate([[0.0], hp[:-1]])) / (2 * FS))
    v = VelocityEstimator(FS).run(accel)
    np.testing.assert_allclose(v, ref, rtol=1e-9, atol=1e-9 * np.max(np.abs(ref)))


@pytest.mark.parametrize("integrator", ["trapezoid", "backward_euler", "forward_euler"])
def test_sine_velocity_amplitude_and_phase(integrator):
    """a = A sin(ωt) -> v = -A/ω cos(ωt): amplitude within 0.5 %, lead as reported."""
    f = 8.0
    t = np.arange(int(20 * FS)) / FS
    w = 2 * math.pi * f
    est = VelocityEstimator(FS, integrator=integrator)
    v = est.run(np.sin(w * t))[-int(4 * FS) :]
    tt = t[-int(4 * FS) :]
    # least-squares fit of the steady state: v ≈ c cos(ωt) + s sin(ωt)
    basis = np.column_stack([np.cos(w * tt), np.sin(w * tt)])
    c, s = np.linalg.lstsq(basis, v, rcond=None)[0]
    amp = math.hypot(c, s) * w
    phase = math.degrees(math.atan2(s, -c))  # v = -R cos(ωt + lead); 0 for an ideal integral
    assert amp == pytest.approx(est.gain_error(f), rel=1e-3)
    assert abs(amp - 1) < 5e-3
    assert phase == pytest.approx(est.phase_lead_deg(f), abs=0.05)


def test_lead_at_8hz_and_compensation():
    est = VelocityEstimator(FS)
    assert 14.0 < est.phase_lead_deg(8.0) < 14.6  # 1 Hz 3rd-order Butterworth
    comp = VelocityEstimator(FS, lead_compensation_hz=8.0)
    assert abs(comp.phase_lead_deg(8.0)) < 1e-6
    assert comp.gain_error(8.0) == pytest.approx(est.gain_error(8.0), rel=1e-9)
    assert VelocityEstimator(FS, highpass_hz=0.25).phase_lead_deg(8.0) < 4.0


def test_offset_does_not_drift():
    """A constant accelerometer offset gives a velocity that decays back to zero."""
    v = VelocityEstimator(FS).run(np.full(int(60 * FS), 0.5))
    assert abs(v[-1]) < 1e-6
    assert np.all(np.isfinite(v))


@pytest.mark.parametrize(
    "settings",
    [{}, {"lead_compensation_hz": 8.0}, {"integrator": "forward_euler", "highpass_order": 2}],
)
def test_streaming_contract(settings):
    rng = np.random.default_rng(1)
    x = rng.normal(size=1500)
    whole = VelocityEstimator.from_settings(settings, FS)
    ref = whole.run(x)
    one = VelocityEstimator.from_settings(settings, FS)
    y_one = np.array([one.step(float(v)) for v in x])
    chunked = VelocityEstimator.from_settings(settings, FS)
    cuts = np.sort(rng.choice(np.arange(1, x.size), 25, replace=False))
    y_chunks = np.concatenate([chunked.run(part) for part in np.split(x, cuts)])
    atol = 1e-12 * np.max(np.abs(ref))
    np.testing.assert_allclose(y_one, ref, rtol=1e-12, atol=atol)
    np.testing.assert_allclose(y_chunks, ref, rtol=1e-12, atol=atol)
    np.testing.assert_allclose(one.state, whole.state, rtol=1e-12, atol=atol)
    np.testing.assert_allclose(chunked.state, whole.state, rtol=1e-12, atol=atol)
    one.reset()
    assert not np.any(one.state)


def test_settings_round_trip_and_validation():
    est = VelocityEstimator.from_settings({"highpass_hz": 0.5, "integrator": "backward_euler"}, FS)
    s = est.settings()
    assert s["highpass_hz"] == 0.5 and s["highpass_order"] == 3
    again = VelocityEstimator.from_settings(s)
    np.testing.assert_array_equal(again.b, est.b)
    np.testing.assert_array_equal(again.a, est.a)
    with pytest.raises(ValueError, match="unknown"):
        VelocityEstimator.from_settings({"cutoff": 1.0}, FS)
    with pytest.raises(ValueError, match="disagrees"):
        VelocityEstimator.from_settings({"fs_hz": 100.0}, FS)
    with pytest.raises(ValueError, match="needs fs_hz"):
        VelocityEstimator.from_settings({})
    with pytest.raises(ValueError, match="highpass_hz"):
        VelocityEstimator(FS, highpass_hz=200.0)
    with pytest.raises(ValueError, match="integrator"):
        VelocityEstimator(FS, integrator="simpson")
