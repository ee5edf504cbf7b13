"""Wall time of the drop rig's twin (``simulate.rigs.drop.run_drop``), as the critique runs it.

    python -m benchmarks.drop_rig                 # 40 drops (about 1 min)
    python -m benchmarks.drop_rig --drops 10      # a quick check

The case is the critique's full drop twin (``analyse.critique.twins``): one five-sphere segment
released at a random orientation (seeds 0 .. drops-1) from the paper's 400 mm onto the steel
plate, with the default parameters (the automatic time step, t_c / 100). A first drop, not
timed, compiles or loads the kernels and builds the segment. Every drop is then timed on its
own, one after the other in this process (one core): wall and CPU time per drop, their mean,
median and maximum (a segment landing nearly flat rocks on the plate and costs the most), the
engine's steps and the rig's records per drop, and the mean apparent restitution as a check
that the drops did what they should.

Outputs: ``benchmarks/results/drop_rig_<UTC time>.json`` (every drop, machine, versions) and one
row appended to the drop rig's table in ``benchmarks/RESULTS.md``.
"""

from __future__ import annotations

import argparse
import datetime as dt
import os
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from benchmarks.repose_vs_liggghts import machine, versions  # noqa: E402
from demcal.jsonio import write_json  # noqa: E402

#: Heading and header of the drop rig's table in RESULTS.md.
RESULTS_MD_SECTION = (
    "\n## Drop rig\n\nOne row per run of `benchmarks/drop_rig.py`: the critique's drop twin "
    "(random orientation, 400 mm, steel plate, default parameters), one drop after another on "
    "one core; times per drop.\n\n"
    "| date (UTC) | machine | versions | note | drops | wall mean / median / max [s] | "
    "CPU mean [s] | steps mean | records mean | mean apparent e | load average |\n|"
    + "---|" * 11 + "\n")


def run_drops(n_drops: int, height: float) -> list:
    """Time ``n_drops`` drops (seeds 0 .. n_drops - 1) after an untimed first one."""
    from demcal.simulate.params import DEMParameters
    from demcal.simulate.rigs import run_rig

    params = DEMParameters()
    run_rig("drop", params, 0, height=height)      # kernels and segment, not timed
    out = []
    for seed in range(n_drops):
        cpu0, t0 = time.process_time(), time.perf_counter()
        res = run_rig("drop", params, seed, height=height)
        wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
        obs = {k: (v if np.isfinite(v) else None) for k, v in res.observable.items()}
        out.append({"seed": seed, "wall_s": wall, "cpu_s": cpu, "steps": res.meta["steps"],
                    "records": int(res.record["t"].size), "dt": res.meta["dt"],
                    "orientation_deg": obs["orientation_deg"],
                    "apparent_restitution": obs["apparent_restitution"],
                    "velocity_ratio": obs["velocity_ratio"],
                    "rotational_energy_share": obs["rotational_energy_share"]})
        print(f"seed {seed:3d}: {wall:6.3f} s (CPU {cpu:6.3f} s), {res.meta['steps']:6d} steps, "
              f"{out[-1]['records']:5d} records, axis {obs['orientation_deg']:5.1f} deg, "
              f"apparent e {res.observable['apparent_restitution']:.4f}", flush=True)
    return out


def summarise(drops: list) -> dict:
    wall = np.array([d["wall_s"] for d in drops])
    e_app = [np.nan if d["apparent_restitution"] is None else d["apparent_restitution"] for d in drops]
    return {"drops": len(drops), "wall_mean_s": float(wall.mean()),
            "wall_median_s": float(np.median(wall)), "wall_max_s": float(wall.max()),
            "wall_total_s": float(wall.sum()),
            "cpu_mean_s": float(np.mean([d["cpu_s"] for d in drops])),
            "steps_mean": float(np.mean([d["steps"] for d in drops])),
            "records_mean": float(np.mean([d["records"] for d in drops])),
            "apparent_restitution_mean": float(np.nanmean(e_app))}


