"""``demcal critique``: critique a calibrated model against the lab's measurements.

    demcal critique WORKBOOK_OR_DIR [--json OUT] [--no-twins] [--rigs drop,incline,repose]
                    [--extensions NAME,...] [--alpha 0.01] [--correction bh|holm]
                    [--workers N] [--store DIR] [--repose-seeds N] [--seed S] [--progress]
                    [--heap-gain]

WORKBOOK_OR_DIR is a lab workbook (``.xlsx`` or CSV folder) or a calibration campaign folder
(``results.json``); for a campaign the result is also written to ``DIR/critique.json``, which
the report renders, and the twin runs are kept in ``DIR/critique_runs``. With ``--heap-gain``
the campaign is run again with each accepted extension (``DIR/heap_gain/<extension>``, one
campaign each, resumable) and the heaps compared.
"""

from __future__ import annotations

from pathlib import Path

from demcal.errors import InputError
from demcal.jsonio import write_json
from demcal.measure.cli import add_workbook_options, read_options


def _list(text: str, what: str) -> tuple:
    items = tuple(s.strip() for s in text.split(",") if s.strip())
    if text.strip() and not items:
        raise InputError(f"{what} must be a comma-separated list, got {text!r}")
    return items


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "critique", help="twins, discrepancies, mechanisms and extension gains of a calibrated model",
        description="Run the twin of every lab test with the calibrated parameters, test the residual "
                    "structure against every covariate, judge a catalogue of mechanisms and measure the "
                    "gain of the model extensions that answer the ones found.")
    p.add_argument("source", metavar="WORKBOOK_OR_DIR", help="lab workbook or calibration campaign folder")
    p.add_argument("--json", metavar="OUT", help="write the critique here (a campaign folder also gets "
                                                 "DIR/critique.json)")
    p.add_argument("--no-twins", action="store_true", help="only the residual structure of the measurements")
    p.add_argument("--rigs", default="drop,incline,repose", help="twins to run (default: %(default)s)")
    p.add_argument("--extensions", default="inverted_restitution,velocity_dependent_restitution,size_distribution",
                   help="extensions to evaluate for found mechanisms ('' for none; default: %(default)s)")
    p.add_argument("--alpha", type=float, default=0.01, help="significance after correction (%(default)s)")
    p.add_argument("--correction", default="bh", choices=("bh", "holm"),
                   help="multiple-testing correction: Benjamini-Hochberg or Holm (%(default)s)")
    p.add_argument("--workers", type=int, default=1, help="worker processes for the twins (%(default)s)")
    p.add_argument("--store", metavar="DIR", help="run store of the twins (default: DIR/critique_runs for a "
                                                  "campaign, else temporary)")
    p.add_argument("--repose-seeds", type=int, default=0,
                   help="repose twins to run when no campaign gives validation runs (%(default)s)")
    p.add_argument("--seed", type=int, default=0, help="seed of the bootstrap intervals (%(default)s)")
    p.add_argument("--progress", action="store_true", help="show progress bars")
    p.add_argument("--heap-gain", action="store_true",
                   help="campaign folder only: recalibrate with each accepted extension (a whole campaign "
                        "each, in DIR/heap_gain/) and report what it changes in the calibrated parameters "
                        "and in the heap observables the calibration does not fit")
    add_workbook_options(p)
    p.set_defaults(handler=critique_command)


def critique_command(args) -> int:
    from demcal.analyse.critique.loop import run_critique
    from demcal.simulate.extensions import EXTENSIONS

    source = Path(args.source)
    campaign = source.is_dir() and (source / "results.json").is_file()
    if args.json is None and not campaign:
        raise InputError("give --json OUT (only a campaign folder has a default output, DIR/critique.json)")
    extensions = _list(args.extensions, "--extensions")
    unknown = [e for e in extensions if e not in EXTENSIONS]
    if unknown:
        raise InputError(f"unknown extension(s) {', '.join(unknown)}; valid: {', '.join(EXTENSIONS)}")
    if args.workers < 1:
        raise InputError(f"--workers must be >= 1, got {args.workers}")
    if args.repose_seeds < 0:
        raise InputError(f"--repose-seeds must be >= 0, got {args.repose_seeds}")
    result = run_critique(source, twins=not args.no_twins, rigs=_list(args.rigs, "--rigs"),
                          extensions=extensions, alpha=args.alpha, correction=args.correction,
                          store_dir=args.store, workers=args.workers, progress=args.progress,
                          repose_seeds=args.repose_seeds, seed=args.seed, heap_gain=args.heap_gain,
                          reading=read_options(args))
    doc = result.to_dict()
    written = []
    if args.json:
        written.append(write_json(args.json, doc))
    if campaign and not (args.json and Path(args.json).resolve() == (source / "critique.json").resolve()):
        written.append(write_json(source / "critique.json", doc))
    print(result.summary())
    print("wrote " + ", ".join(str(p) for p in written))
    return 0
