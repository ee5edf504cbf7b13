"""One run on several threads (``simulate.forces.contact_forces_ranged``): the forces of the
plain loop (no race: every contact counted once, on the right bodies), the same run on one
thread and on two, the same heap as the plain loop in distribution over seeds; and the choice
of thread count (``simulate.threads``)."""

from __future__ import annotations

import numba
import numpy as np
import pytest

from demcal.errors import InputError
from demcal.simulate import DEMParameters
from demcal.simulate.clump import segment_template
from demcal.simulate.factory import ParticleFactory
from demcal.simulate.threads import THREADS_MIN_SPHERES, threads_limited_to, threads_per_run
from demcal.simulate.walls import box_rectangles
from tests.simulate.helpers import simulation


def _pour(seed, threads, n=40, duration=0.3, **hooks):
    sim = simulation(DEMParameters().with_(**hooks), dt=5e-5, gravity=(0.0, 0.0, -9.81), lo=(-0.1, -0.1, -0.02),
                     hi=(0.1, 0.1, 0.3), threads=threads)
    tpl = sim.add_template(segment_template(0.025, 0.011, 5, 912.0))
    sim.add_walls(box_rectangles((-0.05, -0.03, 0.0), (0.05, 0.03, 0.25), faces=("x-", "x+", "y-", "y+", "z-")))
    sim.add_factory(ParticleFactory(tpl, n, (-0.045, -0.025, 0.05), (0.045, 0.025, 0.2), seed=seed,
                                    start_time=0.0, end_time=0.1))
    sim.run(duration=duration)
    return sim


@pytest.mark.parametrize("hooks", [{}, {"rolling_model": "epsd", "contact_effective_mass": True,
                                        "e_pw_exponent": 0.2}, {"rolling_lever": "edem_com"}])
def test_the_ranged_forces_are_those_of_the_plain_loop(hooks):
    """The contacts split into ranges on threads, against the one loop: every contact counted
    once, on the right bodies (a race or a lost share would show as a wrong force)."""
    plain = _pour(5, None, n=60, **hooks)
    ranged = _pour(5, None, n=60, **hooks)
    assert plain.n_contacts()[0] > 30 and plain.threads_in_use() == 1
    ranged.threads = 2
    for sim in (plain, ranged):
        sim.evaluate_forces()
    for x, y in zip(plain.contact_forces() + plain.rolling_resistance(),
                    ranged.contact_forces() + ranged.rolling_resistance()):
        np.testing.assert_allclose(y, x, rtol=1e-9, atol=1e-12)
    # and the motion: the same to roundoff over a few hundred steps
    for sim in (plain, ranged):
        sim.run(n_steps=400)
    np.testing.assert_allclose(ranged.positions(), plain.positions(), rtol=0, atol=1e-9)
    np.testing.assert_allclose(ranged.angular_velocities(), plain.angular_velocities(), rtol=0, atol=1e-4)


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="needs two cores")
def test_a_run_is_the_same_on_one_thread_and_on_two():
    one, two = _pour(11, 1), _pour(11, 2)
    assert one.threads_in_use() == 1 and two.threads_in_use() == 2
    np.testing.assert_array_equal(two.positions(), one.positions())
    np.testing.assert_array_equal(two.angular_momenta(), one.angular_momenta())


def test_the_ranged_loop_gives_the_heap_of_the_plain_one_over_seeds():
    """Beyond roundoff the runs part like any two DEM runs; over 8 seeds each, the mean height
    of the bed and its number of contacts agree within three standard errors."""
    heights = {None: [], 2: []}
    contacts = {None: [], 2: []}
    for threads in (None, 2):
        for seed in range(8):
            sim = _pour(100 + seed, threads)
            heights[threads].append(sim.positions()[:, 2].mean())
            contacts[threads].append(sum(sim.n_contacts()))
    # the runs did part (the mean heights; the contact counts, whole numbers, can all agree when
    # the runs part late, as in one of two pours from other draws)
    assert np.any(np.array(heights[None]) != np.array(heights[2]))
    for obs in (heights, contacts):
        one, two = np.array(obs[None], float), np.array(obs[2], float)
        se = np.sqrt(one.var(ddof=1) / one.size + two.var(ddof=1) / two.size)
        assert abs(one.mean() - two.mean()) < 3 * se


def test_thread_count_follows_size_and_limits(monkeypatch):
    monkeypatch.delenv("DEMCAL_THREADS", raising=False)
    sim = simulation(DEMParameters())
    assert sim.n_spheres < THREADS_MIN_SPHERES and sim.threads_in_use() == 1
    sim.n_spheres = THREADS_MIN_SPHERES          # as if it held that many
    assert sim.threads_in_use() == threads_per_run()
    with threads_limited_to(1):
        assert sim.threads_in_use() == 1
    monkeypatch.setenv("DEMCAL_THREADS", "1")
    assert sim.threads_in_use() == 1
    monkeypatch.setenv("DEMCAL_THREADS", "two")
    with pytest.raises(InputError, match="DEMCAL_THREADS"):
        threads_per_run()
    with pytest.raises(InputError, match="threads"):
        simulation(DEMParameters(), threads=0)
