"""The compiled reference chain of `fdi bench` computes what the monitor's chain computes:
checked against scipy's lfilter and a direct least-squares solve per window."""

import numpy as np
import pytest
from scipy.signal import lfilter

from fdi_daemon.bench.reference_chain import ReferenceChain
from fdi_daemon.detect.pipeline import Pipeline
from fdi_daemon.io.model_file import load_model
from fdi_daemon.service.config import default_config_path

WINDOW = 64


@pytest.fixture(scope="module")
def model():
    return load_model(default_config_path().with_name("model_sim_rig.yaml"))


@pytest.fixture(scope="module")
def signals():
    rng = np.random.default_rng(7)
    n = 700
    t = np.arange(n) / 256.0
    v_in = np.sin(2 * np.pi * 3.0 * t) + 0.4 * np.sin(2 * np.pi * 7.0 * t)
    accel = 0.3 * np.cos(2 * np.pi * 3.0 * t) + 0.05 * rng.standard_normal(n)
    return v_in, accel


def test_theta_equals_a_direct_least_squares_solve_of_each_window(model, signals):
    v_in, accel = signals
    pl = Pipeline(model, WINDOW)
    (pb, pa), (vb, va), (gb, ga) = (
        (pl.plant.b, pl.plant.a),
        (pl.velocity.b, pl.velocity.a),
        (pl.ge_sign.b, pl.ge_sign.a),
    )
    r = accel - lfilter(pb, pa, v_in)
    v = lfilter(vb, va, accel)
    g1, g2 = lfilter(gb, ga, np.sign(v)), lfilter(gb, ga, v)
    theta1, theta2 = ReferenceChain.from_model(model, WINDOW).run(v_in, accel)
    assert np.all(np.isnan(theta1[: WINDOW - 1]))
    for k in range(WINDOW - 1, len(r), 37):
        sl = slice(k - WINDOW + 1, k + 1)
        expect = np.linalg.lstsq(np.column_stack([g1[sl], g2[sl]]), r[sl], rcond=None)[0]
        np.testing.assert_allclose([theta1[k], theta2[k]], expect, rtol=1e-7, atol=1e-9)


def test_one_call_per_sample_equals_one_call_over_the_array(model, signals):
    v_in, accel = signals
    whole = ReferenceChain.from_model(model, WINDOW).run(v_in, accel)
    chain = ReferenceChain.from_model(model, WINDOW)
    per_sample = np.empty((2, len(v_in)))
    for k, (v, a) in enumerate(zip(v_in, accel)):
        chain.step(float(v), float(a))
        per_sample[:, k] = chain.out
    np.testing.assert_array_equal(per_sample, np.vstack(whole))
