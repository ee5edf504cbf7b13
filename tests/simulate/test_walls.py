"""Walls: finite rectangles push from their edges, pass-by misses them, moving walls impart
their velocity, and nothing tunnels through a wall at the paper's time step."""

from __future__ import annotations

import math

import numpy as np
import pytest

from demcal.simulate import Cylinder, DEMParameters, Plane, Rectangle
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


# ---- cylinders (the lifting cylinder of a repose test)

def _tube(radius=0.03, half_height=0.05, **kwargs):
    # axis z through (0, 0, 0.05): the tube spans z from 0 to 0.1
    return Cylinder((0.0, 0.0, 0.05), (0.0, 0.0, 1.0), radius, half_height, "steel", **kwargs)


def test_cylinder_distance_by_hand_in_kernel_and_numpy():
    from demcal.simulate.walls import pack_walls, wall_distance, wall_distances

    packed = pack_walls([_tube()], lambda name: 0)
    # (point, distance to the tube, unit normal from the tube to the point), by hand
    cases = [((0.01, 0.0, 0.05), 0.02, (-1.0, 0.0, 0.0)),       # inside, toward the axis
             ((0.0, 0.05, 0.02), 0.02, (0.0, 1.0, 0.0)),        # outside
             ((0.03, 0.0, 0.13), 0.03, (0.0, 0.0, 1.0)),        # above the rim
             ((0.06, 0.0, 0.14), 0.05, (0.6, 0.0, 0.8)),        # beyond the rim, 3-4-5
             ((0.0, 0.0, 0.07), 0.03, None)]                    # on the axis: any radial way
    for point, dist, normal in cases:
        got = wall_distance(packed["kind"], packed["origin"], packed["normal"], packed["axis_u"],
                            packed["axis_v"], packed["half"], 0, *point)
        assert got[0] == pytest.approx(dist, abs=1e-15)
        assert wall_distances(packed, [point])[0, 0] == pytest.approx(dist, abs=1e-15)
        if normal is not None:
            np.testing.assert_allclose(got[1:], normal, atol=1e-12)
        else:
            assert got[3] == pytest.approx(0.0, abs=1e-12) and math.hypot(got[1], got[2]) == pytest.approx(1.0)


def _inner_wall_scattering(start, v0, radius, e_star, mass, t_end):
    """Independent reference: a sphere inside a tube of ``radius`` under the central Hertz force
    4/3 E* sqrt(R) d^1.5 toward the axis, d = rho - (radius - R) (frictionless, elastic),
    integrated by scipy in the plane across the axis."""
    from scipy.integrate import solve_ivp

    def rhs(t, y):
        x, yy, vx, vy = y
        rho = math.hypot(x, yy)
        d = max(rho - (radius - R), 0.0)
        f = 4.0 / 3.0 * e_star * math.sqrt(R) * d ** 1.5 / mass
        return [vx, vy, -f * x / rho, -f * yy / rho]

    out = solve_ivp(rhs, (0.0, t_end), [*start, *v0], rtol=1e-10, atol=1e-13, max_step=2e-6)
    return out.y[2, -1], out.y[3, -1]


def test_elastic_bounce_inside_a_cylinder_matches_central_force_scattering():
    # frictionless, elastic: a sphere moving out along a radius comes back along it; one moving
    # along a chord is reflected about the radius it meets (to the turn of the normal during
    # the contact, which the reference integrates)
    sim = simulation(_frictionless(), dt=1e-6)
    tpl = sphere_template(sim)
    sim.add_wall(_tube())
    sim.add_clump(tpl, (0.0, 0.0, 0.05), velocity=(1.0, 0.0, 0.0))
    # along the chord y = 0.6 (0.03 - R): it meets the wall where sin(phi) = 0.6
    start = (-0.015, 0.6 * (0.03 - R))
    sim.add_clump(tpl, (*start, 0.02), velocity=(1.0, 0.0, 0.0))
    sim.run(duration=0.05)                        # one bounce each (the next come after 73 ms)
    np.testing.assert_allclose(sim.velocities()[0], [-1.0, 0.0, 0.0], atol=1e-6)
    e_star = 1.0 / ((1 - 0.25 ** 2) / 2.5e7 + (1 - 0.3 ** 2) / (2 * 8e10 * 1.3))
    vx, vy = _inner_wall_scattering(start, (1.0, 0.0), 0.03, e_star, sim.masses()[1], 0.05)
    v = sim.velocities()[1]
    np.testing.assert_allclose(v, [vx, vy, 0.0], rtol=0, atol=1e-4)
    assert np.linalg.norm(v) == pytest.approx(1.0, rel=1e-6)
    # a hard wall would give the mirror image (-0.28, -0.96): the soft one turns it a little more
    assert abs(v[0] + 0.28) < 0.02 and abs(v[1] + 0.96) < 0.01


