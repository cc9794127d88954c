"""Reliability against bad samples: NaN, inf, saturation, sequence jumps, time going back.

A fault-free simulated recording gets defects at known places. The same events must come
out of the per-tick path (`Monitor.step`, the daemon's), the batch path (`Monitor.run`) and
`fdi replay` (CSV with ``seq``, and npz without it, where sample numbers come from ``t``):
one ``bad_sample`` per run of bad samples with its exact count and reason, one
``data_gap`` per jump with the exact number missing, no exception, no alarm.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from reliability_support import ALARMS, fault_free, load_test_model

from fdi_daemon.cli import main
from fdi_daemon.detect.monitor import Monitor
from fdi_daemon.io.model_file import save_model
from fdi_daemon.io.recordings import Recording, write_recording
from fdi_daemon.io.sample import Sample

FS = 256


def _model(limit: float):
    return load_test_model(detector={"accel_limit_mps2": limit})


def _limit(rec) -> float:
    """Full scale above the signal, a round number (exact in CSV, so saturated samples
    written at full scale still read as saturated)."""
    return float(np.ceil(1.5 * np.max(np.abs(rec.accel))))


def defective(rec):
    """The recording with one of each defect; returns (recording, expected events)."""
    limit = _limit(rec)
    cols = {k: np.array(rec.columns[k], dtype=float) for k in ("t", "v_in", "accel")}
    cols["seq"] = np.array(rec.columns["seq"], dtype=np.int64)
    at = {
        name: int(s * FS)
        for name, s in (
            ("nan", 5),
            ("inf", 8),
            ("vin", 11),
            ("both", 14),
            ("sat", 17),
            ("gap", 20),
            ("back", 23),
            ("dup", 26),
            ("neg_sat", 29),
        )
    }
    cols["accel"][at["nan"] : at["nan"] + 5] = np.nan
    cols["accel"][at["inf"]] = np.inf
    cols["v_in"][at["vin"]] = -np.inf
    cols["v_in"][at["both"]] = np.nan
    cols["accel"][at["both"]] = np.nan
    cols["accel"][at["sat"] : at["sat"] + 3] = limit
    cols["accel"][at["neg_sat"]] = -2 * limit
    order = list(range(len(rec)))
    del order[at["gap"] : at["gap"] + 20]  # 20 samples missing
    b = order.index(at["back"])
    order[b:b] = list(range(at["back"] - 10, at["back"]))  # 10 samples again (seq and t back)
    d = order.index(at["dup"])
    order.insert(d, at["dup"] - 1)  # one duplicate
    cols = {k: v[order] for k, v in cols.items()}
    t = rec.t
    expected = [
        ("bad_sample", t[at["nan"]], 5, "accel not finite"),
        ("bad_sample", t[at["inf"]], 1, "accel not finite"),
        ("bad_sample", t[at["vin"]], 1, "v_in not finite"),
        ("bad_sample", t[at["both"]], 1, "v_in not finite"),
        ("bad_sample", t[at["sat"]], 3, "accel saturated"),
        ("data_gap", t[at["gap"] + 20], 20, None),
        ("bad_sample", t[at["back"] - 10], 10, "backwards"),
        ("bad_sample", t[at["dup"] - 1], 1, "duplicate"),
        ("bad_sample", t[at["neg_sat"]], 1, "accel saturated"),
    ]
    return Recording(cols, {"fs": str(FS)}), expected


def _summary(events):
    out = []
    for e in events:
        if e["kind"] == "bad_sample":
            out.append((e["kind"], e["t"], e["count"], e["reason"]))
        elif e["kind"] == "data_gap":
            out.append((e["kind"], e["t"], e["missing_samples"], None))
    return out


def _stepped(model, rec):
    mon = Monitor(model)
    seq = rec.columns.get("seq")
    events = []
    for k in range(len(rec)):
        s = int(seq[k]) if seq is not None else k
        events.extend(mon.step(Sample(s, float(rec.t[k]), float(rec.v_in[k]), float(rec.accel[k]))))
    return events + mon.finish()


@pytest.fixture(scope="module")
def case():
    rec = fault_free(40.0)
    bad, expected = defective(rec)
    return _model(_limit(rec)), bad, expected


def test_per_tick_path_reports_each_defect_exactly(case):
    model, rec, expected = case
    events = _stepped(model, rec)
    assert _summary(events) == [(k, pytest.approx(t), n, r) for k, t, n, r in expected]
    assert [e for e in events if e["kind"] in ALARMS] == []
    assert [e["kind"] for e in events].count("calibrated") == 1


def test_batch_path_gives_the_same_events(case):
    model, rec, _ = case
    events, _ = Monitor(model).run(rec)
    assert events == _stepped(model, rec)


@pytest.mark.parametrize("fmt", ["csv", "npz-without-seq"])
def test_fdi_replay_gives_the_same_events(tmp_path, case, fmt):
    model, rec, expected = case
    model_file = save_model(tmp_path / "model.yaml", model)
    if fmt == "csv":
        path = write_recording(tmp_path / "bad.csv", rec)
    else:
        cols = {k: v for k, v in rec.columns.items() if k != "seq"}
        path = write_recording(tmp_path / "bad.npz", Recording(cols, dict(rec.meta)))
    code = main(
        [
            "replay",
            str(path),
            "--model",
            str(model_file),
            "--events",
            str(tmp_path / "ev.jsonl"),
            "--summary",
            str(tmp_path / "s.json"),
        ]
    )
    assert code == 0
    events = [json.loads(line) for line in (tmp_path / "ev.jsonl").read_text().splitlines()]
    assert _summary(events) == [(k, pytest.approx(t), n, r) for k, t, n, r in expected]
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["alarm_episodes"] == 0 and summary["classification"] is None
    assert summary["bad_samples"] == sum(n for k, _, n, _ in expected if k == "bad_sample")
    assert summary["missing_samples"] == 20


@settings(
    max_examples=12,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)
@given(
    st.lists(
        st.tuples(
            st.integers(512, 5000),
            st.integers(1, 40),
            st.sampled_from(["nan", "inf", "-inf", "sat", "vnan", "gap", "back"]),
        ),
        min_size=1,
        max_size=8,
    )
)
def test_random_defects_are_all_accounted_for(defects):
    """Random runs of defects: step == batch, every bad sample and every missing sample
    counted, nothing raised, no alarm."""
    rec = fault_free(20.0)
    limit = _limit(rec)
    n = len(rec)
    cols = {k: np.array(rec.columns[k], dtype=float) for k in ("t", "v_in", "accel")}
    cols["seq"] = np.array(rec.columns["seq"], dtype=np.int64)
    drop = np.zeros(n, dtype=bool)
    value_bad = np.zeros(n, dtype=bool)
    back = []
    for start, length, kind in defects:
        sl = slice(start, start + length)
        if kind == "gap":
            drop[sl] = True
        elif kind == "back":
            back.append((start, length))
        elif kind == "vnan":
            cols["v_in"][sl] = np.nan
            value_bad[sl] = True
        else:
            cols["accel"][sl] = {"nan": np.nan, "inf": np.inf, "-inf": -np.inf, "sat": -limit}[kind]
            value_bad[sl] = True
    order = [k for k in range(n) if not drop[k]]
    repeated = 0
    for start, length in back:  # replay `length` earlier samples again before row `start`
        if drop[start] or start - length < 0:
            continue
        i = order.index(start)
        again = [k for k in range(start - length, start) if not drop[k]]
        order[i:i] = again
        repeated += len(again)
    bad_rec = Recording({k: v[order] for k, v in cols.items()}, {"fs": str(FS)})
    model = _model(limit)
    stepped = _stepped(model, bad_rec)
    batch, _ = Monitor(model).run(bad_rec)
    assert batch == stepped
    kept = ~drop
    expected_bad = int(np.count_nonzero(value_bad & kept)) + repeated
    assert sum(e["count"] for e in batch if e["kind"] == "bad_sample") == expected_bad
    # missing samples: the dropped rows, less a dropped run at the very end (no sample
    # after it, so nothing can be reported)
    last_kept = int(np.flatnonzero(kept)[-1])
    assert sum(e["missing_samples"] for e in batch if e["kind"] == "data_gap") == int(
        np.count_nonzero(drop[:last_kept])
    )
    assert [e for e in batch if e["kind"] in ALARMS] == []
    for e in batch:
        assert e["t"] is None or math.isfinite(e["t"])
        json.dumps(e, allow_nan=False)


def test_a_short_accel_glitch_is_not_isolated_as_friction():
    """Glitches of 1 sample to 0.25 s (64 samples) at 2-6 m/s² (the signal's peak is
    4.1 m/s²): an alarm is fine (something is wrong), calling it friction is not."""
    rec = fault_free(40.0)
    model = load_test_model()
    isolated = []
    for width in (1, 2, 3, 5, 10, 20, 32, 64):
        for accel in (2.0, 4.0, 6.0):
            cols = {k: np.array(rec.columns[k]) for k in ("t", "v_in", "accel", "seq")}
            cols["accel"][17 * FS : 17 * FS + width] = accel
            events, _ = Monitor(model).run(Recording(cols, {"fs": str(FS)}))
            if "friction_isolated" in [e["kind"] for e in events]:
                isolated.append((width, accel))
    assert isolated == []
