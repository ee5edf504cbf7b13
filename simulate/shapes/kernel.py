"""A grain kernel (maize, rice, wheat, rapeseed pods): an ellipsoid of overlapping spheres.

The kernel is the ellipsoid of its three calliper axes, length L >= width W >= thickness T
(semi-axes a, b, c). It is filled with inscribed spheres, each the largest sphere inside the
ellipsoid about its centre, as Favier et al. (1999) fill an axisymmetric particle along its
axis: here the centres lie on rows of the ellipsoid's mid-plane (z = 0) parallel to its long
axis, one row for a kernel of round section (W <= 1.05 T) and three for a flat one, each row
ending where a sphere of the section's tip curvature touches the tip. The sphere model is
smaller than the ellipsoid and its surface is bumpy; :meth:`Kernel.approximation` gives the
volume and principal moments of the union against the exact ellipsoid, which the report prints.

Favier, J. F., Abbaspour-Fard, M. H., Kremmer, M., Raji, A. O. (1999). Shape representation of
axi-symmetrical, non-spherical particles in discrete element simulation using multi-element
model particles. Engineering Computations 16(4), 467-480.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import ClassVar

import numpy as np
from demcal.errors import InputError
from demcal.simulate.clump import MassProperties, principal_frame, union_mass_properties
from demcal.simulate.shapes.base import Shape, SpecimenError, specimen_value
from demcal.units import MM

#: Offset of the side rows of a flat kernel, in units of (semi-width - semi-thickness).
SIDE_ROW = 0.7

#: Surface points per angle of the search for the nearest surface point (polar, azimuth x 2).
_SURFACE_GRID = 120


@dataclass(frozen=True)
class Kernel(Shape):
    """An ellipsoid of ``length_m`` >= ``width_m`` >= ``thickness_m`` filled with inscribed
    spheres, ``n_spheres`` along the middle row."""

    name: ClassVar[str] = "kernel"
    specimen_columns: ClassVar[tuple] = (("length_mm", "width_mm", "thickness_mm"),)
    sizes: ClassVar[tuple] = ("length_m", "width_m", "thickness_m")
    body: ClassVar[str] = "an ellipsoid of the three calliper axes, pi L W T / 6"
    strip_contact: ClassVar[bool] = True

    length_m: float
    width_m: float
    thickness_m: float
    n_spheres: int = 9

    def __post_init__(self):
        super().__post_init__()
        if int(self.n_spheres) != self.n_spheres or self.n_spheres < 1:
            raise InputError(f"kernel shape: n_spheres must be a positive integer, got {self.n_spheres!r}")
        self.check_spheres(self.n_spheres)
        object.__setattr__(self, "n_spheres", int(self.n_spheres))
        _check_axes(self.length_m, self.width_m, self.thickness_m)

    @classmethod
    def check_specimen(cls, row: dict) -> None:
        _check_axes(*cls._axes(row), columns=True)

    @classmethod
    def check_spheres(cls, n_spheres: int) -> None:
        if n_spheres == 2:
            # the middle row runs tip to tip: two spheres are its tip spheres, nothing between
            raise InputError("kernel shape: n_spheres 2 puts the middle row's two spheres at the kernel's "
                             "tips, with nothing between them: give 1, or 3 or more (spheres_per_particle)")

    @classmethod
    def from_specimen(cls, row: dict, n_spheres: int = 9, **_) -> "Kernel":
        cls.check_specimen(row)
        return cls(*cls._axes(row), n_spheres=n_spheres)

    @classmethod
    def _axes(cls, row: dict) -> list:
        return [specimen_value(row, c, cls.name) for c in ("length_mm", "width_mm", "thickness_mm")]

    @property
    def semi_axes(self) -> np.ndarray:
        return np.array([self.length_m, self.width_m, self.thickness_m]) / 2.0

    def spheres(self):
        return _inscribed_spheres(tuple(self.semi_axes), self.n_spheres)

    def volume(self) -> float:
        a, b, c = self.semi_axes
        return 4.0 / 3.0 * math.pi * a * b * c

    def body_mass_properties(self, density: float) -> MassProperties:
        a, b, c = self.semi_axes
        m = density * self.volume()
        return MassProperties(float(m), np.zeros(3), np.diag([m * (b * b + c * c) / 5.0, m * (a * a + c * c) / 5.0,
                                                           m * (a * a + b * b) / 5.0]))

    def approximation(self) -> dict:
        """Volume and principal moments of the sphere model (their union) over the exact
        ellipsoid's, at any density (ratios)."""
        centres, radii = self.spheres()
        union = union_mass_properties(centres, radii, 1.0)
        body = self.body_mass_properties(1.0)
        moments = principal_frame(union.inertia)[0]
        return {"volume_ratio": union.mass / body.mass,
                "moment_ratios": (np.sort(moments) / np.sort(np.diag(body.inertia))).tolist()}

    def rows(self) -> list:
        ratio = self.approximation()
        return super().rows() + [("sphere model / ellipsoid volume", ratio["volume_ratio"], ""),
                                 ("sphere model / ellipsoid principal moments",
                                  ", ".join(f"{r:.3g}" for r in ratio["moment_ratios"]), "")]

    def describe(self) -> str:
        n = self.spheres()[1].size
        return (f"{n} overlapping spheres inscribed in the ellipsoid of {self.length_m / MM:.3g} x "
                f"{self.width_m / MM:.3g} x {self.thickness_m / MM:.3g} mm (Favier et al. 1999)")


