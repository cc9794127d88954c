"""Workloads timed side by side (`fdi bench`): they take blocks of their data in turn, so
that a shared machine's slow spells, which last from milliseconds to seconds, fall on each
of them alike, and the ratio of their times is steady from run to run."""

from __future__ import annotations

import time

import numpy as np

#: samples each workload takes in its turn (eight of `Monitor.run`'s chunks: tens of
#: milliseconds of the monitor)
BLOCK = 8 * 16384


def side_by_side(workloads, samples: int, block: int = BLOCK) -> np.ndarray:
    """Call each of ``workloads`` (callables taking a slice of sample indices) on every
    block of ``samples`` in turn; returns the wall-clock and process-CPU seconds each
    spent, one row (wall s, CPU s) per workload."""
    spent = np.zeros((len(workloads), 2))
    for start in range(0, samples, block):
        part = slice(start, start + block)
        for row, work in zip(spent, workloads):
            t0, c0 = time.perf_counter(), time.process_time()
            work(part)
            row += (time.perf_counter() - t0, time.process_time() - c0)
    return spent
