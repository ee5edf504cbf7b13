"""The paper's repose case run by demcal and by LIGGGHTS-PUBLIC 3.8, side by side on one machine.

    python -m benchmarks.repose_vs_liggghts                      # 5 seeds each, 10 s (the paper's)
    python -m benchmarks.repose_vs_liggghts --seeds 1 --duration 1.5   # a quick end-to-end check
    python -m benchmarks.repose_vs_liggghts --skip-liggghts      # demcal only
    python -m benchmarks.repose_vs_liggghts --truth data/soybean/truth.yaml   # another material

What it measures, on one core each and sequentially (never both codes at once):

- Throughput: sphere-steps per second of the time-step loop, counted for both codes as
  LIGGGHTS quotes it (final number of spheres x steps / wall time of the loop: demcal's
  ``Simulation.run`` calls, LIGGGHTS' "Loop time"), per run and over all runs, and the ratio
  demcal/LIGGGHTS; for demcal also counted over the spheres present at each step.
- Start-up: the time from a fresh Python process to the first simulated step, twice in a row
  with an empty numba cache of their own: the first compiles the kernels, the second loads
  them from the on-disk cache.
- Angle of repose from ``--seeds`` seeds per code, measured the same way on both codes' final
  sphere positions (``simulate.rigs.repose.heap_angles``: rendered side view + photo
  estimator, profile fit of the full slope, outside heap alone): mean and standard deviation.

The case is the LIGGGHTS deck's (``demcal.simulate.liggghts.deck.ReposeCase``): 500 five-sphere
segments, carton 200 x 100 x 250 mm, plate lifted at 0.1 m/s from 4 s, 10 s at
7.43678e-5 s, the paper's calibrated contact parameters. demcal runs it with LIGGGHTS'
conventions: rolling friction lever ``liggghts_reff`` and the cylinder mass model.

With ``--truth FILE`` (a ``demcal virtual-lab`` truth file) the case is that material's: its
parameters and shape, the paper's carton in proportion to the particle
(``ReposeGeometry.for_particle``), the same fill, lift and duration. demcal then runs with its
own conventions and LIGGGHTS with the particle, materials and contact model of demcal's
LIGGGHTS export (``ReposeCase.for_params``), so the comparison covers the export too.

Outputs: ``benchmarks/results/repose_vs_liggghts_<UTC time>.json`` (every run, the summary,
machine, versions) and one row appended to ``benchmarks/RESULTS.md``.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime as dt
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from demcal.errors import DemcalError  # noqa: E402
from demcal.jsonio import write_json  # noqa: E402
from demcal.provenance import code_version  # noqa: E402
from demcal.simulate.scenes import compile_kernels  # noqa: E402

RESULTS_MD_HEADER = (
    "| date (UTC) | machine | versions | duration [s] | seeds | demcal sphere-steps/s | "
    "LIGGGHTS sphere-steps/s | ratio | start-up 1st / 2nd [s] | angle photo demcal | "
    "angle photo LIGGGHTS | angle profile demcal | angle profile LIGGGHTS | outside heap demcal | "
    "outside heap LIGGGHTS |\n|" + "---|" * 15 + "\n")

#: Time from a fresh interpreter to the first step of a small repose case (run as a subprocess).
STARTUP_SCRIPT = """
import time
t0 = time.perf_counter()
import sys
sys.path.insert(0, {root!r})
from demcal.simulate.params import DEMParameters
from demcal.simulate.shapes.segment import Segment
from demcal.simulate.scenes import build_paper_repose_case
sim = build_paper_repose_case(DEMParameters(rolling_lever="liggghts_reff", mass_model="cylinder"),
                              seed=1, n_clumps=5)
