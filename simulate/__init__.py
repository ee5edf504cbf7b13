"""Simulate stage: a numba DEM of multi-sphere clumps and the twins of the lab rigs."""