def test_elastic_bounce_off_a_cylinder_rim_matches_central_force_scattering():
    # the rim seen in the radial plane of the sphere's path is the rectangle's edge: same reference
    sim = simulation(_frictionless(), dt=1e-6)
    tpl = sphere_template(sim)
    radius = 0.03
    sim.add_wall(Cylinder((0.0, 0.0, 0.05), (0.0, 0.0, 1.0), radius, 0.05, "steel"))
    sim.add_clump(tpl, (radius + 0.004 + R * math.cos(math.pi / 6), 0.0, 0.1 + R / 2), velocity=(-1.0, 0.0, 0.0))
    sim.run(duration=0.006)
    e_star = 1.0 / ((1 - 0.25 ** 2) / 2.5e7 + (1 - 0.3 ** 2) / (2 * 8e10 * 1.3))
    vx, vz = _edge_scattering(1.0, R / 2, e_star, sim.masses()[0])
    np.testing.assert_allclose(sim.velocities()[0], [vx, 0.0, vz], rtol=0, atol=1e-4)


def test_lifted_cylinder_releases_its_fill_and_nothing_tunnels_while_it_holds():
    # spheres that do not hold each other by friction: once the tube is gone they spread
    params = DEMParameters(e_pp=0.5, e_pw=0.5, mu_s_pp=0.0, mu_r_pp=0.0, mu_s_pw=0.3)
    sim = simulation(params, dt=2e-5, gravity=(0.0, 0.0, -9.81), lo=(-0.3, -0.3, -0.05), hi=(0.3, 0.3, 0.4))
    tpl = sphere_template(sim)
    sim.add_wall(Plane((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), material="steel", name="floor"))
    tube = sim.add_wall(_tube(radius=0.012, half_height=0.1, name="cylinder"))
    rng = np.random.default_rng(3)
    for k in range(12):
        # stacked in the tube, thrown at the wall
        direction = np.append(rng.normal(size=2), 0.0)
        sim.add_clump(tpl, (0.0, 0.0, 0.01 + 0.012 * k), velocity=2.0 * direction / np.linalg.norm(direction))
    sim.run(duration=0.4)
    rho = np.hypot(*sim.positions()[:, :2].T)
    assert np.all(rho < 0.012 - 0.9 * R)
    sim.set_wall_motion(tube, (0.0, 0.0, 0.5), sim.time, sim.time + 0.6)
    sim.run(duration=1.0)
    rho = np.hypot(*sim.positions()[:, :2].T)
    assert sim.wall_origins()[tube, 2] == pytest.approx(0.05 + 0.3, rel=1e-6)
    assert rho.max() > 0.03                       # the column fell and spread once the tube rose
    assert sim.positions()[:, 2].max() < 0.05     # and none was carried up


# ---- cones (the fixed funnel of a repose test)

def _funnel(r_outlet=0.004, r_top=0.03, half_height=0.025, **kwargs):
    # axis z through (0, 0, 0.1): the outlet at z = 0.075, the top at z = 0.125
    return Cylinder((0.0, 0.0, 0.1), (0.0, 0.0, 1.0), r_outlet, half_height, "steel", top_radius=r_top, **kwargs)


