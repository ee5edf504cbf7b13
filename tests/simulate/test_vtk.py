"""VTK export: a .vtp frame parses back to the simulation's spheres."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest

from demcal.errors import InputError
from demcal.simulate import DEMParameters
from demcal.simulate.clump import segment_from_parameters
from demcal.simulate.vtk import read_vtp, write_vtp
from tests.simulate.helpers import simulation


def test_vtp_round_trip(tmp_path):
    sim = simulation(DEMParameters(), dt=1e-5)
    tpl = sim.add_template(segment_from_parameters(DEMParameters()))
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
    assert back["time"] == sim.time and back["points"].shape == (10, 3)


def test_vtp_needs_the_extension(tmp_path):
    sim = simulation(DEMParameters(), dt=1e-5)
    with pytest.raises(InputError, match=".vtp"):
        write_vtp(tmp_path / "frame.vtk", sim)
