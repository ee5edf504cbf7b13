"""Where the fill phase's time goes, on 1 and on 2 threads: the paper's carton scaled to
``--spheres`` spheres (as ``dem_scaling.py``), 0.6 s of fill, with the engine's Python-side
steps wrapped in timers: the compiled step loop (``Simulation._advance``, admitting new spheres
included), the factory's insertions (``ParticleFactory.insert_due``), admitting new spheres
(``admit_spheres``) and the sorts in memory; and each of ``--windows`` equal parts of the fill
timed apart, with the spheres present at its end; and one build of the sphere-wall list (on
one thread) for the filled bed.

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
from benchmarks.dem_scaling import FILL_PHASE, scaled_carton  # noqa: E402
from demcal.simulate.neighbours import build_wall_list  # noqa: E402

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


def fill(n_spheres: int, threads: int, seconds: collections.Counter, windows: int):
    """The filled carton, and the wall time and spheres at the end of each of ``windows`` equal
    parts of the fill."""
    sim = scaled_carton(n_spheres, fill_time=0.5, seed=1)
    sim.threads = threads
    sim.run(n_steps=1)          # load the kernels before timing
    seconds.clear()
    parts = []
    for _ in range(windows):
        start = time.perf_counter()
        summary = sim.run(duration=FILL_PHASE / windows)
        parts.append((time.perf_counter() - start, summary.n_spheres))
    return sim, parts


def wall_list_build(sim, repeats: int = 50) -> float:
    """Wall time [s] of one build of the sphere-wall list (on one thread) for the bed as it is."""
    S, B, W = sim._s, sim._b, sim._w
    wstart, _, wk, wh = sim._wpairs
    args = (sim.n_spheres, S["sx"], S["srad"], S["sbody"], B["bactive"], sim.skin, W["kind"], W["origin"],
            W["normal"], W["axis_u"], W["axis_v"], W["half"], wstart, wk, wh, S["swallow"].copy())
    build_wall_list(*args)
    start = time.perf_counter()
    for _ in range(repeats):
        build_wall_list(*args)
    return (time.perf_counter() - start) / repeats


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--spheres", type=int, default=20000)
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--windows", type=int, default=6, help="equal parts of the fill timed apart")
    args = ap.parse_args(argv)
    seconds = collections.Counter()
    timed(seconds)
    best = {}       # (threads, window) -> the shortest wall time over the rounds
    for r in range(1, args.rounds + 1):
        for t in args.threads:
            sim, parts = fill(args.spheres, t, seconds, args.windows)
            wall = sum(w for w, _ in parts)
            print(f"round {r}, {args.spheres} spheres, {t} thread(s): fill {wall:.2f} s, "
                  f"{sim.total_wall_rebuilds} wall-list builds; one build of the filled bed's "
                  f"{wall_list_build(sim) * 1e3:.2f} ms")
            for label, s in seconds.most_common():
                print(f"  {label:42s} {s:6.2f} s  {s / wall:6.1%}")
            for w, (s, n) in enumerate(parts):
                best[t, w] = (min(s, best.get((t, w), (math.inf, n))[0]), n)
    first = args.threads[0]
    for w in range(args.windows):
        line = f"window {w + 1} (to {best[first, w][1]} spheres): " + ", ".join(
            f"{t} thread(s) {best[t, w][0]:.2f} s" for t in args.threads)
        if len(args.threads) > 1:
            line += ", gain " + ", ".join(f"{best[first, w][0] / best[t, w][0]:.2f}" for t in args.threads[1:])
        print(line + " (shortest of the rounds)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
