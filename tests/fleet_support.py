"""A fleet task that kills its worker process on one file (for tests/test_fleet_replay.py).

In its own module so that Dask's worker processes can import it by name.
"""

import os

from fdi_daemon.fleet.replay_one import replay_row


def replay_or_die(file: str, model: str | None) -> dict:
    if file.endswith("-kill.csv"):
        os._exit(3)  # the worker process dies, as on a segfault or the OOM killer
    return replay_row(file, model)
