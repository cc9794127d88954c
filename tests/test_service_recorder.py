"""The raw-data recorder: contract files, rotation, and at most 1 s lost to a SIGKILL."""

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
    rec = Recorder(tmp_path, FS, meta={"link": "modbus-tcp"})
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
    rec = Recorder(tmp_path, FS, rotate_seconds=1.0)
    rec.append(samples(0, 600, rng))  # 2.34 s -> 3 files
    rec.append(samples(5, 10, rng))  # counter restarted -> a 4th file
    rec.close()
    lengths = [len(read_recording(p)) for p in rec.files_written]
    assert lengths == [256, 256, 88, 10]


def test_gaps_stay_visible_to_replay(tmp_path):
    rng = np.random.default_rng(3)
    rec = Recorder(tmp_path, FS)
    rec.append(samples(0, 50, rng))
    rec.append(samples(60, 50, rng))
    rec.close()
    back = read_recording(rec.files_written[0], strict=False)
    (issue,) = back.sampling.issues
    assert issue.kind == "gap" and issue.missing_samples == 10


def test_keep_files_prunes_the_oldest(tmp_path):
    rng = np.random.default_rng(4)
    rec = Recorder(tmp_path, FS, rotate_seconds=0.5, keep_files=2)
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
    rec = Recorder(sys.argv[1], 256.0)
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


@pytest.mark.slow
def test_sigkill_loses_at_most_one_second(tmp_path):
    proc = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(tmp_path)], stdout=subprocess.PIPE, text=True
    )
    last_handed_over = -1
    try:
        for line in proc.stdout:
            last_handed_over = int(line)
            if last_handed_over >= 3 * 256:  # 3 s of samples
                break
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(30)
    (path,) = sorted(tmp_path.glob("rec-*.csv"))
    rec = read_recording(path, strict=False)
    assert rec.sampling.ok
    lost = last_handed_over - int(rec["seq"][-1])
    assert rec["seq"][0] == 0 and lost <= 256, f"lost {lost} samples"
