"""The Parquet archive's encodings (seq as deltas, t split by bytes, the rest through a
dictionary) are lossless: every value, dtype and the metadata come back bit for bit, for
quantized sensor readings and for values that repeat nothing."""

from __future__ import annotations

import numpy as np
import pytest

from fdi_daemon.io.recordings import Recording, read_recording, write_recording

pq = pytest.importorskip("pyarrow.parquet")


def test_archive_encodings_round_trip_bit_for_bit(tmp_path):
    rng = np.random.default_rng(45)
    n = 200_000  # more distinct values than a dictionary page holds: the plain fallback
    seq = np.arange(n) + 10_000
    seq[5000:] += 7  # a gap: the deltas are not all one
    cols = {
        "seq": seq,
        "t": seq / 256.0,
        "v_in": np.round(rng.normal(size=n) * 3000) * (10 / 32768),  # a 16-bit ADC
        "accel": rng.normal(size=n) * 1e3,  # nothing repeats
        "position": np.where(rng.random(n) < 0.01, np.nan, rng.normal(size=n)),
        "fault_active": (rng.random(n) < 0.5).astype(float),
    }
    rec = Recording(cols, {"fs": "256", "device": "rig 7"})
    path = write_recording(tmp_path / "a.parquet", rec)
    back = read_recording(path, strict=False)
    assert back.meta == rec.meta
    for name, col in cols.items():
        assert back[name].dtype == (np.int64 if name == "seq" else np.float64)
        np.testing.assert_array_equal(back[name], col)
    meta = pq.ParquetFile(path).metadata.row_group(0)
    enc = {meta.column(i).path_in_schema: meta.column(i).encodings for i in range(6)}
    assert "DELTA_BINARY_PACKED" in enc["seq"]
    assert "BYTE_STREAM_SPLIT" in enc["t"]
    assert any("DICTIONARY" in e for e in enc["v_in"])
