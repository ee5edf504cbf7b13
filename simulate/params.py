"""The DEM parameter set of one simulation, with the source paper's values as defaults.

``DEMParameters`` is a frozen dataclass: change it with ``with_(**changes)`` or build it from
names (``from_names({"e_pp": 0.32})``, what ``--set NAME=VALUE`` uses); unknown names are
refused with the list of valid ones.

Defaults (docs/design.md, "Paper defaults"): the paper's measured means for the contact parameters,
its segment (``shape``), densities and time step; the particle shear modulus (1e7 Pa) is not in
the paper and is demcal's stated default. A parameter set built from a workbook takes its
material's shape and, unless the workbook states one, the time step that follows the material
(``dt=None``: ``simulate.timestep.TIME_STEP_FRACTION`` of the Rayleigh time of the shape's
smallest sphere).

The shape (``simulate.shapes``) is one field. The segment's former fields
(``segment_length_m``, ``segment_diameter_m``, ``spheres_per_clump``) are still read: they set
the sizes of a segment shape (``SEGMENT_FIELDS``).

Four engine extensions (``simulate.extensions.ENGINE_HOOKS``) are switched by fields here and
so recorded with every run; all are off by default: a velocity-dependent restitution
(``e_pp_exponent``, ``e_pw_exponent`` != 0), the spring-dashpot rolling model
(``rolling_model="epsd"``), particles drawn from a size distribution (``particle_sizes``) and
dashpots that damp the effective mass at each contact (``contact_effective_mass``). A field
renamed since (``RENAMED``) is still read under its former name, so that stored results and
truth files keep their meaning.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, fields

from demcal.errors import InputError
from demcal.simulate.clump import MASS_MODELS, ClumpTemplate
from demcal.simulate.contact.rolling import EPSD_DAMPING_RATIO, ROLLING_LEVERS, ROLLING_MODELS
from demcal.simulate.shapes import Shape, shape_class, shape_from_dict
from demcal.simulate.shapes.segment import Segment

#: The source paper's time step [s] (EDEM, 0.41 of the Rayleigh time of its 5.5 mm spheres).
PAPER_TIME_STEP = 7.43678e-5

#: Former fields of the segment -> the ``Segment`` field each sets.
SEGMENT_FIELDS = {"segment_length_m": "length_m", "segment_diameter_m": "diameter_m",
                  "spheres_per_clump": "n_spheres"}


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
    shape : simulate.shapes.Shape
        The particle: its kind and measured size (default the paper's segment, 25 x 11 mm in 5
        spheres). ``--set shape=sphere:0.0066`` style values are read by :func:`parse_shape`.
    dt : float or None
        Time step of the bulk rigs [s]; None: ``TIME_STEP_FRACTION`` of the Rayleigh time of
        the shape's smallest sphere (``simulate.timestep.material_time_step``). Default: the
        paper's.
    mass_model : str
        ``"union"`` (mass and inertia of the sphere union, EDEM's default), ``"body"`` (the body
        the shape stands for: a cylinder, a sphere, an ellipsoid), ``"cylinder"`` (a segment's
        body, its former name) or ``"scaled"`` (the union scaled to ``mean_mass_kg``).
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
    particle_sizes : tuple of tuple of float, or None
        A measured size distribution (callipers): one entry per specimen, its lengths [m] in
        the order of the shape's ``sizes`` (a segment's (length, diameter), a sphere's
        (diameter,), a kernel's (length, width, thickness)). When given, the repose scene draws
        each particle from them (equal weight per entry, duplicates counting twice;
        ``simulate.extensions.SizeDistribution``) instead of ``shape``'s one size. Default
        None (one size).
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
    shape: Shape = Segment(0.025, 0.011, 5)
    dt: float | None = PAPER_TIME_STEP
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
    particle_sizes: tuple | None = None
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
                     "wall_shear_modulus_pa"):
            value = getattr(self, name)
            if not value > 0.0:
                raise InputError(f"{name} must be > 0, got {value!r}")
        if not isinstance(self.shape, Shape):
            object.__setattr__(self, "shape", parse_shape(self.shape))
        if self.dt is not None and not (isinstance(self.dt, (int, float)) and math.isfinite(self.dt) and self.dt > 0):
            raise InputError(f"dt must be a time step > 0 [s] (or none: from the material), got {self.dt!r}")
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
        if self.particle_sizes is not None:
            object.__setattr__(self, "particle_sizes", _particle_sizes(self.shape, self.particle_sizes))
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
        A former name (``RENAMED``) sets the field it became; a former segment field
        (``SEGMENT_FIELDS``) sets the size of a segment shape."""
        changes = current_names(changes)
        segment = {SEGMENT_FIELDS[k]: _coerce_number(k, changes.pop(k), int if k == "spheres_per_clump" else float)
                   for k in list(changes) if k in SEGMENT_FIELDS}
        unknown = sorted(set(changes) - set(self.names()))
        if unknown:
            raise InputError(f"unknown DEM parameter(s) {', '.join(map(repr, unknown))}; "
                             f"valid names: {', '.join(self.names())}")
        out = {k: _coerce(k, v) for k, v in changes.items()}
        if segment:
            shape = out.get("shape", self.shape)
            if not isinstance(shape, Segment):
                raise InputError(f"{', '.join(k for k in SEGMENT_FIELDS if SEGMENT_FIELDS[k] in segment)} "
                                 f"set(s) the size of a segment; the shape is {shape.name}")
            out["shape"] = dataclasses.replace(shape, **segment)
        return dataclasses.replace(self, **out)

    def sized_shapes(self) -> tuple:
        """The shape at each entry of ``particle_sizes`` (duplicates kept), or ``(shape,)``."""
        if self.particle_sizes is None:
            return (self.shape,)
        return tuple(self.shape.with_sizes(entry) for entry in self.particle_sizes)

    def template(self, shape: Shape | None = None, name: str | None = None) -> ClumpTemplate:
        """The clump of ``shape`` (default this set's) with this set's density and mass model."""
        shape = self.shape if shape is None else shape
        return shape.template(self.particle_density_kg_m3, self.mass_model, self.mean_mass_kg, name=name)

    @classmethod
    def from_names(cls, values: dict) -> "DEMParameters":
        """Paper defaults with ``values`` (name -> value, values may be strings, former names
        read as the fields they became) applied."""
        return cls().with_(**dict(values))

    def to_dict(self) -> dict:
        d = {f.name: getattr(self, f.name) for f in fields(self)}
        d["shape"] = self.shape.to_dict()
        if not self.contact_effective_mass:
            # off is the model every stored run was made with: leaving it out keeps their keys
            del d["contact_effective_mass"]
        return d


