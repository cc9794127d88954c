"""`fdi_daemon.blas_kernel`: one OpenBLAS kernel where the CPU runs it, a user's choice kept."""

import os
import subprocess
import sys

from fdi_daemon import blas_kernel


def test_an_avx2_machine_is_given_the_haswell_kernel():
    env = {}
    assert blas_kernel.pin(env, "x86_64", {"avx2", "fma", "sse2"}) == "Haswell"
    assert env == {"OPENBLAS_CORETYPE": "Haswell"}


def test_a_cpu_without_avx2_or_another_architecture_is_left_to_openblas():
    for machine, flags in (("x86_64", {"sse2", "fma"}), ("aarch64", {"avx2", "fma"})):
        env = {}
        assert blas_kernel.pin(env, machine, flags) is None
        assert env == {}


def test_a_kernel_the_user_chose_is_kept():
    env = {"OPENBLAS_CORETYPE": "SkylakeX"}
    assert blas_kernel.pin(env, "x86_64", {"avx2", "fma"}) == "SkylakeX"
    assert env == {"OPENBLAS_CORETYPE": "SkylakeX"}


def test_importing_fdi_daemon_pins_the_kernel_before_numpy_loads():
    # a fresh interpreter: the package sets the variable before its first NumPy import
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
    code = (
        "import sys, os, fdi_daemon; print('numpy' in sys.modules, "
        "os.environ.get('OPENBLAS_CORETYPE'))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    ).stdout.split()
    expected = blas_kernel.pin({}) or "None"
    assert out == ["False", expected]
