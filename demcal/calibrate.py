"""``demcal calibrate``: the whole calibration, composed from the stages.

    measure (demcal.measure) -> DEM campaign (demcal.analyse) -> report (demcal.report)

The workbook is measured, and the parts of the report that rest on it rendered
(``report.render.preflight``), before any DEM run, so a bad workbook costs nothing; finished DEM
runs are kept in ``DIR/runs`` and never redone, so a killed campaign resumes where it stopped.
"""

from __future__ import annotations

from pathlib import Path

from demcal.errors import InputError
from demcal.measure.cli import add_workbook_options, read_options


def register(subparsers) -> None:
    """Add ``demcal calibrate``."""
    cal = subparsers.add_parser(
        "calibrate", help="whole calibration: measure, runs of the repose twin, the parameters "
        "consistent with the lab, validation (runs the DEM)",
        description="Calibrate DEM parameters from a lab workbook. With --profile quick (the "
        "plausible workflow): measure the noise, run a space-filling design and sequential runs, "
        "fit a surrogate that models the noise, report the set of parameters consistent with "
        "the measured angle and validate by an equivalence test. With --profile paper (the "
        "design-expert workflow): the source paper's Plackett-Burman screening, steepest climb, "
        "Box-Behnken design, optimisation and validation. Finished DEM runs are kept in DIR/runs "
        "and never redone, so a killed campaign resumes where it stopped.")
    cal.add_argument("workbook", type=Path, help="lab workbook (.xlsx, or a folder of CSVs "
                     "or holding workbook.xlsx)")
    cal.add_argument("--out", required=True, type=Path, help="output folder")
    cal.add_argument("--profile", choices=("quick", "paper"), default="quick",
                     help="repose-rig profile (default quick; paper = the source paper's case)")
    cal.add_argument("--workers", type=int, default=None,
                     help="local worker processes (default: all cores)")
    cal.add_argument("--scheduler", help="Dask scheduler address (e.g. tcp://host:8786); "
                     "runs go to that cluster")
    cal.add_argument("--levels", choices=("minmax", "sd"), default="minmax",
                     help="screening levels: measured min/max (default, as the paper) or mean -+ sd")
    cal.add_argument("--workflow", choices=("plausible", "design-expert"), default=None,
                     help="plausible (default with --profile quick) or design-expert (default "
                          "with --profile paper)")
    cal.add_argument("--seed", type=int, default=1,
                     help="campaign seed: every run of every stage, validation included, draws "
                          "its seed from it (default 1)")
    cal.add_argument("--replicates", type=int, default=None,
                     help="DEM runs per design point (default: plausible, from the measured "
                          "noise; design-expert, 1 as the paper did)")
    cal.add_argument("--budget", type=int, default=None, dest="budget_runs",
                     help="plausible: most runs of design and sequential rounds (default 72)")
    cal.add_argument("--validation-cap", type=int, default=None,
                     help="plausible: most validation runs (default 40)")
    cal.add_argument("--tolerance", type=float, default=None,
                     help="equivalence tolerance of the validation [deg] (default: the larger of "
                          "1 deg and the lab's heap-to-heap sd)")
    cal.add_argument("--target", dest="extra_targets", action="append", default=[], metavar="QUANTITY",
                     help="plausible: fit this other reading of the heaps beside the angle (repeatable): "
                          "crest_height_mm, the crest height of every repose rig's photos (they need "
                          "scale_mm_per_px). Default: the angles alone")
    cal.add_argument("--set", dest="sets", action="append", default=[], metavar="NAME=VALUE",
                     help="a model setting for every run (repeatable): an extension, e.g. --set "
                          "contact_effective_mass=true; the time step, --set dt=2e-5 (default: the "
                          "workbook's meta time_step_s, else 0.2 of the Rayleigh time); --set "
                          "rolling_lever=edem_com; --set mass_model=body; --set spheres_per_clump=7")
    add_workbook_options(cal)
    cal.add_argument("--no-report", action="store_true",
                     help="skip the HTML/PDF report (and its check of the workbook text before the campaign)")
    cal.set_defaults(handler=_run_calibrate)


def extension_settings(items) -> dict:
    """``--set NAME=VALUE`` items as typed ``DEMParameters`` values (``CampaignConfig``
    checks that each names a model setting); the segment's ``spheres_per_clump`` as its count."""
    from demcal.simulate.cli import parameters, parse_sets
    from demcal.simulate.params import SEGMENT_FIELDS, current_names

    names = current_names(parse_sets(items))
    params = parameters(items)
    return {name: getattr(params.shape, SEGMENT_FIELDS[name]) if name in SEGMENT_FIELDS else getattr(params, name)
            for name in names}


def _run_calibrate(args) -> int:
    from demcal.analyse.campaign import CampaignConfig, calibrate
    from demcal.measure.pipeline import measure_workbook
    from demcal.measure.workbook import resolve_workbook
    from demcal.report.render import build_report, preflight

    workbook = resolve_workbook(args.workbook)
    optional = {name: getattr(args, name) for name in ("workers", "budget_runs", "tolerance")
                if getattr(args, name) is not None}
    if args.validation_cap is not None:
        optional["validation_cap"] = args.validation_cap
    if args.sets:
        optional["model_extensions"] = extension_settings(args.sets)
    if args.extra_targets:
        optional["extra_targets"] = tuple(args.extra_targets)
    config = CampaignConfig(profile=args.profile, workflow=args.workflow, levels=args.levels,
                            seed=args.seed, replicates=args.replicates, scheduler=args.scheduler,
                            **optional)
    if config.workers < 1:
        raise InputError(f"--workers must be >= 1, got {config.workers}")
    # measure first: a bad workbook stops before any DEM run, and so does workbook text that
    # the report, made after the campaign, could not render
    measurement = measure_workbook(workbook, annotate_dir=args.out / "annotated",
                                   reading=read_options(args))
    if not args.no_report:
        preflight(measurement, args.out)
    results = calibrate(workbook, args.out, config, measurement=measurement)
    print(results.summary())
    print(f"results: {args.out / 'results.json'}")
    if not args.no_report:
        paths = build_report(args.out)
        print("report: " + ", ".join(str(p) for p in paths))
    return 0
