"""The engine's guards and bookkeeping: runaway energy, escapes, input errors, state readers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from demcal.errors import InputError, SimulationError
from demcal.simulate import DEMParameters, MaterialTable, Plane, Simulation, rayleigh_time
from demcal.simulate.integrate import axis_angle_quat, matrix_from_quat, quat_from_matrix, quat_multiply
from tests.simulate.helpers import R, floor, simulation, sphere_template


def test_unstable_time_step_stops_with_simulation_error():
    # forced to 4 Rayleigh times, a sphere pressed into the plate explodes; the run must stop
    t_r = rayleigh_time(R, 912.0, 1e7, 0.25)
    sim = simulation(DEMParameters(e_pw=0.9), dt=4 * t_r, force=True, gravity=(0, 0, -9.81))
    tpl = sphere_template(sim)
    floor(sim)
    sim.add_clump(tpl, (0.0, 0.0, 0.5 * R), velocity=(0.0, 0.0, -2.0))
    with pytest.raises(SimulationError, match="runaway kinetic energy|non-finite"):
        sim.run(duration=0.5)


def test_body_leaving_the_domain_is_recorded_and_deactivated():
    sim = simulation(DEMParameters(), dt=5e-5, lo=(-0.1, -0.1, -0.1), hi=(0.1, 0.1, 0.1))
    tpl = sphere_template(sim)
    sim.add_clump(tpl, (0.0, 0.0, 0.0), velocity=(2.0, 0.0, 0.0))
    sim.add_clump(tpl, (0.0, 0.05, 0.0))
    summary = sim.run(duration=0.1)
    assert summary.escaped == 1 and len(sim.escaped) == 1
    esc = sim.escaped[0]
    assert esc.body == 0 and esc.position[0] > 0.1 and 0.05 <= esc.time <= 0.1
    assert list(sim.active()) == [False, True]
    assert sim.kinetic_energy() == 0.0
    assert summary.n_bodies == 1 and summary.n_spheres == 1


def test_state_readers_agree_with_what_was_added():
    sim = simulation(DEMParameters(), dt=1e-5)
    tpl = sim.add_template(DEMParameters().template())
    q = axis_angle_quat((0.0, 0.0, 1.0), math.pi / 2)
    sim.add_clump(tpl, (0.01, 0.02, 0.03), q, velocity=(0.1, 0.0, 0.0), angular_velocity=(0.0, 0.0, 2.0))
    np.testing.assert_allclose(sim.orientations()[0], q, atol=1e-15)
    # the segment axis (template x) now points along world y
    np.testing.assert_allclose(sim.rotation_matrices()[0][:, 0], [0.0, 1.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(sim.sphere_positions()[:, 1] - 0.02, [-0.007, -0.0035, 0.0, 0.0035, 0.007],
                               atol=1e-15)
    tpl_obj = sim.templates[tpl]
    e = 0.5 * tpl_obj.mass * 0.01 + 0.5 * tpl_obj.principal_moments[2] * 4.0
    assert sim.kinetic_energy() == pytest.approx(e, rel=1e-12)


def test_clumps_added_at_once_are_those_the_per_clump_arithmetic_gives():
    """``add_clumps`` (a factory's batch) gives, to the bit, the bodies and spheres of the
    arithmetic of one clump: the orientation over its norm times the template's principal frame,
    that quaternion's rotation matrix R, the spheres at x + offsets R^T and L = R I R^T w; and
    the same as ``add_clump`` clump by clump. Two templates of 5 and 1 spheres, mixed."""
    rng = np.random.default_rng(11)
    n = 40
    pos = rng.uniform(-0.1, 0.1, (n, 3))
    q = rng.normal(size=(n, 4)) * rng.uniform(0.1, 10.0, (n, 1))     # not normalised
    v, w = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    sims = []
    for _ in range(2):
        sim = simulation(DEMParameters(), dt=1e-5)
        templates = [sim.add_template(DEMParameters().template()), sphere_template(sim)]
        sims.append(sim)
    ids = rng.choice(templates, n)
    assert sims[0].add_clumps(ids, pos, q, velocities=v, angular_velocities=w).tolist() == list(range(n))
    for k in range(n):
        assert sims[1].add_clump(int(ids[k]), pos[k], q[k], velocity=v[k], angular_velocity=w[k]) == k
    spheres, momenta, owner = [], [], []
    for k in range(n):
        tpl = sims[0].templates[ids[k]]
        q_body = quat_multiply(q[k] / np.linalg.norm(q[k]), quat_from_matrix(tpl.principal_axes))
        R = matrix_from_quat(q_body)
        spheres.append(pos[k] + tpl.offsets @ R.T)
        momenta.append(R @ np.diag(tpl.principal_moments) @ R.T @ w[k])
        owner += [k] * tpl.n_spheres
    for sim in sims:
        np.testing.assert_array_equal(sim.sphere_positions(), np.vstack(spheres))
        np.testing.assert_array_equal(sim.angular_momenta(), np.array(momenta))
        np.testing.assert_array_equal(sim.sphere_body(), owner)
        np.testing.assert_array_equal(sim.positions(), pos)
        np.testing.assert_array_equal(sim.velocities(), v)
        np.testing.assert_array_equal(sim.angular_velocities(), w)
    # a bad row stops the whole batch before anything is added
    sim = sims[0]
    with pytest.raises(InputError, match=r"non-zero quaternion .* got \[0.0, 0.0, 0.0, 0.0\]"):
        sim.add_clumps([0, 0], pos[:2], [[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0]])
    with pytest.raises(InputError, match="position must be 3 numbers per clump"):
        sim.add_clumps([0], [[0.0, 0.0]], [[1.0, 0.0, 0.0, 0.0]])
    with pytest.raises(InputError, match="velocity must be finite"):
        sim.add_clumps([0], [[0.0, 0.0, 0.0]], [[1.0, 0.0, 0.0, 0.0]], velocities=[np.nan, 0.0, 0.0])
    with pytest.raises(InputError, match="unknown template id 7"):
        sim.add_clumps([0, 7], pos[:2], q[:2])
    assert sim.n_bodies == n and sim.add_clumps([], np.zeros((0, 3)), np.zeros((0, 4))).size == 0


def test_input_errors_name_the_problem():
    table = MaterialTable()
    table.add_material("particle", density=912.0, poisson_ratio=0.25, shear_modulus=1e7)
    table.add_material("rubber", density=1100.0, poisson_ratio=0.45, shear_modulus=1e6)
    sim = Simulation(table, domain_lo=(0, 0, 0), domain_hi=(1, 1, 1), dt=1e-5)
    with pytest.raises(InputError, match="unknown material 'steel'; defined: particle, rubber"):
        sim.add_wall(Plane((0, 0, 0), (0, 0, 1), material="steel"))
    with pytest.raises(InputError, match="unknown template id"):
        sim.add_clump(3, (0.5, 0.5, 0.5))
    tpl = sphere_template(sim)
    with pytest.raises(InputError, match="no contact parameters for material pair particle-particle"):
        sim.add_clump(tpl, (0.5, 0.5, 0.5))
    with pytest.raises(InputError, match="domain_hi"):
        Simulation(table, domain_lo=(0, 0, 0), domain_hi=(1, 0, 1), dt=1e-5)
    with pytest.raises(InputError, match="dt"):
        Simulation(table, domain_lo=(0, 0, 0), domain_hi=(1, 1, 1), dt=-1.0)
    with pytest.raises(InputError, match="rolling_lever"):
        Simulation(table, domain_lo=(0, 0, 0), domain_hi=(1, 1, 1), dt=1e-5, rolling_lever="com")
    with pytest.raises(InputError, match="exactly one"):
        sim.run(duration=1.0, n_steps=3)
    with pytest.raises(InputError, match="gravity"):
        sim.gravity = (0, 0, float("nan"))
