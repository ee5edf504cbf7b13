"""Hertz-Mindlin (no slip) contact with restitution damping, as EDEM implements it.

Effective properties of a contact between bodies i and j (a wall has infinite radius and mass):

    E = 2 G (1 + nu),   1/E* = (1 - nu_i^2)/E_i + (1 - nu_j^2)/E_j,
    1/R* = 1/R_i + 1/R_j,   1/m* = 1/m_i + 1/m_j (m the mass of the whole clump),
    1/G* = (2 - nu_i)/G_i + (2 - nu_j)/G_j.

Normal force (Hertz 1882; Johnson 1985, sec. 4.2) and its dashpot (Tsuji et al. 1992 in the
form of the EDEM theory reference guide):

    F_n = 4/3 E* sqrt(R*) d_n^(3/2),   S_n = 2 E* sqrt(R* d_n),
    beta = ln e / sqrt(ln^2 e + pi^2),  F_n^d = 2 sqrt(5/6) |beta| sqrt(S_n m*) v_n  (opposing v_n).

The total normal force is not clipped at zero: near separation the dashpot may pull. With this
choice the coefficient of restitution of a binary collision is exactly ``e`` at every impact
velocity (the 2 sqrt(5/6) factor is calibrated for separation at zero overlap); clipping the
force would raise the effective restitution at low ``e`` (0.25 instead of 0.1).

Tangential force (Mindlin 1949, no-slip): a spring on the accumulated tangential displacement
``s`` with stiffness S_t = 8 G* sqrt(R* d_n), a dashpot 2 sqrt(5/6) |beta| sqrt(S_t m*) |v_t|
opposing v_t, and the Coulomb cap |F_t| <= mu_s |F_n|. Each step the displacement is first
incremented by v_t dt and then projected onto the current tangent plane, in that order and
without restoring its length, as LIGGGHTS-PUBLIC 3.8's ``tangential_model_history.h`` does;
when the spring alone exceeds the cap the contact slides: the displacement is shortened to
mu_s |F_n| / S_t and the dashpot is dropped. Unlike LIGGGHTS, which leaves the spring and
dashpot sum uncapped while the spring holds, the sum is also held at mu_s |F_n|. A force
evaluation with dt = 0 reads the history and never writes it.

Velocity-dependent restitution (optional, per material pair). With an exponent n != 0 the
restitution of a contact follows the power law e(v) = e_ref (max(v, v_min) / v_ref)^(-n),
capped to [1e-6, 1] (as ``simulate.extensions.VelocityRestitution``), v the normal approach
speed at the contact's first touch, kept in its history for the whole contact; beta, and so
both dashpots, use that e (``impact_damping``). n = 0 is the constant e above. With n > 0 and
v_min = 0 the law reaches e = 1 at v_y = v_ref e_ref^(1/n) (Johnson's yield speed): slower
impacts are elastic, so a body bouncing on a plate keeps bouncing at about v_y; v_min (e.g.
the slowest measured impact) holds e at e(v_min) below it instead.

References
----------
Johnson, K. L. (1985). Contact Mechanics. Cambridge University Press.
Mindlin, R. D. (1949). Compliance of elastic bodies in contact. J. Appl. Mech. 16, 259-268.
Tsuji, Y., Tanaka, T., Ishida, T. (1992). Lagrangian numerical simulation of plug flow of
cohesionless particles in a horizontal pipe. Powder Technol. 71, 239-250.
DEM Solutions (2018). EDEM 2018 Theory Reference Guide, "Hertz-Mindlin (no slip)".
"""

from __future__ import annotations

import math

from demcal.simulate._jit import evaluator

SQRT_5_6 = math.sqrt(5.0 / 6.0)


#: Bounds of ln e for the velocity-dependent restitution: e in [1e-6, 1].
LOG_E_MIN = math.log(1e-6)
#: Approach speed recorded at first touch when the bodies are not approaching then [m/s] (a
#: stored 0 means "no contact yet").
V_FIRST_TOUCH_MIN = 1e-9


def effective_modulus(e_i: float, nu_i: float, e_j: float, nu_j: float) -> float:
    """E* [Pa] of two bodies of Young's moduli ``e_i``, ``e_j`` [Pa] and Poisson's ratios [-]."""
    return 1.0 / ((1.0 - nu_i ** 2) / e_i + (1.0 - nu_j ** 2) / e_j)


def effective_shear_modulus(g_i: float, nu_i: float, g_j: float, nu_j: float) -> float:
    """G* [Pa] of two bodies of shear moduli ``g_i``, ``g_j`` [Pa] and Poisson's ratios [-]."""
    return 1.0 / ((2.0 - nu_i) / g_i + (2.0 - nu_j) / g_j)


def damping_ratio(restitution: float) -> float:
    """beta = ln e / sqrt(ln^2 e + pi^2) [-] (negative; 0 for e = 1)."""
    log_e = math.log(restitution)
    return log_e / math.sqrt(log_e ** 2 + math.pi ** 2)


def contact_duration_elastic(m_star: float, r_star: float, e_star: float, v_impact: float) -> float:
    """Duration [s] of an elastic Hertz impact, t_c = 2.868 (m*^2 / (R* E*^2 v))^(1/5).

    Johnson (1985), sec. 11.4 (impact of elastic spheres), with E* as defined in this module.
    """
    return 2.868 * (m_star ** 2 / (r_star * e_star ** 2 * v_impact)) ** 0.2


