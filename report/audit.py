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
   absolute 1e-12, so that numerical zeros such as 3e-16 compare equal);
5. compare the replayed results with ``results.json`` field by field (except the fields that
   record how the campaign ran rather than what it found: ``VOLATILE_RESULTS`` and the time and
   code version inside each ``provenance``);
6. build ``runs.csv`` again from the run records and compare it cell by cell, and its SHA-256
   with the one ``tables.json`` records (``artefacts``);
7. render the report again from the stored results and the re-derived tables and compare what
   a reader reads: the text of every cell and paragraph of ``report.html``, and the text and
   images of ``report.pdf`` read back with pypdf against a PDF rendered afresh;
8. draw the figures again from the same results and compare each PNG byte for byte (SHA-256)
   with the report's, and with the SHA-256 ``tables.json`` recorded when the report drew them.
   Drawn with another matplotlib than the report's (``tables.json`` records its version), the
   bytes may differ without a number differing: the figures are then reported as not compared,
   and the audit fails, as it has not checked what the reader sees.

The critique tables are rebuilt from the stored ``critique.json`` (checked by its hash): the
critique stage's own re-derivation is not part of this audit.
"""

from __future__ import annotations

import base64
import hashlib
import json
import math
import re
import tempfile
from dataclasses import dataclass, replace
from difflib import SequenceMatcher
from html.parser import HTMLParser
from pathlib import Path

from demcal.analyse.results import CampaignResult
from demcal.errors import DemcalError, InputError
from demcal.jsonio import read_json, to_jsonable
from demcal.provenance import sha256_file
from demcal.report.runs_csv import RUNS_CSV, read_runs_csv, run_list
from demcal.report.tables import (RESULT_TABLE_IDS, Campaign, build_tables, load_critique, load_paper,
                                  normalised, run_keys, shipped_file)

#: Relative and absolute tolerance of a float cell.
REL_TOL = 1e-9
ABS_TOL = 1e-12
#: Status of figures drawn again by another matplotlib than the report's, whose bytes differ.
NOT_COMPARED = "not compared"


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
    artefacts: tuple = ()

    @property
    def ok(self) -> bool:
        return (all(f.status == "ok" for f in self.files) and all(t.status == "ok" for t in self.tables)
                and all(a.status == "ok" for a in self.artefacts) and not self.problems)

    def to_dict(self) -> dict:
        return {"directory": self.directory, "ok": self.ok, "files": [f.to_dict() for f in self.files],
                "tables": [t.to_dict() for t in self.tables], "problems": list(self.problems),
                "artefacts": [a.to_dict() for a in self.artefacts]}

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
        for a in self.artefacts:
            out += a.lines()
        n_cells = sum(len(t.differences) for t in self.tables)
        n_tables = sum(t.status != "ok" for t in self.tables)
        n_art = [a.artefact for a in self.artefacts if a.status != "ok"]
        out.append("audit: OK, every table re-derived from its sources, and results.json, runs.csv, "
                   "report.html, report.pdf and the figures agree with them" if self.ok else
                   f"audit: FAILED ({len(bad)} missing or changed file(s), {n_tables} table(s) not "
                   f"matching, {n_cells} differing cell(s)"
                   + (f"; differs: {', '.join(n_art)}" if n_art else "") + ")")
        return out


@dataclass(frozen=True)
class PlaceDifference:
    """What a reader reads differently in one place of an artefact.

    Attributes
    ----------
    place : str
        Where: a JSON path in results.json (``validation.mean_deg``), a table cell or a section
        of report.html, a page and line of report.pdf.
    stored, derived : str
        The text (or value) found and the one re-derived.
    """

    place: str
    stored: object
    derived: object

    def to_dict(self) -> dict:
        return {"place": self.place, "stored": self.stored, "derived": self.derived}


@dataclass(frozen=True)
class ArtefactCheck:
    """The audit of one artefact a reader receives (results.json, runs.csv, report.html,
    report.pdf).

    Attributes
    ----------
    artefact : str
    status : str
        ``ok``, ``differs``, ``missing``, ``not checked`` (see ``reason``) or, for the figures
        only, ``not compared`` (drawn again by another matplotlib, whose bytes differ).
    differences : tuple of PlaceDifference
    reason : str
    """

    artefact: str
    status: str
    differences: tuple = ()
    reason: str = ""

    def to_dict(self) -> dict:
        return {"artefact": self.artefact, "status": self.status,
                "differences": [d.to_dict() for d in self.differences], "reason": self.reason}

    def lines(self, limit: int = 20) -> list[str]:
        head = f"{self.artefact}: "
        if self.status == "ok":
            return [head + "OK"]
        if self.status != "differs":
            return [head + self.status.upper() + (f": {self.reason}" if self.reason else "")]
        out = [head + f"{len(self.differences)} difference(s)"]
        out += [f"  {self.artefact}, {d.place}: reads {d.stored!r}, re-derived {d.derived!r}"
                for d in self.differences[:limit]]
        if len(self.differences) > limit:
            out.append(f"  ... and {len(self.differences) - limit} more")
        return out


# ----------------------------------------------------------------------------------------------

def check_files(inputs: dict, out_dir: Path) -> list[FileCheck]:
    """Compare each recorded SHA-256 with the file's present one."""
    checks = []
    for name, stored in inputs.items():
        p = shipped_file(name) or Path(name)
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


