"""The same diagnosis under two OpenBLAS kernels (issue 42): rig and machine cases run in a
subprocess each with ``OPENBLAS_CORETYPE=Haswell`` and ``=SkylakeX`` (where the CPU has
AVX-512; elsewhere OpenBLAS's own choice), and the names must be the same and the gaps
within 5 %. OpenBLAS reads the variable when it loads, so each kernel needs its own
process (a value set in the environment is kept by `fdi_daemon`)."""

from __future__ import annotations

import functools
import json
import platform
import subprocess
import sys
from pathlib import Path

import pytest

from tests.diagnose_cases import has_avx512, openblas_environment

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(platform.machine() != "x86_64", reason="OpenBLAS's x86-64 kernels"),
]

REPO = Path(__file__).resolve().parents[1]

#: per case: the code that leaves its `run_diagnose` result in ``r``
CASES = {
    "rig 3.4 N under 0.4 V": (
        "u, y = rig_recording(variant=(('seal_coulomb_n', 3.4), ('seal_static_n', 3.4)))\n"
        "b, a = rig_model()\n"
        "r = run_diagnose(u, y, RIG_FS, 'acceleration', b, a)"
    ),
    "duffing under noise": (
        "rec = duffing_recording(1e5, noise_hz=15.0)\n"
        "r = run_diagnose(rec.v_in, rec['position'], FS, 'position')"
    ),
}
_PRELUDE = (
    "import json\n"
    "from fdi_daemon.diagnose.workflow import run_diagnose\n"
    "from tests.diagnose_cases import FS, RIG_FS, duffing_recording, rig_model, rig_recording\n"
)
_SHOW = (
    "print(json.dumps({'named': r.named, 'gap_before': r.gap_before, 'gap_after': r.gap_after}))"
)


def _diagnose_under(case: str, kernel: str | None) -> dict:
    """The case in a fresh process under OpenBLAS kernel ``kernel`` (None: its choice)."""
    env = {**openblas_environment(kernel), "PYTHONPATH": str(REPO)}
    code = _PRELUDE + CASES[case] + "\n" + _SHOW
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True, check=True
    ).stdout
    return json.loads(next(line for line in out.splitlines() if line.startswith("{")))


#: measured on 29 Nov 2026 (AMD EPYC, AVX-512; `git show b57fd1a:docs/diagnose.md` §5.1): the
#: known differences
_AVX512 = has_avx512()
_NAMES_DIFFER = pytest.mark.xfail(
    _AVX512, strict=True, reason="issue 42: under AVX-512 a backlash is named second"
)


@functools.cache
def _both(case: str) -> tuple[dict, dict]:
    """The case under Haswell and under SkylakeX (where the CPU has it, else OpenBLAS's choice)."""
    return _diagnose_under(case, "Haswell"), _diagnose_under(case, "SkylakeX" if _AVX512 else None)


@pytest.mark.parametrize(
    "case",
    ["rig 3.4 N under 0.4 V", pytest.param("duffing under noise", marks=_NAMES_DIFFER)],
)
def test_the_same_names_under_two_blas_kernels(case):
    one, other = _both(case)
    assert one["named"] == other["named"]


@pytest.mark.parametrize(
    "case",
    [
        "rig 3.4 N under 0.4 V",
        pytest.param(
            "duffing under noise", marks=pytest.mark.xfail(_AVX512, reason="names differ")
        ),
    ],
)
def test_gaps_within_5_percent_under_two_blas_kernels(case):
    one, other = _both(case)
    assert other["gap_before"] == pytest.approx(one["gap_before"], rel=0.05)
    assert other["gap_after"] == pytest.approx(one["gap_after"], rel=0.05)
