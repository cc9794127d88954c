"""The one place that compiles: numba ``njit`` with ``cache=True`` (compiled once per
install, then loaded from numba's cache), and a plain-Python fallback.

``jit`` is used by every per-tick kernel (`core.kernels`, `detect.kernel`). The kernels
work on arrays they are given and never allocate, so they are compiled without numba's
runtime (``nrt``): no reference counts taken on the arrays at every call (about a fifth of
a monitor tick). A kernel that allocates asks for it (``jit(nrt=True)``). With
``NUMBA_DISABLE_JIT=1`` (or without numba) the kernels run as ordinary Python functions,
the same arithmetic in the same order, so results do not depend on the setting.

numba checks only a cached function's own source file, but the kernels call kernels and
read constants of other modules: so the cache of a package's kernels is a folder named
after the hash of all the package's ``.py`` files (`_package_cache_dir`), and a change to
any of them compiles every kernel afresh.

Every kernel compiles with its integer indices taken as given (`_indices_as_given`): numba
would otherwise test each signed index for a negative value to wrap it around, and the
kernels index their arrays by offsets that are never negative (a test runs them under
numba's bounds checks, where a negative index raises).

`Arena` holds the state of the compiled blocks: one float64 and one int64 array shared by
the blocks of one monitor (each block owns a region and knows its offsets), so one kernel
call per tick passes two arrays, not one per block.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import logging
import os
import shutil
import sys
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, TypeVar, overload

import numpy as np

__all__ = ["jit", "JIT_ENABLED", "Arena"]

JIT_ENABLED = os.environ.get("NUMBA_DISABLE_JIT", "0") in ("", "0")

try:  # pragma: no cover - numba is a dependency; the fallback keeps the arithmetic usable
    from numba import njit as _njit
    from numba.core import config as _config

    _numba_config: Any = _config  # its settings (CACHE_DIR) are set at run time
except ImportError:  # pragma: no cover
    _njit = None  # type: ignore[assignment]  # numba missing: the plain-Python fallback
    JIT_ENABLED = False

log = logging.getLogger("fdi.compiled")


_F = TypeVar("_F", bound=Callable[..., Any])


@overload
def jit(func: _F, *, inline: bool = False, nrt: bool = False) -> _F: ...
@overload
def jit(func: None = None, *, inline: bool = False, nrt: bool = False) -> Callable[[_F], _F]: ...
def jit(func: Any = None, *, inline: bool = False, nrt: bool = False) -> Any:
    """``numba.njit(cache=True, nogil=True)``, cached per version of the package's sources;
    ``inline``: inlined into its callers; ``nrt``: with numba's runtime (needed to allocate
    arrays; see the module docstring)."""

    def wrap(f: Any) -> Any:
        if not JIT_ENABLED or _njit is None:
            return f
        options: dict[str, Any] = {"nogil": True, "_nrt": nrt}
        if inline:
            options["inline"] = "always"
        package = _package_of(f)
        cache_dir = _package_cache_dir(package) if package else None
        if cache_dir is None:
            return _compiling_indices_as_given(_njit(**options)(f))
        with _numba_cache_dir(cache_dir):
            return _compiling_indices_as_given(_njit(cache=True, **options)(f))

    return wrap(func) if func is not None else wrap


def _compiling_indices_as_given(dispatcher: Any) -> Any:
    """``dispatcher``, compiling with every integer index taken as it is
    (`_indices_as_given`). Each of the two numba internals this rests on falls back to plain
    ``njit`` (slower, the same results) when a numba release refuses it: the private
    ``_nrt`` option (`_without_private_nrt`) and the swapped index lowering (a compile that
    fails with it is compiled again with numba's own)."""
    compile_signature = dispatcher.compile

    @functools.wraps(compile_signature)
    def compile(sig: Any) -> Any:
        try:
            with _indices_as_given():
                return _compile_allowing_nrt_refusal(dispatcher, compile_signature, sig)
        except Exception as exc:  # numba wraps the failure in its own error types
            if not _caused_by_index_swap(exc):
                raise
            _warn_fallback("the swapped index lowering (arrayobj.fix_integer_index)", exc)
            return _compile_allowing_nrt_refusal(dispatcher, compile_signature, sig)

    dispatcher.compile = compile
    return dispatcher


class _IndexSwapRefused(Exception):
    """The swapped ``fix_integer_index`` failed inside numba's lowering."""


#: marks `_IndexSwapRefused` in the text of numba's error that wraps it
_INDEX_SWAP_MARK = "fdi index swap refused"


def _caused_by_index_swap(exc: BaseException | None) -> bool:
    """Whether ``exc`` (or an exception it wraps) is `_IndexSwapRefused`."""
    seen = 0
    while exc is not None and seen < 20:
        if isinstance(exc, _IndexSwapRefused) or _INDEX_SWAP_MARK in str(exc):
            return True
        exc, seen = exc.__cause__ or exc.__context__, seen + 1
    return False


def _compile_allowing_nrt_refusal(dispatcher: Any, compile_signature: Any, sig: Any) -> Any:
    """``compile_signature(sig)``; when numba refuses the private ``_nrt`` option (an
    unknown option is a KeyError or TypeError naming it), the option is dropped from the
    dispatcher and the kernel compiled as plain ``njit`` (with numba's runtime)."""
    try:
        return compile_signature(sig)
    except (KeyError, TypeError, ValueError) as exc:
        if "_nrt" not in str(exc) or "_nrt" not in dispatcher.targetoptions:
            raise
        _warn_fallback("the private numba option _nrt", exc)
        dispatcher.targetoptions.pop("_nrt")
        return compile_signature(sig)


@functools.cache
def _warn_fallback(internal: str, exc: BaseException) -> None:
    """One warning per internal and cause: the kernels run slower, with the same results."""
    log.warning(
        "numba %s refused %s (%s): kernels compile as plain njit, slower with the same results",
        _numba_version(),
        internal,
        " ".join(str(exc).split())[:200],
    )


def _numba_version() -> str:
    import numba

    return str(numba.__version__)


def _index_as_given(context: Any, builder: Any, idxty: Any, idx: Any, size: Any) -> Any:
    """numba's ``fix_integer_index`` without its wrap-around of a negative index."""
    from numba.core import types

    return context.cast(builder, idx, idxty, types.intp if idxty.signed else types.uintp)


def _guarded_index_as_given(context: Any, builder: Any, idxty: Any, idx: Any, size: Any) -> Any:
    """`_index_as_given`; any failure (a numba whose lowering calls it differently) is
    `_IndexSwapRefused`, on which the kernel is compiled again with numba's own."""
    try:
        return _index_as_given(context, builder, idxty, idx, size)
    except Exception as exc:  # any failure of an internal API: compile without the swap
        raise _IndexSwapRefused(f"{_INDEX_SWAP_MARK}: {type(exc).__name__}: {exc}") from exc


@contextlib.contextmanager
def _indices_as_given() -> Iterator[None]:
    """While a kernel compiles (its callees and inlined helpers with it), an integer index
    is lowered as it is: numba otherwise tests every signed index for a negative value to
    wrap it around (Python's ``a[-1]``), an unsigned one excepted (numba PR #929; an opt-out
    per function was discussed in numba issue #3205, not built). The kernels index the
    arena by offsets, which are never negative: a test runs them with
    ``NUMBA_BOUNDSCHECK=1``, under which a negative index raises. Measured: the monitor's
    tick 125 → 91 ns, the same results (docs/detector.md §6). The compile holds numba's
    compiler lock, so no other thread compiles with the change."""
    from numba.core.compiler_lock import global_compiler_lock

    try:
        from numba.np import arrayobj
    except ImportError:  # pragma: no cover - another numba layout
        arrayobj = None  # type: ignore[assignment]  # numba without the module
    with global_compiler_lock:
        saved = getattr(arrayobj, "fix_integer_index", None)
        if saved is None:  # a numba without this hook: its own indexing, the same results
            yield
            return
        arrayobj.fix_integer_index = _guarded_index_as_given
        try:
            yield
        finally:
            arrayobj.fix_integer_index = saved


def _package_of(func: Any) -> Path | None:
    """The folder of the top-level package ``func`` is defined in; None outside a package."""
    top = sys.modules.get(func.__module__.partition(".")[0])
    folders = list(getattr(top, "__path__", []))
    return Path(folders[0]).resolve() if folders else None


@functools.cache
def _package_cache_dir(package: Path) -> str | None:
    """The writable folder for the compiled kernels of ``package``, named after its install
    and the hash of its sources. When it is new, the folders of the install's earlier
    sources are removed, and so are the cache files numba wrote beside the sources before
    this scheme (``__pycache__/*.nbi``, ``*.nbc``; never read again). None (compiled at
    every start) if no folder is writable."""
    prefix = f"numba-{_digest(str(package).encode())}-"
    name = prefix + _sources_digest(package)
    for root in _cache_roots(package):
        fresh = not (root / name).exists()
        if _writable(root / name):
            if fresh:
                stale = [p for p in root.glob(prefix + "*") if p.name != name]
                for folder in stale:
                    shutil.rmtree(folder, ignore_errors=True)
                for old in package.rglob("__pycache__/*.nb[ic]"):
                    old.unlink(missing_ok=True)
            return str(root / name)
    log.warning(
        "no writable folder to cache the compiled kernels of %s: they are compiled at every start",
        package,
    )
    return None


def _cache_roots(package: Path) -> Iterator[Path]:
    """Where the cache may go, in order: $NUMBA_CACHE_DIR if set, the package's __pycache__,
    systemd's CacheDirectory, the user's cache folder."""
    if _numba_config.CACHE_DIR:
        yield Path(_numba_config.CACHE_DIR)
    yield package / "__pycache__"
    if os.environ.get("CACHE_DIRECTORY"):
        yield Path(os.environ["CACHE_DIRECTORY"])
    yield Path(os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache")) / "fdi"


def _sources_digest(package: Path) -> str:
    """A hash of the names and contents of every ``.py`` file in ``package``."""
    files = sorted(package.rglob("*.py"))
    return _digest(
        b"".join(
            f.relative_to(package).as_posix().encode()
            + b"\0"
            + hashlib.sha256(f.read_bytes()).digest()
            for f in files
        )
    )


def _digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()[:16]


def _writable(folder: Path) -> bool:
    try:
        folder.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=folder).close()
    except OSError:
        return False
    return True


@contextlib.contextmanager
def _numba_cache_dir(folder: str) -> Iterator[None]:
    """numba's cache folder while a function is decorated (its cache is located then)."""
    saved = _numba_config.CACHE_DIR
    _numba_config.CACHE_DIR = folder
    try:
        yield
    finally:
        _numba_config.CACHE_DIR = saved


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
