"""`fdi identify` and `fdi signature` end to end, in-process and as a subprocess."""

import hashlib
import subprocess
import sys

import numpy as np
import pytest
import yaml
from conftest_ident import plant_recording

from fdi_daemon.cli import main
from fdi_daemon.io.model_file import load_model
from fdi_daemon.io.recordings import Recording, read_recording, write_recording

PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def chirps(tmp_path_factory):
    out = tmp_path_factory.mktemp("ident_cli")
    return (
        plant_recording(out / "est.csv", 1024, seed=1),
        plant_recording(out / "val.csv", 2048, seed=2),
    )


@pytest.fixture(scope="module")
def identified(chirps, tmp_path_factory):
    out = tmp_path_factory.mktemp("ident_model")
    model, plot = out / "model.yaml", out / "bode.png"
    code = main(
        [
            "identify",
            str(chirps[0]),
            "-o",
            str(model),
            "--validate",
            str(chirps[1]),
            "--plot",
            str(plot),
        ]
    )
    assert code == 0
    return model, plot


def test_identify_writes_model_with_provenance(identified, chirps):
    model_path, plot = identified
    model = load_model(model_path)
    assert model.fs == 256.0 and model.plant_b[0] == 0.0 and len(model.plant_a) == 5
    assert np.all(np.abs(np.roots(model.plant_a)) < 1)
    prov = model.provenance["identify"]
    assert prov["source_sha256"] == hashlib.sha256(chirps[0].read_bytes()).hexdigest()
    assert prov["date_utc"].endswith("+00:00")
    assert prov["command"].startswith("fdi identify")
    metrics = prov["metrics"]
    assert metrics["fit_percent"] >= 95.0
    assert "validation" in metrics["fit_percent_on"]
    assert prov["choices"]["lag_samples"] >= 16 and len(prov["choices"]["band_hz"]) == 2
    assert plot.read_bytes()[:8] == PNG


def test_identify_order_option(chirps, tmp_path):
    out = tmp_path / "m2.yaml"
    assert (
        main(
            [
                "identify",
                str(chirps[0]),
                "-o",
                str(out),
                "--order",
                "2",
                "--band",
                "1:15",
                "--method",
                "welch",
            ]
        )
        == 0
    )
    model = load_model(out)
    assert len(model.plant_a) == 3 and len(model.plant_b) == 3
    assert model.provenance["identify"]["choices"]["band_rule"] == "given"


def test_signature_end_to_end_on_the_papers_model(msd_recordings, tmp_path):  # noqa: F811
    """§V model (mass-spring-damper, Coulomb 0.5 N + viscous 1 N·s/m): γ_f = 2 within ±0.3."""
    model = tmp_path / "msd.yaml"
    assert (
        main(
            [
                "identify",
                str(msd_recordings["chirp"]),
                "-o",
                str(model),
                "--validate",
                str(msd_recordings["chirp_val"]),
            ]
        )
        == 0
    )
    assert load_model(model).provenance["identify"]["metrics"]["fit_percent"] >= 90
    out, plot = tmp_path / "msd_sig.yaml", tmp_path / "sig.png"
    assert (
        main(
            [
                "signature",
                str(msd_recordings["amp_steps"]),
                "--model",
                str(model),
                "--fault-window",
                "1.5:6",
                "-o",
                str(out),
                "--plot",
                str(plot),
            ]
        )
        == 0
    )
    result = load_model(out)
    ff = result.fault_filter
    assert abs(ff.gamma_f - msd_recordings["gamma_true"]) <= 0.3
    assert len(ff.b) == 4 and len(ff.f) == 4 and ff.nk == 0
    assert np.all(np.abs(np.roots(ff.f)) < 1)
    np.testing.assert_allclose(result.plant_a, load_model(model).plant_a)
    assert result.velocity["highpass_hz"] == 1.0 and result.velocity["highpass_order"] == 3
    prov = result.provenance
    assert "identify" in prov and prov["signature"]["cost_profile"]["flat"] is False
    assert prov["signature"]["fault_window_s"] == [1.5, 6.0]
    lo, hi = ff.band_hz  # the 8 Hz sine of the fault window, within the Welch resolution
    assert 6.0 <= lo <= 8.0 <= hi <= 10.0
    assert plot.read_bytes()[:8] == PNG


