"""Particle shapes (simulate.shapes) against closed forms: the sphere's and the ellipsoid's
volume and inertia, the largest sphere inside a spheroid about a point of its axis, the
cylinder of a segment; and the refusals a workbook's readings can meet."""

from __future__ import annotations

import math

import numpy as np
import pytest

from demcal.errors import InputError
from demcal.simulate.clump import segment_template
from demcal.simulate.shapes import SHAPES, shape_class, shape_from_dict
from demcal.simulate.shapes.clump import ClumpTable, table_from_rows
from demcal.simulate.shapes.kernel import Kernel, _inscribed_radius
from demcal.simulate.shapes.segment import Segment
from demcal.simulate.shapes.sphere import Sphere

RHO = 1200.0


def test_a_sphere_is_one_sphere_with_the_mass_and_inertia_of_a_solid_ball():
    s = Sphere(0.0066)
    t = s.template(RHO)
    m = RHO * math.pi * 0.0066 ** 3 / 6.0
    assert t.n_spheres == 1 and t.radii[0] == pytest.approx(0.0033)
    assert t.mass == pytest.approx(m, rel=1e-12)
    assert t.principal_moments == pytest.approx([0.4 * m * 0.0033 ** 2] * 3, rel=1e-12)
    assert s.volume() == pytest.approx(m / RHO, rel=1e-12)
    assert s.outline_m == pytest.approx((0.0066, 0.0066), rel=1e-12)   # a photo shows a disc


def test_a_sphere_from_three_axes_takes_their_geometric_mean():
    s = Sphere.from_specimen({"length_mm": 7.3, "width_mm": 6.6, "thickness_mm": 5.6})
    assert s.diameter_m == pytest.approx((7.3 * 6.6 * 5.6) ** (1 / 3) * 1e-3, rel=1e-12)
    assert Sphere.from_specimen({"diameter_mm": 6.0}).diameter_m == pytest.approx(0.006)
    assert Sphere.columns_of(["specimen_id", "length_mm", "width_mm", "thickness_mm"]) == \
        ("length_mm", "width_mm", "thickness_mm")


def test_the_segment_shape_is_the_papers_row_of_spheres_and_its_body_a_cylinder():
    seg = Segment(0.025, 0.011, 5)
    a, b = seg.template(912.0), segment_template(0.025, 0.011, 5, 912.0)
    assert a.mass == b.mass and np.array_equal(a.principal_moments, b.principal_moments)
    assert np.array_equal(a.offsets, b.offsets)
    assert seg.volume() == pytest.approx(math.pi * 0.011 ** 2 * 0.025 / 4, rel=1e-12)
    body = seg.template(912.0, "body")
    assert body.mass == pytest.approx(912.0 * seg.volume(), rel=1e-12)
    assert seg.template(912.0, "cylinder").mass == body.mass
    assert seg.outline_m == pytest.approx((0.025, 0.011), rel=1e-12)


def test_the_largest_sphere_inside_a_spheroid_about_a_point_of_its_axis():
    """Prolate spheroid (a, b, b): about (x0, 0, 0) the inscribed radius is
    b sqrt(1 - x0^2 / (a^2 - b^2)) for |x0| <= a - b^2/a (the normal from the axis)."""
    a, b = 3.6e-3, 1.5e-3
    for x0 in (0.0, 1.0e-3, 2.0e-3, a - b * b / a):
        expected = b * math.sqrt(1.0 - x0 ** 2 / (a * a - b * b))
        assert _inscribed_radius(np.array([a, b, b]), np.array([x0, 0.0, 0.0])) == pytest.approx(expected, rel=1e-6)


