"""Alarm management on top of the detector's events (pure logic, no I/O)."""
