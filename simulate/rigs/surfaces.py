"""The plate a single segment meets in the drop and incline rigs: its material and contact.

The lab names the plate by a material pair (drop sheet, ``pair``: ``particle-steel``) or by a
surface (incline sheet, ``surface``: ``steel``). The twins build it the same way:

``steel`` (``particle-steel``)
    The wall material of the ``DEMParameters`` (density, Poisson's ratio, shear modulus) with
    the particle-wall contact parameters ``e_pw``, ``mu_s_pw``, ``mu_r_pw``.
``particle`` (``particle-particle``)
    A flat plate of the particle material (in the lab: segments glued side by side) with the
    particle-particle parameters ``e_pp``, ``mu_s_pp``, ``mu_r_pp`` (and the velocity
    dependence ``e_pp_exponent``, ``e_pp_v_ref``). A plane has an infinite
    radius, so the contact radius R* is the sphere's own radius, twice the R* of two equal
    spheres; a clump lying on glued clumps also touches them at ridges and grooves, which a
    flat plate does not model.
any other name (``particle-rubber``, ``rubber``)
    Needs the material (``surface_material``: ``density`` [kg/m3], ``poisson_ratio`` [-],
    ``shear_modulus`` [Pa]) and the pair's contact parameters (``surface_contact``:
    ``restitution``, ``static_friction``, ``rolling_friction`` [-]).
"""

from __future__ import annotations

from dataclasses import dataclass

from demcal.errors import InputError
from demcal.simulate.materials import MaterialTable, pair_contact
from demcal.simulate.params import DEMParameters

#: Material name of the bodies in every rig.
PARTICLE = "particle"
#: Surfaces defined by ``DEMParameters`` alone.
BUILT_IN_SURFACES = ("steel", "particle")
MATERIAL_KEYS = ("density", "poisson_ratio", "shear_modulus")
CONTACT_KEYS = ("restitution", "static_friction", "rolling_friction")


@dataclass(frozen=True)
class Surface:
    """A rig's plate: the material table of body and plate, and the plate's material name.

    Attributes
    ----------
    name : str
        Surface name as the lab gives it (``steel``, ``particle``, ``rubber``...).
    plate_material : str
        Name of the plate's material in ``materials``.
    materials : MaterialTable
        Particle material, plate material and their pair (and the particle pair).
    """

    name: str
    plate_material: str
    materials: MaterialTable

    def to_dict(self) -> dict:
        return {"name": self.name, "plate_material": self.plate_material,
                "materials": self.materials.to_dict()}


def surface_from_pair(pair: str) -> str:
    """Surface name of a lab pair ``particle-<surface>`` (e.g. ``particle-steel`` -> ``steel``)."""
    text = str(pair).strip()
    head, sep, tail = text.partition("-")
    if head != PARTICLE or not sep or not tail:
        raise InputError(f"pair must be 'particle-<material>' (e.g. particle-steel, "
                         f"particle-particle, particle-rubber), got {pair!r}")
    return tail


def make_surface(params: DEMParameters, surface: str = "steel", *, surface_material: dict | None = None,
                 surface_contact: dict | None = None) -> Surface:
    """The material table of a rig whose body of ``params``' particle material meets a plate.

    Parameters
    ----------
    params : DEMParameters
        Particle and wall (steel) properties and their contact parameters.
    surface : str
        ``"steel"``, ``"particle"`` or the name of another material.
    surface_material : dict, optional
        For another material: ``density`` [kg/m3], ``poisson_ratio`` [-], ``shear_modulus`` [Pa].
    surface_contact : dict, optional
        For another material: the particle-surface ``restitution``, ``static_friction`` and
        ``rolling_friction`` [-].

    Returns
    -------
    Surface
    """
    name = str(surface).strip()
    if not name:
        raise InputError("surface must be a material name (steel, particle, ...), got ''")
    if name in BUILT_IN_SURFACES:
        extra = [k for k, v in (("surface_material", surface_material),
                                ("surface_contact", surface_contact)) if v]
        if extra:
            raise InputError(f"surface {name!r} takes its properties from the DEM parameters; "
                             f"do not give {', '.join(extra)}")
    table = MaterialTable.from_parameters(params, particle=PARTICLE, wall="steel")
    if name == "steel":
        return Surface(name, "steel", table)
    if name == "particle":
        plate = "particle plate"
        table.add_material(plate, density=params.particle_density_kg_m3,
                           poisson_ratio=params.poisson_ratio, shear_modulus=params.shear_modulus_pa)
        table.set_pair(PARTICLE, plate, **pair_contact(params, "pp"))
        return Surface(name, plate, table)
    material = _checked(surface_material, MATERIAL_KEYS, f"surface_material of {name!r}")
    contact = _checked(surface_contact, CONTACT_KEYS, f"surface_contact of particle-{name}")
    table.add_material(name, **material)
    table.set_pair(PARTICLE, name, **contact)
    return Surface(name, name, table)


def _checked(values: dict | None, keys: tuple, label: str) -> dict:
    if not values:
        raise InputError(f"{label} is needed (keys {', '.join(keys)}): only "
                         f"{', '.join(BUILT_IN_SURFACES)} are defined by the DEM parameters")
    unknown = sorted(set(values) - set(keys))
    missing = [k for k in keys if k not in values]
    if unknown or missing:
        raise InputError(f"{label}: needs exactly the keys {', '.join(keys)}"
                         + (f"; unknown {', '.join(unknown)}" if unknown else "")
                         + (f"; missing {', '.join(missing)}" if missing else ""))
    out = {}
    for k in keys:
        try:
            out[k] = float(values[k])
        except (TypeError, ValueError):
            raise InputError(f"{label}: {k} needs a number, got {values[k]!r}") from None
    return out


def surface_options(items) -> dict:
    """``--surface-material KEY=VALUE`` items of ``demcal simulate`` -> the rig options
    ``surface_material`` and ``surface_contact``; a bad item names itself and the valid keys."""
    if not items:
        return {}
    values = {}
    for item in items:
        key, sep, value = str(item).partition("=")
        key = key.strip()
        if not sep or key not in MATERIAL_KEYS + CONTACT_KEYS:
            raise InputError(f"--surface-material {item!r}: expected KEY=VALUE with KEY one of "
                             f"{', '.join(MATERIAL_KEYS + CONTACT_KEYS)}")
        try:
            values[key] = float(value)
        except ValueError:
            raise InputError(f"--surface-material {key}: needs a number, got {value!r}") from None
    return {"surface_material": {k: v for k, v in values.items() if k in MATERIAL_KEYS},
            "surface_contact": {k: v for k, v in values.items() if k in CONTACT_KEYS}}
