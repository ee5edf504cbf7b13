"""Size and mass of the particles: calliper and balance readings of the ``specimens`` sheet.

Labs report the mean sizes and mass of their particles measured with vernier callipers and an
electronic balance (which sizes, the particle's shape says: ``measure.shape``); these
estimators give the same means with their spread, n and 95 % interval.
"""

from __future__ import annotations

from dataclasses import replace

from demcal.measure.estimate import Estimate, summarise

#: Method text shared by the dimension and mass statistics.
METHOD = "sample mean, sd (n - 1) and Student-t 95 % CI of calliper/balance readings (Student 1908)"


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
        Each calliper column the sheet was read with for its shape (``length_mm``,
        ``diameter_mm``, ``width_mm``, ``thickness_mm``) [mm] and ``mass_g`` [g], named and
        expressed in the units of docs/workbook.md. ``extra`` holds the minimum and maximum of
        the rows used.
    """
    from demcal.measure.shape import size_columns

    if specimens is None or not specimens.rows:
        return {}
    frame = specimens.frame
    records = [{"id": frame.at[r, "specimen_id"], "covariates": specimens.covariates_of(r)}
               for r in specimens.rows]
    out: dict[str, Estimate] = {}
    for column, unit in [(c, "mm") for c in size_columns(specimens)] + [("mass_g", "g")]:
        est = summarise(column, frame[column].to_numpy(float), specimens.rows, unit=unit,
                        source=specimens.source(), method=METHOD, outliers=outliers,
                        per_row=records)
        used = frame.loc[est.rows_used, column]
        extra = dict(est.extra, min=float(used.min()), max=float(used.max()))
        out[column] = replace(est, extra=extra)
    return out
