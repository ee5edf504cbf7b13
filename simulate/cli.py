"""``demcal simulate``: run one lab-rig twin (repose, drop, incline) and store its result;
``demcal compile``: compile the DEM kernels once for this installation.

    demcal simulate repose --profile quick --set e_pp=0.32 --seed 3 --json run.json
    demcal simulate drop --height 400 --orientation random --pair particle-steel --json drop.json
    demcal simulate incline --mode roll --surface steel --json incline.json

Lengths on the command line are in the lab's units (mm, deg), as in the workbook; the JSON
holds SI values. ``--set NAME=VALUE`` changes one ``DEMParameters`` field (SI names, e.g.
``mu_s_pw=0.22``, ``shear_modulus_pa=2e7``, ``rolling_lever=liggghts_reff``).
"""

from __future__ import annotations

import dataclasses
import math
import sys

import numpy as np

from demcal.errors import InputError
from demcal.jsonio import write_json
from demcal.measure.cli import add_workbook_options, read_options

#: Frames written by --vtk over a run (besides the last).
VTK_FRAMES = 50
#: Arrays longer than this are summarised in the JSON unless --full-record.
RECORD_INLINE_MAX = 2000


def register(subparsers) -> None:
    """Add the ``simulate`` sub-command: the options of every registered rig, by sheet."""
    from demcal.simulate.rigs import RIGS, rig

    p = subparsers.add_parser(
        "simulate", help="run a lab-rig twin (repose, drop, incline) with given DEM parameters",
        description="Run the DEM twin of one lab test and print its observable; --json writes "
                    "the observable, the run metadata, the parameters, a summary of the record "
                    "and the provenance.")
    p.add_argument("rig", choices=rig_sheets(), help="the lab test to simulate")
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="NAME=VALUE",
                   help="set a DEM parameter (repeatable), e.g. --set e_pp=0.32")
    p.add_argument("--seed", type=int, default=0, help="run seed (default 0)")
    p.add_argument("--json", dest="json_out", metavar="OUT", help="write the result to this JSON file")
    p.add_argument("--full-record", action="store_true",
                   help="put the whole record (all sphere positions, time series) in the JSON")
    p.add_argument("--vtk", metavar="DIR",
                   help=f"write about {VTK_FRAMES} frames of the spheres and the walls to DIR "
                        "(.vtp), and their time series particles.pvd and walls.pvd for ParaView")
    p.add_argument("--workbook", metavar="PATH",
                   help="simulate the workbook's particle: its shape and sizes, densities and moduli "
                        "(and for the repose rig the carton, lift speed and fill count of its meta); "
                        "--set changes them further")
    p.add_argument("--repose-rig", metavar="NAME",
                   help="with a workbook naming several repose rigs (meta repose_rig), the one to "
                        "simulate (default: the first)")
    add_workbook_options(p)
    added = set()
    for r in map(rig, RIGS):
        if r.cli_arguments is not None and r.cli_arguments not in added:
            r.cli_arguments(p.add_argument_group(f"{r.sheet} rig"))
            added.add(r.cli_arguments)
    g = p.add_argument_group("another plate material (drop and incline rigs)")
    g.add_argument("--surface-material", dest="surface_values", action="append", default=[],
                   metavar="KEY=VALUE",
                   help="another plate material: density [kg/m3], poisson_ratio, shear_modulus [Pa], "
                        "and its contact with the particle: restitution, static_friction, "
                        "rolling_friction (repeatable)")
    p.set_defaults(handler=run)
    c = subparsers.add_parser(
        "compile", help="compile the DEM kernels once for this installation",
        description="Compile the DEM engine's kernels (the step loop on one thread and on "
                    "threads) and cache them on disk, so that no later command compiles: run "
                    "once after installing or updating demcal. Takes a minute or two; a second "
                    "call only loads them.")
    c.set_defaults(handler=compile_engine)


def compile_engine(args) -> int:
    """``demcal compile``: compile (or load) every kernel variant and say how long it took."""
    import time

    from demcal.simulate.scenes import compile_kernels

    start = time.perf_counter()
    compile_kernels(threaded=True)
    print(f"DEM kernels ready in {time.perf_counter() - start:.1f} s; later commands load them from the cache")
    return 0


def parse_sets(items) -> dict:
    """``["NAME=VALUE", ...]`` -> dict; a malformed item names itself and the valid names."""
    from demcal.simulate.params import DEMParameters
    out = {}
    for item in items:
        name, sep, value = str(item).partition("=")
        name = name.strip()
        if not sep or not name:
            raise InputError(f"--set {item!r}: expected NAME=VALUE; valid names: "
                             f"{', '.join(DEMParameters.names())}")
        out[name] = value.strip()
    return out


def parameters(items, base=None):
    """``DEMParameters`` (``base``, default the paper's) with the ``--set`` items applied."""
    from demcal.simulate.params import DEMParameters
    values = parse_sets(items)
    try:
        return (base or DEMParameters()).with_(**values)
    except InputError as exc:
        raise InputError(f"--set: {exc}") from None


def rig_sheets() -> tuple:
    """The lab tests ``demcal simulate`` runs: the sheets of the registered rigs."""
    from demcal.simulate.rigs import RIGS, rig

    return tuple(dict.fromkeys(r.sheet for r in map(rig, RIGS) if r.cli_options is not None))


