"""LIGGGHTS-PUBLIC 3.8 throughput against the number of spheres, fill and settled phases apart, on 1 or more MPI ranks.

The LIGGGHTS side of ``benchmarks/dem_scaling.py``, on the same cases: the paper's carton
scaled in x and y by sqrt(n_clumps / 500) with n_clumps = spheres // 5 (2,500 spheres in
200 x 100 mm, 20,000 in 566 x 283 mm, 100,000 in 1265 x 632 mm, the fill depth the same),
filled as demcal's ``build_paper_repose_case`` fills it (whole clumps inside x and y inset
10 mm from the walls, z 100-240 mm, at rest, random orientation, over the first
``--fill-time`` seconds, a batch every 50 steps as demcal's factory), the end plate never
lifted. The run is two LIGGGHTS ``run`` commands, so LIGGGHTS prints one "Loop time" each:
the *fill* phase (the first ``--fill-phase`` = 0.6 s simulated) and the *settled* phase (the
``--settled-phase`` = 0.15 s after it). Contact model, particle and time step are the
LIGGGHTS deck's (``simulate.liggghts.deck.ReposeCase``), the model demcal's benchmark runs.

Per phase: steps, wall time (LIGGGHTS' "Loop time": the time-step loop alone, without set-up
and the template's Monte Carlo), spheres at the end, neighbour-list builds, and sphere-steps
per second counted two ways:

- ``sphere_steps_per_s``: the spheres present at each step, summed over the steps, over the
  loop time: the count ``dem_scaling.py`` uses. The spheres present at each step come from
  LIGGGHTS' own insertion report ("inserted N particle templates ... at step S": a batch takes
  part from the step it is inserted at) and are checked against the atoms of every thermo line.
  Spheres lost through the box walls would be counted until the end (none are expected in the
  closed carton; the row's ``lost_spheres`` says).
- ``sphere_steps_per_s_final_count``: spheres at the end of the phase x steps / loop time, as
  LIGGGHTS quotes its throughput (``repose_vs_liggghts.py``); it overstates the fill phase,
  where the carton is still filling.

One rank runs as ``liggghts -in in.repose`` (the Debian build runs without ``mpirun``, as the
side-by-side runs it); n > 1 ranks as ``mpirun -np n liggghts ...`` (with
``--allow-run-as-root`` when run as root, ``--oversubscribe`` when n exceeds the cores), the
carton split along x into n equal slabs (``processors * 1 1``). Ranks are timed one
configuration after another, never two runs at once.

    python -m benchmarks.liggghts_scaling                          # 2,500 and 20,000 spheres, 1 rank
    python -m benchmarks.liggghts_scaling --spheres 2500 20000 100000 --ranks 1 2
    python -m benchmarks.liggghts_scaling --spheres 1000 --fill-time 0.05 --fill-phase 0.06 \\
        --settled-phase 0.02 --ranks 1 2                          # a smoke test of a few seconds

Below 1000 spheres the scaled fill region is narrower than a segment and the case is refused.
LIGGGHTS inserts at most the batch it is due (``insert/rate/region``); what does not fit is
inserted in later batches, so a fill too fast for the region runs past ``--fill-time`` (the
row's ``fill_complete`` is false when segments were still missing at the end of the fill
phase; the count of spheres present follows what was actually inserted).

Prints one line per run; ``--json PATH`` writes every number with the machine, versions and
date. The run folders (deck, meshes, log) are left in
``benchmarks/results/tmp/liggghts_scaling/``.
"""

from __future__ import annotations

import argparse
import inspect
import math
import os
import re
import resource
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks.repose_vs_liggghts import machine, versions  # noqa: E402
from demcal.errors import InputError, SimulationError  # noqa: E402
from demcal.jsonio import write_json  # noqa: E402
from demcal.simulate.factory import ParticleFactory  # noqa: E402
from demcal.simulate.liggghts.deck import ReposeCase, write_deck  # noqa: E402
from demcal.simulate.liggghts.run import (LiggghtsUnavailable, find_liggghts, liggghts_command,  # noqa: E402
                                          package_version, parse_log)
from demcal.simulate.scenes import build_paper_repose_case  # noqa: E402

