"""demcal and LIGGGHTS-PUBLIC 3.8 side by side at several sizes in one run, fill and settled phases apart.

For each size and round, one run after the other (never two at once): demcal on one core and
LIGGGHTS on one rank, then demcal on ``--cores`` threads and LIGGGHTS on as many MPI ranks. The
cases are those of ``benchmarks/dem_scaling.py`` and ``benchmarks/liggghts_scaling.py``: the
paper's carton scaled in x and y to the number of spheres (the fill depth kept), segments
inserted over the first ``--fill-time`` seconds, the *fill* phase the first 0.6 s simulated and
the *settled* phase the 0.15 s after it. Both codes' sphere-steps are counted over the spheres
present at each step. demcal's one-core run is its own choice by size kept to one thread; its
``--cores`` run sets that many threads.

Printed, and with ``--record`` appended to ``benchmarks/RESULTS.md`` as a section of its own:

- per size and core count: each code's fill and settled sphere-steps per second and their
  ratio, and each code's list builds per 1000 steps in either phase;
- each code's speed-up on ``--cores`` cores (fill plus settled wall time), round by round;
- demcal's settled throughput at each size against that at the first size (one core), and its
  fill throughput and rebuild rate against its settled ones.

Every number, with the machine, versions and date, goes to
``benchmarks/results/scaling_vs_liggghts_<UTC time>.json``.

    python -m benchmarks.scaling_vs_liggghts                            # 2,500, 20,000, 100,000 spheres
    python -m benchmarks.scaling_vs_liggghts --spheres 2500 20000 --rounds 3 --record
    python -m benchmarks.scaling_vs_liggghts --spheres 1000 --fill-time 0.05 --fill-phase 0.06 \\
        --settled-phase 0.02                                            # a smoke test of a few seconds

Without LIGGGHTS (``apt-get install liggghts``) the demcal side runs alone.
"""

from __future__ import annotations

import argparse
import datetime as dt
import math
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks import dem_scaling, liggghts_scaling  # noqa: E402
from benchmarks.repose_vs_liggghts import machine, versions  # noqa: E402
from demcal.jsonio import write_json  # noqa: E402
from demcal.simulate.liggghts.run import LiggghtsUnavailable  # noqa: E402
from demcal.simulate.scenes import compile_kernels  # noqa: E402


def demcal_run(n_spheres: int, cores: int, args) -> dict:
    threads = None if cores == 1 else cores
    t0 = time.perf_counter()
    row = dem_scaling.case(n_spheres, args.fill_time, args.seed, threads, args.fill_phase, args.settled_phase)
    row["elapsed_s"] = time.perf_counter() - t0
    for p in ("fill", "settled"):
        row[p]["builds_per_1000_steps"] = row[p]["pair_rebuilds_per_1000_steps"]
    return row


def liggghts_run(n_spheres: int, cores: int, args) -> dict:
    row = liggghts_scaling.run_case(n_spheres, cores, args, args.workdir / f"{n_spheres}_spheres_{cores}_ranks")
    for p in ("fill", "settled"):
        row[p]["builds_per_1000_steps"] = row[p]["neighbour_builds_per_1000_steps"]
    return row


def run_seconds(row: dict) -> float:
    return row["fill"]["wall_s"] + row["settled"]["wall_s"]


def _fmt(x: float) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{x:.3g}"


def table(runs: list) -> str:
    """Markdown table, a line per size, core count and round."""
    head = ("| round | spheres | cores | fill demcal | fill LIGGGHTS | ratio | settled demcal | settled LIGGGHTS "
            "| ratio | builds per 1000 steps, fill / settled: demcal | LIGGGHTS |\n|" + "---|" * 11 + "\n")
    lines = []
    for r in runs:
        d, g = r["demcal"], r.get("liggghts")
        cells = [str(r["round"] + 1), f"{r['spheres']:,}", str(r["cores"])]
        for p in ("fill", "settled"):
            a = d[p]["sphere_steps_per_s"]
            b = g[p]["sphere_steps_per_s"] if g else math.nan
            cells += [_fmt(a), _fmt(b), f"{a / b:.2f}" if g else "-"]
        cells.append(f"{d['fill']['builds_per_1000_steps']:.0f} / {d['settled']['builds_per_1000_steps']:.0f}")
        cells.append(f"{g['fill']['builds_per_1000_steps']:.0f} / {g['settled']['builds_per_1000_steps']:.0f}"
                     if g else "-")
        lines.append("| " + " | ".join(cells) + " |")
    return head + "\n".join(lines) + "\n"


