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