#: Former field names -> current ones. Results files, critique files and truth files written
#: before a rename name the field the old way (``multi_contact_damping`` was switched on by
#: ``--set`` and stored with the calibrated parameters and the campaign's model extensions;
#: ``segment_sizes`` held a segment's (length, diameter) pairs, its sizes in order);
#: :func:`current_names` reads them.
RENAMED = {"multi_contact_damping": "contact_effective_mass", "segment_sizes": "particle_sizes"}


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


def _particle_sizes(shape: Shape, value) -> tuple:
    """``particle_sizes`` as a tuple of float tuples [m], each a size ``shape`` can take."""
    what = f"particle_sizes of the {shape.name} shape: each entry is ({', '.join(shape.sizes)}) [m]"
    try:
        entries = tuple(tuple(float(v) for v in entry) for entry in value)
    except (TypeError, ValueError):
        raise InputError(f"{what}; got {value!r}") from None
    if not entries:
        raise InputError(f"{what}; got none (give at least one, or None for one size)")
    for entry in entries:
        if not all(math.isfinite(v) for v in entry):
            raise InputError(f"{what}; got {entry!r}")
        try:
            shape.with_sizes(entry)
        except InputError as exc:
            raise InputError(f"particle_sizes: entry {entry!r}: {exc}") from None
    return entries


def parse_shape(value) -> Shape:
    """A shape from a ``Shape``, its ``to_dict()`` layout, that layout as JSON text, or
    ``NAME:SIZE[:SIZE...]`` in metres in the order of the shape's ``sizes`` (``sphere:0.0066``,
    ``kernel:0.0072:0.003:0.0021``, ``segment:0.025:0.011``)."""
    if isinstance(value, Shape):
        return value
    if isinstance(value, dict):
        return shape_from_dict(value)
    text = str(value).strip()
    if text.startswith("{"):
        try:
            return shape_from_dict(json.loads(text))
        except json.JSONDecodeError:
            raise InputError(f"DEM parameter shape: not JSON: {text!r}") from None
    name, *sizes = text.split(":")
    cls = shape_class(name)
    if len(sizes) != len(cls.sizes):
        raise InputError(f"DEM parameter shape: {cls.name} needs {len(cls.sizes)} size(s) [m] "
                         f"({', '.join(cls.sizes)}), e.g. {cls.name}:" + ":".join(["0.005"] * len(cls.sizes))
                         + f"; got {text!r}")
    try:
        return cls(**{n: _coerce_number(f"shape {n}", v, float) for n, v in zip(cls.sizes, sizes)})
    except TypeError:   # a shape with more than sizes (a clump's table)
        example = json.dumps({"shape": cls.name, **{n: "..." for n in cls.field_names()}})
        raise InputError(f"DEM parameter shape: give the {cls.name} shape as JSON, e.g. {example}") from None


def _coerce_number(name: str, value, kind):
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise InputError(f"DEM parameter {name} needs a number, got {value!r}") from None
    if kind is int:
        if number != int(number):
            raise InputError(f"DEM parameter {name} needs an integer, got {value!r}")
        return int(number)
    return number


def _coerce(name: str, value):
    """Convert a ``--set`` string to the field's type; name the field on failure."""
    default = next(f.default for f in fields(DEMParameters) if f.name == name)
    if name == "shape":
        return parse_shape(value)
    if not isinstance(value, str):
        return value
    text = value.strip()
    if name == "dt" and text.lower() in ("", "none", "auto"):
        return None
    if name == "particle_sizes":
        if text.lower() in ("", "none"):
            return None
        # one entry per specimen, its sizes joined by x, in metres: 0.025x0.011,0.024x0.0105
        try:
            return tuple(tuple(float(v) for v in item.lower().split("x")) for item in text.split(","))
        except ValueError:
            raise InputError(f"DEM parameter particle_sizes needs 'AxB,AxB,...' in metres (the shape's "
                             f"sizes of each specimen joined by x), got {value!r}") from None
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