def _check_axes(length, width, thickness, columns: bool = False):
    for (big, small), (nb, ns) in (((length, width), ("length", "width")),
                                   ((width, thickness), ("width", "thickness"))):
        if small > big:
            message = (f"{ns} {small / MM:.4g} mm exceeds the {nb} {big / MM:.4g} mm; a kernel's axes are "
                       "length >= width >= thickness")
            if columns:
                raise SpecimenError(f"{ns}_mm", message)
            raise InputError(f"kernel shape: {message}")


@lru_cache(maxsize=4096)
def _inscribed_spheres(semi_axes: tuple, n_spheres: int) -> tuple[np.ndarray, np.ndarray]:
    a, b, c = semi_axes
    # a side row each way where the section is flat: at 0.7 (b - c) it adds the most volume
    # (0.85 of rice's and maize's ellipsoid with 9 spheres in the middle row, against 0.64 and
    # 0.54 for the middle row alone)
    rows = [0.0] if b <= 1.05 * c else [-SIDE_ROW * (b - c), 0.0, SIDE_ROW * (b - c)]
    centres = []
    for y in rows:
        shrink = math.sqrt(1.0 - (y / b) ** 2)
        a_row, c_row = a * shrink, c * shrink
        end = max(a_row - c_row * c_row / a_row, 0.0)     # a sphere of the tip's curvature touches the tip
        n = n_spheres if y == 0.0 else max(2, int(round(n_spheres * shrink * end / max(a - c * c / a, 1e-12))))
        xs = np.linspace(-end, end, n) if n > 1 and end > 0 else np.zeros(1)
        centres += [(x, y, 0.0) for x in xs]
    centres = np.array(centres, dtype=float)
    radii = np.array([_inscribed_radius(np.array(semi_axes), p) for p in centres])
    centres.setflags(write=False)
    radii.setflags(write=False)
    return centres, radii


def _inscribed_radius(semi: np.ndarray, p: np.ndarray) -> float:
    """Distance from the interior point ``p`` to the ellipsoid of semi-axes ``semi``: the
    nearest point of a grid over the surface angles, then of a grid 20 times finer about it
    (twice), each a few milliseconds."""
    def distances(u, v):
        uu, vv = np.meshgrid(u, v, indexing="ij")
        pts = np.stack([semi[0] * np.cos(uu), semi[1] * np.sin(uu) * np.cos(vv),
                        semi[2] * np.sin(uu) * np.sin(vv)], axis=-1)
        d = np.linalg.norm(pts - p, axis=-1)
        k = np.unravel_index(np.argmin(d), d.shape)
        return float(d[k]), float(uu[k]), float(vv[k])

    du, dv = math.pi / _SURFACE_GRID, math.pi / _SURFACE_GRID
    best, u0, v0 = distances(np.linspace(0.0, math.pi, _SURFACE_GRID + 1),
                             np.linspace(0.0, 2.0 * math.pi, 2 * _SURFACE_GRID, endpoint=False))
    for _ in range(2):
        d, u0, v0 = distances(np.linspace(u0 - du, u0 + du, 41), np.linspace(v0 - dv, v0 + dv, 41))
        best, du, dv = min(best, d), du / 20.0, dv / 20.0
    return best
