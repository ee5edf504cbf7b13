"""Neighbour lists: the cell-list Verlet build against brute force, and contact history kept
across rebuilds (a second run that never rebuilds is the reference)."""

from __future__ import annotations

import numba
import numpy as np
import pytest

from demcal.simulate import DEMParameters
from demcal.simulate.clump import segment_template
from demcal.simulate.neighbours import (JOIN_BLOCKS_MAX, build_pair_list, build_pair_list_serial, build_wall_list,
                                       grid_shape, padded_cell_count)
from demcal.simulate.walls import Plane, Rectangle, pack_walls, wall_distances
from tests.simulate.helpers import R, floor, simulation

POOL = numba.config.NUMBA_NUM_THREADS


@pytest.fixture(autouse=True)
def _restore_threads():
    """The tests below set numba's thread count; later tests in the worker see it restored."""
    before = numba.get_num_threads()
    yield
    numba.set_num_threads(before)


def _cloud(seed, n_bodies=120, per=5):
    rng = np.random.default_rng(seed)
    sx = rng.uniform(-0.05, 0.05, (n_bodies * per, 3))
    sx[:7] += 0.2                      # strays outside the domain
    srad = rng.uniform(0.003, 0.0055, n_bodies * per)
    sbody = np.repeat(np.arange(n_bodies), per)
    active = np.ones(n_bodies, bool)
    active[5] = False
    return sx, srad, sbody, active


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("seed", [0, 1])
def test_pair_list_equals_brute_force(seed, threads):
    numba.set_num_threads(min(threads, POOL))
    sx, srad, sbody, active = _cloud(seed)
    skin, lo, hi = 0.002, np.array([-0.06, -0.06, -0.06]), np.array([0.06, 0.06, 0.06])
    cell_xyz, dims = grid_shape(lo, hi, 2 * srad.max() + skin)
    cell_start = np.zeros(padded_cell_count(dims) + 1, np.int64)
    empty = (np.zeros(1, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)))
    allow = np.zeros(sx.shape[0])
    start, pi, pj, hist = build_pair_list(sx.shape[0], sx, srad, sbody, active, skin, lo,
                                          1.0 / cell_xyz, dims, cell_start, *empty, allow, POOL)
    d = np.linalg.norm(sx[:, None] - sx[None], axis=2)
    i, j = np.nonzero(np.triu(d < srad[:, None] + srad[None] + skin, k=1))
    keep = (sbody[i] != sbody[j]) & active[sbody[i]] & active[sbody[j]]
    assert set(zip(pi.tolist(), pj.tolist())) == set(zip(i[keep].tolist(), j[keep].tolist()))
    # each sphere's allowance is at least skin / 2 and at most half its gap to every sphere of
    # another clump that is not listed with it: then no unlisted pair can touch before a rebuild
    gap = d - srad[:, None] - srad[None]
    unlisted = (sbody[:, None] != sbody[None]) & active[sbody][None] & (gap >= skin)
    on = active[sbody]
    nearest = np.where(unlisted, gap, np.inf).min(axis=1)[on]
    assert np.all(allow[on] >= 0.5 * skin - 1e-15)
    assert np.all(allow[on] <= 0.5 * nearest + 1e-12)
    # and it is not only skin / 2: a sphere with room has more
    assert np.mean(allow[on] > 0.505 * skin) > 0.9
    assert len(pi) == keep.sum()
    assert np.all(pi < pj) and np.all(np.diff(pi) >= 0)
    for row in range(sx.shape[0]):
        assert np.all(pi[start[row]:start[row + 1]] == row)
    # a rebuild carries the history of pairs that persist
    hist[:] = np.arange(3 * len(pi)).reshape(-1, 3)
    start2, pi2, pj2, hist2 = build_pair_list(sx.shape[0], sx, srad, sbody, active, skin, lo,
                                              1.0 / cell_xyz, dims, cell_start, start, pj, hist, allow, POOL)
    np.testing.assert_array_equal(hist2, hist)


