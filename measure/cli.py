"""``demcal measure``: every material quantity from a lab workbook."""

from __future__ import annotations

import sys
from pathlib import Path

from demcal.errors import InputError
from demcal.jsonio import write_json
from demcal.text import one_line
from demcal.measure.estimate import OUTLIER_RULES, parse_outlier_rule


def add_workbook_options(p) -> None:
    """The options of every command that reads a workbook: how to read it and its bounds."""
    g = p.add_argument_group("reading the workbook")
    g.add_argument("--csv-separator", choices=(",", ";", "tab"), default=None,
                   help="separator of CSV sheets, curves and tracks (default: detected and stated)")
    g.add_argument("--csv-decimal", choices=(".", ","), default=None,
                   help="decimal mark of CSV sheets, curves and tracks (default: detected and stated)")
    g.add_argument("--range", dest="ranges", action="append", default=[], metavar="NAME=LO:HI",
                   help="plausible range of a column or meta key, replacing the stated one "
                        "(docs/workbook.md); repeatable")
    g.add_argument("--allow-folder", dest="allowed_folders", action="append", default=[],
                   metavar="DIR", help="a folder outside the workbook's own that photo, curve and "
                                       "track paths may point into; repeatable")
    g.add_argument("--max-photo-pixels", type=int, default=None, metavar="N",
                   help="largest photo read, width x height (default: measure.images.MAX_PHOTO_PIXELS)")
    g.add_argument("--max-file-mb", type=float, default=None, metavar="MB",
                   help="largest workbook file, and largest an .xlsx may unpack to (default 50)")


def read_options(args):
    """:class:`measure.workbook.ReadOptions` from the options of :func:`add_workbook_options`."""
    from demcal.measure.workbook import ReadOptions

    ranges = {}
    for item in args.ranges:
        name, sep, bounds = item.partition("=")
        lo, sep2, hi = bounds.partition(":")
        try:
            if not (sep and sep2 and name.strip()):
                raise ValueError
            ranges[name.strip()] = (float(lo), float(hi))
        except ValueError:
            raise InputError(f"--range {item!r}: expected NAME=LO:HI, e.g. length_mm=0.01:2000") from None
    kwargs = {}
    if args.max_file_mb is not None:
        kwargs["max_file_bytes"] = int(args.max_file_mb * 2**20)
    if args.max_photo_pixels is not None and args.max_photo_pixels < 1:
        raise InputError(f"--max-photo-pixels must be positive, got {args.max_photo_pixels}")
    return ReadOptions(csv_separator="\t" if args.csv_separator == "tab" else args.csv_separator,
                       csv_decimal=args.csv_decimal, ranges=ranges,
                       allowed_folders=tuple(str(Path(f).resolve()) for f in args.allowed_folders),
                       max_photo_pixels=args.max_photo_pixels, **kwargs)


def register(subparsers) -> None:
    """Add the ``measure`` sub-command."""
    p = subparsers.add_parser(
        "measure", help="measure every material parameter from a lab workbook",
        description="Read a lab workbook (.xlsx or a folder of <sheet>.csv), validate it and "
                    "estimate every quantity with sd, n, 95 % CI, rows used and rejected, and "
                    "source hashes. Prints a table; writes the full result as JSON with --json.")
    p.add_argument("workbook", help="the .xlsx file or the folder of CSV sheets")
    p.add_argument("--json", dest="json_out", metavar="OUT", help="write the measurement to this JSON file")
    p.add_argument("--annotate-dir", metavar="DIR",
                   help="folder for annotated heap photos (default: OUT's name + '_annotated' beside OUT)")
    p.add_argument("--outliers", default="none", metavar="RULE",
                   help=f"outlier rule: {', '.join(OUTLIER_RULES)}, optionally with a limit "
                        "('mad:3.5' = modified z-score limit, 'grubbs:0.05' = significance); default none: every row is used")
    p.add_argument("--r2-min", type=float, default=0.995,
                   help="R^2 the initial linear part of a compression curve must reach (default 0.995)")
    add_workbook_options(p)
    p.set_defaults(handler=run)


def run(args) -> int:
    from demcal.measure.pipeline import measure_workbook
    from demcal.measure.workbook import read_workbook

    parse_outlier_rule(args.outliers)  # a bad rule fails before any work
    options = read_options(args)
    out = Path(args.json_out) if args.json_out else None
    annotate_dir = args.annotate_dir
    if annotate_dir is None and out is not None:
        annotate_dir = out.parent / f"{out.stem}_annotated"
    wb = read_workbook(args.workbook, options)
    m = measure_workbook(wb, outliers=args.outliers, annotate_dir=annotate_dir, r2_min=args.r2_min)
    if out is not None:
        write_json(out, m.to_dict())
    print(f"{one_line(m.material)}: {len(m.quantities)} quantities from {one_line(wb.source)}")
    print(m.table())
    if out is not None:
        print(f"written: {one_line(out)}")
    for note in m.notes:
        print(f"note: {one_line(note, limit=2000)}", file=sys.stderr)
    return 0