def test_signature_flags_a_single_sine(identified, tmp_path, capsys):
    """A sine-driven fault window on the known plant: γ is not identified, and the warning
    names what to change in this run (step its amplitude, add a reference pass)."""
    model_path, _ = identified
    model = load_model(model_path)
    from conftest_ident import FS, OE_B, OE_F
    from scipy import signal

    from fdi_daemon.core.velocity import VelocityEstimator

    t = np.arange(1536) / FS
    v_in = 1.4 * np.sin(2 * np.pi * 8 * t)
    accel = signal.lfilter(model.plant_b, model.plant_a, v_in)
    velocity = VelocityEstimator(FS).run(accel)
    friction = np.where(t > 2.0, np.sign(velocity) + 1.5 * velocity, 0.0)
    rng = np.random.default_rng(3)
    effect = signal.lfilter(OE_B, OE_F, friction)
    accel = accel + effect + 0.1 * np.std(effect) * rng.standard_normal(len(t))
    rec = tmp_path / "sine.csv"
    write_recording(rec, Recording({"t": t, "v_in": v_in, "accel": accel}, {"fs": "256"}))
    out = tmp_path / "sig.yaml"
    assert (
        main(
            [
                "signature",
                str(rec),
                "--model",
                str(model_path),
                "--fault-window",
                "2.5:6",
                "-o",
                str(out),
                "--gamma-grid",
                "0:10:0.5",
            ]
        )
        == 0
    )
    err = capsys.readouterr().err
    assert "gamma_f is poorly identified" in err or "gamma_f is not identifiable" in err
    assert "step its amplitude" in err and "--reference-window" in err
    assert load_model(out).provenance["signature"]["gamma_f_status"] != "identified"


@pytest.fixture(scope="module")
def exact_model(tmp_path_factory):
    """A model file holding the known plant of conftest_ident exactly."""
    from conftest_ident import FS, plant

    from fdi_daemon.io.model_file import FdiModel, save_model

    b, a = plant()
    return save_model(
        tmp_path_factory.mktemp("exact") / "exact.yaml",
        FdiModel(fs=FS, plant_b=np.asarray(b), plant_a=np.asarray(a)),
    )


def _stepped_fault_recording(model, path, gamma, noise_ratio):
    """Known plant, an amplitude-stepped 3 + 5 Hz input and a friction effect through the
    known G_e of x_f = sign(v) + γ v from 2 s, plus white noise of noise_ratio·std(effect)."""
    from conftest_ident import FS, OE_B, OE_F
    from scipy import signal

    from fdi_daemon.core.velocity import VelocityEstimator

    t = np.arange(int(10 * FS)) / FS
    amplitude = np.repeat([0.6, 1.0, 1.4, 1.8, 0.6, 1.0, 1.4, 1.8, 1.0, 1.0], int(FS))
    v_in = amplitude * (np.sin(2 * np.pi * 3 * t) + 0.5 * np.sin(2 * np.pi * 5 * t))
    accel = signal.lfilter(model.plant_b, model.plant_a, v_in)
    velocity = VelocityEstimator(FS).run(accel)
    friction = np.where(t > 2.0, np.sign(velocity) + gamma * velocity, 0.0)
    effect = signal.lfilter(OE_B, OE_F, friction)
    effect *= 0.1 * np.std(accel) / np.std(effect)  # small: it hardly moves the velocity
    rng = np.random.default_rng(5)
    accel = accel + effect + noise_ratio * np.std(effect) * rng.standard_normal(len(t))
    write_recording(path, Recording({"t": t, "v_in": v_in, "accel": accel}, {"fs": "256"}))
    return path


