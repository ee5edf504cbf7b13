"""Elastic-plastic spring-dashpot rolling resistance in the engine (Ai et al. 2011, type C).

Analytic answers (Ai et al. 2011, sec. 2.3 and 4): the spring torque never exceeds
M_m = mu_r F_n R_r, so a sphere on a slope is held below theta = atan(mu_r) and above it rolls
against the full M_m, with the acceleration of model A, 5/7 g (sin - mu_r cos); a rolling sphere
on a plate decelerates at 5/7 g mu_r, stops at t = v0 / (5/7 g mu_r), rocks back on the spring
and comes to rest. The pair torque is equal and opposite, so angular momentum is conserved.
F_n is the Hertz force of the overlap, computed by hand here.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from demcal.errors import InputError
from demcal.simulate import DEMParameters, MaterialTable
from tests.simulate.helpers import R, floor, simulation, sphere_template
from tests.simulate.test_rolling import MU_R, slope_run

THRESHOLD_DEG = math.degrees(math.atan(MU_R))  # 8.53 deg
G = 9.81
E_P, E_S = 2 * 1e7 * 1.25, 2 * 8e10 * 1.3
E_STAR_PW = 1.0 / ((1 - 0.25 ** 2) / E_P + (1 - 0.3 ** 2) / E_S)


def _limit_on_floor(sim):
    """mu_r F_n R of a sphere resting on the floor, F_n the Hertz force of its overlap [N m]."""
    overlap = R - sim.positions()[0, 2]
    return MU_R * 4.0 / 3.0 * E_STAR_PW * math.sqrt(R) * max(overlap, 0.0) ** 1.5 * R


def _slope_run(deg):
    return slope_run(deg, rolling_model="epsd")


def test_spring_dashpot_ai2011_sphere_held_below_atan_mu_r():
    for deg in (THRESHOLD_DEG - 1.0, THRESHOLD_DEG - 0.2):
        theta = math.radians(deg)
        sim, dx, v0, v1, _ = _slope_run(deg)
        assert abs(dx) < 1e-9 and abs(v1) < 1e-9
        # the spring holds the gravity torque m g sin R of the rolling sphere, below its limit
        spring = sim.contact_history()["walls"]["rolling_torque"][0]
        mass = sim.masses()[0]
        assert -spring[1] == pytest.approx(mass * G * math.sin(theta) * R, rel=0.01)
        assert np.linalg.norm(spring) < _limit_on_floor(sim)


def test_spring_dashpot_ai2011_sphere_rolls_above_atan_mu_r_as_model_a():
    for deg in (THRESHOLD_DEG + 0.5, THRESHOLD_DEG + 3.0):
        theta = math.radians(deg)
        sim, dx, v0, v1, accel = _slope_run(deg)
        expected = 5.0 / 7.0 * G * (math.sin(theta) - MU_R * math.cos(theta))
        assert dx > 0 and v1 > v0
        assert accel == pytest.approx(expected, rel=0.01)
        # fully mobilised: the spring sits at its limit mu_r F_n R
        spring = sim.contact_history()["walls"]["rolling_torque"][0]
        assert np.linalg.norm(spring) == pytest.approx(_limit_on_floor(sim), rel=1e-9)


def test_spring_dashpot_rolling_sphere_stops_rocks_and_rests():
    w0 = 20.0                                  # rad/s, rolling at v0 = w0 R = 0.11 m/s
    sim = simulation(DEMParameters(mu_r_pw=MU_R, mu_s_pw=0.5, rolling_model="epsd"), dt=2e-5,
                     gravity=(0.0, 0.0, -G), lo=(-0.5, -0.1, -0.05), hi=(1.0, 0.1, 0.1))
    tpl = sphere_template(sim)
    floor(sim)
    sim.add_clump(tpl, (0.0, 0.0, R), velocity=(w0 * R, 0.0, 0.0), angular_velocity=(0.0, w0, 0.0))
    rows = []
    for _ in range(3000):                      # 0.6 s in steps of 10 dt
        sim.run(n_steps=10)
        spring = sim.contact_history()["walls"]["rolling_torque"]
        limit, vector = sim.rolling_resistance()
        rows.append((sim.time, sim.positions()[0, 0], sim.angular_velocities()[0, 1],
                     np.linalg.norm(spring[0]), _limit_on_floor(sim), limit[0]))
    t, x, w, spring, limit, reported = np.array(rows).T
    # the static torque never exceeds mu_r F_n R (the engine's own limit is the hand value)
    assert np.all(spring <= limit * (1 + 1e-12))
    np.testing.assert_allclose(reported, limit, rtol=1e-9)
    # rolls against the full limit (model A) until it stops ...
    stop = int(np.argmax(w <= 0.0))
    assert t[stop] == pytest.approx(w0 * R / (5.0 / 7.0 * G * MU_R), abs=0.002)
    # ... rocks back on the spring (the spin changes sign), and comes to rest without creeping
    after = w[stop:]
    assert after.min() < -1e-3
    assert np.count_nonzero(np.diff(np.sign(after[np.abs(after) > 1e-6])) != 0) >= 3
    assert abs(w[-1]) < 1e-9
    rest = t > t[-1] - 0.2
    assert np.ptp(x[rest]) < 1e-9


def test_spring_dashpot_pair_torque_is_equal_and_opposite_and_conserves_momentum():
    # two spheres pressed together (no gravity), spinning differently about axes in the
    # contact plane and along the normal: the rolling pair torque is equal and opposite and the
    # total angular momentum (orbit and spin) is conserved to round-off
    params = DEMParameters(mu_r_pp=0.4, mu_s_pp=0.5, rolling_model="epsd")
    sim = simulation(params, dt=1e-6)
    tpl = sphere_template(sim)
    overlap = 5e-5
    sim.add_clump(tpl, (0.0, 0.0, 0.0), angular_velocity=(0.5, -2.0, 3.0))
    sim.add_clump(tpl, (2 * R - overlap, 0.0, 0.0), angular_velocity=(0.0, 1.0, -1.0))

    def momentum():
        m = sim.masses()[:, None]
        return (np.cross(sim.positions(), m * sim.velocities()) + sim.angular_momenta()).sum(axis=0)

    l0 = momentum()
    spin0 = sim.angular_momenta()
    sim.run(n_steps=50)                        # still touching (they part after ~0.2 ms)
    assert sim.n_contacts() == (1, 0)
    _, vector = sim.rolling_resistance()
    assert np.linalg.norm(vector[0]) > 0
    np.testing.assert_allclose(vector[1], -vector[0], rtol=1e-12, atol=1e-24)
    sim.run(duration=2e-3)
    assert sim.n_contacts() == (0, 0)
    # the spins changed (rolling and sliding torques acted), the total did not
    assert np.abs(sim.angular_momenta() - spin0).max() > 1e-3 * np.abs(spin0).max()
    scale = np.abs(spin0).max()
    np.testing.assert_allclose(momentum(), l0, rtol=0, atol=1e-10 * scale)


def test_spring_dashpot_is_selected_by_name():
    assert MaterialTable.from_parameters(DEMParameters(rolling_model="epsd")).rolling_model == "epsd"
    assert simulation(DEMParameters()).rolling_model == "constant_torque"
    with pytest.raises(InputError, match="constant_torque, epsd"):
        DEMParameters(rolling_model="type_c")
    with pytest.raises(InputError, match="rolling_damping_ratio"):
        DEMParameters(rolling_damping_ratio=-0.1)
    with pytest.raises(InputError, match="constant_torque, epsd"):
        MaterialTable(rolling_model="spring")
