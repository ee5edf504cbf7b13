"""``demcal audit``: re-derive every table of a report from its sources and compare.

Steps:

1. check the SHA-256 of every file the tables rest on (``tables.json`` ``inputs``: the
   workbook and the files its rows read, the paper's numbers, every run record, critique.json);
   a missing or changed file is a failure that names the file;
2. measure the workbook again (``measure.pipeline.measure_workbook``, with the options the
   campaign recorded);
3. replay the campaign's analysis from the stored run records, running no DEM
   (``analyse.campaign.derive_results``); if a run the replay needs is not in the store (its
   inputs changed, e.g. because a measured level changed), the tables that need the analysis
   are reported as not re-derived;
4. rebuild the tables with the code that wrote ``tables.json`` (``report.tables.build_tables``)
   and compare them cell by cell: text and integers exactly, floats to a relative 1e-9 (and an
   absolute 1e-12, so that numerical zeros such as 3e-16 compare equal).

The critique tables are rebuilt from the stored ``critique.json`` (checked by its hash): the
critique stage's own re-derivation is not part of this audit.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

from demcal.errors import DemcalError, InputError
from demcal.jsonio import read_json
from demcal.provenance import sha256_file
from report.tables import (PAPER_FILE, RESULT_TABLE_IDS, Campaign, build_tables, load_critique,
                           load_paper, normalised, run_keys)

#: Relative and absolute tolerance of a float cell.
REL_TOL = 1e-9
ABS_TOL = 1e-12


@dataclass(frozen=True)
class FileCheck:
    """One source file checked against the SHA-256 recorded in ``tables.json``.

    Attributes
    ----------
    file : str
        Path as recorded (run records and critique.json relative to the campaign folder).
    stored, current : str or None
        Recorded and present SHA-256 (``current`` None when the file is missing).
    status : str
        ``ok``, ``changed`` or ``missing``.
    """

    file: str
    stored: str | None
    current: str | None
    status: str

    def to_dict(self) -> dict:
        return {"file": self.file, "stored": self.stored, "current": self.current, "status": self.status}


@dataclass(frozen=True)
class CellDifference:
    """One cell (or structural item) that differs between the stored and re-derived table.

    Attributes
    ----------
    table : str
        Table id (``"2"``, ``"9a"``...).
    row : int or None
        Row number from 1 (None for the title, columns, units or number of rows).
    row_label : str
        First cell of that row (or what differs: ``title``, ``columns``, ``rows``...).
    column : str
        Column heading.
    stored, derived : object
        The two values.
    """

    table: str
    row: int | None
    row_label: str
    column: str
    stored: object
    derived: object

    def to_dict(self) -> dict:
        return {"table": self.table, "row": self.row, "row_label": self.row_label,
                "column": self.column, "stored": self.stored, "derived": self.derived}

    def describe(self) -> str:
        where = f"row {self.row} ({self.row_label})" if self.row is not None else self.row_label
        return (f"Table {self.table}, {where}, column '{self.column}': stored {self.stored!r}, "
                f"re-derived {self.derived!r}")


@dataclass(frozen=True)
class TableCheck:
    """The audit of one table.

    Attributes
    ----------
    id, title : str
    status : str
        ``ok``; ``differs`` (see ``differences``); ``not re-derived`` (see ``reason``);
        ``missing`` (re-derived but not in tables.json); ``extra`` (in tables.json only).
    differences : tuple of CellDifference
    reason : str
    """

    id: str
    title: str
    status: str
    differences: tuple = ()
    reason: str = ""

    def to_dict(self) -> dict:
        return {"id": self.id, "title": self.title, "status": self.status,
                "differences": [d.to_dict() for d in self.differences], "reason": self.reason}


@dataclass(frozen=True)
class AuditResult:
    """Everything ``demcal audit`` found.

    Attributes
    ----------
    directory : str
    files : tuple of FileCheck
    tables : tuple of TableCheck
    problems : tuple of str
        What stopped part of the re-derivation (e.g. a run missing from the store).
    """

    directory: str
    files: tuple
    tables: tuple
    problems: tuple = ()

    @property
    def ok(self) -> bool:
        return (all(f.status == "ok" for f in self.files) and all(t.status == "ok" for t in self.tables)
                and not self.problems)

    def to_dict(self) -> dict:
        return {"directory": self.directory, "ok": self.ok, "files": [f.to_dict() for f in self.files],
                "tables": [t.to_dict() for t in self.tables], "problems": list(self.problems)}

    def lines(self) -> list[str]:
        """The audit as text, one finding a line."""
        out = []
        bad = [f for f in self.files if f.status != "ok"]
        out.append(f"source files: {len(self.files)} checked, {len(bad)} missing or changed")
        for f in bad:
            if f.status == "missing":
                out.append(f"  MISSING  {f.file} (recorded SHA-256 {f.stored})")
            else:
                out.append(f"  CHANGED  {f.file}: SHA-256 recorded {f.stored}, now {f.current}")
        for p in self.problems:
            out.append(f"  PROBLEM  {p}")
        for t in self.tables:
            head = f"Table {t.id} ({t.title}): "
            if t.status == "ok":
                out.append(head + "OK")
            elif t.status == "differs":
                out.append(head + f"{len(t.differences)} difference(s)")
                out += ["  " + d.describe() for d in t.differences]
            else:
                out.append(head + t.status.upper() + (f": {t.reason}" if t.reason else ""))
        n_cells = sum(len(t.differences) for t in self.tables)
        n_tables = sum(t.status != "ok" for t in self.tables)
        out.append("audit: OK, every table re-derived from its sources" if self.ok else
                   f"audit: FAILED ({len(bad)} missing or changed file(s), {n_tables} table(s) not "
                   f"matching, {n_cells} differing cell(s))")
        return out


# ----------------------------------------------------------------------------------------------

def check_files(inputs: dict, out_dir: Path) -> list[FileCheck]:
    """Compare each recorded SHA-256 with the file's present one."""
    checks = []
    for name, stored in inputs.items():
        p = Path(name)
        if not p.is_absolute():
            p = out_dir / p
        if not p.is_file():
            checks.append(FileCheck(name, stored, None, "missing"))
            continue
        current = sha256_file(p)
        checks.append(FileCheck(name, stored, current, "ok" if current == stored else "changed"))
    return checks


