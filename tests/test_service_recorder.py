"""The raw-data recorder: contract files, rotation, and at most 1 s lost to a SIGKILL; the
Parquet archive: closed files converted, leftovers of a killed recorder converted at the next
start, pruning across both formats."""

import math
import signal
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from fdi_daemon.io.recordings import read_recording
from fdi_daemon.io.sample import Sample
from fdi_daemon.service.recorder import Recorder

FS = 256.0


def samples(seq0, n, rng):
    return [
        Sample(seq0 + i, (seq0 + i) / FS, float(v), float(a), math.nan)
        for i, (v, a) in enumerate(rng.normal(size=(n, 2)))
    ]


def test_files_follow_the_recording_contract(tmp_path):
    rng = np.random.default_rng(1)
    batch = samples(100, 300, rng)
    rec = Recorder(tmp_path, FS, meta={"link": "modbus-tcp"}, archive_format="csv")
    for i in range(0, 300, 7):
        rec.append(batch[i : i + 7])
    rec.close()
    (path,) = rec.files_written
    back = read_recording(path)  # strict: no gaps
    assert back.fs == FS and back.meta["link"] == "modbus-tcp"
    np.testing.assert_array_equal(back["seq"], np.arange(100, 400))
    np.testing.assert_allclose(back.v_in, [s.v_in for s in batch], rtol=1e-9)
    np.testing.assert_allclose(back.t, [s.t for s in batch], atol=1e-9)
    assert np.all(np.isnan(back["position"]))


def test_rotation_by_duration_and_on_device_restart(tmp_path):
    rng = np.random.default_rng(2)
    rec = Recorder(tmp_path, FS, rotate_seconds=1.0, archive_format="csv")
    rec.append(samples(0, 600, rng))  # 2.34 s -> 3 files
    rec.append(samples(5, 10, rng))  # counter restarted -> a 4th file
    rec.close()
    lengths = [len(read_recording(p)) for p in rec.files_written]
    assert lengths == [256, 256, 88, 10]


def test_gaps_stay_visible_to_replay(tmp_path):
    rng = np.random.default_rng(3)
    rec = Recorder(tmp_path, FS, archive_format="csv")
    rec.append(samples(0, 50, rng))
    rec.append(samples(60, 50, rng))
    rec.close()
    back = read_recording(rec.files_written[0], strict=False)
    (issue,) = back.sampling.issues
    assert issue.kind == "gap" and issue.missing_samples == 10


def test_keep_files_prunes_the_oldest(tmp_path):
    rng = np.random.default_rng(4)
    rec = Recorder(tmp_path, FS, rotate_seconds=0.5, keep_files=2, archive_format="csv")
    rec.append(samples(0, 640, rng))  # 5 files of 128 samples
    rec.close()
    remaining = sorted(tmp_path.glob("rec-*.csv"))
    assert remaining == rec.files_written[-2:]


def test_fsync_period_is_at_most_one_second(tmp_path):
    with pytest.raises(ValueError):
        Recorder(tmp_path, FS, fsync_period_s=1.5)


CHILD = textwrap.dedent("""
    import math, sys, time
    from fdi_daemon.io.sample import Sample
    from fdi_daemon.service.recorder import Recorder
    from fdi_daemon.service.sinks import Worker
    rec = Recorder(sys.argv[1], 256.0, rotate_seconds=float(sys.argv[2]), keep_files=int(sys.argv[3]))
    worker = Worker("recorder", rec.append, maxsize=1000)
    seq = 0
    t0 = time.monotonic()
    while True:  # 256 Hz in batches of 8, like a link read
        batch = [Sample(seq + i, (seq + i) / 256.0, 0.5, -0.25) for i in range(8)]
        worker.put(batch)
        seq += 8
        print(seq - 1, flush=True)
        time.sleep(max(0.0, t0 + seq / 256.0 - time.monotonic()))
""")


def _record_then_kill(folder, seconds: float, rotate_s: float = 3600.0, keep: int = 0) -> int:
    """Run a recorder at 256 Hz in a child process, SIGKILL it after ``seconds`` of samples;
    returns the last sample counter handed to it."""
    proc = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(folder), str(rotate_s), str(keep)],
        stdout=subprocess.PIPE,
        text=True,
    )
    last_handed_over = -1
    try:
        for line in proc.stdout:
            last_handed_over = int(line)
            if last_handed_over >= seconds * 256:
                break
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(30)
    return last_handed_over


