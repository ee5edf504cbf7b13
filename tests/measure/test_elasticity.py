"""Poisson's ratio, elastic modulus from a loading curve, and shear modulus."""

from __future__ import annotations

import math

import numpy as np
import pytest

from demcal.errors import InputError
from demcal.measure.elasticity import (contact_area, elastic_modulus, initial_linear_region,
                                poisson_ratio, poisson_ratio_eq1, shear_modulus)
from tests.measure.conftest import curve_frame


def test_poisson_ratio_normalised_hand_values():
    # width 10 -> 10.3 mm (strain 0.03), thickness 12 -> 10 mm (strain 1/6): nu = 0.18
    assert poisson_ratio(10e-3, 10.3e-3, 12e-3, 10e-3) == pytest.approx(0.18)
    # width 11 -> 11.2 (0.2/11), thickness 25 -> 22 (3/25): nu = 0.01818 / 0.12 = 0.1515
    assert poisson_ratio(11e-3, 11.2e-3, 25e-3, 22e-3) == pytest.approx(0.151515, abs=1e-6)


def test_poisson_ratio_eq1_uses_absolute_changes():
    # source paper eq. (1): (L1 - L2) / (H2 - H1) = -0.3 / -2 = 0.15 for the first case above
    assert poisson_ratio_eq1(10e-3, 10.3e-3, 12e-3, 10e-3) == pytest.approx(0.15)
    # with equal width and thickness before loading the two definitions agree
    assert poisson_ratio_eq1(11e-3, 11.5e-3, 11e-3, 10e-3) == pytest.approx(
        poisson_ratio(11e-3, 11.5e-3, 11e-3, 10e-3))


def test_poisson_ratio_needs_axial_strain():
    with pytest.raises(InputError, match="thickness"):
        poisson_ratio(10e-3, 10.2e-3, 12e-3, 12e-3)


def test_initial_linear_region_stops_where_the_specimen_cracks():
    # F = 200 N/mm x d up to 1 mm (21 samples), then the force halves
    c = curve_frame(200.0, 1.0)
    region = initial_linear_region(c.displacement_mm.to_numpy() * 1e-3, c.force_N.to_numpy())
    assert region.slope == pytest.approx(200e3)  # [N/m]
    assert (region.start, region.stop) == (1, 21)  # sample 0 (F = 0) is below the trigger
    assert region.r2 == pytest.approx(1.0)


def test_initial_linear_region_on_a_softening_curve_with_noise():
    # linear to 0.5 mm, then softening F = k d - c (d - 0.5)^2 (mm, N); small noise.
    rng = np.random.default_rng(3)
    d = np.linspace(0, 2.0, 201)
    k = 150.0
    F = k * d - np.where(d > 0.5, 120.0 * (d - 0.5) ** 2, 0.0) + rng.normal(0, 0.2, d.size)
    region = initial_linear_region(d * 1e-3, F, r2_min=0.999)
    # the window must cover the linear part and stop before the curve bends much
    assert 0.5 <= d[region.stop - 1] <= 1.0
    assert region.slope == pytest.approx(k * 1e3, rel=0.05)


def test_initial_linear_region_failure():
    d = np.linspace(0, 1, 10)
    with pytest.raises(InputError, match="linear"):
        initial_linear_region(d, np.sin(8 * d) + 1.0, r2_min=0.999)


def test_elastic_modulus_hand_values():
    # radial: k 200 N/mm, t0 11 mm, A = w0 L = 11 x 24 mm^2: E = 2e5 x 0.011 / 2.64e-4 = 8.333 MPa
    A = contact_area("radial", 11e-3, 24e-3)
    assert A == pytest.approx(2.64e-4)
    assert elastic_modulus(2e5, 11e-3, A) == pytest.approx(8.3333e6, rel=1e-4)
    # axial: k 100 N/mm, t0 25 mm, A = pi 11^2 / 4 = 95.03 mm^2: E = 1e5 x 0.025 / 9.503e-5 = 26.31 MPa
    A = contact_area("axial", 11e-3)
    assert A == pytest.approx(math.pi * 121e-6 / 4)
    assert elastic_modulus(1e5, 25e-3, A) == pytest.approx(26.307e6, rel=1e-4)
    with pytest.raises(InputError, match="length"):
        contact_area("radial", 11e-3)


def test_shear_modulus_isotropic():
    # steel in the source paper: E 2.06e11 Pa, nu 0.3 -> G = 7.92e10 Pa (the paper rounds to 8e10)
    assert shear_modulus(2.06e11, 0.3) == pytest.approx(7.923e10, rel=1e-3)
    assert shear_modulus(3.0e6, 0.5) == pytest.approx(1.0e6)
