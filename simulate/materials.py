"""Materials and the per-pair contact parameters of the Hertz-Mindlin law.

Each material has a density, Poisson's ratio and shear modulus; each unordered pair of
materials has a coefficient of restitution, a static and a rolling friction coefficient (the
"interaction" table of EDEM), and optionally a velocity dependence of its restitution
(e(v) = e (max(v, v_min) / v_ref)^(-n), ``simulate.contact.hertz_mindlin``). The table also
names the rolling resistance model its rolling coefficients are meant for (``rolling_model``:
``"constant_torque"`` or ``"epsd"``, with the latter's damping ratio;
``simulate.contact.rolling``), so that every rig building its table from ``DEMParameters``
runs the model the parameters name. ``MaterialTable.compile()`` turns all this into dense
``(n_materials, n_materials)`` arrays of the pair constants used by the kernels, so the contact
loop never recomputes E*, G* or the damping ratio.

Example
-------
>>> table = MaterialTable()
>>> table.add_material("particle", density=912.0, poisson_ratio=0.25, shear_modulus=1e7)
0
>>> table.add_material("steel", density=7850.0, poisson_ratio=0.3, shear_modulus=8e10)
1
>>> table.set_pair("particle", "particle", restitution=0.3, static_friction=0.65, rolling_friction=0.53)
>>> table.set_pair("particle", "steel", restitution=0.35, static_friction=0.2, rolling_friction=0.15)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from demcal.errors import InputError
from demcal.simulate.contact.hertz_mindlin import damping_ratio, effective_modulus, effective_shear_modulus
from demcal.simulate.contact.rolling import EPSD_DAMPING_RATIO, rolling_model_index


def youngs_modulus(shear_modulus: float, poisson: float) -> float:
    """E = 2 G (1 + nu) of an isotropic solid [Pa]."""
    return 2.0 * shear_modulus * (1.0 + poisson)


@dataclass(frozen=True)
class Material:
    """A solid material.

    Attributes
    ----------
    name : str
    density : float
        [kg/m3]
    poisson_ratio : float
        [-]
    shear_modulus : float
        [Pa]
    """

    name: str
    density: float
    poisson_ratio: float
    shear_modulus: float

    @property
    def youngs_modulus(self) -> float:
        """E = 2 G (1 + nu) [Pa]."""
        return youngs_modulus(self.shear_modulus, self.poisson_ratio)

    def to_dict(self) -> dict:
        return {"name": self.name, "density": self.density, "poisson_ratio": self.poisson_ratio,
                "shear_modulus": self.shear_modulus}


@dataclass(frozen=True)
class PairContact:
    """Interaction parameters of one unordered material pair.

    Attributes
    ----------
    restitution : float
        Coefficient of restitution e in (0, 1] [-].
    static_friction : float
        Coulomb coefficient mu_s [-].
    rolling_friction : float
        Rolling friction coefficient mu_r [-] (dimensionless, as EDEM's; the torque is
        mu_r F_n times a lever arm, see ``simulate.contact.rolling``).
    restitution_exponent : float
        n of e(v) = restitution (max(v, restitution_v_min) / restitution_v_ref)^(-n), v the
        normal approach speed at first touch [-]; 0 (default): constant restitution.
    restitution_v_ref : float
        Speed at which the restitution is ``restitution`` [m/s] (used only when n != 0).
    restitution_v_min : float
        Impacts slower than this take e(v_min) [m/s]; 0 (default): the law down to e = 1.
    """

    restitution: float
    static_friction: float
    rolling_friction: float
    restitution_exponent: float = 0.0
    restitution_v_ref: float = 1.0
    restitution_v_min: float = 0.0

    def to_dict(self) -> dict:
        return {"restitution": self.restitution, "static_friction": self.static_friction,
                "rolling_friction": self.rolling_friction,
                "restitution_exponent": self.restitution_exponent,
                "restitution_v_ref": self.restitution_v_ref,
                "restitution_v_min": self.restitution_v_min}


@dataclass(frozen=True)
class PairArrays:
    """Dense pair-constant tables indexed ``[material_i, material_j]`` (symmetric).

    Attributes
    ----------
    e_star : ndarray
        Effective Young's modulus E* [Pa].
    g_star : ndarray
        Effective shear modulus G* [Pa].
    damping : ndarray
        2 sqrt(5/6) |beta| [-], the factor of the normal and tangential dashpots.
    mu_s, mu_r : ndarray
        Static and rolling friction coefficients [-].
    log_e, e_exponent, log_v_ref, v_min : ndarray
        ln e, the exponent n [-], ln v_ref (v_ref in [m/s]) and v_min [m/s] of the
        velocity-dependent restitution (n = 0: constant e, the ``damping`` table).
    rolling_model : int
        Kernel index of the rolling model (``simulate.contact.rolling.ROLLING_MODELS``).
    rolling_damping_ratio : float
        eta_r of the spring-dashpot rolling model [-].
    contact_effective_mass : bool
        Normal dashpots damp the body's effective mass at each contact, shared among its
        simultaneous contacts (``simulate.extensions``, ``contact_effective_mass``).
    """

    e_star: np.ndarray
    g_star: np.ndarray
    damping: np.ndarray
    mu_s: np.ndarray
    mu_r: np.ndarray
    log_e: np.ndarray
    e_exponent: np.ndarray
    log_v_ref: np.ndarray
    v_min: np.ndarray
    rolling_model: int = 0
    rolling_damping_ratio: float = EPSD_DAMPING_RATIO
    contact_effective_mass: bool = False

    @property
    def velocity_restitution(self) -> bool:
        """True if any defined pair has a velocity-dependent restitution."""
        n = self.e_exponent[np.isfinite(self.e_exponent)]
        return bool(np.any(n != 0.0))


class MaterialTable:
    """Materials by name and the contact parameters of every pair used.

    Parameters
    ----------
    rolling_model : str
        Rolling resistance model of every contact: ``"constant_torque"`` (default) or
        ``"epsd"`` (``simulate.contact.rolling``).
    rolling_damping_ratio : float
        eta_r of the ``"epsd"`` model [-] (default 0.3, Ai et al. 2011).
    contact_effective_mass : bool
        Normal dashpots damp the body's effective mass at each contact, shared among its
        simultaneous contacts (default False: each damps with the whole mass, as LIGGGHTS'
        multisphere does).
    """

    def __init__(self, rolling_model: str = "constant_torque",
                 rolling_damping_ratio: float = EPSD_DAMPING_RATIO, contact_effective_mass: bool = False):
        rolling_model_index(rolling_model)
        if not (isinstance(rolling_damping_ratio, (int, float)) and math.isfinite(rolling_damping_ratio)
                and rolling_damping_ratio >= 0.0):
            raise InputError(f"rolling_damping_ratio must be a finite number >= 0, got {rolling_damping_ratio!r}")
        self.rolling_model = rolling_model
        self.rolling_damping_ratio = float(rolling_damping_ratio)
        self.contact_effective_mass = bool(contact_effective_mass)
        self._materials: dict[str, Material] = {}
        self._pairs: dict[frozenset, PairContact] = {}

    # ---- building ----
    def add_material(self, name: str, *, density: float, poisson_ratio: float,
                     shear_modulus: float) -> int:
        """Add a material; returns its index. Density [kg/m3], shear modulus [Pa]."""
        if name in self._materials:
            raise InputError(f"material {name!r} is already defined")
        for label, value in (("density", density), ("shear_modulus", shear_modulus)):
            if not (np.isfinite(value) and value > 0):
                raise InputError(f"material {name!r}: {label} must be > 0, got {value!r}")
        if not -1.0 < poisson_ratio < 0.5:
            raise InputError(f"material {name!r}: poisson_ratio must be in (-1, 0.5), got {poisson_ratio!r}")
        self._materials[name] = Material(name, float(density), float(poisson_ratio), float(shear_modulus))
        return len(self._materials) - 1

    def set_pair(self, a: str, b: str, *, restitution: float, static_friction: float,
                 rolling_friction: float, restitution_exponent: float = 0.0,
                 restitution_v_ref: float = 1.0, restitution_v_min: float = 0.0) -> None:
        """Set the interaction of materials ``a`` and ``b`` (order does not matter).

        ``restitution_exponent`` n [-], ``restitution_v_ref`` and ``restitution_v_min`` [m/s]
        make the restitution depend on the impact speed, e(v) = restitution
        (max(v, v_min) / v_ref)^(-n) (default n = 0: constant).
        """
        for name in (a, b):
            self.index(name)
        if not 0.0 < restitution <= 1.0:
            raise InputError(f"pair {a}-{b}: restitution must be in (0, 1], got {restitution!r}")
        for label, value in (("static_friction", static_friction), ("rolling_friction", rolling_friction)):
            if not value >= 0.0:
                raise InputError(f"pair {a}-{b}: {label} must be >= 0, got {value!r}")
        if not math.isfinite(restitution_exponent):
            raise InputError(f"pair {a}-{b}: restitution_exponent must be a finite number, "
                             f"got {restitution_exponent!r}")
        if not (math.isfinite(restitution_v_ref) and restitution_v_ref > 0.0):
            raise InputError(f"pair {a}-{b}: restitution_v_ref must be > 0 [m/s], got {restitution_v_ref!r}")
        if not (math.isfinite(restitution_v_min) and restitution_v_min >= 0.0):
            raise InputError(f"pair {a}-{b}: restitution_v_min must be >= 0 [m/s], got {restitution_v_min!r}")
        self._pairs[frozenset((a, b))] = PairContact(float(restitution), float(static_friction),
                                                     float(rolling_friction),
                                                     float(restitution_exponent),
                                                     float(restitution_v_ref),
                                                     float(restitution_v_min))

    # ---- reading ----
    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self._materials)

    def index(self, name: str) -> int:
        """Index of material ``name``; an unknown name lists the defined ones."""
        try:
            return list(self._materials).index(name)
        except ValueError:
            defined = ", ".join(self._materials) or "none"
            raise InputError(f"unknown material {name!r}; defined: {defined}") from None

    def material(self, name: str) -> Material:
        return self._materials[self.names[self.index(name)]]

    def pair(self, a: str, b: str) -> PairContact:
        try:
            return self._pairs[frozenset((a, b))]
        except KeyError:
            raise InputError(f"no contact parameters for material pair {a}-{b}; use set_pair()") from None

    def compile(self) -> PairArrays:
        """Dense pair tables for the kernels. Pairs never set get NaN (a contact between them
        is refused when the body or wall is added, see ``Simulation``)."""
        n = len(self._materials)
        out = {k: np.full((n, n), np.nan) for k in ("e_star", "g_star", "damping", "mu_s", "mu_r",
                                                     "log_e", "e_exponent", "log_v_ref", "v_min")}
        mats = list(self._materials.values())
        for i, mi in enumerate(mats):
            for j, mj in enumerate(mats):
                out["e_star"][i, j] = effective_modulus(mi.youngs_modulus, mi.poisson_ratio,
                                                        mj.youngs_modulus, mj.poisson_ratio)
                out["g_star"][i, j] = effective_shear_modulus(mi.shear_modulus, mi.poisson_ratio,
                                                              mj.shear_modulus, mj.poisson_ratio)
                p = self._pairs.get(frozenset((mi.name, mj.name)))
                if p is not None:
                    out["damping"][i, j] = 2.0 * np.sqrt(5.0 / 6.0) * abs(damping_ratio(p.restitution))
                    out["mu_s"][i, j] = p.static_friction
                    out["mu_r"][i, j] = p.rolling_friction
                    out["log_e"][i, j] = math.log(p.restitution)
                    out["e_exponent"][i, j] = p.restitution_exponent
                    out["log_v_ref"][i, j] = math.log(p.restitution_v_ref)
                    out["v_min"][i, j] = p.restitution_v_min
        return PairArrays(**out, rolling_model=rolling_model_index(self.rolling_model),
                          rolling_damping_ratio=self.rolling_damping_ratio,
                          contact_effective_mass=self.contact_effective_mass)

    def has_pair(self, a: str, b: str) -> bool:
        return frozenset((a, b)) in self._pairs

    def to_dict(self) -> dict:
        return {"materials": [m.to_dict() for m in self._materials.values()],
                "pairs": [{"a": sorted(k)[0], "b": sorted(k)[-1], **p.to_dict()}
                          for k, p in self._pairs.items()],
                "rolling_model": self.rolling_model, "rolling_damping_ratio": self.rolling_damping_ratio,
                "contact_effective_mass": self.contact_effective_mass}

    @classmethod
    def from_parameters(cls, params, particle: str = "particle", wall: str = "steel") -> "MaterialTable":
        """The two-material table (particle, wall) of a ``DEMParameters``, with its restitution
        laws and rolling model."""
        table = cls(rolling_model=params.rolling_model, rolling_damping_ratio=params.rolling_damping_ratio,
                    contact_effective_mass=params.contact_effective_mass)
        table.add_material(particle, density=params.particle_density_kg_m3,
                           poisson_ratio=params.poisson_ratio, shear_modulus=params.shear_modulus_pa)
        table.add_material(wall, density=params.wall_density_kg_m3,
                           poisson_ratio=params.wall_poisson_ratio,
                           shear_modulus=params.wall_shear_modulus_pa)
        table.set_pair(particle, particle, **pair_contact(params, "pp"))
        table.set_pair(particle, wall, **pair_contact(params, "pw"))
        return table


def pair_contact(params, pair: str) -> dict:
    """``set_pair`` keywords of a ``DEMParameters`` pair: ``"pp"`` (particle-particle) or
    ``"pw"`` (particle-wall)."""
    if pair not in ("pp", "pw"):
        raise InputError(f"pair must be 'pp' or 'pw', got {pair!r}")
    return {"restitution": getattr(params, f"e_{pair}"),
            "static_friction": getattr(params, f"mu_s_{pair}"),
            "rolling_friction": getattr(params, f"mu_r_{pair}"),
            "restitution_exponent": getattr(params, f"e_{pair}_exponent"),
            "restitution_v_ref": getattr(params, f"e_{pair}_v_ref"),
            "restitution_v_min": getattr(params, f"e_{pair}_v_min")}
