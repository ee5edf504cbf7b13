"""The same settled bed's contact loop over blocks of growing size: what the working set alone
costs a pair.

The settled bed of ``dem_scaling.py`` runs slower per sphere at 100,000 spheres than at 2,500
(``benchmarks/RESULTS.md``). Between those two beds more than the size changes: the larger one is
sorted in memory along the Morton curve (from 4,096 spheres), has more pairs a sphere, and
rebuilds its lists at another rate. This benchmark holds all of that fixed. It fills the large
bed once (``dem_scaling.py``'s fill, then its settled phase on one thread) and times the
engine's sphere-sphere loop (``simulate.forces.pair_forces``, one thread) over the pairs of a
block of consecutive sphere rows in the middle of the bed, both spheres in the block, for blocks
of growing size. The pairs, their physics and their order in memory are the bed's own. The only
thing that changes from block to block is how many bytes the loop goes through before it
comes back to the same pair at its next call.

Each block is timed with and without asking for the second spheres' rows ahead (the engine
asks from ``PREFETCH_MIN_SPHERES`` spheres on, ``PREFETCH_AHEAD`` pairs ahead). The blocks take
turns round by round, so the machine's drift spreads over all of them. For each block the
shortest of the rounds is reported (a core of the machine this was written on has windows in
which it runs about 1.45 times slower; ``settled_step.py``), with the median beside it, as ns
a pair and as bytes: the rows the loop reads and writes for the block (pair list and history,
sphere rows, body rows). The small bed itself (``--reference``, filled the same way) is timed
over all its pairs alongside, as the baseline a flat throughput would keep.

    python benchmarks/working_set.py                        # a 100,000-sphere bed, 2,500 as reference
    python benchmarks/working_set.py --blocks 2500 10000 50000 100000 --rounds 21 --json out.json
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import numba
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from benchmarks.dem_scaling import FILL_PHASE, SETTLED_PHASE, scaled_carton  # noqa: E402
from benchmarks.repose_vs_liggghts import write_measurements  # noqa: E402
from demcal.simulate.forces import PREFETCH_AHEAD, pair_forces  # noqa: E402
from demcal.simulate.threads import threads_limited_to  # noqa: E402

#: Body rows and sphere rows the sphere-sphere loop reads or writes (the rolling cap reads the
#: orientation and inverse inertia).
BODY_ROWS = ("bx", "bv", "bw", "bR", "bf", "bt", "brm", "brv", "binvm", "binvi", "bmat")
SPHERE_ROWS = ("sx", "srad", "sbody")
#: Loop calls timed together: about this many pairs in all, so that a round lasts some
#: milliseconds at every block size.
PAIRS_A_ROUND = 400_000


def settled_bed(n_spheres: int, fill_time: float, seed: int):
    """The carton of ``dem_scaling.py`` filled (on every thread: the state is the same on any
    number) and then run through its settled phase on one thread."""
    sim = scaled_carton(n_spheres, fill_time, seed)
    sim.run(duration=FILL_PHASE)
    with threads_limited_to(1):
        sim.run(duration=SETTLED_PHASE)
    return sim


def row_bytes(arrays: dict, names) -> int:
    """Bytes of one row of each of the arrays ``names``, added up."""
    return sum(arrays[k].itemsize * int(np.prod(arrays[k].shape[1:])) for k in names)


def block_pairs(sim, n_block: int) -> tuple[np.ndarray, int, int]:
    """The list positions of the pairs with both spheres in the block of ``n_block`` sphere rows
    in the middle of the bed (whole bodies: spheres are stored body after body), and the block's
    numbers of spheres and bodies."""
    _, ppi, pj, _ = sim._pairs
    sbody = sim._s["sbody"][:sim.n_spheres]
    n_block = min(n_block, sim.n_spheres)
    first = (sim.n_spheres - n_block) // 2
    b0, b1 = sbody[first], sbody[first + n_block - 1] + 1
    s0, s1 = np.searchsorted(sbody, [b0, b1])
    inside = (ppi >= s0) & (ppi < s1) & (pj >= s0) & (pj < s1)
    return np.flatnonzero(inside).astype(np.int64), int(s1 - s0), int(b1 - b0)


def pair_loop(sim, near: np.ndarray, ahead: int):
    """The engine's sphere-sphere loop over the list positions ``near`` of ``sim``'s bed, as a
    call without arguments (every body in the one range: nothing is put aside)."""
    B, S = sim._b, sim._s
    _, ppi, pj, ph = sim._pairs
    pt = sim.materials.compile()
    unused = np.empty(0, np.int64), np.empty((0, 3)), np.empty((0, 3)), np.empty(0), np.empty((0, 3))
    n_bodies = sim.n_bodies

    def call():
        pair_forces(0, near.shape[0], sim.dt, sim.dt, sim._lever, pt.rolling_model, pt.rolling_damping_ratio,
                    pt.contact_effective_mass, ahead, B["bx"], B["bv"], B["bw"], B["bR"], B["binvm"], B["binvi"],
                    B["bmat"], B["bcount"], S["sbody"], S["sx"], S["srad"], near, ppi, pj, ph, pt.e_star, pt.g_star,
                    pt.damping, pt.mu_s, pt.mu_r, pt.log_e, pt.e_exponent, pt.log_v_ref, pt.v_min, B["bf"], B["bt"],
                    B["brm"], B["brv"], 0, n_bodies, *unused)
    return call


def cases(sim, blocks, label: str) -> list[dict]:
    """A case (loop call, pairs, bytes) per block of ``sim``'s bed, with and without the hints."""
    _, ppi, pj, ph = sim._pairs
    pair_row = ppi.itemsize + pj.itemsize + ph.itemsize * ph.shape[1] + 8   # 8: the near index
    out = []
    for n_block in blocks:
        near, n_spheres, n_bodies = block_pairs(sim, n_block)
        nbytes = (near.size * pair_row + n_spheres * row_bytes(sim._s, SPHERE_ROWS)
                  + n_bodies * row_bytes(sim._b, BODY_ROWS))
        for ahead in (0, PREFETCH_AHEAD):
            out.append({"bed": label, "block_spheres": n_spheres, "pairs": int(near.size), "ahead": ahead,
                        "bytes": int(nbytes), "call": pair_loop(sim, near, ahead)})
    return out


