"""The on-disk fixture cache (tests/disk_cache.py): built once under concurrent callers, rebuilt
when an input changes; a shared diagnosis is named by its arguments' content
(tests/conftest_diagnose.py)."""

import shutil
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from tests.conftest_diagnose import arguments_digest
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


def test_a_call_is_named_by_its_arguments_content():
    def diagnose(u, fs_hz, output_kind="acceleration", plant_b=None):
        pass

    u = np.linspace(0.0, 1.0, 50)
    name = arguments_digest(diagnose, u, 256.0)
    # the same call: the defaults spelled out, by keyword, a copy, a NumPy scalar
    assert name == arguments_digest(diagnose, u.copy(), fs_hz=np.float64(256.0))
    assert name == arguments_digest(diagnose, u, 256.0, "acceleration", None)
    # another: one sample's last bit, the shape, the dtype, another argument
    nudged = u.copy()
    nudged[7] = np.nextafter(nudged[7], 2.0)
    others = [
        arguments_digest(diagnose, nudged, 256.0),
        arguments_digest(diagnose, u[:, None], 256.0),
        arguments_digest(diagnose, u.astype(np.float32), 256.0),
        arguments_digest(diagnose, u, 256.0, "velocity"),
        arguments_digest(diagnose, u, 256.0, plant_b=np.ones(3)),
    ]
    assert len({name, *others}) == 1 + len(others)