#: Fields of results.json that record how the campaign ran, not what it found (a replay from the
#: run store reuses every run and takes its own time): at the top, inside every ``provenance``,
#: and anywhere (where the annotated photos were written).
VOLATILE_RESULTS = ("runner", "wall_s", "stages")
VOLATILE_PROVENANCE = ("created", "code")
VOLATILE_ANYWHERE = ("annotated",)


def _volatile(path: str, key: str) -> bool:
    return (key in VOLATILE_ANYWHERE or (not path and key in VOLATILE_RESULTS)
            or (path.endswith("provenance") and key in VOLATILE_PROVENANCE))


def compare_results(stored, derived, path: str = "") -> list[PlaceDifference]:
    """Every field where ``results.json`` differs from the replayed results, by JSON path
    (``derived`` is compared as it would be written: tuples as lists, NaN as null)."""
    if not path:
        derived = to_jsonable(derived)
    if isinstance(stored, dict) and isinstance(derived, dict):
        diffs = []
        for key in dict.fromkeys(list(stored) + list(derived)):
            if _volatile(path, key):
                continue
            where = f"{path}.{key}" if path else str(key)
            if key not in stored or key not in derived:
                diffs.append(PlaceDifference(where, stored.get(key, "(absent)"), derived.get(key, "(absent)")))
            else:
                diffs += compare_results(stored[key], derived[key], where)
        return diffs
    if isinstance(stored, list) and isinstance(derived, list):
        if len(stored) != len(derived):
            return [PlaceDifference(f"{path} (length)", len(stored), len(derived))]
        diffs = []
        for i, (a, b) in enumerate(zip(stored, derived)):
            diffs += compare_results(a, b, f"{path}[{i}]")
        return diffs
    return [] if _same(stored, derived) else [PlaceDifference(path, stored, derived)]


