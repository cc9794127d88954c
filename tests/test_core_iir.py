"""IIRFilter: the lfilter recursion per sample, in chunks and whole, same outputs and state."""

import numpy as np
import pytest
from scipy.signal import butter, lfilter

from fdi_daemon.core.iir import IIRFilter


def _random_filter(rng, nb, na):
    """Random numerator; stable denominator from real poles inside (-0.9, 0.9)."""
    return rng.normal(size=nb), np.poly(rng.uniform(-0.9, 0.9, na - 1))


def _chunks(rng, n):
    cuts = np.sort(rng.choice(np.arange(1, n), size=min(20, n - 1), replace=False))
    return np.split(np.arange(n), cuts)


@pytest.mark.parametrize("nb,na", [(5, 5), (4, 4), (5, 4), (2, 5), (1, 1), (3, 1), (1, 3)])
def test_step_run_chunks_match_lfilter(nb, na):
    rng = np.random.default_rng(nb * 10 + na)
    b, a = _random_filter(rng, nb, na)
    a = a * 2.5  # not normalised on purpose: the block normalises a0 = 1
    x = rng.normal(size=700)
    zi = rng.normal(size=max(nb, na) - 1)
    ref, zref = lfilter(b, a, x, zi=zi) if zi.size else (lfilter(b, a, x), np.zeros(0))

    one = IIRFilter(b, a, state=zi)
    y_step = np.array([one.step(float(v)) for v in x])
    whole = IIRFilter(b, a, state=zi)
    y_whole = whole.run(x)
    chunked = IIRFilter(b, a, state=zi)
    y_chunks = np.concatenate([chunked.run(x[idx]) for idx in _chunks(rng, x.size)])

    scale = np.max(np.abs(ref))
    np.testing.assert_allclose(y_whole, ref, rtol=1e-12, atol=1e-12 * scale)
    np.testing.assert_allclose(y_step, ref, rtol=1e-12, atol=1e-12 * scale)
    np.testing.assert_allclose(y_chunks, ref, rtol=1e-12, atol=1e-12 * scale)
    for f in (one, whole, chunked):
        np.testing.assert_allclose(f.state, zref, rtol=1e-12, atol=1e-12 * scale)


def test_mixing_step_and_run_continues_state():
    b, a = butter(4, 0.2)
    rng = np.random.default_rng(3)
    x = rng.normal(size=300)
    ref = lfilter(b, a, x)
    f = IIRFilter(b, a)
    out = [f.run(x[:100])]
    out.append(np.array([f.step(float(v)) for v in x[100:150]]))
    out.append(f.run(x[150:]))
    np.testing.assert_allclose(np.concatenate(out), ref, rtol=1e-12, atol=1e-13)


def test_normalises_a0_and_reset_and_state_validation():
    f = IIRFilter([2.0, 1.0], [2.0, -1.0])
    np.testing.assert_array_equal(f.a, [1.0, -0.5])
    np.testing.assert_array_equal(f.b, [1.0, 0.5])
    assert f.order == 1
    f.step(1.0)
    assert f.state[0] != 0.0
    f.reset()
    np.testing.assert_array_equal(f.state, [0.0])
    with pytest.raises(ValueError):
        f.state = [1.0, 2.0]
    with pytest.raises(ValueError):
        IIRFilter([1.0], [0.0, 1.0])
    with pytest.raises(ValueError):
        IIRFilter([np.nan], [1.0])


def test_empty_run_keeps_state():
    f = IIRFilter([1.0, 0.5], [1.0, -0.3], state=[0.7])
    assert f.run(np.array([])).size == 0
    np.testing.assert_array_equal(f.state, [0.7])
