"""Walls: finite rectangles push from their edges, pass-by misses them, moving walls impart
their velocity, and nothing tunnels through a wall at the paper's time step."""

from __future__ import annotations

import math

import numpy as np
import pytest

from demcal.simulate import DEMParameters, Rectangle
from demcal.simulate.walls import box_rectangles
from tests.simulate.helpers import R, simulation, sphere_template


def _frictionless(e=1.0):
    return DEMParameters(e_pw=e, mu_s_pw=0.0, mu_r_pw=0.0)


def _plate_x0():
    # a plate in the plane x = 0, y in [-0.05, 0.05], z in [0, 0.1]
    return Rectangle((0.0, 0.0, 0.05), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0), 0.05, 0.05, "steel")


def _edge_scattering(v0, z0, e_star, mass):
    """Independent reference: a sphere scattered by a fixed edge point under the central Hertz
    force 4/3 E* sqrt(R) d^1.5 (frictionless, elastic), integrated by scipy in the x-z plane."""
    from scipy.integrate import solve_ivp

    def rhs(t, y):
        x, z, vx, vz = y
        r = math.hypot(x, z)
        d = max(R - r, 0.0)
        f = 4.0 / 3.0 * e_star * math.sqrt(R) * d ** 1.5 / mass
        return [vx, vz, f * x / r, f * z / r]

    out = solve_ivp(rhs, (0.0, 0.006), [0.004 + R * math.cos(math.pi / 6), z0, -v0, 0.0],
                    rtol=1e-10, atol=1e-13, max_step=2e-6)
    return out.y[2, -1], out.y[3, -1]


def test_elastic_bounce_off_a_rectangle_edge_matches_central_force_scattering():
    # the sphere meets the top edge (z = 0.1) with its centre R/2 above it; an infinitely stiff
    # contact would reflect it about n = (cos 30, 0, sin 30), to (0.5, 0, 0.866) m/s; the soft
    # Hertz contact turns it a little further (the normal turns as the sphere rides the edge)
    sim = simulation(_frictionless(), dt=1e-6)
    tpl = sphere_template(sim)
    sim.add_wall(_plate_x0())
    sim.add_clump(tpl, (0.004 + R * math.cos(math.pi / 6), 0.0, 0.1 + R / 2), velocity=(-1.0, 0.0, 0.0))
    sim.run(duration=0.006)
    e_star = 1.0 / ((1 - 0.25 ** 2) / 2.5e7 + (1 - 0.3 ** 2) / (2 * 8e10 * 1.3))
    vx, vz = _edge_scattering(1.0, R / 2, e_star, sim.masses()[0])
    np.testing.assert_allclose(sim.velocities()[0], [vx, 0.0, vz], rtol=0, atol=1e-4)
    assert math.hypot(vx, vz) == pytest.approx(1.0, rel=1e-6)
    assert 0.4 < vx < 0.5 and vz > 0.866
    np.testing.assert_allclose(sim.angular_velocities()[0], 0.0, atol=1e-12)


def test_sphere_passing_beside_a_rectangle_is_not_touched():
    sim = simulation(_frictionless(), dt=1e-5)
    tpl = sphere_template(sim)
    sim.add_wall(_plate_x0())
    sim.add_clump(tpl, (0.02, 0.0, 0.1 + R + 1e-4), velocity=(-1.0, 0.0, 0.0))
    sim.run(duration=0.04)
    np.testing.assert_allclose(sim.velocities()[0], [-1.0, 0.0, 0.0], atol=1e-15)
    assert sim.positions()[0, 0] < -0.015


@pytest.mark.parametrize("e", [1.0, 0.5])
def test_moving_plate_hits_resting_sphere_with_restitution(e):
    # a plate moving at U into a free sphere: the sphere leaves at (1 + e) U (wall of infinite mass)
    u = 0.2
    sim = simulation(_frictionless(e), dt=1e-6)
    tpl = sphere_template(sim)
    sim.add_wall(Rectangle((0.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0), 0.05, 0.05, "steel",
                           velocity=(u, 0.0, 0.0), move_start=0.0, move_stop=0.01))
    sim.add_clump(tpl, (R + 2e-4, 0.0, 0.0))
    sim.run(duration=0.01)
    assert sim.velocities()[0, 0] == pytest.approx((1 + e) * u, rel=0.01)
    assert sim.wall_origins()[0, 0] == pytest.approx(u * 0.01, rel=1e-6)
    sim.run(duration=0.005)                    # the plate has stopped
    assert sim.wall_origins()[0, 0] == pytest.approx(u * 0.01, rel=1e-6)


def test_no_tunnelling_through_a_carton_wall_at_the_paper_time_step():
    params = DEMParameters(e_pp=0.32, e_pw=0.36, mu_s_pw=0.22)
    sim = simulation(params, dt=7.43678e-5, lo=(-0.1, -0.1, -0.1), hi=(0.3, 0.2, 0.3))
    tpl = sphere_template(sim)
    sim.add_walls(box_rectangles((0.0, 0.0, 0.0), (0.2, 0.1, 0.25)))  # closed: no gravity here
    rng = np.random.default_rng(5)
    for k in range(20):
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        sim.add_clump(tpl, (0.03 + 0.007 * k, 0.05, 0.05 + 0.008 * k), velocity=6.0 * direction)
    sim.run(duration=0.3)
    x = sim.positions()
    assert not sim.escaped
    assert np.all(x > np.array([0.0, 0.0, 0.0]) + 0.9 * R)
    assert np.all(x < np.array([0.2, 0.1, 0.25]) - 0.9 * R)
