"""One sample of the data-acquisition link, as every link and the monitor see it."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class Sample:
    """One 256 Hz tick from the rig.

    seq: the device's sample counter (wraps are unwrapped by the link, so it only grows);
    t: device sample time in s; v_in: valve voltage in V; accel: load acceleration in m/s²;
    position: LVDT position in m (NaN when the link does not carry it).
    """

    seq: int
    t: float
    v_in: float
    accel: float
    position: float = math.nan
