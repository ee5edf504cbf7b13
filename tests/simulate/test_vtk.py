"""VTK export: frames parse back to the simulation's spheres and walls, in our reader and VTK's.

The ParaView checks read every frame with VTK's own ``vtkXMLPolyDataReader`` (the reader
ParaView uses for .vtp); the .pvd collections are plain XML, parsed here as ParaView does.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest

from demcal.cli import main
from demcal.errors import InputError
from demcal.simulate import DEMParameters
from demcal.simulate.vtk import FrameSeries, read_pvd, read_vtp, write_pvd, write_vtp
from demcal.simulate.walls import PLANE, RECTANGLE, Rectangle, box_rectangles
from tests.simulate.helpers import floor, simulation, sphere_template

SPHERE_FIELDS = {"clump_id", "radius", "velocity", "speed", "active"}


def test_vtp_round_trip(tmp_path):
    sim = simulation(DEMParameters(), dt=1e-5)
    tpl = sim.add_template(DEMParameters().template())
    sim.add_clump(tpl, (0.0, 0.0, 0.05), (0.9, 0.1, 0.3, 0.2), velocity=(0.1, 0.0, 0.0),
                  angular_velocity=(0.0, 0.0, 4.0))
    sim.add_clump(tpl, (0.05, 0.0, 0.05))
    sim.run(n_steps=3)
    path = write_vtp(tmp_path / "frame.vtp", sim)
    root = ET.parse(path).getroot()
    assert root.get("type") == "PolyData" and root.get("version") == "1.0"
    back = read_vtp(path)
    np.testing.assert_array_equal(back["points"], sim.sphere_positions())
    np.testing.assert_array_equal(back["radius"], sim.sphere_radii())
    np.testing.assert_array_equal(back["clump_id"], sim.sphere_body())
    x, body = sim.sphere_positions(), sim.sphere_body()
    v = sim.velocities()[body] + np.cross(sim.angular_velocities()[body], x - sim.positions()[body])
    np.testing.assert_allclose(back["velocity"], v, rtol=1e-15)
    np.testing.assert_allclose(back["speed"], np.linalg.norm(v, axis=1), rtol=1e-15)
    assert back["time"] == sim.time and back["points"].shape == (10, 3)


def test_vtp_needs_the_extension(tmp_path):
    sim = simulation(DEMParameters(), dt=1e-5)
    with pytest.raises(InputError, match=".vtp"):
        write_vtp(tmp_path / "frame.vtk", sim)
    with pytest.raises(InputError, match=".pvd"):
        write_pvd(tmp_path / "series.xml", [])


# ------------------------------------------------------------------ read back by VTK itself
def _vtk_read(path) -> dict:
    """A .vtp through VTK's reader: points, vertex and polygon cells, point and cell data, TIME."""
    pytest.importorskip("vtkmodules.vtkIOXML", reason="VTK (pip install vtk) reads the frames")
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

    reader = vtkXMLPolyDataReader()
    reader.SetFileName(str(path))
    reader.Update()
    assert reader.GetErrorCode() == 0, f"VTK could not read {path}"
    poly = reader.GetOutput()

    def arrays(data):
        return {data.GetArrayName(i): vtk_to_numpy(data.GetArray(i)) for i in range(data.GetNumberOfArrays())}

    polys = poly.GetPolys()
    return {"points": vtk_to_numpy(poly.GetPoints().GetData()), "n_verts": poly.GetNumberOfVerts(),
            "n_polys": poly.GetNumberOfPolys(),
            "poly_offsets": vtk_to_numpy(polys.GetOffsetsArray()),
            "poly_connectivity": vtk_to_numpy(polys.GetConnectivityArray()),
            "point_data": arrays(poly.GetPointData()), "cell_data": arrays(poly.GetCellData()),
            "time": float(vtk_to_numpy(poly.GetFieldData().GetArray("TIME"))[0])}


def _check_collections(folder):
    """Both .pvd files: ParaView's layout, the same strictly increasing times, every frame on
    disk listed once; returns [(time, sphere frame, wall frame)]."""
    for name in ("particles.pvd", "walls.pvd"):
        root = ET.parse(folder / name).getroot()
        assert root.tag == "VTKFile" and root.get("type") == "Collection"
        assert [d.tag for d in root.find("Collection")] == ["DataSet"] * len(root.find("Collection"))
    spheres, walls = read_pvd(folder / "particles.pvd"), read_pvd(folder / "walls.pvd")
    times = [t for t, _ in spheres]
    assert times == [t for t, _ in walls] and len(times) >= 3
    assert np.all(np.diff(times) > 0)
    assert sorted(f for _, f in spheres) == sorted(folder.glob("frame_*.vtp"))
    assert sorted(f for _, f in walls) == sorted(folder.glob("walls_*.vtp"))
    # the final state is the last frame, also under a fixed name for scripts
    assert (folder / "last.vtp").read_bytes() == spheres[-1][1].read_bytes()
    assert (folder / "last_walls.vtp").read_bytes() == walls[-1][1].read_bytes()
    return [(t, s, w) for (t, s), (_, w) in zip(spheres, walls)]


