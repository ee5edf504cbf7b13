"""Conservation laws in clump-clump impacts (no walls, no gravity).

Every contact force acts on both bodies at the same contact point with opposite signs, and the
kick-drift-kick integrator applies forces and torques in the same half steps, so linear momentum
and angular momentum about a fixed point (orbital plus spin) are conserved to round-off. The
LIGGGHTS rolling torque and the spring-dashpot (type C) rolling torque are equal and opposite
pairs and conserve them too; the EDEM rolling torques (against each body's own rotation) are not
a pair and are left out here.
"""

from __future__ import annotations

import numpy as np
import pytest

from demcal.simulate import DEMParameters
from demcal.simulate.clump import segment_template
from demcal.simulate.integrate import random_quaternions
from tests.simulate.helpers import simulation


def _momenta(sim):
    m = sim.masses()[:, None]
    x, v = sim.positions(), sim.velocities()
    p = (m * v).sum(axis=0)
    ang = (np.cross(x, m * v) + sim.angular_momenta()).sum(axis=0)
    return p, ang


@pytest.mark.parametrize("lever,mu_r,model", [("edem_com", 0.0, "constant_torque"),
                                               ("liggghts_reff", 0.53, "constant_torque"),
                                               ("liggghts_reff", 0.53, "epsd")])
def test_momentum_conserved_in_clump_impacts(lever, mu_r, model):
    rng = np.random.default_rng(7)
    params = DEMParameters(e_pp=0.3, mu_s_pp=0.65, mu_r_pp=mu_r, rolling_model=model)
    sim = simulation(params, dt=5e-6, rolling_lever=lever, lo=(-0.3, -0.3, -0.3), hi=(0.3, 0.3, 0.3))
    tpl = sim.add_template(segment_template(0.025, 0.011, 5, 912.0))
    # two small groups of segments thrown at each other, spinning, at random orientations
    q = random_quaternions(rng, 6)
    for k in range(6):
        side = -1.0 if k < 3 else 1.0
        pos = (side * 0.03, 0.02 * (k % 3) - 0.02, 0.004 * (k % 3))
        sim.add_clump(tpl, pos, q[k], velocity=(-side * 1.5, 0.1 * rng.standard_normal(), 0.0),
                      angular_velocity=20 * rng.standard_normal(3))
    p0, l0 = _momenta(sim)
    sim.run(duration=0.04)
    p1, l1 = _momenta(sim)
    # the impacts happened and changed the motion a lot
    assert np.abs(sim.velocities()[:, 0]).max() < 1.4
    scale_p = np.abs(sim.masses()).sum() * 1.5
    np.testing.assert_allclose(p1, p0, rtol=0, atol=1e-12 * scale_p)
    scale_l = scale_p * 0.05
    np.testing.assert_allclose(l1, l0, rtol=0, atol=1e-11 * scale_l)