@pytest.mark.slow
def test_sigkill_loses_at_most_one_second(tmp_path):
    last_handed_over = _record_then_kill(tmp_path, 3)
    (path,) = sorted(tmp_path.glob("rec-*.csv"))  # the journal, not yet archived
    rec = read_recording(path, strict=False)
    assert rec.sampling.ok
    lost = last_handed_over - int(rec["seq"][-1])
    assert rec["seq"][0] == 0 and lost <= 256, f"lost {lost} samples"
    Recorder(tmp_path, FS).close()  # the next start archives what the killed one left
    assert not list(tmp_path.glob("rec-*.csv"))
    (archived,) = tmp_path.glob("rec-*.parquet")
    back = read_recording(archived)
    np.testing.assert_array_equal(back["seq"], rec["seq"])
    assert back.meta == rec.meta


def test_closed_files_are_archived_as_parquet_with_the_same_samples(tmp_path):
    rng = np.random.default_rng(5)
    batch = samples(0, 600, rng)
    rec = Recorder(tmp_path, FS, rotate_seconds=1.0, meta={"device": "rig-07"})
    rec.append(batch)
    rec.close()
    assert not list(tmp_path.glob("rec-*.csv"))
    archived = sorted(tmp_path.glob("rec-*.parquet"))
    assert [p.with_suffix(".csv") for p in archived] == rec.files_written
    back = [read_recording(p) for p in archived]
    assert [len(b) for b in back] == [256, 256, 88]
    seq = np.concatenate([b["seq"] for b in back])
    np.testing.assert_array_equal(seq, np.arange(600))
    v_in = np.concatenate([b.v_in for b in back])
    np.testing.assert_allclose(v_in, [s.v_in for s in batch], rtol=1e-9)
    assert back[0].meta["device"] == "rig-07" and back[0].meta["fs"] == "256"


def test_a_torn_journal_is_archived_without_its_torn_row_and_reported(tmp_path, caplog):
    rng = np.random.default_rng(6)
    rec = Recorder(tmp_path, FS, archive_format="csv")
    rec.append(samples(0, 100, rng))
    rec.close()
    (path,) = rec.files_written
    path.write_bytes(path.read_bytes() + b"100,0.39")  # a row cut by the kill
    Recorder(tmp_path, FS).close()
    (archived,) = tmp_path.glob("rec-*.parquet")
    assert len(read_recording(archived)) == 100
    assert "torn last line" in caplog.text


def test_an_unreadable_journal_is_kept_and_reported_never_dropped(tmp_path, caplog):
    bad = tmp_path / "rec-20260101T000000.000000Z-seq0.csv"
    bad.write_text("# fs: 256\nseq,t,v_in,accel,position\n0,0,1,2,nan\n1,x,1,2,nan\n3,")
    Recorder(tmp_path, FS).close()
    assert bad.exists() and not list(tmp_path.glob("*.parquet"))
    assert "kept as CSV" in caplog.text and bad.name in caplog.text


def test_keep_files_prunes_across_csv_and_parquet(tmp_path):
    rng = np.random.default_rng(7)
    rec = Recorder(tmp_path, FS, rotate_seconds=0.5, keep_files=2)
    rec.append(samples(0, 640, rng))  # 5 files of 128 samples
    rec.close()
    kept = sorted(p.with_suffix(".csv") for p in tmp_path.glob("rec-*"))
    assert kept == rec.files_written[-2:]


@pytest.mark.slow
def test_soak_short_rotating_pruned_and_killed_loses_nothing_archived(tmp_path):
    """A short soak: 1 s files, keep 4, SIGKILL, restart: the archive holds the last files
    whole, contiguous up to what the killed recorder had written."""
    last = _record_then_kill(tmp_path, 6, rotate_s=1.0, keep=4)
    Recorder(tmp_path, FS, keep_files=4).close()
    files = sorted(tmp_path.glob("rec-*"))
    assert all(p.suffix == ".parquet" for p in files) and 3 <= len(files) <= 4
    seq = np.concatenate([read_recording(p)["seq"] for p in files])
    np.testing.assert_array_equal(seq, np.arange(seq[0], seq[0] + len(seq)))
    assert last - int(seq[-1]) <= 256