def test_signature_at_the_grid_edge_is_not_stored_as_a_value(exact_model, tmp_path, capsys):
    """True γ beyond the grid's end: 'not identified (edge)', gamma_f null in the model."""
    model_path = exact_model
    rec = _stepped_fault_recording(load_model(model_path), tmp_path / "edge.csv", 40.0, 0.05)
    out = tmp_path / "sig.yaml"
    assert (
        main(
            [
                "signature",
                str(rec),
                "--model",
                str(model_path),
                "--fault-window",
                "2.5:10",
                "-o",
                str(out),
                "--gamma-grid",
                "0:4:0.5",
            ]
        )
        == 0
    )
    captured = capsys.readouterr()
    assert "not identified (edge)" in captured.out
    result = load_model(out)
    assert result.fault_filter.gamma_f is None
    assert yaml.safe_load(out.read_text())["fault_filter"]["gamma_f"] is None
    sig = result.provenance["signature"]
    assert sig["gamma_f_status"] == "not identified (edge)"
    assert sig["gamma_at_least_cost"] == pytest.approx(4.0, abs=0.5)
    # the sequential monitor runs on it; the band method, which needs γ_f, refuses it
    from fdi_daemon.detect.monitor import Monitor
    from fdi_daemon.errors import ConfigError

    Monitor(result)
    result.detector = {"method": "band"}
    with pytest.raises(ConfigError, match="gamma_f is not identified"):
        Monitor(result)


def test_signature_reports_the_variance_explained_and_warns_when_low(exact_model, tmp_path, capsys):
    model_path = exact_model
    model = load_model(model_path)
    for noise, low in ((0.1, False), (1.5, True)):
        rec = _stepped_fault_recording(model, tmp_path / f"n{noise}.csv", 1.5, noise)
        out = tmp_path / f"sig{noise}.yaml"
        assert (
            main(
                [
                    "signature",
                    str(rec),
                    "--model",
                    str(model_path),
                    "--fault-window",
                    "2.5:10",
                    "-o",
                    str(out),
                    "--gamma-grid",
                    "0:4:0.5",
                ]
            )
            == 0
        )
        captured = capsys.readouterr()
        vaf = load_model(out).provenance["signature"]["fault_filter_vaf_percent_full_band"]
        # the noise sets the share: 1/(1 + noise²) of the variance is the friction's
        assert vaf == pytest.approx(100 / (1 + noise**2), abs=5)
        assert "of the unfiltered fault residual's variance" in captured.out
        assert ("explains only" in captured.err) is low


def test_signature_with_the_model_observer_stores_its_settings(exact_model, tmp_path):
    model_path = exact_model
    rec = _stepped_fault_recording(load_model(model_path), tmp_path / "obs.csv", 1.5, 0.1)
    out = tmp_path / "sig.yaml"
    assert (
        main(
            [
                "signature",
                str(rec),
                "--model",
                str(model_path),
                "--fault-window",
                "2.5:10",
                "-o",
                str(out),
                "--gamma-grid",
                "0:4:0.5",
                "--velocity-method",
                "model_observer",
            ]
        )
        == 0
    )
    velocity = load_model(out).velocity
    assert velocity["method"] == "model_observer" and velocity["leak_hz"] == 0.02


def test_signature_with_a_drift_cut_off_stores_the_growing_fault_path_signature(
    exact_model, tmp_path, capsys
):
    """--drift-highpass-hz: a second G_e and γ on the high-pass velocity at that cut-off, in
    fault_filter.drift; the monitor's own G_e is the one made without the option. A later
    `fdi signature` without it drops the drift signature with the rest of the old one."""
    model_path = exact_model
    rec = _stepped_fault_recording(load_model(model_path), tmp_path / "drift.csv", 1.5, 0.1)
    common = ["signature", str(rec), "--fault-window", "2.5:10", "--gamma-grid", "0:4:0.5"]
    plain, drift = tmp_path / "plain.yaml", tmp_path / "drift.yaml"
    assert main([*common, "--model", str(model_path), "-o", str(plain)]) == 0
    option = ["--drift-highpass-hz", "0.5"]
    assert main([*common, "--model", str(model_path), "-o", str(drift), *option]) == 0
    assert "drift signature   : high-pass 0.5 Hz" in capsys.readouterr().out
    with_drift, without = load_model(drift), load_model(plain)
    np.testing.assert_array_equal(with_drift.fault_filter.b, without.fault_filter.b)
    d = with_drift.fault_filter.drift
    assert d.highpass_hz == 0.5 and 0.0 <= d.gamma <= 4.0
    assert not np.array_equal(d.b, without.fault_filter.b)
    assert with_drift.provenance["signature"]["drift"]["highpass_hz"] == 0.5
    again = tmp_path / "again.yaml"
    assert main([*common, "--model", str(drift), "-o", str(again)]) == 0
    assert load_model(again).fault_filter.drift is None
    # the low cut-off is the high-pass estimator's: refused with another velocity
    observer = [*common, "--model", str(model_path), "-o", str(again), *option]
    capsys.readouterr()
    assert "needs the high-pass velocity" in _bad(
        [*observer, "--velocity-method", "model_observer"], capsys
    )