def time_in_turn(cases: list[dict], rounds: int) -> None:
    """Each case's time per pair [ns], the cases in turn in every round: ``ns_a_pair`` (all
    rounds), ``shortest`` and ``median`` into each case."""
    for c in cases:
        c["call"]()     # compiled, and its rows brought in once
        c["calls"] = max(3, PAIRS_A_ROUND // max(c["pairs"], 1))
        c["ns_a_pair"] = []
    for _ in range(rounds):
        for c in cases:
            t0 = time.perf_counter()
            for _ in range(c["calls"]):
                c["call"]()
            c["ns_a_pair"].append((time.perf_counter() - t0) / c["calls"] / c["pairs"] * 1e9)
    for c in cases:
        c["shortest"] = min(c["ns_a_pair"])
        c["median"] = statistics.median(c["ns_a_pair"])


def table(cases: list[dict]) -> list[str]:
    """A Markdown table of the cases, against the reference bed's shortest (the first case)."""
    base = {c["ahead"]: c["shortest"] for c in cases if c["bed"] == "reference"}
    lines = ["| bed | block, spheres | pairs | bytes the loop goes through | hints | ns a pair, shortest (median) "
             "| reference bed's shortest / this |",
             "|---|---|---|---|---|---|---|"]
    for c in cases:
        ref = base.get(c["ahead"])
        against = f"{ref / c['shortest']:.2f}" if ref else ""
        lines.append(f"| {c['bed']} | {c['block_spheres']:,} | {c['pairs']:,} | {c['bytes'] / 2**20:.1f} MiB "
                     f"| {c['ahead'] or 'none'} | {c['shortest']:.1f} ({c['median']:.1f}) | {against} |")
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spheres", type=int, default=100_000, help="the large bed")
    parser.add_argument("--blocks", type=int, nargs="+", default=[2500, 5000, 10000, 25000, 50000, 100000])
    parser.add_argument("--reference", type=int, default=2500, help="the small bed, timed whole (0: none)")
    parser.add_argument("--rounds", type=int, default=15)
    parser.add_argument("--fill-time", type=float, default=0.5, help="insertion window [s]")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--json", default=None, help="write the numbers to this file")
    args = parser.parse_args(argv)
    all_cases = []
    if args.reference:
        small = settled_bed(args.reference, args.fill_time, args.seed)
        all_cases += cases(small, [small.n_spheres], "reference")
    large = settled_bed(args.spheres, args.fill_time, args.seed)
    all_cases += cases(large, args.blocks, f"{large.n_spheres:,} spheres")
    numba.set_num_threads(1)
    time_in_turn(all_cases, args.rounds)
    print("\n".join(table(all_cases)), flush=True)
    if args.json:
        write_measurements(args.json, rounds=args.rounds,
                           cases=[{k: v for k, v in c.items() if k != "call"} for c in all_cases])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
