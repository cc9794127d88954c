"""The rich terminal dashboard; it reads status snapshots only."""