class _ReaderText(HTMLParser):
    """The words a reader reads in an HTML report, each with its place: the table cell (table
    id, row, column) or the section heading it is under. Style, script and image data are not
    read."""

    SKIP = ("style", "script", "title")

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.words: list[tuple[str, tuple]] = []
        self.section = "top of the report"
        self._heading: list[str] | None = None
        self._skip = 0
        self._table_id: str | None = None
        self._div_depth = 0
        self._table_depth = -1
        self._row = self._col = -1
        self._in_head = False
        self.headers: dict = {}
        self.row_labels: dict = {}

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag in self.SKIP:
            self._skip += 1
        elif tag in ("h1", "h2", "h3", "h4"):
            self._heading = []
        elif tag == "div":
            self._div_depth += 1
            if (attrs.get("id") or "").startswith("table-"):
                self._table_id = attrs["id"][len("table-"):]
                self._table_depth = self._div_depth
                self._row = -1
        elif tag == "thead":
            self._in_head = True
        elif tag == "tr" and self._table_id is not None:
            self._col = -1
            if not self._in_head:
                self._row += 1
        elif tag in ("td", "th") and self._table_id is not None:
            self._col += 1

    def handle_endtag(self, tag):
        if tag in self.SKIP:
            self._skip -= 1
        elif tag in ("h1", "h2", "h3", "h4") and self._heading is not None:
            self.section = " ".join(" ".join(self._heading).split())
            self._heading = None
        elif tag == "thead":
            self._in_head = False
        elif tag == "table":
            self._col = -1
        elif tag == "div":
            if self._div_depth == self._table_depth:
                self._table_id, self._table_depth = None, -1
            self._div_depth -= 1

    def handle_data(self, data):
        if self._skip:
            return
        if self._heading is not None:
            self._heading.append(data)
        words = data.split()
        if not words:
            return
        if self._table_id is not None and self._col >= 0:
            key = (self._table_id, self._row, self._col)
            if self._in_head:
                self.headers[(self._table_id, self._col)] = (
                    self.headers.get((self._table_id, self._col), "") + " " + data).strip()
                place = ("table", self._table_id, "head", self._col)
            else:
                if self._col == 0:
                    self.row_labels[(self._table_id, self._row)] = (
                        self.row_labels.get((self._table_id, self._row), "") + data).strip()
                place = ("table",) + key
        else:
            place = ("section", self.section, self._table_id)
        self.words += [(w, place) for w in words]

    def describe(self, place: tuple) -> str:
        if place[0] == "table":
            _, tid, row, col = place
            column = " ".join(self.headers.get((tid, col), f"#{col + 1}").split())
            if row == "head":
                return f"Table {tid}, column heading '{column}'"
            label = " ".join(self.row_labels.get((tid, row), "").split())
            return f"Table {tid}, row {row + 1} ({label}), column '{column}'"
        _, section, tid = place
        return f"section '{section}'" + (f", near Table {tid}" if tid else "")


def reader_words(html_text: str) -> _ReaderText:
    """Parse ``html_text`` into the words a reader reads, with their places."""
    parser = _ReaderText()
    parser.feed(html_text)
    parser.close()
    return parser


def _word_differences(stored: list[tuple[str, object]], derived: list[tuple[str, object]],
                      describe) -> list[PlaceDifference]:
    """Aligned differences of two word sequences; each names the place of the stored words."""
    a = [w for w, _ in stored]
    b = [w for w, _ in derived]
    diffs = []
    for op, i1, i2, j1, j2 in SequenceMatcher(None, a, b, autojunk=False).get_opcodes():
        if op == "equal":
            continue
        place = stored[i1][1] if i1 < i2 else (stored[i1 - 1][1] if i1 else derived[j1][1])
        diffs.append(PlaceDifference(describe(place), " ".join(a[i1:i2]), " ".join(b[j1:j2])))
    return diffs


def compare_html(stored_text: str, derived_text: str) -> list[PlaceDifference]:
    """Where the words of a stored HTML report differ from a freshly rendered one."""
    stored, derived = reader_words(stored_text), reader_words(derived_text)
    return _word_differences(stored.words, derived.words, stored.describe)


def pdf_words(path) -> list[tuple[str, tuple]]:
    """The words of a PDF read back with pypdf, each with its page and line."""
    from pypdf import PdfReader

    words = []
    for n, page in enumerate(PdfReader(str(path)).pages, 1):
        for line in (page.extract_text() or "").splitlines():
            words += [(w, (n, line.strip())) for w in line.split()]
    return words


