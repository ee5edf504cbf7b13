"""Density by displacement and from the envelope; dimension statistics."""

from __future__ import annotations

import math

import pytest

from demcal.errors import InputError
from demcal.measure.density import displacement_density, envelope_density
from demcal.measure.dimensions import cylinder_volume


def test_displacement_density_hand_values():
    # 10 g raising the level from 50 to 61 ml: 10 / 11 g/ml = 909.09 kg/m^3
    assert displacement_density(10e-3, 50e-6, 61e-6) == pytest.approx(909.0909, rel=1e-6)
    # the source paper's 0.912 g/cm^3: 9.12 g displacing 10 ml
    assert displacement_density(9.12e-3, 40e-6, 50e-6) == pytest.approx(912.0)
    with pytest.raises(InputError):
        displacement_density(1e-3, 50e-6, 50e-6)


def test_envelope_density_of_a_cylinder():
    # 11 mm x 25 mm segment: V = pi 121 x 25 / 4 = 2375.8 mm^3; at 912 kg/m^3 it weighs 2.1667 g
    V = cylinder_volume(25e-3, 11e-3)
    assert V == pytest.approx(math.pi * 121 * 25 / 4 * 1e-9)
    assert envelope_density(912.0 * V, 25e-3, 11e-3) == pytest.approx(912.0)
    assert envelope_density(1.6e-3, 24e-3, 10e-3) == pytest.approx(848.826, rel=1e-5)
