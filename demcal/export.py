"""``demcal export DIR --to liggghts|yade|edem|json|all [--out PATH]``: the calibrated parameters
of a finished campaign in the input terms of another DEM code (``simulate.export``).

When the campaign folder holds a ``critique.json`` whose critique recalibrated with an accepted
extension (its ``heap_gains``), each export also says whether the target can run that
extension and gives the set calibrated with it beside its own (``simulate.export.CalibratedWith``)."""

from __future__ import annotations

import argparse
from pathlib import Path

from demcal.errors import InputError
from demcal.provenance import code_version, sha256_file
from demcal.simulate.export import EXPORT_FILES, CalibratedWith, export_model, render
from demcal.simulate.params import DEMParameters


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
    for path in write_exports(args.campaign, _targets(args.to), args.out):
        print(f"wrote {path}")
    return 0


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
    p.set_defaults(handler=_run)
