"""The source files a module can reach through its imports inside its package, and their
digest: what a compiled kernel may depend on (`core.compiled` names a kernel's cache after
it, so that a change elsewhere in the package does not compile the kernel again).

A compiled kernel reaches other code only through its module's globals: the kernels it
calls and the constants it reads are imported, at the top of a module or inside a
function. So every line that starts an ``import`` or ``from ... import`` statement counts,
wherever it is (`_IMPORT`: read as text, the code is not run; a docstring line that reads
like one counts too, which can only add files), with the packages above each module
imported (their ``__init__`` runs first), and the closure is taken transitively. Imports of
other packages are left out: a new numba, NumPy or Python has its own cache key in numba.
The scan takes about 1 ms per file (`ast` took 5: it ran at every start of a process).
"""

from __future__ import annotations

import functools
import hashlib
import re
from pathlib import Path

__all__ = ["closure", "closure_digest"]


def closure(module_file: Path, package: Path) -> frozenset[Path]:
    """``module_file`` and every file of ``package`` that it imports, directly or not."""
    root = package.resolve()
    seen: set[Path] = set()
    todo = [module_file.resolve()]
    while todo:
        path = todo.pop()
        if path not in seen:
            seen.add(path)
            todo.extend(_imported_files(path, root, _stamp(path)))
    return frozenset(seen)


def closure_digest(module_file: Path, package: Path) -> str:
    """A hash of the names (relative to ``package``) and contents of `closure`'s files."""
    root = package.resolve()
    h = hashlib.sha256()
    for path in sorted(closure(module_file, root)):
        h.update(path.relative_to(root).as_posix().encode() + b"\0")
        h.update(_content_digest(path, _stamp(path)))
    return h.hexdigest()[:16]


@functools.cache
def _content_digest(path: Path, stamp: tuple[int, int]) -> bytes:
    """sha256 of a file's bytes, read once per version of the file (``stamp``): the
    closures of a package's kernel modules share most of their files."""
    return hashlib.sha256(path.read_bytes()).digest()


def _stamp(path: Path) -> tuple[int, int]:
    """(modification time in ns, size): a file edited since it was read is read again."""
    try:
        stat = path.stat()
    except OSError:
        return (0, 0)
    return (stat.st_mtime_ns, stat.st_size)


#: a line that starts an import statement: ``from MODULE import NAMES`` (NAMES in
#: parentheses may span lines) or ``import MODULES``
_IMPORT = re.compile(
    r"^[ \t]*(?:from[ \t]+(\.*[\w.]*)[ \t]+import[ \t]+(\([^)]*\)|[^\n#;]*)"
    r"|import[ \t]+([^\n#;]*))",
    re.MULTILINE,
)


def _listed(names: str) -> list[str]:
    """The names of an import list (``a as b, c``: a, c)."""
    return [n.split()[0] for n in names.strip("() \t\n").replace("\n", " ").split(",") if n.split()]


@functools.cache
def _imported_files(path: Path, package: Path, stamp: tuple[int, int]) -> frozenset[Path]:
    """The files of ``package`` that ``path``'s import statements name (one scan per
    version of a file, ``stamp``)."""
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return frozenset()
    parts = list(path.relative_to(package.parent).with_suffix("").parts)
    here = parts[:-1]  # the package that holds the module (a package's own __init__ too)
    names: list[str] = []
    for source, listed, modules in _IMPORT.findall(text):
        if modules:
            names += _listed(modules)
            continue
        level = len(source) - len(source.lstrip("."))
        above = here[: len(here) - level + 1] if level else []
        base = ".".join(above + ([source[level:]] if source[level:] else []))
        names += [base] + [f"{base}.{name}" for name in _listed(listed)]
    found: set[Path] = set()
    for name in names:
        bits = name.split(".")
        if bits[0] != package.name:
            continue
        for k in range(1, len(bits) + 1):  # the module and each package above it
            module = _module_file(package.parent, tuple(bits[:k]))
            if module is not None:
                found.add(module)
    return frozenset(found)


@functools.cache
def _module_file(root: Path, dotted: tuple[str, ...]) -> Path | None:
    """The file of module ``dotted`` under ``root`` (a module or a package), if there is one."""
    base = root.joinpath(*dotted)
    for candidate in (base.with_suffix(".py"), base / "__init__.py"):
        if candidate.is_file():
            return candidate.resolve()
    return None
