"""Offline identification: spectral estimate, rational fit, output-error fit, friction signature."""