def test_cone_distance_against_a_dense_sampling_of_its_surface_in_kernel_and_numpy():
    """The closest point of a truncated cone, against the nearest of 2 million points sampled on
    its surface (an independent brute force), for points inside, outside, above the top rim,
    below the outlet and on the axis."""
    from demcal.simulate.walls import pack_walls, wall_distance, wall_distances

    wall = _funnel()
    packed = pack_walls([wall], lambda name: 0)
    s = np.linspace(0.0, 1.0, 2001)                # along the generator
    phi = np.linspace(0.0, 2.0 * np.pi, 1000, endpoint=False)
    r = wall.radius + s * (wall.top_radius - wall.radius)
    z = 0.1 - wall.half_height + s * 2.0 * wall.half_height
    surface = np.stack([np.outer(r, np.cos(phi)), np.outer(r, np.sin(phi)), np.repeat(z[:, None], phi.size, 1)],
                       axis=-1).reshape(-1, 3)
    points = [(0.01, 0.0, 0.1), (0.0, 0.03, 0.09), (0.02, 0.01, 0.14), (0.0, 0.0, 0.06), (0.0, 0.0, 0.1),
              (0.005, 0.0, 0.074), (0.04, 0.0, 0.13)]
    for point in points:
        brute = float(np.min(np.linalg.norm(surface - np.asarray(point), axis=1)))
        got = wall_distance(packed["kind"], packed["origin"], packed["normal"], packed["axis_u"],
                            packed["axis_v"], packed["half"], 0, *point)
        # the sampling resolves the surface to about 0.1 mm around the rim
        assert got[0] == pytest.approx(brute, abs=1e-4) and got[0] <= brute + 1e-12
        assert wall_distances(packed, [point])[0, 0] == pytest.approx(got[0], abs=1e-15)
        assert math.sqrt(got[1] ** 2 + got[2] ** 2 + got[3] ** 2) == pytest.approx(1.0)


def test_equal_radii_make_the_same_tube_as_a_cylinder_bit_for_bit():
    from demcal.simulate.walls import pack_walls, wall_distance

    tube, cone = pack_walls([_tube()], lambda name: 0), pack_walls([_tube(top_radius=0.03)], lambda name: 0)
    rng = np.random.default_rng(1)
    for point in rng.uniform((-0.05, -0.05, -0.05), (0.05, 0.05, 0.15), size=(200, 3)):
        a = wall_distance(*(tube[k] for k in ("kind", "origin", "normal", "axis_u", "axis_v", "half")), 0, *point)
        b = wall_distance(*(cone[k] for k in ("kind", "origin", "normal", "axis_u", "axis_v", "half")), 0, *point)
        assert a == b


def test_a_sphere_too_big_for_the_outlet_rests_in_the_funnel_at_the_cones_height():
    """A sphere on the axis of a funnel of half-angle alpha touches the wall where the radius is
    R / cos(alpha): the rigid sphere would rest with its centre at z0 + (R / cos(alpha) - r0) /
    tan(alpha) above the outlet (z0, r0). The wall is one contact at its closest point, so the
    sphere sinks further by the Hertz overlap of a force m g / sin(alpha) along the normal,
    delta / sin(alpha): 6.5e-6 m here."""
    params = DEMParameters(e_pp=0.3, e_pw=0.3, mu_s_pw=0.4)
    sim = simulation(params, dt=2e-5, gravity=(0.0, 0.0, -9.81))
    tpl = sphere_template(sim)
    wall = _funnel()
    sim.add_wall(wall)
    sim.add_clump(tpl, (0.0, 0.0, 0.15))
    sim.run(duration=1.0)
    tan_a = (wall.top_radius - wall.radius) / (2.0 * wall.half_height)
    cos_a = 1.0 / math.sqrt(1.0 + tan_a ** 2)
    sin_a = tan_a * cos_a
    e_star = 1.0 / ((1 - 0.25 ** 2) / 2.5e7 + (1 - 0.3 ** 2) / (2 * 8e10 * 1.3))
    normal_force = sim.masses()[0] * 9.81 / sin_a
    overlap = (normal_force / (4.0 / 3.0 * e_star * math.sqrt(R))) ** (2.0 / 3.0)
    z_rest = 0.1 - wall.half_height + (R / cos_a - wall.radius) / tan_a - overlap / sin_a
    x = sim.positions()[0]
    assert x[2] == pytest.approx(z_rest, abs=2e-7)
    # on the axis every point of the ring is closest: the contact takes one side, pushes the
    # sphere a step's distance across, then the other, so it chatters sideways in place
    assert math.hypot(x[0], x[1]) < 1e-7 and abs(sim.velocities()[0][2]) < 1e-5


# ---- spinning walls (the rotating drum)

