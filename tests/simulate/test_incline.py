"""Static friction on a slowly tilting plate (the inclinometer of the paper's friction tests):
a body that cannot roll starts to slide at tan(theta) = mu_s (Coulomb's law of friction).

A flat clump of three spheres lies on the plate; the tilt is applied by turning gravity
(equivalent for a quasi-static test) at 2 deg/s from 2 deg below the expected angle. Sliding is
declared when the clump moves down the slope faster than 2 mm/s; at that tilt rate the body
reaches that speed within about 0.2 deg of the onset.
"""

from __future__ import annotations

import math

import pytest

from demcal.simulate import DEMParameters
from demcal.simulate.clump import make_template
from tests.simulate.helpers import R, floor, simulation


def _gravity(deg):
    th = math.radians(deg)
    return (9.81 * math.sin(th), 0.0, -9.81 * math.cos(th))


@pytest.mark.parametrize("mu_s", [0.2, 0.5])
def test_slide_onset_coulomb_flat_clump_on_tilting_plate(mu_s):
    sim = simulation(DEMParameters(mu_s_pw=mu_s, mu_r_pw=0.15), dt=5e-5, lo=(-1.0, -0.2, -0.05),
                     hi=(1.0, 0.2, 0.1))
    a = 0.008  # sphere centres on a circle of 8 mm: overlapping spheres, a flat triangle
    tpl = sim.add_template(make_template([[a, 0.0, 0.0], [-a / 2, a * math.sqrt(3) / 2, 0.0],
                                          [-a / 2, -a * math.sqrt(3) / 2, 0.0]], R, 912.0))
    floor(sim)
    expected = math.degrees(math.atan(mu_s))
    tilt = expected - 2.0
    sim.gravity = _gravity(tilt)
    sim.add_clump(tpl, (0.0, 0.0, R))
    sim.run(duration=0.2)                       # settle
    assert abs(sim.velocities()[0, 0]) < 1e-6   # holds well below the angle
    rate, chunk = 2.0, 20
    while sim.velocities()[0, 0] < 0.002:
        sim.run(n_steps=chunk)
        tilt += rate * chunk * sim.dt
        sim.gravity = _gravity(tilt)
        assert tilt < expected + 2.0, "never slid"
    assert tilt == pytest.approx(expected, abs=0.5)
    assert abs(sim.angular_velocities()[0]).max() < 1e-6  # it slides, it does not roll
