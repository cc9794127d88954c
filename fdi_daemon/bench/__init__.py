"""Speed measurements behind `fdi bench` (one module per measured component)."""
