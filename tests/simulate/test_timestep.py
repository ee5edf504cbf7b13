"""Rayleigh time-step check: T_R = pi R sqrt(rho/G) / (0.1631 nu + 0.8766)."""

from __future__ import annotations

import math

import pytest

from demcal.errors import UnsafeTimeStepError
from demcal.simulate import DEMParameters, rayleigh_time
from tests.simulate.helpers import simulation


def test_rayleigh_time_by_hand_and_paper_fraction():
    t_r = math.pi * 0.0055 * math.sqrt(912 / 1e7) / (0.1631 * 0.25 + 0.8766)
    assert rayleigh_time(0.0055, 912.0, 1e7, 0.25) == pytest.approx(t_r, rel=1e-14)
    # the paper's step is 0.41 T_R at G = 1e7 Pa (docs/design.md)
    assert 7.43678e-5 / t_r == pytest.approx(0.41, abs=0.005)


def _segment_sim(dt, **kwargs):
    sim = simulation(DEMParameters(), dt=dt, **kwargs)
    tpl = sim.add_template(DEMParameters().template())
    sim.add_clump(tpl, (0.0, 0.0, 0.1))
    return sim


def test_unsafe_time_step_is_refused_with_its_numbers():
    t_r = rayleigh_time(0.0055, 912.0, 1e7, 0.25)
    sim = _segment_sim(0.6 * t_r)
    with pytest.raises(UnsafeTimeStepError) as info:
        sim.run(n_steps=1)
    message = str(info.value)
    assert f"{t_r:.6g}" in message            # the Rayleigh time
    assert "0.600 of the Rayleigh time" in message
    assert "allowed fraction 0.5" in message
    assert f"{0.5 * t_r:.6g}" in message      # the limit
    assert sim.time == 0.0


def test_forced_and_stricter_limits():
    t_r = rayleigh_time(0.0055, 912.0, 1e7, 0.25)
    _segment_sim(0.6 * t_r, force=True).run(n_steps=2)
    _segment_sim(7.43678e-5).run(n_steps=2)  # the paper's step passes the default limit
    with pytest.raises(UnsafeTimeStepError):
        _segment_sim(7.43678e-5, max_dt_fraction=0.3).run(n_steps=1)


def test_the_time_step_follows_the_material_unless_stated():
    """dt None: 0.2 of the Rayleigh time of the shape's smallest sphere, by hand: a 6.6 mm
    sphere at rho 1200 kg/m3, G 1.04e6 Pa, nu 0.25 has T_R = pi 0.0033 sqrt(1200 / 1.04e6) /
    (0.1631 x 0.25 + 0.8766) = 3.8388e-4 s."""
    from demcal.simulate.shapes.sphere import Sphere
    from demcal.simulate.timestep import material_time_step

    params = DEMParameters(shape=Sphere(0.0066), particle_density_kg_m3=1200.0, shear_modulus_pa=1.04e6, dt=None)
    t_r = math.pi * 0.0033 * math.sqrt(1200.0 / 1.04e6) / (0.1631 * 0.25 + 0.8766)
    assert t_r == pytest.approx(3.8388e-4, rel=1e-4)
    assert material_time_step(params) == pytest.approx(0.2 * t_r, rel=1e-12)
    assert material_time_step(params.with_(dt=5e-5)) == 5e-5
    # the paper's step is 0.41 of its segment's T_R, and what the paper's parameters state
    assert material_time_step(DEMParameters()) == 7.43678e-5


def test_a_time_step_above_the_safe_limit_is_refused_naming_the_option():
    from demcal.errors import UnsafeTimeStepError
    from demcal.simulate.shapes.sphere import Sphere
    from demcal.simulate.timestep import material_time_step

    small = DEMParameters(shape=Sphere(0.002), particle_density_kg_m3=1200.0)     # the paper's step
    with pytest.raises(UnsafeTimeStepError, match=r"give a smaller time step: --set dt=SECONDS"):
        material_time_step(small)


# ----------------------------------------------------------------------------------------------
# the damped limit: w dt < 2 (sqrt(1 + z^2) - z) for the kick-drift-kick scheme


