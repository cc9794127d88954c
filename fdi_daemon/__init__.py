"""fdi: on-line Coulomb/viscous friction fault detection and isolation.

Implements Dunbar, de Callafon and Kosmatka, "Coulomb and viscous friction fault
detection with application to a pneumatic actuator" and goes beyond it.
"""

from importlib.metadata import version

from fdi_daemon import blas_kernel

blas_kernel.pin()  # before NumPy loads OpenBLAS: one kernel, the same diagnosis on every machine

__version__ = version("fdi")  # single source: pyproject.toml [project] version
