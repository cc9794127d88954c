"""Shared pytest configuration: plots never need a screen."""

import matplotlib

matplotlib.use("Agg")
