"""The DEM parameters a campaign calibrates: the lab quantity that measures each, their
admissible ranges, and the parameters that follow from the workbook without calibration.

Every stage that turns a measurement into DEM parameters (the campaign, its joint likelihood,
the plausible set, the critique's twins) reads them here.
"""

from __future__ import annotations


#: Screening factors: letter, DEM parameter, measured quantity (``{wall}`` = the rig's plate
#: material from the workbook meta), as the source paper's Plackett-Burman table.
SCREENING_FACTORS = (
    ("A", "poisson_ratio", "poisson_ratio"),
    ("B", "e_pp", "restitution.particle-particle"),
    ("C", "mu_s_pp", "static_friction.particle"),
    ("D", "mu_r_pp", "rolling_friction.particle"),
    ("E", "e_pw", "restitution.particle-{wall}"),
    ("F", "mu_s_pw", "static_friction.{wall}"),
    ("G", "mu_r_pw", "rolling_friction.{wall}"),
)

#: Admissible range of each DEM parameter; design levels are clipped into it.
PARAMETER_BOUNDS = {"poisson_ratio": (0.0, 0.49), "e_pp": (0.01, 1.0), "e_pw": (0.01, 1.0),
                    "mu_s_pp": (0.0, 5.0), "mu_s_pw": (0.0, 5.0), "mu_r_pp": (0.0, 5.0),
                    "mu_r_pw": (0.0, 5.0)}


def wall_of(meta: dict) -> str:
    """The rig's plate material from the workbook meta (default ``steel``): the DEM's wall."""
    return str(meta.get("contact_material") or "steel").strip().lower() or "steel"


def base_parameters(measurement):
    """DEM parameters from the measured shape, density and materials (meta), paper defaults
    for the rest. The time step is the meta ``time_step_s`` when the workbook states one, else
    the one that follows the material (``simulate.timestep.material_time_step``). Returns a
    ``simulate.params.DEMParameters``."""
    from demcal.simulate.params import DEMParameters

    q, meta = measurement.quantities, measurement.meta
    changes = {"dt": meta.get("time_step_s")}
    if measurement.shape:
        changes["shape"] = measurement.shape
    if "particle_density_kg_m3" in q:
        changes["particle_density_kg_m3"] = q["particle_density_kg_m3"].value
    for key, name in (("particle_shear_modulus_pa", "shear_modulus_pa"),
                      ("contact_density_kg_m3", "wall_density_kg_m3"),
                      ("contact_poisson", "wall_poisson_ratio"),
                      ("contact_shear_modulus_pa", "wall_shear_modulus_pa")):
        if meta.get(key) not in (None, ""):
            changes[name] = float(meta[key])
    return DEMParameters().with_(**changes)
