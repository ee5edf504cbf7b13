"""LIGGGHTS-PUBLIC 3.8 beside demcal: the input deck of a repose rig (``deck``) and the runner
of the Debian ``liggghts`` binary on one core (``run``), which returns its loop time and the
final sphere positions.

They serve the side-by-side benchmarks (``benchmarks/``) and ``demcal export --to liggghts
--check``, which runs a calibrated set in LIGGGHTS in the lab's repose rig.
"""