FILL_PHASE, SETTLED_PHASE = 0.6, 0.15          # as benchmarks/dem_scaling.py
#: demcal's factory region in build_paper_repose_case: x and y inset by fill_margin, z fill_bottom..fill_top
_SCENE = inspect.signature(build_paper_repose_case).parameters
FILL_MARGIN, FILL_BOTTOM, FILL_TOP = (_SCENE[k].default for k in ("fill_margin", "fill_bottom", "fill_top"))
#: Steps between demcal's insertion batches (ParticleFactory's default, which the scene uses).
BATCH_STEPS = inspect.signature(ParticleFactory).parameters["batch_steps"].default
#: Room around the carton in x and y of the LIGGGHTS box [m] (see ScalingCase.domain).
DOMAIN_MARGIN = 0.02

_INSERTED = re.compile(r"inserted (\d+) particle templates \(mass [^)]*\) at step (\d+)")
_BUILDS = re.compile(r"^Neighbor list builds = (\d+)", re.M)
_DANGEROUS = re.compile(r"^Dangerous builds = (\d+)", re.M)


@dataclass(frozen=True)
class ScalingCase(ReposeCase):
    """The deck's repose case run as two phases, fill and settled, the plate never lifted.

    Only what ``render_script`` takes from the case changes; ``simulate/liggghts/deck.py`` is
    untouched. ``phase_steps`` gives the two ``run`` commands (labels ``fill`` and ``settled``,
    so ``motion`` never issues the plate's ``move/mesh``). ``domain`` is the carton with
    ``DOMAIN_MARGIN`` around it in x and y: the deck's box leaves room for the heap beyond the
    lifted plate (x to 3 L, y from -1.5 W to 2.5 W), which never forms here, and MPI's equal
    slabs of that box would put the whole carton on one rank (and the empty bins cost every
    list build)."""

    fill_phase: float = FILL_PHASE
    settled_phase: float = SETTLED_PHASE

    title = "DEM scaling benchmark: the paper's carton scaled in x and y, fill and settled phases, LIGGGHTS-PUBLIC 3.8"

    @classmethod
    def scaled(cls, n_spheres: int, fill_time: float, fill_phase: float, settled_phase: float) -> "ScalingCase":
        """The case of ``n_spheres`` (in clumps of the deck's segment), scaled as dem_scaling.py."""
        per = len(ReposeCase.sphere_offsets)
        n_clumps = n_spheres // per
        scale = math.sqrt(n_clumps / 500)
        L, W = 0.2 * scale, 0.1 * scale
        base = cls(fill_phase=fill_phase, settled_phase=settled_phase)
        return replace(base, box_length=L, box_width=W, n_segments=n_clumps, fill_time=fill_time,
                       plate_lift_start=100.0,        # dem_scaling's lift_time: beyond the run
                       fill_region=(FILL_MARGIN, L - FILL_MARGIN, FILL_MARGIN, W - FILL_MARGIN,
                                    FILL_BOTTOM, FILL_TOP),
                       insert_interval=BATCH_STEPS * base.time_step)

    @property
    def duration(self) -> float:
        return self.fill_phase + self.settled_phase

    def phase_steps(self, duration: float) -> tuple:
        """(``fill``, steps of ``fill_phase``), (``settled``, steps of ``settled_phase``); each
        rounded to whole steps as demcal's ``Simulation.run(duration=...)``."""
        return ("fill", self.steps(self.fill_phase)), ("settled", self.steps(self.settled_phase))

    @property
    def domain(self) -> tuple:
        L, W, H = self.box_length, self.box_width, self.box_height
        return (-DOMAIN_MARGIN, L + DOMAIN_MARGIN, -DOMAIN_MARGIN, W + DOMAIN_MARGIN, -0.01, H + 0.02)


def mpi_prefix(ranks: int) -> list:
    """``mpirun`` and its options for ``ranks`` processes; nothing for one."""
    if ranks == 1:
        return []
    mpirun = shutil.which("mpirun")
    if mpirun is None:
        raise LiggghtsUnavailable("mpirun not found; install it with: apt-get install openmpi-bin")
    extra = ["--allow-run-as-root"] if hasattr(os, "geteuid") and os.geteuid() == 0 else []
    if ranks > (os.cpu_count() or 1):
        extra.append("--oversubscribe")
    return [mpirun, *extra, "-np", str(ranks)]


def mpi_version() -> str | None:
    mpirun = shutil.which("mpirun")
    if mpirun is None:
        return None
    out = subprocess.run([mpirun, "--version"], capture_output=True, text=True)
    return (out.stdout.strip().splitlines() or [None])[0]