def _resting_sphere(restitution, factor, mode):
    """A sphere resting on the steel floor under gravity, at ``factor`` times the damped stable
    step of its normal (``"n"``) or tangential (``"t"``) contact mode, linearised about its
    static overlap d0 by hand: m g = 4/3 E* sqrt(R) d0^1.5, S_n = 2 E* sqrt(R d0),
    S_t = 8 G* sqrt(R d0), w_n^2 = S_n / m, w_t^2 = 3.5 S_t / m (rotation included)."""
    from demcal.simulate.contact.hertz_mindlin import effective_modulus, effective_shear_modulus
    from demcal.simulate.timestep import contact_damping_ratios, stable_step_ratio
    from tests.simulate.helpers import R, floor, simulation, sphere_mass, sphere_template

    p = DEMParameters(e_pw=restitution, mu_s_pw=50.0, mu_r_pw=0.0)   # no sliding, no rolling torque
    e_p = 2 * p.shear_modulus_pa * (1 + p.poisson_ratio)
    e_w = 2 * p.wall_shear_modulus_pa * (1 + p.wall_poisson_ratio)
    e_star = effective_modulus(e_p, p.poisson_ratio, e_w, p.wall_poisson_ratio)
    g_star = effective_shear_modulus(p.shear_modulus_pa, p.poisson_ratio, p.wall_shear_modulus_pa,
                                     p.wall_poisson_ratio)
    m, g = sphere_mass(), 9.81
    d0 = (3 * m * g / (4 * e_star * math.sqrt(R))) ** (2 / 3)
    zeta_n, zeta_t = contact_damping_ratios(restitution)
    if mode == "n":
        omega, zeta = math.sqrt(2 * e_star * math.sqrt(R * d0) / m), zeta_n
    else:
        omega, zeta = math.sqrt(3.5 * 8 * g_star * math.sqrt(R * d0) / m), zeta_t
    sim = simulation(p, dt=factor * 2 * stable_step_ratio(zeta) / omega, force=True, gravity=(0, 0, -g))
    tpl = sphere_template(sim)
    floor(sim)
    if mode == "n":   # pressed 0.01 % deeper than at rest (a growing oscillation saturates when it lifts off)
        sim.add_clump(tpl, (0.0, 0.0, R - 1.0001 * d0))
        return sim, lambda: abs(R - sim.sphere_positions()[0, 2] - d0)
    sim.add_clump(tpl, (0.0, 0.0, R - d0), angular_velocity=(0.0, 1e-3, 0.0))   # the contact slips
    return sim, lambda: abs(sim.velocities()[0, 0] - sim.angular_velocities()[0, 1] * R)


@pytest.mark.parametrize("mode", ["n", "t"])
@pytest.mark.parametrize("restitution", [0.9, 0.3, 0.05, 0.01])
def test_the_engine_is_stable_below_the_damped_limit_and_not_above(restitution, mode):
    """Just below the limit the disturbance decays; 5 % above it grows by orders of magnitude
    (the growth factor per step is 1.1-1.7 there), for both contact modes and every damping."""
    def largest_disturbance(factor):
        sim, disturbance = _resting_sphere(restitution, factor, mode)
        sim.run(n_steps=1)
        first = disturbance()
        seen = []
        for _ in range(300):
            sim.run(n_steps=1)
            seen.append(disturbance())
        return max(seen[10:]) / first

    assert largest_disturbance(0.95) < 1.0
    assert largest_disturbance(1.05) > 1e3


def test_a_stated_step_above_the_damped_limit_is_divided_into_sub_steps():
    """By hand, e = 0.012: ln e = -4.4228, beta = -4.4228 / sqrt(4.4228^2 + pi^2) = -0.8153,
    z_t = sqrt(3.5 x 5/6) x 0.8153 = 1.3923, sqrt(1 + z_t^2) - z_t = 0.3219 of T_R: the paper's
    step (0.41 T_R) runs as two halves. At e = 0.3 (z_t = 0.611, 0.56) it runs whole; a
    velocity-dependent restitution counts at its floor 1e-6 (0.277 T_R); a step that follows
    the material (0.2 T_R) is below the damped limit at every restitution."""
    from demcal.simulate.timestep import damped_max_fraction, material_rayleigh_time, material_time_step

    assert damped_max_fraction(0.012) == pytest.approx(0.3219, abs=1e-4)
    assert damped_max_fraction(1e-6) == pytest.approx(0.2772, abs=1e-4)
    assert damped_max_fraction(0.3) == 0.5
    paper = DEMParameters()
    assert material_time_step(paper.with_(e_pp=0.3)) == 7.43678e-5
    assert material_time_step(paper.with_(e_pp=0.012)) == 7.43678e-5 / 2
    assert material_time_step(paper.with_(e_pw=0.012)) == 7.43678e-5 / 2
    assert material_time_step(paper.with_(e_pp_exponent=0.1)) == 7.43678e-5 / 2
    t_r = material_rayleigh_time(paper)
    assert material_time_step(paper.with_(dt=0.49 * t_r, e_pp=0.01)) == pytest.approx(0.49 * t_r / 2)
    assert material_time_step(paper.with_(dt=0.5 * t_r, e_pp=1e-6, e_pw=1e-6)) == pytest.approx(0.5 * t_r / 2)
    assert material_time_step(paper.with_(dt=None, e_pp=1e-6)) == pytest.approx(0.2 * t_r)


@pytest.mark.parametrize("fraction", [0.25, 0.3185, 0.41, 0.45, 0.5])
def test_the_lowest_safe_restitution_is_where_the_damped_limit_meets_the_step(fraction):
    """Its closed-form inverse put back into the forward limit gives the step again; every
    restitution above it allows the step, every one below does not."""
    from demcal.simulate.timestep import RESTITUTION_FLOOR, damped_max_fraction, lowest_safe_restitution

    e = lowest_safe_restitution(fraction)
    if fraction <= damped_max_fraction(RESTITUTION_FLOOR):
        assert e == RESTITUTION_FLOOR
        return
    assert damped_max_fraction(e) == pytest.approx(fraction, rel=1e-12)
    assert damped_max_fraction(e * 1.01) >= fraction > damped_max_fraction(e * 0.99)
