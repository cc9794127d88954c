"""`fdi diagnose` on random variants of the simulated rig, each with its own identified model
(docs/diagnose_results.md, "Rig variants"). Run: ``python studies/diagnose_rig_variants.py
[VARIANT ...]`` (default 0 1 2 3; about half a minute per variant).

Per variant (`test_detect_other_rig.rig_variant`: another load mass, damping, valve, seal
and contact friction): `fdi identify` on its identification chirp, then one blind
`run_diagnose` per fault switched on from the start of a 40 s, 0.8 V RMS multisine
(`diagnose_cases.rig_recording` on the variant): none, contact friction (bearing supply 65 %), supply
pressure 80 % (a softer air spring), valve gain 80 %, accelerometer bias 0.3 m/s², a
payload (the bearing block 0.5 kg heavier: a mass the model does not know), the load's
linear damping doubled (a damper) and the rod seal's friction raised to a pure Coulomb
friction of 0.5 N (static = Coulomb).
Prints the names, the held-out gap before and after, the noise floor and the fitted ratio
of a gain fault, a stiffness change or a mass change, or the damping a viscous friction
adds per unit mass (Δ(c/m), 1/s), with the truth; with ``--json`` one JSON object per cell
(`cells`; what `diagnose_kernel_agreement.py` and `diagnose_results.py` read).
"""

from __future__ import annotations

import contextlib
import io
import json
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
FAULTS = (
    (None, 0.0),
    ("bearing_supply", 0.65),
    ("supply_pressure", 0.8),
    ("valve_gain", 0.8),
    ("accel_bias", 0.3),
    ("payload_kg", 0.5),
    ("damping_x", 2.0),
    ("seal_coulomb_n", 0.5),
)
#: faults made by changing the variant's `RigParams` (in `main`; the others are
#: `rig_recording` faults)
CHANGES = ("payload_kg", "damping_x", "seal_coulomb_n")


def identified_model(rig: dict, folder: Path):
    """`fdi identify` on the variant's identification chirp."""
    from test_detect_other_rig import record

    from fdi_daemon.cli import main
    from fdi_daemon.io.model_file import load_model
    from fdi_daemon.io.recordings import write_recording

    write_recording(folder / "ident.npz", record(rig, "ident_chirp"))
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        assert main(["identify", str(folder / "ident.npz"), "-o", str(folder / "m.yaml")]) == 0
    return load_model(folder / "m.yaml")


def cells(indices: list[int]):
    """Per variant in ``indices`` and per fault of `FAULTS`, one blind diagnosis: yields
    ``{variant, fault, value, named, gap_before, gap_after, floor, ratios, truth,
    ambiguous}`` (ratios: the fitted ratio or Δ(c/m) of each named linear change)."""
    sys.path.insert(0, str(REPO / "tests"))
    sys.path.insert(0, str(REPO))
    from test_detect_other_rig import rig_variant

    from fdi_daemon.diagnose.workflow import run_diagnose
    from hil_sim.rig import RigParams
    from tests.diagnose_cases import NAMED_RATIOS, RIG_FS, rig_recording

    for index in indices:
        rig = rig_variant(index)
        with tempfile.TemporaryDirectory() as folder:
            model = identified_model(rig, Path(folder))
        for fault, value in FAULTS:
            params = dict(rig)
            truth = ""
            nominal = RigParams(**rig)
            if fault == "payload_kg":
                params["bearing_mass_kg"] = nominal.bearing_mass_kg + value
                ratio = RigParams(**params).moving_mass_kg / nominal.moving_mass_kg
                truth = f"moving mass x {ratio:.3f}"
            elif fault == "damping_x":
                params["viscous_damping_n_s_per_m"] = nominal.viscous_damping_n_s_per_m * value
                added = (value - 1.0) * nominal.viscous_damping_n_s_per_m / nominal.moving_mass_kg
                truth = f"damping per unit mass + {added:.1f} /s"
            elif fault == "seal_coulomb_n":
                params.update(seal_coulomb_n=value, seal_static_n=value)
            u, y = rig_recording(
                None if fault in CHANGES else fault,
                value,
                rms_v=0.8,
                duration_s=40.0,
                variant=tuple(sorted(params.items())),
            )
            r = run_diagnose(u, y, RIG_FS, "acceleration", model.plant_b, model.plant_a)
            yield {
                "variant": f"v{index}",
                "fault": fault or "none",
                "value": value,
                "named": r.named,
                "gap_before": r.gap_before,
                "gap_after": r.gap_after,
                "floor": r.info["noise_floor"]["floor"],
                "ratios": {
                    e.named_as: round(float(e.physical[NAMED_RATIOS[e.named_as]]), 3)
                    for e in r.selection.named
                    if e.named_as in NAMED_RATIOS
                },
                "truth": truth,
                "ambiguous": [tie["effects"] for tie in r.ambiguous],
            }


def line(cell: dict) -> str:
    """One cell as the script prints it."""
    truth = f" ({cell['truth']})" if cell["truth"] else ""
    return (
        f"{cell['variant']} {cell['fault']} {cell['value']:g}: {cell['named']} "
        f"{cell['gap_before']:.4f} -> {cell['gap_after']:.4f} (floor {cell['floor']:.4f}) "
        f"{cell['ratios']}{truth}"
    )


def main(indices: list[int], as_json: bool = False) -> None:
    for cell in cells(indices):
        print(json.dumps(cell) if as_json else line(cell), flush=True)


if __name__ == "__main__":
    arguments = [a for a in sys.argv[1:] if a != "--json"]
    main([int(a) for a in arguments] or [0, 1, 2, 3], as_json="--json" in sys.argv[1:])
