"""`fdi replay` runs the alarm lifecycle as the daemon does: one alarm per fault, however
often the detector clears and raises again (fdi_daemon/alarms/replay.py)."""

import json
import time

import numpy as np
import pytest
from conftest_detect import sim_rig_model

from fdi_daemon.alarms.lifecycle import AlarmLifecycle, AlarmSettings
from fdi_daemon.alarms.replay import level_readings, merge_events, replay_alarms, status_stride
from fdi_daemon.cli import main
from fdi_daemon.detect.events import read_events
from fdi_daemon.io.model_file import save_model
from fdi_daemon.io.recordings import write_recording

DURATION_S = 300.0  # the creeping fault ramps in over 100 .. 200 s, then stays


def _event(t, kind):
    return {"t": float(t), "kind": kind}


def test_a_chattering_detector_is_one_alarm_and_ties_go_event_first():
    """Five detector episodes over a level that stays at 0.6: one alarm, priority 2 once the
    level has held 0.5 for raise_delay_s; the readings, at 10 Hz, follow each event."""
    events = []
    for k in range(5):
        events += [_event(100 + 60 * k, "fault_detected"), _event(130 + 60 * k, "cleared")]
    times = np.arange(0.0, 500.0, 0.1)
    level = np.where(times >= 100.0, 0.6, 0.0)
    alarms = replay_alarms(events, times, level)
    kinds = [e["kind"] for e in alarms]
    assert kinds == ["alarm_raised", "alarm_priority"]
    assert alarms[0]["t"] == 100.0 and "time" not in alarms[0]
    assert alarms[1]["priority"] == 2 and alarms[1]["t"] > 100.0 + 60.0
    # the same as stepping the lifecycle by hand, event first at a tie
    by_hand = AlarmLifecycle()
    pending = sorted(events, key=lambda e: e["t"])
    expected = []
    for now, value in zip(times, level):
        while pending and pending[0]["t"] <= now:
            e = pending.pop(0)
            expected += by_hand.step(e["t"], None, e)
        expected += by_hand.step(float(now), float(value))
    assert alarms == [{"t": e.pop("time"), **e} for e in expected]
    merged = merge_events(events, alarms)
    assert [e["kind"] for e in merged[:2]] == ["fault_detected", "alarm_raised"]
    assert [e["t"] for e in merged] == sorted(e["t"] for e in merged)


def test_levels_are_above_the_baseline_or_the_level_itself_without_one():
    t, level = level_readings(
        np.array([0.0, 0.1, 0.2]), np.array([0.5, np.nan, 0.4]), np.array([0.2, 0.2, np.nan])
    )
    np.testing.assert_array_equal(t, [0.0, 0.1, 0.2])
    np.testing.assert_allclose(level, [0.3, np.nan, 0.4])
    assert status_stride(256.0) == 26 and status_stride(1000.0) == 100
    assert status_stride(5.0) == 1


