"""WindowLS: eq. (17) over the last N samples against np.linalg.lstsq; streaming contract."""

import numpy as np
import pytest

from fdi_daemon.core.window_ls import WindowLS, solve_sums

N = 40


def _data(seed, n=600, theta=(1.0, 2.5), noise=0.1):
    rng = np.random.default_rng(seed)
    g1 = np.sign(np.sin(np.arange(n) * 0.13 + 0.4)) + 0.2 * rng.normal(size=n)
    g2 = rng.normal(size=n) * (1 + np.arange(n) / n)
    y = theta[0] * g1 + theta[1] * g2 + noise * rng.normal(size=n)
    return g1, g2, y


def _lstsq_reference(g1, g2, y, n_window):
    out = np.full((g1.size, 2), np.nan)
    for k in range(n_window - 1, g1.size):
        sl = slice(k - n_window + 1, k + 1)
        out[k] = np.linalg.lstsq(np.column_stack([g1[sl], g2[sl]]), y[sl], rcond=None)[0]
    return out


def test_step_matches_direct_lstsq_per_window():
    g1, g2, y = _data(0)
    est = WindowLS(N)
    got = np.array([est.step(a, b, c) for a, b, c in zip(g1, g2, y)])
    ref = _lstsq_reference(g1, g2, y, N)
    assert np.all(np.isnan(got[: N - 1]))
    np.testing.assert_allclose(got[N - 1:], ref[N - 1:], rtol=1e-9, atol=1e-10)


def test_sse_is_window_residual():
    g1, g2, y = _data(1)
    est = WindowLS(N)
    for a, b, c in zip(g1, g2, y):
        est.step(a, b, c)
    sl = slice(-N, None)
    theta = np.array([est.theta1, est.theta2])
    resid = y[sl] - np.column_stack([g1[sl], g2[sl]]) @ theta
    assert est.sse == pytest.approx(np.sum(resid ** 2), rel=1e-8)


def test_batch_bit_equal_to_step_with_random_chunks():
    g1, g2, y = _data(2, n=2000)
    one = WindowLS(N)
    t_one = np.array([one.step(a, b, c) for a, b, c in zip(g1, g2, y)])
    whole = WindowLS(N)
    t1, t2 = whole.run(g1, g2, y)
    rng = np.random.default_rng(5)
    cuts = np.sort(rng.choice(np.arange(1, g1.size), 60, replace=False))
    chunked = WindowLS(N)
    parts = [chunked.run(g1[i], g2[i], y[i]) for i in np.split(np.arange(g1.size), cuts)]
    c1 = np.concatenate([p[0] for p in parts])
    c2 = np.concatenate([p[1] for p in parts])
    np.testing.assert_array_equal(t1, t_one[:, 0])
    np.testing.assert_array_equal(t2, t_one[:, 1])
    np.testing.assert_array_equal(c1, t_one[:, 0])
    np.testing.assert_array_equal(c2, t_one[:, 1])
    for est in (whole, chunked):
        s_one, s_est = one.get_state(), est.get_state()
        for key in s_one:
            np.testing.assert_array_equal(np.asarray(s_est[key]), np.asarray(s_one[key]))


def test_mixed_step_and_run_and_state_round_trip():
    g1, g2, y = _data(3, n=500)
    ref = WindowLS(N)
    r = np.array([ref.step(a, b, c) for a, b, c in zip(g1, g2, y)])
    est = WindowLS(N)
    est.run(g1[:77], g2[:77], y[:77])
    mid = np.array([est.step(a, b, c) for a, b, c in zip(g1[77:130], g2[77:130], y[77:130])])
    copy = WindowLS(N)
    copy.set_state(est.get_state())
    tail = np.column_stack(copy.run(g1[130:], g2[130:], y[130:]))
    np.testing.assert_array_equal(mid, r[77:130])
    np.testing.assert_array_equal(tail, r[130:])


def test_no_drift_over_long_runs():
    """Large offsets in the regressors: sliding sums stay exact thanks to the refresh."""
    rng = np.random.default_rng(4)
    n = 200_000
    g1 = 1e3 + rng.normal(size=n)
    g2 = rng.normal(size=n) * np.where(np.arange(n) % 7000 < 3500, 1e3, 1e-2)
    y = 0.5 * g1 - 2.0 * g2 + rng.normal(size=n)
    est = WindowLS(N)
    est.run(g1, g2, y)
    sl = slice(-N, None)
    exact = [np.sum(g1[sl] ** 2), np.sum(g1[sl] * g2[sl]), np.sum(g2[sl] ** 2),
             np.sum(g1[sl] * y[sl]), np.sum(g2[sl] * y[sl]), np.sum(y[sl] ** 2)]
    np.testing.assert_allclose(est.sums, exact, rtol=1e-12)


def test_rig_at_rest_gives_invalid_windows_not_numbers():
    """v ≈ 0: g2 = 0 and g1 is constant -> singular normal equations -> NaN, ok False."""
    n = 200
    g1 = np.ones(n)
    g2 = np.zeros(n)
    y = np.random.default_rng(6).normal(size=n) * 1e-3
    est = WindowLS(N)
    t1, t2 = est.run(g1, g2, y)
    assert np.all(np.isnan(t1)) and np.all(np.isnan(t2))
    assert est.ok is False
    # collinear regressors (g2 a multiple of g1)
    est2 = WindowLS(N)
    t1, _ = est2.run(g1 * np.arange(n), 3 * g1 * np.arange(n), y)
    assert np.all(np.isnan(t1))


def test_min_mean_square_floor():
    g1, g2, y = _data(7, n=300)
    est = WindowLS(N, min_mean_square=(0.0, 1e6))
    t1, _ = est.run(g1, g2, y)
    assert np.all(np.isnan(t1))
    sums, counts = WindowLS(N).run_sums(g1, g2, y)
    sol = solve_sums(sums, counts, N, 1e-6, (0.0, 0.0))
    assert sol.ok[N - 1:].all() and not sol.ok[: N - 1].any()


def test_validation():
    with pytest.raises(ValueError):
        WindowLS(2)
    with pytest.raises(ValueError):
        WindowLS(10, min_rcond=1.5)
    with pytest.raises(ValueError):
        WindowLS(10).run(np.ones(3), np.ones(4), np.ones(3))