def pdf_images(path) -> list[tuple[int, str]]:
    """Every image of a PDF once, in the order of the pages that first show it: the page and
    the SHA-256 of its stream as stored, encoded, with its filter and its transparency mask's.

    The encoded bytes, not the pixels: the fresh PDF is written by the same code from the same
    PNGs, so its streams are the same bytes, and decoding the PNG predictor in Python took
    about 10 s a report."""
    from pypdf import PdfReader

    def stored(obj) -> bytes:
        raw = getattr(obj, "_data", None)      # pypdf keeps a stream's bytes as read there
        data = raw if isinstance(raw, bytes) else obj.get_data()
        return repr((obj.get("/Filter"), obj.get("/DecodeParms"))).encode() + data

    seen, images = set(), []
    for n, page in enumerate(PdfReader(str(path)).pages, 1):
        xobjects = page.get("/Resources", {}).get_object().get("/XObject")
        for ref in (xobjects.get_object().values() if xobjects else ()):
            obj = ref.get_object()
            if obj.get("/Subtype") != "/Image" or ref.idnum in seen:
                continue
            seen.add(ref.idnum)
            h = hashlib.sha256(stored(obj))
            if obj.get("/SMask") is not None:
                h.update(stored(obj["/SMask"].get_object()))
            images.append((n, h.hexdigest()))
    return images


def compare_pdf(stored_pdf, derived_pdf) -> list[PlaceDifference]:
    """Where the text of a stored PDF report differs from a freshly rendered one, and which
    of its images differ from the fresh one's (drawn from the same PNGs)."""
    def describe(place):
        page, line = place
        return f"page {page}, line '{line[:90]}'"
    diffs = _word_differences(pdf_words(stored_pdf), pdf_words(derived_pdf), describe)
    stored, derived = pdf_images(stored_pdf), pdf_images(derived_pdf)
    for k in range(max(len(stored), len(derived))):
        a, b = (stored[k] if k < len(stored) else None), (derived[k] if k < len(derived) else None)
        if a is None or b is None or a[1] != b[1]:
            page = (a or b)[0]
            diffs.append(PlaceDifference(f"page {page}, image {k + 1}, SHA-256",
                                         a[1] if a else "no image", b[1] if b else "no image"))
    return diffs


def compare_runs_csv(path: Path, campaign: Campaign, recorded: str | None) -> list[PlaceDifference]:
    """Where ``runs.csv`` differs from the rows re-derived from the run records (``campaign``:
    re-derived), cell by cell, rows counted from 1 under the header; when every cell agrees,
    whether its bytes still have the SHA-256 ``recorded`` in tables.json."""
    header, rows = run_list(campaign)
    stored_header, stored_rows = read_runs_csv(path)
    diffs = []
    if stored_header != header:
        diffs.append(PlaceDifference("header", stored_header, header))
    if len(stored_rows) != len(rows):
        diffs.append(PlaceDifference("number of rows", len(stored_rows), len(rows)))
    for i, (a, b) in enumerate(zip(stored_rows, rows), 1):
        for j in range(max(len(a), len(b))):
            x, y = (a[j] if j < len(a) else None), (b[j] if j < len(b) else None)
            if x != y:
                column = header[j] if j < len(header) else f"#{j + 1}"
                diffs.append(PlaceDifference(f"row {i} (key {b[0]}), column '{column}'", x, y))
    current = sha256_file(path)
    if not diffs and current != recorded:
        diffs.append(PlaceDifference("SHA-256 (re-derived: the one tables.json records)", current, recorded))
    return diffs


