"""The monitor pipeline (per tick and batch), the detector logic and its events."""