def ratio_lines(runs: list, cores: int) -> list[str]:
    """The ratios the performance acceptance reads, round by round, with median and range."""
    found: dict[str, list[float]] = {}

    def add(name, value):
        found.setdefault(name, []).append(value)

    rounds = sorted({r["round"] for r in runs})
    sizes = sorted({r["spheres"] for r in runs})
    for k in rounds:
        one = {r["spheres"]: r for r in runs if r["round"] == k and r["cores"] == 1}
        many = {r["spheres"]: r for r in runs if r["round"] == k and r["cores"] == cores}
        for n in sizes:
            if n in one and n in many and cores > 1:
                for code in ("demcal", "liggghts"):
                    if one[n].get(code) and many[n].get(code):
                        add(f"{code} at {n:,} spheres, {cores} cores / 1: the run faster",
                            run_seconds(one[n][code]) / run_seconds(many[n][code]))
            if n in one:
                d = one[n]["demcal"]
                add(f"demcal at {n:,} spheres, one core: fill / settled throughput",
                    d["fill"]["sphere_steps_per_s"] / d["settled"]["sphere_steps_per_s"])
                add(f"demcal at {n:,} spheres, one core: fill / settled rebuild rate",
                    d["fill"]["builds_per_1000_steps"] / max(d["settled"]["builds_per_1000_steps"], 1e-9))
            if n in one and n != sizes[0] and sizes[0] in one:
                add(f"demcal settled throughput at {n:,} spheres / at {sizes[0]:,} (one core)",
                    one[n]["demcal"]["settled"]["sphere_steps_per_s"]
                    / one[sizes[0]]["demcal"]["settled"]["sphere_steps_per_s"])
    return dem_scaling.round_by_round(found)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.scaling_vs_liggghts",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--spheres", type=int, nargs="+", default=[2500, 20000, 100000])
    parser.add_argument("--cores", type=int, default=2, help="threads and MPI ranks of the second run (1: none)")
    parser.add_argument("--rounds", type=int, default=1, help="run every case this many times, in turn")
    parser.add_argument("--fill-time", type=float, default=0.5, help="insertion window [s]")
    parser.add_argument("--fill-phase", type=float, default=dem_scaling.FILL_PHASE,
                        help="simulated time of the fill phase [s]")
    parser.add_argument("--settled-phase", type=float, default=dem_scaling.SETTLED_PHASE,
                        help="simulated time of the settled phase [s]")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--skip-liggghts", action="store_true")
    parser.add_argument("--record", action="store_true", help="append the table and ratios to RESULTS.md")
    parser.add_argument("--workdir", type=Path, default=HERE / "results" / "tmp" / "scaling_vs_liggghts",
                        help="parent of LIGGGHTS' run folders")
    args = parser.parse_args(argv)
    if args.cores < 1 or args.rounds < 1 or min(args.spheres) < 1000:
        parser.error("--cores and --rounds must be >= 1, --spheres >= 1000 (the scaled carton's fill region)")
    for name in ("fill_time", "fill_phase", "settled_phase"):
        if not (getattr(args, name) > 0 and math.isfinite(getattr(args, name))):
            parser.error(f"--{name.replace('_', '-')} must be > 0")

    use_liggghts = not args.skip_liggghts
    core_counts = [1] if args.cores == 1 else [1, args.cores]
    compile_kernels(threaded=True)   # every kernel a demcal case may use, before any timing
    runs = []
    for k in range(args.rounds):
        for n in args.spheres:
            for cores in core_counts:
                entry = {"round": k, "spheres": n, "cores": cores, "demcal": demcal_run(n, cores, args)}
                if use_liggghts:
                    try:
                        entry["liggghts"] = liggghts_run(n, cores, args)
                    except LiggghtsUnavailable as exc:
                        print(f"LIGGGHTS skipped: {exc}")
                        use_liggghts = False
                runs.append(entry)
                d, g = entry["demcal"], entry.get("liggghts")
                print(f"round {k + 1}, {n:>7} spheres, {cores} core(s) | demcal fill "
                      f"{_fmt(d['fill']['sphere_steps_per_s'])}, settled {_fmt(d['settled']['sphere_steps_per_s'])}"
                      + (f" | LIGGGHTS fill {_fmt(g['fill']['sphere_steps_per_s'])}, settled "
                         f"{_fmt(g['settled']['sphere_steps_per_s'])}" if g else ""), flush=True)
    text = table(runs)
    lines = ratio_lines(runs, args.cores)
    print()
    print(text)
    print("\n".join(lines))

    stamp = dt.datetime.now(dt.timezone.utc)
    info = machine()
    out = HERE / "results" / f"scaling_vs_liggghts_{stamp:%Y%m%dT%H%M%SZ}.json"
    liggghts_version = liggghts_scaling.package_version() if use_liggghts else None
    write_json(out, {"machine": info, "versions": {**versions(), "liggghts": liggghts_version,
                                                   "mpi": liggghts_scaling.mpi_version() if use_liggghts else None},
                     "date": stamp.isoformat(timespec="seconds"),
                     "arguments": vars(args) | {"workdir": str(args.workdir)},
                     "runs": runs, "ratios": lines})
    print(f"written: {out}")
    if args.record:
        v = versions()
        block = (f"\n### {stamp:%Y-%m-%d %H:%M} UTC, {info['cpu']}, {info['cores']} cores: "
                 f"demcal {v['demcal']} ({v['git_sha'][:7]}), numba {v['numba']}, LIGGGHTS {liggghts_version}\n\n"
                 f"`python -m benchmarks.scaling_vs_liggghts {' '.join(sys.argv[1:] if argv is None else argv)}`; "
                 f"sphere-steps per second (spheres present at each step); `{out.name}`.\n\n"
                 + text + "\n" + "\n".join(f"- {line}" for line in lines) + "\n")
        with open(HERE / "RESULTS.md", "a") as fh:
            fh.write(block)
        print(f"appended to {HERE / 'RESULTS.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