def _same(a, b) -> bool:
    if isinstance(a, bool) or isinstance(b, bool):
        return a is b
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        if isinstance(a, int) and isinstance(b, int):
            return a == b
        return math.isclose(a, b, rel_tol=REL_TOL, abs_tol=ABS_TOL)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    return a == b


def _source_differences(tid: str, stored: list, derived: list) -> list[CellDifference]:
    """Differing fields of the sources, one line per distinct change (a changed workbook hash
    shows once, with the number of source entries it appears in)."""
    if len(stored) != len(derived):
        return [CellDifference(tid, None, "sources", "number of entries", len(stored), len(derived))]
    changes: dict = {}
    for a, b in zip(stored, derived):
        for key in dict.fromkeys(list(a) + list(b)):
            if not _same(a.get(key), b.get(key)):
                what = (key, json.dumps(a.get(key), sort_keys=True), json.dumps(b.get(key), sort_keys=True))
                changes[what] = changes.get(what, 0) + 1
    return [CellDifference(tid, None, f"sources ({n} entr{'y' if n == 1 else 'ies'})", key,
                           json.loads(x), json.loads(y)) for (key, x, y), n in changes.items()]


def compare_tables(stored: dict, derived: dict) -> list[CellDifference]:
    """Differences between one stored and one re-derived table (both as JSON dicts)."""
    tid = stored["id"]
    diffs = []
    for item in ("title", "columns", "units", "notes"):
        if not _same(stored.get(item), derived.get(item)):
            diffs.append(CellDifference(tid, None, item, item, stored.get(item), derived.get(item)))
    diffs += _source_differences(tid, stored.get("sources", []), derived.get("sources", []))
    columns = derived.get("columns", [])
    s_rows, d_rows = stored.get("rows", []), derived.get("rows", [])
    if len(s_rows) != len(d_rows):
        diffs.append(CellDifference(tid, None, "number of rows", "", len(s_rows), len(d_rows)))
    for i, (sr, dr) in enumerate(zip(s_rows, d_rows), 1):
        label = str(dr[0]) if dr else ""
        for j in range(max(len(sr), len(dr))):
            a = sr[j] if j < len(sr) else None
            b = dr[j] if j < len(dr) else None
            if not _same(a, b):
                col = columns[j] if j < len(columns) else f"#{j + 1}"
                diffs.append(CellDifference(tid, i, label, col, a, b))
    return diffs


