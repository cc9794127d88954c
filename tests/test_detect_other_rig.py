"""The monitor on other simulated rigs, set up the way a user sets up a new rig.

Each rig's model is made from its own recordings with the command line (`fdi identify` on
the identification chirp, `fdi signature` on the calibration run); nothing is taken from the
shipped model. The rigs differ from the default one in mass, damping, valve bandwidth and
gain, seal friction, bearing pocket time constant and friction coefficient, drawn at random
(`rig_variant`, eight variants, docs/detector.md §4). Before the isolation test went beyond
a linear change of the plant, the valve-gain fault was isolated as friction on variants 1,
2 and 3, and on variant 1 also the supply-pressure, accelerometer-dropout and -saturation
faults.
"""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from conftest_detect import SCENARIOS

from fdi_daemon.detect.monitor import Monitor

FRICTION = [("test_case_1", 3.05, 1.5), ("test_case_2", 2.9, 0.7)]
NON_FRICTION = [
    "fault_accel_bias",
    "fault_valve_gain",
    "fault_supply_pressure",
    "fault_accel_dropout",
    "fault_accel_saturation",
]


def rig_variant(index: int) -> dict[str, float]:
    """RigParams overrides of random rig variant ``index`` (seeded)."""
    rng = np.random.default_rng(1000 + index)
    rig = {
        "bearing_mass_kg": rng.uniform(0.6, 1.8),
        "viscous_damping_n_s_per_m": rng.uniform(25.0, 80.0),
        "valve_bandwidth_hz": rng.uniform(8.0, 16.0),
        "valve_gain_per_v": rng.uniform(0.22, 0.38),
        "seal_coulomb_n": rng.uniform(0.03, 0.12),
        "bearing_time_constant_s": rng.uniform(0.003, 0.02),
        "bearing_mu_kinetic": rng.uniform(0.2, 0.35),
        "force_noise_n": rng.uniform(0.02, 0.06),
    }
    rig["seal_static_n"] = 2.0 * rig["seal_coulomb_n"]
    rig["bearing_mu_static"] = 1.1 * rig["bearing_mu_kinetic"]
    return {key: float(value) for key, value in rig.items()}


def record(rig: dict, name: str, duration_s: float | None = None):
    """A configs/scenarios scenario played on a rig variant."""
    from hil_sim.scenarios import scenario_from_dict, simulate

    spec = yaml.safe_load((SCENARIOS / f"{name}.yaml").read_text())
    spec["rig"] = {**spec.get("rig", {}), **rig}
    return simulate(scenario_from_dict(spec), duration_s=duration_s)


def model_of(rig: dict, tmp):
    """`fdi identify` and `fdi signature` on the rig's own recordings."""
    from fdi_daemon.cli import main
    from fdi_daemon.io.model_file import load_model
    from fdi_daemon.io.recordings import write_recording

    for name in ("ident_chirp", "ident_chirp_long", "signature_calibration"):
        write_recording(tmp / f"{name}.npz", record(rig, name))
    model = tmp / "model.yaml"
    assert (
        main(
            [
                "identify",
                str(tmp / "ident_chirp.npz"),
                "-o",
                str(model),
                "--validate",
                str(tmp / "ident_chirp_long.npz"),
            ]
        )
        == 0
    )
    assert (
        main(
            [
                "signature",
                str(tmp / "signature_calibration.npz"),
                "--model",
                str(model),
                "--fault-window",
                "11:40",
                "-o",
                str(model),
            ]
        )
        == 0
    )
    return load_model(model)


VARIANTS = range(8)
#: (variant, test case) whose small friction fault the fast test does not see
MISSED = {(4, "test_case_1"), (5, "test_case_1")}
MISSED_WHY = (
    "light load (0.60 and 0.70 kg), low contact friction and a noisier residual "
    "(σ_ref 0.077 m/s²): the statistic peaks at 24 and 19.5 against h = 30; the "
    "level path raises the alarm 2.8 s after the fault, too late to isolate it "
    "before the 6 s recording ends"
)


@pytest.fixture(scope="module")
def variant_model(tmp_path_factory):
    """variant -> its model, made once per module."""
    models = {}

    def get(variant: int):
        if variant not in models:
            models[variant] = model_of(
                rig_variant(variant), tmp_path_factory.mktemp(f"variant{variant}")
            )
        return models[variant]

    return get


def _kinds(model, rec):
    events, _ = Monitor(model).run(rec, trace_every=len(rec))
    return [(e["kind"], e["t"]) for e in events if e["kind"] != "calibrated"]


@pytest.mark.parametrize(
    "variant,name,fault_s,isolate_s",
    [
        pytest.param(
            v, name, fault_s, isolate_s, marks=pytest.mark.xfail(strict=True, reason=MISSED_WHY)
        )
        if (v, name) in MISSED
        else (v, name, fault_s, isolate_s)
        for v in VARIANTS
        for name, fault_s, isolate_s in FRICTION
    ],
)
def test_friction_is_detected_and_isolated(variant_model, variant, name, fault_s, isolate_s):
    """Detected within the default rig's delays (test case 1: 63 ms, the bearing touches down
    late; test case 2: the paper's 35 ms), isolated within the paper's tracking times."""
    kinds = _kinds(variant_model(variant), record(rig_variant(variant), name))
    assert [k for k, _ in kinds] == ["fault_detected", "friction_isolated"]
    assert fault_s <= kinds[0][1] <= fault_s + (0.07 if name == "test_case_1" else 0.035)
    assert kinds[1][1] <= fault_s + isolate_s


@pytest.mark.parametrize("variant", VARIANTS)
def test_no_other_fault_is_called_friction(variant_model, variant):
    """On some variants a fault leaves no trace under the 1.4 V sine (clipping at 3 m/s² of a
    signal that peaks below it) and nothing is raised; what is raised is never friction, also
    not in the minute after the fault (friction evidence that comes after the isolation
    timeout turns an other_fault into friction)."""
    model, rig = variant_model(variant), rig_variant(variant)
    for name in NON_FRICTION:
        kinds = [k for k, _ in _kinds(model, record(rig, name, duration_s=64.0))]
        assert "friction_isolated" not in kinds


@pytest.mark.parametrize("name", NON_FRICTION)
def test_on_variant_1_every_other_fault_is_detected_and_isolated_as_other(variant_model, name):
    kinds = _kinds(variant_model(1), record(rig_variant(1), name))
    assert [k for k, _ in kinds] == ["fault_detected", "other_fault"]
    assert kinds[0][1] >= 4.0


@pytest.mark.slow
@pytest.mark.parametrize("variant", VARIANTS)
def test_fault_free_changing_operation_raises_no_alarm(variant_model, variant):
    """10 minutes of the changing-operation scenario on every variant."""
    assert (
        _kinds(variant_model(variant), record(rig_variant(variant), "fault_free_hour", 600.0)) == []
    )
