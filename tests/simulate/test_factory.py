"""Particle factory: seeded, on schedule, inside its region, never overlapping."""

from __future__ import annotations

import numpy as np
import pytest

from demcal.errors import InputError
from demcal.simulate import DEMParameters, ParticleFactory
from demcal.simulate.walls import box_rectangles
from tests.simulate.helpers import floor, simulation

LO, HI = np.array([0.01, 0.01, 0.10]), np.array([0.19, 0.09, 0.24])


def _sim(n, seed, start=0.0, end=1.0, gravity=(0.0, 0.0, -9.81)):
    sim = simulation(DEMParameters(), dt=7.43678e-5, gravity=gravity, lo=(-0.05, -0.05, -0.02),
                     hi=(0.25, 0.15, 0.3))
    tpl = sim.add_template(DEMParameters().template())
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
    # the draws rejected for want of room depend on where the clumps before fell: 89 to 128 over
    # 13 pours from other draws (as another machine's last bits would pour them); the bound
    # catches a factory that rejects half as often again as any of them did
    assert factory.inserted == 100 and factory.failed_attempts < 200


def test_full_region_does_not_hang():
    sim = simulation(DEMParameters(), dt=7.43678e-5)
    tpl = sim.add_template(DEMParameters().template())
    factory = ParticleFactory(tpl, 10, (0.0, 0.0, 0.0), (0.03, 0.03, 0.03), seed=0, end_time=0.0,
                              max_attempts=500)
    sim.add_factory(factory)
    sim.run(n_steps=10)
    assert 1 <= factory.inserted < 10
    assert factory.failed_attempts > 0


@pytest.mark.parametrize("crowded", [False, True])
def test_the_generator_is_left_just_after_the_last_draw_used(crowded):
    # one template: a placed clump used its rejected draws and its own, a clump that found no
    # room max_attempts draws, six numbers each; draws made ahead are given back, none used twice
    if crowded:
        sim = simulation(DEMParameters(), dt=7.43678e-5)
        factory = ParticleFactory(sim.add_template(DEMParameters().template()), 10, (0.0, 0.0, 0.0),
                                  (0.03, 0.03, 0.03), seed=4, end_time=0.0, max_attempts=300)
        sim.add_factory(factory)
        sim.run(n_steps=3)
        assert 1 <= factory.inserted < 10 and factory.failed_attempts > 300
    else:
        sim, factory = _sim(60, seed=4, start=0.0, end=0.05)
        sim.run(duration=0.06)
        assert factory.inserted == 60 and factory.failed_attempts > 0
    ref = np.random.default_rng(4)
    ref.random((factory.failed_attempts + factory.inserted, 6))
    assert factory.rng.random() == ref.random()


def test_bad_factory_arguments():
    with pytest.raises(InputError, match="seed"):
        ParticleFactory(0, 5, LO, HI, seed=1.5)
    with pytest.raises(InputError, match="region_hi"):
        ParticleFactory(0, 5, HI, LO, seed=1)


# ---------------------------------------------------------------- several templates (sizes)
# A calliper size distribution: (length, diameter) pairs [m], some measured twice. Reference:
# the factory resamples the measured pairs, so the drawn sizes are a sample of the pairs'
# empirical distribution (mean and sd, weighted by the pair counts).
SIZES = ((0.021, 0.0095), (0.023, 0.0100), (0.025, 0.0110), (0.025, 0.0110), (0.027, 0.0115),
         (0.029, 0.0120), (0.029, 0.0120), (0.029, 0.0120), (0.031, 0.0125))


def _sized_sim(n, seed, sizes=SIZES, dt=7.43678e-5, half=0.25):
    from collections import Counter

    from demcal.simulate.extensions import particle_of_size

    params = DEMParameters()
    sim = simulation(params, dt=dt, lo=(-0.3, -0.3, -0.3), hi=(0.3, 0.3, 0.3))
    counts = Counter(sizes)
    ids = [sim.add_template(particle_of_size(params, size)) for size in counts]
    factory = ParticleFactory(ids, n, (-half, -half, -half), (half, half, half), seed=seed,
                              end_time=0.0, weights=list(counts.values()))
    sim.add_factory(factory)
    return sim, factory, list(counts)


def test_several_templates_follow_the_size_distribution():
    n = 400
    sim, factory, pairs = _sized_sim(n, seed=11)
    sim.run(n_steps=0)
    assert factory.inserted == n
    drawn = np.array([pairs[factory.templates.index(k)] for k in factory.body_templates])
    ref = np.array(SIZES)
    for col in (0, 1):
        mu, sd = ref[:, col].mean(), ref[:, col].std()
        # the sample mean within 4 standard errors, the sample sd within 15 % (n = 400)
        assert abs(drawn[:, col].mean() - mu) < 4 * sd / np.sqrt(n)
        assert drawn[:, col].std() == pytest.approx(sd, rel=0.15)
    # each pair's share against its weight (binomial, 4 sigma)
    counts = np.array([np.sum(np.asarray(factory.body_templates) == k) for k in factory.templates])
    p = factory.probabilities
    assert np.all(np.abs(counts - n * p) < 4 * np.sqrt(n * p * (1 - p)))
    # every body is its template: mass, and spheres of radius D/2
    masses = sim.masses()
    radii, body = sim.sphere_radii(), sim.sphere_body()
    for b, k in zip(factory.bodies, factory.body_templates):
        tpl = sim.templates[k]
        assert masses[b] == tpl.mass
        np.testing.assert_array_equal(radii[body == b], tpl.radii)
        assert tpl.radii[0] == pytest.approx(pairs[factory.templates.index(k)][1] / 2, rel=1e-12)
    # no overlaps between bodies of different sizes
    x = sim.sphere_positions()
    d = np.linalg.norm(x[:, None] - x[None], axis=2)
    other = body[:, None] != body[None]
    assert np.all(d[other] >= (radii[:, None] + radii[None])[other])


