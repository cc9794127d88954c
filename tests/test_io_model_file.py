"""The model file contract: round trip and validation that names the key."""

import numpy as np
import pytest

from fdi_daemon.errors import ConfigError
from fdi_daemon.io.model_file import DriftFilter, FaultFilter, FdiModel, load_model, save_model


def sample_model():
    return FdiModel(
        fs=256.0,
        plant_b=np.array([0.0, 0.01, -0.02, 0.015, -0.004]),
        plant_a=np.array([1.0, -2.9, 3.2, -1.6, 0.31]),
        fault_filter=FaultFilter(
            b=np.array([0.1, -0.2, 0.05, 0.02, 0.0]),
            f=np.array([1.0, -1.2, 0.5, -0.1]),
            nk=0,
            gamma_f=2.4,
            band_hz=(5.25, 12.5),
            drift=DriftFilter(
                b=np.array([0.2, -0.1]), f=np.array([1.0, -0.5]), nk=1, gamma=3.1, highpass_hz=0.5
            ),
        ),
        velocity={"highpass_hz": 1.0, "highpass_order": 3},
        provenance={"source_sha256": "ab" * 32, "fit_percent": np.float64(93.5)},
        extra={"effects": [{"name": "coulomb_friction", "params": {"level": 0.3}}]},
    )


def test_round_trip_keeps_every_key(tmp_path):
    model = sample_model()
    back = load_model(save_model(tmp_path / "m.yaml", model))
    np.testing.assert_array_equal(back.plant_b, model.plant_b)
    np.testing.assert_array_equal(back.plant_a, model.plant_a)
    np.testing.assert_array_equal(back.fault_filter.b, model.fault_filter.b)
    assert back.fault_filter.gamma_f == 2.4
    assert back.fault_filter.band_hz == (5.25, 12.5)
    drift = back.fault_filter.drift
    np.testing.assert_array_equal(drift.b, [0.2, -0.1])
    np.testing.assert_array_equal(drift.f, [1.0, -0.5])
    assert (drift.nk, drift.gamma, drift.highpass_hz) == (1, 3.1, 0.5)
    assert back.velocity == model.velocity
    assert back.provenance["fit_percent"] == 93.5
    assert back.extra["effects"][0]["name"] == "coulomb_friction"


@pytest.mark.parametrize(
    "text, message",
    [
        ("fs: 256\n", r"m.yaml: missing required key plant$"),
        ("plant: {b: [0, 1], a: [1]}\n", r"m.yaml: missing required key fs$"),
        ("fs: 256\nplant: {b: [0, 1]}\n", r"plant: missing required key a$"),
        ("fs: 256\nplant: 3\n", r"plant must be a mapping"),
        ("fs: -1\nplant: {b: [0, 1], a: [1, 0.5]}\n", r"fs must be a positive number"),
        ("fs: 256\nplant: {b: [0, 1], a: [2, 0.5]}\n", r"plant.a must start with 1"),
        ("fs: 256\nplant: {b: [], a: [1]}\n", r"plant.b must be a non-empty list"),
        ("fs: 256\nplant: {b: [0, x], a: [1]}\n", r"plant.b must be a non-empty list"),
        (
            "fs: 256\nplant: {b: [0, 1], a: [1]}\nfault_filter: {b: [1], f: [1], nk: -1}\n",
            r"fault_filter.nk must be a whole number",
        ),
        (
            "fs: 256\nplant: {b: [0, 1], a: [1]}\nfault_filter: {b: [1], f: [1], gamma_f: .nan}\n",
            r"gamma_f must be a finite number",
        ),
        (
            "fs: 256\nplant: {b: [0, 1], a: [1]}\nfault_filter: {b: [1], f: [1], band_hz: [6]}\n",
            r"fault_filter.band_hz must be \[lo, hi\] in Hz",
        ),
        (
            "fs: 256\nplant: {b: [0, 1], a: [1]}\n"
            "fault_filter: {b: [1], f: [1], band_hz: [12, 6]}\n",
            r"fault_filter.band_hz must be \[lo, hi\] in Hz with 0 < lo <= hi",
        ),
        (
            "fs: 256\nplant: {b: [0, 1], a: [1]}\n"
            "fault_filter: {b: [1], f: [1], drift: {b: [1], f: [1], gamma: 3}}\n",
            r"fault_filter.drift: missing required key highpass_hz",
        ),
        (
            "fs: 256\nplant: {b: [0, 1], a: [1]}\n"
            "fault_filter: {b: [1], f: [1], drift: {b: [1], f: [1], gamma: 3, highpass_hz: 0}}\n",
            r"fault_filter.drift.highpass_hz must be a positive number of Hz",
        ),
        (
            "fs: 256\nplant: {b: [0, 1], a: [1]}\n"
            "fault_filter: {b: [1], f: [1], drift: {b: [1], f: [2], gamma: 3, highpass_hz: 1}}\n",
            r"fault_filter.drift.f must start with 1",
        ),
        (
            "fs: 256\nplant: {b: [0, 1], a: [1]}\nfault_filter: {b: [1], f: [1], drift: 3}\n",
            r"fault_filter: drift must be a mapping",
        ),
        ("fs: 256\nplant: {b: [0, 1], a: [1]}\nvelocity: 3\n", r"velocity must be a mapping"),
        ("- just a list\n", r"must be a mapping"),
        ("fs: [unclosed\n", r"not valid YAML at line"),
    ],
)
def test_invalid_models_name_the_key(tmp_path, text, message):
    path = tmp_path / "m.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message):
        load_model(path)


