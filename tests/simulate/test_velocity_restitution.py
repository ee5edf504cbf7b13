"""Velocity-dependent restitution inside the contact law (engine hook).

Reference: the power law e(v) = e_ref (v / v_ref)^(-n) (Johnson 1985, sec. 11.5) evaluated at
the analytic impact speed sqrt(2 g h) of a free fall from h. The restitution damping of the
EDEM theory guide gives a binary impact the velocity ratio e of its beta, so a sphere, and a
segment landing end on (one contact through its centre of mass), rebound to h e(v)^2. The
flight after the contact is ballistic, which the velocity Verlet integrator follows exactly, so
the rebound height is read from the state just after separation. Below Johnson's yield speed
v_y = v_ref e_ref^(1/n) the law gives e = 1: bounces on a plate converge to v_y.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from demcal.errors import InputError
from demcal.simulate import DEMParameters, MaterialTable
from demcal.simulate.clump import segment_template
from demcal.simulate.integrate import axis_angle_quat
from tests.simulate.helpers import R, floor, simulation, sphere_template

G = 9.81
E_REF, V_REF, N = 0.5, 1.0, 0.25
HEIGHTS = (0.05, 0.2, 0.5)              # impact speeds 0.99, 1.98, 3.13 m/s


def law(v):
    return E_REF * (v / V_REF) ** (-N)


def _drop(params, height, body="sphere", dt=2e-6):
    """Free fall from rest, lowest point ``height`` [m] above the plate; returns the apparent
    restitution sqrt(h_rebound / h_drop) of the centre of mass and the simulation."""
    sim = simulation(params, dt=dt, gravity=(0.0, 0.0, -G), hi=(0.2, 0.2, 1.0))
    if body == "sphere":
        tpl, q, z_touch = sphere_template(sim), (1.0, 0.0, 0.0, 0.0), R
    else:
        # the segment's axis (template x) vertical: only its end sphere meets the plate
        tpl = sim.add_template(segment_template(0.025, 0.011, 5, 912.0))
        q, z_touch = axis_angle_quat((0.0, 1.0, 0.0), math.pi / 2), 0.0125
    floor(sim)
    sim.add_clump(tpl, (0.0, 0.0, z_touch + height), q)
    sim.run(duration=math.sqrt(2.0 * height / G) - 1e-3)      # to 1 ms before the contact
    touched = False
    for _ in range(2000):
        sim.run(n_steps=20)
        z = sim.positions()[0, 2]
        if z < z_touch:
            touched = True
            impact = sim.contact_history()["walls"]["impact_speed"]
        elif touched:
            break
    vz = sim.velocities()[0, 2]
    apex = z + vz ** 2 / (2.0 * G)
    return math.sqrt((apex - z_touch) / height), impact, sim


@pytest.mark.parametrize("body", ["sphere", "segment end on"])
def test_rebound_follows_the_power_law_johnson1985(body):
    params = DEMParameters(e_pw=E_REF, e_pw_v_ref=V_REF, e_pw_exponent=N)
    for h in HEIGHTS:
        v = math.sqrt(2.0 * G * h)
        e, impact, sim = _drop(params, h, body)
        assert e == pytest.approx(law(v), rel=0.01), h
        # the contact kept its first-touch approach speed
        assert impact.shape == (1,) and impact[0] == pytest.approx(v, rel=0.005)
        if body != "sphere":
            assert np.abs(sim.angular_velocities()).max() < 1e-9   # no turn: a one-contact impact


def test_constant_restitution_when_the_exponent_is_zero():
    for h in (HEIGHTS[0], HEIGHTS[-1]):
        e, impact, _ = _drop(DEMParameters(e_pw=E_REF), h)
        assert e == pytest.approx(E_REF, rel=0.01)
        assert np.isnan(impact).all()                 # nothing recorded on the default path


def test_zero_exponent_is_bit_identical_to_the_default_path():
    # a law on the particle-particle pair widens every contact's history; the drop on steel
    # (exponent 0) must not change by a bit.
    default = _drop(DEMParameters(e_pw=E_REF), 0.2)[2]
    hooked = _drop(DEMParameters(e_pw=E_REF, e_pp_exponent=0.3, e_pw_exponent=0.0), 0.2)[2]
    for read in ("positions", "velocities", "angular_momenta", "orientations"):
        np.testing.assert_array_equal(getattr(hooked, read)(), getattr(default, read)())
    assert hooked.time == default.time


def test_particle_pair_law_in_a_binary_impact():
    # two spheres meet at 2 x 0.9 m/s: e(1.8 m/s) of the particle-particle law, no gravity
    params = DEMParameters(e_pp=0.6, e_pp_v_ref=0.5, e_pp_exponent=0.2)
    sim = simulation(params, dt=1e-6)
    tpl = sphere_template(sim)
    sim.add_clump(tpl, (0.0, 0.0, 0.0), velocity=(0.9, 0.0, 0.0))
    sim.add_clump(tpl, (2 * R + 1e-6, 0.0, 0.0), velocity=(-0.9, 0.0, 0.0))
    sim.run(duration=2.5e-3)
    v = sim.velocities()
    assert (v[1, 0] - v[0, 0]) / 1.8 == pytest.approx(0.6 * (1.8 / 0.5) ** -0.2, rel=0.01)


def _bouncing_sphere(params, vx=0.0):
    sim = simulation(params, dt=1e-5, gravity=(0.0, 0.0, -G), lo=(-0.1, -0.2, -0.05), hi=(1.0, 0.2, 0.5))
    tpl = sphere_template(sim)
    floor(sim)
    sim.add_clump(tpl, (0.0, 0.0, R + 0.01), velocity=(vx, 0.0, 0.0))   # lands at 0.44 m/s
    return sim


def test_elastic_below_the_yield_speed_johnson1985():
    # e(v) reaches 1 at v_y = v_ref e_ref^(1/n) = 0.0625 m/s: without a floor the bounces
    # converge to v_y (v_k+1 = e(v_k) v_k) and never stop; with v_min = 0.2 m/s every slower
    # impact keeps e(0.2) = 0.748 and the sphere comes to rest
    v_y = V_REF * E_REF ** (1.0 / N)
    sim = _bouncing_sphere(DEMParameters(e_pw=E_REF, e_pw_v_ref=V_REF, e_pw_exponent=N))
    sim.run(duration=1.0)
    speeds = []
    for _ in range(300):
        sim.run(n_steps=10)
        speeds.append(abs(sim.velocities()[0, 2]))
    assert max(speeds) == pytest.approx(v_y, rel=0.03)
    sim = _bouncing_sphere(DEMParameters(e_pw=E_REF, e_pw_v_ref=V_REF, e_pw_exponent=N, e_pw_v_min=0.2))
    sim.run(duration=1.0)
    assert abs(sim.velocities()[0, 2]) < 1e-4 and sim.n_contacts() == (0, 1)


def test_first_touch_speed_survives_list_rebuilds():
    # a frictionless sphere slides across the plate at 0.5 m/s while resting on it, the lists
    # rebuilt after every 10 steps: its contact keeps the speed it was first met with
    params = DEMParameters(e_pw=E_REF, e_pw_exponent=N, e_pw_v_min=0.2, mu_s_pw=0.0)
    sim = _bouncing_sphere(params, vx=0.5)
    sim.run(duration=0.8)
    first = sim.contact_history()["walls"]["impact_speed"]
    rebuilds = sim.total_wall_rebuilds
    sim.chunk_steps = 10

    def rebuild(s):
        s._need_rebuild = True

    sim.run(duration=0.2, progress=rebuild)
    assert sim.total_wall_rebuilds > rebuilds + 20
    assert sim.contact_history()["walls"]["impact_speed"] == first
    assert first.shape == (1,) and 0.0 < first[0] < 0.2


@pytest.mark.parametrize("changes,match", [
    ({"e_pw_v_ref": 0.0}, "e_pw_v_ref must be a speed > 0"),
    ({"e_pp_exponent": math.inf}, "e_pp_exponent must be a finite number"),
    ({"e_pp_exponent": "steep"}, "needs a number"),
    ({"e_pp_v_min": -0.1}, "e_pp_v_min must be a speed >= 0"),
])
def test_bad_law_parameters_are_named(changes, match):
    with pytest.raises(InputError, match=match):
        DEMParameters().with_(**changes)


def test_material_table_carries_the_law():
    table = MaterialTable.from_parameters(DEMParameters(e_pw=0.4, e_pw_v_ref=2.0, e_pw_exponent=0.1))
    pair = table.pair("particle", "steel")
    assert (pair.restitution, pair.restitution_v_ref, pair.restitution_exponent) == (0.4, 2.0, 0.1)
    assert table.pair("particle", "particle").restitution_exponent == 0.0
    with pytest.raises(InputError, match="restitution_v_ref must be > 0"):
        table.set_pair("particle", "steel", restitution=0.4, static_friction=0.2, rolling_friction=0.1,
                       restitution_v_ref=-1.0)