def _check_spheres(frame, n_spheres):
    assert frame["points"].shape == (n_spheres, 3) and frame["n_verts"] == n_spheres
    data = frame["point_data"]
    assert set(data) == SPHERE_FIELDS
    assert data["velocity"].shape == (n_spheres, 3)
    for name in SPHERE_FIELDS - {"velocity"}:
        assert data[name].shape == (n_spheres,)
    np.testing.assert_allclose(data["speed"], np.linalg.norm(data["velocity"], axis=1), rtol=1e-12)


def _wall_quads(frame):
    """The wall polygons as (n_walls, 4, 3) corners, checking each is one quad."""
    assert frame["n_polys"] == len(frame["poly_offsets"]) - 1
    assert np.all(np.diff(frame["poly_offsets"]) == 4)
    return frame["points"][frame["poly_connectivity"]].reshape(-1, 4, 3)


def test_cli_frames_read_by_vtk(tmp_path):
    """``demcal simulate incline --vtk DIR``: a series ParaView reads, spheres over the plate."""
    frames = tmp_path / "frames"
    assert main(["simulate", "incline", "--tilt-rate", "4", "--vtk", str(frames)]) == 0
    series = _check_collections(frames)
    for t, sphere_file, wall_file in series:
        spheres, walls = _vtk_read(sphere_file), _vtk_read(wall_file)
        assert spheres["time"] == t and walls["time"] == t
        _check_spheres(spheres, 5)                             # one segment of five spheres
        assert set(spheres["point_data"]["clump_id"]) == {0}
        # the incline's plate: the infinite plane z = 0, drawn as one quad under the segment
        quad = _wall_quads(walls)
        assert quad.shape == (1, 4, 3) and np.all(quad[..., 2] == 0.0)
        assert walls["cell_data"]["wall_id"].tolist() == [0]
        assert walls["cell_data"]["kind"].tolist() == [PLANE]
        lo, hi = quad[0].min(axis=0), quad[0].max(axis=0)
        assert np.all(spheres["points"][:, :2] > lo[:2]) and np.all(spheres["points"][:, :2] < hi[:2])
    # the segment slid: the last frame moves faster than the first
    first, last = _vtk_read(series[0][1]), _vtk_read(series[-1][1])
    assert last["point_data"]["speed"].max() > first["point_data"]["speed"].max()


