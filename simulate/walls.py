"""Rigid walls: infinite planes, finite rectangles and open cylinders or cones, static or translating.

``Plane(point, normal)``
    One-sided infinite plane (the floor); spheres are kept on the side ``normal`` points to.
``Rectangle(centre, axis_u, axis_v, half_u, half_v)``
    Finite, two-sided rectangle (carton sides, the lifted end plate). A sphere touches it at the
    closest point of the rectangle, so its edges and corners push correctly.
``Cylinder(centre, axis, radius, half_height, top_radius=None)``
    Finite, two-sided open tube (the lifting cylinder of a repose test): its surface is the
    points at ``radius`` from the axis within ``half_height`` of ``centre`` along it; a sphere
    touches it at the closest point of that surface, so its rims push correctly too. With a
    ``top_radius`` the radius changes linearly from ``radius`` at ``-half_height`` to
    ``top_radius`` at ``+half_height``: a truncated cone (a funnel), whose closest point is
    found on the straight generator in the plane through the axis and the sphere centre.
``box_rectangles(lo, hi, faces=...)``
    The faces of an axis-aligned box as rectangles (e.g. an open carton: no "z+" face).

A wall may translate at a constant ``velocity`` [m/s] during ``[move_start, move_stop)`` [s]
(e.g. the end plate lifted at 0.1 m/s from t = 4 s). The wall's velocity enters the relative
contact velocity, so friction and damping see the moving surface.

A rectangle or a cylinder may also spin at ``spin`` [rad/s] (an angular velocity vector) about
the axis through its ``centre`` during the same window: its surface moves at
``velocity + spin x (p - centre)`` at a contact point p, while its shape stays where it is.
That is exact for a wall that is symmetric about the spin axis: a tube spinning about its own
axis (a rotating drum), or a plate spinning about its normal through its centre whose edges
the particles never reach (the drum's end plates, larger than the drum). The rolling friction
against a wall uses the sphere's own angular velocity, as LIGGGHTS' ``cdt`` model does.

Kernel layout (``pack_walls``): one row per wall in float64 arrays ``kind`` (0 plane,
1 rectangle, 2 cylinder or cone), ``origin``, ``normal`` (a cylinder's axis), ``axis_u``,
``axis_v``, ``half`` (3: a rectangle's half sizes; a cylinder's radius, half height and top
radius), ``velocity``, ``spin``, ``window`` (2) and int ``material``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from demcal.errors import InputError
from demcal.simulate._jit import evaluator, kernel

PLANE, RECTANGLE, CYLINDER = 0, 1, 2


def _unit(vector, name):
    v = np.asarray(vector, dtype=float).reshape(3)
    n = np.linalg.norm(v)
    if not (np.isfinite(n) and n > 0):
        raise InputError(f"{name} must be a non-zero 3-vector, got {vector!r}")
    return v / n


@dataclass(frozen=True)
class Plane:
    """Infinite one-sided plane through ``point`` [m] with unit ``normal`` toward the particles."""

    point: tuple
    normal: tuple
    material: str = "steel"
    velocity: tuple = (0.0, 0.0, 0.0)
    move_start: float = 0.0
    move_stop: float = math.inf
    name: str = "plane"

    def to_dict(self) -> dict:
        return {"kind": "plane", "point": list(self.point), "normal": list(self.normal),
                "material": self.material, "velocity": list(self.velocity),
                "move_start": self.move_start, "move_stop": self.move_stop, "name": self.name}


@dataclass(frozen=True)
class Rectangle:
    """Finite two-sided rectangle: ``centre`` [m], in-plane unit axes ``axis_u``, ``axis_v``
    (orthogonal) and half-sizes ``half_u``, ``half_v`` [m] along them."""

    centre: tuple
    axis_u: tuple
    axis_v: tuple
    half_u: float
    half_v: float
    material: str = "steel"
    velocity: tuple = (0.0, 0.0, 0.0)
    move_start: float = 0.0
    move_stop: float = math.inf
    name: str = "rectangle"
    spin: tuple = (0.0, 0.0, 0.0)

    def to_dict(self) -> dict:
        return {"kind": "rectangle", "centre": list(self.centre), "axis_u": list(self.axis_u),
                "axis_v": list(self.axis_v), "half_u": self.half_u, "half_v": self.half_v,
                "material": self.material, "velocity": list(self.velocity),
                "move_start": self.move_start, "move_stop": self.move_stop, "name": self.name,
                **_spin_entry(self.spin)}


@dataclass(frozen=True)
class Cylinder:
    """Finite two-sided open tube: axis through ``centre`` [m] along ``axis`` (unit), ``radius``
    [m], extending ``half_height`` [m] either side of ``centre`` along the axis; with
    ``top_radius`` [m] a truncated cone, its radius ``radius`` at ``-half_height`` and
    ``top_radius`` at ``+half_height`` along the axis (None: a cylinder)."""

    centre: tuple
    axis: tuple
    radius: float
    half_height: float
    material: str = "steel"
    velocity: tuple = (0.0, 0.0, 0.0)
    move_start: float = 0.0
    move_stop: float = math.inf
    name: str = "cylinder"
    top_radius: float | None = None
    spin: tuple = (0.0, 0.0, 0.0)

    def to_dict(self) -> dict:
        out = {"kind": "cylinder", "centre": list(self.centre), "axis": list(self.axis),
               "radius": self.radius, "half_height": self.half_height, "material": self.material,
               "velocity": list(self.velocity), "move_start": self.move_start,
               "move_stop": self.move_stop, "name": self.name, **_spin_entry(self.spin)}
        if self.top_radius is not None:
            out["top_radius"] = self.top_radius
        return out


def _spin_entry(spin) -> dict:
    """A spinning wall's ``spin`` for its ``to_dict`` (none for a wall that does not spin, so the
    records of the walls before spins existed are unchanged)."""
    return {"spin": [float(v) for v in spin]} if any(float(v) != 0.0 for v in spin) else {}


WALL_TYPES = (Plane, Rectangle, Cylinder)

BOX_FACES = ("x-", "x+", "y-", "y+", "z-", "z+")


def box_rectangles(lo, hi, faces=BOX_FACES, material: str = "steel", name: str = "box") -> list[Rectangle]:
    """Rectangles on the chosen ``faces`` of the axis-aligned box ``lo``-``hi`` [m]."""
    lo = np.asarray(lo, dtype=float)
    hi = np.asarray(hi, dtype=float)
    if not np.all(hi > lo):
        raise InputError(f"box hi {hi.tolist()} must exceed lo {lo.tolist()} on every axis")
    unknown = [f for f in faces if f not in BOX_FACES]
    if unknown:
        raise InputError(f"unknown box face(s) {unknown}; valid: {', '.join(BOX_FACES)}")
    mid = (lo + hi) / 2.0
    half = (hi - lo) / 2.0
    eye = np.eye(3)
    out = []
    for face in faces:
        axis = "xyz".index(face[0])
        u_axis, v_axis = [a for a in range(3) if a != axis]
        centre = mid.copy()
        centre[axis] = lo[axis] if face[1] == "-" else hi[axis]
        out.append(Rectangle(tuple(centre), tuple(eye[u_axis]), tuple(eye[v_axis]),
                             float(half[u_axis]), float(half[v_axis]), material, name=f"{name} {face}"))
    return out


def pack_walls(walls, material_index) -> dict:
    """Kernel arrays of ``walls`` (see module docstring); ``material_index(name) -> int``."""
    n = len(walls)
    out = {"kind": np.zeros(n, np.int64), "origin": np.zeros((n, 3)), "normal": np.zeros((n, 3)),
           "axis_u": np.zeros((n, 3)), "axis_v": np.zeros((n, 3)), "half": np.zeros((n, 3)),
           "velocity": np.zeros((n, 3)), "spin": np.zeros((n, 3)), "window": np.zeros((n, 2)),
           "material": np.zeros(n, np.int64)}
    for k, w in enumerate(walls):
        if isinstance(w, Plane):
            out["kind"][k] = PLANE
            out["origin"][k] = np.asarray(w.point, float)
            out["normal"][k] = _unit(w.normal, f"wall {w.name!r} normal")
        elif isinstance(w, Rectangle):
            u = _unit(w.axis_u, f"wall {w.name!r} axis_u")
            v = _unit(w.axis_v, f"wall {w.name!r} axis_v")
            if abs(u @ v) > 1e-9:
                raise InputError(f"wall {w.name!r}: axis_u and axis_v must be orthogonal")
            if not (w.half_u > 0 and w.half_v > 0):
                raise InputError(f"wall {w.name!r}: half sizes must be > 0, got {w.half_u!r}, {w.half_v!r}")
            out["kind"][k] = RECTANGLE
            out["origin"][k] = np.asarray(w.centre, float)
            out["axis_u"][k] = u
            out["axis_v"][k] = v
            out["normal"][k] = np.cross(u, v)
            out["half"][k] = (w.half_u, w.half_v, 0.0)
        elif isinstance(w, Cylinder):
            top = w.radius if w.top_radius is None else w.top_radius
            if not (w.radius > 0 and w.half_height > 0 and top > 0):
                raise InputError(f"wall {w.name!r}: radius, top radius and half height must be > 0, "
                                 f"got {w.radius!r}, {top!r}, {w.half_height!r}")
            axis = _unit(w.axis, f"wall {w.name!r} axis")
            # any unit vector across the axis: the direction used for a point on the axis
            u = np.cross(axis, (1.0, 0.0, 0.0) if abs(axis[0]) < 0.9 else (0.0, 1.0, 0.0))
            out["kind"][k] = CYLINDER
            out["origin"][k] = np.asarray(w.centre, float)
            out["normal"][k] = axis
            out["axis_u"][k] = u / np.linalg.norm(u)
            out["axis_v"][k] = np.cross(axis, out["axis_u"][k])
            out["half"][k] = (w.radius, w.half_height, top)
        else:
            raise InputError(f"not a wall: {w!r}")
        out["velocity"][k] = np.asarray(w.velocity, float).reshape(3)
        out["spin"][k] = np.asarray(getattr(w, "spin", (0.0, 0.0, 0.0)), float).reshape(3)
        if not np.all(np.isfinite(out["spin"][k])):
            raise InputError(f"wall {w.name!r}: spin must be a finite 3-vector [rad/s], got {w.spin!r}")
        if not w.move_stop >= w.move_start:
            raise InputError(f"wall {w.name!r}: move_stop ({w.move_stop!r}) is before "
                             f"move_start ({w.move_start!r})")
        out["window"][k] = (w.move_start, w.move_stop)
        out["material"][k] = material_index(w.material)
    return out


@evaluator
def wall_distance(kind, origin, normal, axis_u, axis_v, half, k, x, y, z):
    """Distance [m] from point (x, y, z) to wall ``k`` and the unit normal from the wall to it.

    Plane: signed distance along its normal (negative behind it). Rectangle: distance to the
    closest point of the rectangle (its edges included); at zero distance the rectangle normal.
    Cylinder: distance to the closest point of the tube (its rims included); at zero distance
    the radial direction. A cone: the closest point on its generator, the segment from
    (radius, -half height) to (top radius, +half height) in the plane through the axis.
    """
    dx = x - origin[k, 0]
    dy = y - origin[k, 1]
    dz = z - origin[k, 2]
    nx = normal[k, 0]
    ny = normal[k, 1]
    nz = normal[k, 2]
    if kind[k] == PLANE:
        return dx * nx + dy * ny + dz * nz, nx, ny, nz
    if kind[k] == CYLINDER:
        a = dx * nx + dy * ny + dz * nz
        rx = dx - a * nx
        ry = dy - a * ny
        rz = dz - a * nz
        rho = math.sqrt(rx * rx + ry * ry + rz * rz)
        if rho > 0.0:
            ex = rx / rho
            ey = ry / rho
            ez = rz / rho
        else:
            ex = axis_u[k, 0]
            ey = axis_u[k, 1]
            ez = axis_u[k, 2]
        hh = half[k, 1]
        r0 = half[k, 0]
        r1 = half[k, 2]
        if r1 == r0:
            ac = -hh if a < -hh else (hh if a > hh else a)
            rc = r0
        else:
            # closest point of the generator (r0, -hh)-(r1, hh) to (rho, a)
            gr = r1 - r0
            ga = 2.0 * hh
            t = ((rho - r0) * gr + (a + hh) * ga) / (gr * gr + ga * ga)
            t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
            ac = -hh + t * ga
            rc = r0 + t * gr
        # vector from the closest point of the tube to the sphere centre
        px = dx - ac * nx - rc * ex
        py = dy - ac * ny - rc * ey
        pz = dz - ac * nz - rc * ez
        d = math.sqrt(px * px + py * py + pz * pz)
        if d == 0.0:
            return 0.0, ex, ey, ez
        inv = 1.0 / d
        return d, px * inv, py * inv, pz * inv
    du = dx * axis_u[k, 0] + dy * axis_u[k, 1] + dz * axis_u[k, 2]
    dv = dx * axis_v[k, 0] + dy * axis_v[k, 1] + dz * axis_v[k, 2]
    hu = half[k, 0]
    hv = half[k, 1]
    du = -hu if du < -hu else (hu if du > hu else du)
    dv = -hv if dv < -hv else (hv if dv > hv else dv)
    # vector from the closest point of the rectangle to the sphere centre
    px = dx - du * axis_u[k, 0] - dv * axis_v[k, 0]
    py = dy - du * axis_u[k, 1] - dv * axis_v[k, 1]
    pz = dz - du * axis_u[k, 2] - dv * axis_v[k, 2]
    d = math.sqrt(px * px + py * py + pz * pz)
    if d == 0.0:
        return 0.0, nx, ny, nz
    inv = 1.0 / d
    return d, px * inv, py * inv, pz * inv


@kernel
def walls_near(kind, origin, normal, axis_u, axis_v, half, x, y, z, reach):
    """Indices of the walls closer than ``reach`` [m] to point (x, y, z) (``wall_distance``,
    with a margin well over its rounding): the only walls a body within ``reach`` of the
    point can touch, a wall's distance changing by at most the distance moved."""
    out = np.empty(kind.shape[0], np.int64)
    n = 0
    for k in range(kind.shape[0]):
        d, nx, ny, nz = wall_distance(kind, origin, normal, axis_u, axis_v, half, k, x, y, z)
        if d < reach * (1.0 + 1e-6) + 1e-9:
            out[n] = k
            n += 1
    return out[:n]


