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
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import time

import numba
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from benchmarks.repose_vs_liggghts import machine, versions  # noqa: E402
from demcal.simulate.neighbours import morton_keys  # noqa: E402

#: Body rows of the probe: position, velocity, angular velocity, force, torque (3 each) and
#: an orientation matrix (9), as the engine's body rows; sphere rows: position (3), radius.
BODY_COLUMNS, SPHERE_COLUMNS, HISTORY_COLUMNS = 24, 4, 3


@numba.njit(cache=False, fastmath=False)
def pair_pass(pi, pj, sx, body, hist, stiffness):
    for k in range(pi.size):
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


def measure(n: int, seconds: float, seed: int, index_dtype=np.int64) -> dict:
    sx, body, pi, pj, hist = bed(n, seed, index_dtype)
    pair_pass(pi, pj, sx, body, hist, 1.0)
    body_pass(body, sx, 0.0)
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        for _ in range(20):
            pair_pass(pi, pj, sx, body, hist, 1.0)
            body_pass(body, sx, 0.0)
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
    ap.add_argument("--json", help="write the numbers here")
    args = ap.parse_args(argv)
    numba.set_num_threads(1)
    rows = []
    for r in range(args.rounds):
        for n in args.spheres:
            row = {"round": r + 1, "index_bits": args.index_bits,
                   **measure(n, args.seconds, seed=r, index_dtype=np.int32 if args.index_bits == 32 else np.int64)}
            rows.append(row)
            print(f"round {r + 1}  {n:>7} spheres  {row['pairs_per_sphere']:.2f} pairs/sphere  "
                  f"{row['bytes_per_sphere']:.0f} B/sphere ({row['state_mb']:.1f} MB)  "
                  f"{row['sphere_steps_per_s']:.3g} sphere-steps/s", flush=True)
    first = args.spheres[0]
    ratios = {}
    for n in args.spheres[1:]:
        ratios[n] = [next(x for x in rows if x["round"] == r and x["spheres"] == n)["sphere_steps_per_s"]
                     / next(x for x in rows if x["round"] == r and x["spheres"] == first)["sphere_steps_per_s"]
                     for r in range(1, args.rounds + 1)]
        print(f"{n} / {first}: " + ", ".join(f"{v:.2f}" for v in ratios[n])
              + f" (median {statistics.median(ratios[n]):.2f})")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"machine": machine(), "versions": versions(), "rows": rows,
                       "ratios_to_first": {str(k): v for k, v in ratios.items()}}, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