@pytest.mark.parametrize("field", ["band_hz", "drift"])
def test_a_model_without_an_optional_fault_filter_field_has_none(tmp_path, field):
    """Models made before `fdi signature` recorded the calibration band, or made without
    ``--drift-highpass-hz``, load and save as before."""
    model = sample_model()
    setattr(model.fault_filter, field, None)
    path = save_model(tmp_path / "m.yaml", model)
    assert field not in path.read_text()
    assert getattr(load_model(path).fault_filter, field) is None


def test_missing_model_file(tmp_path):
    with pytest.raises(ConfigError, match="no such model file"):
        load_model(tmp_path / "absent.yaml")


GOOD = "fs: 256\nplant: {b: [0, 1], a: [1, 0.5]}\n"


@pytest.mark.parametrize(
    "text, message",
    [
        # a typo anywhere in the file is refused with the suggestion, never taken silently
        (
            GOOD + "fault_filter: {b: [1], f: [1], gama_f: 2.9}\n",
            r"m.yaml: fault_filter: unknown key 'gama_f' \(did you mean 'gamma_f'\?\)",
        ),
        (
            GOOD + "detectr: {threshold: 40}\n",
            r"m.yaml: unknown key 'detectr' \(did you mean 'detector'\?\)",
        ),
        (
            "fs: 256\nplnat: {b: [0, 1], a: [1, 0.5]}\n",
            r"m.yaml: unknown key 'plnat' \(did you mean 'plant'\?\)",
        ),
        (GOOD + "provenanse: {}\n", r"did you mean 'provenance'"),
        (GOOD + "efects: []\n", r"did you mean 'effects'"),
        (GOOD + "baselin: {}\n", r"did you mean 'baseline'"),
        ("fs: 256\nplant: {b: [0, 1], aa: [1, 0.5]}\n", r"plant: missing required key a$"),
        (
            "fs: 256\nplant: {b: [0, 1], a: [1]}\nfault_filter: {b: [1], nk: 0}\n",
            r"fault_filter: missing required key f$",
        ),
    ],
)
def test_typos_in_a_model_file_are_refused_with_a_suggestion(tmp_path, text, message):
    path = tmp_path / "m.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message):
        load_model(path)


def test_unknown_keys_of_other_tools_are_kept_with_a_warning(tmp_path, caplog):
    path = tmp_path / "m.yaml"
    path.write_text(GOOD + "our_lab_notes: {operator: kim}\nbaseline: {theta: [0.1, 0.2]}\n")
    with caplog.at_level("WARNING", logger="fdi.model"):
        model = load_model(path)
    assert model.extra == {"our_lab_notes": {"operator": "kim"}, "baseline": {"theta": [0.1, 0.2]}}
    assert [r.getMessage() for r in caplog.records] == [
        f"{path}: keeping key 'our_lab_notes', which this version does not know"
    ]
    back = load_model(save_model(tmp_path / "again.yaml", model))
    assert back.extra == model.extra


def test_a_failed_write_keeps_the_model_there_before(tmp_path, monkeypatch):
    """`fdi signature -o M --model M` rewrites the model it read: a write that fails half-way
    (disk full, Ctrl-C) must leave M as it was, not truncated."""
    import yaml

    path = save_model(tmp_path / "m.yaml", sample_model())
    before = path.read_bytes()

    def full_disk(data, fh, **kwargs):
        fh.write("fs: 2")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(yaml, "safe_dump", full_disk)
    with pytest.raises(ConfigError, match="No space left"):
        save_model(path, sample_model())
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["m.yaml"]


def test_a_rewritten_model_keeps_its_permissions(tmp_path):
    """The model is written to a new file and renamed over the old one: the old one's mode
    (a model kept readable to its group only) stays."""
    path = save_model(tmp_path / "m.yaml", sample_model())
    path.chmod(0o640)
    save_model(path, sample_model())
    assert path.stat().st_mode & 0o777 == 0o640
