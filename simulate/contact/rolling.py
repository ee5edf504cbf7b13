"""Rolling resistance: the constant directional torque model (EDEM "type A", LIGGGHTS ``cdt``)
and the elastic-plastic spring-dashpot model (Ai et al. 2011 "type C", LIGGGHTS ``epsd``).

Each model is one evaluator called alike by the engine's sphere-sphere and sphere-wall loops
(as ``hertz_mindlin`` is for the contact force): ``constant_torque`` (LIGGGHTS lever),
``rolling_lever`` (the lever of each convention; the EDEM torque is applied by the kick against
the body's spin) and ``epsd_torque``.

The model is chosen by name (``ROLLING_MODELS``): ``"constant_torque"`` (default) or ``"epsd"``.

Constant directional torque
---------------------------
Each contact adds to body i a torque of magnitude mu_r F_n R_lever against its rotation:

    T_i = -mu_r F_n R_lever w_i / |w_i|,

with F_n the elastic (Hertz) part of the normal force (as LIGGGHTS' ``cdt``, which uses
k_n d_n), and the lever arm ``R_lever`` chosen by name (``ROLLING_LEVERS``):

``"edem_com"``
    EDEM's definition, "the distance of the contact point from the centre of mass", applied to
    the clump: |contact point - clump centre of mass|. ``w`` is the body's angular velocity.
``"edem_sphere"``
    The distance from the contact point to the centre of the member sphere that touches
    (R - d_n/2, EDEM's value for a single sphere). ``w`` is the body's angular velocity.
``"liggghts_reff"`` (default)
    LIGGGHTS ``rolling_friction cdt``: R_eff = R_i R_j / (R_i + R_j) between particles and the
    sphere radius against walls; ``w`` is the relative angular velocity w_i - w_j (the body's
    own against a wall), the torque has its component along the contact normal removed and is
    applied as an equal and opposite pair (so it conserves angular momentum while both bodies
    roll).

For a clump the three differ several-fold: a segment touching the floor at its end sphere has
a lever of about 12 mm with ``edem_com``, 5.5 mm with ``edem_sphere`` and 2.75 mm with
``liggghts_reff`` against another sphere.

Why the default is LIGGGHTS' and not EDEM's. EDEM's text does not say which centre a
multi-sphere particle uses, and EDEM is not available to check against; LIGGGHTS is, side by
side (``benchmarks/``). With the paper's measured parameters (mu_r p-p 0.53) both EDEM readings
jam the paper's carton: in the quick repose profile 2-4 % of the segments leave it and the
face stands at 55-68 deg (``edem_com``, ``edem_sphere``; 2-3 seeds each), where the lab
photographed 35.8 deg. With ``liggghts_reff`` 7-10 % leave and the face reads 34-37 deg in six
of eight seeds (the other two 42 and 48 deg). The EDEM readings stay selectable.

Cap. A constant torque does not vanish as w -> 0, so an explicit step makes the body spin back
and forth (Ai et al. 2011). Between two particles (``liggghts_reff``) the pair torque is scaled
down, for both bodies alike, just enough that its impulse over the step does not reverse their
relative angular velocity (``pair_rolling_scale``). Against walls, and for every contact with
the EDEM levers, the engine applies the rolling torque of a body after its other torques, in
each half step of the integrator (``simulate.integrate.half_kick``):

1. if the summed resistance sum(mu_r F_n R_lever) over the half step could absorb the body's
   rolling angular momentum, the rolling stops: the torque acts as a static constraint up to
   its magnitude, so a body whose driving torque is below the rolling resistance rests
   exactly, as the continuous model says. With ``liggghts_reff`` the rolling part is the
   rotation about axes in the tangent plane: when all the body's wall contacts share one
   normal, the spin about that normal (twist, which no rolling model resists) is kept. The
   EDEM torque acts against the body's whole angular velocity, twist included, and so does
   its stop;
2. otherwise the torque acts in full, with w the angular velocity the other torques give, its
   impulse scaled down only so that it never reverses the spin about the current rotation axis
   (``cap_rolling_impulse``; this matters for the anisotropic inertia of a clump).

Without step 1 a pile of clumps creeps: each body's spin is driven to a nearby axis instead of
to zero every step, and the contacts slip a little each time.

Elastic-plastic spring-dashpot (type C)
---------------------------------------
Each contact carries a rolling spring torque M^k (three components of its history, kept across
neighbour-list rebuilds like the tangential spring). Per step (Ai et al. 2011, eqs. 12-17):

    dtheta_r = (w_i - w_j) dt with its component along the contact normal removed,
    M^k <- M^k - k_r dtheta_r,  |M^k| <= M_m = mu_r F_n R_r  (full mobilisation: held at M_m),
    M   = M^k - C_r w_r        while |M^k| < M_m, M = M^k at full mobilisation,

on body i, -M on body j (an equal and opposite pair), with

    R_r = R_i R_j / (R_i + R_j) (the sphere radius R_i against a wall; the ``rolling_lever``
          conventions belong to the constant torque model and are not used),
    k_r = 2.25 k_n mu_r^2 R_r^2 (eq. 15, after Iwashita & Oda 1998), with k_n = 4/3 E*
          sqrt(R* d_n) the Hertz secant stiffness F_n / d_n, as LIGGGHTS-PUBLIC 3.8's
          ``rolling_model_epsd.h`` takes it from ``normal_model_hertz.h``,
    C_r = eta_r 2 sqrt(I_r k_r), eta_r the rolling damping ratio (0.3 recommended, eq. 16),
          1/I_r = 1/I_i + 1/I_j with I_i = 7/5 m_i R_i^2 the moment of inertia about the
          contact point of a sphere of the clump's mass m_i and the touching sphere's radius,
    F_n the elastic (Hertz) part of the normal force, as for the constant torque.

Below M_m the spring holds a body still at a small rolling angle M/k_r and lets it rock back
and settle (the constant torque needs the static stop of its cap above for that); at full
mobilisation it rolls against the same constant torque as type A. The torque is an ordinary
torque (``KICK_ELASTIC``): no cap is applied. I_r only sets the damping; for a clump the
sphere-of-clump-mass value is an approximation (its true inertia about the contact depends on
the axis). The rolling spring is stiff: k_r / I about a body's own axis is up to about
5 mu_r^2 k_n / m, so for mu_r near 1 a time step chosen for the normal contact alone has less
margin than with the constant torque.

References
----------
Ai, J., Chen, J.-F., Rotter, J. M., Ooi, J. Y. (2011). Assessment of rolling resistance models
in discrete element simulations. Powder Technol. 206, 269-282 (model types A and C).
Iwashita, K., Oda, M. (1998). Rolling resistance at contacts in simulation of shear band
development by DEM. J. Eng. Mech. 124(3), 285-292.
DEM Solutions (2018). EDEM 2018 Theory Reference Guide, "Rolling friction".
LIGGGHTS-PUBLIC 3.8 documentation, ``gran rolling_friction cdt`` and ``epsd``; source files
``rolling_model_cdt.h``, ``rolling_model_epsd.h`` and ``normal_model_hertz.h``.
"""

