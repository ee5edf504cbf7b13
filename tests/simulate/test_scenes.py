"""The paper's repose case (plate withdrawal): a quick, scaled-down run by default and the
full 10 s paper case as an opt-in validation run."""

from __future__ import annotations

import numpy as np
import pytest

from demcal.simulate import DEMParameters
from demcal.simulate.scenes import PAPER_DURATION, build_paper_repose_case

#: The LIGGGHTS benchmark's parameters (the paper's calibrated values, cylinder mass model).
BENCHMARK = dict(e_pp=0.32, e_pw=0.36, mu_s_pw=0.22, mass_model="cylinder")


def _check_heap(sim, n_clumps, ke_trace, length=0.2, width=0.1, top=0.1):
    x = sim.positions()
    assert sim.n_bodies == n_clumps
    assert not sim.escaped
    in_carton = (x[:, 0] > 0) & (x[:, 0] < length) & (x[:, 1] > 0) & (x[:, 1] < width)
    assert (~in_carton).sum() >= 1                         # segments flowed under the plate
    # none went through a carton wall: every segment outside came out by the opening, so its
    # centre is at most half a segment (12.5 mm) back from the plate's plane
    assert np.all(x[~in_carton, 0] > length - 0.0125)
    assert np.all(x[:, 2] > 0) and np.all(x[:, 2] < top)   # resting on the floor or the pile
    times, ke = np.array(ke_trace).T
    assert ke[-1] < 1e-3 * ke.max()                       # the heap has come to rest


def test_scaled_down_repose_case_forms_a_heap():
    params = DEMParameters().with_(**BENCHMARK)
    # a small, narrow carton so that 60 segments pile up high enough to flow out
    sim = build_paper_repose_case(params, seed=3, n_clumps=60, box_length=0.08, box_width=0.05,
                                  fill_time=0.3, lift_time=0.6, lift_speed=0.5, fill_bottom=0.02,
                                  fill_top=0.2)
    assert [w.name for w in sim.walls] == ["floor", "carton x-", "carton y-", "carton y+", "end plate"]
    trace = []
    sim.run(duration=2.0, progress=lambda s: trace.append((s.time, s.kinetic_energy())))
    _check_heap(sim, 60, trace, length=0.08, width=0.05)
    plate = sim.wall_origins()[sim.wall_index("end plate")]
    assert plate[2] == pytest.approx(0.125 + 0.5 * (sim.time - 0.6), abs=0.5 * 0.5 * sim.dt)


@pytest.mark.validation
def test_paper_repose_case_full_run_liggghts_convention():
    # docs/design.md (LIGGGHTS, 5 seeds): with these frictions only about 10 % of the segments
    # leave the 200 x 100 mm carton; the same rolling convention should give the same picture
    params = DEMParameters().with_(rolling_lever="liggghts_reff", **BENCHMARK)
    sim = build_paper_repose_case(params, seed=1)
    trace = []
    sim.run(duration=PAPER_DURATION, progress=lambda s: trace.append((s.time, s.kinetic_energy())))
    _check_heap(sim, 500, trace, top=0.15)
    x = sim.positions()
    outside = ~((x[:, 0] < 0.2) & (x[:, 1] > 0) & (x[:, 1] < 0.1))
    assert 0.03 <= outside.mean() <= 0.2
    assert sim.wall_origins()[sim.wall_index("end plate")][2] > 0.6  # lifted 0.6 m from 4 s


def test_repose_case_draws_segments_from_a_size_distribution():
    from demcal.simulate.extensions import SizeDistribution, particle_of_size

    dist = SizeDistribution(((0.022, 0.010), (0.025, 0.011), (0.025, 0.011), (0.028, 0.012)))
    params = DEMParameters().with_(**BENCHMARK)
    small = dict(n_clumps=60, box_length=0.08, box_width=0.05, fill_time=0.0, fill_bottom=0.02, fill_top=0.2)
    sim = build_paper_repose_case(params, seed=5, size_distribution=dist, **small)
    # one template per distinct pair, weighted by its count
    assert len(sim.templates) == 3
    factory = sim.factories[0]
    np.testing.assert_allclose(factory.probabilities, [0.25, 0.5, 0.25])
    for tpl, (length, dia) in zip(sim.templates, ((0.022, 0.010), (0.025, 0.011), (0.028, 0.012))):
        ref = particle_of_size(params, (length, dia))
        assert tpl.mass == ref.mass and np.array_equal(tpl.radii, ref.radii)
    sim.run(n_steps=0)
    assert set(factory.body_templates) == {0, 1, 2}
    # the same distribution given as parameters (what a run record holds) builds the same heap
    again = build_paper_repose_case(params.with_(particle_sizes=dist.sizes),
                                    seed=5, **small)
    again.run(n_steps=0)
    np.testing.assert_array_equal(again.positions(), sim.positions())
    # and without one, a single template as before
    assert len(build_paper_repose_case(params, seed=5, **small).templates) == 1
