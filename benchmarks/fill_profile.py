"""Where the fill phase's time goes, on 1 and on 2 threads: the paper's carton scaled to
``--spheres`` spheres (as ``dem_scaling.py``), 0.6 s of fill, with the engine's Python-side
steps wrapped in timers: the compiled step loop (``Simulation._advance``, admitting new spheres
included), the factory's insertions (``ParticleFactory.insert_due``), admitting new spheres
(``admit_spheres``) and the sorts in memory.

    python benchmarks/fill_profile.py                       # 20,000 spheres, 1 then 2 threads, twice
    python benchmarks/fill_profile.py --spheres 100000 --rounds 1
"""

from __future__ import annotations

import argparse
import collections
import math
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import demcal.simulate.engine as engine  # noqa: E402
import demcal.simulate.factory as factory  # noqa: E402
from benchmarks.dem_scaling import FILL_PHASE  # noqa: E402
from benchmarks.dem_throughput import BENCHMARK_PARAMETERS  # noqa: E402
from demcal.simulate.params import DEMParameters  # noqa: E402
from demcal.simulate.scenes import build_paper_repose_case  # noqa: E402

TIMED = ((engine.Simulation, "_advance", "compiled step loop (admitting included)"),
         (factory.ParticleFactory, "insert_due", "factory insertions"),
         (engine, "admit_spheres", "admitting new spheres"),
         (engine.Simulation, "sort_in_memory", "sorts in memory"))


def timed(seconds: collections.Counter):
    """Wrap each of ``TIMED`` so that its wall time adds up in ``seconds``."""
    for owner, name, label in TIMED:
        inner = getattr(owner, name)

        def wrapper(*args, _inner=inner, _label=label, **kwargs):
            start = time.perf_counter()
            try:
                return _inner(*args, **kwargs)
            finally:
                seconds[_label] += time.perf_counter() - start
        setattr(owner, name, wrapper)


def fill(n_spheres: int, threads: int, seconds: collections.Counter) -> float:
    n_clumps = n_spheres // 5
    scale = math.sqrt(n_clumps / 500)
    sim = build_paper_repose_case(DEMParameters().with_(**BENCHMARK_PARAMETERS), seed=1, n_clumps=n_clumps,
                                  box_length=0.2 * scale, box_width=0.1 * scale, fill_time=0.5, lift_time=100.0)
    sim.threads = threads
    sim.run(n_steps=1)          # load the kernels before timing
    seconds.clear()
    start = time.perf_counter()
    sim.run(duration=FILL_PHASE)
    return time.perf_counter() - start


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--spheres", type=int, default=20000)
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--rounds", type=int, default=2)
    args = ap.parse_args(argv)
    seconds = collections.Counter()
    timed(seconds)
    for r in range(1, args.rounds + 1):
        for t in args.threads:
            wall = fill(args.spheres, t, seconds)
            print(f"round {r}, {args.spheres} spheres, {t} thread(s): fill {wall:.2f} s")
            for label, s in seconds.most_common():
                print(f"  {label:42s} {s:6.2f} s  {s / wall:6.1%}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