def _bad(args, capsys):
    code = main(args)
    err = capsys.readouterr().err
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_bad_inputs_exit_2_with_one_line(identified, chirps, tmp_path, capsys):
    model, _ = identified
    rec = str(chirps[0])
    out = str(tmp_path / "o.yaml")
    assert "no such file" in _bad(["identify", str(tmp_path / "nope.csv"), "-o", out], capsys)
    data = read_recording(rec)
    no_accel = tmp_path / "no_accel.csv"
    write_recording(no_accel, Recording({"t": data.t, "v_in": data.v_in}, {"fs": "256"}))
    assert "accel" in _bad(["identify", str(no_accel), "-o", out], capsys)
    huge = tmp_path / "huge.csv"  # an accelerometer in the wrong unit, say: squares overflow
    write_recording(
        huge,
        Recording({"t": data.t, "v_in": data.v_in, "accel": data.accel * 1e300}, {"fs": "256"}),
    )
    for command in (
        ["identify", str(huge), "-o", out],
        ["signature", str(huge), "--model", str(model), "--fault-window", "1:3", "-o", out],
        ["diagnose", str(huge), "--model", str(model)],
    ):
        assert "column accel holds" in _bad(command, capsys)
    assert "--band" in _bad(["identify", rec, "-o", out, "--band", "x:y"], capsys)
    for window in ("abc", "5:3", "1:2:3"):
        assert "--fault-window" in _bad(
            ["signature", rec, "--model", str(model), "--fault-window", window, "-o", out], capsys
        )
    assert "outside" in _bad(
        ["signature", rec, "--model", str(model), "--fault-window", "2:50", "-o", out], capsys
    )
    # a range that starts with a minus sign is a value, not an option
    assert "-5:10 lies outside" in _bad(
        ["signature", rec, "--model", str(model), "--fault-window", "-5:10", "-o", out], capsys
    )
    no_plant = tmp_path / "no_plant.yaml"
    no_plant.write_text(yaml.safe_dump({"fs": 256.0}))
    assert "plant" in _bad(
        ["signature", rec, "--model", str(no_plant), "--fault-window", "1:3", "-o", out], capsys
    )
    assert "no such model" in _bad(
        ["signature", rec, "--model", str(tmp_path / "x.yaml"), "--fault-window", "1:3", "-o", out],
        capsys,
    )
    assert not (tmp_path / "o.yaml").exists()


