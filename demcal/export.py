"""``demcal export DIR --to liggghts|yade|edem|json|all [--out PATH] [--check]``: the calibrated
parameters of a finished campaign in the input terms of another DEM code (``simulate.export``).

``--check`` (with ``--to liggghts``) runs the calibrated set in LIGGGHTS-PUBLIC in the lab's
repose rig and tests LIGGGHTS' angle against the lab's (``analyse.liggghts_check``); the
verdict goes to ``DIR/export/liggghts_check.json``.

When the campaign folder holds a ``critique.json`` whose critique recalibrated with an accepted
extension (its ``heap_gains``), each export also says whether the target can run that
extension and gives the set calibrated with it beside its own (``simulate.export.CalibratedWith``)."""

from __future__ import annotations

import argparse
from pathlib import Path

from demcal.analyse.liggghts_check import CAP, FIRST, LIFT_TIME_S, SETTLE_S, STEP
from demcal.errors import InputError
from demcal.provenance import code_version, sha256_file
from demcal.simulate.export import EXPORT_FILES, CalibratedWith, export_model, render
from demcal.simulate.params import DEMParameters
from demcal.text import one_line


def accepted_extensions(critique) -> tuple:
    """The ``CalibratedWith`` of each extension a critique (``analyse.critique.loop.Critique``
    or None) accepted and recalibrated with."""
    if critique is None:
        return ()
    return tuple(CalibratedWith(h.extension, h.mechanism, dict(h.settings), h.campaign,
                                {p.name: (p.after, None if p.after_ci95 is None else tuple(p.after_ci95))
                                 for p in h.parameters})
                 for h in critique.heap_gains)


def campaign_model(campaign_dir):
    """The ``ExportModel`` of a finished calibration: its calibrated parameters, the 95 %
    plausible intervals (plausible workflow), the results file's hash and, from its
    ``critique.json``, the extensions the critique accepted."""
    from demcal.analyse.critique.loop import load_critique
    from demcal.analyse.results import read_campaign_results

    path = Path(campaign_dir) / "results.json"
    results = read_campaign_results(campaign_dir)
    try:
        params = DEMParameters.from_names(results.calibrated_parameters)
    except InputError as exc:
        raise InputError(f"{path}: calibrated_parameters is not a DEM parameter set ({exc})") from None
    intervals = ({name: list(est.ci95) for name, est in results.calibration.parameters.items()}
                 if results.calibration is not None else {})
    source = {"file": str(path), "sha256": sha256_file(path), "code": code_version(),
              "calibrated_by": results.provenance.code}
    critique, critique_source = load_critique(campaign_dir)
    if critique_source:
        source["critique"] = critique_source
    try:
        accepted = accepted_extensions(critique)
    except InputError as exc:
        raise InputError(f"{Path(campaign_dir) / 'critique.json'}: heap_gains: {exc}") from None
    return export_model(params, material=results.material or "segment", source=source, intervals=intervals,
                        accepted=accepted)


def write_exports(campaign_dir, targets, out=None) -> list:
    """Write each target's export; ``out`` is a file for one target, a folder for several
    (default: the campaign's ``export/``). Returns the paths written."""
    model = campaign_model(campaign_dir)
    if len(targets) == 1 and out is not None and Path(out).suffix:
        paths = {targets[0]: Path(out)}
    else:
        folder = Path(out) if out is not None else Path(campaign_dir) / "export"
        if folder.is_file():
            raise InputError(f"--out {folder}: a file; give a folder when exporting several formats")
        paths = {t: folder / EXPORT_FILES[t] for t in targets}
    written = []
    for target, path in paths.items():
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(render(model, target), encoding="utf-8")
        written.append(path)
    return written


def _targets(text: str) -> list:
    names = list(EXPORT_FILES) if text == "all" else [t.strip() for t in text.split(",") if t.strip()]
    unknown = [t for t in names if t not in EXPORT_FILES]
    if unknown or not names:
        raise InputError(f"--to {text!r}: unknown format {', '.join(unknown) or '(none)'}; "
                         f"valid: {', '.join(EXPORT_FILES)} or all")
    return names


