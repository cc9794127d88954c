"""The augmented model: streaming contract, model-file round trip, what was fitted."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from fdi_daemon.diagnose.augment import AugmentedPlant
from fdi_daemon.diagnose.effects import SPECS, FittedEffect
from fdi_daemon.errors import ConfigError
from fdi_daemon.io.model_file import FdiModel, model_from_dict
from hil_sim.msd import MsdParams, friction_tf
from tests.diagnose_cases import FS, changed_recording, nominal_model, recording


def _plant(kind: str = "acceleration") -> AugmentedPlant:
    b, a = nominal_model()
    rng = np.random.default_rng(0)
    width = len(a)
    # force on the mass -> output: the §V model's exact force path (no input filter on it)
    b_force, a_force = friction_tf(MsdParams())
    np.testing.assert_allclose(a_force, a)
    path = AugmentedPlant(FS, b_force, a, kind, 0.2)
    b_path = np.zeros(len(path.a_dom))
    b_path[: len(path.b_dom)] = path.b_dom
    #: forces in the loop: friction that opposes motion, a hardening spring, a stiffer
    #: linear spring (input units)
    force = {
        "coulomb_friction": 0.05,
        "stribeck_friction": 0.05,
        "cubic_stiffness": 1e4,
        "stiffness_change": 10.0,
        "mass_change": 5.0,
    }
    effects = []
    for name, param in [
        ("coulomb_friction", None),
        ("stribeck_friction", 0.05),
        ("cubic_stiffness", None),
        ("stiffness_change", None),
        ("mass_change", None),
        ("dead_time", 2.6),
        ("mode_damping", 1.7),
        ("mode_mass", 1.2),
        ("backlash", 0.1),
        ("dead_zone", 0.05),
        ("output_saturation", 5.0),
        ("sensor_offset", None),
    ]:
        spec = SPECS[name]
        n_reg = 2 if name == "stribeck_friction" else 1
        if name in force:
            coefs = [-force[name] * rng.uniform(0.5, 1.5) * b_path for _ in range(n_reg)]
        elif spec.dynamic:
            coefs = [0.01 * rng.standard_normal(width) for _ in range(n_reg)]
        else:
            coefs = [0.1 * rng.standard_normal(1)]
        centre = 0.05 if name in ("dead_zone", "output_saturation") else 0.0
        effects.append(
            FittedEffect(name, param, coefs, n_linear=sum(c.size for c in coefs), centre=centre)
        )
    return AugmentedPlant(FS, b, a, kind, 0.2, effects)


def _same_state(s1, s2):
    assert len(s1) == len(s2)
    for x, y in zip(s1, s2):
        if x is None or y is None:
            assert x is None and y is None
        else:
            np.testing.assert_allclose(
                np.asarray(x, float), np.asarray(y, float), rtol=1e-12, atol=1e-12
            )


@pytest.mark.parametrize("kind", ["acceleration", "velocity"])
def test_step_chunks_and_whole_array_agree(kind):
    rng = np.random.default_rng(1)
    u = 0.5 * rng.standard_normal(700)
    whole = _plant(kind)
    y_whole = whole.run(u)
    single = _plant(kind)
    y_single = np.array([single.step(float(x)) for x in u])
    chunked = _plant(kind)
    cuts = np.sort(rng.choice(np.arange(1, len(u)), 12, replace=False))
    y_chunks = np.concatenate([chunked.run(c) for c in np.split(u, cuts)])
    assert np.all(np.isfinite(y_whole))  # the force loop of the test plant is stable
    scale = np.max(np.abs(y_whole))
    np.testing.assert_allclose(y_single, y_whole, rtol=1e-12, atol=1e-12 * scale)
    np.testing.assert_allclose(y_chunks, y_whole, rtol=1e-12, atol=1e-12 * scale)
    _same_state(single.state, whole.state)
    _same_state(chunked.state, whole.state)
    whole.reset()
    np.testing.assert_array_equal(whole.run(u), y_whole)


def test_without_effects_it_is_the_plain_plant():
    b, a = nominal_model()
    u = np.random.default_rng(2).standard_normal(500)
    np.testing.assert_allclose(
        AugmentedPlant(FS, b, a).run(u), signal.lfilter(b, a, u), rtol=1e-12, atol=1e-12
    )


@pytest.mark.parametrize("sensor", ["sensor_offset", "output_saturation"])
def test_a_sensor_effect_is_added_after_the_force_loop(sensor):
    """A sensor's effect changes what is measured, not how the mass moves: the plant with a
    Coulomb friction and the sensor's effect is the plant with the friction alone plus the
    sensor's part computed on the plain plant's ŷ₀ (before, a fitted offset entered the loop
    and its integral was taken for a velocity)."""
    b, a = nominal_model()
    b_force, _ = friction_tf(MsdParams())
    path = AugmentedPlant(FS, b_force, a, "acceleration", 0.2)
    b_path = np.zeros(len(path.a_dom))
    b_path[: len(path.b_dom)] = path.b_dom
    friction = FittedEffect("coulomb_friction", None, [-0.05 * b_path], n_linear=len(b_path))
    size = {"sensor_offset": 0.5, "output_saturation": 0.3}[sensor]
    at_sensor = FittedEffect(sensor, 2.0, [np.array([size])], n_linear=1)
    u = np.random.default_rng(4).standard_normal(600)
    both = AugmentedPlant(FS, b, a, "acceleration", 0.2, [friction, at_sensor]).run_signals(u)
    alone = AugmentedPlant(FS, b, a, "acceleration", 0.2, [friction]).run(u)
    assert np.max(np.abs(both["parts"][sensor])) > 0.01
    np.testing.assert_allclose(both["y"], alone + both["parts"][sensor], rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("kind", ["acceleration", "velocity"])
def test_model_file_round_trip(kind):
    plant = _plant(kind)
    b, a = nominal_model()
    model = FdiModel(fs=FS, plant_b=b, plant_a=a, extra={"effects": plant.to_extra()})
    back = AugmentedPlant.from_model(model_from_dict(model.to_dict()))
    u = np.random.default_rng(3).standard_normal(400)
    np.testing.assert_allclose(back.run(u), _plant(kind).run(u), rtol=1e-12, atol=1e-12)


#: the recordings diagnosed here, by the effect they hide
HIDDEN = {
    "coulomb_friction": lambda: recording("coulomb_friction"),
    # the refit's damping line (`mode_lines`), an output effect with its own filter
    "mode_damping": lambda: changed_recording("damping_n_s_per_m", 1.5),
}


def _diagnosed(diagnosis, hidden: str):
    """(recording, its diagnosis against the nominal plant), once per test run (`diagnosis`,
    conftest_diagnose.py): two tests here and test_diagnose_effects.py read the Coulomb
    friction's."""
    rec = HIDDEN[hidden]()
    b, a = nominal_model()
    return rec, diagnosis(rec.v_in, rec.accel, FS, "acceleration", b, a)