def wall_distances(packed: dict, points) -> np.ndarray:
    """Distances [m] from ``points`` (n, 3) to every wall of ``pack_walls`` output, (n, n_walls);
    the numpy twin of ``wall_distance`` (signed for planes)."""
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    n_walls = packed["kind"].shape[0]
    out = np.empty((p.shape[0], n_walls))
    for k in range(n_walls):
        d = p - packed["origin"][k]
        if packed["kind"][k] == PLANE:
            out[:, k] = d @ packed["normal"][k]
            continue
        if packed["kind"][k] == CYLINDER:
            n = packed["normal"][k]
            r0, hh, r1 = packed["half"][k]
            a = d @ n
            radial = np.linalg.norm(d - a[:, None] * n, axis=1)
            # distance within the plane through the axis: from (radial, a) to the generator,
            # the segment from (r0, -hh) to (r1, hh)
            g = np.array([r1 - r0, 2.0 * hh])
            t = np.clip(((radial - r0) * g[0] + (a + hh) * g[1]) / (g @ g), 0.0, 1.0)
            out[:, k] = np.hypot(radial - (r0 + t * g[0]), a - (-hh + t * g[1]))
            continue
        u, v = packed["axis_u"][k], packed["axis_v"][k]
        du = np.clip(d @ u, -packed["half"][k, 0], packed["half"][k, 0])
        dv = np.clip(d @ v, -packed["half"][k, 1], packed["half"][k, 1])
        out[:, k] = np.linalg.norm(d - du[:, None] * u - dv[:, None] * v, axis=1)
    return out
