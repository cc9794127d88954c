"""SlidingSums: window sums equal a direct sum; push, chunks and whole array are bit-equal."""

import numpy as np
import pytest

from fdi_daemon.core.sliding_sums import SlidingSums


@pytest.mark.parametrize("window", [1, 2, 7, 64])
def test_matches_direct_sum_and_batch_is_bit_equal(window):
    rng = np.random.default_rng(window)
    rows = rng.normal(size=(500, 3)) * [1.0, 1e3, 1e-3]
    one = SlidingSums(window, 3)
    pushed = np.array([list(one.push(tuple(r))) for r in rows.tolist()])
    direct = np.array([rows[max(0, k - window + 1):k + 1].sum(axis=0) for k in range(len(rows))])
    scale = np.abs(rows).max(axis=0)
    np.testing.assert_allclose(pushed / scale, direct / scale, rtol=0, atol=1e-12)
    for n_cuts in (0, 5, 80):
        est = SlidingSums(window, 3)
        cuts = np.sort(rng.choice(np.arange(1, len(rows)), n_cuts, replace=False))
        parts = [est.run(part) for part in np.split(rows, cuts)]
        got = np.concatenate([p[0] for p in parts])
        counts = np.concatenate([p[1] for p in parts])
        np.testing.assert_array_equal(got, pushed)
        np.testing.assert_array_equal(counts, np.minimum(np.arange(1, len(rows) + 1), window))
        state, ref = est.get_state(), one.get_state()
        for key in ref:
            np.testing.assert_array_equal(np.asarray(state[key]), np.asarray(ref[key]))


def test_state_round_trip_and_validation():
    rows = np.random.default_rng(9).normal(size=(50, 2))
    a = SlidingSums(8, 2)
    a.run(rows[:30])
    b = SlidingSums(8, 2)
    b.set_state(a.get_state())
    np.testing.assert_array_equal(a.run(rows[30:])[0], b.run(rows[30:])[0])
    with pytest.raises(ValueError):
        SlidingSums(0, 2)
    with pytest.raises(ValueError):
        a.run(np.ones((3, 3)))
