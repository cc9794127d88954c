"""End to end in real terminals (tmux): `fdi run --dashboard` on the built-in simulated rig in
one pane and `fdi dashboard` attached to it in another; both screens are read until the
scheduled friction fault shows. Then q in the daemon's pane stops the daemon cleanly, and the
attached dashboard says the daemon is gone."""

from __future__ import annotations

import re
import sys

import pytest
from conftest_dashboard import TMUX, TmuxScreen

from fdi_daemon.service.config import load_config

DEFAULT = load_config()

pytestmark = [
    pytest.mark.usefixtures("compiled_kernel_cache"),
    pytest.mark.slow,
    pytest.mark.skipif(TMUX is None, reason="tmux is not installed"),
    pytest.mark.skipif(
        not DEFAULT.model_path.exists(),
        reason=f"{DEFAULT.model_path.name} is not in fdi_daemon/data",
    ),
]


def test_both_dashboards_follow_the_daemon_to_the_friction_fault(tmp_path):
    (fault,) = DEFAULT.simulated_device["faults"]
    fdi = [sys.executable, "-m", "fdi_daemon"]
    daemon = TmuxScreen(
        fdi + ["run", "--dashboard", "--duration", str(fault["at_s"] + 60.0)], 100, 30, cwd=tmp_path
    )
    # no --connect: the dashboard finds the socket `fdi run` uses (same $XDG_STATE_HOME)
    attached = TmuxScreen(fdi + ["dashboard"], 100, 32, cwd=tmp_path)
    try:
        for screen in (daemon, attached):
            text = screen.wait_for("MONITORING", timeout_s=fault["at_s"] + 30.0)
            assert re.search(r"\d+\.\d Hz", text) and "not reachable" not in text
        for screen in (daemon, attached):
            text = screen.wait_for("FRICTION ISOLATED", timeout_s=60.0)
            assert "friction_isolated" in text  # the alarm row
            assert float(re.search(r"t (\d+\.\d+) s", text).group(1)) >= fault["at_s"]
        daemon.keys("q")  # stops the daemon as SIGINT does
        assert daemon.wait_until_dead(timeout_s=30.0)
        after = daemon.text(history_lines=100)  # printed meanwhile, shown after the view
        assert re.search(r"fdi run: \d+ samples", after)
        assert "FRICTION ISOLATED" in after  # its event line
        text = attached.wait_for("daemon not reachable, retrying")
        assert "last known" in text
        attached.keys("q")
        assert attached.wait_until_dead()
    finally:
        daemon.close()
        attached.close()
