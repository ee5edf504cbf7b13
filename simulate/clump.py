"""Rigid clumps of overlapping spheres: templates and their mass properties.

A ``ClumpTemplate`` is the shape of one particle type: sphere centres and radii in a template
frame, plus the mass, centre of mass and principal moments of inertia of the body. The engine
works in the principal frame (``offsets`` are the sphere centres relative to the centre of mass
in that frame); ``principal_axes`` maps it back to the template frame, so orientations given by
the user always refer to the template frame.

Mass models (``mass_model``):

``"union"`` (EDEM's default)
    Mass and inertia of the union of the spheres at the particle density, by
    ``union_mass_properties``: exact integration along x of the union of the chords of every
    sphere on each line of a regular midpoint grid in (y, z). Deterministic; relative error
    about 1e-5 at the default resolution. Spheres that do not overlap (a single sphere
    included) are summed exactly instead (``disjoint_spheres_mass_properties``).
``"body"``
    The body the spheres stand for, of the particle's shape (``simulate.shapes``): a solid
    cylinder for a segment, a sphere, an ellipsoid for a kernel.
``"cylinder"``
    A solid cylinder of the segment's length and diameter (the LIGGGHTS benchmark case): the
    segment's ``"body"``, under the name stored results use.
``"scaled"``
    The union's mass and inertia multiplied by ``mean_mass / union mass`` (a measured mean
    mass, same shape).

The paper's segment (``segment_template``): ``n`` equal spheres of radius D/2 on the x axis,
end centres at +-(L/2 - D/2), i.e. 5 spheres of r = 5.5 mm over 25 mm.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

from demcal.errors import InputError

MASS_MODELS = ("union", "body", "cylinder", "scaled")


@dataclass(frozen=True)
class MassProperties:
    """Mass, centre of mass and inertia tensor of a rigid body.

    Attributes
    ----------
    mass : float
        [kg]
    centre_of_mass : ndarray (3,)
        [m], in the frame the body was described in.
    inertia : ndarray (3, 3)
        Inertia tensor about the centre of mass [kg m2].
    """

    mass: float
    centre_of_mass: np.ndarray
    inertia: np.ndarray

    def to_dict(self) -> dict:
        return {"mass": self.mass, "centre_of_mass": self.centre_of_mass.tolist(),
                "inertia": self.inertia.tolist()}


def union_mass_properties(centres, radii, density: float, resolution: int = 600) -> MassProperties:
    """Mass properties of a union of (possibly overlapping) spheres of uniform density.

    Lines parallel to x through the midpoints of a ``resolution`` x ``resolution`` grid over the
    (y, z) bounding square; on each line the chords of all spheres are merged and the integrals
    of 1, x and x^2 over their union are taken exactly. The (y, z) midpoint rule is the only
    approximation (the chord length has a square-root edge at each silhouette, so the error falls
    as about resolution^-1.5).

    Parameters
    ----------
    centres : array (n, 3)
        Sphere centres [m].
    radii : array (n,)
        Sphere radii [m].
    density : float
        [kg/m3]
    resolution : int
        Grid lines per side.

    Returns
    -------
    MassProperties
    """
    c = np.ascontiguousarray(centres, dtype=float).reshape(-1, 3)
    r = np.ascontiguousarray(radii, dtype=float).reshape(-1)
    props = _union_mass_properties(c.tobytes(), r.tobytes(), float(density), int(resolution))
    return MassProperties(props.mass, props.centre_of_mass.copy(), props.inertia.copy())


# Every run of a rig builds its particle template: the grid integration takes about 0.3 s,
# a small heap's whole run a few times that, so a process keeps the answers it has computed.
@functools.lru_cache(maxsize=256)
def _union_mass_properties(centres: bytes, radii: bytes, density: float, resolution: int) -> MassProperties:
    c = np.frombuffer(centres).reshape(-1, 3)
    r = np.frombuffer(radii)
    lo = (c[:, 1:] - r[:, None]).min(axis=0)
    hi = (c[:, 1:] + r[:, None]).max(axis=0)
    side = float((hi - lo).max())
    h = side / resolution
    g = lo[:, None] + (np.arange(resolution) + 0.5) * h          # (2, res) midpoints
    y, z = np.meshgrid(g[0], g[1], indexing="ij")
    y = y.ravel()
    z = z.ravel()
    rho2 = (y[:, None] - c[None, :, 1]) ** 2 + (z[:, None] - c[None, :, 2]) ** 2
    half = np.sqrt(np.clip(r[None, :] ** 2 - rho2, 0.0, None))
    hit = rho2 < r[None, :] ** 2
    start = np.where(hit, c[None, :, 0] - half, np.inf)
    end = np.where(hit, c[None, :, 0] + half, np.inf)
    order = np.argsort(start, axis=1)
    start = np.take_along_axis(start, order, axis=1)
    end = np.take_along_axis(end, order, axis=1)

    # sweep the sorted chords, closing a merged interval whenever the next one starts after it
    m0 = np.zeros(y.size)  # integral of 1
    m1 = np.zeros(y.size)  # integral of x
    m2 = np.zeros(y.size)  # integral of x^2
    cur_s = start[:, 0].copy()
    cur_e = end[:, 0].copy()

    def close(mask, s, e):
        s, e = s[mask], e[mask]
        m0[mask] += e - s
        m1[mask] += (e ** 2 - s ** 2) / 2.0
        m2[mask] += (e ** 3 - s ** 3) / 3.0

    for k in range(1, c.shape[0]):
        s_k, e_k = start[:, k], end[:, k]
        gap = np.isfinite(s_k) & (s_k > cur_e)
        close(gap & np.isfinite(cur_s), cur_s, cur_e)
        cur_s = np.where(gap, s_k, cur_s)
        cur_e = np.where(gap, e_k, np.where(np.isfinite(s_k), np.maximum(cur_e, e_k), cur_e))
    close(np.isfinite(cur_s), cur_s, cur_e)

    da = h * h * density
    mass = da * m0.sum()
    com = da * np.array([m1.sum(), (y * m0).sum(), (z * m0).sum()]) / mass
    sxx = da * m2.sum()
    syy = da * (y * y * m0).sum()
    szz = da * (z * z * m0).sum()
    sxy = da * (y * m1).sum()
    sxz = da * (z * m1).sum()
    syz = da * (y * z * m0).sum()
    second = np.array([[sxx, sxy, sxz], [sxy, syy, syz], [sxz, syz, szz]])  # int x_a x_b dm
    second -= mass * np.outer(com, com)                                      # about the centre of mass
    inertia = np.trace(second) * np.eye(3) - second
    return MassProperties(float(mass), com, inertia)


def disjoint_spheres_mass_properties(centres, radii, density: float) -> MassProperties:
    """Exact mass properties of spheres that do not overlap: m_k = rho 4/3 pi r_k^3, each with
    I = 2/5 m_k r_k^2 about its centre, moved to the common centre of mass (parallel axes)."""
    c = np.asarray(centres, dtype=float).reshape(-1, 3)
    r = np.asarray(radii, dtype=float).reshape(-1)
    m = density * 4.0 / 3.0 * np.pi * r ** 3
    mass = float(m.sum())
    com = (m[:, None] * c).sum(axis=0) / mass
    inertia = np.zeros((3, 3))
    for mk, rk, ck in zip(m, r, c - com):
        inertia += 0.4 * mk * rk ** 2 * np.eye(3) + mk * ((ck @ ck) * np.eye(3) - np.outer(ck, ck))
    return MassProperties(mass, com, inertia)


def spheres_overlap(centres, radii) -> bool:
    """True if any two of the spheres intersect."""
    c = np.asarray(centres, dtype=float).reshape(-1, 3)
    r = np.asarray(radii, dtype=float).reshape(-1)
    d = np.linalg.norm(c[:, None, :] - c[None, :, :], axis=2)
    reach = r[:, None] + r[None, :]
    np.fill_diagonal(d, np.inf)
    return bool((d < reach).any())


def cylinder_mass_properties(length: float, diameter: float, density: float) -> MassProperties:
    """Solid cylinder along x, centred at the origin: m = rho pi R^2 L, I_xx = m R^2 / 2,
    I_yy = I_zz = m (3 R^2 + L^2) / 12. Lengths [m], density [kg/m3]."""
    radius = diameter / 2.0
    mass = density * np.pi * radius ** 2 * length
    axial = mass * radius ** 2 / 2.0
    transverse = mass * (3.0 * radius ** 2 + length ** 2) / 12.0
    return MassProperties(float(mass), np.zeros(3), np.diag([axial, transverse, transverse]))


def principal_frame(inertia) -> tuple[np.ndarray, np.ndarray]:
    """Principal moments [kg m2] and axes (columns, a proper rotation) of an inertia tensor.

    A tensor already diagonal (to 1e-9 of its trace) keeps the identity, so a symmetric template
    keeps its own axes rather than an arbitrary eigenbasis of a degenerate tensor.
    """
    inertia = np.asarray(inertia, dtype=float)
    off = inertia - np.diag(np.diag(inertia))
    if np.abs(off).max() <= 1e-9 * np.trace(inertia):
        return np.diag(inertia).copy(), np.eye(3)
    moments, axes = np.linalg.eigh(inertia)
    if np.linalg.det(axes) < 0:
        axes[:, 2] *= -1.0
    return moments, axes


@dataclass(frozen=True)
class ClumpTemplate:
    """A rigid particle made of spheres.

    Attributes
    ----------
    name : str
    centres : ndarray (n, 3)
        Sphere centres in the template frame [m].
    radii : ndarray (n,)
        Sphere radii [m].
    mass : float
        [kg]
    centre_of_mass : ndarray (3,)
        In the template frame [m].
    principal_moments : ndarray (3,)
        [kg m2]
    principal_axes : ndarray (3, 3)
        Columns: principal axes in the template frame (a proper rotation).
    mass_model : str
        How mass and inertia were obtained (``MASS_MODELS``).
    """

    name: str
    centres: np.ndarray
    radii: np.ndarray
    mass: float
    centre_of_mass: np.ndarray
    principal_moments: np.ndarray
    principal_axes: np.ndarray
    mass_model: str = "union"
    offsets: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        offsets = (np.asarray(self.centres, float) - self.centre_of_mass) @ self.principal_axes
        object.__setattr__(self, "offsets", offsets)

    @property
    def n_spheres(self) -> int:
        return int(self.radii.size)

    @functools.cached_property
    def bounding_radius(self) -> float:
        """Radius of the smallest sphere about the centre of mass holding every member [m]."""
        return float((np.linalg.norm(self.offsets, axis=1) + self.radii).max())

    def to_dict(self) -> dict:
        return {"name": self.name, "centres": self.centres.tolist(), "radii": self.radii.tolist(),
                "mass": self.mass, "centre_of_mass": self.centre_of_mass.tolist(),
                "principal_moments": self.principal_moments.tolist(),
                "principal_axes": self.principal_axes.tolist(), "mass_model": self.mass_model}


def make_template(centres, radii, density: float, *, name: str = "clump", mass_model: str = "union",
                  mean_mass: float | None = None, cylinder: tuple[float, float] | None = None,
                  body: MassProperties | None = None, resolution: int = 600) -> ClumpTemplate:
    """Build a ``ClumpTemplate`` from sphere centres [m], radii [m] and a density [kg/m3].

    ``mass_model="body"`` needs ``body``, the mass properties of the body the spheres stand for
    in the template frame; ``"cylinder"`` needs ``cylinder=(length, diameter)`` [m] (a
    cylinder along the template x axis, centred at the origin); ``"scaled"`` needs
    ``mean_mass`` [kg].
    """
    centres = np.asarray(centres, dtype=float).reshape(-1, 3)
    radii = np.broadcast_to(np.asarray(radii, dtype=float), (centres.shape[0],)).copy()
    if centres.shape[0] == 0:
        raise InputError("a clump template needs at least one sphere")
    if not np.all(radii > 0):
        raise InputError(f"clump sphere radii must be > 0, got {radii.tolist()}")
    if not density > 0:
        raise InputError(f"density must be > 0, got {density!r}")
    def union():
        if spheres_overlap(centres, radii):
            return union_mass_properties(centres, radii, density, resolution)
        return disjoint_spheres_mass_properties(centres, radii, density)

    if mass_model == "union":
        props = union()
    elif mass_model == "scaled":
        if not (mean_mass and mean_mass > 0):
            raise InputError(f"mass_model='scaled' needs mean_mass > 0 [kg], got {mean_mass!r}")
        union = union()
        k = mean_mass / union.mass
        props = MassProperties(float(mean_mass), union.centre_of_mass, union.inertia * k)
    elif mass_model == "cylinder":
        if cylinder is None:
            raise InputError("mass_model='cylinder' is a segment's body: it needs cylinder=(length, diameter) [m]")
        props = cylinder_mass_properties(cylinder[0], cylinder[1], density)
    elif mass_model == "body":
        if body is None:
            raise InputError(f"mass_model='body' needs the mass properties of the body of {name!r}")
        props = body
    else:
        raise InputError(f"unknown mass_model {mass_model!r}; valid: {', '.join(MASS_MODELS)}")
    moments, axes = principal_frame(props.inertia)
    return ClumpTemplate(name, centres, radii, props.mass, np.asarray(props.centre_of_mass, float),
                         moments, axes, mass_model)


def segment_centres(length: float, diameter: float, n_spheres: int) -> np.ndarray:
    """Centres [m] of ``n_spheres`` spheres of radius D/2 along x, ends at +-(L/2 - D/2)."""
    if n_spheres < 1:
        raise InputError(f"n_spheres must be >= 1, got {n_spheres!r}")
    if diameter > length:
        raise InputError(f"segment diameter ({diameter!r} m) exceeds its length ({length!r} m)")
    end = length / 2.0 - diameter / 2.0
    x = np.linspace(-end, end, n_spheres) if n_spheres > 1 else np.zeros(1)
    return np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])


def segment_template(length: float, diameter: float, n_spheres: int, density: float, *,
                     mass_model: str = "union", mean_mass: float | None = None,
                     name: str = "segment") -> ClumpTemplate:
    """The paper's segment: ``n_spheres`` spheres of radius D/2 over length L (along x)."""
    centres = segment_centres(length, diameter, n_spheres)
    return make_template(centres, diameter / 2.0, density, name=name, mass_model=mass_model,
                         mean_mass=mean_mass, cylinder=(length, diameter))