def check_artefacts(out: Path, campaign: Campaign, derived_tables: list[dict],
                    reason: str = "", recorded: dict | None = None) -> list[ArtefactCheck]:
    """Compare results.json, runs.csv, report.html and report.pdf with what the sources give.

    ``campaign`` is the re-derived campaign (``rederive``); ``recorded`` the SHA-256 of the
    report's files as tables.json records them (``artefacts``). The report is rendered again
    from the re-derived results (with the stored values of the fields that record how the
    campaign ran) and the re-derived tables, so that a change in any one artefact is reported
    in that artefact only.
    """
    from demcal.report.figures import FIGURES, make_figures
    from demcal.report.render import render_html, write_pdf

    if campaign.results is None:
        why = reason or "the analysis was not replayed"
        return [ArtefactCheck(name, "not checked", reason=why)
                for name in ("results.json", RUNS_CSV, "report.html", "report.pdf", FIGURES)]
    stored = read_json(out / "results.json")
    derived = campaign.results.to_dict()
    checks = [_check("results.json", compare_results(stored, derived))]
    runs_csv = out / RUNS_CSV
    checks.append(_check(RUNS_CSV, compare_runs_csv(runs_csv, campaign, (recorded or {}).get(RUNS_CSV)))
                  if runs_csv.is_file() else ArtefactCheck(RUNS_CSV, "missing", reason=f"{runs_csv} not found"))
    html_path, pdf_path = out / "report.html", out / "report.pdf"
    if not html_path.is_file():
        return checks + [ArtefactCheck("report.html", "missing", reason=f"{html_path} not found"),
                         ArtefactCheck("report.pdf", "not checked", reason="no report.html")]
    results = CampaignResult.from_dict(with_run_record(derived, stored))
    rendered = replace(campaign, results=results, measurement=results.measurement or campaign.measurement)
    with tempfile.TemporaryDirectory(prefix="demcal-audit-") as tmp:
        # the report's own PNGs when they are all there (the report embeds them, so its layout,
        # and the PDF's words, are those of these images; figures are not compared), else drawn
        figures = make_figures(rendered, out / "figures", draw=False)
        if not all(f.path.is_file() for f in figures):
            figures = make_figures(rendered, Path(tmp) / "figures")
        html_text = render_html(rendered, derived_tables, figures)
        checks.append(_check("report.html", compare_html(html_path.read_text(encoding="utf-8"), html_text)))
        if not pdf_path.is_file():
            checks.append(ArtefactCheck("report.pdf", "missing", reason=f"{pdf_path} not found"))
        else:
            fresh = write_pdf(html_text, Path(tmp) / "report.pdf", base_url=out)
            checks.append(_check("report.pdf", compare_pdf(pdf_path, fresh)))
        checks.append(compare_figures(rendered, out, html_path.read_text(encoding="utf-8"),
                                      (recorded or {}).get(FIGURES) or {}, Path(tmp) / "redrawn"))
    return checks


def html_images(html_text: str) -> dict:
    """The PNG bytes of each figure an HTML report embeds, by its number."""
    return {int(n): base64.b64decode(data) for data, n in
            re.findall(r'<img src="data:image/png;base64,([A-Za-z0-9+/=]*)" alt="Fig\. (\d+)">', html_text)}


def compare_figures(rendered: Campaign, out: Path, html_text: str, record: dict, tmp: Path) -> ArtefactCheck:
    """Each figure of the report (embedded in ``html_text``, and its PNG in ``figures/`` when
    there) against the one drawn again from ``rendered`` into ``tmp`` and against the SHA-256
    ``record`` holds (``report.figures.figure_record``). Only the comparisons with the figures
    drawn again depend on matplotlib's version: when they alone differ and the version is not
    the report's, the figures are ``not compared``."""
    import matplotlib

    from demcal.report.figures import DPI, FIGURES, make_figures

    theirs = make_figures(rendered, out / "figures", draw=False)
    fresh = make_figures(rendered, tmp, dpi=int(record.get("dpi", DPI)))
    embedded, recorded = html_images(html_text), record.get("sha256", {})
    changed, redrawn = [], []
    for n, (mine, new) in enumerate(zip(theirs, fresh), 1):
        name, drawn = mine.path.relative_to(out).as_posix(), sha256_file(new.path)
        kept = sha256_file(mine.path) if mine.path.is_file() else None
        known = recorded.get(name, kept)
        if kept is not None and known != kept:
            changed.append(PlaceDifference(f"{name}, SHA-256 (the one tables.json records)", kept, known))
        elif kept is not None and kept != drawn:
            redrawn.append(PlaceDifference(f"{name}, SHA-256 (drawn again from the sources)", kept, drawn))
        shown = hashlib.sha256(embedded[n]).hexdigest() if n in embedded else "no image"
        if known is not None and shown != known:
            changed.append(PlaceDifference(f"report.html, Fig. {n}, SHA-256 ({name})", shown, known))
        elif shown != drawn:
            redrawn.append(PlaceDifference(f"report.html, Fig. {n}, SHA-256 (drawn again from the sources)",
                                           shown, drawn))
    extra = sorted(set(embedded) - set(range(1, len(theirs) + 1)))
    changed += [PlaceDifference(f"report.html, Fig. {n}", "an image", "no such figure") for n in extra]
    version = record.get("matplotlib")
    if redrawn and not changed and version != matplotlib.__version__:
        return ArtefactCheck(FIGURES, NOT_COMPARED, reason=(
            f"drawn with matplotlib {version or '(not recorded)'}, drawn again with {matplotlib.__version__}, "
            f"whose bytes differ: audit where the report was built, or build it again ('demcal report')"))
    return _check(FIGURES, changed + redrawn)