def spheres_present(log_text: str, per_body: int, last_step: int):
    """Spheres present at each step 0..``last_step`` (numpy array) from the insertion reports:
    a batch inserted at step S takes part in step S and after (LIGGGHTS inserts in
    ``pre_exchange``, before that step's forces)."""
    count = np.zeros(last_step + 1, dtype=np.int64)
    for bodies, step in _INSERTED.findall(log_text):
        if int(step) <= last_step:
            count[int(step)] += int(bodies) * per_body
    return np.cumsum(count)


def phase_numbers(loop: dict, present, first_step: int, builds: int, dangerous: int) -> dict:
    """One phase's numbers: ``loop`` LIGGGHTS' Loop-time record, ``present`` spheres per step."""
    steps, wall = loop["steps"], loop["loop_s"]
    sphere_steps = int(present[first_step + 1:first_step + steps + 1].sum())
    return {"steps": steps, "wall_s": wall, "spheres_at_end": loop["atoms"],
            "sphere_steps": sphere_steps,
            "sphere_steps_per_s": sphere_steps / wall if wall > 0 else math.nan,
            "sphere_steps_per_s_final_count": loop["atoms"] * steps / wall if wall > 0 else math.nan,
            "neighbour_builds": builds, "dangerous_builds": dangerous,
            "neighbour_builds_per_1000_steps": 1000.0 * builds / steps}


