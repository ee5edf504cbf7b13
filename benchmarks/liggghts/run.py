"""Run the paper's repose deck with LIGGGHTS-PUBLIC 3.8 on one core and store the results.

    python -m benchmarks.liggghts.run --seed 1 --duration 10

The deck and the runner are ``demcal.simulate.liggghts``; this command stores what the
side-by-side benchmark needs (README.md). With no LIGGGHTS binary it prints why and exits 0
(a skipped benchmark, not a failure).
"""

from __future__ import annotations

import argparse
import gzip
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from demcal.errors import InputError, SimulationError  # noqa: E402
from demcal.jsonio import write_json  # noqa: E402
from demcal.simulate.liggghts.run import LiggghtsUnavailable, heap_summary, run_liggghts  # noqa: E402


def save_side_view(result: dict, path) -> Path:
    """Side view (x-z) of the final spheres with the carton outline, as a PNG."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import EllipseCollection

    pos, rad = result["positions"], result["radii"]
    fig, ax = plt.subplots(figsize=(8, 3.5), dpi=90)
    ax.add_collection(EllipseCollection(2 * rad, 2 * rad, np.zeros_like(rad), units="xy",
                                        offsets=pos[:, [0, 2]], offset_transform=ax.transData,
                                        facecolors="tab:olive", edgecolors="k", linewidths=0.2, alpha=0.5))
    L, H = result["deck"]["case"]["box_length"], result["deck"]["case"]["box_height"]
    ax.plot([0, 0, L], [H, 0, 0], "k-", lw=1.5)
    ax.axhline(0, color="k", lw=0.8)
    ax.set_aspect("equal")
    ax.set_xlim(-0.02, max(L + 0.05, float(pos[:, 0].max()) + 0.02) if len(pos) else L + 0.05)
    ax.set_ylim(-0.01, min(H, float(pos[:, 2].max()) + 0.03) if len(pos) else H)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("z [m]")
    ax.set_title(f"{result['version']}, seed {result['seed']}, t = {result['duration']:g} s")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return Path(path)


def save_result(result: dict, json_path, positions_path=None) -> Path:
    """Store the run summary as JSON and, optionally, the spheres as gzipped text
    (columns atom_id body_id x y z radius, metres)."""
    summary = {k: v for k, v in result.items() if k not in ("positions", "radii", "body_id", "atom_id")}
    summary["heap"] = heap_summary(result)
    if positions_path is not None:
        positions_path = Path(positions_path)
        positions_path.parent.mkdir(parents=True, exist_ok=True)
        table = np.column_stack([result["atom_id"], result["body_id"], result["positions"], result["radii"]])
        with gzip.open(positions_path, "wt") as f:
            np.savetxt(f, table, fmt=["%d", "%d", "%.7g", "%.7g", "%.7g", "%.7g"],
                       header="atom_id body_id x_m y_m z_m radius_m")
        summary["positions_file"] = str(positions_path)
    return write_json(json_path, summary)


def main(argv=None) -> int:
    here = HERE
    parser = argparse.ArgumentParser(prog="python -m benchmarks.liggghts.run",
                                     description="Run the paper's repose case with LIGGGHTS-PUBLIC on one core.")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--duration", type=float, default=10.0, help="simulated time [s] (default 10)")
    parser.add_argument("--workdir", type=Path, default=None,
                        help="run folder (default benchmarks/results/tmp/liggghts/seed<N>)")
    parser.add_argument("--results", type=Path, default=here / "results",
                        help="where the JSON summary, positions and side view go")
    parser.add_argument("--nice", type=int, default=10)
    parser.add_argument("--dump-interval", type=float, default=None, help="periodic dumps every [s]")
    args = parser.parse_args(argv)
    workdir = args.workdir or here.parent / "results" / "tmp" / "liggghts" / f"seed{args.seed}"
    try:
        result = run_liggghts(args.seed, workdir, args.duration, nice=args.nice,
                              dump_interval=args.dump_interval)
    except LiggghtsUnavailable as exc:
        print(f"skipped: {exc}")
        return 0
    except (SimulationError, InputError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    stem = f"repose_seed{args.seed}_{args.duration:g}s"
    json_path = save_result(result, args.results / f"{stem}.json", args.results / f"{stem}_positions.txt.gz")
    save_side_view(result, args.results / f"{stem}_side.png")
    heap = heap_summary(result)
    print(f"{result['version']} (package {result['package_version']}), seed {args.seed}, "
          f"{args.duration:g} s simulated")
    print(f"  {result['steps']} steps, {result['spheres']} spheres in {result['bodies']} bodies, "
          f"lost {result['lost_spheres']}")
    print(f"  loop time {result['wall_s']:.2f} s (cpu {result['cpu_s']:.2f} s), "
          f"{result['sphere_steps_per_s']:.3g} sphere-steps/s")
    print(f"  bodies outside the carton {heap['outside_fraction']:.1%}, "
          f"runout {heap['runout_max'] * 1e3:.0f} mm beyond the plate")
    print(f"  summary: {json_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
