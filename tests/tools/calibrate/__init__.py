"""Tests of ``python -m tools.calibrate``."""
