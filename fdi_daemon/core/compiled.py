"""The one place that compiles: numba ``njit`` with ``cache=True`` (compiled once per
install, then loaded from numba's cache), and a plain-Python fallback.

``jit`` is used by every per-tick kernel (`core.kernels`, `detect.kernel`). The kernels
work on arrays they are given and never allocate, so they are compiled without numba's
runtime (``nrt``): no reference counts taken on the arrays at every call (about a fifth of
a monitor tick). A kernel that allocates asks for it (``jit(nrt=True)``). With
``NUMBA_DISABLE_JIT=1`` (or without numba) the kernels run as ordinary Python functions,
the same arithmetic in the same order, so results do not depend on the setting.

numba checks only a cached function's own source file, but the kernels call kernels and
read constants of other modules: so a kernel's cache is a folder named after the hash of
the files its module can reach through its imports in the package
(`source_closure.closure_digest`, `_kernel_cache_dir`). A change to one of them compiles
the kernel afresh; a change elsewhere in the package (the diagnose workflow, the CLI)
leaves the monitor's kernels cached.

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

from fdi_daemon.core.source_closure import closure_digest

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
        module_file = getattr(sys.modules.get(f.__module__), "__file__", None)
        cache_dir = (
            _kernel_cache_dir(package, Path(module_file).resolve())
            if package and module_file
            else None
        )
        if cache_dir is None:
            return _compiling_indices_as_given(_njit(**options)(f))
        with _numba_cache_dir(cache_dir):
            dispatcher = _njit(cache=True, **options)(f)
        lock = Path(cache_dir) / "locks" / f"{f.__module__}.{f.__qualname__}.lock"
        return _compiling_indices_as_given(dispatcher, lock)

    return wrap(func) if func is not None else wrap


def _compiling_indices_as_given(dispatcher: Any, lock: Path | None = None) -> Any:
    """``dispatcher``, compiling with every integer index taken as it is
    (`_indices_as_given`). Each of the two numba internals this rests on falls back to plain
    ``njit`` (slower, the same results) when a numba release refuses it: the private
    ``_nrt`` option (`_without_private_nrt`) and the swapped index lowering (a compile that
    fails with it is compiled again with numba's own). With a cached kernel, ``lock`` is its
    file lock among processes (`_compile_lock`)."""
    compile_signature = dispatcher.compile

    @functools.wraps(compile_signature)
    def compile(sig: Any) -> Any:
        from numba.core.compiler_lock import global_compiler_lock

        # numba's lock first, then the file lock: a thread waiting for the file lock holds
        # no other thread's way to it
        with global_compiler_lock, _compile_lock(lock, dispatcher, sig):
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


#: the compile locks this process holds (a kernel compiling itself again takes none)
_held_locks: set[Path] = set()


@contextlib.contextmanager
def _compile_lock(lock: Path | None, dispatcher: Any, sig: Any) -> Iterator[None]:
    """Held while ``dispatcher`` compiles ``sig`` (or loads it from the cache): one process
    at a time per kernel, so processes that start together on a fresh cache (the daemon and
    the device simulator, the instances of fdi@.service after an upgrade, the test workers)
    compile a kernel once: numba looks in the cache only after the lock is taken, and finds
    there what the first one compiled. No lock where ``fcntl`` is missing, the lock file
    cannot be made, or the signature is compiled in this process already."""
    if lock is None or lock in _held_locks or _compiled_here(dispatcher, sig):
        yield
        return
    try:
        import fcntl

        lock.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
    except (ImportError, OSError):
        yield
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        _held_locks.add(lock)
        try:
            yield
        finally:
            _held_locks.discard(lock)
    finally:
        os.close(fd)  # releases the lock


def _compiled_here(dispatcher: Any, sig: Any) -> bool:
    """Whether ``dispatcher`` holds ``sig`` compiled (numba then returns it at once)."""
    try:
        from numba.core import sigutils

        normalize: Any = sigutils.normalize_signature  # untyped in numba
        args, _ = normalize(sig)
        return tuple(args) in dispatcher.overloads
    except Exception:  # another numba's internals: take the lock
        return False


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
def _kernel_cache_dir(package: Path, module_file: Path) -> str | None:
    """The writable folder for the compiled kernels of ``module_file`` (in ``package``),
    named after the package's install and the digest of the module's import closure
    (`source_closure.closure_digest`). When it is new, the install's folders that no
    module of the present sources is named after are removed (earlier sources), and so are
    the cache files numba wrote beside the sources before this scheme
    (``__pycache__/*.nbi``, ``*.nbc``; never read again). None (compiled at every start)
    if no folder is writable."""
    prefix = f"numba-{_digest(str(package).encode())}-"
    name = prefix + closure_digest(module_file, package)
    for root in _cache_roots(package):
        fresh = not (root / name).exists()
        if _writable(root / name):
            if fresh:
                current = {prefix + closure_digest(f, package) for f in package.rglob("*.py")}
                for folder in root.glob(prefix + "*"):
                    if folder.name not in current:
                        shutil.rmtree(folder, ignore_errors=True)
                for old in package.rglob("__pycache__/*.nb[ic]"):
                    old.unlink(missing_ok=True)
            return str(root / name)
    log.warning(
        "no writable folder to cache the compiled kernels of %s: they are compiled at every start",
        module_file,
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
