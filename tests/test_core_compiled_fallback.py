"""Each numba internal the kernels rest on falls back to plain ``njit`` when a numba release
refuses it (`core.compiled`): the private ``_nrt`` option and the swapped
``arrayobj.fix_integer_index``. The refusal is simulated here; the kernel must still compile
and give the same results as the same function run as Python."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from fdi_daemon.core import compiled

pytestmark = pytest.mark.skipif(not compiled.JIT_ENABLED, reason="needs numba's compiler")


def _weighted_tail(values: np.ndarray, weights: np.ndarray, out: np.ndarray) -> None:
    """A kernel indexing by offsets, as the monitor's do (never allocates)."""
    n = values.shape[0]
    acc = 0.0
    for k in range(n):
        acc = 0.5 * acc + values[k] * weights[n - 1 - k]
        out[k] = acc


def _run(kernel) -> np.ndarray:
    rng = np.random.default_rng(45)
    values, weights = rng.normal(size=200), rng.normal(size=200)
    out = np.zeros(200)
    kernel(values, weights, out)
    return out


def _fresh_copy(func):
    """A new function object of the same code: a dispatcher of its own, compiled afresh."""
    import types

    return types.FunctionType(func.__code__, func.__globals__, func.__name__ + "_copy")


def _option_owner(name: str) -> type:
    from numba.core.cpu import CPUTargetOptions

    return next(cls for cls in CPUTargetOptions.__mro__ if name in vars(cls))


def test_a_numba_refusing_the_private_nrt_option_compiles_plain_njit(monkeypatch, caplog):
    monkeypatch.delattr(_option_owner("_nrt"), "_nrt")  # numba: "Unrecognized options"
    kernel = compiled.jit(_fresh_copy(_weighted_tail))
    with caplog.at_level(logging.WARNING, logger="fdi.compiled"):
        result = _run(kernel)
    assert kernel.signatures, "the kernel was not compiled"
    assert "_nrt" not in kernel.targetoptions
    assert "private numba option _nrt" in caplog.text
    np.testing.assert_array_equal(result, _run(_weighted_tail))


def test_a_refused_index_swap_compiles_with_numbas_own_indexing(monkeypatch, caplog):
    def changed_signature(*args):
        raise TypeError("fix_integer_index() takes 4 positional arguments but 5 were given")

    monkeypatch.setattr(compiled, "_index_as_given", changed_signature)
    kernel = compiled.jit(_fresh_copy(_weighted_tail))
    with caplog.at_level(logging.WARNING, logger="fdi.compiled"):
        result = _run(kernel)
    assert kernel.signatures
    assert "fix_integer_index" in caplog.text
    np.testing.assert_array_equal(result, _run(_weighted_tail))


def test_a_numba_without_the_index_hook_compiles_with_its_own(monkeypatch):
    import types

    import numba.np
    from numba.np import arrayobj

    class WithoutHook(types.ModuleType):
        """numba's arrayobj as a release without ``fix_integer_index`` would show it."""

        def __getattr__(self, name: str) -> object:
            if name == "fix_integer_index":
                raise AttributeError(name)
            return getattr(arrayobj, name)

    monkeypatch.setattr(numba.np, "arrayobj", WithoutHook("arrayobj"))
    kernel = compiled.jit(_fresh_copy(_weighted_tail))
    np.testing.assert_array_equal(_run(kernel), _run(_weighted_tail))


def test_with_both_internals_the_swap_is_in_place_while_compiling(monkeypatch):
    """The counter-check: the patched hook is reached when numba accepts it."""
    calls: list[int] = []
    real = compiled._index_as_given

    def counting(*args):
        calls.append(1)
        return real(*args)

    monkeypatch.setattr(compiled, "_index_as_given", counting)
    kernel = compiled.jit(_fresh_copy(_weighted_tail))
    np.testing.assert_array_equal(_run(kernel), _run(_weighted_tail))
    assert calls
