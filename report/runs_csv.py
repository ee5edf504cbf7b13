"""``runs.csv``: every DEM run of a campaign, one row each, beside the report.

The PDF sums the runs up by stage (Table A2); the list of every run with its key is too long for
it (a plausible campaign makes hundreds). The rows are read from the run records the campaign's
results name (``DIR/runs/<key>.json``) and the stages that name them; nothing is computed.
``demcal audit`` builds the rows again from the run records and compares them cell by cell.

Every text cell is one line (:func:`demcal.text.one_line`), and one a spreadsheet would read
as a formula (starting with ``=``, ``+``, ``-`` or ``@``) is prefixed with ``'``. Numbers are
written as Python writes them back exactly, so the file re-derives to the character.
"""

from __future__ import annotations

import csv
from pathlib import Path

from demcal.report.tables import Campaign, run_stages
from demcal.text import no_formula, one_line

#: The run list's file name, in the campaign folder beside the report.
RUNS_CSV = "runs.csv"

#: Columns before the observables (then one column per observable name, in order of first
#: appearance over the runs).
COLUMNS = ("key", "stage", "rig", "seed", "status", "attempts", "wall_s", "error")

def csv_cell(value) -> str:
    """One cell as written: empty for None, numbers exactly (``repr``), text on one line and
    never read as a formula."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    return no_formula(one_line(value))


def run_list(c: Campaign) -> tuple[list[str], list[list[str]]]:
    """The header and rows of ``runs.csv``: one row per run record the campaign's results name,
    in campaign order, with every stage that used it (separated by ``; ``)."""
    stages: dict = {}
    for stage, runs in run_stages(c.results):
        for run in runs:
            named = stages.setdefault(run["key"], [])
            if stage not in named:
                named.append(stage)
    observed = [(c.runs[key].get("result") or {}).get("observable") or {} for key in stages]
    names = list(dict.fromkeys(name for obs in observed for name in obs))
    rows = []
    for (key, used_by), obs in zip(stages.items(), observed):
        rec = c.runs[key]
        inputs = rec.get("inputs") or {}
        cells = (key, "; ".join(used_by), inputs.get("rig"), inputs.get("seed"), rec.get("status"),
                 rec.get("attempts"), rec.get("wall_s"), rec.get("error"), *[obs.get(n) for n in names])
        rows.append([csv_cell(v) for v in cells])
    return [csv_cell(name) for name in (*COLUMNS, *names)], rows


def write_runs_csv(c: Campaign, path) -> Path:
    """Write ``runs.csv`` (UTF-8, the csv module's default dialect) to ``path``; returns the path."""
    header, rows = run_list(c)
    path = Path(path)
    with open(path, "w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        writer.writerows(rows)
    return path


def read_runs_csv(path) -> tuple[list[str], list[list[str]]]:
    """The header and rows of a ``runs.csv``, as text."""
    with open(path, newline="", encoding="utf-8") as f:
        rows = list(csv.reader(f))
    return (rows[0] if rows else []), rows[1:]