def test_the_rebuild_is_the_same_on_one_thread_and_on_all():
    """Lists, their order and the allowances, to the bit: on one thread in one pass (a pool of
    one, so the pairs are joined in one block), in as many blocks as the joining takes, on
    every thread, and compiled without threads (the serial runs' kernel)."""
    sx, srad, sbody, active = _cloud(3, n_bodies=400)
    skin, lo, hi = 0.002, np.array([-0.06, -0.06, -0.06]), np.array([0.06, 0.06, 0.06])
    cell_xyz, dims = grid_shape(lo, hi, 2 * srad.max() + skin)
    empty = (np.zeros(1, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)))
    out, allowances = [], []
    for rebuild, threads, pool in ((build_pair_list, 1, 1), (build_pair_list, 1, JOIN_BLOCKS_MAX),
                                   (build_pair_list, POOL, POOL), (build_pair_list_serial, POOL, 1),
                                   (build_pair_list_serial, POOL, JOIN_BLOCKS_MAX)):
        numba.set_num_threads(threads)
        allow = np.zeros(sx.shape[0])
        out.append(rebuild(sx.shape[0], sx, srad, sbody, active, skin, lo, 1.0 / cell_xyz, dims,
                           np.zeros(padded_cell_count(dims) + 1, np.int64), *empty, allow, pool))
        allowances.append(allow)
    for other, allow in zip(out[1:], allowances[1:]):
        for a, b in zip(out[0], other):
            np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(allowances[0], allow)


def test_wall_list_equals_brute_force():
    sx, srad, sbody, active = _cloud(3)
    walls = [Plane((0, 0, -0.02), (0, 0, 1)),
             Rectangle((0.01, 0.0, 0.0), (0, 1, 0), (0, 0, 1), 0.02, 0.03),
             Rectangle((0.0, 0.0, 0.02), (1, 0, 0), (0, 1, 0), 0.01, 0.01)]
    w = pack_walls(walls, lambda name: 0)
    skin = 0.002
    empty = (np.zeros(1, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)))
    allow = np.zeros(sx.shape[0])
    start, ws, wk, _ = build_wall_list(sx.shape[0], sx, srad, sbody, active, skin, w["kind"],
                                       w["origin"], w["normal"], w["axis_u"], w["axis_v"], w["half"], *empty,
                                       allow)
    dist = wall_distances(w, sx)
    s, k = np.nonzero(dist < (srad + skin)[:, None])
    keep = active[sbody[s]]
    assert set(zip(ws.tolist(), wk.tolist())) == set(zip(s[keep].tolist(), k[keep].tolist()))
    # the wall allowance: at least skin, at most the gap to every wall not listed
    gap = dist - srad[:, None]
    on = active[sbody]
    nearest = np.where(gap >= skin, gap, np.inf).min(axis=1)[on]
    assert np.all(allow[on] >= skin) and np.all(allow[on] <= nearest + 1e-12)
    assert np.mean(allow[on] > 2 * skin) > 0.2


def _pushed_pair(skin):
    """Two segments pressed together while sliding and turning on a plate."""
    params = DEMParameters(mu_s_pw=0.3, mu_s_pp=0.6)
    sim = simulation(params, dt=2e-5, gravity=(0.0, 0.0, -9.81), skin=skin,
                     lo=(-0.3, -0.3, -0.05), hi=(0.3, 0.3, 0.2))
    tpl = sim.add_template(segment_template(0.025, 0.011, 5, 912.0))
    floor(sim)
    # side by side, pressed together, sliding past each other, one turning
    sim.add_clump(tpl, (0.0, 0.0, R - 2e-5), velocity=(0.4, 0.02, 0.0), angular_velocity=(0, 0, 2.0))
    sim.add_clump(tpl, (0.0, 2 * R - 3e-5, R - 2e-5), velocity=(0.1, -0.02, 0.0))
    sim.run(duration=0.06)
    return sim


def test_history_survives_rebuilds():
    frequent = _pushed_pair(skin=2e-5)       # rebuilds every few steps
    never = _pushed_pair(skin=0.2)           # one list for the whole run
    assert frequent.total_rebuilds > 100 and never.total_rebuilds == 1
    np.testing.assert_allclose(frequent.positions(), never.positions(), rtol=0, atol=1e-10)
    np.testing.assert_allclose(frequent.velocities(), never.velocities(), rtol=0, atol=1e-8)
    # the faster segment slid and was dragged by the other: slower than plate friction alone
    # would make it (0.4 - 0.3 g t = 0.22 m/s)
    assert never.velocities()[0, 0] < 0.2


