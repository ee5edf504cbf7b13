"""LIGGGHTS-PUBLIC 3.8 reference run of the source paper's repose case.

``deck`` writes the input script and carton meshes; ``run`` executes the Debian ``liggghts``
binary on one core and returns its wall time and the final sphere positions, so the
project's own DEM can be compared with an independent, widely used code on the same case.
"""
