"""A cut segment (a root, a stem, a pellet): equal spheres in a row.

``n_spheres`` spheres of radius D/2 on the x axis, the end centres at +-(L/2 - D/2), so the
row spans the measured length; the body is the solid cylinder of length L and diameter D. The
source paper models its 25 x 11 mm root segments with 5 spheres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from demcal.errors import InputError
from demcal.simulate.clump import MassProperties, cylinder_mass_properties, segment_centres
from demcal.simulate.shapes.base import Shape, SpecimenError, specimen_value
from demcal.units import MM


@dataclass(frozen=True)
class Segment(Shape):
    """A segment of ``length_m`` x ``diameter_m`` modelled by ``n_spheres`` spheres in a row."""

    name: ClassVar[str] = "segment"
    specimen_columns: ClassVar[tuple] = (("length_mm", "diameter_mm"),)
    sizes: ClassVar[tuple] = ("length_m", "diameter_m")
    body: ClassVar[str] = "a cylinder of the calliper length and diameter, pi d^2 L / 4"
    strip_contact: ClassVar[bool] = True

    length_m: float
    diameter_m: float
    n_spheres: int = 5

    def __post_init__(self):
        super().__post_init__()
        if int(self.n_spheres) != self.n_spheres or self.n_spheres < 1:
            raise InputError(f"segment shape: n_spheres must be a positive integer, got {self.n_spheres!r}")
        object.__setattr__(self, "n_spheres", int(self.n_spheres))
        if self.diameter_m > self.length_m:
            raise InputError(f"segment shape: the diameter ({self.diameter_m / MM:.4g} mm) exceeds the length "
                             f"({self.length_m / MM:.4g} mm); a particle as wide as it is long is a sphere "
                             "or a kernel (meta key shape)")

    @classmethod
    def check_specimen(cls, row: dict) -> None:
        length = specimen_value(row, "length_mm", cls.name)
        diameter = specimen_value(row, "diameter_mm", cls.name)
        if diameter > length:
            raise SpecimenError("diameter_mm", f"{diameter / MM:.4g} mm exceeds the length_mm {length / MM:.4g} mm, "
                                "which a segment cannot (meta key shape: sphere or kernel)")

    @classmethod
    def from_specimen(cls, row: dict, n_spheres: int = 5, **_) -> "Segment":
        cls.check_specimen(row)
        return cls(specimen_value(row, "length_mm", cls.name), specimen_value(row, "diameter_mm", cls.name),
                   n_spheres)

    def spheres(self):
        centres = segment_centres(self.length_m, self.diameter_m, self.n_spheres)
        return centres, np.full(self.n_spheres, self.diameter_m / 2.0)

    def volume(self) -> float:
        return math.pi * self.diameter_m ** 2 * self.length_m / 4.0

    def body_mass_properties(self, density: float) -> MassProperties:
        return cylinder_mass_properties(self.length_m, self.diameter_m, density)

    def _cylinder(self):
        return (self.length_m, self.diameter_m)

    def describe(self) -> str:
        return (f"{self.n_spheres} spheres of {self.diameter_m / MM:.3g} mm diameter in a row over the "
                f"{self.length_m / MM:.3g} mm length of the segment")