sim.run(n_steps=2)
print(time.perf_counter() - t0)
"""


def benchmark_parameters(case=None):
    """``DEMParameters`` of the LIGGGHTS deck's case, with LIGGGHTS' lever and mass model."""
    from demcal.simulate.liggghts.deck import ReposeCase
    from demcal.simulate.params import DEMParameters
    from demcal.simulate.shapes.segment import Segment

    c = case or ReposeCase()
    return DEMParameters(
        poisson_ratio=c.particle_poisson, shear_modulus_pa=c.particle_shear_modulus,
        particle_density_kg_m3=c.particle_density, e_pp=c.restitution_pp, e_pw=c.restitution_ps,
        mu_s_pp=c.friction_pp, mu_s_pw=c.friction_ps, mu_r_pp=c.rolling_pp, mu_r_pw=c.rolling_ps,
        wall_poisson_ratio=c.steel_poisson, wall_shear_modulus_pa=c.steel_shear_modulus,
        shape=Segment(c.segment_length, c.segment_diameter, len(c.sphere_offsets)), mass_model="cylinder",
        rolling_lever="liggghts_reff")


def machine() -> dict:
    """CPU model (from /proc/cpuinfo), logical cores, OS."""
    model = platform.processor() or "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"cpu": model, "cores": os.cpu_count(), "os": platform.platform(),
            "load_avg": list(os.getloadavg()) if hasattr(os, "getloadavg") else None}


def versions() -> dict:
    import numba
    return {**code_version(), "numpy": np.__version__, "numba": numba.__version__}


def write_measurements(path, **numbers) -> Path:
    """``numbers`` as JSON in ``path``, with the machine, the code and library versions and the
    time (UTC)."""
    return write_json(path, {"machine": machine(), "versions": versions(),
                             "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), **numbers}, indent=1)


def startup_times() -> list:
    """Seconds from interpreter start to the first steps in two fresh processes in a row that
    share an empty numba cache: the first compiles every kernel and stores it, the second loads
    them (the project's own cache is left alone)."""
    out = []
    with tempfile.TemporaryDirectory(prefix="demcal-numba-cache-") as cache:
        env = dict(os.environ, NUMBA_NUM_THREADS="1", OMP_NUM_THREADS="1", NUMBA_CACHE_DIR=cache)
        for _ in range(2):
            proc = subprocess.run([sys.executable, "-c", STARTUP_SCRIPT.format(root=str(ROOT))],
                                  capture_output=True, text=True, cwd=str(ROOT), env=env)
            if proc.returncode != 0:
                raise DemcalError(f"start-up probe failed: {proc.stderr.strip().splitlines()[-1:]}")
            out.append(float(proc.stdout.strip().splitlines()[-1]))
    return out


#: Observables both codes report (NaN where a rig has none).
OBSERVABLES = ("angle_deg", "angle_profile_deg", "angle_outside_deg", "outside_fraction")


def _rig(geometry):
    """The repose rig of ``geometry`` (default the lifted plate)."""
    from demcal.simulate.rigs import rig, rig_of_geometry

    return rig("repose") if geometry is None else rig_of_geometry(geometry)


def run_demcal(seed: int, duration: float, params, geometry=None, lift_time: float = 4.0) -> dict:
    """The case by demcal's repose rig (the ``paper`` profile with the wall lifted at
    ``lift_time``, ``duration`` simulated; the paper's carton unless ``geometry``)."""
    from demcal.simulate.rigs.heap import PROFILES

    profile = dataclasses.replace(PROFILES["paper"], duration=float(duration), lift_time=float(lift_time))
    t0 = time.perf_counter()
    res = _rig(geometry).run(params, seed, profile=profile, geometry=geometry)
    meta = res.meta
    sphere_steps = meta["spheres"] * meta["steps"]          # LIGGGHTS' convention: final spheres
    return {"code": "demcal", "seed": seed, "wall_s": meta["wall_s"], "elapsed_s": time.perf_counter() - t0,
            "steps": meta["steps"], "spheres": meta["spheres"], "sphere_steps": sphere_steps,
            "sphere_steps_per_s": sphere_steps / meta["wall_s"],
            "sphere_steps_present_per_s": meta["sphere_steps_per_s"],
            **{k: res.observable.get(k, math.nan) for k in OBSERVABLES},
            "escaped": res.observable["escaped"], "notes": meta["notes"]}


def run_reference(seed: int, duration: float, workdir: Path, case=None, geometry=None) -> dict:
    """The same case by LIGGGHTS on one core; its final spheres measured by the rig's own
    ``measure`` (for the carton ``heap_angles``)."""
    from demcal.simulate.liggghts.run import heap_summary, run_liggghts

    res = run_liggghts(seed, workdir / f"seed{seed}", duration=duration, case=case, nice=0)
    heap = _rig(geometry).measure(res["positions"], res["radii"], res["deck"]["case"])
    outside = heap_summary(res)["outside_fraction"] if "angle_outside_deg" in heap else math.nan
    return {"code": "liggghts", "seed": seed, "wall_s": res["wall_s"], "cpu_s": res["cpu_s"],
            "elapsed_s": res["elapsed_s"], "steps": res["steps"], "spheres": res["spheres"],
            "sphere_steps_per_s": res["sphere_steps_per_s"], "sphere_steps": res["spheres"] * res["steps"],
            **{k: heap.get(k, math.nan) for k in OBSERVABLES[:3]}, "outside_fraction": outside,
            "lost_spheres": res["lost_spheres"], "notes": list(heap["notes"]),
            "version": res["version"], "package_version": res["package_version"]}


def summarise(runs: list) -> dict:
    """Throughput over all runs and the angles' mean and sample standard deviation."""
    if not runs:
        return {}
    wall = sum(r["wall_s"] for r in runs)
    out = {"runs": len(runs), "wall_s": wall,
           "sphere_steps_per_s": sum(r["sphere_steps"] for r in runs) / wall if wall > 0 else math.nan}
    for key in ("angle_deg", "angle_profile_deg", "angle_outside_deg", "outside_fraction"):
        v = np.array([r[key] for r in runs], dtype=float)
        v = v[np.isfinite(v)]
        out[key] = {"mean": float(v.mean()) if v.size else math.nan,
                    "sd": float(v.std(ddof=1)) if v.size > 1 else math.nan, "n": int(v.size)}
    return out


def _pm(stat: dict) -> str:
    if not stat or not np.isfinite(stat.get("mean", math.nan)):
        return "-"
    sd = stat["sd"]
    return f"{stat['mean']:.1f} ± {sd:.1f}" if np.isfinite(sd) else f"{stat['mean']:.1f}"


def results_row(doc: dict) -> str:
    d, lg = doc["summary"]["demcal"], doc["summary"].get("liggghts", {})
    ratio = doc["summary"].get("ratio_demcal_to_liggghts")
    m, v = doc["machine"], doc["versions"]
    lig_version = next((r.get("package_version") or r.get("version") for r in doc["runs"]
                        if r["code"] == "liggghts"), None)
    cells = [doc["date"], f"{m['cpu']}, {m['cores']} cores",
             f"demcal {v['demcal']} ({(v['git_sha'] or '?')[:12]}), numba {v['numba']}"
             + (f", LIGGGHTS {lig_version}" if lig_version else ""),
             f"{doc['duration']:g}" + (f", {doc['material']['truth']}" if doc.get("material") else ""),
             str(doc["seeds"]), f"{d['sphere_steps_per_s']:.3g}",
             f"{lg['sphere_steps_per_s']:.3g}" if lg else "skipped",
             f"{ratio:.2f}" if ratio else "-",
             " / ".join(f"{t:.1f}" for t in doc["startup_s"]),
             _pm(d.get("angle_deg")), _pm(lg.get("angle_deg")), _pm(d.get("angle_profile_deg")),
             _pm(lg.get("angle_profile_deg")), _pm(d.get("angle_outside_deg")), _pm(lg.get("angle_outside_deg"))]
    return "| " + " | ".join(cells) + " |\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.repose_vs_liggghts",
                                     description="The paper's repose case by demcal and by LIGGGHTS-PUBLIC 3.8, "
                                                 "one core each, sequentially.")
    parser.add_argument("--seeds", type=int, default=5, help="seeds per code (default 5)")
    parser.add_argument("--duration", type=float, default=10.0, help="simulated time [s] (default 10)")
    parser.add_argument("--lift-time", type=float, default=4.0,
                        help="time the plate or tube starts to rise [s] (default 4, the paper's)")
    parser.add_argument("--skip-liggghts", action="store_true", help="run demcal only")
    parser.add_argument("--truth", type=Path, help="a virtual-lab truth file: that material's case instead "
                                                   "of the paper's (LIGGGHTS from demcal's export)")
    parser.add_argument("--results", type=Path, default=HERE / "results", help="folder of the JSON output")
    parser.add_argument("--results-md", type=Path, default=HERE / "RESULTS.md", help="table the row is appended to")
    args = parser.parse_args(argv)
    if args.seeds < 1:
        parser.error(f"--seeds must be >= 1, got {args.seeds}")
    if not (args.duration > 0 and math.isfinite(args.duration)):
        parser.error(f"--duration must be > 0, got {args.duration}")
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")

    now = dt.datetime.now(dt.timezone.utc)
    stamp = now.strftime("%Y%m%dT%H%M%SZ")
    doc = {"date": now.isoformat(timespec="seconds"), "duration": args.duration, "seeds": args.seeds,
           "command": [sys.executable, "-m", "benchmarks.repose_vs_liggghts", *(argv or sys.argv[1:])],
           "machine": machine(), "versions": versions(), "runs": []}
    print(f"machine: {doc['machine']['cpu']}, {doc['machine']['cores']} cores", flush=True)

    doc["startup_s"] = startup_times()
    print(f"demcal start-up to the first step: {doc['startup_s'][0]:.1f} s compiling the kernels, "
          f"{doc['startup_s'][1]:.1f} s loading them from numba's cache", flush=True)

    geometry = case = None
    if args.truth is not None:
        from demcal.simulate.rigs.lifting_cylinder import CylinderGeometry
        from demcal.simulate.rigs.repose import ReposeGeometry
        from demcal.simulate.truth_file import read_truth_file
        from demcal.simulate.virtual_lab import repose_geometry

        try:
            truth_file = read_truth_file(args.truth)
        except DemcalError as exc:
            parser.error(str(exc))
        params = truth_file.truth.params
        stated = truth_file.design.get("repose_rig")
        geometry = repose_geometry(stated) if stated else ReposeGeometry.for_particle(params.shape)
        if isinstance(geometry, CylinderGeometry):
            geometry = geometry.filled_for(params.shape)       # the twin runs the same fill
        case = _rig(geometry).liggghts_case(params, geometry, args.lift_time)
        doc["material"] = {"truth": str(args.truth), "shape": params.shape.describe(),
                           "rig": _rig(geometry).workbook_name, "geometry": geometry.to_dict()}
        print(f"material: {params.shape.describe()}; {geometry.describe()}", flush=True)
    else:
        from demcal.simulate.liggghts.deck import ReposeCase

        params = benchmark_parameters()
        case = ReposeCase(plate_lift_start=args.lift_time)
    doc["params"] = params.to_dict()
    compile_kernels()    # load (or compile) the kernels before anything is timed
    seeds = list(range(1, args.seeds + 1))
    for seed in seeds:
        r = run_demcal(seed, args.duration, params, geometry, args.lift_time)
        doc["runs"].append(r)
        print(f"demcal   seed {seed}: {r['wall_s']:.1f} s, {r['sphere_steps_per_s']:.3g} sphere-steps/s, "
              f"angle {r['angle_deg']:.1f} deg (profile {r['angle_profile_deg']:.1f}, outside "
              f"{r['angle_outside_deg']:.1f}), {r['outside_fraction']:.1%} outside", flush=True)

    skipped = None
    if not args.skip_liggghts:
        from demcal.simulate.liggghts.run import LiggghtsUnavailable
        workdir = args.results / "tmp" / "liggghts"
        for seed in seeds:
            try:
                r = run_reference(seed, args.duration, workdir, case, geometry)
            except LiggghtsUnavailable as exc:
                skipped = str(exc)
                print(f"LIGGGHTS skipped: {exc}", flush=True)
                break
            doc["runs"].append(r)
            print(f"LIGGGHTS seed {seed}: {r['wall_s']:.1f} s, {r['sphere_steps_per_s']:.3g} sphere-steps/s, "
                  f"angle {r['angle_deg']:.1f} deg (profile {r['angle_profile_deg']:.1f}, outside "
                  f"{r['angle_outside_deg']:.1f}), {r['outside_fraction']:.1%} outside", flush=True)
    doc["liggghts_skipped"] = skipped or (True if args.skip_liggghts else None)

    summary = {"demcal": summarise([r for r in doc["runs"] if r["code"] == "demcal"])}
    lig = [r for r in doc["runs"] if r["code"] == "liggghts"]
    if lig:
        summary["liggghts"] = summarise(lig)
        summary["ratio_demcal_to_liggghts"] = (summary["demcal"]["sphere_steps_per_s"]
                                               / summary["liggghts"]["sphere_steps_per_s"])
    doc["summary"] = summary
    json_path = write_json(args.results / f"repose_vs_liggghts_{stamp}.json", doc)
    md = args.results_md
    if not md.exists():
        md.write_text("# Benchmark results\n\nOne row per run of `benchmarks/run` "
                      "(`benchmarks/repose_vs_liggghts.py`); the JSON beside each run in "
                      "`benchmarks/results/` has every number.\n\n" + RESULTS_MD_HEADER)
    # the repose table comes first in the file (other benchmarks' tables follow it): the row
    # goes after its last row
    lines = md.read_text().splitlines(keepends=True)
    ends = [i for i, line in enumerate(lines) if line.startswith("|")]
    first_gap = next((i for i in range(ends[0], len(lines)) if not lines[i].startswith("|")), len(lines)) \
        if ends else len(lines)
    row = results_row(doc)
    lines.insert(first_gap, row if row.endswith("\n") else row + "\n")
    md.write_text("".join(lines))
    d = summary["demcal"]
    print(f"demcal:   {d['sphere_steps_per_s']:.3g} sphere-steps/s, angle {_pm(d['angle_deg'])} deg")
    if lig:
        print(f"LIGGGHTS: {summary['liggghts']['sphere_steps_per_s']:.3g} sphere-steps/s, "
              f"angle {_pm(summary['liggghts']['angle_deg'])} deg; ratio demcal/LIGGGHTS "
              f"{summary['ratio_demcal_to_liggghts']:.2f}")
    print(f"written: {json_path} and a row in {md}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
