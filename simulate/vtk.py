"""Frames for ParaView: the member spheres of every clump as a VTK XML PolyData file (.vtp).

``write_vtp(path, sim)`` writes one point per sphere (its centre) with point data ``radius``
[m], ``clump_id``, ``velocity`` [m/s] (of the sphere centre) and ``active``; in ParaView use a
"Glyph" filter of type Sphere scaled by ``radius`` (scale factor 2 for the diameter).
``read_vtp(path)`` reads such a file back into numpy arrays. The format is ASCII XML
(VTK file format version 1.0), readable by ParaView and VisIt.

Reference: Kitware, "VTK File Formats", https://docs.vtk.org/en/latest/design_documents/VTKFileFormats.html
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from demcal.errors import InputError


def _data_array(parent, name, values, n_components, vtk_type):
    node = ET.SubElement(parent, "DataArray", type=vtk_type, Name=name,
                         NumberOfComponents=str(n_components), format="ascii")
    fmt = "%.17g" if vtk_type.startswith("Float") else "%d"
    node.text = "\n" + "\n".join(" ".join(fmt % v for v in row)
                                 for row in np.asarray(values).reshape(-1, n_components)) + "\n"
    return node


def write_vtp(path, sim, active_only: bool = False) -> Path:
    """Write the spheres of ``sim`` (a ``Simulation``) to ``path`` (.vtp); returns the path.

    ``active_only`` leaves out the spheres of bodies that left the domain.
    """
    path = Path(path)
    if path.suffix != ".vtp":
        raise InputError(f"VTK PolyData files end in .vtp, got {str(path)!r}")
    centres = sim.sphere_positions()
    radius = sim.sphere_radii()
    body = sim.sphere_body()
    active = sim.active()[body] if body.size else np.zeros(0, bool)
    # velocity of each sphere centre: v + w x (x_s - x_b)
    v = sim.velocities()[body] + np.cross(sim.angular_velocities()[body], centres - sim.positions()[body])
    if active_only:
        centres, radius, body, active, v = (a[active] for a in (centres, radius, body, active, v))
    n = centres.shape[0]
    root = ET.Element("VTKFile", type="PolyData", version="1.0", byte_order="LittleEndian")
    poly = ET.SubElement(root, "PolyData")
    piece = ET.SubElement(poly, "Piece", NumberOfPoints=str(n), NumberOfVerts=str(n),
                          NumberOfLines="0", NumberOfStrips="0", NumberOfPolys="0")
    points = ET.SubElement(piece, "Points")
    _data_array(points, "Points", centres, 3, "Float64")
    verts = ET.SubElement(piece, "Verts")
    _data_array(verts, "connectivity", np.arange(n), 1, "Int64")
    _data_array(verts, "offsets", np.arange(1, n + 1), 1, "Int64")
    pdata = ET.SubElement(piece, "PointData", Scalars="radius")
    _data_array(pdata, "radius", radius, 1, "Float64")
    _data_array(pdata, "clump_id", body, 1, "Int64")
    _data_array(pdata, "velocity", v, 3, "Float64")
    _data_array(pdata, "active", active.astype(np.int64), 1, "Int64")
    fdata = ET.SubElement(piece, "FieldData")
    _data_array(fdata, "TIME", [sim.time], 1, "Float64").set("NumberOfTuples", "1")
    path.parent.mkdir(parents=True, exist_ok=True)
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)
    return path


def read_vtp(path) -> dict:
    """Read a .vtp written by ``write_vtp``: ``points`` (n, 3) and every point-data array by
    name, plus ``time``."""
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
    for node in piece.find("PointData"):
        out[node.get("Name")] = parse(node)
    time_node = piece.find("FieldData/DataArray[@Name='TIME']")
    if time_node is not None:
        out["time"] = float(parse(time_node)[0])
    return out
