"""The nonlinear servo-pneumatic rig: flapper-nozzle valve, two air chambers, piston with
rod-seal friction, air-bearing load whose friction is the fault, and the DAQ's sensors.

Public API: `RigParams`, `Rig`, `RigOutput`, `FAULTS`.
"""

from hil_sim.rig.params import RigParams
from hil_sim.rig.rig import FAULTS, Rig, RigOutput

__all__ = ["FAULTS", "Rig", "RigOutput", "RigParams"]