from __future__ import annotations

import math

from demcal.simulate._jit import evaluator

#: Lever-arm conventions by name; the index is what the kernels receive.
ROLLING_LEVERS = ("edem_com", "edem_sphere", "liggghts_reff")
EDEM_COM, EDEM_SPHERE, LIGGGHTS_REFF = 0, 1, 2

#: Rolling resistance models by name; the index is what the kernels receive.
ROLLING_MODELS = ("constant_torque", "epsd")
CONSTANT_TORQUE, EPSD = 0, 1

#: How ``simulate.integrate.half_kick`` applies a body's rolling terms: the summed magnitude
#: against the body's own spin (EDEM levers), the summed vector with the static stop and the
#: no-reversal cap (LIGGGHTS lever), or the summed vector as a plain torque (spring-dashpot).
KICK_DIRECTIONAL, KICK_RELATIVE, KICK_ELASTIC = 0, 1, 2

#: Rolling damping ratio eta_r of the spring-dashpot model recommended by Ai et al. (2011) [-].
EPSD_DAMPING_RATIO = 0.3

#: Moment of inertia about the contact point of a sphere of the body's mass and the touching
#: sphere's radius, over m R^2 (2/5 + 1): the I_r of the spring-dashpot rolling damping.
SPHERE_CONTACT_INERTIA = 1.4


def lever_index(name: str) -> int:
    """Kernel index of the lever convention ``name``; an unknown name lists the valid ones."""
    from demcal.errors import InputError
    if name not in ROLLING_LEVERS:
        raise InputError(f"unknown rolling_lever {name!r}; valid: {', '.join(ROLLING_LEVERS)}")
    return ROLLING_LEVERS.index(name)


def rolling_model_index(name: str) -> int:
    """Kernel index of the rolling model ``name``; an unknown name lists the valid ones."""
    from demcal.errors import InputError
    if name not in ROLLING_MODELS:
        raise InputError(f"unknown rolling_model {name!r}; valid: {', '.join(ROLLING_MODELS)}")
    return ROLLING_MODELS.index(name)