@pytest.mark.parametrize("named", list(HIDDEN))
def test_augmented_plant_reproduces_the_workflow(named, diagnosis):
    rec, result = _diagnosed(diagnosis, named)
    b, a = nominal_model()
    assert named in [e.name for e in result.selection.named]
    model = FdiModel(fs=FS, plant_b=b, plant_a=a, extra={"effects": result.plant.to_extra()})
    plant = AugmentedPlant.from_model(model_from_dict(model.to_dict()))
    np.testing.assert_allclose(
        plant.run(rec.v_in), result.y_after, rtol=1e-9, atol=1e-9 * np.max(np.abs(result.y_after))
    )


def test_bad_effects_section_is_a_config_error():
    b, a = nominal_model()
    for section in (
        {"items": [{"name": "warp_drive"}]},
        {"items": [{"name": "dead_zone", "coefficients": [[1.0]]}]},
        {"output_kind": "jerk", "items": []},
    ):
        with pytest.raises(ConfigError):
            AugmentedPlant.from_model(
                FdiModel(fs=FS, plant_b=b, plant_a=a, extra={"effects": section})
            )
    # a mode line on a plant that has no mode (a first-order plant)
    line = {
        "items": [
            {
                "name": "mode_damping",
                "param": {"name": "damping_scale", "value": 2.0},
                "coefficients": [[1.0]],
            }
        ]
    }
    with pytest.raises(ConfigError, match="no pole pair"):
        AugmentedPlant.from_model(
            FdiModel(fs=FS, plant_b=[0.1], plant_a=[1.0, -0.9], extra={"effects": line})
        )


