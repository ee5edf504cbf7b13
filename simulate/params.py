"""The DEM parameter set of one simulation, with the source paper's values as defaults.

``DEMParameters`` is a frozen dataclass: change it with ``with_(**changes)`` or build it from
names (``from_names({"e_pp": 0.32})``, what ``--set NAME=VALUE`` uses); unknown names are
refused with the list of valid ones.

Defaults (DESIGN.md, "Paper defaults"): the paper's measured means for the contact parameters,
its segment geometry and densities; the particle shear modulus (1e7 Pa) is not in the paper and
is demcal's stated default.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, fields

from demcal.errors import InputError
from simulate.clump import MASS_MODELS
from simulate.contact.rolling import ROLLING_LEVERS


@dataclass(frozen=True)
class DEMParameters:
    """Material, contact and particle-shape parameters of one DEM run.

    Attributes
    ----------
    poisson_ratio : float
        Particle Poisson's ratio [-].
    shear_modulus_pa : float
        Particle shear modulus [Pa].
    particle_density_kg_m3 : float
        Particle (solid) density [kg/m3].
    e_pp, e_pw : float
        Coefficient of restitution particle-particle and particle-wall (steel) [-].
    mu_s_pp, mu_s_pw : float
        Static (sliding) friction coefficient particle-particle and particle-wall [-].
    mu_r_pp, mu_r_pw : float
        Rolling friction coefficient particle-particle and particle-wall [-].
    wall_density_kg_m3, wall_poisson_ratio, wall_shear_modulus_pa : float
        Wall material (steel) density [kg/m3], Poisson's ratio [-] and shear modulus [Pa].
    segment_length_m, segment_diameter_m : float
        Length and diameter of one segment [m].
    spheres_per_clump : int
        Number of equal spheres along the segment axis.
    mass_model : str
        ``"union"`` (mass and inertia of the sphere union, EDEM's default), ``"cylinder"``
        (solid cylinder of the segment's length and diameter) or ``"scaled"`` (the union scaled
        to ``mean_mass_kg``).
    mean_mass_kg : float or None
        Measured mean segment mass [kg], used only by ``mass_model="scaled"``.
    rolling_lever : str
        Lever arm of the rolling-friction torque: ``"liggghts_reff"`` (default), ``"edem_com"``
        or ``"edem_sphere"``; see ``simulate.contact.rolling`` for the conventions and the
        reason for the default.
    """

    poisson_ratio: float = 0.25
    shear_modulus_pa: float = 1.0e7
    particle_density_kg_m3: float = 912.0
    e_pp: float = 0.3
    e_pw: float = 0.35
    mu_s_pp: float = 0.65
    mu_s_pw: float = 0.2
    mu_r_pp: float = 0.53
    mu_r_pw: float = 0.15
    wall_density_kg_m3: float = 7850.0
    wall_poisson_ratio: float = 0.3
    wall_shear_modulus_pa: float = 8.0e10
    segment_length_m: float = 0.025
    segment_diameter_m: float = 0.011
    spheres_per_clump: int = 5
    mass_model: str = "union"
    mean_mass_kg: float | None = None
    rolling_lever: str = "liggghts_reff"

    def __post_init__(self):
        for name in ("e_pp", "e_pw"):
            value = getattr(self, name)
            if not 0.0 < value <= 1.0:
                raise InputError(f"{name} must be in (0, 1], got {value!r}")
        for name in ("mu_s_pp", "mu_s_pw", "mu_r_pp", "mu_r_pw"):
            value = getattr(self, name)
            if not value >= 0.0:
                raise InputError(f"{name} must be >= 0, got {value!r}")
        for name in ("poisson_ratio", "wall_poisson_ratio"):
            value = getattr(self, name)
            if not -1.0 < value < 0.5:
                raise InputError(f"{name} must be in (-1, 0.5), got {value!r}")
        for name in ("shear_modulus_pa", "particle_density_kg_m3", "wall_density_kg_m3",
                     "wall_shear_modulus_pa", "segment_length_m", "segment_diameter_m"):
            value = getattr(self, name)
            if not value > 0.0:
                raise InputError(f"{name} must be > 0, got {value!r}")
        if int(self.spheres_per_clump) != self.spheres_per_clump or self.spheres_per_clump < 1:
            raise InputError(f"spheres_per_clump must be a positive integer, got {self.spheres_per_clump!r}")
        if self.segment_diameter_m > self.segment_length_m:
            raise InputError(f"segment_diameter_m ({self.segment_diameter_m!r}) must not exceed "
                             f"segment_length_m ({self.segment_length_m!r})")
        if self.mass_model not in MASS_MODELS:
            raise InputError(f"mass_model must be one of {', '.join(MASS_MODELS)}; got {self.mass_model!r}")
        if self.mass_model == "scaled" and not (self.mean_mass_kg and self.mean_mass_kg > 0):
            raise InputError(f"mass_model='scaled' needs mean_mass_kg > 0, got {self.mean_mass_kg!r}")
        if self.rolling_lever not in ROLLING_LEVERS:
            raise InputError(f"rolling_lever must be one of {', '.join(ROLLING_LEVERS)}; "
                             f"got {self.rolling_lever!r}")

    @classmethod
    def names(cls) -> tuple[str, ...]:
        """The valid parameter names."""
        return tuple(f.name for f in fields(cls))

    def with_(self, **changes) -> "DEMParameters":
        """A copy with ``changes`` applied; unknown names raise ``InputError`` listing the valid ones."""
        unknown = sorted(set(changes) - set(self.names()))
        if unknown:
            raise InputError(f"unknown DEM parameter(s) {', '.join(map(repr, unknown))}; "
                             f"valid names: {', '.join(self.names())}")
        return dataclasses.replace(self, **{k: _coerce(k, v) for k, v in changes.items()})

    @classmethod
    def from_names(cls, values: dict) -> "DEMParameters":
        """Paper defaults with ``values`` (name -> value, values may be strings) applied."""
        return cls().with_(**dict(values))

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def _coerce(name: str, value):
    """Convert a ``--set`` string to the field's type; name the field on failure."""
    default = next(f.default for f in fields(DEMParameters) if f.name == name)
    if not isinstance(value, str):
        return value
    text = value.strip()
    if isinstance(default, str):
        return text
    if name == "mean_mass_kg" and text.lower() in ("", "none"):
        return None
    try:
        number = float(text)
    except ValueError:
        raise InputError(f"DEM parameter {name} needs a number, got {value!r}") from None
    if isinstance(default, int) and not isinstance(default, bool):
        if number != int(number):
            raise InputError(f"DEM parameter {name} needs an integer, got {value!r}")
        return int(number)
    return number
