"""fdi: on-line Coulomb/viscous friction fault detection and isolation.

Implements Dunbar, de Callafon and Kosmatka, "Coulomb and viscous friction fault
detection with application to a pneumatic actuator" and goes beyond it.
"""

from fdi_daemon import blas_kernel

blas_kernel.pin()  # before NumPy loads OpenBLAS: one kernel, the same diagnosis on every machine

__version__ = "0.1.0"