def _listed_contacts_missing(sim):
    """Touching sphere pairs (found by a k-d tree, independent of the engine's cells) and
    sphere-wall pairs (brute force) that the lists lack."""
    from scipy.spatial import cKDTree

    n = sim.n_spheres
    x, r, body = sim.sphere_positions(), sim.sphere_radii(), sim.sphere_body()
    on = sim.active()[body]
    near = (cKDTree(x).query_pairs(2.0 * float(r.max()), output_type="ndarray") if n    # each pair i < j
            else np.zeros((0, 2), dtype=int))
    i, j = near[:, 0], near[:, 1]
    keep = (np.linalg.norm(x[i] - x[j], axis=1) < r[i] + r[j]) & (body[i] != body[j]) & on[i] & on[j]
    sid = sim._s["sid"]                 # sphere id of each row of the engine's arrays
    _, pi, pj, _ = sim._pairs
    listed = {(min(a, b), max(a, b)) for a, b in zip(sid[pi].tolist(), sid[pj].tolist())}
    missing = set(zip(i[keep].tolist(), j[keep].tolist())) - listed
    dist = wall_distances(sim._w, x[:n])
    s, k = np.nonzero(dist < r[:, None])
    _, ws, wk, _ = sim._wpairs
    missing_walls = set(zip(s[on[s]].tolist(), k[on[s]].tolist())) - set(zip(sid[ws].tolist(), wk.tolist()))
    return missing, missing_walls


