"""Density by displacement and from the envelope; dimension statistics."""

from __future__ import annotations

import math

import pytest

from demcal.errors import InputError
from demcal.measure.density import displacement_density
from demcal.simulate.shapes.kernel import Kernel
from demcal.simulate.shapes.segment import Segment
from demcal.simulate.shapes.sphere import Sphere


def test_displacement_density_hand_values():
    # 10 g raising the level from 50 to 61 ml: 10 / 11 g/ml = 909.09 kg/m^3
    assert displacement_density(10e-3, 50e-6, 61e-6) == pytest.approx(909.0909, rel=1e-6)
    # the source paper's 0.912 g/cm^3: 9.12 g displacing 10 ml
    assert displacement_density(9.12e-3, 40e-6, 50e-6) == pytest.approx(912.0)
    with pytest.raises(InputError):
        displacement_density(1e-3, 50e-6, 50e-6)


def test_envelope_volumes_of_the_shapes():
    # 11 mm x 25 mm segment: V = pi 121 x 25 / 4 = 2375.8 mm^3; 1.6 g of a 24 x 10 mm one: 848.826 kg/m^3
    assert Segment(25e-3, 11e-3).volume() == pytest.approx(math.pi * 121 * 25 / 4 * 1e-9)
    assert 1.6e-3 / Segment(24e-3, 10e-3).volume() == pytest.approx(848.826, rel=1e-5)
    # a 6.6 mm soybean: pi 6.6^3 / 6 = 150.53 mm^3; a 7.2 x 3.0 x 2.1 mm rice kernel: pi 45.36 / 6
    assert Sphere(6.6e-3).volume() == pytest.approx(150.5329e-9, rel=1e-6)
    assert Kernel(7.2e-3, 3.0e-3, 2.1e-3).volume() == pytest.approx(math.pi * 45.36 / 6 * 1e-9, rel=1e-12)
