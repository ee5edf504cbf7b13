"""CPU time of one step of a rig of one particle: the floor under every step, whatever the size.

    python -m benchmarks.one_particle_step              # 3 rounds of 400,000 steps (about 1 min)
    python -m benchmarks.one_particle_step --note "..."

The case is the incline twin's sled (``simulate.rigs.incline``, ``mode="sled"``: nine 6.6 mm
spheres glued in one rigid body, 1200 kg/m3, G 1.04 MPa) resting on the steel plate under a
gravity tilted by 6 deg, stepped in chunks of 1,000 steps (the rig's own chunks are 130). The
contacts, the kick and the list checks of nine spheres cost little; what a step costs beyond
them is the step loop's fixed work, which the incline and drop twins (hundreds of thousands of
steps each) pay at every step. CPU time is read in the process (``time.process_time``), so a
machine whose speed drifts moves it less than wall time; compare rows taken one after the other.

Outputs: ``benchmarks/results/one_particle_step_<UTC time>.json`` and one row appended to the
table of ``benchmarks/RESULTS.md``.
"""

from __future__ import annotations

import argparse
import datetime as dt
import math
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

HEADING = "\n## One-particle step\n"
SECTION = (HEADING + "\nOne row per run of `benchmarks/one_particle_step.py`: the incline twin's "
           "sled of nine spheres at rest on the steel plate, chunks of 1,000 steps, one core; CPU "
           "time per step in the process.\n\n| date (UTC) | machine | versions | note | rounds x steps | "
           "CPU per step, each round [us] | median [us] |\n|" + "---|" * 7 + "\n")


def sled_on_plate():
    """The sled of the incline twin at rest on its plate, ready to step."""
    import numpy as np

    from demcal.simulate.engine import Simulation
    from demcal.simulate.params import DEMParameters, parse_shape
    from demcal.simulate.rigs.incline import PARTICLE, sled_template
    from demcal.simulate.rigs.surfaces import make_surface
    from demcal.simulate.timestep import material_time_step
    from demcal.simulate.walls import Plane

    params = replace(DEMParameters(), shape=parse_shape("sphere:0.0066"), particle_density_kg_m3=1200.0,
                     shear_modulus_pa=1.04e6, dt=None)
    surface = make_surface(params, "steel")
    tpl = sled_template(params.template())
    tilt = math.radians(6.0)
    sim = Simulation(surface.materials, domain_lo=(-0.05, -0.1, -0.02), domain_hi=(0.2, 0.1, 0.1),
                     dt=material_time_step(params), gravity=(9.81 * math.sin(tilt), 0.0, -9.81 * math.cos(tilt)))
    tid = sim.add_template(tpl)
    sim.add_wall(Plane((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), material=surface.plate_material, name="plate"))
    rel = tpl.centres - tpl.centre_of_mass
    sim.add_clump(tid, position=(0.0, 0.0, -float(np.min(rel[:, 2] - tpl.radii))), material=PARTICLE)
    sim.chunk_steps = 1000
    return sim


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.one_particle_step",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3, help="timed rounds (default 3)")
    parser.add_argument("--steps", type=int, default=400_000, help="steps a round (default 400,000)")
    add_output_options(parser)
    args = parser.parse_args(argv)
    if args.rounds < 1 or args.steps < 1000:
        parser.error("--rounds must be >= 1 and --steps >= 1000")
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")

    now = dt.datetime.now(dt.timezone.utc)
    sim = sled_on_plate()
    sim.run(n_steps=1000)                     # kernels compiled or loaded, not timed
    per_step = []
    for _ in range(args.rounds):
        cpu0 = time.process_time()
        sim.run(n_steps=args.steps)
        per_step.append((time.process_time() - cpu0) / args.steps * 1e6)
    median = sorted(per_step)[len(per_step) // 2]
    doc = {"date": now.isoformat(timespec="seconds"), "note": args.note, "rounds": args.rounds,
           "steps": args.steps, "cpu_us_per_step": per_step, "median_us": median,
           "command": [sys.executable, "-m", "benchmarks.one_particle_step", *(argv or sys.argv[1:])],
           "machine": machine(), "versions": versions()}
    json_path = write_json(args.results / f"one_particle_step_{now.strftime('%Y%m%dT%H%M%SZ')}.json", doc)
    v = doc["versions"]
    row = (f"| {doc['date']} | {doc['machine']['cpu']}, {doc['machine']['cores']} cores | "
           f"demcal {v['demcal']} ({(v['git_sha'] or '?')[:12]}), numba {v['numba']} | "
           f"{args.note or '-'} | {args.rounds} x {args.steps:,} | "
           f"{', '.join(f'{x:.2f}' for x in per_step)} | {median:.2f} |\n")
    add_table_row(args.results_md, HEADING, SECTION, row)
    print(f"CPU per step: {', '.join(f'{x:.2f}' for x in per_step)} us (median {median:.2f} us)")
    print(f"written: {json_path} and a row in {args.results_md}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
