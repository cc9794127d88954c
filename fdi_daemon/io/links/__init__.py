"""Data-acquisition links: serial frames, Modbus TCP/RTU, replay files, the simulated rig.

Use ``make_link(config)`` (in ``base``) and wrap it in ``ReconnectingLink`` for the daemon.
"""
