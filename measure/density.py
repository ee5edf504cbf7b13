"""Particle density: by liquid displacement in a measuring cylinder, and from the envelope.

Pieces of known mass are immersed in a measuring cylinder and the rise of the liquid gives
their volume (Archimedes' principle). The envelope density uses instead the geometric volume of
each specimen, the body of its shape at its calliper readings (a cylinder for a segment, a
sphere, an ellipsoid for a kernel; ``simulate.shapes``). The two differ by the particles'
departure from that body and by any open porosity the liquid fills.

References
----------
.. [1] Mohsenin, N. N. (1986). Physical Properties of Plant and Animal Materials, 2nd ed.
   Gordon and Breach, New York. Chapter 2: volume and density (liquid displacement; volume
   from dimensions of a geometric approximation).
"""

from __future__ import annotations

import numpy as np

from demcal.errors import InputError
from demcal.measure.estimate import summarise
from demcal.measure.shape import specimen_shapes

GRAM = 1e-3         # [kg]
MILLILITRE = 1e-6   # [m^3]


def displacement_density(mass, volume_before, volume_after):
    """Density by liquid displacement, rho = m / (V_after - V_before) [1]_.

    Parameters
    ----------
    mass : array_like
        Mass of the immersed pieces [kg].
    volume_before, volume_after : array_like
        Liquid level before and after immersion [m^3].

    Returns
    -------
    numpy.ndarray
        Density [kg/m^3].
    """
    mass = np.asarray(mass, dtype=float)
    displaced = np.asarray(volume_after, dtype=float) - np.asarray(volume_before, dtype=float)
    if np.any(displaced <= 0):
        raise InputError("volume_after must exceed volume_before")
    return mass / displaced


def density_estimates(workbook, *, outliers="none") -> dict:
    """``particle_density_kg_m3`` (``density`` sheet) and ``envelope_density_kg_m3`` (``specimens``).

    Each is the mean of the per-row densities; a quantity is returned only when its sheet is
    present.
    """
    out = {}
    sheet = workbook.sheet("density")
    if sheet is not None and sheet.rows:
        f = sheet.frame
        rho = displacement_density(f["mass_g"].to_numpy(float) * GRAM,
                                   f["volume_before_ml"].to_numpy(float) * MILLILITRE,
                                   f["volume_after_ml"].to_numpy(float) * MILLILITRE)
        records = [{"id": f.at[r, "sample_id"], "covariates": sheet.covariates_of(r)} for r in sheet.rows]
        out["particle_density_kg_m3"] = summarise(
            "particle_density_kg_m3", rho, sheet.rows, unit="kg/m^3", source=sheet.source(),
            method="liquid displacement in a measuring cylinder, m / (V_after - V_before) (Mohsenin 1986)",
            outliers=outliers, per_row=records)
    sheet = workbook.sheet("specimens")
    if sheet is not None and sheet.rows:
        f = sheet.frame
        shapes = specimen_shapes(workbook)
        rho = f["mass_g"].to_numpy(float) * GRAM / np.array([s.volume() for _, s in shapes])
        records = [{"id": f.at[r, "specimen_id"], "covariates": sheet.covariates_of(r)} for r in sheet.rows]
        body = type(shapes[0][1]).body
        out["envelope_density_kg_m3"] = summarise(
            "envelope_density_kg_m3", rho, sheet.rows, unit="kg/m^3", source=sheet.source(),
            method=f"envelope density m / V, V the volume of {body}, callipers and balance (Mohsenin 1986)",
            outliers=outliers, per_row=records)
    return out