@evaluator
def impact_damping(hist, k, slot, v_approach, log_e_ref, exponent, log_v_ref, v_min, store):
    """Dashpot factor 2 sqrt(5/6) |beta| [-] of a contact whose restitution depends on its
    impact speed: e(v) = e_ref (max(v, v_min) / v_ref)^(-n), capped to [1e-6, 1].

    Parameters
    ----------
    hist : ndarray (n, w)
        Contact history; ``hist[k, slot]`` holds the approach speed at first touch [m/s] (0
        until the contact has been met).
    v_approach : float
        Normal approach speed now [m/s], recorded if the contact is new.
    log_e_ref, exponent, log_v_ref : float
        ln e_ref, n [-] and ln v_ref (v_ref in [m/s]) of the pair.
    v_min : float
        Slower impacts take e(v_min) [m/s] (0: the law down to e = 1).
    store : bool
        Record the first-touch speed (False for an evaluation that must not advance history).
    """
    v = hist[k, slot]
    if v == 0.0:
        v = max(v_approach, V_FIRST_TOUCH_MIN)
        if store:
            hist[k, slot] = v
    log_e = log_e_ref - exponent * (math.log(max(v, v_min)) - log_v_ref)
    log_e = min(max(log_e, LOG_E_MIN), 0.0)
    return 2.0 * SQRT_5_6 * abs(log_e) / math.sqrt(log_e * log_e + math.pi * math.pi)


@evaluator
def normal_force(e_star, r_star, m_star, damping, overlap, v_approach):
    """Hertz normal force with its dashpot.

    Parameters
    ----------
    e_star, r_star, m_star : float
        Effective modulus [Pa], radius [m] and mass [kg].
    damping : float
        2 sqrt(5/6) |beta| [-] of the pair.
    overlap : float
        d_n > 0 [m].
    v_approach : float
        Normal relative velocity, positive when the bodies approach [m/s].

    Returns
    -------
    f_n : float
        Total normal force, positive when repulsive [N].
    f_elastic : float
        Its elastic (Hertz) part [N].
    sqrt_rd : float
        sqrt(R* d_n) [m], reused by the tangential law.
    """
    sqrt_rd = math.sqrt(r_star * overlap)
    f_elastic = (4.0 / 3.0) * e_star * sqrt_rd * overlap
    s_n = 2.0 * e_star * sqrt_rd
    f_n = f_elastic + damping * math.sqrt(s_n * m_star) * v_approach
    return f_n, f_elastic, sqrt_rd


@evaluator
def tangential_force(hist, k, nx, ny, nz, vtx, vty, vtz, g_star, m_star, damping, mu_s, sqrt_rd,
                     f_n, dt):
    """Mindlin no-slip tangential force on body i, updating the stored displacement ``hist[k]``.

    Parameters
    ----------
    hist : ndarray (n, 3)
        Accumulated tangential displacement of each contact [m]; row ``k`` is read and written.
    nx, ny, nz : float
        Contact normal (unit).
    vtx, vty, vtz : float
        Tangential velocity of i relative to j at the contact point [m/s].
    g_star, m_star : float
        Effective shear modulus [Pa] and mass [kg].
    damping : float
        2 sqrt(5/6) |beta| [-].
    mu_s : float
        Coulomb coefficient [-].
    sqrt_rd : float
        sqrt(R* d_n) [m].
    f_n : float
        Normal force [N]; the cap is mu_s |f_n|.
    dt : float
        Time step [s]; 0 evaluates the force without advancing or writing the history.

    Returns
    -------
    (ftx, fty, ftz) : force on body i [N] (body j receives the opposite).
    """
    sx = hist[k, 0]
    sy = hist[k, 1]
    sz = hist[k, 2]
    update = dt > 0.0
    if update:
        # LIGGGHTS' order: increment, then project onto the current tangent plane
        sx += vtx * dt
        sy += vty * dt
        sz += vtz * dt
        sn = sx * nx + sy * ny + sz * nz
        sx -= sn * nx
        sy -= sn * ny
        sz -= sn * nz
    s_t = 8.0 * g_star * sqrt_rd
    f_max = mu_s * abs(f_n)
    spring2 = s_t * s_t * (sx * sx + sy * sy + sz * sz)
    if spring2 > f_max * f_max:
        # sliding: the spring is held at the Coulomb limit, no dashpot
        ratio = f_max / math.sqrt(spring2)
        sx *= ratio
        sy *= ratio
        sz *= ratio
        ftx = -s_t * sx
        fty = -s_t * sy
        ftz = -s_t * sz
    else:
        g_t = damping * math.sqrt(s_t * m_star)
        ftx = -s_t * sx - g_t * vtx
        fty = -s_t * sy - g_t * vty
        ftz = -s_t * sz - g_t * vtz
        f2 = ftx * ftx + fty * fty + ftz * ftz
        if f2 > f_max * f_max:
            ratio = f_max / math.sqrt(f2)
            ftx *= ratio
            fty *= ratio
            ftz *= ratio
    if update:
        hist[k, 0] = sx
        hist[k, 1] = sy
        hist[k, 2] = sz
    return ftx, fty, ftz
