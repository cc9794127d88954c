"""Replay link (recording files, paced or flat out) and the in-process sim link."""

import time

import numpy as np
import pytest

from fdi_daemon.errors import RecordingError
from fdi_daemon.io.links.base import ReconnectingLink, make_link
from fdi_daemon.io.recordings import Recording, write_recording
from hil_sim.devices.realtime import DEFAULT_SCENARIO
from hil_sim.scenarios import scenario_from_dict, simulate


def recording(n=600, fs=256.0, seq=None):
    rng = np.random.default_rng(0)
    cols = {"t": np.arange(n) / fs, "v_in": rng.normal(size=n), "accel": rng.normal(size=n)}
    if seq is not None:
        cols["seq"] = seq
    return Recording(cols, {"fs": str(fs)})


def drain(link, limit_s=10.0):
    out = []
    end = time.monotonic() + limit_s
    while not link.finished and time.monotonic() < end:
        out += link.read(0.05)
    return out


def test_replay_flat_out_delivers_the_file_then_finishes(tmp_path):
    path = write_recording(tmp_path / "r.csv", recording())
    link = make_link({"kind": "replay", "path": str(path), "realtime": False})
    link.open()
    out = drain(link)
    assert [s.seq for s in out] == list(range(600))
    assert [s.accel for s in out] == pytest.approx(recording().accel, rel=1e-9)
    assert link.finished and link.read(0.0) == []


def test_replay_keeps_recorded_gaps_for_the_service_to_see(tmp_path):
    seq = np.concatenate([np.arange(100), np.arange(110, 200)])
    rec = recording(190, seq=seq)
    rec.columns["t"] = seq / 256.0
    path = write_recording(tmp_path / "gap.npz", rec)
    link = make_link({"kind": "replay", "path": str(path), "realtime": False})
    link.open()
    out = drain(link)
    assert [s.seq for s in out] == list(seq)


def test_replay_loops_with_seq_and_time_counting_on(tmp_path):
    path = write_recording(tmp_path / "r.csv", recording(100))
    link = make_link({"kind": "replay", "path": str(path), "realtime": False, "loop": True})
    link.open()
    out = []
    while len(out) < 350:
        out += link.read(0.0)
    assert [s.seq for s in out[:350]] == list(range(350))
    assert out[349].t == pytest.approx(349 / 256.0)
    assert not link.finished


def test_replay_in_real_time_is_paced_by_the_clock(tmp_path):
    path = write_recording(tmp_path / "r.csv", recording(512))
    link = make_link({"kind": "replay", "path": str(path), "speed": 4.0})
    link.open()
    start = time.monotonic()
    out = drain(link)
    elapsed = time.monotonic() - start
    assert [s.seq for s in out] == list(range(512))
    assert elapsed >= 0.45  # 2 s of data at 4x: not delivered all at once


def test_a_bad_replay_file_is_a_user_error(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("t,v_in\n0,1\n")
    with pytest.raises(RecordingError, match="missing column"):
        make_link({"kind": "replay", "path": str(bad)}).open()
    with pytest.raises(RecordingError):
        ReconnectingLink(lambda: make_link({"kind": "replay", "path": str(bad)})).open()


def test_sim_link_flat_out_equals_the_offline_simulation():
    ref = simulate(scenario_from_dict(DEFAULT_SCENARIO), seed=6, duration_s=4.0)
    link = make_link({"kind": "sim", "seed": 6, "realtime": False})
    link.open()
    out = []
    while len(out) < 1000:
        out += link.read(0.0)
    n = len(out)
    assert [s.seq for s in out] == list(range(n))
    np.testing.assert_array_equal([s.accel for s in out], ref.accel[:n])
    link.set_fault("bearing_supply", 0.3)
    link.read(0.0)
    assert link.rt.rig.bearing_supply == 0.3


def test_sim_link_in_real_time():
    link = make_link({"kind": "sim", "seed": 1})
    link.open()
    out = []
    start = time.monotonic()
    while time.monotonic() - start < 0.5:
        out += link.read(0.05)
    seqs = [s.seq for s in out]
    assert seqs == list(range(len(seqs))) and 64 <= len(seqs) <= 256


def test_a_recording_at_another_rate_than_the_monitors_is_refused_on_open(tmp_path):
    """`fdi run` with a replay link ran a 128 Hz file through a 256 Hz model as if it were
    256 Hz (`fdi replay` refuses it): every time and rate came out wrong, silently."""
    slow = write_recording(tmp_path / "slow.csv", recording(fs=128.0))
    config = {"kind": "replay", "path": str(slow), "realtime": False}
    with pytest.raises(RecordingError, match="sampled at 128 Hz but the model is for 256 Hz"):
        make_link(config, fs_hz=256.0).open()
    link = make_link(config, fs_hz=128.0)  # the right rate, or no rate given: as before
    link.open()
    assert len(drain(link)) == 600
    make_link(config).open()
