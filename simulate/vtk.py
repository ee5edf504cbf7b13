"""Frames for ParaView: spheres and walls as VTK XML PolyData (.vtp), series as .pvd collections.

``write_vtp(path, sim)``
    One point per sphere (its centre), as a vertex cell, with point data ``clump_id`` (the body
    the sphere belongs to, the row of ``sim.positions()``), ``radius`` [m], ``velocity`` [m/s]
    (3 components, of the sphere centre: v + w x (x_s - x_b)), ``speed`` [m/s] (its magnitude)
    and ``active`` (0 once the body left the domain). In ParaView use a "Glyph" filter of type
    Sphere, scale array ``radius``, scale factor 2 (the glyph's size is a diameter).
``write_walls_vtp(path, sim)``
    Quads of every wall, where the wall is at ``sim.time`` (a moving plate at its current
    height), with cell data ``wall_id`` (index in ``sim.walls``) and ``kind`` (0 plane,
    1 rectangle, 2 cylinder). A ``Rectangle`` is its own quad, a ``Cylinder`` a ring of
    ``CYLINDER_FACETS`` quads. An infinite ``Plane`` is drawn as the rectangle on it that
    covers the orthogonal projection of the simulation domain (``domain_lo``-``domain_hi``):
    bodies leaving the domain are deactivated, so nothing of interest lies beyond it.
``write_pvd(path, entries)``
    A ParaView collection (time series) over ``(time, file)`` entries.
``FrameSeries(folder)``
    The frames of one run in a folder: ``frame_NNNN.vtp`` (spheres) and ``walls_NNNN.vtp`` at the
    same times, listed in ``particles.pvd`` and ``walls.pvd``; ``last.vtp`` and
    ``last_walls.vtp`` hold the final state. Open both collections in ParaView.
``read_vtp(path)``
    Reads a .vtp written here back into numpy arrays (no VTK needed).

The format is ASCII XML (VTK file format version 1.0), readable by ParaView and VisIt; each
frame also carries its time [s] as field data ``TIME``.

Reference: Kitware, "VTK File Formats", https://docs.vtk.org/en/latest/design_documents/VTKFileFormats.html
"""

from __future__ import annotations

import os
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from demcal.errors import InputError
from demcal.simulate.walls import CYLINDER, PLANE, pack_walls

#: Quads a cylinder is drawn with.
CYLINDER_FACETS = 32

#: Collections and file names of a ``FrameSeries``.
PARTICLES_PVD = "particles.pvd"
WALLS_PVD = "walls.pvd"
LAST_PARTICLES = "last.vtp"
LAST_WALLS = "last_walls.vtp"


def _data_array(parent, name, values, n_components, vtk_type):
    node = ET.SubElement(parent, "DataArray", type=vtk_type, Name=name,
                         NumberOfComponents=str(n_components), format="ascii")
    fmt = "%.17g" if vtk_type.startswith("Float") else "%d"
    node.text = "\n" + "\n".join(" ".join(fmt % v for v in row)
                                 for row in np.asarray(values).reshape(-1, n_components)) + "\n"
    return node


def _check_suffix(path) -> Path:
    path = Path(path)
    if path.suffix != ".vtp":
        raise InputError(f"VTK PolyData files end in .vtp, got {str(path)!r}")
    return path


def _polydata(points, time, n_verts=0, n_polys=0):
    """The ``VTKFile``/``Piece`` skeleton with ``points`` (n, 3) and ``time`` [s] written."""
    root = ET.Element("VTKFile", type="PolyData", version="1.0", byte_order="LittleEndian")
    poly = ET.SubElement(root, "PolyData")
    # field data belongs to the data set, before its pieces: VTK ignores it inside a piece
    fdata = ET.SubElement(poly, "FieldData")
    _data_array(fdata, "TIME", [time], 1, "Float64").set("NumberOfTuples", "1")
    piece = ET.SubElement(poly, "Piece", NumberOfPoints=str(len(points)), NumberOfVerts=str(n_verts),
                          NumberOfLines="0", NumberOfStrips="0", NumberOfPolys=str(n_polys))
    _data_array(ET.SubElement(piece, "Points"), "Points", points, 3, "Float64")
    return root, piece


