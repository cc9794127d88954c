"""The on-disk fixture cache (tests/disk_cache.py): built once under concurrent callers, rebuilt
when an input changes."""

import shutil
from concurrent.futures import ThreadPoolExecutor

from tests.disk_cache import cached_build


def test_concurrent_callers_build_once_and_a_changed_input_builds_anew(pytestconfig, tmp_path):
    source = tmp_path / "input.txt"
    source.write_text("one")
    built = []

    def build(out):
        built.append(out)
        (out / "copy.txt").write_text(source.read_text())

    name = f"selftest-{tmp_path.name}"
    with ThreadPoolExecutor(4) as pool:
        folders = set(
            pool.map(lambda _: cached_build(pytestconfig, name, [source], build), range(4))
        )
    assert len(built) == 1 and len(folders) == 1
    (first,) = folders
    assert (first / "copy.txt").read_text() == "one"

    source.write_text("two")
    second = cached_build(pytestconfig, name, [source], build)
    assert len(built) == 2 and second != first and not first.exists()
    assert (second / "copy.txt").read_text() == "two"
    shutil.rmtree(second)  # leave no self-test in the cache
    for lock in second.parent.glob(f"{name}-*.lock"):
        lock.unlink()
