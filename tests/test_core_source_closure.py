"""`core.source_closure`: the files a module reaches through its imports in its package,
on a package written for the test (every import form) and on this package's kernels."""

from pathlib import Path

from fdi_daemon.core.source_closure import closure, closure_digest

FDI = Path(__file__).resolve().parents[1] / "fdi_daemon"


def _tree(root: Path, files: dict[str, str]) -> Path:
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return root / "pkg"


def test_every_import_form_is_followed_and_nothing_else(tmp_path):
    package = _tree(
        tmp_path,
        {
            "pkg/__init__.py": "",
            "pkg/core/__init__.py": "",
            "pkg/core/a.py": "from . import b\nfrom .sub.c import X\nimport numpy\n",
            "pkg/core/b.py": "def f():\n    from pkg.io import d  # a lazy import counts\n",
            "pkg/core/sub/__init__.py": "from ..e import Y\n",
            "pkg/core/sub/c.py": "X = 1\n",
            "pkg/core/e.py": "Y = 2\n",
            "pkg/io/__init__.py": "",
            "pkg/io/d.py": "import pkg.cli.main as m\n",
            "pkg/cli/__init__.py": "",
            "pkg/cli/main.py": "",
            "pkg/unused.py": "import pkg.core.a\n",  # imports a, is not imported
            "pkg/broken.py": "def (:\n",
        },
    )
    got = {p.relative_to(package).as_posix() for p in closure(package / "core/a.py", package)}
    assert got == {
        "__init__.py",
        "core/__init__.py",
        "core/a.py",
        "core/b.py",
        "core/sub/__init__.py",
        "core/sub/c.py",
        "core/e.py",
        "io/__init__.py",
        "io/d.py",
        "cli/__init__.py",
        "cli/main.py",
    }
    assert closure(package / "broken.py", package) == {(package / "broken.py").resolve()}


def test_the_digest_changes_with_a_file_of_the_closure_only(tmp_path):
    package = _tree(
        tmp_path,
        {"pkg/__init__.py": "", "pkg/a.py": "from pkg import b\n", "pkg/b.py": "K = 1\n"},
    )
    (package / "c.py").write_text("Z = 1\n")
    before = closure_digest(package / "a.py", package)
    (package / "c.py").write_text("Z = 2\n")
    assert closure_digest(package / "a.py", package) == before
    (package / "b.py").write_text("K = 2\n")
    assert closure_digest(package / "a.py", package) != before
    # an edit that adds an import is read again in the same process
    (package / "a.py").write_text("from pkg import b, c\n")
    assert package / "c.py" in closure(package / "a.py", package)


def test_the_monitors_kernels_do_not_reach_the_diagnose_workflow():
    reached = {p.relative_to(FDI).as_posix() for p in closure(FDI / "detect/kernel.py", FDI)}
    assert {"core/kernels.py", "core/compiled.py", "detect/episode_kernel.py"} <= reached
    assert not any(name.startswith(("diagnose/", "service/", "cli")) for name in reached)
