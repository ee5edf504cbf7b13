"""Hertz-Mindlin (no slip) contact law against analytic answers and hand calculations.

References: Johnson (1985) Contact Mechanics, sec. 11.4 (elastic impact duration); the
restitution damping of the EDEM theory guide (docs/design.md, "The DEM"), whose 2 sqrt(5/6) beta
factor makes the velocity ratio of a binary impact equal to the set coefficient e.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from demcal.simulate import DEMParameters
from demcal.simulate.contact.hertz_mindlin import contact_duration_elastic, tangential_force
from tests.simulate.helpers import R, floor, simulation, sphere_mass, sphere_template

PARTICLE = dict(G=1e7, nu=0.25)
STEEL = dict(G=8e10, nu=0.3)


def e_star(a, b):
    ea, eb = 2 * a["G"] * (1 + a["nu"]), 2 * b["G"] * (1 + b["nu"])
    return 1.0 / ((1 - a["nu"] ** 2) / ea + (1 - b["nu"] ** 2) / eb)


def g_star(a, b):
    return 1.0 / ((2 - a["nu"]) / a["G"] + (2 - b["nu"]) / b["G"])


def beta(e):
    return math.log(e) / math.sqrt(math.log(e) ** 2 + math.pi ** 2)


# ---------------------------------------------------------------- restitution (velocity ratio)
@pytest.mark.parametrize("e", [0.1, 0.3, 0.5, 0.7, 0.9])
def test_restitution_damping_tsuji1992_sphere_on_plate(e):
    # dt = 1e-6 s resolves the ~0.5 ms contact in ~500 steps; no gravity: the pure impact
    sim = simulation(DEMParameters(e_pw=e), dt=1e-6)
    tpl = sphere_template(sim)
    floor(sim)
    sim.add_clump(tpl, (0.0, 0.0, R + 1e-6), velocity=(0.0, 0.0, -1.2))
    sim.run(duration=1.5e-3)
    assert sim.velocities()[0, 2] / 1.2 == pytest.approx(e, rel=0.01)


@pytest.mark.parametrize("e", [0.1, 0.3, 0.5, 0.7, 0.9])
def test_restitution_damping_tsuji1992_sphere_on_sphere(e):
    sim = simulation(DEMParameters(e_pp=e), dt=1e-6)
    tpl = sphere_template(sim)
    sim.add_clump(tpl, (0.0, 0.0, 0.0), velocity=(0.6, 0.0, 0.0))
    sim.add_clump(tpl, (2 * R + 1e-6, 0.0, 0.0), velocity=(-0.6, 0.0, 0.0))
    sim.run(duration=2.5e-3)
    v = sim.velocities()
    assert (v[1, 0] - v[0, 0]) / 1.2 == pytest.approx(e, rel=0.01)


# ---------------------------------------------------------------- contact duration
def _contact_steps(sim, touching, max_steps=5000):
    """Steps during which ``touching(sim)`` holds, from first contact to separation."""
    steps, started = 0, False
    for _ in range(max_steps):
        sim.run(n_steps=1)
        if touching(sim):
            started = True
            steps += 1
        elif started:
            return steps
    raise AssertionError("contact did not end")


def test_hertz_contact_time_johnson1985_sphere_on_plate():
    v = 0.8
    sim = simulation(DEMParameters(e_pw=1.0), dt=2e-7)
    tpl = sphere_template(sim)
    floor(sim)
    sim.add_clump(tpl, (0.0, 0.0, R + 1e-8), velocity=(0.0, 0.0, -v))
    steps = _contact_steps(sim, lambda s: s.positions()[0, 2] < R)
    t_c = 2.868 * (sphere_mass() ** 2 / (R * e_star(PARTICLE, STEEL) ** 2 * v)) ** 0.2
    assert steps * 2e-7 == pytest.approx(t_c, rel=0.03)
    # the library's own formula is the same expression
    ours = contact_duration_elastic(sphere_mass(), R, e_star(PARTICLE, STEEL), v)
    assert ours == pytest.approx(t_c, rel=1e-12)


def test_hertz_contact_time_johnson1985_two_spheres():
    v_rel = 1.0
    sim = simulation(DEMParameters(e_pp=1.0), dt=2e-7)
    tpl = sphere_template(sim)
    sim.add_clump(tpl, (0.0, 0.0, 0.0), velocity=(v_rel / 2, 0.0, 0.0))
    sim.add_clump(tpl, (2 * R + 1e-8, 0.0, 0.0), velocity=(-v_rel / 2, 0.0, 0.0))
    steps = _contact_steps(sim, lambda s: np.linalg.norm(s.positions()[1] - s.positions()[0]) < 2 * R)
    m_star, r_star = sphere_mass() / 2, R / 2
    t_c = 2.868 * (m_star ** 2 / (r_star * e_star(PARTICLE, PARTICLE) ** 2 * v_rel)) ** 0.2
    assert steps * 2e-7 == pytest.approx(t_c, rel=0.03)


# ---------------------------------------------------------------- two spheres, by hand
def _two_sphere_state(v_a, v_b, w_a, w_b, overlap=1e-4, e=0.3, mu_s=0.65):
    params = DEMParameters(e_pp=e, mu_s_pp=mu_s, mu_r_pp=0.0)
    sim = simulation(params, dt=1e-6)
    tpl = sphere_template(sim)
    sim.add_clump(tpl, (0.0, 0.0, 0.0), velocity=v_a, angular_velocity=w_a)
    sim.add_clump(tpl, (2 * R - overlap, 0.0, 0.0), velocity=v_b, angular_velocity=w_b)
    sim.evaluate_forces()
    return sim


def _hand_forces(v_a, v_b, w_a, w_b, overlap=1e-4, e=0.3, mu_s=0.65):
    """Force and torque on sphere A from docs/design.md's formulas (no tangential history yet)."""
    es, gs = e_star(PARTICLE, PARTICLE), g_star(PARTICLE, PARTICLE)
    r_star, m_star = R / 2, sphere_mass() / 2
    n = np.array([1.0, 0.0, 0.0])                       # from A to B
    arm_a = (R - overlap / 2) * n                        # contact point from A's centre
    arm_b = -(R - overlap / 2) * n
    v_rel = (np.add(v_a, np.cross(w_a, arm_a))) - (np.add(v_b, np.cross(w_b, arm_b)))
    v_n = v_rel @ n
    v_t = v_rel - v_n * n
    s_n = 2 * es * math.sqrt(r_star * overlap)
    s_t = 8 * gs * math.sqrt(r_star * overlap)
    f_n = 4 / 3 * es * math.sqrt(r_star) * overlap ** 1.5 + \
        2 * math.sqrt(5 / 6) * abs(beta(e)) * math.sqrt(s_n * m_star) * v_n
    f_t = -2 * math.sqrt(5 / 6) * abs(beta(e)) * math.sqrt(s_t * m_star) * v_t
    if np.linalg.norm(f_t) > mu_s * abs(f_n):
        f_t *= mu_s * abs(f_n) / np.linalg.norm(f_t)
    force = -f_n * n + f_t
    return force, np.cross(arm_a, force), f_n