@pytest.mark.parametrize("sort_every", [0, 7])
def test_a_filling_box_never_misses_a_contact_between_rebuilds(sort_every):
    """Segments poured into a box, then pushed by a moving plate: with per-sphere allowances
    and spheres admitted without a rebuild, every touching pair is listed at every step, and
    the fill rebuilds far less often than once per insertion; also with the state sorted in
    memory every 7 steps (the lists renumbered, not rebuilt)."""
    from demcal.simulate.factory import ParticleFactory
    from demcal.simulate.walls import box_rectangles
    params = DEMParameters()
    sim = simulation(params, dt=5e-5, gravity=(0.0, 0.0, -9.81), lo=(-0.1, -0.1, -0.02), hi=(0.1, 0.1, 0.3),
                     sort_every=sort_every, sort_min_spheres=0)
    sim.chunk_steps = 1
    tpl = sim.add_template(segment_template(0.025, 0.011, 5, 912.0))
    sim.add_walls(box_rectangles((-0.05, -0.03, 0.0), (0.05, 0.03, 0.25), faces=("x-", "x+", "y-", "y+", "z-")))
    # a plate inside the x+ face pushes into the heap once it has formed
    pusher = sim.add_wall(Rectangle((0.048, 0.0, 0.1), (0, 1, 0), (0, 0, 1), 0.03, 0.1, material="steel"))
    sim.set_wall_motion(pusher, (-0.1, 0.0, 0.0), 0.15, 0.3)
    sim.add_factory(ParticleFactory(tpl, 60, (-0.045, -0.025, 0.08), (0.045, 0.025, 0.24), seed=4,
                                    start_time=0.0, end_time=0.15))
    checked = []

    def check(s):
        checked.append(_listed_contacts_missing(s))

    sim.run(duration=0.3, progress=check)
    assert len(checked) == 6000 and sim.n_bodies == 60
    assert sim.total_sorts == (0 if sort_every == 0 else 6000 // 7)
    assert all(not a and not b for a, b in checked)


def test_a_clump_falling_through_empty_space_needs_few_rebuilds_and_a_new_one_none():
    """A segment falls 0.2 m from rest beside another far away: under the plain criterion
    (skin / 2 = 1.1 mm per rebuild) that is some 180 rebuilds. With nothing in the 125 cells
    around it (cells of 2 R + skin = 13.2 mm), each sphere's gap to anything beyond them is at
    least 2 cells less its radius and the largest, 15.4 mm: it falls 7.7 mm or more between
    rebuilds, so at most 26. A segment added with room joins the lists without a rebuild."""
    sim = simulation(DEMParameters(), dt=5e-5, gravity=(0.0, 0.0, -9.81), lo=(-0.3, -0.3, -0.05),
                     hi=(0.3, 0.3, 0.4))
    tpl = sim.add_template(segment_template(0.025, 0.011, 5, 912.0))
    floor(sim)
    sim.add_clump(tpl, (0.0, 0.0, 0.3))
    sim.add_clump(tpl, (0.2, 0.2, 0.3))
    sim.run(n_steps=1)
    before = sim.total_rebuilds
    sim.run(duration=0.2)                         # falls 0.196 m
    assert 0.09 < sim.positions()[0, 2] < 0.11
    assert sim.total_rebuilds - before <= 26
    before = sim.total_rebuilds
    sim.add_clump(tpl, (-0.2, -0.2, 0.3))
    sim.run(n_steps=1)
    assert sim.total_rebuilds == before


def _admit_every_sphere(first, n, sx, srad, sbody, bactive, skin, sx0, allow, sxw, wall_allow, packed, wall_ref):
    """``admit_spheres`` as first written: each new sphere against every earlier one, in plain
    Python (the second implementation the cell search is held to)."""
    import math

    from demcal.simulate.walls import wall_distance
    wall_args = tuple(packed[k] for k in ("kind", "origin", "normal", "axis_u", "axis_v", "half"))
    wmax = max((math.sqrt(sum((packed["origin"][k, a] - wall_ref[k, a]) ** 2 for a in range(3)))
                for k in range(len(packed["kind"]))), default=0.0)

    def room(s, j):
        return math.sqrt(sum((sx[s, a] - sx0[j, a]) ** 2 for a in range(3))) - srad[s] - srad[j]

    least = 0.5 * skin
    for s in range(first, n):
        if not bactive[sbody[s]]:
            continue
        w_s = min((wall_distance(*wall_args, k, *sx[s])[0] - srad[s] - wmax for k in range(len(packed["kind"]))),
                  default=math.inf)
        if w_s < least:
            return False
        others = [j for j in range(s) if sbody[j] != sbody[s] and bactive[sbody[j]]]
        a_s = min((room(s, j) - allow[j] for j in others), default=math.inf)
        if a_s < least:
            for j in others:
                narrowed = room(s, j) - least
                if narrowed < allow[j]:
                    moved2 = sum((sx[j, a] - sx0[j, a]) ** 2 for a in range(3))
                    if narrowed <= 0.0 or moved2 >= narrowed * narrowed:
                        return False
                    allow[j] = narrowed
            a_s = least
        allow[s], wall_allow[s] = a_s, w_s
        sx0[s] = sx[s]
        sxw[s] = sx[s]
    return True


def _admission_case(seed):
    """Earlier spheres with reference positions and allowances (one without bound, strays
    outside the grid, an inactive clump) and 40 new spheres dropped among them, one a stray;
    a floor that moved since the wall list was built."""
    rng = np.random.default_rng(seed)
    sx, srad, sbody, active = _cloud(seed, n_bodies=90)
    n, skin = sx.shape[0], 0.002
    first = n - 40
    sx0 = sx + rng.normal(0.0, 2e-4, sx.shape)
    allow = rng.uniform(0.5 * skin, 2.0 * skin, n)
    allow[11] = np.inf
    sx[first:] = rng.uniform(-0.05, 0.05, (n - first, 3))
    if seed % 2:    # spread out above the cloud, the first 0.8 skin above an old sphere's top
        sx[first:, 2] = rng.uniform(0.06, 0.56, n - first)
        top = np.argmax(np.where(active[sbody[:first]] & (sx0[:first, 2] < 0.06), sx0[:first, 2], -np.inf))
        sx[first] = sx0[top] + (0.0, 0.0, srad[top] + srad[first] + 0.8 * skin)
    sx[n - 3] += 0.3
    walls = pack_walls([Plane((0.0, 0.0, -0.2), (0.0, 0.0, 1.0))], lambda name: 0)
    wall_ref = walls["origin"] - (0.0, 0.0, 1e-4)
    state = [sx0, allow, sx0.copy(), np.zeros(n)]        # sx0, allow, sxw, wall allowance
    return first, n, sx, srad, sbody, active, skin, state, walls, wall_ref


@pytest.mark.parametrize("seed", range(8))
def test_admitting_new_spheres_by_cells_equals_admitting_them_against_every_sphere(seed):
    from demcal.simulate.neighbours import admit_spheres
    first, n, sx, srad, sbody, active, skin, got, walls, wall_ref = _admission_case(seed)
    ref = [a.copy() for a in got]
    lo = np.array([-0.06, -0.06, -0.06])
    cell_xyz, dims = grid_shape(lo, np.array([0.06, 0.06, 0.6]), 2 * srad.max() + skin)
    ok = admit_spheres(first, n, sx, srad, sbody, active, skin, *got, walls["kind"], walls["origin"],
                       walls["normal"], walls["axis_u"], walls["axis_v"], walls["half"], wall_ref, lo,
                       1.0 / cell_xyz, dims)
    assert ok == _admit_every_sphere(first, n, sx, srad, sbody, active, skin, *ref, walls, wall_ref)
    if ok:    # a refusal leaves the allowances to the rebuild
        for a, b in zip(got, ref):
            np.testing.assert_array_equal(a, b)


def test_the_admission_cases_both_admit_and_refuse():
    # the comparison above is only as good as its cases: some admit (one narrowing its
    # neighbours), some refuse
    outcomes = []
    for seed in range(8):
        first, n, sx, srad, sbody, active, skin, state, walls, wall_ref = _admission_case(seed)
        before = state[1].copy()
        ok = _admit_every_sphere(first, n, sx, srad, sbody, active, skin, *state, walls, wall_ref)
        outcomes.append((ok, ok and bool(np.any(state[1][:first] < before[:first]))))
    assert any(ok for ok, _ in outcomes) and not all(ok for ok, _ in outcomes)
    assert any(narrowed for _, narrowed in outcomes)


@pytest.mark.parametrize("cell", [0.004, 0.02, 1.0])
def test_a_clump_clear_of_spheres_by_cells_equals_against_every_sphere(cell):
    # the factory's test of a drawn clump, the spheres in cells (some outside the grid), against
    # every sphere in plain Python: the same first clear candidate from every start
    from demcal.simulate.neighbours import bin_spheres, first_clear
    rng = np.random.default_rng(3)
    x, r, _, _ = _cloud(3, n_bodies=60)
    n, gap = len(r), 0.002
    lo, hi = np.array([-0.04, -0.04, -0.04]), np.array([0.04, 0.04, 0.04])
    dims = np.maximum(np.ceil((hi - lo) / cell), 1).astype(np.int64)
    head, nxt = np.full(int(dims.prod()), -1, np.int64), np.empty(n, np.int64)
    bin_spheres(x, 0, n, lo, np.full(3, 1.0 / cell), dims, head, nxt)
    offsets = np.array([[-0.01, 0.0, 0.0], [0.0, 0.0, 0.0], [0.01, 0.0, 0.0]])
    radii, reach = np.full(3, 0.004), 0.014
    pos = rng.uniform(-0.06, 0.06, (40, 3))
    centres = pos[:, None, :] + offsets
    inside = rng.random(40) < 0.9
    box = reach + r.max() + gap

    def clear(m):
        near = np.all(np.abs(x - pos[m]) < box, axis=1)
        d = np.linalg.norm(x[near][:, None] - centres[m][None], axis=2)
        return not np.any(d < radii[None] + r[near][:, None] + gap)

    expected = [m for m in range(40) if inside[m] and clear(m)]
    assert 0 < len(expected) < inside.sum()
    for start in range(41):
        got = first_clear(start, x, r, r.max(), lo, np.full(3, 1.0 / cell), dims, head, nxt, pos, reach, centres,
                          radii, gap, inside)
        assert got == next((m for m in expected if m >= start), -1)
