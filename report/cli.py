"""``demcal report DIR`` and ``demcal audit DIR``."""

from __future__ import annotations

import sys
from pathlib import Path

from demcal.jsonio import write_json
from demcal.text import control_characters, one_line

EXIT_DIFFERENCES = 1


def register(subparsers) -> None:
    rep = subparsers.add_parser(
        "report", help="rebuild the HTML and PDF report of a campaign from its stored results",
        description="Render DIR/results.json, the run records in DIR/runs and, when present, "
        "DIR/critique.json as a report laid out like the source paper: DIR/tables.json (every "
        "table with its sources), DIR/runs.csv (every DEM run, one row each), DIR/figures/, "
        "DIR/report.html and DIR/report.pdf (A4). Nothing is recomputed.")
    rep.add_argument("dir", type=Path, help="campaign folder made by 'demcal calibrate'")
    rep.add_argument("--no-pdf", action="store_true", help="write the HTML only")
    rep.set_defaults(handler=_run_report)

    aud = subparsers.add_parser(
        "audit", help="re-derive every table of a report from the workbook and the run store",
        description="Check the SHA-256 of every source file, measure the workbook again, replay "
        "the analysis from the stored DEM runs (no DEM is run), rebuild every table and compare "
        "it cell by cell with DIR/tables.json, and DIR/runs.csv with the run records. Prints OK or "
        "the differing cells per table; exits 1 on any difference or on a missing or changed "
        "source file.")
    aud.add_argument("dir", type=Path, help="campaign folder holding tables.json")
    aud.add_argument("--json", type=Path, help="also write the findings as JSON to this file")
    aud.set_defaults(handler=_run_audit)


def _run_report(args) -> int:
    from demcal.report.render import build_report

    paths = build_report(args.dir, pdf=not args.no_pdf)
    print("report: " + ", ".join(str(p) for p in paths))
    return 0


def _run_audit(args) -> int:
    from demcal.report.audit import audit

    result = audit(args.dir)
    for line in result.lines():
        # a line quoting a table's text (a workbook id) is reduced only when that text could
        # break it: the others keep their layout
        print(one_line(line, limit=2000) if control_characters(line) else line)
    if args.json:
        write_json(args.json, result.to_dict())
    sys.stdout.flush()
    return 0 if result.ok else EXIT_DIFFERENCES
