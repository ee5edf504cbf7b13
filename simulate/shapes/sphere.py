"""A round particle (soybean, pea, pellet): one sphere.

Measured by its diameter, or by three calliper axes (length, width, thickness), whose geometric
mean (L W T)^(1/3) is the diameter of the sphere of the same volume as the ellipsoid of those
axes (Mohsenin 1986, the size of round seeds in ASABE practice).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from demcal.simulate.clump import MassProperties
from demcal.simulate.shapes.base import Shape, specimen_value
from demcal.units import MM


@dataclass(frozen=True)
class Sphere(Shape):
    """A sphere of ``diameter_m``."""

    name: ClassVar[str] = "sphere"
    specimen_columns: ClassVar[tuple] = (("diameter_mm",), ("length_mm", "width_mm", "thickness_mm"))
    sizes: ClassVar[tuple] = ("diameter_m",)
    body: ClassVar[str] = "a sphere of the diameter, pi d^3 / 6"
    rolls_first: ClassVar[bool] = True

    diameter_m: float

    @classmethod
    def from_specimen(cls, row: dict, **_) -> "Sphere":
        if row.get("diameter_mm") is not None:
            return cls(specimen_value(row, "diameter_mm", cls.name))
        axes = [specimen_value(row, c, cls.name) for c in ("length_mm", "width_mm", "thickness_mm")]
        return cls(float(np.prod(axes) ** (1.0 / 3.0)))

    @staticmethod
    def size_note(columns) -> str:
        """How the diameter was taken from ``columns``, for measure's notes."""
        if tuple(columns) == ("diameter_mm",):
            return "sphere diameter: the specimens' diameter_mm"
        return ("sphere diameter: the geometric mean (L W T)^(1/3) of length_mm, width_mm and thickness_mm "
                "(the sphere of the same volume as the ellipsoid of the three axes)")

    def spheres(self):
        return np.zeros((1, 3)), np.array([self.diameter_m / 2.0])

    def volume(self) -> float:
        return math.pi * self.diameter_m ** 3 / 6.0

    def body_mass_properties(self, density: float) -> MassProperties:
        mass = density * self.volume()
        return MassProperties(float(mass), np.zeros(3), np.eye(3) * 0.1 * mass * self.diameter_m ** 2)

    def describe(self) -> str:
        return f"one sphere of {self.diameter_m / MM:.3g} mm diameter"