def _carton(dt=1e-5):
    """A small open carton on a floor, six spheres in it and an end plate to lift."""
    sim = simulation(DEMParameters(), dt=dt, gravity=(0.0, 0.0, -9.81), lo=(-0.05, -0.04, -0.01),
                     hi=(0.06, 0.04, 0.1))
    floor(sim)
    sim.add_walls(box_rectangles((-0.03, -0.02, 0.0), (0.03, 0.02, 0.05), faces=("x-", "y-", "y+"),
                                 name="carton"))
    plate = sim.add_wall(Rectangle((0.03, 0.0, 0.025), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0), 0.02, 0.025,
                                   name="end plate"))
    tpl = sphere_template(sim)
    for i in range(6):
        sim.add_clump(tpl, (-0.02 + 0.012 * (i % 4), -0.006 + 0.012 * (i // 4), 0.006 + 0.002 * i))
    return sim, plate


def test_moving_plate_frames_follow_the_simulation(tmp_path):
    """The rigs' callback writes the plate where the simulation has it at each frame's time."""
    from demcal.simulate.cli import _Monitor

    sim, plate = _carton()
    lift = 0.5                                                  # [m/s]
    sim.set_wall_motion(plate, (0.0, 0.0, lift), move_start=1e-3)
    z0 = sim.wall_origins()[plate, 2]
    monitor = _Monitor(tmp_path)
    origins = {}
    chunk, t_end = 50, 8 * 50 * sim.dt
    for _ in range(8):
        sim.run(n_steps=chunk)
        origins[sim.time] = sim.wall_origins()
        monitor(sim, t_end, False)
    monitor(sim, t_end, True)

    series = _check_collections(tmp_path)
    assert len(series) == 8
    lo, hi = sim.domain_lo, sim.domain_hi
    for t, sphere_file, wall_file in series:
        spheres, walls = _vtk_read(sphere_file), _vtk_read(wall_file)
        _check_spheres(spheres, sim.n_spheres)
        np.testing.assert_array_equal(spheres["point_data"]["clump_id"], sim.sphere_body())
        quads = _wall_quads(walls)
        assert len(quads) == len(sim.walls) == walls["n_polys"] == 5
        assert walls["cell_data"]["wall_id"].tolist() == list(range(5))
        assert walls["cell_data"]["kind"].tolist() == [PLANE] + [RECTANGLE] * 4
        # every quad is centred on the wall's position at this frame's time
        np.testing.assert_allclose(quads.mean(axis=1)[1:], origins[t][1:], atol=1e-15)
        # the floor: the domain's footprint at z = 0
        np.testing.assert_allclose(np.sort(quads[0], axis=0),
                                   [[lo[0], lo[1], 0.0], [lo[0], lo[1], 0.0],
                                    [hi[0], hi[1], 0.0], [hi[0], hi[1], 0.0]], atol=1e-15)
    # late frame: the plate has been lifted, its quad 40 mm wide and 50 mm high around it
    plate_quad = _wall_quads(_vtk_read(series[-1][2]))[plate]
    z_now = sim.wall_origins()[plate, 2]
    assert z_now == pytest.approx(z0 + lift * (sim.time - 1e-3), rel=1e-9) and z_now > z0 + 1e-3
    np.testing.assert_allclose(plate_quad.mean(axis=0), sim.wall_origins()[plate], atol=1e-15)
    np.testing.assert_allclose(plate_quad.min(axis=0), [0.03, -0.02, z_now - 0.025], atol=1e-15)
    np.testing.assert_allclose(plate_quad.max(axis=0), [0.03, 0.02, z_now + 0.025], atol=1e-15)
    # our reader agrees with VTK's
    ours = read_vtp(series[-1][2])
    np.testing.assert_array_equal(ours["points"][np.concatenate(ours["polys"])].reshape(-1, 4, 3),
                                  _wall_quads(_vtk_read(series[-1][2])))


def test_a_frame_at_the_same_time_replaces_the_previous(tmp_path):
    sim, _ = _carton()
    frames = FrameSeries(tmp_path / "f")
    frames.write(sim)
    sim.run(n_steps=2)
    assert frames.write(sim) == 1 and frames.write(sim, last=True) == 1
    assert [t for t, _ in read_pvd(tmp_path / "f" / "walls.pvd")] == [0.0, sim.time]
    earlier = simulation(DEMParameters(), dt=1e-5)
    with pytest.raises(InputError, match="before the previous one"):
        frames.write(earlier)


def test_cli_vtk_needs_a_folder(tmp_path, capsys):
    target = tmp_path / "frames.vtp"
    target.write_text("not a folder")
    assert main(["simulate", "drop", "--vtk", str(target)]) == 2
    err = capsys.readouterr().err
    assert f"--vtk: '{target}' is a file; frames need a folder" in err
    assert "Traceback" not in err and err.count("\n") == 1
    with pytest.raises(InputError, match="cannot make the frames folder"):
        FrameSeries(target / "inside")


def test_cylinder_wall_is_drawn_as_a_ring_of_quads_on_its_surface(tmp_path):
    from demcal.simulate.vtk import CYLINDER_FACETS, write_walls_vtp
    from demcal.simulate.walls import CYLINDER, Cylinder

    sim = simulation(DEMParameters(), dt=1e-5)
    floor(sim)
    sim.add_wall(Cylinder((0.01, 0.02, 0.05), (0.0, 0.0, 1.0), 0.03, 0.05, "steel", name="cylinder"))
    walls = _vtk_read(write_walls_vtp(tmp_path / "walls.vtp", sim))
    quads = _wall_quads(walls)
    assert quads.shape == (1 + CYLINDER_FACETS, 4, 3)
    assert walls["cell_data"]["wall_id"].tolist() == [0] + [1] * CYLINDER_FACETS
    assert walls["cell_data"]["kind"].tolist() == [PLANE] + [CYLINDER] * CYLINDER_FACETS
    ring = quads[1:].reshape(-1, 3)
    np.testing.assert_allclose(np.hypot(ring[:, 0] - 0.01, ring[:, 1] - 0.02), 0.03, rtol=1e-12)
    assert set(np.round(ring[:, 2], 12)) == {0.0, 0.1}
