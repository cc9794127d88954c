"""The mode lines (`fdi_daemon.diagnose.mode_lines`): one parameter of the nominal mode
changed, checked against a mass-spring-damper whose parameters we chose, simulated
exactly by scipy (zero-order hold), and the streaming block against its batch path."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from fdi_daemon.diagnose.mode_lines import ModeLineRegressor, mode_report, nominal_pole

FS = 256.0
MASS_KG, DAMPING_N_S_PER_M, STIFFNESS_N_PER_M = 2.0, 6.0, 2000.0  # 5.03 Hz, ζ 0.047


def _acceleration_model(mass, damping, stiffness):
    """a/F of m ẍ + c ẋ + k x = F, sampled with a zero-order hold (b, a in z⁻¹)."""
    num, den = [1.0 / mass, 0.0, 0.0], [1.0, damping / mass, stiffness / mass]
    b, a, _ = signal.cont2discrete((num, den), 1.0 / FS, method="zoh")
    return np.ravel(b), np.ravel(a)


def _force(seed=7, n=4096):
    """A broadband force (N), low-passed well below fs/2."""
    rng = np.random.default_rng(seed)
    return signal.lfilter(*signal.butter(4, 20.0, fs=FS), rng.standard_normal(n))


@pytest.mark.parametrize(
    "line,changed",
    [
        ("damping", {"damping": 3.0 * DAMPING_N_S_PER_M}),
        ("stiffness", {"stiffness": 0.8 * STIFFNESS_N_PER_M}),
        ("mass", {"mass": 1.25 * MASS_KG}),
        ("damping", {"damping": 0.5 * DAMPING_N_S_PER_M}),
    ],
)
def test_a_line_moves_the_mode_as_the_parameter_does(line, changed):
    params = {"mass": MASS_KG, "damping": DAMPING_N_S_PER_M, "stiffness": STIFFNESS_N_PER_M}
    ratio = next(changed[k] / params[k] for k in changed)
    b0, a0 = _acceleration_model(**params)
    b1, a1 = _acceleration_model(**{**params, **changed})
    force = _force()
    y0, y1 = signal.lfilter(b0, a0, force), signal.lfilter(b1, a1, force)
    phi = ModeLineRegressor(line, ratio, a0).run(force, force, force, y0)[:, 0]
    # the changed response, from the nominal one and the ratio alone: the line is exact in
    # continuous time; the sampled numerators differ by the hold (0.8–1.4 % of the change
    # here, a 5 Hz mode at 256 Hz)
    assert np.linalg.norm(y0 + phi - y1) <= 0.02 * np.linalg.norm(y1 - y0)
    # and its report reads the mode scipy's poles give
    report = mode_report(nominal_pole(a0), line, ratio, FS)
    s1 = np.log(np.roots(a1).astype(complex)) * FS
    s1 = s1[s1.imag > 0][0]
    assert report["resonance_hz"] == pytest.approx(abs(s1) / (2 * np.pi), rel=1e-9)
    assert report["damping_ratio"] == pytest.approx(-s1.real / abs(s1), rel=1e-9)
    per_mass = {**params, **changed}
    added = (per_mass["damping"] / per_mass["mass"]) - DAMPING_N_S_PER_M / MASS_KG
    assert report["damping_change_per_s"] == pytest.approx(added, rel=1e-9, abs=1e-9)


def test_a_line_streams_as_it_runs():
    _, a0 = _acceleration_model(MASS_KG, DAMPING_N_S_PER_M, STIFFNESS_N_PER_M)
    y0 = _force(seed=3, n=600)
    batch = ModeLineRegressor("mass", 1.3, a0)
    first = batch.run(y0, y0, y0, y0)[:, 0]
    second = batch.run(y0, y0, y0, y0)[:, 0]  # continues from its state
    streamed = ModeLineRegressor("mass", 1.3, a0)
    per_sample = [streamed.step(0.0, 0.0, 0.0, v)[0] for v in np.concatenate([y0, y0])]
    np.testing.assert_allclose(per_sample, np.concatenate([first, second]), rtol=0, atol=1e-12)
    np.testing.assert_allclose(streamed.state, batch.state, rtol=0, atol=1e-12)


def test_a_ratio_of_one_changes_nothing_and_a_model_without_a_mode_has_no_line():
    _, a0 = _acceleration_model(MASS_KG, DAMPING_N_S_PER_M, STIFFNESS_N_PER_M)
    y0 = _force(n=300)
    for line in ("damping", "stiffness", "mass"):
        phi = ModeLineRegressor(line, 1.0, a0).run(y0, y0, y0, y0)
        assert np.max(np.abs(phi)) <= 1e-12 * np.max(np.abs(y0))
    assert nominal_pole([1.0, -0.5]) is None
    with pytest.raises(ValueError, match="no pole pair"):
        ModeLineRegressor("damping", 2.0, [1.0, -0.5])
