"""DEM throughput on the paper's repose case, in sphere-steps per second on one core.

The case (the one LIGGGHTS-PUBLIC 3.8 runs side by side): carton 200 x 100 x 250 mm on an
infinite steel floor, 500 five-sphere segments (r = 5.5 mm over 25 mm) inserted in the first
second, the end plate lifted at 0.1 m/s from t = 4 s, 10 s at dt = 7.43678e-5 s; clump mass and
inertia of an 11 x 25 mm cylinder at 912 kg/m3, G = 1e7 Pa, nu = 0.25; particle-particle
e 0.32, mu_s 0.65, mu_r 0.53; particle-steel e 0.36, mu_s 0.22, mu_r 0.15.

    python benchmarks/dem_throughput.py                 # the full 10 s case
    python benchmarks/dem_throughput.py --duration 2    # shorter, while tuning

Prints the time to the first step (imports, scene, kernel load or compile), then the wall and
CPU time of the simulation and two throughputs: sphere-steps per second counting the spheres
present at each step (the carton fills during the first second), and the figure LIGGGHTS'
number is quoted in, all 2500 spheres times the steps over the wall time (LIGGGHTS-PUBLIC 3.8:
2500 x 134 467 / 69 s = 4.9e6 on one core of this machine). Last a sanity summary: segments
outside the carton, escapes, kinetic energy over time.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

T_START = time.perf_counter()

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numpy as np  # noqa: E402

from demcal.simulate.params import DEMParameters  # noqa: E402
from demcal.simulate.scenes import PAPER_DURATION, build_paper_repose_case  # noqa: E402

#: The LIGGGHTS benchmark's parameters (the paper's calibrated values, cylinder mass model).
BENCHMARK_PARAMETERS = dict(e_pp=0.32, e_pw=0.36, mu_s_pw=0.22, mass_model="cylinder")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=PAPER_DURATION, help="simulated time [s]")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--n-clumps", type=int, default=500)
    parser.add_argument("--rolling-lever", default="liggghts_reff")
    parser.add_argument("--vtk", default=None, help="write the final frame to this .vtp file")
    args = parser.parse_args(argv)

    params = DEMParameters().with_(rolling_lever=args.rolling_lever, **BENCHMARK_PARAMETERS)
    sim = build_paper_repose_case(params, seed=args.seed, n_clumps=args.n_clumps)
    ke_trace = []

    def progress(s):
        ke_trace.append((s.time, s.kinetic_energy()))

    # one step first, so that loading (or compiling) the kernels is timed apart from simulating
    first = sim.run(n_steps=1)
    t_ready = time.perf_counter() - T_START
    print(f"ready to simulate after {t_ready:.2f} s (imports, scene, kernel load or compile)")
    cpu0 = time.process_time()
    summary = sim.run(duration=max(args.duration - sim.time, 0.0), progress=progress)
    cpu = time.process_time() - cpu0
    steps = summary.steps + first.steps
    full = sim.templates[0].n_spheres * args.n_clumps
    print(f"simulated {sim.time:.3f} s in {steps} steps, {sim.n_spheres} spheres at the end")
    print(f"wall time {summary.wall_time:.1f} s (CPU {cpu:.1f} s), "
          f"{summary.n_rebuilds} sphere-list rebuilds, {sim.total_wall_rebuilds} wall-list rebuilds")
    print(f"  {summary.sphere_steps_per_second:.3e} sphere-steps/s (spheres present at each step)")
    print(f"  {full * summary.steps / summary.wall_time:.3e} sphere-steps/s as LIGGGHTS is quoted "
          f"({full} spheres x steps / wall time); {full * summary.steps / cpu:.3e} per CPU second")

    x = sim.positions()
    act = sim.active()
    outside = int(((x[:, 0] > 0.200) & act).sum())
    plate = sim.wall_origins()[sim.wall_index("end plate")]
    print(f"segments outside the carton (x > 200 mm): {outside} of {sim.n_bodies}; "
          f"escaped the domain: {len(sim.escaped)}; end plate bottom at z = {plate[2] - 0.125:.3f} m")
    if ke_trace:
        times, ke = np.array(ke_trace).T
        for t_mark in (1.0, 4.0, 5.0, 7.0, 10.0):
            k = np.searchsorted(times, t_mark - 1e-9)
            if k < len(times):
                print(f"  kinetic energy at t = {times[k]:.2f} s: {ke[k]:.3e} J")
    if args.vtk:
        from demcal.simulate.vtk import write_vtp
        write_vtp(args.vtk, sim)
        print(f"final frame written to {args.vtk}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
