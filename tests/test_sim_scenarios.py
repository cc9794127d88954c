"""Scenario files, their validation, and the `fdi sim record` command."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from conftest_sim import FS, SCENARIOS, scenario_path

from fdi_daemon.cli import main
from fdi_daemon.errors import ConfigError
from fdi_daemon.io.recordings import read_recording
from hil_sim.excitation import chirp
from hil_sim.scenarios import load_scenario, simulate

EXPECTED = [
    "ident_chirp",
    "ident_chirp_long",
    "test_case_1",
    "test_case_2",
    "signature_calibration",
    "fault_free_hour",
    "fault_accel_bias",
    "fault_valve_gain",
    "fault_supply_pressure",
    "fault_accel_dropout",
    "fault_accel_saturation",
]


@pytest.mark.parametrize("name", EXPECTED)
def test_scenarios_load_and_simulate(name):
    scenario = load_scenario(scenario_path(name))
    rec = simulate(scenario, duration_s=min(scenario.duration_s, 3.0))
    assert rec.meta["scenario"] == name
    assert rec.fs == FS
    assert np.all(np.isfinite(rec.accel))
    assert set(
        (
            "t",
            "v_in",
            "accel",
            "position",
            "seq",
            "friction_force",
            "seal_friction_force",
            "fault_active",
            "bearing_supply",
        )
    ) <= set(rec.columns)
    assert list(rec.columns)[:5] == ["t", "v_in", "accel", "position", "seq"]


def test_every_scenario_file_is_valid():
    for path in sorted(SCENARIOS.glob("*.yaml")):
        load_scenario(path)


def test_ident_chirp_is_the_papers_experiment():
    rec = simulate(load_scenario(scenario_path("ident_chirp")))
    assert len(rec) == 1024
    expected = chirp(np.arange(1024) / FS, 0.7, 0.0, 20.0, 4.0)
    assert np.abs(rec["valve_drive"] - expected).max() < 1e-12
    assert np.abs(rec.v_in - expected).max() < 5e-3  # ADC noise and quantisation
    assert np.all(rec["fault_active"] == 0.0)


def test_test_case_metadata_and_ground_truth():
    rec = simulate(load_scenario(scenario_path("test_case_2")), seed=4)
    assert rec.meta["friction_fault_t"] == "2.9"
    assert rec.meta["seed"] == "4"
    assert np.all(rec["bearing_supply"][rec.t < 2.9] == 1.0)
    assert np.all(rec["bearing_supply"][rec.t >= 2.9] == 0.0)
    assert np.abs(rec.v_in).max() == pytest.approx(1.5, abs=0.01)


def test_signature_calibration_has_fault_window_and_varied_amplitudes():
    scenario = load_scenario(scenario_path("signature_calibration"))
    rec = simulate(scenario)
    t0, t1 = (float(x) for x in rec.meta["fault_window"].split(":"))
    inside = (rec.t >= t0) & (rec.t < t1)
    assert np.all(rec["fault_active"][inside] == 1.0)
    assert np.all(rec["fault_active"][rec.t < float(rec.meta["friction_fault_t"])] == 0.0)
    # the velocity amplitude varies (so gamma_f is identifiable) within the fault window
    whole_segments = rec.t >= 12.5  # segments are 2.5 s long
    segment_rms = rec["velocity_true"][whole_segments].reshape(-1, 640).std(axis=1)
    assert segment_rms.max() > 2 * segment_rms.min()
    assert {seg["frequency_hz"] for seg in scenario.excitation} == {6.0, 8.0}


def test_fault_free_hour_drifts_but_stays_fault_free():
    scenario = load_scenario(scenario_path("fault_free_hour"))
    assert scenario.duration_s == 3600.0
    rec = simulate(scenario, duration_s=600.0)
    assert np.all(rec["fault_active"] == 0.0)
    assert np.all(rec["other_fault_active"] == 0.0)
    assert rec["bearing_supply"].min() < 0.99  # the bearing supply drifts ...
    assert np.abs(rec["position_true"]).max() < 0.04  # ... the piston stays off the stops
    assert np.abs(rec.v_in).max() < 2.5
    # changing operation: the per-10 s RMS of the drive varies
    rms = rec.v_in[: 600 * 256].reshape(60, -1).std(axis=1)
    assert rms.max() > 2 * rms.min()


def test_random_excitation_depends_on_seed_only():
    scenario = load_scenario(scenario_path("fault_free_hour"))
    a = simulate(scenario, seed=1, duration_s=60)
    b = simulate(scenario, seed=1, duration_s=60)
    c = simulate(scenario, seed=2, duration_s=60)
    assert np.array_equal(a["valve_drive"], b["valve_drive"])
    assert not np.array_equal(a["valve_drive"], c["valve_drive"])


BAD = [
    ({"colour": 1}, "colour"),
    (
        {"excitation": [{"kind": "sine", "amplitude_v": 1, "frequency_hz": 8, "phase": 0}]},
        "excitation[0].phase",
    ),
    ({"excitation": [{"kind": "square", "amplitude_v": 1}]}, "excitation[0].kind"),
    ({"excitation": [{"kind": "sine", "amplitude_v": 1}]}, "excitation[0].frequency_hz"),
    ({"duration_s": "long"}, "duration_s"),
    ({"rig": {"bore_mm": 25}}, "rig.bore_mm"),
    ({"events": [{"t_s": 1, "fault": "accel_gain", "value": 1}]}, "events[0].fault"),
    ({"events": [{"t_s": 1, "bearing_supply": 0.5, "ramp": 2}]}, "events[0].ramp"),
    ({"drift": {"humidity": {"times_s": [0], "values": [1]}}}, "drift.humidity"),
]


@pytest.mark.parametrize("change, key", BAD)
def test_bad_scenario_is_a_one_line_config_error_naming_the_key(tmp_path, change, key):
    data = {
        "duration_s": 2.0,
        "excitation": [{"kind": "sine", "amplitude_v": 1.0, "frequency_hz": 8.0}],
    }
    data.update(change)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError) as err:
        load_scenario(path)
    message = str(err.value)
    assert key in message
    assert "\n" not in message


def test_missing_duration_and_broken_yaml(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("excitation: [{kind: zero}]\n")
    with pytest.raises(ConfigError, match="duration_s"):
        load_scenario(path)
    path.write_text("duration_s: [1\n")
    with pytest.raises(ConfigError, match="YAML"):
        load_scenario(path)


def test_cli_record_writes_a_readable_recording(tmp_path, capsys):
    out = tmp_path / "tc1.csv"
    code = main(
        [
            "sim",
            "record",
            str(scenario_path("test_case_1")),
            "-o",
            str(out),
            "--seed",
            "7",
            "--duration",
            "4",
        ]
    )
    assert code == 0
    rec = read_recording(out)
    assert len(rec) == 4 * 256
    assert rec.meta["seed"] == "7"
    assert rec.meta["friction_fault_t"] == "3.05"
    assert rec.sampling.ok
    expected = simulate(load_scenario(scenario_path("test_case_1")), seed=7, duration_s=4)
    assert np.allclose(rec.accel, expected.accel, rtol=1e-9, atol=1e-9)
    assert "wrote" in capsys.readouterr().err


def test_cli_record_npz(tmp_path):
    out = tmp_path / "chirp.npz"
    assert (
        main(["sim", "record", str(scenario_path("ident_chirp")), "-o", str(out), "--quiet"]) == 0
    )
    assert len(read_recording(out)) == 1024


@pytest.mark.parametrize(
    "argv_tail, fragment",
    [
        (["missing.yaml", "-o", "X.csv"], "no such scenario file"),
        ([str(scenario_path("ident_chirp")), "-o", "X.txt"], "unknown recording format"),
        ([str(scenario_path("ident_chirp")), "-o", "X.csv", "--duration", "-1"], "--duration"),
        ([str(scenario_path("ident_chirp")), "-o", "X.dir/x.csv"], "does not exist"),
        # an IsADirectoryError and a MemoryError traceback, after the simulation / before it
        ([str(scenario_path("ident_chirp")), "-o", "X.made_dir"], "is a directory"),
        ([str(scenario_path("ident_chirp")), "-o", "X.csv", "--duration", "1e12"], "memory"),
    ],
)
def test_cli_record_bad_input_exits_2_with_one_line(tmp_path, capsys, argv_tail, fragment):
    argv_tail = [str(tmp_path / a) if a.startswith("X.") else a for a in argv_tail]
    (tmp_path / "X.made_dir").mkdir()
    assert main(["sim", "record", *argv_tail]) == 2
    err = capsys.readouterr().err.strip()
    assert fragment in err
    assert len(err.splitlines()) == 1


def test_cli_record_bad_scenario_key_exits_2(tmp_path, capsys):
    path = tmp_path / "bad.yaml"
    path.write_text("duration_s: 1\nexcitation: [{kind: zero}]\nspeed: 3\n")
    assert main(["sim", "record", str(path), "-o", str(tmp_path / "x.csv")]) == 2
    assert "'speed'" in capsys.readouterr().err