def rederive(out_dir) -> tuple[Campaign | None, list[str]]:
    """Measure the workbook again and replay the analysis from the run store.

    Returns the campaign to build tables from (None when the workbook cannot be measured;
    ``results`` None when the replay failed) and the problems met.
    """
    from analyse.campaign import CampaignConfig, derive_results
    from measure.pipeline import Measurement, measure_workbook

    out = Path(out_dir)
    problems = []
    results = read_json(out / "results.json")
    stored_m = results.get("measurement") or read_json(out / "measure.json")
    source = stored_m.get("workbook", {}).get("source")
    opts = stored_m.get("provenance", {}).get("options", {})
    kwargs = {k: opts[k] for k in ("outliers", "r2_min", "g") if k in opts}
    try:
        measurement = measure_workbook(source, **kwargs)
    except (DemcalError, OSError) as exc:
        return None, [f"the workbook {source} cannot be measured again: {exc}"]
    derived = None
    try:
        config = CampaignConfig.from_dict(results["config"])
        derived = derive_results(Measurement.from_dict(measurement.to_dict()), config, out / "runs")
    except DemcalError as exc:
        problems.append(f"analysis not replayed: {exc}")
    runs = {}
    for key in run_keys(derived or {}):
        p = out / "runs" / f"{key}.json"
        runs[key] = read_json(p)
    paper, paper_source = load_paper()
    critique, critique_source = load_critique(out)
    return Campaign(measurement=measurement.to_dict(), results=derived, runs=runs, paper=paper,
                    paper_source=paper_source, critique=critique, critique_source=critique_source), problems


def audit(out_dir) -> AuditResult:
    """Re-derive every table of ``out_dir/tables.json`` from its sources and compare.

    Raises
    ------
    InputError
        ``tables.json`` or ``results.json`` is missing (no report to audit).
    """
    out = Path(out_dir)
    tables_path = out / "tables.json"
    if not tables_path.exists():
        raise InputError(f"{out} holds no tables.json: build the report first ('demcal report {out}')")
    if not (out / "results.json").exists():
        raise InputError(f"{out} holds no results.json")
    stored_doc = read_json(tables_path)
    files = check_files(stored_doc.get("inputs", {}), out)
    # a missing workbook file (absolute path) stops the measurement; run records, critique.json
    # (relative) and the paper's numbers only stop the tables that use them
    missing_inputs = [f.file for f in files if f.status == "missing" and Path(f.file).is_absolute()
                      and f.file != str(PAPER_FILE)]
    if missing_inputs:
        campaign, problems = None, ["workbook input(s) missing: " + ", ".join(missing_inputs)]
    else:
        campaign, problems = rederive(out)
    if campaign is None:
        checks = [TableCheck(t["id"], t["title"], "not re-derived", reason=problems[0])
                  for t in stored_doc.get("tables", [])]
        return AuditResult(str(out), tuple(files), tuple(checks), tuple(problems))
    derived = {t["id"]: t for t in normalised(build_tables(campaign))}
    checks = []
    for st in stored_doc.get("tables", []):
        tid = st["id"]
        if tid not in derived:
            reason = problems[0] if problems and tid in RESULT_TABLE_IDS else "not built from the sources"
            status = "not re-derived" if tid in RESULT_TABLE_IDS and campaign.results is None else "extra"
            checks.append(TableCheck(tid, st["title"], status, reason=reason))
            continue
        diffs = compare_tables(st, derived[tid])
        checks.append(TableCheck(tid, st["title"], "differs" if diffs else "ok", tuple(diffs)))
    stored_ids = {t["id"] for t in stored_doc.get("tables", [])}
    for tid, t in derived.items():
        if tid not in stored_ids:
            checks.append(TableCheck(tid, t["title"], "missing", reason="re-derived but not in tables.json"))
    return AuditResult(str(out), tuple(files), tuple(checks), tuple(problems))
