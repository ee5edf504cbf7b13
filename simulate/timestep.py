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

Damping. The Rayleigh rule ignores the dashpots, and a hard-damped contact needs a smaller
step. The kick-drift-kick scheme (``simulate.integrate``: the force at step n+1 sees the
half-step velocity) applied to a spring-dashpot of frequency w and damping ratio z is stable
for w dt < 2 (sqrt(1 + z^2) - z) (derived from its amplification matrix; the same limit as the
central-difference scheme, Belytschko, Liu & Moran 2000, ch. 6). The Hertz-Mindlin dashpot
has z = sqrt(5/6) |beta| on the normal tangent stiffness; the tangential one damps with the
whole mass m* while the contact point of a sphere moves as m*/3.5 (rotation included), so its
z is sqrt(3.5) times larger and its mode the first to go unstable: at e = 0.01, z_t = 1.41
and the stable step is 0.32 of the undamped one. demcal allows

    dt <= T_R min(DEFAULT_MAX_FRACTION, DAMPED_LIMIT_SCALE (sqrt(1 + z_t^2) - z_t)),

z_t at the lowest restitution a run can meet (:func:`damped_max_fraction`). The scale 1 puts
the undamped limit of that mode at one T_R. Measured on the paper's heap (the quick repose
twin of its segments, e_pw 0.41, mu_s_pp 0.64, mu_r_pp 0.50; seeds 1-6): at e_pp = 0.012,
where the rule allows 0.32 T_R, 2 of 6 heaps ran away at 0.41 T_R, none of 4 at 0.35 or 0.29;
at e = 0.9 none of 4 at 0.82 T_R, 2 of 4 at 1.03 and 4 of 4 at 1.24. The ratio of the onsets,
about 2.5, is the tangential mode's (2.9) rather than the normal one's (1.9).

A step that the material states (the workbook's ``time_step_s``, ``--set dt``) and that lies
above the damped limit but below ``DEFAULT_MAX_FRACTION`` is divided into the fewest equal
sub-steps that satisfy it (:func:`material_time_step`; the runs record the step they ran at):
a calibration keeps the paper's step where it is safe (restitution above about 0.1) and
crosses the low restitutions its priors allow without running away.

References
----------
Belytschko, T., Liu, W. K., Moran, B. (2000). Nonlinear Finite Elements for Continua and
Structures. Wiley.
Li, Y., Xu, Y., Thornton, C. (2005). A comparison of discrete element simulations and
experiments for 'sandpiles' composed of spherical particles. Powder Technol. 160, 219-228.
DEM Solutions (2018). EDEM 2018 User Guide, "Time step".
"""

from __future__ import annotations

import math

from demcal.errors import InputError, UnsafeTimeStepError
from demcal.simulate.contact.hertz_mindlin import LOG_E_MIN, SQRT_5_6, damping_ratio

DEFAULT_MAX_FRACTION = 0.5

#: The damped limit's scale: the undamped stable step of a sphere's tangential mode, in T_R.
DAMPED_LIMIT_SCALE = 1.0

#: A sphere's contact point moves as m / (1 + m R^2 / I) = m / 3.5 under a tangential force.
TANGENTIAL_MASS_FACTOR = 3.5

#: Lowest restitution a velocity-dependent law reaches.
RESTITUTION_FLOOR = math.exp(LOG_E_MIN)

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


def stable_step_ratio(zeta: float) -> float:
    """sqrt(1 + z^2) - z: the stable step of a spring-dashpot of damping ratio ``zeta`` [-]
    over the undamped one (w dt < 2 of the kick-drift-kick scheme)."""
    return math.sqrt(1.0 + zeta * zeta) - zeta


def contact_damping_ratios(restitution: float) -> tuple[float, float]:
    """Damping ratios (normal, tangential) [-] of a Hertz-Mindlin contact of a sphere at
    ``restitution``: sqrt(5/6) |beta| on the tangent stiffness, and sqrt(3.5) times it for the
    tangential mode (dashpot on m*, contact point moving as m*/3.5)."""
    if not (0.0 < restitution <= 1.0):
        raise InputError(f"restitution must lie in (0, 1], got {restitution!r}")
    zeta_n = SQRT_5_6 * abs(damping_ratio(restitution))
    return zeta_n, math.sqrt(TANGENTIAL_MASS_FACTOR) * zeta_n


def damped_max_fraction(restitution: float) -> float:
    """Largest dt / T_R allowed for contacts of ``restitution`` [-]: the undamped
    ``DEFAULT_MAX_FRACTION``, or less where the tangential dashpot limits the step."""
    return min(DEFAULT_MAX_FRACTION,
               DAMPED_LIMIT_SCALE * stable_step_ratio(contact_damping_ratios(restitution)[1]))


def lowest_safe_restitution(fraction: float) -> float:
    """The lowest restitution [-] whose damped limit (:func:`damped_max_fraction`) allows a
    step of ``fraction`` of T_R; ``RESTITUTION_FLOOR`` when every one does. The limit inverted
    in closed form: sqrt(1 + z^2) - z = f gives z = (1 - f^2) / (2 f), then |beta| = z_t /
    sqrt(3.5 x 5/6) and ln e = -pi |beta| / sqrt(1 - beta^2)."""
    f = fraction / DAMPED_LIMIT_SCALE
    if not f > 0.0:
        raise InputError(f"fraction must be positive, got {fraction!r}")
    beta = (1.0 - f * f) / (2.0 * f) / (SQRT_5_6 * math.sqrt(TANGENTIAL_MASS_FACTOR))
    if beta <= 0.0:
        return 1.0
    if beta >= 1.0:
        return RESTITUTION_FLOOR
    return max(RESTITUTION_FLOOR, math.exp(-math.pi * beta / math.sqrt(1.0 - beta * beta)))


def lowest_restitution(params) -> float:
    """The lowest restitution a ``DEMParameters`` can give a contact: its e_pp and e_pw, or
    ``RESTITUTION_FLOOR`` for a pair whose restitution follows the impact speed."""
    return min(RESTITUTION_FLOOR if getattr(params, f"e_{pair}_exponent") != 0.0 else getattr(params, f"e_{pair}")
               for pair in ("pp", "pw"))


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
    (refused above ``DEFAULT_MAX_FRACTION`` of the Rayleigh time, naming the option; divided
    into the fewest equal sub-steps below :func:`damped_max_fraction` of its lowest
    restitution), else ``TIME_STEP_FRACTION`` of the Rayleigh time of its smallest sphere
    (below the damped limit at every restitution)."""
    t_r = material_rayleigh_time(params)
    if params.dt is None:
        return TIME_STEP_FRACTION * t_r
    dt = stated_time_step(params)
    limit = damped_max_fraction(lowest_restitution(params)) * t_r
    return dt / math.ceil(dt / limit) if dt > limit else dt


def stated_time_step(params) -> float:
    """The step [s] a ``DEMParameters`` asks for before any sub-step: its ``dt`` (refused above
    ``DEFAULT_MAX_FRACTION`` of the Rayleigh time, naming the option), else
    ``TIME_STEP_FRACTION`` of the Rayleigh time."""
    t_r = material_rayleigh_time(params)
    if params.dt is None:
        return TIME_STEP_FRACTION * t_r
    check_time_step(float(params.dt), t_r)
    return float(params.dt)
