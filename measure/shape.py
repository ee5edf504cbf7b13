"""The particle's shape from the workbook: the meta ``shape`` and the specimens' callipers.

The meta key ``shape`` names one of ``simulate.shapes.SHAPES`` (default ``segment``); the
``specimens`` sheet carries the columns that shape is measured by (the reader checked them),
and a ``clump`` shape takes its spheres from the ``clump`` sheet. :func:`specimen_shapes` gives
each specimen's own shape (its envelope volume, a size distribution), :func:`mean_shape` the
shape of the mean readings, which the DEM uses.
"""

from __future__ import annotations

import math

from demcal.measure.workbook import SIZE_COLUMNS
from demcal.simulate.shapes import DEFAULT_SHAPE, Shape, shape_class
from demcal.simulate.shapes.clump import table_from_rows


def shape_name(meta: dict) -> str:
    """The shape a workbook's ``meta`` names (``DEFAULT_SHAPE`` when none)."""
    return shape_class(meta.get("shape") or DEFAULT_SHAPE).name


def size_columns(sheet) -> list:
    """The calliper columns the ``specimens`` sheet was read with for its shape."""
    return [c for c in sheet.required if c in SIZE_COLUMNS]


def shape_settings(workbook) -> dict:
    """What the shape needs beside a specimen's readings: a clump's table of spheres, the
    meta ``spheres_per_particle`` of a segment or kernel."""
    out = {}
    clump = workbook.sheet("clump")
    if clump is not None:
        f = clump.frame
        out["table"] = table_from_rows([(r, {c: f.at[r, c] for c in ("x_mm", "y_mm", "z_mm", "radius_mm")})
                                        for r in clump.rows])
    n = workbook.meta.get("spheres_per_particle")
    if n is not None:
        out["n_spheres"] = int(n)
    return out


def specimen_shapes(workbook) -> list[tuple[int, Shape]]:
    """(row, shape) of every specimen, from its own readings."""
    sheet = workbook.sheet("specimens")
    cls = shape_class(shape_name(workbook.meta))
    settings = shape_settings(workbook)
    columns = size_columns(sheet)
    return [(r, cls.from_specimen({c: sheet.frame.at[r, c] for c in columns}, **settings)) for r in sheet.rows]


def mean_shape(workbook, quantities: dict) -> Shape | None:
    """The shape of the mean readings (the estimates of the size columns, outliers screened as
    measure screened them); None when a size has no finite estimate."""
    sheet = workbook.sheet("specimens")
    if sheet is None:
        return None
    row = {}
    for c in size_columns(sheet):
        est = quantities.get(c)
        if est is None or not math.isfinite(est.value):
            return None
        row[c] = est.value
    return shape_class(shape_name(workbook.meta)).from_specimen(row, **shape_settings(workbook))
