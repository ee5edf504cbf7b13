"""Steps and CPU time of the calibration's incline twins started flat and started tilted.

    python -m benchmarks.incline_start              # two likelihood grids, 7 frictions each (about 1 min)
    python -m benchmarks.incline_start --note "..."

A calibration runs each sliding twin over a grid of its friction (``simulate.rigs.incline``,
``LIKELIHOOD_POINTS`` values). The cases are the segment of the paper sliding on steel and the
soybean sled (6.6 mm spheres, 1200 kg/m3, G 1.04 MPa) on steel, each at mu_s 0.2-0.6: once as
the lab tilts, from 0 (``run_incline``), and once as the calibration's task runs it, from 0.8
atan(mu_s) (``run_task``). The row gives the steps and CPU time of each grid and the largest
difference between the onsets read, which must stay within the tilt's 0.01 deg chunk.

Outputs: ``benchmarks/results/incline_start_<UTC time>.json`` and one row per case appended to
the table of ``benchmarks/RESULTS.md``.
"""

from __future__ import annotations

import argparse
import datetime as dt
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks.drop_rig import add_output_options, add_table_row  # noqa: E402
from benchmarks.repose_vs_liggghts import machine, versions  # noqa: E402
from demcal.jsonio import write_json  # noqa: E402

HEADING = "\n## Incline twins: flat and tilted start\n"
SECTION = (HEADING + "\nOne row per case and run of `benchmarks/incline_start.py`: a likelihood grid "
           "of 7 static frictions (0.2-0.6) on steel, run from a flat plate and from 0.8 atan(mu_s); "
           "one core, CPU time in the process.\n\n| date (UTC) | machine | versions | note | case | "
           "steps flat / tilted | CPU flat / tilted [s] | largest onset difference [deg] |\n|"
           + "---|" * 8 + "\n")
FRICTIONS = (0.2, 0.267, 0.333, 0.4, 0.467, 0.533, 0.6)


def cases():
    """(name, parameters, mode) of each grid."""
    from demcal.simulate.params import DEMParameters, parse_shape

    sled = replace(DEMParameters(), shape=parse_shape("sphere:0.0066"), particle_density_kg_m3=1200.0,
                   shear_modulus_pa=1.04e6, dt=None)
    return [("paper segment, slide", DEMParameters(), "slide"), ("soybean sled", sled, "sled")]


def grid(params, mode) -> dict:
    """Steps, CPU time and onsets of the grid run flat and run tilted."""
    from demcal.simulate.rigs.incline import run_incline, run_task, task

    out = {"flat_steps": 0, "tilted_steps": 0, "flat_cpu_s": 0.0, "tilted_cpu_s": 0.0, "onsets": []}
    for mu in FRICTIONS:
        p = params.with_(mu_s_pw=mu)
        cpu0 = time.process_time()
        flat = run_incline(p, mode=mode, surface="steel")
        cpu1 = time.process_time()
        tilted = run_task(task(p, mode, "steel"))
        cpu2 = time.process_time()
        out["flat_steps"] += flat.meta["steps"]
        out["tilted_steps"] += tilted["steps"]
        out["flat_cpu_s"] += cpu1 - cpu0
        out["tilted_cpu_s"] += cpu2 - cpu1
        out["onsets"].append((mu, flat.observable["slide_angle_deg"], tilted["observable"]["slide_angle_deg"]))
    out["largest_difference_deg"] = max(abs(a - b) for _, a, b in out["onsets"])
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.incline_start",
                                     description=__doc__.splitlines()[0])
    add_output_options(parser)
    args = parser.parse_args(argv)
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")
    from demcal.simulate.rigs.incline import run_incline

    now = dt.datetime.now(dt.timezone.utc)
    run_incline(cases()[0][1], max_tilt_deg=0.5)      # kernels compiled or loaded, not timed
    doc = {"date": now.isoformat(timespec="seconds"), "note": args.note, "frictions": FRICTIONS,
           "cases": {}, "command": [sys.executable, "-m", "benchmarks.incline_start", *(argv or sys.argv[1:])],
           "machine": machine(), "versions": versions()}
    v = doc["versions"]
    for name, params, mode in cases():
        r = doc["cases"][name] = grid(params, mode)
        row = (f"| {doc['date']} | {doc['machine']['cpu']}, {doc['machine']['cores']} cores | "
               f"demcal {v['demcal']} ({(v['git_sha'] or '?')[:12]}), numba {v['numba']} | "
               f"{args.note or '-'} | {name} | {r['flat_steps']:,} / {r['tilted_steps']:,} | "
               f"{r['flat_cpu_s']:.2f} / {r['tilted_cpu_s']:.2f} | {r['largest_difference_deg']:.4f} |\n")
        add_table_row(args.results_md, HEADING, SECTION, row)
        print(f"{name}: steps {r['flat_steps']:,} flat, {r['tilted_steps']:,} tilted; CPU "
              f"{r['flat_cpu_s']:.2f} s against {r['tilted_cpu_s']:.2f} s; onsets differ by at most "
              f"{r['largest_difference_deg']:.4f} deg")
    json_path = write_json(args.results / f"incline_start_{now.strftime('%Y%m%dT%H%M%SZ')}.json", doc)
    print(f"written: {json_path} and rows in {args.results_md}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
