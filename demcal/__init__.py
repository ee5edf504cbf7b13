"""demcal: calibrate DEM material models from lab measurements.

The four stages live in the top-level packages ``measure``, ``simulate``, ``analyse`` and
``report``; this small front-door package holds what they share: the command line, the
domain errors and provenance.
"""

__version__ = "0.1.0"
