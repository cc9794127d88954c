"""The two CSV readers (pyarrow's for large files, NumPy's) give the same arrays,
metadata, sampling findings and errors on the same files, malformed ones included."""

from __future__ import annotations

import gzip
import logging

import numpy as np
import pytest

from fdi_daemon.errors import RecordingError
from fdi_daemon.io import recordings
from fdi_daemon.io.recordings import read_recording

pytest.importorskip("pyarrow")

HEAD = "# fs: 256\n# device: rig 7\n"


def _rows(n: int, sep: str = ",", seq: bool = True) -> str:
    rng = np.random.default_rng(45)
    v, a = rng.normal(size=n), rng.normal(size=n) * 1e3
    return "".join(
        (f"{k}{sep}" if seq else "") + f"{k / 256:.9f}{sep}{v[k]:.10g}{sep}{a[k]:.10g}\n"
        for k in range(n)
    )


GOOD = HEAD + "seq,t,v_in,accel\n" + _rows(3000)
CASES = {
    "plain": GOOD,
    "crlf": GOOD.replace("\n", "\r\n"),
    "bom": "\ufeff" + GOOD,
    "semicolon": HEAD + "seq;t;v_in;accel\n" + _rows(500, ";"),
    "quoted_header": HEAD + '"seq","t","v_in","accel"\n' + _rows(500),
    "no_seq_with_gap": HEAD
    + "t,v_in,accel\n"
    + _rows(500, seq=False).replace("0.015625000,", "0.019531250,"),
    "duplicate_seq": GOOD.replace("\n8,", "\n7,", 1),
    "nan_inf": GOOD.replace(
        "\n5,0.019531250,", "\n5,0.019531250,nan,inf\n6,0.0234375,-inf,", 1
    ).replace("\n6,0.023437500,", "\n66,0.023437500,", 1),
    "comment_in_body": GOOD.replace("\n10,", "\n# note: a comment\n10,", 1),
    "blank_lines": GOOD.replace("\n10,", "\n\n10,", 1),
    "torn_last_line": GOOD + "3000,11.71875,0.5",
    "complete_last_line_without_end": GOOD + "3000,11.71875,0.5,1",
    "bad_middle_line": GOOD.replace("\n10,", "\n10,abc,", 1),
    "short_middle_line": GOOD.replace("\n12,", "\n12,0.5\n13,", 1),
    "empty_field": GOOD.replace("\n20,", "\n20,,", 1),
    "spaces": GOOD.replace("\n20,", "\n20, ", 1),
    "seq_not_whole": GOOD.replace("\n20,", "\n20.5,", 1),
    "quoted_value": GOOD.replace("\n20,", '\n"20",', 1),
    "missing_column": HEAD + "seq,t,v_in\n" + "".join(f"{k},{k / 256},0.5\n" for k in range(500)),
    "empty_header_name": HEAD + "seq,t,,accel\n" + _rows(50),
    "header_only": HEAD + "seq,t,v_in,accel\n",
    "carriage_return_only": GOOD.replace("\n", "\r"),
    "form_feed": GOOD.replace("\n30,", "\x0c30,", 1),
}


def _read(path, arrow: bool, monkeypatch):
    monkeypatch.setattr(recordings, "ARROW_CSV_MIN_BYTES", 0 if arrow else 1 << 60)
    try:
        rec = read_recording(path, strict=False)
    except RecordingError as exc:
        return ("error", str(exc))
    return ("ok", rec)


@pytest.mark.parametrize("gz", [False, True], ids=["csv", "csv.gz"])
@pytest.mark.parametrize("case", list(CASES))
def test_both_readers_give_the_same_recording_or_error(tmp_path, monkeypatch, caplog, case, gz):
    text = CASES[case]
    path = tmp_path / ("rec.csv.gz" if gz else "rec.csv")
    data = text.encode("utf-8")
    path.write_bytes(gzip.compress(data, mtime=0) if gz else data)
    with caplog.at_level(logging.WARNING, logger="fdi.recordings"):
        arrow = _read(path, True, monkeypatch)
        warned_arrow = [r.getMessage() for r in caplog.records]
        caplog.clear()
        plain = _read(path, False, monkeypatch)
        warned_plain = [r.getMessage() for r in caplog.records]
    assert warned_arrow == warned_plain
    assert arrow[0] == plain[0], (arrow, plain)
    if arrow[0] == "error":
        assert arrow[1] == plain[1]
        return
    a, p = arrow[1], plain[1]
    assert a.meta == p.meta
    assert list(a.columns) == list(p.columns)
    for name in a.columns:
        assert a[name].dtype == p[name].dtype, name
        np.testing.assert_array_equal(a[name], p[name])
    assert a.sampling == p.sampling


def test_a_plain_large_file_is_read_by_pyarrow(tmp_path, monkeypatch):
    """The counter-check: the pyarrow reader is the one that answered above on plain files."""
    path = tmp_path / "rec.csv"
    path.write_text(GOOD)
    monkeypatch.setattr(recordings, "ARROW_CSV_MIN_BYTES", 0)
    seen = []
    real = recordings._read_csv_arrow
    monkeypatch.setattr(recordings, "_read_csv_arrow", lambda p: seen.append(r := real(p)) or r)
    read_recording(path)
    assert seen and seen[0] is not None
    (tmp_path / "c.csv").write_text(CASES["comment_in_body"])
    read_recording(tmp_path / "c.csv")
    assert seen[1] is None  # a comment in the body: the NumPy reader's