def test_two_sphere_forces_by_hand_from_design_formulas():
    case = dict(v_a=(0.3, 0.2, 0.0), v_b=(-0.1, 0.0, 0.05), w_a=(0.0, 0.0, 5.0), w_b=(1.0, 0.0, 0.0))
    sim = _two_sphere_state(**case)
    force, torque = sim.contact_forces()
    f_hand, t_hand, f_n = _hand_forces(**case)
    assert f_n > 0
    np.testing.assert_allclose(force[0], f_hand, rtol=1e-10, atol=1e-12 * abs(f_n))
    np.testing.assert_allclose(force[1], -f_hand, rtol=1e-10, atol=1e-12 * abs(f_n))
    np.testing.assert_allclose(torque[0], t_hand, rtol=1e-10, atol=1e-14)


def test_two_sphere_coulomb_cap_by_hand_from_design_formulas():
    # a fast sideways slip: the tangential dashpot alone would exceed mu_s F_n
    case = dict(v_a=(0.0, 3.0, 0.0), v_b=(0.0, -3.0, 0.0), w_a=(0.0, 0.0, 0.0), w_b=(0.0, 0.0, 0.0))
    sim = _two_sphere_state(**case)
    force, _ = sim.contact_forces()
    f_hand, _, f_n = _hand_forces(**case)
    assert abs(force[0, 1]) == pytest.approx(0.65 * f_n, rel=1e-10)
    np.testing.assert_allclose(force[0], f_hand, rtol=1e-10)


# ---------------------------------------------------------------- tangential spring, by hand
def test_tangential_spring_accumulates_and_slides():
    g, m, damping, mu, sqrt_rd, dt = 3e6, 1e-3, 0.5, 0.4, 1e-4, 1e-5
    s_t = 8 * g * sqrt_rd
    hist = np.zeros((1, 3))
    n = (0.0, 0.0, 1.0)
    # stick: spring from v_t dt plus dashpot
    f = tangential_force(hist, 0, *n, 0.01, 0.0, 0.0, g, m, damping, mu, sqrt_rd, 100.0, dt)
    expected = -s_t * 0.01 * dt - damping * math.sqrt(s_t * m) * 0.01
    assert f[0] == pytest.approx(expected, rel=1e-12)
    assert hist[0, 0] == pytest.approx(0.01 * dt, rel=1e-12)
    # slide: the spring is held at mu F_n and the displacement shortened to match
    hist[0] = (1.0, 0.0, 0.0)
    f = tangential_force(hist, 0, *n, 0.0, 0.0, 0.0, g, m, damping, mu, sqrt_rd, 100.0, dt)
    assert f[0] == pytest.approx(-mu * 100.0, rel=1e-12)
    assert hist[0, 0] == pytest.approx(mu * 100.0 / s_t, rel=1e-12)


def test_tangential_history_turns_into_new_tangent_plane():
    # a stored displacement with a normal component is projected onto the tangent plane, its
    # length not restored (LIGGGHTS-PUBLIC 3.8, tangential_model_history.h)
    hist = np.array([[3e-6, 0.0, 4e-6]])
    tangential_force(hist, 0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1e6, 1e-3, 0.0, 10.0, 1e-4, 1e6, 1e-5)
    np.testing.assert_allclose(hist[0], [3e-6, 0.0, 0.0], rtol=1e-12, atol=1e-20)
