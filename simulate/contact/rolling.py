"""Rolling friction: the constant directional torque model (EDEM "type A", LIGGGHTS ``cdt``).

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
and forth (Ai et al. 2011). The engine therefore applies the rolling torque of a body after its
other torques, in each half step of the integrator (``simulate.integrate.half_kick``):

1. if the summed resistance sum(mu_r F_n R_lever) over the half step could absorb the body's
   whole angular momentum, the rotation stops: the torque acts as a static constraint up to
   its magnitude, so a body whose driving torque is below the rolling resistance rests
   exactly, as the continuous model says;
2. otherwise the torque acts in full, with w the angular velocity the other torques give, its
   impulse scaled down only so that it never reverses the spin about the current rotation axis
   (``cap_rolling_impulse``; this matters for the anisotropic inertia of a clump).

Without step 1 a pile of clumps creeps: each body's spin is driven to a nearby axis instead of
to zero every step, and the contacts slip a little each time.

References
----------
Ai, J., Chen, J.-F., Rotter, J. M., Ooi, J. Y. (2011). Assessment of rolling resistance models
in discrete element simulations. Powder Technol. 206, 269-282 (model type A).
DEM Solutions (2018). EDEM 2018 Theory Reference Guide, "Rolling friction".
LIGGGHTS-PUBLIC 3.8 documentation, ``gran rolling_friction cdt``.
"""

from __future__ import annotations

import math

from simulate._jit import evaluator

#: Lever-arm conventions by name; the index is what the kernels receive.
ROLLING_LEVERS = ("edem_com", "edem_sphere", "liggghts_reff")
EDEM_COM, EDEM_SPHERE, LIGGGHTS_REFF = 0, 1, 2


def lever_index(name: str) -> int:
    """Kernel index of the lever convention ``name``; an unknown name lists the valid ones."""
    from demcal.errors import InputError
    if name not in ROLLING_LEVERS:
        raise InputError(f"unknown rolling_lever {name!r}; valid: {', '.join(ROLLING_LEVERS)}")
    return ROLLING_LEVERS.index(name)


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
