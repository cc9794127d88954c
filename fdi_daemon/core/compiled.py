"""The one place that compiles: numba ``njit`` with ``cache=True`` (compiled once per
install, then loaded from ``__pycache__``), and a plain-Python fallback.

``jit`` is used by every per-tick kernel (`core.kernels`, `detect.kernel`). The kernels
work on arrays they are given and never allocate, so they are compiled without numba's
runtime (``nrt``): no reference counts taken on the arrays at every call (about a fifth of
a monitor tick). A kernel that allocates asks for it (``jit(nrt=True)``). With
``NUMBA_DISABLE_JIT=1`` (or without numba) the kernels run as ordinary Python functions,
the same arithmetic in the same order, so results do not depend on the setting.

`Arena` holds the state of the compiled blocks: one float64 and one int64 array shared by
the blocks of one monitor (each block owns a region and knows its offsets), so one kernel
call per tick passes two arrays, not one per block.
"""

from __future__ import annotations

import os

import numpy as np

__all__ = ["jit", "JIT_ENABLED", "Arena"]

JIT_ENABLED = os.environ.get("NUMBA_DISABLE_JIT", "0") in ("", "0")

try:  # pragma: no cover - numba is a dependency; the fallback keeps the arithmetic usable
    from numba import njit as _njit
except ImportError:  # pragma: no cover
    _njit = None
    JIT_ENABLED = False


def jit(func=None, *, inline: bool = False, nrt: bool = False):
    """``numba.njit(cache=True, nogil=True)``; ``inline``: inlined into its callers;
    ``nrt``: with numba's runtime (needed to allocate arrays; see the module docstring)."""
    def wrap(f):
        if not JIT_ENABLED or _njit is None:
            return f
        options = {"cache": True, "nogil": True, "_nrt": nrt}
        if inline:
            options["inline"] = "always"
        return _njit(**options)(f)
    return wrap(func) if func is not None else wrap


class Arena:
    """Growable float64/int64 state arrays; ``alloc`` returns a block's offsets.

    Blocks allocate while they are built (the arrays are then re-created, so hold offsets,
    never views, until the owner has finished building)."""

    __slots__ = ("f", "i")

    def __init__(self) -> None:
        self.f = np.zeros(0)
        self.i = np.zeros(0, dtype=np.int64)

    def alloc(self, n_float: int, n_int: int) -> tuple[int, int]:
        fo, io = self.f.size, self.i.size
        self.f = np.concatenate([self.f, np.zeros(int(n_float))])
        self.i = np.concatenate([self.i, np.zeros(int(n_int), dtype=np.int64)])
        return fo, io
