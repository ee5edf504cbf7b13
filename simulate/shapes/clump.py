"""Any particle given as a table of spheres (the workbook's ``clump`` sheet).

The lab (or a sphere-fitting tool) gives sphere centres and radii of one reference particle in
millimetres, in any frame; demcal centres them on their bounding box, orders the axes by
extent (longest x, then y) and scales the table to each specimen: by length_mm alone, or by
the geometric mean of the three axis ratios when width_mm and thickness_mm are measured too.
The body the spheres stand for is their union.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from demcal.errors import InputError
from demcal.simulate.clump import MassProperties, disjoint_spheres_mass_properties, spheres_overlap, \
    union_mass_properties
from demcal.simulate.shapes.base import Shape, specimen_value
from demcal.units import MM

#: Columns of the ``clump`` sheet [mm].
CLUMP_COLUMNS = ("x_mm", "y_mm", "z_mm", "radius_mm")


@dataclass(frozen=True)
class ClumpTable(Shape):
    """The spheres of ``table`` ((x, y, z, r) [m] of the reference particle, axes ordered by
    extent, centred) scaled to the length ``length_m``."""

    name: ClassVar[str] = "clump"
    specimen_columns: ClassVar[tuple] = (("length_mm", "width_mm", "thickness_mm"), ("length_mm",))
    sizes: ClassVar[tuple] = ("length_m",)
    body: ClassVar[str] = "the union of the clump table's spheres at the specimen's scale"

    length_m: float
    table: tuple

    def __post_init__(self):
        super().__post_init__()
        object.__setattr__(self, "table", normalised_table(self.table))

    @classmethod
    def from_specimen(cls, row: dict, table=(), **_) -> "ClumpTable":
        ref = normalised_table(table)
        extent = _extent(ref)
        length = specimen_value(row, "length_mm", cls.name)
        if row.get("width_mm") is not None and row.get("thickness_mm") is not None:
            axes = [length, specimen_value(row, "width_mm", cls.name), specimen_value(row, "thickness_mm", cls.name)]
            scale = float(np.prod(np.array(axes) / extent) ** (1.0 / 3.0))
            return cls(scale * extent[0], ref)
        return cls(length, ref)

    @property
    def scale(self) -> float:
        return self.length_m / _extent(self.table)[0]

    def spheres(self):
        t = np.asarray(self.table, float) * self.scale
        return t[:, :3].copy(), t[:, 3].copy()

    def volume(self) -> float:
        return self.body_mass_properties(1.0).mass

    def body_mass_properties(self, density: float) -> MassProperties:
        c, r = self.spheres()
        if spheres_overlap(c, r):
            return union_mass_properties(c, r, density)
        return disjoint_spheres_mass_properties(c, r, density)

    def describe(self) -> str:
        return (f"{len(self.table)} spheres of the workbook's clump table, scaled to "
                f"{self.length_m / MM:.3g} mm length")


def _extent(table) -> np.ndarray:
    t = np.asarray(table, float)
    return (t[:, :3] + t[:, 3:]).max(axis=0) - (t[:, :3] - t[:, 3:]).min(axis=0)


def normalised_table(table) -> tuple:
    """``table`` ((x, y, z, r) rows [m]) centred on its bounding box, its axes ordered by
    extent (longest first), as a tuple of float tuples."""
    try:
        t = np.asarray(table, dtype=float).reshape(-1, 4)
    except (TypeError, ValueError):
        raise InputError(f"clump shape: the table needs rows of (x, y, z, radius), got {table!r}") from None
    if t.shape[0] == 0 or not np.isfinite(t).all() or not (t[:, 3] > 0).all():
        raise InputError("clump shape: the table needs at least one sphere, finite coordinates and radii > 0")
    lo, hi = (t[:, :3] - t[:, 3:]).min(axis=0), (t[:, :3] + t[:, 3:]).max(axis=0)
    centred = t[:, :3] - (lo + hi) / 2.0
    order = np.argsort(-(hi - lo), kind="stable")
    out = np.column_stack([centred[:, order], t[:, 3]])
    return tuple(tuple(float(round(v, 15)) for v in row) for row in out)


def table_from_rows(rows) -> tuple:
    """The (x, y, z, r) table [m] of the ``clump`` sheet's rows (``(row number, {column: value})``),
    each reading refused by row and column unless a finite number (radius > 0)."""
    out = []
    for number, row in rows:
        values = []
        for column in CLUMP_COLUMNS:
            try:
                v = float(row.get(column))
            except (TypeError, ValueError):
                v = math.nan
            if not math.isfinite(v) or (column == "radius_mm" and v <= 0):
                need = "a radius > 0" if column == "radius_mm" else "a finite number"
                raise InputError(f"sheet clump, row {number}, column {column}: needs {need} [mm], "
                                 f"got {row.get(column)!r}")
            values.append(v * MM)
        out.append(tuple(values))
    if not out:
        raise InputError("sheet clump: shape clump needs at least one sphere row")
    return tuple(out)