def _run(args: argparse.Namespace) -> int:
    targets = _targets(args.to)
    if args.check and targets != ["liggghts"]:
        raise InputError(f"--check runs the calibrated set in LIGGGHTS: give --to liggghts, not --to {args.to}")
    for path in write_exports(args.campaign, targets, args.out):
        print(f"wrote {path}")
    if args.check:
        return check_in_liggghts(args)
    return 0


def check_in_liggghts(args: argparse.Namespace) -> int:
    """``--check``: the calibrated set in LIGGGHTS, its verdict printed and written; exit 0
    when LIGGGHTS' angle is equivalent to the lab's, 1 otherwise."""
    import sys

    from demcal.analyse.liggghts_check import check_calibration
    from demcal.analyse.results import read_campaign_results
    from demcal.jsonio import write_json
    from demcal.simulate.liggghts.run import LiggghtsUnavailable

    campaign = Path(args.campaign)
    results = read_campaign_results(campaign)
    path = campaign / "results.json"
    folder = campaign / "export"
    workdir = Path(args.check_dir) if args.check_dir else folder / "liggghts_check"

    def progress(run):
        angle = f"{run.angle_deg:.2f} deg ({run.read_by})" if run.read_by else "no angle found"
        print(f"  LIGGGHTS seed {run.seed}: {angle}, {run.spheres} spheres, loop {run.wall_s:.1f} s", flush=True)

    print(f"running the calibrated set in LIGGGHTS ({one_line(results.repose_rig)} rig), runs in {workdir}", flush=True)
    try:
        check = check_calibration(results, workdir, source={"file": str(path), "sha256": sha256_file(path)},
                                  lift_time=args.lift_time, duration=args.duration, first=args.first,
                                  step=args.step, cap=args.cap, progress=progress)
    except LiggghtsUnavailable as exc:
        print(f"error: --check: {exc}", file=sys.stderr)
        return 2
    out = write_json(folder / "liggghts_check.json", check.to_dict())
    print(check.summary())
    print(f"wrote {out}")
    return {"equivalent": 0, "failed": 2}.get(check.verdict, 1)


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "export", help="write the calibrated parameters for LIGGGHTS, Yade, EDEM or as JSON",
        description="Write the calibrated parameters of a finished calibration in the terms of "
                    "another DEM code. Each file states the rolling-friction lever convention "
                    "and converts mu_r where the target's differs.")
    p.add_argument("campaign", metavar="DIR", help="a finished calibration (the --out of demcal calibrate)")
    p.add_argument("--to", default="all", metavar="FORMAT",
                   help=f"{', '.join(EXPORT_FILES)}, a comma list, or all (default)")
    p.add_argument("--out", metavar="PATH", help="file (one format) or folder (default DIR/export/)")
    g = p.add_argument_group("--check: the calibrated set run in LIGGGHTS (needs the liggghts binary)")
    g.add_argument("--check", action="store_true",
                   help="run the calibrated set in LIGGGHTS in the lab's repose rig and test its mean angle "
                        "against the lab's (two one-sided tests, the validation's tolerance); exit 0 when "
                        "equivalent, 1 otherwise; the verdict goes to DIR/export/liggghts_check.json")
    g.add_argument("--check-dir", metavar="DIR", help="folder of the LIGGGHTS runs (default DIR/export/liggghts_check)")
    g.add_argument("--lift-time", type=float, default=LIFT_TIME_S, metavar="S",
                   help=f"time the wall starts to rise [s] (default {LIFT_TIME_S:g}, the paper's)")
    g.add_argument("--duration", type=float, default=None, metavar="S",
                   help=f"simulated time [s] (default: until {SETTLE_S:g} s after the wall is clear)")
    g.add_argument("--first", type=int, default=FIRST, help=f"runs at the first look (default {FIRST})")
    g.add_argument("--step", type=int, default=STEP, help=f"runs added between looks (default {STEP})")
    g.add_argument("--cap", type=int, default=CAP, help=f"largest number of runs (default {CAP})")
    p.set_defaults(handler=_run)