def results_row(doc: dict) -> str:
    s, m, v = doc["summary"], doc["machine"], doc["versions"]
    load = m.get("load_avg")
    cells = [doc["date"], f"{m['cpu']}, {m['cores']} cores",
             f"demcal {v['demcal']} ({(v['git_sha'] or '?')[:12]}), numba {v['numba']}",
             doc.get("note") or "-", str(s["drops"]),
             f"{s['wall_mean_s']:.3f} / {s['wall_median_s']:.3f} / {s['wall_max_s']:.2f}",
             f"{s['cpu_mean_s']:.3f}", f"{s['steps_mean']:.0f}", f"{s['records_mean']:.0f}",
             f"{s['apparent_restitution_mean']:.4f}",
             " / ".join(f"{x:.1f}" for x in load) if load else "-"]
    return "| " + " | ".join(cells) + " |\n"


def add_output_options(parser: argparse.ArgumentParser) -> None:
    """The options a benchmark that adds a row to ``RESULTS.md`` shares: note, JSON folder, table."""
    parser.add_argument("--note", default="", help="free text for the table's note column")
    parser.add_argument("--results", type=Path, default=HERE / "results", help="folder of the JSON output")
    parser.add_argument("--results-md", type=Path, default=HERE / "RESULTS.md",
                        help="the file whose table the row is added to")


def add_table_row(md: Path, heading: str, section: str, row: str) -> None:
    """Add ``row`` at the end of the table under ``heading`` in ``md`` (the section ``section``
    appended first if it is not there), whatever sections follow it."""
    text = md.read_text() if md.exists() else "# Benchmark results\n"
    if heading not in text:
        text = text.rstrip("\n") + "\n" + section
    lines = text.splitlines(keepends=True)
    at = next(i for i, line in enumerate(lines) if line.rstrip("\n") == heading.strip("\n"))
    at += 1
    while at < len(lines) and not lines[at].startswith("|"):
        at += 1
    while at < len(lines) and lines[at].startswith("|"):
        at += 1
    lines.insert(at, row)
    md.write_text("".join(lines))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.drop_rig",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--drops", type=int, default=40, help="number of drops (default 40)")
    parser.add_argument("--height", type=float, default=0.4, help="drop height [m] (default 0.4)")
    add_output_options(parser)
    args = parser.parse_args(argv)
    if args.drops < 1:
        parser.error(f"--drops must be >= 1, got {args.drops}")
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")

    now = dt.datetime.now(dt.timezone.utc)
    stamp = now.strftime("%Y%m%dT%H%M%SZ")
    doc = {"date": now.isoformat(timespec="seconds"), "height_m": args.height, "note": args.note,
           "command": [sys.executable, "-m", "benchmarks.drop_rig", *(argv or sys.argv[1:])],
           "machine": machine(), "versions": versions()}
    print(f"machine: {doc['machine']['cpu']}, {doc['machine']['cores']} cores", flush=True)
    doc["drops"] = run_drops(args.drops, args.height)
    doc["summary"] = s = summarise(doc["drops"])
    doc["machine"]["load_avg"] = list(os.getloadavg()) if hasattr(os, "getloadavg") else None
    json_path = write_json(args.results / f"drop_rig_{stamp}.json", doc)
    md = args.results_md
    add_table_row(md, "\n## Drop rig\n", RESULTS_MD_SECTION, results_row(doc))
    print(f"{s['drops']} drops: wall per drop mean {s['wall_mean_s']:.3f} s, median "
          f"{s['wall_median_s']:.3f} s, max {s['wall_max_s']:.2f} s (total {s['wall_total_s']:.1f} s); "
          f"CPU mean {s['cpu_mean_s']:.3f} s; mean apparent e {s['apparent_restitution_mean']:.4f}")
    print(f"written: {json_path} and a row in {md}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
