"""The model-discrepancy workflow (`fdi diagnose`) and its library of physical effects."""