@pytest.mark.parametrize("dims", [(7.2e-3, 3.0e-3, 2.1e-3), (12e-3, 8e-3, 4.5e-3), (7.2e-3, 3.0e-3, 3.0e-3)])
def test_a_kernels_spheres_lie_inside_its_ellipsoid_and_touch_it(dims):
    k = Kernel(*dims)
    centres, radii = k.spheres()
    semi = k.semi_axes
    rng = np.random.default_rng(1)
    u = rng.normal(size=(2000, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    for c, r in zip(centres, radii):
        q = (((c + r * u) / semi) ** 2).sum(axis=1)        # <= 1 inside the ellipsoid
        assert q.max() <= 1.0 + 1e-5 and q.max() >= 0.995
    # the model spans the measured length, and its extent never exceeds the axes
    assert k.extent[0] == pytest.approx(dims[0], rel=1e-6)
    assert np.all(k.extent <= np.array(dims) * (1 + 1e-6))
    # a photo shows it its length long and about the mean of its other axes wide
    length, width = k.outline_m
    assert length == pytest.approx(dims[0], rel=1e-6)
    assert min(dims[1:]) * 0.95 <= width <= math.sqrt(dims[1] * dims[2]) * (1 + 1e-6)


def test_a_kernels_body_is_the_exact_ellipsoid_and_the_approximation_is_reported():
    k = Kernel(7.2e-3, 3.0e-3, 2.1e-3)
    a, b, c = 3.6e-3, 1.5e-3, 1.05e-3
    m = RHO * 4 / 3 * math.pi * a * b * c
    t = k.template(RHO, "body")
    assert t.mass == pytest.approx(m, rel=1e-12)
    assert sorted(t.principal_moments) == pytest.approx(sorted([m * (b * b + c * c) / 5, m * (a * a + c * c) / 5,
                                                                m * (a * a + b * b) / 5]), rel=1e-12)
    ratio = k.approximation()
    union = k.template(RHO)
    assert ratio["volume_ratio"] == pytest.approx(union.mass / m, rel=1e-3)
    assert 0.8 < ratio["volume_ratio"] < 1.0                   # inscribed spheres: smaller than the body
    rows = dict((q, v) for q, v, _ in k.rows())
    assert rows["sphere model / ellipsoid volume"] == ratio["volume_ratio"]


def test_a_kernel_of_two_spheres_is_refused_naming_the_option():
    """The middle row runs tip to tip, so two spheres would be its tip spheres only: a
    dumbbell holding a small part of the kernel (computed here, against three spheres)."""
    from demcal.simulate.shapes.kernel import _inscribed_spheres, union_mass_properties

    dims = (10.54e-3, 7.26e-3, 4.57e-3)     # a flat maize kernel
    with pytest.raises(InputError, match="n_spheres 2 .*spheres_per_particle"):
        Kernel(*dims, n_spheres=2)
    semi = tuple(np.array(dims) / 2)
    ellipsoid = 4 / 3 * math.pi * np.prod(semi)
    two = union_mass_properties(*_inscribed_spheres(semi, 2), 1.0).mass / ellipsoid
    three = union_mass_properties(*_inscribed_spheres(semi, 3), 1.0).mass / ellipsoid
    assert two < 0.15 < 0.4 < three


def test_a_clump_table_is_centred_ordered_by_extent_and_scaled_to_the_specimen():
    # two touching spheres along z in the lab's frame, off-centre
    table = ((0.01, 0.0, 0.002, 0.002), (0.01, 0.0, 0.006, 0.002))
    shape = ClumpTable.from_specimen({"length_mm": 16.0}, table=table)
    centres, radii = shape.spheres()
    assert shape.scale == pytest.approx(2.0)
    assert centres.ravel().tolist() == pytest.approx([-0.004, 0, 0, 0.004, 0, 0])
    assert radii.tolist() == pytest.approx([0.004, 0.004])
    assert shape.volume() == pytest.approx(2 * 4 / 3 * math.pi * 0.004 ** 3, rel=1e-9)   # disjoint: exact


def test_bad_readings_are_refused_by_sheet_row_and_column():
    with pytest.raises(InputError, match=r"sheet clump, row 3, column radius_mm: needs a radius > 0"):
        table_from_rows([(2, {"x_mm": 0, "y_mm": 0, "z_mm": 0, "radius_mm": 1}),
                         (3, {"x_mm": 1, "y_mm": 0, "z_mm": 0, "radius_mm": -1})])
    with pytest.raises(InputError, match=r"column width_mm: width 5 mm exceeds the length 4 mm"):
        Kernel.from_specimen({"length_mm": 4, "width_mm": 5, "thickness_mm": 2})
    with pytest.raises(InputError, match=r"column diameter_mm: 8 mm exceeds the length_mm 7 mm"):
        Segment.from_specimen({"length_mm": 7, "diameter_mm": 8})
    with pytest.raises(InputError, match=r"missing width_mm, thickness_mm"):
        Kernel.columns_of(["specimen_id", "length_mm", "diameter_mm"])


def test_the_registry_names_the_valid_shapes_and_reads_back_what_it_stores():
    assert set(SHAPES) == {"segment", "sphere", "kernel", "clump"}
    with pytest.raises(InputError, match="unknown shape 'cube'; valid shapes: segment, sphere, kernel, clump"):
        shape_class("cube")
    for shape in (Segment(0.025, 0.011), Sphere(0.006), Kernel(0.007, 0.003, 0.002),
                  ClumpTable(0.01, ((0, 0, 0, 0.002), (0.003, 0, 0, 0.002)))):
        assert shape_from_dict(shape.to_dict()) == shape
    with pytest.raises(InputError, match="shape sphere: unknown field"):
        shape_from_dict({"shape": "sphere", "diameter_m": 0.006, "colour": "red"})
