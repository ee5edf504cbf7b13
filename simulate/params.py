"""The DEM parameter set of one simulation, with the source paper's values as defaults.

``DEMParameters`` is a frozen dataclass: change it with ``with_(**changes)`` or build it from
names (``from_names({"e_pp": 0.32})``, what ``--set NAME=VALUE`` uses); unknown names are
refused with the list of valid ones.

Defaults (docs/design.md, "Paper defaults"): the paper's measured means for the contact parameters,
its segment geometry and densities; the particle shear modulus (1e7 Pa) is not in the paper and
is demcal's stated default.

Four engine extensions (``simulate.extensions.ENGINE_HOOKS``) are switched by fields here and
so recorded with every run; all are off by default: a velocity-dependent restitution
(``e_pp_exponent``, ``e_pw_exponent`` != 0), the spring-dashpot rolling model
(``rolling_model="epsd"``), segments drawn from a size distribution (``segment_sizes``) and
dashpots that damp the effective mass at each contact (``contact_effective_mass``). A field
renamed since (``RENAMED``) is still read under its former name, so that stored results and
truth files keep their meaning.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, fields

from demcal.errors import InputError
from demcal.simulate.clump import MASS_MODELS
from demcal.simulate.contact.rolling import EPSD_DAMPING_RATIO, ROLLING_LEVERS, ROLLING_MODELS


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
        reason for the default. Used by the ``constant_torque`` rolling model only.
    e_pp_exponent, e_pw_exponent : float
        Velocity-dependent restitution (engine hook): exponent n [-] of
        e(v) = e_pp (max(v, e_pp_v_min) / e_pp_v_ref)^(-n) (and the same for ``pw``), v the
        normal approach speed of a contact at first touch, e capped to [1e-6, 1]; 0 (default):
        constant restitution. n > 0 when e falls with speed (1/4 for plastic impacts, Johnson
        1985).
    e_pp_v_ref, e_pw_v_ref : float
        Impact speed at which the restitution is ``e_pp`` (``e_pw``) [m/s]; default 1.
    e_pp_v_min, e_pw_v_min : float
        Impacts slower than this take e(v_min) [m/s], e.g. the slowest measured drop; default
        0: the law all the way down, so that impacts slower than v_ref e^(1/n) are elastic
        (e = 1) and a body on a plate never stops bouncing.
    rolling_model : str
        Rolling resistance model: ``"constant_torque"`` (default; EDEM type A with the
        ``rolling_lever`` conventions) or ``"epsd"`` (elastic-plastic spring-dashpot, Ai et al.
        2011 type C); ``simulate.contact.rolling``.
    rolling_damping_ratio : float
        Rolling damping ratio eta_r of the ``"epsd"`` model [-] (default 0.3, Ai et al. 2011).
    segment_sizes : tuple of (float, float) or None
        (length, diameter) pairs [m] of a measured size distribution (callipers): when given,
        the repose scene draws each segment from them (equal weight per pair, duplicates
        counting twice; ``simulate.extensions.SizeDistribution``) instead of
        ``segment_length_m`` x ``segment_diameter_m``. Default None (one size).
    contact_effective_mass : bool
        Engine hook (``simulate.extensions``): each normal dashpot damps the body's effective
        mass at its contact, rotation included, shared among the body's simultaneous contacts
        (``simulate.integrate.damping_inverse_mass``), so that a segment landing flat on several
        spheres damps like one contact and one striking with an end sphere rebounds as a rigid
        body. Default False (each contact damps with the whole mass, as LIGGGHTS and EDEM).
        Formerly ``multi_contact_damping``.
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
    e_pp_exponent: float = 0.0
    e_pp_v_ref: float = 1.0
    e_pw_exponent: float = 0.0
    e_pw_v_ref: float = 1.0
    e_pp_v_min: float = 0.0
    e_pw_v_min: float = 0.0
    rolling_model: str = "constant_torque"
    rolling_damping_ratio: float = EPSD_DAMPING_RATIO
    segment_sizes: tuple | None = None
    contact_effective_mass: bool = False

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
        for name in ("e_pp_exponent", "e_pw_exponent"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value)):
                raise InputError(f"{name} must be a finite number (0 for a constant restitution), got {value!r}")
        for name in ("e_pp_v_ref", "e_pw_v_ref"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0.0):
                raise InputError(f"{name} must be a speed > 0 [m/s], got {value!r}")
        for name in ("e_pp_v_min", "e_pw_v_min"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0.0):
                raise InputError(f"{name} must be a speed >= 0 [m/s] (0: no floor), got {value!r}")
        if self.rolling_model not in ROLLING_MODELS:
            raise InputError(f"rolling_model must be one of {', '.join(ROLLING_MODELS)}; "
                             f"got {self.rolling_model!r}")
        value = self.rolling_damping_ratio
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0.0):
            raise InputError(f"rolling_damping_ratio must be a finite number >= 0, got {value!r}")
        if self.segment_sizes is not None:
            object.__setattr__(self, "segment_sizes", _size_pairs(self.segment_sizes))
        if self.contact_effective_mass not in (True, False, 0, 1):
            raise InputError(f"contact_effective_mass must be true or false (1 or 0), "
                             f"got {self.contact_effective_mass!r}")
        object.__setattr__(self, "contact_effective_mass", bool(self.contact_effective_mass))

    @classmethod
    def names(cls) -> tuple[str, ...]:
        """The valid parameter names."""
        return tuple(f.name for f in fields(cls))

    def with_(self, **changes) -> "DEMParameters":
        """A copy with ``changes`` applied; unknown names raise ``InputError`` listing the valid ones.
        A former name (``RENAMED``) sets the field it became."""
        changes = current_names(changes)
        unknown = sorted(set(changes) - set(self.names()))
        if unknown:
            raise InputError(f"unknown DEM parameter(s) {', '.join(map(repr, unknown))}; "
                             f"valid names: {', '.join(self.names())}")
        return dataclasses.replace(self, **{k: _coerce(k, v) for k, v in changes.items()})

    @classmethod
    def from_names(cls, values: dict) -> "DEMParameters":
        """Paper defaults with ``values`` (name -> value, values may be strings, former names
        read as the fields they became) applied."""
        return cls().with_(**dict(values))

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        if not self.contact_effective_mass:
            # off is the model every stored run was made with: leaving it out keeps their keys
            del d["contact_effective_mass"]
        return d


#: Former field names -> current ones. Results files, critique files and truth files written
#: before a rename name the field the old way (``multi_contact_damping`` was switched on by
#: ``--set`` and stored with the calibrated parameters and the campaign's model extensions);
#: :func:`current_names` reads them.
RENAMED = {"multi_contact_damping": "contact_effective_mass"}


def current_names(values: dict) -> dict:
    """``values`` (field name -> value) with former names (``RENAMED``) replaced by the current
    ones; a field given under both names is refused."""
    out = dict(values)
    for old, new in RENAMED.items():
        if old in out:
            if new in out:
                raise InputError(f"DEM parameter {new} is given twice, also under its former name {old}")
            out[new] = out.pop(old)
    return out


def _size_pairs(value) -> tuple:
    """``segment_sizes`` as a tuple of (length, diameter) float pairs [m], checked."""
    try:
        pairs = tuple((float(length), float(dia)) for length, dia in value)
    except (TypeError, ValueError):
        raise InputError(f"segment_sizes must be a list of (length, diameter) pairs [m], "
                         f"got {value!r}") from None
    if not pairs:
        raise InputError("segment_sizes must hold at least one (length, diameter) pair, or be None")
    for length, dia in pairs:
        if not (math.isfinite(length) and math.isfinite(dia) and 0.0 < dia <= length):
            raise InputError(f"segment_sizes: each pair needs 0 < diameter <= length [m], got "
                             f"length {length!r}, diameter {dia!r}")
    return pairs


def _coerce(name: str, value):
    """Convert a ``--set`` string to the field's type; name the field on failure."""
    default = next(f.default for f in fields(DEMParameters) if f.name == name)
    if not isinstance(value, str):
        return value
    text = value.strip()
    if name == "segment_sizes":
        if text.lower() in ("", "none"):
            return None
        # "LxD,LxD,..." in metres, e.g. 0.025x0.011,0.024x0.0105
        try:
            return tuple(tuple(float(v) for v in item.lower().split("x")) for item in text.split(","))
        except ValueError:
            raise InputError(f"DEM parameter segment_sizes needs 'LxD,LxD,...' in metres, "
                             f"got {value!r}") from None
    if isinstance(default, str):
        return text
    if isinstance(default, bool):
        flag = {"true": True, "yes": True, "on": True, "1": True, "false": False, "no": False, "off": False, "0": False}
        if text.lower() not in flag:
            raise InputError(f"DEM parameter {name} needs true or false, got {value!r}")
        return flag[text.lower()]
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
