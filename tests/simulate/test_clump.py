"""Clump templates: geometry of the paper's segment and mass properties of sphere unions,
checked against an independent Monte Carlo integration and closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from demcal.errors import InputError
from demcal.simulate.clump import (make_template, segment_centres, segment_template, union_mass_properties)


def _monte_carlo(centres, radii, density, n, seed):
    """Mass, centre of mass and inertia tensor by uniform sampling of the bounding box, with
    the standard error of the mass."""
    rng = np.random.default_rng(seed)
    c, r = np.asarray(centres, float), np.asarray(radii, float)
    lo, hi = (c - r[:, None]).min(axis=0), (c + r[:, None]).max(axis=0)
    box = np.prod(hi - lo)
    mass, first, second, hits = 0.0, np.zeros(3), np.zeros((3, 3)), 0
    for _ in range(n // 500_000):
        p = lo + rng.random((500_000, 3)) * (hi - lo)
        inside = (((p[:, None, :] - c[None]) ** 2).sum(axis=2) < r ** 2).any(axis=1)
        q = p[inside]
        hits += q.shape[0]
        first += q.sum(axis=0)
        second += q.T @ q
    frac = hits / n
    mass = density * box * frac
    com = first / hits
    cov = second / hits - np.outer(com, com)           # per unit mass, about the centre of mass
    inertia = mass * (np.trace(cov) * np.eye(3) - cov)
    rel_se = math.sqrt((1 - frac) / (frac * n))
    return mass, com, inertia, rel_se


def test_paper_segment_geometry():
    c = segment_centres(0.025, 0.011, 5)
    np.testing.assert_allclose(c[:, 0], [-0.007, -0.0035, 0.0, 0.0035, 0.007], atol=1e-15)
    tpl = segment_template(0.025, 0.011, 5, 912.0)
    assert tpl.bounding_radius == pytest.approx(0.0125, rel=1e-12)
    np.testing.assert_allclose(tpl.principal_axes, np.eye(3))


@pytest.mark.parametrize("shape", ["segment", "bent"])
def test_union_mass_properties_match_monte_carlo(shape):
    if shape == "segment":
        centres, radii = segment_centres(0.025, 0.011, 5), np.full(5, 0.0055)
    else:  # a non-collinear clump of unequal spheres: off-diagonal inertia
        centres = np.array([[0.0, 0.0, 0.0], [0.006, 0.002, 0.0], [0.01, 0.007, 0.003]])
        radii = np.array([0.005, 0.004, 0.003])
    ours = union_mass_properties(centres, radii, 912.0)
    mass, com, inertia, rel_se = _monte_carlo(centres, radii, 912.0, 4_000_000, seed=3)
    assert ours.mass == pytest.approx(mass, rel=4 * rel_se)
    size = radii.max()
    np.testing.assert_allclose(ours.centre_of_mass, com, atol=4 * rel_se * size + 1e-7)
    scale = np.abs(inertia).max()
    np.testing.assert_allclose(ours.inertia, inertia, rtol=0, atol=6 * rel_se * scale)


def test_union_of_two_spheres_matches_lens_formula():
    r, d = 0.005, 0.006
    centres = np.array([[0.0, 0.0, 0.0], [d, 0.0, 0.0]])
    # V = 2 V_sphere - V_lens, V_lens = pi (2r - d)^2 (d^2 + 4 d r) / (12 d) (equal radii)
    lens = math.pi * (2 * r - d) ** 2 * (d ** 2 + 4 * d * r) / (12 * d)
    volume = 2 * 4 / 3 * math.pi * r ** 3 - lens
    ours = union_mass_properties(centres, [r, r], 1000.0)
    assert ours.mass == pytest.approx(1000.0 * volume, rel=5e-5)
    assert ours.centre_of_mass[0] == pytest.approx(d / 2, rel=1e-9)


def test_a_kept_union_is_handed_out_as_a_copy():
    # the grid integration is kept per process: a caller that changes its answer in place
    # must not change the next caller's, and other inputs (a density) are integrated afresh
    centres, radii = segment_centres(0.025, 0.011, 5), np.full(5, 0.0055)
    first = union_mass_properties(centres, radii, 912.0)
    com, inertia = first.centre_of_mass.copy(), first.inertia.copy()
    first.centre_of_mass[:] = 1.0
    first.inertia[:] = 1.0
    again = union_mass_properties(centres, radii, 912.0)
    np.testing.assert_array_equal(again.centre_of_mass, com)
    np.testing.assert_array_equal(again.inertia, inertia)
    assert union_mass_properties(centres, radii, 2 * 912.0).mass == pytest.approx(2 * first.mass, rel=1e-12)


def test_single_sphere_is_exact():
    tpl = make_template([[0.0, 0.0, 0.0]], 0.0055, 912.0)
    m = 912.0 * 4 / 3 * math.pi * 0.0055 ** 3
    assert tpl.mass == pytest.approx(m, rel=1e-14)
    np.testing.assert_allclose(tpl.principal_moments, 0.4 * m * 0.0055 ** 2, rtol=1e-14)


def test_cylinder_and_scaled_mass_models():
    cyl = segment_template(0.025, 0.011, 5, 912.0, mass_model="cylinder")
    m = 912.0 * math.pi * 0.0055 ** 2 * 0.025
    assert cyl.mass == pytest.approx(m, rel=1e-14)
    np.testing.assert_allclose(cyl.principal_moments,
                               [m * 0.0055 ** 2 / 2, m * (3 * 0.0055 ** 2 + 0.025 ** 2) / 12,
                                m * (3 * 0.0055 ** 2 + 0.025 ** 2) / 12], rtol=1e-14)
    union = segment_template(0.025, 0.011, 5, 912.0)
    scaled = segment_template(0.025, 0.011, 5, 912.0, mass_model="scaled", mean_mass=2.2e-3)
    assert scaled.mass == pytest.approx(2.2e-3, rel=1e-14)
    np.testing.assert_allclose(scaled.principal_moments, union.principal_moments * 2.2e-3 / union.mass,
                               rtol=1e-12)
    assert union.mass < cyl.mass  # the union misses the cylinder's rims


def test_bad_templates_are_refused():
    with pytest.raises(InputError, match="mean_mass"):
        segment_template(0.025, 0.011, 5, 912.0, mass_model="scaled")
    with pytest.raises(InputError, match="valid: union, body, cylinder, scaled"):
        segment_template(0.025, 0.011, 5, 912.0, mass_model="voxel")
    with pytest.raises(InputError, match="exceeds its length"):
        segment_template(0.010, 0.011, 5, 912.0)