def _write(root, path):
    path.parent.mkdir(parents=True, exist_ok=True)
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)
    return path


def sphere_velocities(sim) -> np.ndarray:
    """Velocity [m/s] of every sphere centre of ``sim``, (n_spheres, 3): v + w x (x_s - x_b)."""
    body = sim.sphere_body()
    return sim.velocities()[body] + np.cross(sim.angular_velocities()[body],
                                             sim.sphere_positions() - sim.positions()[body])


def write_vtp(path, sim, active_only: bool = False) -> Path:
    """Write the spheres of ``sim`` (a ``Simulation``) to ``path`` (.vtp); returns the path.

    Parameters
    ----------
    path : str or Path
        Output file, ending in ``.vtp``.
    sim : Simulation
        Its current state is written (see the module docstring for the point data).
    active_only : bool
        Leave out the spheres of bodies that left the domain.
    """
    path = _check_suffix(path)
    centres = sim.sphere_positions()
    radius = sim.sphere_radii()
    body = sim.sphere_body()
    active = sim.active()[body] if body.size else np.zeros(0, bool)
    v = sphere_velocities(sim)
    if active_only:
        centres, radius, body, active, v = (a[active] for a in (centres, radius, body, active, v))
    n = centres.shape[0]
    root, piece = _polydata(centres, sim.time, n_verts=n)
    verts = ET.SubElement(piece, "Verts")
    _data_array(verts, "connectivity", np.arange(n), 1, "Int64")
    _data_array(verts, "offsets", np.arange(1, n + 1), 1, "Int64")
    pdata = ET.SubElement(piece, "PointData", Scalars="radius", Vectors="velocity")
    _data_array(pdata, "radius", radius, 1, "Float64")
    _data_array(pdata, "clump_id", body, 1, "Int64")
    _data_array(pdata, "velocity", v, 3, "Float64")
    _data_array(pdata, "speed", np.linalg.norm(v, axis=1), 1, "Float64")
    _data_array(pdata, "active", active.astype(np.int64), 1, "Int64")
    return _write(root, path)


def _plane_basis(normal):
    """Unit in-plane axes (u, v) with u x v = ``normal``; u is the world axis least along it."""
    axis = np.eye(3)[int(np.argmin(np.abs(normal)))]
    u = axis - (axis @ normal) * normal
    u /= np.linalg.norm(u)
    return u, np.cross(normal, u)


def wall_quads(walls, origins, domain_lo, domain_hi):
    """Corners of the quads that draw the walls, (m, 4, 3), counter-clockwise about the wall's
    outward side, and the wall of each quad, (m,).

    Parameters
    ----------
    walls : list of Plane, Rectangle or Cylinder
        The walls (their axes, sizes and normals; not their positions).
    origins : (n_walls, 3) array
        Current point (plane) or centre (rectangle, cylinder) of each wall [m].
    domain_lo, domain_hi : 3-sequence
        Domain corners [m]; a plane's quad covers the domain's projection onto it.
    """
    # unit axes and normals as the engine uses them; materials play no part here
    packed = pack_walls(walls, lambda name: 0)
    origins = np.asarray(origins, dtype=float).reshape(-1, 3)
    lo, hi = np.asarray(domain_lo, float), np.asarray(domain_hi, float)
    box = np.array([[hi[a] if (c >> a) & 1 else lo[a] for a in range(3)] for c in range(8)])
    quads, owner = [], []
    for k in range(len(walls)):
        c = origins[k]
        if packed["kind"][k] == CYLINDER:
            axis, u, v = packed["normal"][k], packed["axis_u"][k], packed["axis_v"][k]
            r0, hh, r1 = packed["half"][k]
            phi = np.linspace(0.0, 2.0 * np.pi, CYLINDER_FACETS + 1)
            ring = np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * v
            low, high = r0 * ring - hh * axis, r1 * ring + hh * axis
            for f in range(CYLINDER_FACETS):
                quads.append([c + low[f], c + low[f + 1], c + high[f + 1], c + high[f]])
                owner.append(k)
            continue
        if packed["kind"][k] == PLANE:
            u, v = _plane_basis(packed["normal"][k])
            a, b = (box - c) @ u, (box - c) @ v
            # the centre of the covering rectangle, then its half sizes
            c = c + 0.5 * (a.max() + a.min()) * u + 0.5 * (b.max() + b.min()) * v
            hu, hv = 0.5 * (a.max() - a.min()), 0.5 * (b.max() - b.min())
        else:
            u, v = packed["axis_u"][k], packed["axis_v"][k]
            hu, hv = packed["half"][k, :2]
        quads.append([c - hu * u - hv * v, c + hu * u - hv * v, c + hu * u + hv * v, c - hu * u + hv * v])
        owner.append(k)
    return np.array(quads, dtype=float).reshape(-1, 4, 3), np.array(owner, dtype=np.int64)


