"""PositionVelocityObserver: position and acceleration fused; contract, known system, holds."""

import math

import numpy as np
import pytest

from fdi_daemon.core.velocity_observer import velocity_from_settings
from fdi_daemon.core.velocity_position import PositionVelocityObserver

FS = 256.0


def _motion(n=6000, seed=0):
    """A smooth random position (m) and its exact velocity and acceleration."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / FS
    freqs = rng.uniform(0.3, 12.0, 12)
    amps = 0.002 / freqs
    phases = rng.uniform(0, 2 * np.pi, 12)
    arg = 2 * np.pi * freqs[:, None] * t + phases[:, None]
    w = 2 * np.pi * freqs[:, None]
    x = (amps[:, None] * np.sin(arg)).sum(0)
    v = (amps[:, None] * w * np.cos(arg)).sum(0)
    a = (-amps[:, None] * w * w * np.sin(arg)).sum(0)
    return t, x, v, a


def test_exact_signals_give_the_true_velocity():
    """Independent reference: the analytic derivative of a known motion. With consistent
    position and acceleration the weights add up to one at every frequency."""
    _, x, v, a = _motion()
    est = PositionVelocityObserver(FS, crossover_hz=5.0).run(a, x)
    settled = slice(int(3 * FS), None)
    err = np.sqrt(np.mean((est - v)[settled] ** 2) / np.mean(v[settled] ** 2))
    assert err < 1e-2  # the bilinear derivative's warping: at most 0.73 % (12 Hz)


@pytest.mark.parametrize("crossover_hz", [2.0, 5.0, 15.0])
def test_response_is_one_within_the_bilinear_warping(crossover_hz):
    """v̂/(jω x) for ẍ = (jω)² x: the two discretised weights add up to one exactly for the
    bilinear derivative, so what remains is its warping: < 1 % and 0.5° up to 10 Hz."""
    obs = PositionVelocityObserver(FS, crossover_hz=crossover_hz)
    for f in (0.5, 2.0, 5.0, 8.0, 10.0):
        h = obs.response(f)
        assert abs(abs(h) - 1) < 1e-2
        assert abs(math.degrees(np.angle(h))) < 0.5


def test_a_held_load_reads_zero_velocity_whatever_the_accelerometer_says():
    """Position constant, accelerometer with an offset and noise: v̂ stays near zero (the
    integral of the offset is what the high-pass estimator has to fight)."""
    rng = np.random.default_rng(2)
    n = int(20 * FS)
    accel = 0.05 + 0.02 * rng.standard_normal(n)
    v = PositionVelocityObserver(FS, crossover_hz=5.0).run(accel, np.full(n, 0.01))
    assert np.max(np.abs(v[int(5 * FS) :])) < 1e-3


def test_streaming_contract_with_missing_positions():
    _, x, _, a = _motion(3000, seed=1)
    x = x.copy()
    x[[0, 1, 500, 501, 502, 2999]] = np.nan  # missing at the start, inside, at the end
    whole = PositionVelocityObserver(FS)
    ref = whole.run(a, x)
    one = PositionVelocityObserver(FS)
    stepped = np.array([one.step(ai, xi) for ai, xi in zip(a, x)])
    np.testing.assert_allclose(stepped, ref, rtol=1e-12, atol=1e-15)
    chunked = PositionVelocityObserver(FS)
    cuts = [1, 2, 500, 501, 1700, 2999]
    parts = [chunked.run(ai, xi) for ai, xi in zip(np.split(a, cuts), np.split(x, cuts))]
    np.testing.assert_allclose(np.concatenate(parts), ref, rtol=1e-12, atol=1e-15)
    for obs in (one, chunked):
        for s, r in zip(obs.state[:2], whole.state[:2]):
            np.testing.assert_allclose(s, r, rtol=1e-12, atol=1e-15)
        assert obs.state[2] == whole.state[2] == x[2998]
    # a missing position holds the last one: the same as feeding it again
    held = x.copy()
    held[[500, 501, 502]] = x[499]
    held[2999] = x[2998]
    held[[0, 1]] = 0.0
    np.testing.assert_allclose(
        PositionVelocityObserver(FS).run(a, held), ref, rtol=1e-12, atol=1e-15
    )


def test_settings_round_trip():
    obs = velocity_from_settings({"method": "position_observer", "crossover_hz": 8.0}, FS)
    assert isinstance(obs, PositionVelocityObserver) and obs.needs_position
    assert velocity_from_settings(obs.settings(), FS).settings() == obs.settings()
    with pytest.raises(ValueError, match="damping"):
        PositionVelocityObserver(FS, damping=0.1)