def test_several_templates_same_seed_same_draws():
    a, fa, _ = _sized_sim(60, seed=3)
    b, fb, _ = _sized_sim(60, seed=3)
    c, fc, _ = _sized_sim(60, seed=4)
    for s in (a, b, c):
        s.run(n_steps=0)
    assert fa.body_templates == fb.body_templates != fc.body_templates
    np.testing.assert_array_equal(a.positions(), b.positions())
    np.testing.assert_array_equal(a.orientations(), b.orientations())


def test_single_template_in_a_list_is_the_single_template_factory():
    # one template, however given, draws no template: the same clumps for the same seed
    runs = []
    for template, weights in ((0, None), ([0], None), ((0,), [2.0])):
        sim = simulation(DEMParameters(), dt=7.43678e-5, lo=(-0.05, -0.05, -0.02), hi=(0.25, 0.15, 0.3))
        sim.add_template(DEMParameters().template())
        sim.add_factory(ParticleFactory(template, 50, LO, HI, seed=8, end_time=0.0, weights=weights))
        sim.run(n_steps=0)
        runs.append((sim.positions(), sim.orientations()))
    for pos, quat in runs[1:]:
        np.testing.assert_array_equal(pos, runs[0][0])
        np.testing.assert_array_equal(quat, runs[0][1])


def test_time_step_check_uses_the_smallest_sphere_of_all_templates():
    from demcal.errors import UnsafeTimeStepError
    from demcal.simulate import rayleigh_time

    t_small = rayleigh_time(0.0095 / 2, 912.0, 1e7, 0.25)
    t_large = rayleigh_time(0.0125 / 2, 912.0, 1e7, 0.25)
    sim, _, _ = _sized_sim(10, seed=1)
    assert sim.rayleigh_time() == pytest.approx(t_small, rel=1e-12)     # before any insertion
    # a step safe for the largest segment but not for the smallest is refused up front
    dt = 0.55 * t_small
    assert dt < 0.5 * t_large
    sim, factory, _ = _sized_sim(10, seed=1, dt=dt)
    with pytest.raises(UnsafeTimeStepError):
        sim.run(n_steps=1)
    assert factory.inserted == 0


def test_bad_template_weights_are_named():
    with pytest.raises(InputError, match="weights must be 2 finite numbers"):
        ParticleFactory([0, 1], 5, LO, HI, seed=1, weights=[1.0])
    with pytest.raises(InputError, match="weights must be 2 finite numbers"):
        ParticleFactory([0, 1], 5, LO, HI, seed=1, weights=[0.0, 0.0])
    with pytest.raises(InputError, match="template must be a template id"):
        ParticleFactory([], 5, LO, HI, seed=1)


@pytest.mark.parametrize("draws_at_once", [1, 5, 64])
def test_clumps_do_not_depend_on_how_many_draws_are_tested_at_once(monkeypatch, draws_at_once):
    # a crowded region (many draws rejected) and two templates: the clumps, the rejected
    # draws and the generator left behind are those of one draw at a time
    import demcal.simulate.factory as factory_module

    def placed(n_draws):
        monkeypatch.setattr(factory_module, "DRAWS_AT_ONCE", n_draws)
        sim, factory, _ = _sized_sim(150, seed=5, half=0.05)
        sim.run(n_steps=0)
        return sim, factory

    ref, f_ref = placed(1)
    sim, factory = placed(draws_at_once)
    assert f_ref.failed_attempts > f_ref.inserted          # crowded: most draws rejected
    assert factory.failed_attempts == f_ref.failed_attempts
    assert factory.body_templates == f_ref.body_templates
    np.testing.assert_array_equal(sim.positions(), ref.positions())
    np.testing.assert_array_equal(sim.orientations(), ref.orientations())
    assert factory.rng.random() == f_ref.rng.random()


def test_batched_rotation_matrices_are_those_of_one_quaternion_at_a_time():
    from demcal.simulate.integrate import (matrices_from_quats, matrix_from_quat, quaternions_from_uniforms,
                                           random_quaternions)
    rng = np.random.default_rng(2)
    q = random_quaternions(rng, 500) * rng.uniform(0.5, 2.0, (500, 1))     # not normalised
    batched = matrices_from_quats(q)
    for k in range(len(q)):
        np.testing.assert_array_equal(batched[k], matrix_from_quat(q[k]))
    # Shoemake's map from uniforms: a row at a time as a block, and unit quaternions
    u = rng.random((200, 3))
    block = quaternions_from_uniforms(u)
    np.testing.assert_array_equal(block, np.concatenate([quaternions_from_uniforms(row[None]) for row in u]))
    np.testing.assert_allclose(np.linalg.norm(block, axis=1), 1.0, rtol=1e-14)
