"""`io.outputs.write_json`: the reports every command writes are strict JSON."""

from __future__ import annotations

import json
import math

import numpy as np

from fdi_daemon.io.outputs import write_json


def _refuse(constant: str):
    raise ValueError(f"not JSON: {constant}")


def test_non_finite_numbers_are_written_as_null_and_numpy_values_as_plain_json(tmp_path):
    report = {
        "score": math.inf,
        "gap": np.float64(math.nan),
        "ranking": [
            {
                "effect": "cubic_stiffness",
                "sse_ratio": -math.inf,
                "params": np.array([1.5, np.nan]),
            },
            {"effect": "coulomb_friction", "n": np.int64(3), "named": np.bool_(True)},
        ],
    }
    path = write_json(tmp_path / "r.json", report)
    back = json.loads(path.read_text(), parse_constant=_refuse)  # jq and browsers refuse NaN
    assert back == {
        "score": None,
        "gap": None,
        "ranking": [
            {"effect": "cubic_stiffness", "sse_ratio": None, "params": [1.5, None]},
            {"effect": "coulomb_friction", "n": 3, "named": True},
        ],
    }
    assert path.read_text().endswith("}\n")
