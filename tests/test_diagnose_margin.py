"""The principles of issue 42 in isolation: a friction's force path constrained inside the
fit (`force.bounded_least_squares`, `force.friction_bounds`), a friction at that bound no
force (`force.at_bound`), and selection by a margin over held-out time blocks
(`select.margin`)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.optimize import lsq_linear

from fdi_daemon.diagnose.force import (
    _SIGN,
    _STRIBECK,
    _VEL,
    _X,
    at_bound,
    bounded_least_squares,
    friction_bounds,
)
from fdi_daemon.diagnose.select import margin
from fdi_daemon.diagnose.signals import Split


def test_friction_bounds_hold_the_leading_coefficient_of_each_friction_column():
    cols = [(_X, 0.0), (_SIGN, 0.0), (_VEL, 0.0)]
    upper = friction_bounds(cols, n_ff=2, width=3, per_column=3)
    assert list(np.isfinite(upper)) == [False] * 5 + [True, False, False, True, False, False]
    assert upper[5] == 0.0 and upper[8] == 0.0
    assert list(np.isfinite(friction_bounds(cols, 0, 3, 1))) == [False, True, True]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_bounded_least_squares_matches_a_bounded_solver(seed):
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(400, 5))
    theta = np.array([1.0, 0.7, -0.3, 2.0, 0.4])  # two bounded numbers want to be > 0
    y = x @ theta + 0.1 * rng.normal(size=400)
    upper = np.array([np.inf, 0.0, 0.0, np.inf, 0.0])
    got = bounded_least_squares(x, y, upper)
    assert np.all(got <= upper)
    want = lsq_linear(x, y, bounds=(-np.inf, upper), method="bvls").x
    assert got == pytest.approx(want, abs=1e-8)
    # unconstrained where no bound is active
    free = bounded_least_squares(x, y, np.full(5, np.inf))
    assert free == pytest.approx(np.linalg.lstsq(x, y, rcond=None)[0], abs=1e-8)


def _ctx(n=1000, seed=0):
    rng = np.random.default_rng(seed)
    return SimpleNamespace(target=rng.normal(size=n), split=Split(0, 500, n))


def test_a_fit_better_in_every_block_beats_by_the_margin():
    ctx = _ctx()
    better = 0.5 * ctx.target  # removes a quarter... three quarters of the error energy
    beats, gain, spread = margin(ctx, np.zeros_like(ctx.target), better)
    assert beats and gain == pytest.approx(0.75, rel=0.05) and spread < gain


def test_a_gain_held_by_one_block_is_not_a_margin():
    ctx = _ctx()
    better = np.zeros_like(ctx.target)
    better[500:600] = ctx.target[500:600]  # the whole gain sits in the first block
    beats, gain, spread = margin(ctx, np.zeros_like(ctx.target), better)
    assert gain > 0 and not beats and spread > gain
    # and a fit is never beaten by itself
    assert not margin(ctx, better, better)[0]


def test_a_stribeck_excess_is_bounded_like_the_friction_it_adds_to():
    # static friction above the Coulomb level, F_s ≥ F_c: the excess column's high-frequency
    # gain has the Coulomb column's sign (≤ 0)
    cols = [(_SIGN, 0.0), (_STRIBECK, 0.01)]
    upper = friction_bounds(cols, n_ff=0, width=3, per_column=3)
    assert list(upper) == [0.0, np.inf, np.inf, 0.0, np.inf, np.inf]


@pytest.mark.parametrize(
    "b, bound",
    [
        ([0.0, 0.0543, -0.152, 0.148, -0.050], True),  # held at 0 by bounded least squares
        # the trust region's last iterate strictly inside the bound (the rig's payload
        # record: a Stribeck excess beside lagged terms of 4e-3)
        ([-2.4e-7, -0.0015, 0.0043, -0.0042, 0.0014], True),
        ([-0.027, 0.0985, -0.135, 0.0825, -0.019], False),  # a friction that acts
        ([0.0, 0.0, 0.0], True),  # nothing at all
    ],
)
def test_a_friction_column_at_its_bound_is_no_force(b, bound):
    assert at_bound(np.array(b)) is bound