def run_case(n_spheres: int, ranks: int, args, workdir: Path) -> dict:
    """Write the deck of ``n_spheres`` into ``workdir``, run LIGGGHTS on ``ranks`` ranks, read the log."""
    exe = find_liggghts()
    if exe is None:
        raise LiggghtsUnavailable("LIGGGHTS not found; install the Debian package: apt-get install liggghts")
    case = ScalingCase.scaled(n_spheres, args.fill_time, args.fill_phase, args.settled_phase)
    deck = write_deck(workdir, args.seed, case.duration, case)
    # The one change to the rendered text (render_script has no option for it): split the box
    # along x only, before create_box. By default LIGGGHTS cuts the longest side, which for the
    # 2,500-sphere carton (200 x 100 x 250 mm) is the height: the settled bed, under 100 mm
    # deep, would lie in the lower rank alone. The two phases need no text change: they are
    # ScalingCase.phase_steps, which render_script and write_deck already follow.
    text = deck.script.read_text()
    anchor = "\nregion          domain block"
    if text.count(anchor) != 1:
        raise SimulationError(f"{deck.script}: no single 'region domain' line to put 'processors' before")
    deck.script.write_text(text.replace(anchor, "\nprocessors      * 1 1" + anchor))
    deck.log_file.unlink(missing_ok=True)

    cmd = [*mpi_prefix(ranks), *liggghts_command(exe, deck)]
    usage0, t0 = resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter()
    proc = subprocess.run(cmd, cwd=workdir, env=dict(os.environ, OMP_NUM_THREADS="1"),
                          capture_output=True, text=True)
    elapsed, usage = time.perf_counter() - t0, resource.getrusage(resource.RUSAGE_CHILDREN)
    log_text = deck.log_file.read_text(errors="replace") if deck.log_file.exists() else ""
    log = parse_log(log_text)
    if proc.returncode != 0 or log["errors"]:
        tail = [line for line in (proc.stdout + proc.stderr).splitlines() if line.strip()][-3:]
        raise SimulationError(f"LIGGGHTS failed (exit code {proc.returncode}) in {workdir}: "
                              + " | ".join(log["errors"] or tail or ["no message"]))
    loops = log["loops"]
    builds, dangerous = _BUILDS.findall(log_text), _DANGEROUS.findall(log_text)
    if [lp["steps"] for lp in loops] != [n for _, n in deck.phases] or len(builds) != len(loops):
        raise SimulationError(f"{deck.log_file}: runs of {[lp['steps'] for lp in loops]} steps, "
                              f"the deck asked for {[n for _, n in deck.phases]}")

    present = spheres_present(log_text, case.spheres_per_particle, deck.n_steps)
    thermo = log["thermo"]                       # step, atoms, ...: the count checked at every line
    mismatch = [(int(s), int(a), int(present[int(s)])) for s, a in thermo[:, :2] if present[int(s)] != a]
    row = {"spheres": n_spheres, "ranks": ranks, "clumps": case.n_segments,
           "carton_m": [case.box_length, case.box_width], "steps_between_insertions": BATCH_STEPS}
    first = 0
    for (label, _), loop, b, d in zip(deck.phases, loops, builds, dangerous):
        row[label] = phase_numbers(loop, present, first, int(b), int(d))
        first += loop["steps"]
    inserted, fill_steps = int(present[-1]), row["fill"]["steps"]
    row.update(fill_complete=bool(present[fill_steps] == case.n_segments * case.spheres_per_particle),
               fill_over_settled_throughput=row["fill"]["sphere_steps_per_s"] / row["settled"]["sphere_steps_per_s"],
               spheres_inserted=inserted, lost_spheres=inserted - loops[-1]["atoms"],
               count_mismatches=mismatch[:10], elapsed_s=elapsed,
               cpu_s=(usage.ru_utime - usage0.ru_utime) + (usage.ru_stime - usage0.ru_stime),
               procs=loops[-1]["procs"], command=cmd, workdir=str(workdir), liggghts_version=log["version"],
               warnings=sorted(set(log["warnings"])))
    return row


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.liggghts_scaling",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--spheres", type=int, nargs="+", default=[2500, 20000])
    parser.add_argument("--ranks", type=int, nargs="+", default=[1], help="MPI ranks of each run (default 1)")
    parser.add_argument("--fill-time", type=float, default=0.5, help="insertion window [s]")
    parser.add_argument("--fill-phase", type=float, default=FILL_PHASE, help="simulated time of the fill phase [s]")
    parser.add_argument("--settled-phase", type=float, default=SETTLED_PHASE,
                        help="simulated time of the settled phase [s]")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--json", default=None, help="write the numbers to this file")
    parser.add_argument("--workdir", type=Path, default=HERE / "results" / "tmp" / "liggghts_scaling",
                        help="parent of the run folders")
    args = parser.parse_args(argv)
    if min(args.ranks) < 1 or min(args.spheres) < 5:
        parser.error("--ranks must be >= 1 and --spheres >= 5")
    for name in ("fill_time", "fill_phase", "settled_phase"):
        if not (getattr(args, name) > 0 and math.isfinite(getattr(args, name))):
            parser.error(f"--{name.replace('_', '-')} must be > 0")

    rows = []
    for n, ranks in ((n, r) for n in args.spheres for r in args.ranks):
        try:
            row = run_case(n, ranks, args, args.workdir / f"{n}_spheres_{ranks}_ranks")
        except LiggghtsUnavailable as exc:
            print(f"skipped: {exc}")
            return 0
        except InputError as exc:      # e.g. a carton too small for the fill region (under 1000 spheres)
            parser.error(f"{n} spheres: {exc}")
        rows.append(row)
        f, s = row["fill"], row["settled"]
        print(f"{n:>7} spheres, {ranks} rank{'s' if ranks > 1 else ''} | {row['elapsed_s']:.1f} s | fill "
              f"{f['sphere_steps_per_s']:.3g} sphere-steps/s ({f['sphere_steps_per_s_final_count']:.3g} at the "
              f"final {f['spheres_at_end']}), {f['neighbour_builds']} builds in {f['steps']} steps | settled "
              f"{s['sphere_steps_per_s']:.3g}, {s['neighbour_builds']} builds in {s['steps']} | fill/settled "
              f"{row['fill_over_settled_throughput']:.2f} | lost {row['lost_spheres']}"
              + ("" if row["fill_complete"] else f" | fill incomplete: {row['spheres_inserted']} inserted")
              + (f" | count differs from thermo at {len(row['count_mismatches'])} lines" if row["count_mismatches"]
                 else ""), flush=True)
    for row in rows:
        one = next((r for r in rows if r["spheres"] == row["spheres"] and r["ranks"] == 1), None)
        if one is not None and row is not one:
            wall = [sum(r[p]["wall_s"] for p in ("fill", "settled")) for r in (one, row)]
            print(f"{row['spheres']} spheres, {row['ranks']} ranks / 1: speed-up of the loop time "
                  f"{wall[0] / wall[1]:.2f} (fill {one['fill']['wall_s'] / row['fill']['wall_s']:.2f}, settled "
                  f"{one['settled']['wall_s'] / row['settled']['wall_s']:.2f})")
    if args.json:
        write_json(args.json, {"machine": machine(),
                               "versions": {**versions(), "liggghts": package_version(), "mpi": mpi_version()},
                               "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                               "command": [sys.executable, "-m", "benchmarks.liggghts_scaling",
                                           *(sys.argv[1:] if argv is None else argv)],
                               "rows": rows})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
