"""The paper's repose case as whole processes: demcal's and LIGGGHTS-PUBLIC 3.8's, timed from
outside, in turn.

    python -m benchmarks.whole_process                 # 4 pairs, seed 1, 10 s simulated
    python -m benchmarks.whole_process --rounds 6 --seed 2
    python -m benchmarks.whole_process --fresh         # each demcal process compiles its kernels

``benchmarks/repose_vs_liggghts.py`` compares the time-step loops; this times what a user
waits for. demcal's process: the interpreter's start, the imports, the kernels loaded from
numba's cache (run ``demcal compile`` first, or the first process compiles them), the case set
up, filled, lifted and run to its end, and the heap read (``run_demcal``). With ``--fresh``
each demcal process starts from an empty cache of its own (``NUMBA_CACHE_DIR``), as the first
command of a fresh environment: it compiles the kernels it runs. LIGGGHTS' process:
``liggghts -in in.repose`` on the same deck (``simulate.liggghts.deck.write_deck``), to its
exit. One core each (``NUMBA_NUM_THREADS=1``, ``OMP_NUM_THREADS=1``), never both at once.
The two processes of a round run one after the other and their ratio is taken round by round
(a machine whose speed drifts moves both of a pair); the summary is the median and range of
those ratios.

Output: ``benchmarks/results/whole_process_<UTC time>.json`` (``whole_process_fresh_...`` with
``--fresh``).
"""

from __future__ import annotations

import argparse
import datetime as dt
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks.repose_vs_liggghts import machine, versions  # noqa: E402
from demcal.jsonio import write_json  # noqa: E402

#: demcal's process: the benchmark case's run by ``run_demcal`` (seed and duration filled in).
DEMCAL_SCRIPT = """
import sys
sys.path.insert(0, {root!r})
from benchmarks.repose_vs_liggghts import benchmark_parameters, run_demcal
run = run_demcal({seed}, {duration}, benchmark_parameters())
print(run["angle_deg"])
"""


def timed(cmd: list[str], cwd: Path, env: dict) -> float:
    """Wall seconds of ``cmd`` from its start to its exit (it must succeed)."""
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-3:]
        raise SystemExit(f"{cmd[0]} failed (exit {proc.returncode}): {' / '.join(tail)}")
    return wall


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.whole_process", description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=4, help="pairs of processes (default 4)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--duration", type=float, default=10.0, help="simulated time [s] (default 10)")
    parser.add_argument("--fresh", action="store_true",
                        help="each demcal process starts from an empty numba cache (it compiles its kernels)")
    parser.add_argument("--results", type=Path, default=HERE / "results", help="folder of the JSON output")
    args = parser.parse_args(argv)
    if args.rounds < 1:
        parser.error(f"--rounds must be >= 1, got {args.rounds}")

    from demcal.simulate.liggghts.deck import write_deck
    from demcal.simulate.liggghts.run import find_liggghts, liggghts_command

    exe = find_liggghts(None)
    if exe is None:
        raise SystemExit("LIGGGHTS not found; install the Debian package: apt-get install liggghts")
    env = dict(os.environ, NUMBA_NUM_THREADS="1", OMP_NUM_THREADS="1")
    now = dt.datetime.now(dt.timezone.utc)
    doc = {"date": now.isoformat(timespec="seconds"), "seed": args.seed, "duration": args.duration,
           "fresh_numba_cache": args.fresh, "machine": machine(), "versions": versions(), "rounds": []}
    print(f"machine: {doc['machine']['cpu']}, {doc['machine']['cores']} cores", flush=True)
    demcal_cmd = [sys.executable, "-c", DEMCAL_SCRIPT.format(root=str(ROOT), seed=args.seed,
                                                             duration=args.duration)]
    with tempfile.TemporaryDirectory(prefix="demcal-whole-process-") as tmp:
        deck = write_deck(Path(tmp), args.seed, args.duration)
        liggghts_cmd = liggghts_command(exe, deck)
        for k in range(args.rounds):
            cache = {"NUMBA_CACHE_DIR": str(Path(tmp) / f"numba-cache-{k}")} if args.fresh else {}
            demcal_s = timed(demcal_cmd, ROOT, dict(env, **cache))
            liggghts_s = timed(liggghts_cmd, deck.workdir, env)
            doc["rounds"].append({"demcal_s": demcal_s, "liggghts_s": liggghts_s, "ratio": liggghts_s / demcal_s})
            print(f"round {k + 1}: demcal {demcal_s:.1f} s, LIGGGHTS {liggghts_s:.1f} s, "
                  f"ratio {liggghts_s / demcal_s:.2f}", flush=True)
    ratios = [r["ratio"] for r in doc["rounds"]]
    doc["summary"] = {"median_ratio": statistics.median(ratios), "min_ratio": min(ratios), "max_ratio": max(ratios),
                      "median_demcal_s": statistics.median(r["demcal_s"] for r in doc["rounds"]),
                      "median_liggghts_s": statistics.median(r["liggghts_s"] for r in doc["rounds"])}
    s = doc["summary"]
    fresh = " (demcal from an empty cache)" if args.fresh else ""
    print(f"whole processes{fresh}, LIGGGHTS / demcal: median {s['median_ratio']:.2f} ({s['min_ratio']:.2f}-"
          f"{s['max_ratio']:.2f}); demcal {s['median_demcal_s']:.1f} s, LIGGGHTS {s['median_liggghts_s']:.1f} s")
    args.results.mkdir(parents=True, exist_ok=True)
    kind = "whole_process_fresh" if args.fresh else "whole_process"
    out = args.results / f"{kind}_{now.strftime('%Y%m%dT%H%M%SZ')}.json"
    write_json(out, doc)
    print(f"written: {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
