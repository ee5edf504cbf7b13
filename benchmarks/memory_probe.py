"""What the machine's memory allows a settled bed at scale: a pair pass with the engine's bytes
per sphere, without its physics.

The settled bed of ``dem_scaling.py`` at 100,000 spheres runs slower per sphere than at 2,500.
This probe asks how much of that the memory hierarchy alone imposes. It lays N spheres of one
size on a jittered body-centred cubic lattice at the bed's pair density, sorts them along the
same Morton curve as the engine (``simulate.neighbours.morton_keys``), lists the pairs closer
than the sum of radii plus a skin, and times passes of a kernel that does what the engine's
step does to memory and little else:

- per pair: read both spheres' positions, radii and body rows, read and write three history
  values, add a force and a torque to both bodies;
- per body: read and write its rows (position, velocity, angular velocity, orientation, force,
  torque) as the integrator does.

Its state, about 365 bytes a sphere with the pairs' share (printed per case), is close to the
engine's 390 in a settled bed (``benchmarks/RESULTS.md``). The ratio of its throughput at the
largest size to that at the smallest is what the memory hierarchy leaves of flat throughput
for this access pattern with almost no arithmetic; the engine's own ratio (``dem_scaling.py``)
can be read against it: if the probe stays flat where the engine does not, the engine has room.

    python benchmarks/memory_probe.py                      # 2,500, 20,000 and 100,000 spheres
    python benchmarks/memory_probe.py --rounds 5 --spheres 2500 100000
    python benchmarks/memory_probe.py --index-bits 32      # the pair list's indices in 32 bits
    python benchmarks/memory_probe.py --spheres 20000 100000 --threads 1 2   # the engine's ranged
                                                           # kernels on 1, then 2 threads
    python benchmarks/memory_probe.py --ahead 0 32         # rows asked for 32 pairs ahead, and not
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import time

import numba
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from benchmarks.repose_vs_liggghts import write_measurements  # noqa: E402
from demcal.simulate._jit import prefetch  # noqa: E402
from demcal.simulate.neighbours import morton_keys  # noqa: E402

#: Body rows of the probe: position, velocity, angular velocity, force, torque (3 each) and
#: an orientation matrix (9), as the engine's body rows; sphere rows: position (3), radius.
BODY_COLUMNS, SPHERE_COLUMNS, HISTORY_COLUMNS = 24, 4, 3


@numba.njit(cache=False, fastmath=False)
def pair_pass(pi, pj, sx, body, hist, stiffness, ahead=0):
    # with ``ahead`` the second sphere's row and its body's row (192 bytes: every cache line of
    # it) are asked for that many pairs ahead; the engine's contact loop asks for its second
    # sphere's rows alone (``simulate.forces.PREFETCH_AHEAD``)
    flat = body.reshape(-1)
    for k in range(pi.size):
        if ahead > 0 and k + ahead < pi.size:
            later = pj[k + ahead]
            prefetch(sx, later)
            for c in range(0, BODY_COLUMNS, 8):
                prefetch(flat, later * BODY_COLUMNS + c)
            prefetch(flat, later * BODY_COLUMNS + BODY_COLUMNS - 1)
        i = pi[k]
        j = pj[k]
        dx = sx[j, 0] - sx[i, 0]
        dy = sx[j, 1] - sx[i, 1]
        dz = sx[j, 2] - sx[i, 2]
        rsum = sx[i, 3] + sx[j, 3]
        d2 = dx * dx + dy * dy + dz * dz
        if d2 >= rsum * rsum:
            hist[k, 0] = 0.0
            hist[k, 1] = 0.0
            hist[k, 2] = 0.0
            continue
        d = math.sqrt(d2)
        f = stiffness * (rsum - d) / d
        # relative velocity and spin read as the engine's contact does
        vr = (body[i, 3] - body[j, 3]) * dx + (body[i, 4] - body[j, 4]) * dy + (body[i, 5] - body[j, 5]) * dz
        wr = (body[i, 6] - body[j, 6]) + (body[i, 7] - body[j, 7]) + (body[i, 8] - body[j, 8])
        hist[k, 0] += 1e-9 * vr
        hist[k, 1] += 1e-9 * wr
        hist[k, 2] = f
        for c in range(3):
            g = f * (dx, dy, dz)[c]
            body[i, 9 + c] -= g
            body[j, 9 + c] += g
            body[i, 12 + c] += 1e-3 * g
            body[j, 12 + c] += 1e-3 * g


@numba.njit(cache=False, fastmath=False)
def body_pass(body, sx, dt):
    for b in range(body.shape[0]):
        for c in range(3):
            body[b, 3 + c] += dt * body[b, 9 + c]
            body[b, 6 + c] += dt * body[b, 12 + c]
            body[b, 9 + c] = 0.0
            body[b, 12 + c] = 0.0
        for c in range(9):
            body[b, 15 + c] += 1e-12 * body[b, 6 + c % 3]
        sx[b, 0] = body[b, 0]


# The pair's arithmetic is written out again below rather than shared through an inlined
# helper: with the helper the ranged pass ran a third slower on one thread (twice, 2026-11-29).
@numba.njit(parallel=True, cache=False, fastmath=False)
def pair_pass_ranged(pi, pj, sx, body, hist, stiffness, n_ranges, aside_f):
    """``pair_pass`` as the engine's threads run it (``simulate.forces.contact_forces_ranged``):
    the list cut into ``n_ranges`` runs of whole rows, each run summing into its own bodies and
    keeping a second body's share aside when that body is another run's; the shares set aside
    are added after, run by run."""
    n = pi.size
    cut = np.empty(n_ranges + 1, np.int64)
    for c in range(n_ranges):
        cut[c] = np.searchsorted(pi, pi[n * c // n_ranges])
    cut[n_ranges] = n
    aside = np.zeros(n_ranges, np.int64)
    for c in numba.prange(n_ranges):
        hi = pi[cut[c + 1]] if c + 1 < n_ranges else body.shape[0]
        m = 0
        for k in range(cut[c], cut[c + 1]):
            i = pi[k]
            j = pj[k]
            dx = sx[j, 0] - sx[i, 0]
            dy = sx[j, 1] - sx[i, 1]
            dz = sx[j, 2] - sx[i, 2]
            rsum = sx[i, 3] + sx[j, 3]
            d2 = dx * dx + dy * dy + dz * dz
            if d2 >= rsum * rsum:
                hist[k, 0] = 0.0
                hist[k, 1] = 0.0
                hist[k, 2] = 0.0
                continue
            d = math.sqrt(d2)
            f = stiffness * (rsum - d) / d
            vr = (body[i, 3] - body[j, 3]) * dx + (body[i, 4] - body[j, 4]) * dy + (body[i, 5] - body[j, 5]) * dz
            wr = (body[i, 6] - body[j, 6]) + (body[i, 7] - body[j, 7]) + (body[i, 8] - body[j, 8])
            hist[k, 0] += 1e-9 * vr
            hist[k, 1] += 1e-9 * wr
            hist[k, 2] = f
            own_j = j < hi
            for a in range(3):
                g = f * (dx, dy, dz)[a]
                body[i, 9 + a] -= g
                body[i, 12 + a] += 1e-3 * g
                if own_j:
                    body[j, 9 + a] += g
                    body[j, 12 + a] += 1e-3 * g
                else:
                    aside_f[cut[c] + m, a] = g
            if not own_j:
                aside_f[cut[c] + m, 3] = j
                m += 1
        aside[c] = m
    for c in range(n_ranges):
        for e in range(cut[c], cut[c] + aside[c]):
            j = int(aside_f[e, 3])
            for a in range(3):
                body[j, 9 + a] += aside_f[e, a]
                body[j, 12 + a] += 1e-3 * aside_f[e, a]


@numba.njit(parallel=True, cache=False, fastmath=False)
def body_pass_threaded(body, sx, dt):
    for b in numba.prange(body.shape[0]):
        for c in range(3):
            body[b, 3 + c] += dt * body[b, 9 + c]
            body[b, 6 + c] += dt * body[b, 12 + c]
            body[b, 9 + c] = 0.0
            body[b, 12 + c] = 0.0
        for c in range(9):
            body[b, 15 + c] += 1e-12 * body[b, 6 + c % 3]
        sx[b, 0] = body[b, 0]


def bed(n: int, seed: int, index_dtype=np.int64):
    """A jittered body-centred cubic lattice of ``n`` spheres of radius 1, each touching its 8
    nearest neighbours at 1.95 (about 4 pairs a sphere within a skin of 0.1, as the settled
    bed's 3.8), Morton-sorted, and its pair list (i < j)."""
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(seed)
    side = math.ceil((n / 2.0) ** (1.0 / 3.0))
    cube = np.stack(np.meshgrid(*(np.arange(side),) * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    grid = np.concatenate([cube, cube + 0.5])[:n]
    x = grid * (2.0 * 1.95 / math.sqrt(3.0)) + rng.uniform(-0.02, 0.02, size=(n, 3))
    order = np.argsort(morton_keys(x, x.min(axis=0), 2.2), kind="stable")
    x = x[order]
    pairs = cKDTree(x).query_pairs(2.1, output_type="ndarray")
    pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]
    sx = np.empty((n, SPHERE_COLUMNS))
    sx[:, :3], sx[:, 3] = x, 1.0
    body = np.zeros((n, BODY_COLUMNS))
    body[:, :3] = x
    body[:, 15:24] = np.eye(3).ravel()
    return (sx, body, pairs[:, 0].astype(index_dtype), pairs[:, 1].astype(index_dtype),
            np.zeros((len(pairs), HISTORY_COLUMNS)))


def measure(n: int, seconds: float, seed: int, index_dtype=np.int64, threads: int | None = None,
            ahead: int = 0) -> dict:
    """Sphere-steps per second of the probe's passes on a bed of ``n`` spheres: the serial
    kernels (asking for the second sphere's rows ``ahead`` pairs ahead), or with ``threads`` the
    ranged ones on that many threads."""
    sx, body, pi, pj, hist = bed(n, seed, index_dtype)
    if threads:
        numba.set_num_threads(threads)
        aside_f = np.zeros((pi.size, 4))

        def step():
            pair_pass_ranged(pi, pj, sx, body, hist, 1.0, 16, aside_f)
            body_pass_threaded(body, sx, 0.0)
    else:
        def step():
            pair_pass(pi, pj, sx, body, hist, 1.0, ahead)
            body_pass(body, sx, 0.0)
    step()
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        for _ in range(20):
            step()
        steps += 20
    wall = time.perf_counter() - start
    nbytes = sx.nbytes + body.nbytes + pi.nbytes + pj.nbytes + hist.nbytes
    return {"spheres": n, "pairs_per_sphere": len(pi) / n, "bytes_per_sphere": nbytes / n,
            "state_mb": nbytes / 1e6, "steps": steps, "sphere_steps_per_s": n * steps / wall}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--spheres", type=int, nargs="+", default=[2500, 20000, 100000])
    ap.add_argument("--seconds", type=float, default=5.0, help="timed wall seconds per case")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--index-bits", type=int, choices=(32, 64), default=64,
                    help="width of the pair list's sphere indices (the engine's: 64)")
    ap.add_argument("--threads", type=int, nargs="+",
                    help="run each size with the engine's ranged kernels on these thread counts, in turn "
                         "(default: the serial kernels, one thread)")
    ap.add_argument("--ahead", type=int, nargs="+", default=[0],
                    help="serial pass: ask for each pair's second sphere and body rows this many pairs "
                         "ahead (0: not); several values run in turn")
    ap.add_argument("--json", help="write the numbers here")
    args = ap.parse_args(argv)
    numba.set_num_threads(1)
    index_dtype = np.int32 if args.index_bits == 32 else np.int64
    configs = [(t, a) for t in (args.threads or [None]) for a in (args.ahead if t is None else [0])]
    rows = []
    for r in range(1, args.rounds + 1):
        for n in args.spheres:
            for t, a in configs:
                row = {"round": r, "index_bits": args.index_bits, "threads": t or 1, "ranged": t is not None,
                       "ahead": a, **measure(n, args.seconds, seed=r, index_dtype=index_dtype, threads=t, ahead=a)}
                rows.append(row)
                kind = f"serial, ahead {a}" if t is None else f"{t} thread(s), ranged"
                print(f"round {r}  {n:>7} spheres  {kind}  "
                      f"{row['pairs_per_sphere']:.2f} pairs/sphere  {row['bytes_per_sphere']:.0f} B/sphere "
                      f"({row['state_mb']:.1f} MB)  {row['sphere_steps_per_s']:.3g} sphere-steps/s", flush=True)

    def rate(r, n, config):
        t, a = config
        return next(x["sphere_steps_per_s"] for x in rows
                    if (x["round"], x["spheres"], x["threads"], x["ahead"]) == (r, n, t or 1, a))

    def show(label, values):
        print(f"{label}: " + ", ".join(f"{v:.2f}" for v in values) + f" (median {statistics.median(values):.2f})")
        return values

    def name(config):
        t, a = config
        return f"{t or 1} thread(s)" + (f", ahead {a}" if a else "")

    ratios = {}
    for config in configs:
        for n in args.spheres[1:]:
            label = f"{n} / {args.spheres[0]} spheres, {name(config)}"
            ratios[label] = show(label, [rate(r, n, config) / rate(r, args.spheres[0], config)
                                         for r in range(1, args.rounds + 1)])
    for config in configs[1:]:
        for n in args.spheres:
            label = f"{n} spheres, {name(config)} / {name(configs[0])}"
            ratios[label] = show(label, [rate(r, n, config) / rate(r, n, configs[0])
                                         for r in range(1, args.rounds + 1)])
    if args.json:
        write_measurements(args.json, rows=rows, ratios=ratios)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