def write_walls_vtp(path, sim) -> Path:
    """Write the walls of ``sim`` where they are now to ``path`` (.vtp), as quads.

    See the module docstring for how an infinite plane and a cylinder are drawn and for the
    cell data.
    """
    path = _check_suffix(path)
    quads, owner = wall_quads(sim.walls, sim.wall_origins(), sim.domain_lo, sim.domain_hi)
    n = quads.shape[0]
    root, piece = _polydata(quads.reshape(-1, 3), sim.time, n_polys=n)
    polys = ET.SubElement(piece, "Polys")
    _data_array(polys, "connectivity", np.arange(4 * n), 1, "Int64")
    _data_array(polys, "offsets", 4 * np.arange(1, n + 1), 1, "Int64")
    cdata = ET.SubElement(piece, "CellData", Scalars="wall_id")
    _data_array(cdata, "wall_id", owner, 1, "Int64")
    kinds = pack_walls(sim.walls, lambda name: 0)["kind"]
    _data_array(cdata, "kind", kinds[owner], 1, "Int64")
    return _write(root, path)


def write_pvd(path, entries) -> Path:
    """Write a ParaView collection over ``entries``, ``(time [s], file)`` pairs in time order.

    Each ``file`` is given relative to the collection's folder, where ParaView looks for it
    (an absolute path is made relative).
    """
    path = Path(path)
    if path.suffix != ".pvd":
        raise InputError(f"ParaView collections end in .pvd, got {str(path)!r}")
    root = ET.Element("VTKFile", type="Collection", version="0.1", byte_order="LittleEndian")
    coll = ET.SubElement(root, "Collection")
    for time, file in entries:
        rel = os.path.relpath(Path(file), path.parent) if Path(file).is_absolute() else str(file)
        ET.SubElement(coll, "DataSet", timestep=repr(float(time)), group="", part="0",
                      file=Path(rel).as_posix())
    ET.indent(root)
    path.parent.mkdir(parents=True, exist_ok=True)
    # replace in one step, so ParaView never reads a half-written collection
    tmp = path.with_suffix(".pvd.tmp")
    ET.ElementTree(root).write(tmp, encoding="utf-8", xml_declaration=True)
    os.replace(tmp, path)
    return path


