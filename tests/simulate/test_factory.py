"""Particle factory: seeded, on schedule, inside its region, never overlapping."""

from __future__ import annotations

import numpy as np
import pytest

from demcal.errors import InputError
from simulate import DEMParameters, ParticleFactory
from simulate.clump import segment_from_parameters
from simulate.walls import box_rectangles
from tests.simulate.helpers import floor, simulation

LO, HI = np.array([0.01, 0.01, 0.10]), np.array([0.19, 0.09, 0.24])


def _sim(n, seed, start=0.0, end=1.0, gravity=(0.0, 0.0, -9.81)):
    sim = simulation(DEMParameters(), dt=7.43678e-5, gravity=gravity, lo=(-0.05, -0.05, -0.02),
                     hi=(0.25, 0.15, 0.3))
    tpl = sim.add_template(segment_from_parameters(DEMParameters()))
    floor(sim)
    sim.add_walls(box_rectangles((0.0, 0.0, 0.0), (0.2, 0.1, 0.25), faces=("x-", "x+", "y-", "y+")))
    factory = ParticleFactory(tpl, n, LO, HI, seed=seed, start_time=start, end_time=end)
    sim.add_factory(factory)
    return sim, factory


def test_all_at_once_inside_region_without_overlap():
    sim, factory = _sim(120, seed=4, start=0.0, end=0.0)
    sim.run(n_steps=0)
    assert factory.inserted == 120 == sim.n_bodies
    x, r, body = sim.sphere_positions(), sim.sphere_radii(), sim.sphere_body()
    assert np.all(x - r[:, None] >= LO - 1e-12) and np.all(x + r[:, None] <= HI + 1e-12)
    d = np.linalg.norm(x[:, None] - x[None], axis=2)
    other = body[:, None] != body[None]
    assert np.all(d[other] >= (r[:, None] + r[None])[other])
    # random orientations: the segment axes point every way
    axes = sim.rotation_matrices()[:, :, 0]
    assert np.abs(axes.mean(axis=0)).max() < 0.2


def test_same_seed_same_particles_other_seed_differs():
    a, _ = _sim(30, seed=9, end=0.0)
    b, _ = _sim(30, seed=9, end=0.0)
    c, _ = _sim(30, seed=10, end=0.0)
    for s in (a, b, c):
        s.run(n_steps=0)
    np.testing.assert_array_equal(a.positions(), b.positions())
    np.testing.assert_array_equal(a.orientations(), b.orientations())
    assert not np.allclose(a.positions(), c.positions())


def test_insertion_follows_the_rate():
    sim, factory = _sim(100, seed=1, start=0.0, end=1.0)
    for duration in (0.25, 0.25, 0.3, 0.3):
        sim.run(duration=duration)
        # clump k is due at (k + 1) / 100 s and enters at the first step boundary after it
        assert factory.inserted == min(100, int(100 * sim.time + 1e-9))
    assert factory.inserted == 100 and factory.failed_attempts < 100


def test_full_region_does_not_hang():
    sim = simulation(DEMParameters(), dt=7.43678e-5)
    tpl = sim.add_template(segment_from_parameters(DEMParameters()))
    factory = ParticleFactory(tpl, 10, (0.0, 0.0, 0.0), (0.03, 0.03, 0.03), seed=0, end_time=0.0,
                              max_attempts=500)
    sim.add_factory(factory)
    sim.run(n_steps=10)
    assert 1 <= factory.inserted < 10
    assert factory.failed_attempts > 0


def test_bad_factory_arguments():
    with pytest.raises(InputError, match="seed"):
        ParticleFactory(0, 5, LO, HI, seed=1.5)
    with pytest.raises(InputError, match="region_hi"):
        ParticleFactory(0, 5, HI, LO, seed=1)
