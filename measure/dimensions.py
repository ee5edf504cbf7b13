"""Size and mass of the particles: calliper and balance readings of the ``specimens`` sheet.

The source paper (Table 1 and 2) reports the mean length, diameter and mass of cut
*Astragalus membranaceus* segments measured with vernier callipers and an electronic
balance; these estimators give the same means with their spread, n and 95 % interval.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from demcal.measure.estimate import Estimate, summarise

#: Method text shared by the dimension and mass statistics.
METHOD = "sample mean, sd (n - 1) and Student-t 95 % CI of calliper/balance readings (Student 1908)"


def cylinder_volume(length, diameter):
    """Volume of a right circular cylinder, V = pi d^2 L / 4.

    Parameters
    ----------
    length : array_like
        Cylinder length L [m].
    diameter : array_like
        Cylinder diameter d [m].

    Returns
    -------
    numpy.ndarray
        Volume [m^3].
    """
    length = np.asarray(length, dtype=float)
    diameter = np.asarray(diameter, dtype=float)
    return np.pi * diameter**2 * length / 4.0


def specimen_statistics(specimens, *, outliers="none") -> dict:
    """Length, diameter and mass statistics of the ``specimens`` sheet.

    Parameters
    ----------
    specimens : measure.workbook.Sheet
        The ``specimens`` sheet.
    outliers : str
        Outlier rule, see :func:`measure.estimate.screen_outliers`.

    Returns
    -------
    dict of str -> Estimate
        ``length_mm`` [mm], ``diameter_mm`` [mm] and ``mass_g`` [g], named and expressed in
        the units of docs/workbook.md. ``extra`` holds the minimum and maximum of the rows used.
    """
    if specimens is None or not specimens.rows:
        return {}
    frame = specimens.frame
    records = [{"id": frame.at[r, "specimen_id"], "covariates": specimens.covariates_of(r)}
               for r in specimens.rows]
    out: dict[str, Estimate] = {}
    for column, unit in (("length_mm", "mm"), ("diameter_mm", "mm"), ("mass_g", "g")):
        est = summarise(column, frame[column].to_numpy(float), specimens.rows, unit=unit,
                        source=specimens.source(), method=METHOD, outliers=outliers,
                        per_row=records)
        used = frame.loc[est.rows_used, column]
        extra = dict(est.extra, min=float(used.min()), max=float(used.max()))
        out[column] = replace(est, extra=extra)
    return out
