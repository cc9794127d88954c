"""normal_equations and InnovationTest: against lstsq; step, chunks and batch bit-equal."""

import numpy as np
import pytest

from fdi_daemon.core.innovation_test import InnovationTest, packed_row
from fdi_daemon.core.normal_equations import packed_products, packed_width, solve_packed


def test_solve_packed_matches_lstsq_for_floats_and_arrays():
    rng = np.random.default_rng(0)
    phi = rng.normal(size=(200, 4))
    y = phi @ [1.0, -2.0, 0.5, 3.0] + 0.1 * rng.normal(size=200)
    rows = packed_products(phi, y)
    assert rows.shape == (200, packed_width(4)) == (200, 15)
    np.testing.assert_array_equal(rows[7], packed_row(tuple(phi[7]), y[7]))
    theta, sse, ok = solve_packed(rows.sum(axis=0).tolist(), 4)
    ref, res, *_ = np.linalg.lstsq(phi, y, rcond=None)
    assert ok
    np.testing.assert_allclose(theta, ref, rtol=1e-10)
    assert sse == pytest.approx(res[0], rel=1e-6)
    # many windows at once: the same numbers, bit for bit
    cums = np.cumsum(rows, axis=0)[50:]
    th_arr, sse_arr, ok_arr = solve_packed([cums[:, c] for c in range(15)], 4)
    for k in (0, 77, 149):
        th_one, sse_one, ok_one = solve_packed(cums[k].tolist(), 4)
        assert [float(t[k]) for t in th_arr] == th_one
        assert float(sse_arr[k]) == sse_one and bool(ok_arr[k]) == ok_one


def test_rank_deficient_windows_are_invalid():
    phi = np.column_stack([np.ones(50), 2 * np.ones(50)])
    _, _, ok = solve_packed(packed_products(phi, np.ones(50)).sum(axis=0).tolist(), 2)
    assert not ok
    _, _, ok = solve_packed(np.zeros(packed_width(3)).tolist(), 3)
    assert not ok


def _data(n=3000, seed=1):
    rng = np.random.default_rng(seed)
    phi = np.column_stack([np.sin(np.arange(n) * 0.2), rng.normal(size=n), np.ones(n)])
    y = phi @ [1.0, 0.5, -0.2] + 0.05 * rng.normal(size=n)
    y[2000:] += 0.8 * phi[2000:, 0]  # a change the test must see
    return phi, y


def test_statistic_reacts_to_a_change_and_not_before():
    phi, y = _data()
    test = InnovationTest(
        3, window_samples=200, lag_samples=10, test_samples=8, every=2, min_sigma=1e-3
    )
    stat, ok, theta = test.run(phi, y)
    assert len(theta) == 3 and theta[0].shape == y.shape
    assert not ok[:209].any() and ok[300:].all()
    assert np.nanmax(stat[400:2000]) < 5.0
    assert stat[2000:2020].max() > 50.0


@pytest.mark.parametrize("every", [1, 3])
def test_step_run_and_chunks_are_bit_equal(every):
    phi, y = _data(n=1500)
    args = dict(p=3, window_samples=100, lag_samples=7, test_samples=5, every=every, min_sigma=1e-3)
    one = InnovationTest(**args)
    ref = np.array([one.step(tuple(row), float(v)) for row, v in zip(phi.tolist(), y)])
    whole = InnovationTest(**args)
    np.testing.assert_array_equal(whole.run(phi, y)[0], ref)
    rng = np.random.default_rng(every)
    cuts = np.sort(rng.choice(np.arange(1, y.size), 40, replace=False))
    chunked = InnovationTest(**args)
    got = np.concatenate([chunked.run(phi[i], y[i])[0] for i in np.split(np.arange(y.size), cuts)])
    np.testing.assert_array_equal(got, ref)
    for est in (whole, chunked):
        assert est.theta == one.theta and est.sigma2 == one.sigma2 and est.ok == one.ok
    # and back to per-tick after a batch
    mixed = InnovationTest(**args)
    mixed.run(phi[:600], y[:600])
    tail = [mixed.step(tuple(row), float(v)) for row, v in zip(phi[600:].tolist(), y[600:])]
    np.testing.assert_array_equal(tail, ref[600:])


@pytest.mark.parametrize("p,every", [(3, 3), (4, 8), (4, 1)])
def test_reference_fit_is_the_least_squares_fit_of_its_lagged_window(p, every):
    """On every refit tick t (t % every == 0) with a complete window, θ_ref is a direct
    least-squares solve on the N rows ending ``lag`` before t, N = window_samples rounded to
    whole refits: both the generic group sums (p = 3) and the four-regressor ones held in
    registers (p = 4)."""
    from fdi_daemon.core.kernels import itest_groups

    rng = np.random.default_rng(p + every)
    n_rows, lag, window = 1200, 7, 100
    phi = np.column_stack([rng.normal(size=(n_rows, p - 1)), np.ones(n_rows)])
    y = phi @ np.arange(1.0, p + 1.0) + 0.1 * rng.normal(size=n_rows)
    test = InnovationTest(
        p, window_samples=window, lag_samples=lag, test_samples=5, every=every, min_sigma=1e-3
    )
    _, ok, theta = test.run(phi, y)
    theta = np.column_stack(theta)
    n = itest_groups(window, every) * every
    checked = 0
    for t in range(0, n_rows, every):
        if not ok[t]:
            assert t < lag + n + 2 * every  # complete once its first group has left
            continue
        rows = slice(t - lag - n + 1, t - lag + 1)
        direct = np.linalg.lstsq(phi[rows], y[rows], rcond=None)[0]
        np.testing.assert_allclose(theta[t], direct, rtol=1e-9, atol=1e-12)
        checked += 1
    assert checked > (n_rows - lag - n) // every - 3
