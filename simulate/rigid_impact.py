"""Rigid-body impact theory of a clump dropped onto a frictionless plate: the reference the
contact effective-mass extension is judged by.

A rigid clump (mass m, principal moments of inertia, member spheres) released at rest in a
given orientation falls onto a horizontal plate without friction. Each impact is
instantaneous, at the lowest point of the sphere that strikes, along the plate normal n, with
Newton's restitution e for the normal velocity of that point (Stronge 2000, ch. 2 and 3;
Brach 2007, ch. 3):

    j = -(1 + e) v_n / (1/m + (r x n) . I^-1 (r x n)),   v += j n / m,   w += I^-1 (r x n) j,

r the lever of the contact point from the centre of mass. 1 / (1/m + (r x n) . I^-1 (r x n))
is the effective mass of the contact: an off-centre contact moves only that much of the body
along n, so a single impact leaves the centre of mass the velocity ratio
(1 + e) m_eff / m - 1 (-v_z after / v_z before). Between impacts the body flies under gravity,
turning at constant angular velocity. A segment tilted by a few degrees strikes with one end
sphere, turns, and strikes with the other (the bar drops of Stoianovici & Hurmuzlu 1996); the
impacts follow one another, each sphere's gap to the plate searched on a fine time grid and
refined by Brent's method, until the centre of mass reaches its first apex. Spheres striking
at the same instant (a flat landing) take one simultaneous impact whose impulses give every
contact Newton's restitution (the least-norm solution; for a flat segment that is the body's
own restitution e).

Planar motion. The orientations of the drop rig (``simulate.rigs.drop``) tilt the template x
axis by an angle about the world y axis; for a clump whose sphere centres lie in the template
x-z plane and whose y axis is principal (a segment: spheres on its axis), the normal impulses
at the plate only ever turn it about y, so the drop stays in the x-z plane and is followed as
the height of the centre of mass, the tilt and the angular velocity about y.

The drop reports the first-impact velocity ratio, the rebound velocity ratio of the whole
impact sequence (-1 plus the plate's total impulse over m v_in: gravity between the impacts
left out, so that it compares with a twin whose contacts take time) and the apparent
restitution sqrt(h_rebound / h_drop) to the first apex, the lab's observable.

References
----------
Brach, R. M. (2007). Mechanical Impact Dynamics: Rigid Body Collisions, 2nd ed. Wiley, ch. 3.
Stoianovici, D., Hurmuzlu, Y. (1996). A critical study of the applicability of rigid-body
collision theory. J. Appl. Mech. 63, 307-316.
Stronge, W. J. (2000). Impact Mechanics. Cambridge University Press, ch. 2-3.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy.optimize import brentq

from demcal.errors import InputError
from demcal.simulate.clump import ClumpTemplate
from demcal.units import GRAVITY

#: Largest move of any point of the body between two samples of the impact search, as a
#: fraction of the smallest sphere radius [-]: a sphere that dips below the plate between two
#: samples by less than the curvature of its path over a step (about 1e-11 m for a segment)
#: is not found, an impact of negligible speed.
SEARCH_STEP_FRACTION = 1e-3
#: Spheres within this gap of the plate [m] when one strikes strike with it (a flat landing).
SIMULTANEOUS_GAP = 1e-12
#: Most impacts followed before the apex.
MAX_IMPACTS = 1000


@dataclass(frozen=True)
class RigidDrop:
    """A rigid clump's drop onto a frictionless plate (:func:`rigid_drop`).

    Attributes
    ----------
    first_velocity_ratio : float
        -v_z after / v_z before the first impact, of the centre of mass [-].
    rebound_velocity_ratio : float
        -1 + (total impulse of the plate) / (m v_in) over the impacts before the first apex [-]:
        the rebound of the centre of mass, gravity between the impacts left out.
    apparent_restitution : float
        sqrt(h_rebound / h_drop), h_rebound the rise of the centre of mass from its height at
        the first impact to its first apex (0 if the apex lies lower) [-].
    impacts : tuple of (float, tuple of int)
        Time after the first impact [s] and the struck spheres of each impact.
    """

    first_velocity_ratio: float
    rebound_velocity_ratio: float
    apparent_restitution: float
    impacts: tuple

    def to_dict(self) -> dict:
        return asdict(self)


def rigid_drop(template: ClumpTemplate, orientation_deg: float, restitution: float, height: float, *,
               g: float = GRAVITY) -> RigidDrop:
    """Drop a rigid clump at rest onto a frictionless plate (see the module docstring).

    Parameters
    ----------
    template : ClumpTemplate
        The clump: its sphere centres in the template x-z plane, y a principal axis.
    orientation_deg : float
        Angle of the template x axis above the horizontal at release [deg], 0..90, as the drop
        rig's ``orientation_deg`` (a tilt about the world y axis).
    restitution : float
        Newton's coefficient of restitution e of every impact [-], in (0, 1].
    height : float
        Fall of the body to the first impact [m] (impact speed sqrt(2 g height)).
    g : float
        Gravitational acceleration [m/s^2].

    Returns
    -------
    RigidDrop
    """
    if not isinstance(template, ClumpTemplate):
        raise InputError(f"template must be a ClumpTemplate, got {type(template).__name__}")
    if not 0.0 <= orientation_deg <= 90.0:
        raise InputError(f"orientation_deg must be in [0, 90], got {orientation_deg!r}")
    if not 0.0 < restitution <= 1.0:
        raise InputError(f"restitution must be in (0, 1], got {restitution!r}")
    if not height > 0.0:
        raise InputError(f"height must be > 0 [m], got {height!r}")
    # inertia and sphere offsets in the template frame, about the centre of mass
    axes = np.asarray(template.principal_axes, float)
    inertia = axes @ np.diag(template.principal_moments) @ axes.T
    offsets = np.asarray(template.centres, float) - template.centre_of_mass
    scale = float(np.abs(inertia).max())
    if np.abs(offsets[:, 1]).max() > 1e-9 * template.bounding_radius or \
            abs(inertia[0, 1]) + abs(inertia[1, 2]) > 1e-9 * scale:
        raise InputError("rigid_drop follows planar drops only: the clump's sphere centres must lie in its "
                         "template x-z plane, with y a principal axis")
    m = float(template.mass)
    inv_iyy = 1.0 / float(inertia[1, 1])
    u, w = offsets[:, 0], offsets[:, 2]
    radii = np.asarray(template.radii, float)
    v_in = math.sqrt(2.0 * g * height)
    # state: height z of the centre of mass, tilt phi of the template x axis (x towards z), its
    # rate, and the vertical velocity; sphere k's lowest point is at z + u sin phi + w cos phi - r
    phi = math.radians(orientation_deg)
    z = -float((u * math.sin(phi) + w * math.cos(phi) - radii).min())
    z_contact, vz, rate, t = z, -v_in, 0.0, 0.0
    impulse, impacts, first = 0.0, [], math.nan
    step = SEARCH_STEP_FRACTION * float(radii.min())
    reach = float(np.hypot(u, w).max() + radii.max())
    while True:
        gaps = z + u * math.sin(phi) + w * math.cos(phi) - radii
        lever = u * math.cos(phi) - w * math.sin(phi)       # horizontal lever of each contact point
        v_n = vz + rate * lever
        struck = np.flatnonzero((gaps <= SIMULTANEOUS_GAP) & (v_n < 0.0))
        if struck.size:
            if len(impacts) >= MAX_IMPACTS:
                raise InputError(f"rigid_drop: more than {MAX_IMPACTS} impacts before the apex")
            # W j = -(1 + e) v_n for the struck contacts, W = 1/m + a_i a_j / I (least norm)
            a = lever[struck]
            W = 1.0 / m + np.outer(a, a) * inv_iyy
            j = np.linalg.lstsq(W, -(1.0 + restitution) * v_n[struck], rcond=None)[0]
            vz_before = vz
            vz += j.sum() / m
            rate += float(a @ j) * inv_iyy
            impulse += j.sum()
            impacts.append((t, tuple(int(k) for k in struck)))
            if not impacts[1:]:
                first = -vz / vz_before
        # next impact: within the flight to the apex (rising) or to the plate (falling)
        end = vz / g if vz > 0.0 else (vz + math.sqrt(vz * vz + 2.0 * g * reach)) / g
        hit = _next_impact(z, vz, phi, rate, u, w, radii, g, end, step)
        if hit is None:
            break
        z += vz * hit - 0.5 * g * hit * hit
        vz -= g * hit
        phi += rate * hit
        t += hit
    rise = z + vz * vz / (2.0 * g) - z_contact
    return RigidDrop(first_velocity_ratio=float(first),
                     rebound_velocity_ratio=float(-1.0 + impulse / (m * v_in)),
                     apparent_restitution=math.sqrt(max(rise, 0.0) / height), impacts=tuple(impacts))


def _next_impact(z, vz, phi, rate, u, w, radii, g, end, step):
    """Time of the next impact within ``end`` [s] (None if there is none): the first crossing
    of the plate by a sphere's lowest point on a grid of steps over which no point moves more
    than ``step`` [m], refined by Brent's method. Spheres on the plate at the start (just
    struck, separating) count once they have left it."""
    speed = abs(vz) + g * end + abs(rate) * float(np.hypot(u, w).max())
    tau = np.linspace(0.0, end, max(2, int(math.ceil(end * speed / step)) + 1))
    p = phi + rate * tau[:, None]
    gaps = (z + vz * tau - 0.5 * g * tau * tau)[:, None] + u * np.sin(p) + w * np.cos(p) - radii
    cross = (gaps[:-1] > 0.0) & (gaps[1:] <= 0.0)
    rows = np.flatnonzero(cross.any(axis=1))
    if rows.size == 0:
        return None
    i = int(rows[0])

    def gap(t, k):
        q = phi + rate * t
        return z + vz * t - 0.5 * g * t * t + u[k] * math.sin(q) + w[k] * math.cos(q) - radii[k]

    return min(brentq(gap, tau[i], tau[i + 1], args=(int(k),), xtol=1e-15) for k in np.flatnonzero(cross[i]))
