"""The contact loops visit only the near pairs of the Verlet list
(``simulate.neighbours.select_near_pairs``). The references: a brute-force selection in numpy,
and the same simulation with every listed pair visited, which must give the same bits."""

from __future__ import annotations

import numpy as np
import pytest

from demcal.simulate import DEMParameters
from demcal.simulate.clump import segment_template
from demcal.simulate.factory import ParticleFactory
from demcal.simulate.neighbours import NEAR_ALLOWANCE, select_near_pairs
from demcal.simulate.walls import box_rectangles
from tests.simulate.helpers import simulation


def _poured_bed(threads=None, **hooks):
    """Segments poured into a box; the last of them still falling and bouncing."""
    params = DEMParameters().with_(**hooks)
    sim = simulation(params, dt=5e-5, gravity=(0.0, 0.0, -9.81), lo=(-0.1, -0.1, -0.02),
                     hi=(0.1, 0.1, 0.3), chunk_steps=100)
    sim.threads = threads
    tpl = sim.add_template(segment_template(0.025, 0.011, 5, 912.0))
    sim.add_walls(box_rectangles((-0.05, -0.03, 0.0), (0.05, 0.03, 0.25), faces=("x-", "x+", "y-", "y+", "z-")))
    sim.add_factory(ParticleFactory(tpl, 60, (-0.045, -0.025, 0.08), (0.045, 0.025, 0.24), seed=7,
                                    start_time=0.0, end_time=0.15))
    return sim


def test_the_near_pairs_are_those_under_the_margin_and_the_rest_may_not_touch():
    sim = _poured_bed()
    sim.run(duration=0.25)
    start, pi, pj, hist = (a.copy() for a in sim._pairs)
    n_spheres = sim.n_spheres
    sx, srad = sim._s["sx"][:n_spheres].copy(), sim._s["srad"][:n_spheres].copy()
    margin = 0.25 * sim.skin
    gap = np.linalg.norm(sx[pj] - sx[pi], axis=1) - srad[pi] - srad[pj]
    near = np.empty(len(pi), np.int64)
    near_start = np.empty(len(start), np.int64)
    sxn = np.empty_like(sx)
    allow = np.empty(n_spheres)
    n = select_near_pairs(n_spheres, start, pi, pj, hist, sx, srad, margin, near, near_start, sxn, allow)

    want = np.flatnonzero(gap < margin)
    assert 0 < len(want) < 0.8 * len(pi)        # a bed: some pairs near, most not
    np.testing.assert_array_equal(near[:n], want)
    # row pointers as the list's: the near pairs of sphere i are those of its row
    np.testing.assert_array_equal(near_start, np.searchsorted(want, start))
    # the rest are apart and their history is cleared, as a contact loop would clear it
    out = np.setdiff1d(np.arange(len(pi)), want)
    assert (gap[out] > 0).all()
    assert (hist[out] == 0).all()
    np.testing.assert_array_equal(hist[want], sim._pairs[3][want])
    # each sphere may move just under half the gap of its nearest pair left out
    expect = np.full(n_spheres, np.inf)
    np.minimum.at(expect, pi[out], NEAR_ALLOWANCE * gap[out])
    np.minimum.at(expect, pj[out], NEAR_ALLOWANCE * gap[out])
    np.testing.assert_allclose(allow, expect, rtol=1e-12)
    np.testing.assert_array_equal(sxn, sx)

    # an infinite margin takes every pair
    n = select_near_pairs(n_spheres, start, pi, pj, hist, sx, srad, np.inf, near, near_start, sxn, allow)
    assert n == len(pi)
    np.testing.assert_array_equal(near, np.arange(len(pi)))
    np.testing.assert_array_equal(near_start, start)
    assert np.isinf(allow).all()


@pytest.mark.parametrize("threads, hooks", [
    (None, {}),
    (None, {"rolling_model": "epsd", "e_pp_exponent": 0.2, "e_pw_exponent": 0.2, "contact_effective_mass": True}),
    (2, {}),
])
def test_visiting_the_near_pairs_gives_the_bits_of_visiting_every_pair(threads, hooks):
    """Each chunk starts with the smallest margin in one run and with every pair in the other
    (``_near_fraction``: the margin over the skin a call starts from); the pour, the bounces and
    the bed at rest must come out the same to the bit."""
    def margin_each_chunk(fraction):
        def set_it(sim):
            sim._near_fraction = fraction
        return set_it

    near, every = _poured_bed(threads, **hooks), _poured_bed(threads, **hooks)
    for sim, fraction in ((near, 1.0 / 16.0), (every, 1e9)):
        sim._near_fraction = fraction
        sim.run(duration=0.4, progress=margin_each_chunk(fraction))
    assert near.n_contacts()[0] > 30
    for reader in ("positions", "velocities", "orientations", "angular_velocities", "sphere_positions"):
        np.testing.assert_array_equal(getattr(near, reader)(), getattr(every, reader)(), err_msg=reader)
    for a, b in zip(near._pairs + near._wpairs, every._pairs + every._wpairs):
        np.testing.assert_array_equal(a, b)