def rig_options(args) -> tuple[str, dict, dict]:
    """The registered rig to run for the sheet ``args.rig`` (for ``repose``, the workbook's
    repose rig, meta ``repose_rig``, with its dimensions), its keyword options and the input
    files they came from (path -> SHA-256)."""
    from demcal.simulate.rigs import repose_rig, repose_setups, rig, rigs_of_sheet

    inputs, geometry = {}, None
    if getattr(args, "repose_rig", None) and not (args.workbook and args.rig == "repose"):
        raise InputError("--repose-rig chooses among the repose rigs of a workbook: it needs "
                         "'demcal simulate repose --workbook PATH'")
    sheet_rigs = rigs_of_sheet(args.rig)
    if any(r.geometry is not None for r in sheet_rigs):      # the rig and its size: the workbook's
        meta = {}
        if args.workbook:
            from demcal.measure.workbook import read_workbook

            wb = read_workbook(args.workbook, read_options(args))
            meta = wb.meta
            setups = {s.workbook_name: s for s in repose_setups(meta, file=str(wb.source))}
            wanted = getattr(args, "repose_rig", None) or next(iter(setups))
            if wanted not in setups:
                raise InputError(f"--repose-rig {wanted}: the workbook's repose rigs are {', '.join(setups)}")
            setup = setups[wanted]
            geometry = setup.dimensions()
            inputs.update(wb.files)
        chosen = rig(setup.rig) if geometry is not None else repose_rig(meta)
    else:
        chosen = sheet_rigs[0]
    opts = chosen.cli_options(args)
    if geometry is not None:
        opts["geometry"] = geometry
    return chosen.name, opts, inputs


class _Monitor:
    """The rigs' callback: a progress bar on stderr (shown after a few seconds) and VTK frames.

    The frames (``simulate.vtk.FrameSeries``) come every ``t_end / VTK_FRAMES`` simulated
    seconds at the first chunk past that time, and at the end of the run.
    """

    def __init__(self, vtk_dir=None):
        self.bar = None
        self.frames = None
        self.next_frame = 0.0
        if vtk_dir is not None:
            from demcal.simulate.vtk import FrameSeries
            try:
                self.frames = FrameSeries(vtk_dir)
            except InputError as exc:
                raise InputError(f"--vtk: {exc}") from None

    def __call__(self, sim, t_end, final):
        if self.bar is None:
            from tqdm.auto import tqdm
            self.bar = tqdm(total=round(t_end, 3), unit="s", desc="simulated", file=sys.stderr,
                            delay=3.0, leave=False, bar_format="{desc}: {n:.2f}/{total} s "
                            "|{bar}| {elapsed}<{remaining}")
        done = round(min(sim.time, t_end), 3)
        if done > self.bar.n:
            self.bar.update(done - self.bar.n)
        if self.frames is not None and (final or sim.time >= self.next_frame):
            self.frames.write(sim, last=final)
            self.next_frame = sim.time + t_end / VTK_FRAMES
        if final:
            self.bar.close()


def summarise_record(record: dict, full: bool = False) -> dict:
    """The record for the JSON: small arrays whole, large ones as shape, min and max."""
    out = {}
    for key, value in record.items():
        a = value if isinstance(value, np.ndarray) else None
        if a is not None and a.size > RECORD_INLINE_MAX and not full:
            num = a.astype(float) if a.dtype != bool else a.astype(int)
            out[key] = {"shape": list(a.shape), "min": float(np.nanmin(num)) if a.size else None,
                        "max": float(np.nanmax(num)) if a.size else None}
        else:
            out[key] = value
    return out


def result_json(result, full_record: bool = False) -> dict:
    """The JSON document of one rig run."""
    meta = result.meta
    return {"rig": result.rig, "observable": result.observable, "wall_s": meta["wall_s"],
            "steps": meta["steps"], "spheres": meta["spheres"],
            "sphere_steps_per_s": meta["sphere_steps_per_s"], "seed": meta["seed"],
            "profile": meta.get("profile"), "dt": meta["dt"], "simulated_s": meta["simulated_s"],
            "notes": meta.get("notes", []), "params": result.params,
            "record": summarise_record(result.record, full_record),
            "meta": {k: v for k, v in meta.items() if k not in ("notes",)},
            "provenance": result.provenance.to_dict()}


def run(args) -> int:
    from demcal.simulate.rigs import run_rig

    base, particle = None, None
    if args.workbook:
        from demcal.analyse.parameters import base_parameters
        from demcal.measure.pipeline import measure_particle
        particle = measure_particle(args.workbook, read_options(args))
        base = base_parameters(particle)
    params = parameters(args.sets, base)
    if args.seed < 0:
        raise InputError(f"--seed must be >= 0, got {args.seed}")
    name, opts, inputs = rig_options(args)
    if particle is not None:
        inputs.update(particle.provenance.inputs)
    monitor = _Monitor(args.vtk)
    result = run_rig(name, params, args.seed, callback=monitor, **opts)
    if inputs:
        result = dataclasses.replace(result, provenance=dataclasses.replace(
            result.provenance, inputs=dict(result.provenance.inputs, **inputs)))
    doc = result_json(result, args.full_record)
    if args.json_out:
        write_json(args.json_out, doc)
    shown = ", ".join(f"{k} = {_fmt(v)}" for k, v in result.observable.items())
    print(f"{name}: {shown}")
    print(f"  {doc['steps']} steps, {doc['spheres']} spheres, {doc['wall_s']:.1f} s wall, "
          f"{doc['sphere_steps_per_s']:.3g} sphere-steps/s, seed {args.seed}")
    for note in doc["notes"]:
        print(f"note: {note}", file=sys.stderr)
    if args.json_out:
        print(f"written: {args.json_out}")
    return 0


def _fmt(value) -> str:
    if isinstance(value, float):
        return "nan" if math.isnan(value) else f"{value:.4g}"
    return str(value)