def with_run_record(derived, stored, path: str = ""):
    """``derived`` with the stored values of the fields that record how the campaign ran
    (``_volatile``), so that a report rendered from it matches one rendered from the stored
    results whenever the re-derivable fields agree."""
    if isinstance(derived, list) and isinstance(stored, list) and len(derived) == len(stored):
        return [with_run_record(d, s_, f"{path}[{i}]") for i, (d, s_) in enumerate(zip(derived, stored))]
    if not (isinstance(derived, dict) and isinstance(stored, dict)):
        return derived
    out = {k: with_run_record(v, stored.get(k), f"{path}.{k}" if path else k) for k, v in derived.items()}
    out.update({k: v for k, v in stored.items() if _volatile(path, k)})
    return out


def _check(name: str, diffs: list[PlaceDifference]) -> ArtefactCheck:
    return ArtefactCheck(name, "differs" if diffs else "ok", tuple(diffs))


def rederive(out_dir) -> tuple[Campaign | None, list[str]]:
    """Measure the workbook again and replay the analysis from the run store.

    Returns the campaign to build tables from (None when the workbook cannot be measured;
    ``results`` None when the replay failed) and the problems met.
    """
    from demcal.analyse.campaign import CampaignConfig, derive_results
    from demcal.measure.pipeline import Measurement, measure_workbook
    from demcal.measure.workbook import ReadOptions

    out = Path(out_dir)
    problems = []
    results = read_json(out / "results.json")
    stored_m = results.get("measurement") or read_json(out / "measure.json")
    source = stored_m.get("workbook", {}).get("source")
    opts = stored_m.get("provenance", {}).get("options", {})
    kwargs = {k: opts[k] for k in ("outliers", "r2_min", "g") if k in opts}
    try:
        # read as the campaign read it: the same CSV dialect, ranges, folders and limits
        measurement = measure_workbook(source, reading=ReadOptions.from_dict(opts.get("reading")), **kwargs)
    except (DemcalError, OSError) as exc:
        return None, [f"the workbook {source} cannot be measured again: {exc}"]
    derived = None
    try:
        config = CampaignConfig.from_dict(results["config"])
        derived = derive_results(Measurement.from_dict(measurement.to_dict()), config, out / "runs")
    except DemcalError as exc:
        problems.append(f"analysis not replayed: {exc}")
    runs = {}
    for key in (run_keys(derived) if derived is not None else []):
        p = out / "runs" / f"{key}.json"
        runs[key] = read_json(p)
    paper, paper_source = load_paper()
    critique, critique_source = load_critique(out)
    return Campaign(measurement=measurement.to_dict(), results=derived, runs=runs, paper=paper,
                    paper_source=paper_source, critique=critique, critique_source=critique_source,
                    folder=out), problems


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
    missing_inputs = [f.file for f in files if f.status == "missing" and Path(f.file).is_absolute()]
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
    artefacts = check_artefacts(out, campaign, list(derived.values()), problems[0] if problems else "",
                                stored_doc.get("artefacts", {}))
    return AuditResult(str(out), tuple(files), tuple(checks), tuple(problems), tuple(artefacts))
