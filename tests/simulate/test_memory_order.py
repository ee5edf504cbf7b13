"""Sorting the state in memory along a Morton curve: a pure renumbering. The reference is the
same simulation never sorted; ids, readers, forces, contact history and the motion after it
must all agree."""

from __future__ import annotations

import numpy as np
import pytest

from demcal.simulate import DEMParameters
from demcal.simulate.clump import segment_template
from demcal.simulate.factory import ParticleFactory
from demcal.simulate.neighbours import morton_keys
from demcal.simulate.walls import box_rectangles
from tests.simulate.helpers import simulation


def test_morton_keys_interleave_the_cell_bits():
    """Key of cell (i, j, k): bit b of i, j, k at bits 3b, 3b+1, 3b+2 (worked by hand)."""
    cells = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1], [2, 0, 0], [3, 5, 6]])
    points = (cells + 0.5) * 0.01 + np.array([-0.1, 0.0, 0.2])
    keys = morton_keys(points, (-0.1, 0.0, 0.2), 0.01)
    # (3, 5, 6): x = 011, y = 101, z = 110 -> bits (z y x) per level, highest first: 110 101 011
    assert keys.tolist() == [0, 1, 2, 4, 7, 8, 0b110101011]
    assert morton_keys(np.array([[-5.0, -5.0, -5.0]]), (0, 0, 0), 0.01).tolist() == [0]


def _pour(n_clumps, heights, seed, fill_time, duration, params=None, **options):
    """``n_clumps`` segments poured at random into a box from ``heights`` [m] over ``fill_time``,
    run for ``duration`` [s] (``options``: the Simulation's): their order of addition is not their
    order in space."""
    sim = simulation(params or DEMParameters(), dt=5e-5, gravity=(0.0, 0.0, -9.81), lo=(-0.1, -0.1, -0.02),
                     hi=(0.1, 0.1, 0.3), **options)
    tpl = sim.add_template(segment_template(0.025, 0.011, 5, 912.0))
    sim.add_walls(box_rectangles((-0.05, -0.03, 0.0), (0.05, 0.03, 0.25), faces=("x-", "x+", "y-", "y+", "z-")))
    sim.add_factory(ParticleFactory(tpl, n_clumps, (-0.045, -0.025, heights[0]), (0.045, 0.025, heights[1]),
                                    seed=seed, start_time=0.0, end_time=fill_time))
    sim.run(duration=duration)
    return sim


def _poured_bed(**hooks):
    """A bed of 60 segments, never sorted, with the model hooks ``hooks``."""
    return _pour(60, (0.08, 0.24), 7, 0.1, 0.3, DEMParameters().with_(**hooks), sort_every=0)


@pytest.mark.parametrize("hooks", [{}, {"rolling_model": "epsd", "e_pp_exponent": 0.2, "e_pw_exponent": 0.2}])
def test_sorting_renumbers_without_changing_anything(hooks):
    sorted_, plain = _poured_bed(**hooks), _poured_bed(**hooks)
    assert sorted_.n_contacts()[0] > 30              # a bed, with history in its contacts
    sorted_.sort_in_memory()
    rows = sorted_._body_row[:sorted_.n_bodies]
    assert not np.array_equal(rows, np.arange(sorted_.n_bodies))   # it did move the rows
    for sim in (sorted_, plain):
        sim.evaluate_forces()
    for reader in ("positions", "velocities", "orientations", "angular_velocities", "sphere_positions",
                   "sphere_body", "active", "masses"):
        np.testing.assert_array_equal(getattr(sorted_, reader)(), getattr(plain, reader)(), err_msg=reader)
    for a, b in zip(sorted_.contact_forces(), plain.contact_forces()):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12)

    def by_pair(history):
        p = history["pairs"]
        return {(i, j): np.r_[t, r] for i, j, t, r in zip(p["i"], p["j"], p["tangential"], p["rolling_torque"])}

    got, want = by_pair(sorted_.contact_history()), by_pair(plain.contact_history())
    assert got.keys() == want.keys()
    assert any(np.any(v != 0.0) for v in want.values())
    for key in want:
        np.testing.assert_allclose(got[key], want[key], rtol=1e-12, atol=1e-18)
    # and the motion goes on the same (up to the order of summation)
    for sim in (sorted_, plain):
        sim.run(n_steps=400)
    np.testing.assert_allclose(sorted_.positions(), plain.positions(), rtol=0, atol=1e-9)
    np.testing.assert_allclose(sorted_.velocities(), plain.velocities(), rtol=0, atol=1e-6)


def test_a_bed_sorted_every_few_steps_settles_like_one_never_sorted():
    """Sorted every 25 steps from the first particle on, against never: the same heap up to the
    divergence of roundoff, which a short pour keeps small."""
    runs = [_pour(30, (0.05, 0.1), 3, 0.02, 0.08, sort_every=every, sort_min_spheres=0, chunk_steps=25)
            for every in (0, 25)]
    assert runs[0].total_sorts == 0 and runs[1].total_sorts >= 60
    np.testing.assert_allclose(runs[1].positions(), runs[0].positions(), rtol=0, atol=1e-7)


@pytest.mark.parametrize("threads", [None, 2])
def test_asking_for_the_second_spheres_ahead_changes_no_bit(threads):
    """The contact loop's prefetch hints (``prefetch_min_spheres``, on here for every size) only
    move data: the pour, on the plain loop and on the ranged one, is the same to the bit as
    without them."""
    runs = [_pour(40, (0.02, 0.12), 5, 0.05, 0.2, sort_every=0, prefetch_min_spheres=prefetch_from, threads=threads)
            for prefetch_from in (10**9, 0)]
    # a bed, its contacts in the loop: 8 to 33 sphere contacts at the end over 13 pours of these
    # segments from other draws (as another machine's last bits would pour them)
    assert runs[1].n_contacts()[0] >= 3
    for reader in ("positions", "velocities", "angular_velocities"):
        np.testing.assert_array_equal(getattr(runs[1], reader)(), getattr(runs[0], reader)(), err_msg=reader)