@pytest.mark.parametrize("how", ["spinning", "translating"])
def test_a_sphere_set_down_on_a_moving_plate_rolls_off_at_two_sevenths_of_its_speed(how):
    """A solid sphere set down at rest on a surface moving at V slides until it rolls, then
    moves at 2 V / 7 (angular momentum about the contact point is conserved; no rolling
    friction). A plate spinning at omega about its normal drags it as a belt at V = omega r
    under it, and a plate translating at V the same: the spin enters the contact velocity."""
    params = DEMParameters(e_pw=0.5, mu_s_pw=0.5, mu_r_pw=0.0)
    sim = simulation(params, dt=2e-6, gravity=(0.0, 0.0, -9.81))
    tpl = sphere_template(sim)
    omega, r = 1.0, 0.1
    if how == "spinning":
        plate = Rectangle((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), 0.15, 0.15, "steel",
                          spin=(0.0, 0.0, omega))
    else:
        plate = Rectangle((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), 0.15, 0.15, "steel",
                          velocity=(0.0, omega * r, 0.0))
    sim.add_wall(plate)
    sim.add_clump(tpl, (r, 0.0, R - 2e-6))     # resting on the plate, nearly at its weight's overlap
    sim.run(duration=0.03)                       # it rolls after 2 V / (7 mu g) = 5.8 ms
    v = sim.velocities()[0]
    assert v[1] == pytest.approx(2.0 / 7.0 * omega * r, rel=0.02)
    # rolling without slip: the contact point moves with the plate
    w = sim.angular_velocities()[0]
    assert v[1] + w[0] * R == pytest.approx(omega * r, rel=0.02)


def test_a_spinning_wall_keeps_its_place_and_records_its_spin():
    from demcal.simulate.walls import pack_walls

    tube = _tube(spin=(0.0, 0.0, 2.0))
    assert tube.to_dict()["spin"] == [0.0, 0.0, 2.0] and "spin" not in _tube().to_dict()
    sim = simulation(DEMParameters())
    k = sim.add_wall(tube)
    sim.run(duration=0.01)
    np.testing.assert_array_equal(sim.wall_origins()[k], (0.0, 0.0, 0.05))
    assert pack_walls([tube], lambda name: 0)["spin"][0].tolist() == [0.0, 0.0, 2.0]
    with pytest.raises(Exception, match="spin must be a finite"):
        pack_walls([_tube(spin=(0.0, math.nan, 0.0))], lambda name: 0)


def test_walls_near_a_point_are_all_the_walls_a_body_around_it_can_touch():
    # every kind of wall; bodies of random reach at random points: a wall left out is at least
    # (reach - distance from the point) from every point of the body, by wall_distances itself
    from demcal.simulate.walls import pack_walls, wall_distances, walls_near
    walls = [Plane((0.0, 0.0, 0.0), (0.0, 0.0, 1.0)), Plane((0.1, 0.0, 0.0), (-1.0, 0.0, 0.0)),
             Rectangle((0.0, 0.05, 0.05), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0), 0.04, 0.03),
             Cylinder((0.05, 0.0, 0.1), (0.0, 0.0, 1.0), 0.03, 0.05),
             Cylinder((-0.05, 0.0, 0.1), (0.0, 1.0, 0.0), 0.02, 0.04, top_radius=0.04)]
    packed = pack_walls(walls, lambda name: 0)
    args = [packed[k] for k in ("kind", "origin", "normal", "axis_u", "axis_v", "half")]
    rng = np.random.default_rng(4)
    left_out = 0
    for _ in range(400):
        centre, reach = rng.uniform(-0.1, 0.2, 3), rng.uniform(0.002, 0.04)
        near = walls_near(*args, *centre, reach)
        far = np.setdiff1d(np.arange(len(walls)), near)
        left_out += far.size
        d = rng.normal(size=(30, 3))
        body = centre + d / np.linalg.norm(d, axis=1)[:, None] * reach * rng.random((30, 1)) ** (1 / 3)
        dist = wall_distances({k: v[far] for k, v in packed.items()}, body)
        assert np.all(dist >= reach - np.linalg.norm(body - centre, axis=1)[:, None] - 1e-12)
        # and the walls kept are the ones within reach (plus the margin)
        at_centre = wall_distances(packed, centre)[0]
        np.testing.assert_array_equal(near, np.flatnonzero(at_centre < reach * (1 + 1e-6) + 1e-9))
    assert 0 < left_out < 400 * len(walls)
