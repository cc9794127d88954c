"""One BLAS kernel on every x86-64 machine with AVX2, so that a diagnosis is the same there.

NumPy's and SciPy's OpenBLAS pick their kernels by the CPU they run on (DYNAMIC_ARCH): an
AVX-512 machine sums a dot product in another order than an AVX2 machine. `fdi diagnose`
follows those roundings: its loop fits end in other optima and name other effects
(docs/diagnose.md §9, "The diagnosis and the machine's BLAS kernel"). Where the CPU has
AVX2 and FMA, OpenBLAS is asked for its Haswell kernels (``OPENBLAS_CORETYPE``, which
OpenBLAS reads when it loads: before NumPy is first imported); a value already set is kept.
"""

from __future__ import annotations

import os
import platform

#: the kernel asked for: the one every x86-64 CPU with AVX2 and FMA runs
KERNEL = "Haswell"
#: what that kernel needs of the CPU (/proc/cpuinfo flags)
NEEDS = frozenset({"avx2", "fma"})


def pin(
    environ=os.environ, machine: str | None = None, flags: set[str] | None = None
) -> str | None:
    """Set ``OPENBLAS_CORETYPE`` to `KERNEL` in ``environ`` where the CPU (``machine``,
    ``flags``: this one's by default) runs it and no value is set; returns the value in
    force (None: OpenBLAS chooses)."""
    if "OPENBLAS_CORETYPE" in environ:
        return environ["OPENBLAS_CORETYPE"]
    machine = (machine or platform.machine()).lower()
    if machine not in ("x86_64", "amd64"):
        return None
    if NEEDS <= (cpu_flags() if flags is None else flags):
        environ["OPENBLAS_CORETYPE"] = KERNEL
        return KERNEL
    return None


def cpu_flags() -> set[str]:
    """The CPU's feature flags (Linux /proc/cpuinfo; empty where it cannot be read)."""
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as info:
            for line in info:
                if line.startswith("flags"):
                    return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()
