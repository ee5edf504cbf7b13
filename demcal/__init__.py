"""demcal: calibrate DEM material models from lab measurements.

The four stages are the subpackages ``demcal.measure``, ``demcal.simulate``, ``demcal.analyse``
and ``demcal.report`` (the repository's top-level folders of those names). The front door holds
what they share: the command line, the ``calibrate`` command that composes the stages, the
domain errors, units and provenance.
"""

__version__ = "0.1.0"
