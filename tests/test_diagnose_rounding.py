"""The diagnosis is a property of the record, not of rounding (issue 42, property 3): Ĝ's
coefficients times (1 + 1e-12·n) must leave the names as they are and the held-out gap within
5 % (`studies/diagnose_plant_rounding.py`, docs/diagnose.md §9). Unlike the kernel test, this
needs no second machine or process."""

from __future__ import annotations

import pytest

from fdi_daemon.diagnose.workflow import run_diagnose
from studies.diagnose_plant_rounding import perturbed
from tests.diagnose_cases import RIG_FS, rig_model, rig_recording

pytestmark = pytest.mark.slow

#: draw 0 is Ĝ as shipped, the others perturbed
DRAWS = 3


@pytest.mark.xfail(
    strict=True,
    raises=AssertionError,
    reason="issue 42: measured 2026-11-29 (Haswell) on the seal's 3 N / 3.5 N friction: 8 "
    "outcomes in 8 draws, gaps after 0.259-0.381, a dead_zone or a cubic_stiffness beside the "
    "friction in 3; the loop fits end at one of several nearby optima, picked by rounding",
)
def test_rounding_in_the_plant_leaves_the_diagnosis_as_it_is():
    u, y = rig_recording(
        rms_v=0.8, duration_s=40.0, variant=(("seal_coulomb_n", 3.0), ("seal_static_n", 3.5))
    )
    b, a = rig_model()
    results = [
        run_diagnose(u, y, RIG_FS, "acceleration", *perturbed(b, a, draw)) for draw in range(DRAWS)
    ]
    first = results[0]
    assert all(r.named == first.named for r in results), [(r.named, r.gap_after) for r in results]
    assert all(abs(r.gap_after / first.gap_after - 1.0) <= 0.05 for r in results)