def test_monitor_pipeline_uses_the_augmented_model_and_its_residual_shrinks(tmp_path, diagnosis):
    from fdi_daemon.cli import main
    from fdi_daemon.detect.pipeline import Pipeline
    from fdi_daemon.io.model_file import FaultFilter, save_model
    from fdi_daemon.io.recordings import write_recording

    rec, result = _diagnosed(diagnosis, "coulomb_friction")
    b, a = nominal_model()
    ff = FaultFilter(b=np.array([0.01, 0.02]), f=np.array([1.0, -0.5]), nk=0, gamma_f=1.0)
    plain = FdiModel(fs=FS, plant_b=b, plant_a=a, fault_filter=ff)
    augmented = model_from_dict(
        FdiModel(
            fs=FS, plant_b=b, plant_a=a, fault_filter=ff, extra={"effects": result.plant.to_extra()}
        ).to_dict()
    )
    test = slice(len(rec.t) * 2 // 3, None)
    r_plain = Pipeline(plain, 256).run(rec.v_in, rec.accel).residual
    batch = Pipeline(augmented, 256)
    assert isinstance(batch.plant, AugmentedPlant)
    r_aug = batch.run(rec.v_in, rec.accel).residual
    assert np.std(r_aug[test]) < 0.5 * np.std(r_plain[test])
    ticks = Pipeline(augmented, 256)
    per_tick = []
    for v, acc in zip(rec.v_in[:600].tolist(), rec.accel[:600].tolist()):
        ticks.step(v, acc)
        per_tick.append(ticks.residual)
    np.testing.assert_allclose(per_tick, r_aug[:600], rtol=1e-9, atol=1e-9 * np.max(np.abs(r_aug)))
    # and `fdi replay` takes the augmented model file as its nominal model
    save_model(tmp_path / "aug.yaml", augmented)
    write_recording(tmp_path / "rec.csv", rec)
    assert (
        main(
            [
                "replay",
                str(tmp_path / "rec.csv"),
                "--model",
                str(tmp_path / "aug.yaml"),
                "--summary",
                str(tmp_path / "s.json"),
            ]
        )
        == 0
    )
    assert (tmp_path / "s.json").exists()


def test_monitor_refuses_effects_fitted_on_velocity():
    from fdi_daemon.diagnose.augment import nominal_plant

    b, a = nominal_model()
    model = FdiModel(fs=FS, plant_b=b, plant_a=a, extra={"effects": _plant("velocity").to_extra()})
    with pytest.raises(ConfigError, match="velocity"):
        nominal_plant(model)


def test_a_model_file_without_force_loop_keeps_its_fed_forward_meaning():
    # files written before issue 14 have no force_loop key: force effects fed forward
    b, a = nominal_model()
    plant = _plant()
    extra = plant.to_extra()
    del extra["force_loop"]
    old = AugmentedPlant.from_model(
        model_from_dict(FdiModel(fs=FS, plant_b=b, plant_a=a, extra={"effects": extra}).to_dict())
    )
    assert not old.force_loop
    u = 0.5 * np.random.default_rng(2).standard_normal(500)
    fed = old.run_signals(u)
    # fed forward: the output is ŷ₀ plus each effect's own part, nothing in a loop
    assert "force_loop" not in fed["parts"]
    np.testing.assert_allclose(
        fed["y"], fed["y0"] + sum(fed["parts"].values()), rtol=1e-12, atol=1e-12
    )
    assert not np.allclose(fed["y"], plant.run(u))


def test_an_old_dead_time_item_is_refused_not_misread():
    # before issue 14 dead_time was u(t − τ) − u(t) through a numerator; now a pure shift
    b, a = nominal_model()
    items = [
        {
            "name": "dead_time",
            "param": {"name": "dead_time_s", "value": 0.01},
            "coefficients": [[0.1, 0.2, 0.0, 0.0, 0.0]],
        }
    ]
    model = FdiModel(
        fs=FS,
        plant_b=b,
        plant_a=a,
        extra={"effects": {"output_kind": "acceleration", "items": items}},
    )
    with pytest.raises(ConfigError, match="older fdi diagnose"):
        AugmentedPlant.from_model(model_from_dict(model.to_dict()))
