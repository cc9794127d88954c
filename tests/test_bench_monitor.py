"""`fdi bench` monitor section: structure and sanity of the numbers (no timing assertions)."""

import json

import pytest

from fdi_daemon.bench.monitor import bench_monitor
from fdi_daemon.cli import main


def test_bench_monitor_reports_both_implementations():
    out = bench_monitor(
        step_samples=1_000, batch_samples=20_000, baseline_samples=700, incident_s=60.0
    )
    for section in ("step_us", "baseline_step_us"):
        assert set(out[section]) == {"p50", "p99", "max", "samples"}
        assert 0 < out[section]["p50"] <= out[section]["p99"] <= out[section]["max"]
    assert out["batch_samples"] == 20_000
    assert out["batch_samples_per_s"] > 0 and out["baseline_samples_per_s"] > 0
    assert out["batch_alarm_episodes"] == 0  # the fault-free data take the quiet path
    assert out["step_speedup_p50"] == out["baseline_step_us"]["p50"] / out["step_us"]["p50"]
    assert out["step_cpu_over_reference"] == (
        out["step_cpu_us_p50"] / out["reference_step_cpu_us_p50"]
    )
    shares = out["batch_cpu_share_by_pair"]
    assert len(shares) == 5 and all(x > 0 for x in shares)
    assert abs(out["batch_cpu_share_of_reference"] - sorted(shares)[2]) <= 1e-4
    incident = out["incident_replay"]
    assert incident["quiet"]["samples"] == incident["incident"]["samples"] == 60 * 256
    assert incident["quiet"]["alarm_episodes"] == 0


def test_too_few_step_samples_for_the_warm_up_is_a_clear_error():
    with pytest.raises(ValueError, match="warm-up"):
        bench_monitor(step_samples=100, batch_samples=2_000, baseline_samples=100, incident_s=0.0)


def test_the_incident_recording_holds_an_alarm_and_the_quiet_one_none():
    from fdi_daemon.bench.incident import bench_incident_replay

    out = bench_incident_replay(240.0)
    assert out["quiet"]["alarm_episodes"] == 0
    assert out["incident"]["alarm_episodes"] >= 1


@pytest.mark.slow  # a whole `fdi bench` run
def test_bench_command_writes_json(tmp_path, monkeypatch, capsys):
    import fdi_daemon.bench.fleet as bf
    import fdi_daemon.bench.ident as bi
    import fdi_daemon.bench.monitor as bm
    import fdi_daemon.bench.sim as bs

    fleet = bf.bench_fleet  # the real fleet stage, on fewer and shorter files
    monkeypatch.setattr(
        bf,
        "bench_fleet",
        lambda model, **kw: fleet(model, files=3, span_s=20.0, short_files=3, base_s=5.0),
    )

    small = bench_monitor(
        step_samples=600, batch_samples=5_000, baseline_samples=600, incident_s=0.0
    )
    monkeypatch.setattr(bm, "bench_monitor", lambda **kw: small)
    monkeypatch.setattr(
        bs,
        "bench_sim",
        lambda **kw: {
            "sim_s_per_wall_s": 100.0,
            "hour_wall_s": 36.0,
            "kernel_sim_s_per_wall_s": 120.0,
            "jit": True,
        },
    )
    monkeypatch.setattr(
        bi,
        "bench_ident",
        lambda **kw: {
            "identify_1024_samples_s": 0.5,
            "identify_target_s": 2.0,
            "signature_grid_points": 51,
            "signature_grid_1024_samples_s": 9.0,
            "signature_target_s": 30.0,
        },
    )
    assert main(["bench", "--quick", "--json", str(tmp_path / "b.json")]) == 0
    data = json.loads((tmp_path / "b.json").read_text())
    assert data["monitor"] == small and {"sim", "ident", "machine"} <= set(data)
    # --quick leaves the daemon end to end out unless --e2e, and says so under its key
    assert data["e2e"] == {"skipped": "left out (--quick without --e2e)"}
    assert data["replay"]["span_s"] == 600.0 and "hour_parquet_samples_per_s" in data["replay"]
    f = data["fleet"]
    assert (f["files"], f["span_s"], f["short_files"]) == (3, 20.0, 3)
    assert f["two_over_one"] == pytest.approx(f["one_worker_s"] / f["two_workers_s"])
    assert 0 < f["per_file_overhead_s"] < f["one_worker_s"]
    out = capsys.readouterr().out
    assert "per-tick step p50" in out and "compiled chain without detector" in out
    assert "fdi fleet-replay on a local cluster" in out


def test_a_json_path_that_cannot_be_written_is_refused_before_measuring(
    tmp_path, monkeypatch, capsys
):
    """--json in a missing directory failed after the minutes of measuring."""
    import fdi_daemon.bench.monitor as bm

    def measured(**kw):
        raise AssertionError("measured before the output was checked")

    monkeypatch.setattr(bm, "bench_monitor", measured)
    assert main(["bench", "--quick", "--json", str(tmp_path / "no" / "b.json")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "does not exist" in err


def test_e2e_flags_that_contradict_are_one_line(capsys):
    assert main(["bench", "--quick", "--e2e", "--skip-e2e"]) == 2
    assert main(["bench", "--e2e"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err == [
        "fdi bench: error: --e2e and --skip-e2e contradict each other",
        "fdi bench: error: --e2e is for --quick (the full run includes it unless --skip-e2e)",
    ]


def test_a_short_replay_span_gives_no_rate_within_the_noise():
    from fdi_daemon.bench.replay import MIN_MARGINAL_S, _hour_s, _rate

    assert _rate(1000, MIN_MARGINAL_S / 2, 6.0) is None  # --quick: 10 min scaled to an hour
    assert _rate(1000, 0.5, 6.0) == 2000.0
    assert _rate(1000, 0.1, 1.0) == 10000.0  # an hour is measured as it is
    assert _hour_s(9.0, 2.0, 1000, None, 6.0) is None
    assert _hour_s(9.0, 2.0, 1000, 500.0, 6.0) == 4.0
