"""What every particle shape knows (docs/design.md, "Shapes and rigs").

A shape is a frozen dataclass of one particle's size in metres (the mean specimen, or one
specimen of a size distribution). The DEM sees it only through :meth:`Shape.template`; measure
through :meth:`Shape.from_specimen` and :meth:`Shape.volume`; the report through
:meth:`Shape.describe` and :meth:`Shape.rows`; run keys and exports through
:meth:`Shape.to_dict`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields, replace
from typing import ClassVar

import numpy as np

from demcal.errors import InputError
from demcal.simulate.clump import ClumpTemplate, MassProperties, make_template
from demcal.units import MM


class SpecimenError(InputError):
    """A specimen's reading that the shape cannot take, with the column it is in."""

    def __init__(self, column: str, message: str):
        super().__init__(f"column {column}: {message}")
        self.column = column
        self.reason = message


@dataclass(frozen=True)
class Shape:
    """Base of the particle shapes (``simulate.shapes.SHAPES``).

    Class attributes
    ----------------
    name : str
        The workbook's meta ``shape`` value.
    specimen_columns : tuple of tuple of str
        Alternative sets of ``specimens`` columns [mm] the shape is measured by, the first
        preferred (a sphere: its diameter, or three axes).
    sizes : tuple of str
        The fields that hold a length [m]: what a specimen's measurement sets and what
        :meth:`scaled_to` changes.
    body : str
        The body the spheres stand for, in words (the envelope density's method).
    rolls_first : bool
        On an incline it rolls before it slides whatever its friction (a sphere): labs measure
        its sliding friction with a sled of glued particles.
    strip_contact : bool
        Compressed radially between plates it touches them along a strip of its width and
        length, the contact the measure stage's elastic modulus assumes.
    """

    name: ClassVar[str] = ""
    specimen_columns: ClassVar[tuple] = ()
    sizes: ClassVar[tuple] = ()
    body: ClassVar[str] = ""
    rolls_first: ClassVar[bool] = False
    strip_contact: ClassVar[bool] = False

    def __post_init__(self):
        for name in self.sizes:
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise InputError(f"{self.name} shape: {name} must be a length > 0 [m], got {value!r}")
            object.__setattr__(self, name, float(value))

    # -- measured ------------------------------------------------------------------------------

    @classmethod
    def columns_of(cls, available) -> tuple:
        """The first of ``specimen_columns`` that ``available`` (column names) holds; refused,
        naming what is missing, when none is there."""
        have = set(available)
        for option in cls.specimen_columns:
            if set(option) <= have:
                return tuple(option)
        wanted = " or ".join("(" + ", ".join(o) + ")" for o in cls.specimen_columns)
        raise InputError(f"shape {cls.name} is measured by the specimens columns {wanted}; "
                         f"missing {', '.join(c for c in cls.specimen_columns[0] if c not in have)}")

    @classmethod
    def check_specimen(cls, row: dict) -> None:
        """Refuse (:class:`SpecimenError`, naming the column) calliper readings ``row`` (column
        -> mm) the shape cannot take; each must be a length > 0. Shapes add their own rules."""
        for column, _ in row.items():
            specimen_value(row, column, cls.name)

    @classmethod
    def check_spheres(cls, n_spheres: int) -> None:
        """Refuse (:class:`InputError`) a sphere count (the meta ``spheres_per_particle``) the
        shape cannot take; any count does by default."""

    @classmethod
    def from_specimen(cls, row: dict, **settings) -> "Shape":
        """The shape of one specimen from its calliper readings ``row`` (column -> mm).

        Raises :class:`SpecimenError` naming the column of a reading the shape cannot take."""
        raise NotImplementedError

    def scaled_to(self, other: "Shape") -> "Shape":
        """This shape's settings (sphere counts, a clump table) at ``other``'s size."""
        return self.with_sizes(other.size_values)

    def sized_as(self, row: dict) -> "Shape":
        """This shape's settings at the size of the specimen whose calliper readings ``row``
        (column -> mm, other columns ignored) holds; :class:`InputError` when the row lacks the
        shape's columns or they are not lengths it can take."""
        read = [c for c, v in row.items() if v is not None and not (isinstance(v, float) and math.isnan(v))]
        columns = self.columns_of(read)
        settings = {f: getattr(self, f) for f in self.field_names() if f not in self.sizes}
        return self.scaled_to(type(self).from_specimen({c: row[c] for c in columns}, **settings))

    @property
    def size_values(self) -> tuple:
        """The lengths named by ``sizes`` [m], in that order (one specimen's entry of a size
        distribution)."""
        return tuple(getattr(self, n) for n in self.sizes)

    def with_sizes(self, values) -> "Shape":
        """This shape's settings at the lengths ``values`` [m] (in the order of ``sizes``),
        checked as the shape checks a specimen."""
        values = tuple(values)
        if len(values) != len(self.sizes):
            raise InputError(f"shape {self.name} has {len(self.sizes)} size(s) ({', '.join(self.sizes)}), "
                             f"got {len(values)}: {values!r}")
        return replace(self, **dict(zip(self.sizes, (float(v) for v in values))))

    # -- geometry ------------------------------------------------------------------------------

    def spheres(self) -> tuple[np.ndarray, np.ndarray]:
        """(centres (n, 3), radii (n,)) [m] in the shape's frame: centre of the body at the
        origin, longest axis x, then y."""
        raise NotImplementedError

    def volume(self) -> float:
        """Volume of the body the spheres stand for [m3] (the envelope volume of a specimen)."""
        raise NotImplementedError

    def body_mass_properties(self, density: float) -> MassProperties:
        """Mass properties of that body at ``density`` [kg/m3], in the shape's frame."""
        raise NotImplementedError

    @property
    def extent(self) -> np.ndarray:
        """Extent of the sphere model along x, y, z [m]."""
        c, r = self.spheres()
        return (c + r[:, None]).max(axis=0) - (c - r[:, None]).min(axis=0)

    @property
    def outline_m(self) -> tuple[float, float]:
        """(length, width) [m] of the particle lying on a heap as a side photo shows it: its
        longest extent, and the geometric mean of the other two (``render.heap_photo``)."""
        e = self.extent
        return float(e[0]), float(math.sqrt(e[1] * e[2]))

    def template(self, density: float, mass_model: str = "union", mean_mass: float | None = None,
                 name: str | None = None, resolution: int = 600) -> ClumpTemplate:
        """The DEM's clump of this shape (``simulate.clump.make_template``'s mass models and
        grid ``resolution``; the ``body`` model takes :meth:`body_mass_properties`)."""
        centres, radii = self.spheres()
        body = self.body_mass_properties(density) if mass_model == "body" else None
        return make_template(centres, radii, density, name=name or self.name, mass_model=mass_model,
                             mean_mass=mean_mass, body=body, cylinder=self._cylinder(), resolution=resolution)

    def _cylinder(self):
        """(length, diameter) of the cylinder of the ``cylinder`` mass model (a segment's)."""
        return None

    # -- words ---------------------------------------------------------------------------------

    def describe(self) -> str:
        """One sentence for the report: the sphere model of the measured particle."""
        raise NotImplementedError

    def rows(self) -> list:
        """(quantity, value, unit) rows for the report's model table: the sizes in mm, the
        spheres, and the volume of the sphere model against the body's."""
        c, r = self.spheres()
        out = [(n.removesuffix("_m").replace("_", " "), getattr(self, n) / MM, "mm") for n in self.sizes]
        out.append(("spheres", int(r.size), ""))
        out.append(("sphere radii", f"{r.min() / MM:.4g}-{r.max() / MM:.4g}" if np.ptp(r) > 0 else
                    f"{r[0] / MM:.4g}", "mm"))
        return out

    # -- stored --------------------------------------------------------------------------------

    def to_dict(self) -> dict:
        return {"shape": self.name, **asdict(self)}

    @classmethod
    def field_names(cls) -> tuple:
        return tuple(f.name for f in fields(cls))


def specimen_value(row: dict, column: str, shape: str) -> float:
    """A reading of ``row`` [mm] as metres, refused unless a finite number > 0."""
    value = row.get(column)
    try:
        value = float(value)
    except (TypeError, ValueError):
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise SpecimenError(column, f"shape {shape} needs a length > 0 [mm], got {row.get(column)!r}")
    return value * MM