@evaluator
def kick_mode(lever, model):
    """The ``half_kick`` mode of a lever convention and a rolling model (kernel indices)."""
    if model == EPSD:
        return KICK_ELASTIC
    return KICK_RELATIVE if lever == LIGGGHTS_REFF else KICK_DIRECTIONAL


@evaluator
def relative_rolling_torque(mu_r, f_elastic, r_eff, wrx, wry, wrz, nx, ny, nz):
    """LIGGGHTS ``cdt`` torque vector mu_r F_n R_eff w_r/|w_r| with its normal part removed.

    Returns the torque [N m] that body i receives with a minus sign (body j with a plus sign);
    zero when the relative angular velocity ``w_r`` [rad/s] is zero.
    """
    wmag = math.sqrt(wrx * wrx + wry * wry + wrz * wrz)
    if wmag == 0.0:
        return 0.0, 0.0, 0.0
    c = mu_r * f_elastic * r_eff / wmag
    tx = c * wrx
    ty = c * wry
    tz = c * wrz
    tn = tx * nx + ty * ny + tz * nz
    return tx - tn * nx, ty - tn * ny, tz - tn * nz


@evaluator
def cap_rolling_impulse(wx, wy, wz, dwx, dwy, dwz):
    """Fraction s in [0, 1] of a rolling angular-velocity change ``dw`` to apply to ``w``.

    s is the largest value <= 1 for which (w + s dw) . w >= 0: the rolling torque may stop the
    spin about the current axis but never reverse it. A change that does not oppose ``w`` is
    applied in full.
    """
    c = dwx * wx + dwy * wy + dwz * wz
    if c >= 0.0:
        return 1.0
    w2 = wx * wx + wy * wy + wz * wz
    s = -w2 / c
    return s if s < 1.0 else 1.0


# ----------------------------------------------------------------------------------------------
# elastic-plastic spring-dashpot (Ai et al. 2011, type C)


@evaluator
def epsd_stiffness(normal_stiffness: float, mu_r: float, rolling_radius: float) -> float:
    """Rolling stiffness k_r = 2.25 k_n mu_r^2 R_r^2 [N m/rad] (Ai et al. 2011, eq. 15, after
    Iwashita & Oda 1998), from the normal stiffness k_n [N/m], the rolling friction mu_r [-]
    and the rolling radius R_r [m]."""
    return 2.25 * normal_stiffness * mu_r ** 2 * rolling_radius ** 2


@evaluator
def epsd_damping(rolling_stiffness: float, inertia: float, damping_ratio: float = EPSD_DAMPING_RATIO) -> float:
    """Rolling viscous damping C_r = eta_r 2 sqrt(I_r k_r) [N m s/rad] (Ai et al. 2011, eq. 16;
    eta_r = 0.3 recommended), I_r the moment of inertia about the contact point [kg m^2]."""
    return damping_ratio * 2.0 * math.sqrt(inertia * rolling_stiffness)


@evaluator
def epsd_rolling_torque(mx, my, mz, wrx, wry, wrz, nx, ny, nz, k_r, c_r, m_max, dt):
    """One step of the type C (elastic-plastic spring-dashpot) rolling torque of a contact.

    Ai et al. (2011), eqs. (12)-(17): the spring torque M^k is advanced by -k_r dtheta_r with
    dtheta_r = w_r dt the relative rolling rotation (w_r with its component along the contact
    normal n removed), kept in the tangent plane, and capped at |M^k| <= M_m = mu_r R_r F_n
    (full mobilisation: the contact then rolls at constant resistance); the damping torque
    -c_r w_r acts only while the spring is below its cap (their f = 0 option).

    Parameters
    ----------
    mx, my, mz : float
        Spring torque of the contact at the previous step [N m] (the contact's history).
    wrx, wry, wrz : float
        Relative angular velocity w_i - w_j [rad/s].
    nx, ny, nz : float
        Unit contact normal.
    k_r, c_r, m_max : float
        Rolling stiffness [N m/rad], damping [N m s/rad] and limit torque M_m [N m].
    dt : float
        Time step [s] (0: evaluate without advancing the spring).

    Returns
    -------
    (mx, my, mz, tx, ty, tz)
        New spring torque (to store) and the total rolling torque on body i [N m].
    """
    wn = wrx * nx + wry * ny + wrz * nz
    rx = wrx - wn * nx
    ry = wry - wn * ny
    rz = wrz - wn * nz
    # keep the stored torque in the current tangent plane
    mn = mx * nx + my * ny + mz * nz
    mx -= mn * nx
    my -= mn * ny
    mz -= mn * nz
    mx -= k_r * rx * dt
    my -= k_r * ry * dt
    mz -= k_r * rz * dt
    mag = math.sqrt(mx * mx + my * my + mz * mz)
    if mag >= m_max:
        scale = m_max / mag if mag > 0.0 else 0.0
        mx *= scale
        my *= scale
        mz *= scale
        return mx, my, mz, mx, my, mz
    return mx, my, mz, mx - c_r * rx, my - c_r * ry, mz - c_r * rz


