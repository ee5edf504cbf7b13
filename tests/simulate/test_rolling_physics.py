"""Rolling and tangential-history details checked against LIGGGHTS-PUBLIC 3.8's source and
against conservation laws.

- EPSD (Ai et al. 2011 type C) rolling stiffness: LIGGGHTS' ``rolling_model_epsd.h`` takes
  k_r = 2.25 k_n mu_r^2 R_eff^2 with ``sidata.kn`` from ``normal_model_hertz.h``,
  k_n = 4/3 Y_eff sqrt(R_eff d_n); the torque after a rotation d_theta is -k_r d_theta.
- The static stop of the constant torque leaves the twist about the contact normal alone.
- A clump-clump rolling contact conserves the total angular momentum to round-off.
- A force evaluation with dt = 0 reads the contact history and never writes it; with dt > 0
  the tangential displacement is incremented, then projected (LIGGGHTS'
  ``tangential_model_history.h`` order).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from demcal.simulate import DEMParameters
from demcal.simulate.clump import segment_template
from demcal.simulate.contact.hertz_mindlin import tangential_force
from demcal.simulate.contact.rolling import constant_torque, epsd_torque
from tests.simulate.helpers import R, floor, simulation, sphere_template

E_P = 2 * 1e7 * 1.25            # Young's modulus of the segment material, E = 2 G (1 + nu)
E_STAR_PP = 1.0 / (2 * (1 - 0.25 ** 2) / E_P)


def _liggghts_epsd_kr(y_eff, r_eff, overlap, mu_r):
    """k_r as rolling_model_epsd.h computes it (kn from normal_model_hertz.h)."""
    kn = 4.0 / 3.0 * y_eff * math.sqrt(r_eff * overlap)
    return 2.25 * kn * mu_r * mu_r * r_eff * r_eff


def test_epsd_spring_slope_is_liggghts_epsd():
    # evaluator: one step of a relative rolling rate w about an axis in the tangent plane
    mu_r, r_eff, overlap, dt = 0.3, R / 2, 4e-5, 1e-6
    hist = np.zeros((1, 7))
    w = 2.0
    tx, ty, tz, m_i = epsd_torque(mu_r, 10.0, E_STAR_PP, math.sqrt(r_eff * overlap), r_eff, R, R,
                                  1e3, 1e3, 0.0, hist, 0, 4, 0.0, 0.0, w, 1.0, 0.0, 0.0, dt)
    k_r = _liggghts_epsd_kr(E_STAR_PP, r_eff, overlap, mu_r)
    assert hist[0, 6] == pytest.approx(-k_r * w * dt, rel=1e-12)
    assert (tx, ty, tz) == pytest.approx((0.0, 0.0, -k_r * w * dt), rel=1e-12)
    assert m_i == pytest.approx(mu_r * 10.0 * r_eff, rel=1e-12)


def test_epsd_slope_in_the_engine():
    # two spheres pressed together, one turning slowly about z (in the contact plane): after
    # n steps the spring torque is -k_r theta, theta the relative rotation, with LIGGGHTS' k_r
    # (the damping ratio is set to zero so that the spin stays nearly constant)
    mu_r, overlap, w, n = 0.4, 5e-5, 0.01, 20
    params = DEMParameters(mu_r_pp=mu_r, mu_s_pp=0.5, rolling_model="epsd", rolling_damping_ratio=0.0)
    sim = simulation(params, dt=1e-6)
    tpl = sphere_template(sim)
    sim.add_clump(tpl, (0.0, 0.0, 0.0), angular_velocity=(0.0, 0.0, w))
    sim.add_clump(tpl, (2 * R - overlap, 0.0, 0.0))
    expected = 0.0                     # sum of -k_r(d_n) d_theta over the steps
    for _ in range(n):
        w_before = sim.angular_velocities()[:, 2].copy()
        sim.run(n_steps=1)
        # the step's forces act at the new positions with the half-kicked spin
        d_theta = 0.5 * (w_before + sim.angular_velocities()[:, 2]) @ [1.0, -1.0] * sim.dt
        d_n = 2 * R - (sim.positions()[1, 0] - sim.positions()[0, 0])
        expected -= _liggghts_epsd_kr(E_STAR_PP, R / 2, d_n, mu_r) * d_theta
    spring = sim.contact_history()["pairs"]["rolling_torque"][0]
    assert spring[2] == pytest.approx(expected, rel=1e-4)
    # the former stiffness (2 E* sqrt(R d)) would be 1.5 times larger
    assert abs(spring[2] / expected - 1.5) > 0.4


def test_static_stop_keeps_the_twist_about_the_contact_normal():
    # a sphere resting on the floor, turning slowly about the vertical (the floor's normal):
    # the rolling stop must not touch this twist; the point contact under the centre exerts
    # no torque about the normal, so the spin stays as it was
    params = DEMParameters(mu_r_pw=0.15, mu_s_pw=0.5)
    sim = simulation(params, dt=2e-5, gravity=(0.0, 0.0, -9.81), rolling_lever="liggghts_reff",
                     lo=(-0.1, -0.1, -0.05), hi=(0.1, 0.1, 0.1))
    tpl = sphere_template(sim)
    floor(sim)
    sim.add_clump(tpl, (0.0, 0.0, R))
    sim.run(duration=0.1)                        # settle
    twist = 1e-3                                 # rad/s: slow enough for the stop to engage
    assert twist * 0.4 * sim.masses()[0] * R * R < 0.15 * sim.masses()[0] * 9.81 * R * sim.dt
    sim2 = simulation(params, dt=2e-5, gravity=(0.0, 0.0, -9.81), rolling_lever="liggghts_reff",
                      lo=(-0.1, -0.1, -0.05), hi=(0.1, 0.1, 0.1))
    tpl2 = sphere_template(sim2)
    floor(sim2)
    sim2.add_clump(tpl2, sim.positions()[0], velocity=sim.velocities()[0],
                   angular_velocity=(0.0, 0.0, twist))
    sim2.run(duration=0.05)
    w = sim2.angular_velocities()[0]
    assert w[2] == pytest.approx(twist, rel=1e-9)
    assert abs(w[0]) < 1e-12 and abs(w[1]) < 1e-12


def test_clump_clump_rolling_conserves_angular_momentum():
    # two segments pressed side by side (no gravity, no walls), turning slowly in different
    # directions so that the rolling torque's cap acts: the total angular momentum (orbit and
    # spin) is conserved to round-off
    params = DEMParameters(mu_r_pp=0.4, mu_s_pp=0.5)
    sim = simulation(params, dt=1e-6, rolling_lever="liggghts_reff")
    tpl = sim.add_template(segment_template(0.025, 0.011, 5, 912.0))
    overlap = 4e-5
    # spins so slow that one step's rolling impulse could reverse them: the cap acts
    sim.add_clump(tpl, (0.0, 0.0, 0.0), angular_velocity=(2e-4, -5e-4, 3e-4))
    sim.add_clump(tpl, (0.0, 2 * R - overlap, 0.0), angular_velocity=(-1e-4, 4e-4, 0.0))

    def momentum():
        m = sim.masses()[:, None]
        return (np.cross(sim.positions(), m * sim.velocities()) + sim.angular_momenta()).sum(axis=0)

    l0 = momentum()
    spin0 = sim.angular_momenta()
    sim.run(n_steps=60)
    assert sim.n_contacts()[0] > 0
    sim.run(duration=2e-3)
    spin = sim.angular_momenta()
    assert np.abs(spin - spin0).max() > 1e-2 * np.abs(spin0).max()   # torques acted
    scale = np.abs(spin0).max()
    np.testing.assert_allclose(momentum(), l0, rtol=0, atol=1e-9 * scale)


def test_force_evaluation_without_a_step_leaves_the_history_alone():
    # a stored displacement with a component along the (tilted) normal: dt = 0 must not project
    # it or shorten it to the Coulomb limit
    hist = np.array([[3e-6, -1e-6, 2e-6]])
    before = hist.copy()
    n = np.array([0.6, 0.0, 0.8])
    tangential_force(hist, 0, *n, 0.01, 0.0, 0.0, 1e7, 1e-3, 0.3, 0.5, 1e-4, 0.01, 0.0)
    np.testing.assert_array_equal(hist, before)
    rolling = np.array([[0.0, 0.0, 0.0, 0.0, 1e-5, -2e-5, 3e-5]])
    kept = rolling.copy()
    epsd_torque(0.3, 1e-3, E_STAR_PP, 1e-4, R / 2, R, R, 1e3, 1e3, 0.3, rolling, 0, 4, 1.0, 2.0, 3.0,
                *n, 0.0)
    np.testing.assert_array_equal(rolling, kept)


def test_tangential_history_increments_then_projects_as_liggghts():
    hist = np.array([[1e-6, 2e-6, 0.0]])
    n = np.array([0.0, 0.6, 0.8])
    v = np.array([0.01, -0.02, 0.005])
    dt = 1e-5
    tangential_force(hist, 0, *n, *v, 1e9, 1e-3, 0.3, 100.0, 1e-4, 1000.0, dt)
    shear = np.array([1e-6, 2e-6, 0.0]) + v * dt     # increment ...
    shear -= (shear @ n) * n                         # ... then project, length not restored
    np.testing.assert_allclose(hist[0], shear, rtol=1e-12, atol=1e-20)


def test_constant_torque_resists_only_the_tangential_relative_rotation():
    # w_r = (0, 1, 1) rad/s with the normal along z: LIGGGHTS' cdt torque mu_r F_n R w_r/|w_r|
    # with its normal component removed, on body i against the rotation
    mu_r, f_el, r_eff = 0.3, 2.0, R / 2
    tx, ty, tz, m = constant_torque(mu_r, f_el, r_eff, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0)
    assert (tx, ty, tz) == pytest.approx((0.0, -mu_r * f_el * r_eff / math.sqrt(2.0), 0.0), rel=1e-12)
    assert m == pytest.approx(mu_r * f_el * r_eff, rel=1e-12)
