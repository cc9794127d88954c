"""fdi: on-line Coulomb/viscous friction fault detection and isolation.

Implements Dunbar, de Callafon and Kosmatka, "Coulomb and viscous friction fault
detection with application to a pneumatic actuator" and goes beyond it.
"""

__version__ = "0.1.0"
