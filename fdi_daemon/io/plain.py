"""Numpy values to plain Python, for YAML (model files) and JSON (reports, events)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np


def plain_data(value: Any) -> Any:
    """Numpy scalars and arrays (also inside dicts, lists, tuples) as plain Python values."""
    if isinstance(value, dict):
        return {str(k): plain_data(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain_data(v) for v in value]
    if isinstance(value, np.ndarray):
        return plain_data(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    return value


def json_data(value: Any) -> Any:
    """`plain_data`, with NaN and ±inf as None: JSON has no non-finite numbers."""
    value = plain_data(value)
    if isinstance(value, dict):
        return {k: json_data(v) for k, v in value.items()}
    if isinstance(value, list):
        return [json_data(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