def test_subprocess_runs_and_bad_input(chirps, tmp_path):
    out = tmp_path / "m.yaml"
    ok = subprocess.run(
        [sys.executable, "-m", "fdi_daemon", "identify", str(chirps[0]), "-o", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert ok.returncode == 0, ok.stderr
    assert "simulation fit" in ok.stdout and out.exists()
    bad = subprocess.run(
        [
            sys.executable,
            "-m",
            "fdi_daemon",
            "signature",
            str(chirps[0]),
            "--model",
            str(out),
            "--fault-window",
            "9:1",
            "-o",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert bad.returncode == 2
    assert bad.stderr.count("\n") == 1 and "Traceback" not in bad.stderr


def test_identify_on_another_rig_with_a_multisine(tmp_path):
    """An independent rig (stiffer §V model, 12 Hz input filter) excited by a log-spaced
    multisine, in .mat and .npz files without fs metadata: the automatic lag window and band
    must still give a model that simulates unseen data."""
    from hil_sim import msd

    params = msd.MsdParams(
        stiffness_n_per_m=3000.0,
        damping_n_s_per_m=30.0,
        input_filter_hz=12.0,
        accel_noise_width=0.05,
    )
    paths = []
    for seed, name in ((1, "est.mat"), (2, "val.npz")):
        rec = msd.simulate_recording(params, msd.multisine(8.0, 256.0, 0.5, 30.0, 0.5, seed), seed)
        path = tmp_path / name
        write_recording(path, Recording({k: rec.columns[k] for k in ("t", "v_in", "accel")}))
        paths.append(path)
    out = tmp_path / "m.yaml"
    assert main(["identify", str(paths[0]), "--validate", str(paths[1]), "-o", str(out)]) == 0
    assert load_model(out).provenance["identify"]["metrics"]["fit_percent"] >= 95.0


def test_out_of_band_residual_input_correlation_gets_a_verdict(chirps, tmp_path, capsys):
    from fdi_daemon.commands.identify import xcorr_verdict

    assert (
        main(
            [
                "identify",
                str(chirps[0]),
                "-o",
                str(tmp_path / "m2.yaml"),
                "--order",
                "2",
                "--validate",
                str(chirps[1]),
            ]
        )
        == 0
    )  # a 2nd-order model of a 4th-order plant
    out = capsys.readouterr().out
    line = out.splitlines().index(next(s for s in out.splitlines() if "xcorr" in s))
    verdict = out.splitlines()[line + 1]
    assert "misses input-driven dynamics" in verdict and "--order 4" in verdict
    assert f"fdi diagnose {chirps[1]} --model {tmp_path / 'm2.yaml'}" in verdict
    assert xcorr_verdict({"max_abs": 0.05, "bound": 0.057}, 4, "r.csv", "m.yaml") == []
    assert len(xcorr_verdict({"max_abs": 0.06, "bound": 0.057}, 4, "r.csv", "m.yaml")) == 1
    mapped = {"t": "time", "v_in": "u", "accel": "y"}  # the user's --columns, kept in the hint
    (hint,) = xcorr_verdict({"max_abs": 0.06, "bound": 0.057}, 4, "r.csv", "m.yaml", mapped)
    assert "`fdi diagnose r.csv --model m.yaml --columns t=time,v_in=u,accel=y`" in hint


def test_outputs_that_would_destroy_an_input_and_out_of_range_options(
    identified, chirps, tmp_path, capsys
):
    """`-o` naming the recording replaced it with the model; a plot's unknown ending was a
    matplotlib traceback after the fit; an unstable plant, a huge γ grid or G_e order were
    a LinAlgError / MemoryError: one line each, before any work, the inputs untouched."""
    model, _ = identified
    rec = str(chirps[0])
    before = {p: p.read_bytes() for p in (chirps[0], chirps[1], model)}
    out = str(tmp_path / "o.yaml")
    assert "is also an input" in _bad(["identify", rec, "-o", rec], capsys)
    assert "is also an input" in _bad(
        ["identify", rec, "-o", out, "--validate", str(chirps[1]), "--plot", str(chirps[1])], capsys
    )
    assert "cannot write a plot as .txt" in _bad(
        ["identify", rec, "-o", out, "--plot", str(tmp_path / "bode.txt")], capsys
    )
    for value in ("nan", "2", "-1"):
        assert "--min-coherence" in _bad(
            ["identify", rec, "-o", out, "--min-coherence", value], capsys
        )
    sig = ["signature", rec, "--model", str(model), "--fault-window", "1:3"]
    assert "is also an input" in _bad([*sig, "-o", rec], capsys)
    assert "is also an input" in _bad([*sig, "-o", out, "--plot", str(model)], capsys)
    assert "name the same file" in _bad([*sig, "-o", out, "--plot", out], capsys)
    assert "more than 2001" in _bad([*sig, "-o", out, "--gamma-grid", "0:1e9:1e-9"], capsys)
    assert "--orders" in _bad([*sig, "-o", out, "--orders", "400:300:0"], capsys)
    assert "--drift-highpass-hz must be > 0" in _bad(
        [*sig, "-o", out, "--drift-highpass-hz", "0"], capsys
    )
    unstable = yaml.safe_load(model.read_text())
    unstable["plant"]["a"] = [1.0, -3.0, 3.0]
    (tmp_path / "unstable.yaml").write_text(yaml.safe_dump(unstable))
    assert "not stable" in _bad(
        [
            "signature",
            rec,
            "--model",
            str(tmp_path / "unstable.yaml"),
            "--fault-window",
            "1:3",
            "-o",
            out,
        ],
        capsys,
    )
    assert {p: p.read_bytes() for p in before} == before
    assert not (tmp_path / "o.yaml").exists()
