"""``demcal measure``: every material quantity from a lab workbook."""

from __future__ import annotations

import sys
from pathlib import Path

from demcal.jsonio import write_json
from demcal.measure.estimate import OUTLIER_RULES, parse_outlier_rule


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
    p.set_defaults(handler=run)


def run(args) -> int:
    from demcal.measure.pipeline import measure_workbook
    from demcal.measure.workbook import read_workbook

    parse_outlier_rule(args.outliers)  # a bad rule fails before any work
    out = Path(args.json_out) if args.json_out else None
    annotate_dir = args.annotate_dir
    if annotate_dir is None and out is not None:
        annotate_dir = out.parent / f"{out.stem}_annotated"
    wb = read_workbook(args.workbook)
    m = measure_workbook(wb, outliers=args.outliers, annotate_dir=annotate_dir, r2_min=args.r2_min)
    if out is not None:
        write_json(out, m.to_dict())
    print(f"{m.material}: {len(m.quantities)} quantities from {wb.source}")
    print(m.table())
    if out is not None:
        print(f"written: {out}")
    for note in m.notes:
        print(f"note: {note}", file=sys.stderr)
    return 0
