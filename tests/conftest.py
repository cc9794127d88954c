"""Shared pytest configuration: plots never need a screen; the session fixtures of the
conftest_<area> modules are registered here (their helpers are imported where used)."""

import matplotlib

matplotlib.use("Agg")

pytest_plugins = ["conftest_ident", "conftest_sim"]
