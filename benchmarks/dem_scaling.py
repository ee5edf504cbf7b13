"""DEM throughput against the number of spheres, fill and settled phases apart, on one core (or
on ``--threads`` threads).

The paper's repose case (``benchmarks/dem_throughput.py``) with its carton scaled in x and y so
that the fill depth stays the same: 2,500 spheres (500 five-sphere segments) in 200 x 100 mm,
20,000 in 566 x 283 mm, 100,000 in 1265 x 632 mm. The factory inserts the segments over the
first ``--fill-time`` seconds; the *fill* phase is the first 0.6 s simulated, the *settled*
phase the 0.15 s after it. Per phase: sphere-steps per second (spheres present at each step),
pair-list and wall-list rebuilds, and rebuilds per 1000 steps. By default each run is what
demcal chooses by size (from 8,192 spheres the contacts in fixed ranges, ``simulate.forces``)
kept on one thread; ``--threads 1 2`` runs each size on 1, then 2 threads.

    python benchmarks/dem_scaling.py                         # 2,500 and 20,000 spheres
    python benchmarks/dem_scaling.py --spheres 2500 20000 100000
    python benchmarks/dem_scaling.py --spheres 20000 --threads 1 2   # one run on 1, then 2 threads
    python benchmarks/dem_scaling.py --rounds 3                      # each case 3 times, in turn

With ``--rounds`` every case runs again in each round, and each ratio (a size's settled
throughput against the first size's; a thread count's run against the first's) is given round
by round, then as a median and range: on a machine whose speed drifts, the two runs of a pair
are close in time.
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from benchmarks.dem_throughput import BENCHMARK_PARAMETERS  # noqa: E402
from benchmarks.repose_vs_liggghts import write_measurements  # noqa: E402
from demcal.simulate.params import DEMParameters  # noqa: E402
from demcal.simulate.scenes import build_paper_repose_case, compile_kernels  # noqa: E402
from demcal.simulate.threads import threads_limited_to  # noqa: E402

FILL_PHASE, SETTLED_PHASE = 0.6, 0.15


def phase(sim, duration: float) -> dict:
    steps0, wall0 = sim.total_rebuilds, sim.total_wall_rebuilds
    summary = sim.run(duration=duration)
    steps = summary.steps
    return {"sphere_steps_per_s": summary.sphere_steps_per_second, "steps": steps,
            "wall_s": summary.wall_time, "pair_rebuilds": sim.total_rebuilds - steps0,
            "wall_rebuilds": sim.total_wall_rebuilds - wall0,
            "pair_rebuilds_per_1000_steps": 1000.0 * (sim.total_rebuilds - steps0) / steps,
            "spheres_at_end": summary.n_spheres}


def scaled_carton(n_spheres: int, fill_time: float, seed: int):
    """The paper's repose case with its carton scaled in x and y to ``n_spheres`` spheres (the
    fill depth kept), its plate never lifted."""
    params = DEMParameters().with_(**BENCHMARK_PARAMETERS)
    n_clumps = n_spheres // 5
    scale = math.sqrt(n_clumps / 500)
    return build_paper_repose_case(params, seed=seed, n_clumps=n_clumps, box_length=0.2 * scale,
                                   box_width=0.1 * scale, fill_time=fill_time, lift_time=100.0)


def case(n_spheres: int, fill_time: float, seed: int, threads: int | None, fill_phase: float = FILL_PHASE,
         settled_phase: float = SETTLED_PHASE) -> dict:
    sim = scaled_carton(n_spheres, fill_time, seed)
    sim.threads = threads
    with threads_limited_to(1 if threads is None else None):
        used = sim.threads_in_use() if threads else "by size, 1"
        sim.run(n_steps=1)      # load the kernels before timing
        fill = phase(sim, fill_phase)
        settled = phase(sim, settled_phase)
    return {"spheres": n_spheres, "threads": threads, "threads_used": used, "fill": fill, "settled": settled,
            "fill_over_settled_throughput": fill["sphere_steps_per_s"] / settled["sphere_steps_per_s"],
            "fill_over_settled_rebuild_rate": (fill["pair_rebuilds_per_1000_steps"]
                                               / max(settled["pair_rebuilds_per_1000_steps"], 1e-9))}


def ratio_lines(rows: list[dict]) -> list[str]:
    """Each size's settled throughput against the first size's, and each thread count's run
    against the first's, round by round (a machine whose speed drifts moves both of a pair);
    with several rounds, their median and range."""
    def run_s(r):
        return r["fill"]["wall_s"] + r["settled"]["wall_s"]

    def settled(r):
        return r["settled"]["sphere_steps_per_s"]

    ratios: dict[str, list[float]] = {}
    for round_ in sorted({r["round"] for r in rows}):
        these = [r for r in rows if r["round"] == round_]
        base = these[0]
        for row in these[1:]:
            if row["threads"] == base["threads"]:
                name = f"settled throughput at {row['spheres']} / at {base['spheres']}"
                ratios.setdefault(name, []).append(settled(row) / settled(base))
            elif row["spheres"] == base["spheres"]:
                ratios.setdefault(f"{row['threads']} threads / {base['threads']}: the run (fill and settled) "
                                  f"faster", []).append(run_s(base) / run_s(row))
                ratios.setdefault(f"{row['threads']} threads / {base['threads']}: fill faster",
                                  []).append(row["fill"]["sphere_steps_per_s"] / base["fill"]["sphere_steps_per_s"])
                ratios.setdefault(f"{row['threads']} threads / {base['threads']}: settled faster",
                                  []).append(settled(row) / settled(base))
    return round_by_round(ratios)


def round_by_round(ratios: dict) -> list[str]:
    """A line per ratio: its value in each round, then (several rounds) median and range."""
    lines = []
    for name, values in ratios.items():
        each = ", ".join(f"{v:.2f}" for v in values)
        spread = (f"; median {statistics.median(values):.2f}, {min(values):.2f}-{max(values):.2f}"
                  if len(values) > 1 else "")
        lines.append(f"{name}: {each}{spread}")
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spheres", type=int, nargs="+", default=[2500, 20000])
    parser.add_argument("--fill-time", type=float, default=0.5, help="insertion window [s]")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--threads", type=int, nargs="+", default=[None],
                        help="threads of each run (default: demcal's choice by size, on one thread)")
    parser.add_argument("--rounds", type=int, default=1,
                        help="run every case this many times, in turn, and give each ratio round by round")
    parser.add_argument("--json", default=None, help="write the numbers to this file")
    args = parser.parse_args(argv)
    compile_kernels(threaded=True)   # every kernel a case may use (the fill's too), before any timing
    rows = []
    for round_ in range(args.rounds):
        for n, threads in ((n, t) for n in args.spheres for t in args.threads):
            t0 = time.perf_counter()
            row = case(n, args.fill_time, args.seed, threads)
            row["elapsed_s"] = time.perf_counter() - t0
            row["round"] = round_
            rows.append(row)
            f, s = row["fill"], row["settled"]
            print(f"{n:>7} spheres, threads {row['threads_used']} | {row['elapsed_s']:.1f} s | fill {f['sphere_steps_per_s']:.3g} sphere-steps/s, {f['pair_rebuilds']} "
                  f"rebuilds in {f['steps']} steps ({f['wall_rebuilds']} wall) | settled "
                  f"{s['sphere_steps_per_s']:.3g}, {s['pair_rebuilds']} in {s['steps']} ({s['wall_rebuilds']} wall) "
                  f"| fill/settled throughput {row['fill_over_settled_throughput']:.2f}, rebuild rate "
                  f"{row['fill_over_settled_rebuild_rate']:.2f}", flush=True)
    for line in ratio_lines(rows):
        print(line)
    if args.json:
        write_measurements(args.json, rows=rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