class FrameSeries:
    """The frames of one run in ``folder``: spheres and walls at the same times, two collections.

    ``write(sim)`` adds a frame of the current state (``frame_NNNN.vtp``, ``walls_NNNN.vtp``)
    and rewrites ``particles.pvd`` and ``walls.pvd``, so a run stopped midway still leaves a
    series ParaView opens. A frame at the time of the previous one replaces it, so the
    timesteps strictly increase. ``write(sim, last=True)`` also copies the frame to ``last.vtp``
    and ``last_walls.vtp``.

    Parameters
    ----------
    folder : str or Path
        Made if missing; an existing file there is an ``InputError``.
    active_only : bool
        Leave out the spheres of bodies that left the domain.
    """

    def __init__(self, folder, active_only: bool = False):
        if not str(folder).strip():
            raise InputError("the frames folder needs a name, got ''")
        self.folder = Path(folder)
        if self.folder.exists() and not self.folder.is_dir():
            raise InputError(f"{str(self.folder)!r} is a file; frames need a folder")
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise InputError(f"cannot make the frames folder {str(self.folder)!r}: "
                             f"{exc.strerror or exc}") from None
        self.active_only = bool(active_only)
        self.times: list[float] = []

    def _names(self, k):
        return f"frame_{k:04d}.vtp", f"walls_{k:04d}.vtp"

    def write(self, sim, last: bool = False) -> int:
        """Write the current state of ``sim`` as a frame; returns the frame's number."""
        t = float(sim.time)
        if self.times and t < self.times[-1]:
            raise InputError(f"frame at t = {t:g} s is before the previous one "
                             f"({self.times[-1]:g} s); frames must go forward in time")
        if self.times and t == self.times[-1]:
            # same time: the state may still differ (clumps inserted), so rewrite that frame
            k = len(self.times) - 1
        else:
            k = len(self.times)
            self.times.append(t)
        spheres, walls = self._names(k)
        write_vtp(self.folder / spheres, sim, active_only=self.active_only)
        write_walls_vtp(self.folder / walls, sim)
        names = [self._names(i) for i in range(len(self.times))]
        write_pvd(self.folder / PARTICLES_PVD, [(ti, n[0]) for ti, n in zip(self.times, names)])
        write_pvd(self.folder / WALLS_PVD, [(ti, n[1]) for ti, n in zip(self.times, names)])
        if last:
            shutil.copyfile(self.folder / spheres, self.folder / LAST_PARTICLES)
            shutil.copyfile(self.folder / walls, self.folder / LAST_WALLS)
        return k


def read_pvd(path) -> list[tuple[float, Path]]:
    """``(time [s], file)`` of every data set of a .pvd collection, files resolved against its
    folder."""
    root = ET.parse(path).getroot()
    if root.get("type") != "Collection":
        raise InputError(f"{path}: not a ParaView collection (.pvd)")
    folder = Path(path).parent
    return [(float(d.get("timestep")), folder / d.get("file")) for d in root.iter("DataSet")]


def read_vtp(path) -> dict:
    """Read a .vtp written here: ``points`` (n, 3), every point- and cell-data array by name,
    ``polys`` (connectivity split per polygon, when there are polygons), plus ``time``."""
    root = ET.parse(path).getroot()
    if root.get("type") != "PolyData":
        raise InputError(f"{path}: not a VTK PolyData file")
    piece = root.find("PolyData/Piece")
    out = {}

    def parse(node):
        dtype = float if node.get("type").startswith("Float") else int
        values = np.array(node.text.split(), dtype=dtype)
        k = int(node.get("NumberOfComponents", "1"))
        return values.reshape(-1, k) if k > 1 else values

    out["points"] = parse(piece.find("Points/DataArray")).reshape(-1, 3)
    for section in ("PointData", "CellData"):
        for node in piece.findall(f"{section}/DataArray"):
            out[node.get("Name")] = parse(node)
    polys = piece.find("Polys")
    if polys is not None:
        conn = parse(polys.find("DataArray[@Name='connectivity']"))
        offsets = parse(polys.find("DataArray[@Name='offsets']"))
        out["polys"] = np.split(conn, offsets[:-1]) if offsets.size else []
    # older frames kept TIME inside the piece
    time_node = root.find("PolyData/FieldData/DataArray[@Name='TIME']")
    if time_node is None:
        time_node = piece.find("FieldData/DataArray[@Name='TIME']")
    if time_node is not None:
        out["time"] = float(parse(time_node)[0])
    return out
