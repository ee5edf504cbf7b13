"""The critical time step of a Hertzian DEM: the Rayleigh time.

    T_R = pi R sqrt(rho / G) / (0.1631 nu + 0.8766),

the time a Rayleigh surface wave takes to cross a sphere of radius R (Li, Xu & Thornton 2005;
the form used by EDEM, which recommends a step of 20-40 % of T_R). R is the smallest sphere,
rho, G and nu its material's density, shear modulus and Poisson's ratio.

demcal refuses a step above ``DEFAULT_MAX_FRACTION`` = 0.5 of T_R. The paper's 7.43678e-5 s is
0.41 T_R for its 5.5 mm spheres at G = 1e7 Pa, nu = 0.25, rho = 912 kg/m3. A parameter set that
states no step (``DEMParameters.dt`` None, what a workbook without ``time_step_s`` gives) runs
at ``TIME_STEP_FRACTION`` = 0.2 of T_R of its shape's smallest sphere, the lower end of EDEM's
recommendation (:func:`material_time_step`).

Accuracy at that step: a Hertz impact of these spheres at 0.5-2 m/s lasts only 6-8 steps, so
the restitution the integrator realises differs from the set one: measured for a sphere on
steel and two spheres, e = 0.3 gives 0.30-0.32, e = 0.35 gives 0.36-0.37, e = 0.5 gives
0.51-0.52 and e = 0.1 gives 0.07-0.08. At dt < 0.01 T_R it is within 1 % (the tests).

References
----------
Li, Y., Xu, Y., Thornton, C. (2005). A comparison of discrete element simulations and
experiments for 'sandpiles' composed of spherical particles. Powder Technol. 160, 219-228.
DEM Solutions (2018). EDEM 2018 User Guide, "Time step".
"""

from __future__ import annotations

import math

from demcal.errors import InputError, UnsafeTimeStepError

DEFAULT_MAX_FRACTION = 0.5

#: Fraction of the Rayleigh time a parameter set without a stated time step runs at.
TIME_STEP_FRACTION = 0.2

#: How a user changes the time step, for the messages that refuse one.
TIME_STEP_OPTION = "--set dt=SECONDS (or dt=none for 0.2 of the Rayleigh time)"


def rayleigh_time(radius: float, density: float, shear_modulus: float, poisson_ratio: float) -> float:
    """Rayleigh time T_R [s] of a sphere of ``radius`` [m], ``density`` [kg/m3],
    ``shear_modulus`` [Pa] and ``poisson_ratio`` [-]."""
    if not (radius > 0 and density > 0 and shear_modulus > 0):
        raise InputError(f"rayleigh_time needs positive radius, density and shear modulus, got "
                         f"{radius!r}, {density!r}, {shear_modulus!r}")
    return math.pi * radius * math.sqrt(density / shear_modulus) / (0.1631 * poisson_ratio + 0.8766)


def check_time_step(dt: float, t_rayleigh: float, max_fraction: float = DEFAULT_MAX_FRACTION,
                    force: bool = False) -> float:
    """Return dt / T_R; raise ``UnsafeTimeStepError`` if it exceeds ``max_fraction`` (unless ``force``)."""
    if not (dt > 0 and math.isfinite(dt)):
        raise InputError(f"time step dt must be a positive number [s], got {dt!r}")
    fraction = dt / t_rayleigh
    if fraction > max_fraction and not force:
        raise UnsafeTimeStepError(
            f"time step dt = {dt:.6g} s is {fraction:.3f} of the Rayleigh time T_R = {t_rayleigh:.6g} s, "
            f"above the allowed fraction {max_fraction:g} (limit dt <= {max_fraction * t_rayleigh:.6g} s); "
            f"give a smaller time step: {TIME_STEP_OPTION}")
    return fraction


def smallest_radius(params) -> float:
    """Radius [m] of the smallest sphere a ``DEMParameters`` puts in a scene (its shape's, and
    a size distribution's)."""
    return min(float(shape.spheres()[1].min()) for shape in (params.shape, *params.sized_shapes()))


def material_rayleigh_time(params) -> float:
    """T_R [s] of the smallest sphere of a ``DEMParameters`` at its particle material."""
    return rayleigh_time(smallest_radius(params), params.particle_density_kg_m3, params.shear_modulus_pa,
                         params.poisson_ratio)


def material_time_step(params) -> float:
    """The time step [s] of the bulk rigs for a ``DEMParameters``: its ``dt`` when it states one
    (refused above ``DEFAULT_MAX_FRACTION`` of the Rayleigh time, naming the option), else
    ``TIME_STEP_FRACTION`` of the Rayleigh time of its smallest sphere."""
    t_r = material_rayleigh_time(params)
    if params.dt is None:
        return TIME_STEP_FRACTION * t_r
    check_time_step(float(params.dt), t_r)
    return float(params.dt)