@pytest.mark.parametrize("n", [1000, 400_000, 400_001, 1_843_200, 10_400_001, 10**8])
@pytest.mark.parametrize("stride", [1, 26, 100])
def test_the_plots_rows_are_bounded_and_share_the_readings_trace(n, stride):
    """--plot traces every k-th sample (at most TRACE_POINTS rows); k divides the readings'
    stride or is a multiple of it, so one batch trace at gcd(k, stride) holds both and is
    never denser than the plot's or the readings' own."""
    import math

    from fdi_daemon.commands.replay import TRACE_POINTS, _plot_every

    every = _plot_every(n, stride)
    assert -(-n // every) <= TRACE_POINTS
    assert stride % every == 0 or every % stride == 0
    assert math.gcd(every, stride) == min(every, stride)


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    """The simulated rig's model, and a fault-free and a creeping-fault recording of the
    same changing operation (fdi bench's incident pair, shortened)."""
    from fdi_daemon.bench.incident import creeping_fault_scenarios
    from hil_sim.scenarios import simulate

    root = tmp_path_factory.mktemp("replay_alarms")
    model = save_model(root / "model.yaml", sim_rig_model())
    quiet, creeping = creeping_fault_scenarios(DURATION_S, seed=0)
    return (
        root,
        model,
        write_recording(root / "quiet.npz", simulate(quiet)),
        write_recording(root / "creeping.npz", simulate(creeping)),
    )


def _replay(root, model, rec, name, *extra):
    summary, events = root / f"{name}.json", root / f"{name}.jsonl"
    assert (
        main(
            [
                "replay",
                str(rec),
                "--model",
                str(model),
                "--summary",
                str(summary),
                "--events",
                str(events),
                *extra,
            ]
        )
        == 0
    )
    return json.loads(summary.read_text()), read_events(events)


def test_a_creeping_fault_is_one_alarm_raised_during_the_ramp(rig, capsys):
    root, model, _, creeping = rig
    summary, events = _replay(root, model, creeping, "creeping")
    assert summary["alarm_episodes"] == sum(e["kind"] == "fault_detected" for e in events)
    assert summary["alarm_episodes"] == 1  # never cleared (it was 3 before the velocity
    # trust gate: the lifecycle's merging of episodes is tested in test_alarms_lifecycle.py)
    assert summary["alarms"] == 1
    raised = [e for e in events if e["kind"] == "alarm_raised"]
    assert DURATION_S / 3 < raised[0]["t"] < 2 * DURATION_S / 3
    assert summary["alarm_peak_priority"] == max(
        e["priority"] for e in events if e["kind"].startswith("alarm_")
    )
    assert summary["alarm_peak_priority"] >= 1
    assert [e["t"] for e in events] == sorted(e["t"] for e in events)
    assert not any(e["kind"] == "alarm_returned" for e in events)  # the fault stays
    out = capsys.readouterr().out
    assert f"(1 alarm(s), peak priority {summary['alarm_peak_priority']})" in out


def test_a_fault_free_recording_gives_no_alarm(rig):
    root, model, quiet, _ = rig
    summary, events = _replay(root, model, quiet, "quiet")
    assert summary["alarms"] == 0 and summary["alarm_peak_priority"] == 0
    assert summary["alarm_episodes"] == 0
    assert not any(e["kind"].startswith("alarm_") for e in events)


def test_batch_traced_or_not_and_realtime_give_the_same_lifecycle_events(rig, monkeypatch):
    """The batch path traces every 26th sample (the readings), every sample with
    --trace-every 7 (gcd), and the paced path every sample: the same alarm events."""
    root, model, _, creeping = rig
    _, batch = _replay(root, model, creeping, "batch")
    _, traced = _replay(
        root, model, creeping, "traced", "--trace", str(root / "tr.csv"), "--trace-every", "7"
    )
    monkeypatch.setattr(time, "sleep", lambda _s: None)  # pace without waiting
    _, paced = _replay(root, model, creeping, "paced", "--realtime")

    def alarms(events):
        return [e for e in events if e["kind"].startswith("alarm_")]

    assert alarms(batch) and alarms(batch) == alarms(traced)
    for a, b in zip(alarms(batch), alarms(paced), strict=True):
        assert a.keys() == b.keys() and a["kind"] == b["kind"] and a["t"] == b["t"]
        assert a["priority"] == b["priority"] and a["state"] == b["state"]
        for key in ("level", "level_before"):  # alarm_raised: level None, level_before
            if a.get(key) is None:
                assert b.get(key) is None
            else:
                assert a[key] == pytest.approx(b[key], rel=1e-9, abs=1e-12)


def test_alarm_settings_come_from_a_daemon_config(rig, tmp_path):
    """--alarms CONFIG.yaml: the creeping fault's level (about 0.7 of the signature) crosses
    two default steps (0.25, 0.5) and all three of 0.2 / 0.3 / 0.4."""
    root, model, _, creeping = rig
    config = tmp_path / "fdi.yaml"
    head = f"simulated_device: {{}}\nmodel: {{path: {model}}}\n"
    config.write_text(
        head + "alarms:\n  steps: [0.2, 0.3, 0.4]\n  raise_delay_s: 0\n"
        "  deadband: 0.05\n  return_level: 0.1\n"
    )
    summary, _ = _replay(root, model, creeping, "configured", "--alarms", str(config))
    default, _ = _replay(root, model, creeping, "default")
    assert summary["alarms"] == default["alarms"] == 1
    assert (summary["alarm_peak_priority"], default["alarm_peak_priority"]) == (3, 2)
    bad = tmp_path / "bad.yaml"
    bad.write_text(head + "alarms:\n  steps: [0.5, 0.2]\n")
    assert main(["replay", str(creeping), "--model", str(model), "--alarms", str(bad)]) == 2


def test_replay_decides_as_the_daemons_alarm_keeper_against_a_baseline(rig):
    """The daemon's own alarm point (`AlarmKeeper`, clock = sample time) fed as the loop
    does: per-tick Monitor.step, each detector event, and a status snapshot (friction level,
    baseline level of the operating condition) every status period. `fdi replay` with a
    model that has a baseline gives the same lifecycle events."""
    from fdi_daemon.alarms.lifecycle import DETECTOR_INPUTS
    from fdi_daemon.detect.monitor import Monitor
    from fdi_daemon.io.model_file import load_model
    from fdi_daemon.io.recordings import read_recording
    from fdi_daemon.io.sample import Sample
    from fdi_daemon.service.alarm_keeper import AlarmKeeper

    root, model, quiet, creeping = rig
    based = root / "model_baseline.yaml"
    assert main(["baseline", str(quiet), "--model", str(model), "-o", str(based)]) == 0
    _, replayed = _replay(root, based, creeping, "based")

    rec = read_recording(creeping)
    monitor = Monitor(load_model(based))
    assert monitor.baseline is not None
    clock = [0.0]
    keeper = AlarmKeeper(AlarmSettings(), "model", clock=lambda: clock[0])
    stride = status_stride(monitor.fs_hz)
    daemon, baselines = [], set()
    for k in range(len(rec)):
        clock[0] = float(rec.t[k])
        for event in monitor.step(
            Sample(
                k,
                float(rec.t[k]),
                float(rec.columns["v_in"][k]),
                float(rec.columns["accel"][k]),
                float("nan"),
            )
        ):
            if event["kind"] in DETECTOR_INPUTS:
                daemon += keeper.detector_event(event)
        if k % stride == 0:
            snapshot = {"t": clock[0], "monitor": monitor.snapshot()}
            baselines.add(snapshot["monitor"]["baseline_level"])
            daemon += keeper.status(snapshot)[0]
    assert len(baselines) > 1  # the baseline's bin followed the operating condition
    replayed = [e for e in replayed if e["kind"].startswith("alarm_")]
    assert [e["kind"] for e in replayed] == [e["kind"] for e in daemon]
    assert [e["kind"] for e in daemon][:1] == ["alarm_raised"]
    for a, b in zip(replayed, daemon):
        assert (a["t"], a["priority"]) == (b["t"], b["priority"]) and "time" not in a
        assert b["time"] == b["t"]  # the keeper's clock was the sample time
        for key in ("level", "level_before"):  # alarm_raised: level None, level_before
            if a.get(key) is None:
                assert b.get(key) is None
            else:
                assert a[key] == pytest.approx(b[key], rel=1e-9, abs=1e-12)


def test_a_duplicated_sample_leaves_the_trace_and_the_alarms_alike(rig, monkeypatch):
    """A sample sent twice is dropped; the batch trace kept no row for the rest of its
    16384-sample chunk, which moved every later reading: the trace has one row per accepted
    sample, thinned alike, and batch and paced replays give the same alarm events."""
    from fdi_daemon.detect.monitor import Monitor
    from fdi_daemon.io.model_file import load_model
    from fdi_daemon.io.recordings import Recording, read_recording

    root, model, _, creeping = rig
    rec = read_recording(creeping)
    cols = {k: np.asarray(v) for k, v in rec.columns.items()}
    cols.setdefault("seq", np.arange(len(rec)))
    again = 150 * 256  # before the first detection (about 160 s)
    rows = np.concatenate([np.arange(again), [again - 1], np.arange(again, len(rec))])
    dup = write_recording(
        root / "dup.npz", Recording({k: v[rows] for k, v in cols.items()}, dict(rec.meta))
    )
    full = Monitor(load_model(model)).run(read_recording(dup, strict=False), trace_every=1)[1]
    thinned = Monitor(load_model(model)).run(read_recording(dup, strict=False), trace_every=26)[1]
    assert full.t.size == len(rec)
    np.testing.assert_array_equal(thinned.t, full.t[::26])
    np.testing.assert_array_equal(thinned.theta1, full.theta1[::26])
    _, batch = _replay(root, model, dup, "dup_batch")
    monkeypatch.setattr(time, "sleep", lambda _s: None)
    _, paced = _replay(root, model, dup, "dup_paced", "--realtime")
    batch, paced = (
        [e for e in events if e["kind"].startswith("alarm_")] for events in (batch, paced)
    )
    assert batch and [(e["kind"], e["t"]) for e in batch] == [(e["kind"], e["t"]) for e in paced]
    nan = float("nan")  # alarm_raised's level: None (not measured yet)
    assert [nan if e["level"] is None else e["level"] for e in batch] == pytest.approx(
        [nan if e["level"] is None else e["level"] for e in paced], rel=1e-9, nan_ok=True
    )