# ----------------------------------------------------------------------------------------------
# one evaluator per contact, for the pair loop and the wall loop alike


@evaluator
def rolling_lever(lever, ax, ay, az, sphere_lever, r_eff):
    """Lever arm [m] of the constant torque for one body at one contact (``ROLLING_LEVERS``):
    |a| the contact point's distance from the body's centre of mass (``edem_com``), the
    touching sphere's R - d_n/2 (``edem_sphere``) or R_eff (``liggghts_reff``)."""
    if lever == EDEM_COM:
        return math.sqrt(ax * ax + ay * ay + az * az)
    if lever == EDEM_SPHERE:
        return sphere_lever
    return r_eff


@evaluator
def constant_torque(mu_r, f_el, r_eff, wrx, wry, wrz, nx, ny, nz):
    """Constant directional torque with the LIGGGHTS lever (``cdt``): the torque on body i
    (body j receives the opposite) and its magnitude mu_r F_n R_eff [N m]; ``w_r`` the relative
    angular velocity w_i - w_j (w_i against a wall), ``n`` the unit normal. With the EDEM levers
    the torque is the magnitude mu_r F_n R_lever against each body's own spin, applied by the
    kick (``rolling_lever`` gives the lever)."""
    tx, ty, tz = relative_rolling_torque(mu_r, f_el, r_eff, wrx, wry, wrz, nx, ny, nz)
    return -tx, -ty, -tz, mu_r * f_el * r_eff


@evaluator
def epsd_torque(mu_r, f_el, e_star, sqrt_rd, r_roll, r_i, r_j, inv_m_i, inv_m_j, eta_r, hist, row,
                col, wrx, wry, wrz, nx, ny, nz, dt):
    """Elastic-plastic spring-dashpot rolling torque of one contact (LIGGGHTS ``epsd``).

    Parameters
    ----------
    mu_r, f_el : float
        Rolling friction coefficient [-] and elastic (Hertz) normal force [N].
    e_star, sqrt_rd : float
        Effective Young's modulus [Pa] and sqrt(R* d_n) [m]: k_n = 4/3 E* sqrt(R* d_n).
    r_roll : float
        Rolling radius R_eff (the sphere radius against a wall) [m].
    r_i, r_j, inv_m_i, inv_m_j : float
        Radii of the touching spheres [m] and inverse masses of their bodies [1/kg] (0 for a
        wall): the damping's moment of inertia about the contact point, 1/I_r = 1/I_i + 1/I_j
        with I = 7/5 m r^2 (the sphere-of-body-mass value, as LIGGGHTS).
    eta_r : float
        Damping ratio [-].
    hist, row, col : array, int, int
        Contact history; the spring torque is kept in ``hist[row, col:col+3]``.
    wrx, wry, wrz : float
        Relative angular velocity w_i - w_j (w_i against a wall) [rad/s].
    nx, ny, nz : float
        Unit contact normal.
    dt : float
        Time step [s]; 0 evaluates without advancing or writing the history.

    Returns
    -------
    (tx, ty, tz, m_max)
        Torque on body i [N m] (body j receives the opposite) and the limit mu_r F_n R_r [N m].
    """
    k_r = epsd_stiffness(4.0 / 3.0 * e_star * sqrt_rd, mu_r, r_roll)
    inertia_r = SPHERE_CONTACT_INERTIA / (inv_m_i / (r_i * r_i) + inv_m_j / (r_j * r_j))
    c_r = epsd_damping(k_r, inertia_r, eta_r)
    m_max = mu_r * f_el * r_roll
    sx, sy, sz, tx, ty, tz = epsd_rolling_torque(hist[row, col], hist[row, col + 1], hist[row, col + 2],
                                                 wrx, wry, wrz, nx, ny, nz, k_r, c_r, m_max, dt)
    if dt > 0.0:
        hist[row, col] = sx
        hist[row, col + 1] = sy
        hist[row, col + 2] = sz
    return tx, ty, tz, m_max
