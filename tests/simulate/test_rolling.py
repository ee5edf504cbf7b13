"""Constant directional torque rolling friction (EDEM type A, LIGGGHTS cdt).

Analytic answers: a sphere on a slope rolling without slip under a resisting torque
mu_r N R stays put for tan(theta) < mu_r and otherwise accelerates at
a = g (sin(theta) - mu_r cos(theta)) / (1 + I / (m R^2)) = 5/7 g (sin - mu_r cos) (Ai et al. 2011,
model A); lever arms computed by hand for the three conventions.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from demcal.simulate import DEMParameters
from demcal.simulate.clump import segment_template
from tests.simulate.helpers import R, floor, simulation, sphere_template

MU_R = 0.15
THRESHOLD_DEG = math.degrees(math.atan(MU_R))  # 8.53 deg


def slope_run(deg, lever=None, **changes):
    """A sphere settled on a plate tilted by ``deg``, then watched for 0.3 s: the simulation,
    its travel down the slope [m], its speeds before and after [m/s] and its acceleration."""
    theta = math.radians(deg)
    sim = simulation(DEMParameters(mu_r_pw=MU_R, mu_s_pw=0.5, **changes), dt=2e-5, rolling_lever=lever,
                     gravity=(9.81 * math.sin(theta), 0.0, -9.81 * math.cos(theta)),
                     lo=(-0.5, -0.1, -0.05), hi=(1.0, 0.1, 0.1))
    tpl = sphere_template(sim)
    floor(sim)
    sim.add_clump(tpl, (0.0, 0.0, R))
    sim.run(duration=0.2)                      # settle onto the plate
    x0, v0 = sim.positions()[0, 0], sim.velocities()[0, 0]
    sim.run(duration=0.3)
    x1, v1 = sim.positions()[0, 0], sim.velocities()[0, 0]
    return sim, x1 - x0, v0, v1, (v1 - v0) / 0.3


@pytest.mark.parametrize("lever", ["edem_com", "edem_sphere", "liggghts_reff"])
def test_constant_torque_ai2011_sphere_stays_below_atan_mu_r(lever):
    for deg in (THRESHOLD_DEG - 1.0, THRESHOLD_DEG - 0.2):
        _, dx, v0, v1, _ = slope_run(deg, lever)
        assert abs(dx) < 1e-9 and abs(v1) < 1e-9


@pytest.mark.parametrize("lever", ["edem_com", "edem_sphere", "liggghts_reff"])
def test_constant_torque_ai2011_sphere_rolls_above_atan_mu_r(lever):
    for deg in (THRESHOLD_DEG + 0.5, THRESHOLD_DEG + 3.0):
        theta = math.radians(deg)
        _, dx, v0, v1, accel = slope_run(deg, lever)
        expected = 5.0 / 7.0 * 9.81 * (math.sin(theta) - MU_R * math.cos(theta))
        assert dx > 0 and v1 > v0
        assert accel == pytest.approx(expected, rel=0.01)


def _segment_on_floor(lever):
    params = DEMParameters(mu_r_pw=MU_R)
    sim = simulation(params, dt=2e-5, gravity=(0.0, 0.0, -9.81), rolling_lever=lever,
                     lo=(-0.1, -0.1, -0.05), hi=(0.1, 0.1, 0.1))
    tpl = sim.add_template(segment_template(0.025, 0.011, 5, 912.0))
    floor(sim)
    sim.add_clump(tpl, (0.0, 0.0, R))
    sim.run(duration=0.15)
    return sim


def test_lever_arms_of_a_segment_lying_on_the_floor_by_hand():
    # E* particle-steel; the elastic Hertz force of each sphere from its own overlap
    e_p, e_s = 2 * 1e7 * 1.25, 2 * 8e10 * 1.3
    e_star = 1.0 / ((1 - 0.25 ** 2) / e_p + (1 - 0.3 ** 2) / e_s)
    total = {}
    for lever in ("edem_com", "edem_sphere"):
        sim = _segment_on_floor(lever)
        centres = sim.sphere_positions()
        com = sim.positions()[0]
        overlap = R - centres[:, 2]
        assert np.all(overlap > 0)
        f_el = 4.0 / 3.0 * e_star * np.sqrt(R) * overlap ** 1.5
        contact = centres - np.outer(R - overlap / 2, [0.0, 0.0, 1.0])
        if lever == "edem_com":
            arms = np.linalg.norm(contact - com, axis=1)     # contact point to clump centre
        else:
            arms = R - overlap / 2                             # contact point to sphere centre
        magnitude, vector = sim.rolling_resistance()
        assert magnitude[0] == pytest.approx(MU_R * (f_el * arms).sum(), rel=1e-9)
        assert np.all(vector == 0)
        total[lever] = magnitude[0]
    # the clump-centre lever is longer (end spheres sit 7 mm from the centre): mean arm
    # (8.9 + 6.5 + 5.5 + 6.5 + 8.9) / 5 = 7.3 mm against 5.5 mm
    assert total["edem_com"] / total["edem_sphere"] == pytest.approx(7.26 / 5.5, rel=0.02)


def test_liggghts_pair_torque_by_hand():
    # two spheres pressed together, one spinning about z: torque -mu_r F_el R_eff w/|w| on it,
    # the opposite on the other (normal along x, so w is tangential); a particle pair's rolling
    # torque is an ordinary pair torque, so it is the torque with mu_r minus the one without
    def pressed(mu_r):
        sim = simulation(DEMParameters(mu_r_pp=mu_r), dt=1e-6, rolling_lever="liggghts_reff")
        tpl = sphere_template(sim)
        sim.add_clump(tpl, (0.0, 0.0, 0.0), angular_velocity=(0.0, 0.0, 3.0))
        sim.add_clump(tpl, (2 * R - overlap, 0.0, 0.0))
        sim.evaluate_forces()
        return sim

    overlap = 5e-5
    sim, plain = pressed(0.4), pressed(0.0)
    e_p = 2 * 1e7 * 1.25
    e_star = 1.0 / (2 * (1 - 0.25 ** 2) / e_p)
    r_eff = R * R / (2 * R)
    f_el = 4.0 / 3.0 * e_star * math.sqrt(r_eff) * overlap ** 1.5
    rolling = sim.contact_forces()[1] - plain.contact_forces()[1]
    np.testing.assert_allclose(rolling[0], [0.0, 0.0, -0.4 * f_el * r_eff], rtol=1e-9, atol=1e-18)
    np.testing.assert_allclose(rolling[1], -rolling[0], rtol=1e-12, atol=1e-20)
    # a particle contact resists relative rolling only, so it never holds a body still
    magnitude, vector = sim.rolling_resistance()
    np.testing.assert_array_equal(magnitude, [0.0, 0.0])
    np.testing.assert_array_equal(vector, np.zeros((2, 3)))
