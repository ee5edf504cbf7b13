"""Where a settled bed's step goes, kernel by kernel, at each size.

The carton of ``dem_scaling.py`` is filled for its 0.6 s (on every thread: the state is the same
on any number of them), then its settled phase (0.15 s) runs on one thread, as there, for the
phase's throughput, its pair-list rebuilds and the near-pair margin it ends with. On the state
it leaves, each kernel of a step is then timed alone, on one thread (the serial kernels, the
shortest of 15 rounds: the machine this was written on has windows of tens of milliseconds in
which a core runs about 1.45 times slower, and a kernel timed in rounds of a few milliseconds
may spend most of its rounds in one; ``benchmarks/RESULTS.md``): the contact forces over every
listed pair (as the settled phase visits them while its margin stays at the skin), with and
without asking for each pair's second sphere ``PREFETCH_AHEAD`` pairs ahead (in turn, round by
round), then over the pairs whose two spheres are within ``LOCAL_ROWS`` rows of each other in
memory and over the others apart (less the cost of a call with no pair: the wall contacts and
the zeroing of the sums); a pair-list rebuild; a near-pair selection; a kick and drift; the
sphere positions. Times are per sphere, or per pair, so that the sizes compare directly; the
step adds them up with the rebuilds and selections at the phase's rate, against the phase's own
time per step.

    python benchmarks/settled_step.py                      # 2,500 and 100,000 spheres
    python benchmarks/settled_step.py --spheres 2500 20000 100000 --json out.json
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numba
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from benchmarks.dem_scaling import FILL_PHASE, SETTLED_PHASE, scaled_carton  # noqa: E402
from benchmarks.repose_vs_liggghts import write_measurements  # noqa: E402
from demcal.simulate import engine  # noqa: E402
from demcal.simulate.forces import PREFETCH_AHEAD, contact_forces  # noqa: E402
from demcal.simulate.neighbours import build_pair_list_serial, select_near_pairs  # noqa: E402
from demcal.simulate.threads import threads_limited_to  # noqa: E402

#: Pairs whose spheres are at most this many rows apart count as near in memory.
LOCAL_ROWS = 200
#: Rounds of each timing (the shortest is given).
ROUNDS = 15


def shortest_time(fn, calls: int, rounds: int = ROUNDS) -> float:
    """Shortest over ``rounds`` of the mean time [s] of ``calls`` calls of ``fn`` (after one)."""
    fn()
    times = []
    for _ in range(rounds):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()
        times.append((time.perf_counter() - t0) / calls)
    return min(times)


def kernel_times(sim) -> dict:
    """Each step kernel of ``sim``'s state timed alone on one thread [s per call]."""
    B, S, W = sim._b, sim._s, sim._w
    pstart, ppi, pj, ph = sim._pairs
    wstart, ws, wk, wh = sim._wpairs
    pt = sim.materials.compile()
    _, inv_cell, dims, cell_start = sim._grid
    nb, ns = sim.n_bodies, sim.n_spheres
    near = np.arange(ppi.shape[0], dtype=np.int64)
    near_start = pstart.copy()
    wcv = np.zeros((max(ws.shape[0], 1), 3))
    unused = np.empty(0, np.int64), np.empty((0, 3)), np.empty((0, 3)), np.empty(0), np.empty((0, 3))
    calls = max(5, 200_000 // ns)

    def forces(ahead=0):
        contact_forces(*unused, near, near_start, wstart, sim.dt, sim.dt, sim._lever, pt.rolling_model,
                       pt.rolling_damping_ratio, pt.contact_effective_mass, ahead, nb, ns, B["bx"], B["bv"], B["bw"],
                       B["bR"], B["bf"], B["bt"], B["brm"], B["brv"], B["brn"], B["binvm"], B["binvi"], B["bmat"],
                       B["bcount"], S["sbody"], S["sx"], S["srad"], ppi, pj, ph, ws, wk, wh, W["kind"], W["origin"],
                       W["normal"], W["axis_u"], W["axis_v"], W["half"], wcv, W["material"], pt.e_star, pt.g_star,
                       pt.damping, pt.mu_s, pt.mu_r, pt.log_e, pt.e_exponent, pt.log_v_ref, pt.v_min)

    def visit(mask) -> int:
        chosen = np.flatnonzero(mask)
        near[:chosen.size] = chosen
        near_start[0] = 0
        near_start[1:] = np.cumsum(np.bincount(ppi[chosen], minlength=ns))
        return chosen.size

    out = {"pairs": int(ppi.shape[0]), "wall_pairs": int(ws.shape[0])}
    out["forces_all_s"] = shortest_time(forces, calls)
    # with and without the hints of the second spheres, in turn
    plain, hinted = [], []
    for _ in range(ROUNDS):
        plain.append(shortest_time(forces, calls, 1))
        hinted.append(shortest_time(lambda: forces(PREFETCH_AHEAD), calls, 1))
    out["forces_all_plain_s"], out["forces_all_prefetch_s"] = min(plain), min(hinted)
    apart = np.abs(pj - ppi)
    visit(np.zeros(ppi.shape[0], bool))
    out["forces_no_pair_s"] = shortest_time(forces, calls)
    for name, mask in (("local", apart < LOCAL_ROWS), ("far", apart >= LOCAL_ROWS)):
        out[f"{name}_pairs"] = visit(mask)
        out[f"forces_{name}_s"] = shortest_time(forces, calls)
    visit(np.ones(ppi.shape[0], bool))
    allow = S["sallow"].copy()
    out["rebuild_s"] = shortest_time(lambda: build_pair_list_serial(
        ns, S["sx"], S["srad"], S["sbody"], B["bactive"], sim.skin, sim.domain_lo, inv_cell, dims, cell_start,
        pstart, pj, ph, allow, 1), max(2, calls // 10))
    chosen, chosen_start = np.empty_like(near), np.empty_like(near_start)
    sxn, snear = S["sxn"].copy(), S["snear"].copy()
    out["select_s"] = shortest_time(lambda: select_near_pairs(
        ns, pstart, ppi, pj, ph, S["sx"], S["srad"], 0.25 * sim.skin, chosen, chosen_start, sxn, snear), calls)
    bodies = [B[k].copy() for k in ("bactive", "bx", "bv", "bq", "bL", "bw", "bR", "bf", "bt", "brm", "brv", "brn",
                                    "binvm", "binvi")]
    out["kick_s"] = shortest_time(lambda: engine._kick_drift(nb, sim.dt, 0.0, 0.0, 0.0, -9.81, 0, *bodies), calls)
    spheres = [S[k].copy() for k in ("sx", "sx0", "sxw", "sxn", "sallow", "swallow", "snear")]
    out["spheres_s"] = shortest_time(lambda: engine._update_spheres(
        ns, S["sbody"], S["soff"], B["bx"], B["bR"], B["bactive"], *spheres, 0.0), calls)
    return out


def case(n_spheres: int, fill_time: float, seed: int) -> dict:
    sim = scaled_carton(n_spheres, fill_time, seed)
    sim.run(duration=FILL_PHASE)
    with threads_limited_to(1):
        rebuilds = sim.total_rebuilds
        phase = sim.run(duration=SETTLED_PHASE)
        row = {"spheres": sim.n_spheres, "steps": phase.steps, "sphere_steps_per_s": phase.sphere_steps_per_second,
               "step_s": phase.wall_time / phase.steps, "pair_rebuilds": sim.total_rebuilds - rebuilds,
               "near_margin_over_skin": sim._near_fraction}
        numba.set_num_threads(1)
        row.update(kernel_times(sim))
    return row


def report(row: dict) -> list[str]:
    n, per = row["spheres"], 1e9 / row["spheres"]
    fixed = row["forces_no_pair_s"]
    rate = row["pair_rebuilds"] / row["steps"]
    step = (row["forces_all_s"] + row["kick_s"] + row["spheres_s"]
            + rate * (row["rebuild_s"] + row["select_s"]))
    lines = [f"{n:>7} spheres: settled {row['sphere_steps_per_s']:.3g} sphere-steps/s on one thread, "
             f"{row['pair_rebuilds']} rebuilds in {row['steps']} steps, near margin {row['near_margin_over_skin']:g} "
             f"of the skin; {row['pairs'] / n:.2f} pairs and {row['wall_pairs'] / n:.2f} wall pairs a sphere",
             f"  ns a sphere: forces {row['forces_all_s'] * per:.1f} (of which no-pair part {fixed * per:.1f}), "
             f"kick {row['kick_s'] * per:.1f}, positions {row['spheres_s'] * per:.1f}, "
             f"rebuild {row['rebuild_s'] * per:.0f} (x {rate:.3f} a step), "
             f"selection {row['select_s'] * per:.1f}",
             f"  forces with the second spheres asked for {PREFETCH_AHEAD} pairs ahead: "
             f"{row['forces_all_prefetch_s'] * 1e3:.3f} ms against {row['forces_all_plain_s'] * 1e3:.3f} ms "
             f"({row['forces_all_prefetch_s'] / row['forces_all_plain_s']:.2f})",
             f"  ns a pair: all {(row['forces_all_s'] - fixed) / row['pairs'] * 1e9:.1f}, "
             f"within {LOCAL_ROWS} rows {(row['forces_local_s'] - fixed) / max(row['local_pairs'], 1) * 1e9:.1f} "
             f"({row['local_pairs'] / row['pairs']:.0%} of them), "
             f"others {(row['forces_far_s'] - fixed) / max(row['far_pairs'], 1) * 1e9:.1f}",
             f"  a step: the kernels add up to {step * per:.0f} ns a sphere, the phase took "
             f"{row['step_s'] * per:.0f}"]
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spheres", type=int, nargs="+", default=[2500, 100000])
    parser.add_argument("--fill-time", type=float, default=0.5, help="insertion window [s]")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--json", default=None, help="write the numbers to this file")
    args = parser.parse_args(argv)
    rows = []
    for n in args.spheres:
        rows.append(case(n, args.fill_time, args.seed))
        print("\n".join(report(rows[-1])), flush=True)
    if args.json:
        write_measurements(args.json, rows=rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
