"""The report of the example campaign (analytic stand-in rig): the PDF holds the paper's tables,
equation and figures, and sums the runs up by stage in at most 15 pages while runs.csv lists
every run; the tables agree with independent recomputations from the workbook and the run
records; ``demcal audit`` passes on a fresh report and names the table and cell, or the file,
that was changed; the HTML needs no network; workbook text of any kind is printed as typed, and
text the report could not render stops ``demcal calibrate`` before its first DEM run."""

import base64
import copy
import csv
import hashlib
import json
import math
import re
import shutil
from dataclasses import replace
from html import unescape
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from demcal.analyse.campaign import CampaignConfig, calibrate
from demcal.cli import main
from demcal.provenance import sha256_file
from demcal.report.render import abstract, build_report, render_html, write_tables
from demcal.report.tables import PAPER_FILE, PAPER_NAME, build_tables, load_campaign
from tests.analyse.standin import heap_standin_runner, standin_runner

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "data" / "astragalus"
CONFIG = CampaignConfig(workers=1, progress=False, workflow="design-expert")


def _campaign(tmp_root: Path, name: str) -> tuple[Path, Path]:
    """Copy the example workbook folder and run the stand-in campaign on the copy."""
    if not (EXAMPLE / "workbook.xlsx").exists():
        pytest.skip(f"example workbook missing: {EXAMPLE}")
    data = tmp_root / f"{name}_data"
    shutil.copytree(EXAMPLE, data)
    out = tmp_root / name
    calibrate(data / "workbook.xlsx", out, CONFIG, runner=standin_runner)
    return data, out


def _folder_digest(folder: Path) -> str:
    """SHA-256 over the names and contents of every file under ``folder``."""
    h = hashlib.sha256()
    for p in sorted(q for q in folder.rglob("*") if q.is_file()):
        h.update(str(p.relative_to(folder)).encode() + b"\0" + hashlib.sha256(p.read_bytes()).digest())
    return h.hexdigest()


@pytest.fixture(scope="module", autouse=True)
def _memoised_audit_inputs():
    """Every audit here measures the example workbook again and reads the stored PDF's words;
    both are pure functions of file contents, so they are computed once per content: the
    measurement keyed by the workbook's path, options and every file beside it (photos
    included), the PDF's words by its SHA-256, and the PDF the audit renders again by the
    SHA-256 of its HTML (the same derived HTML gives the same PDF, wherever the campaign lies). A changed workbook, photo,
    PDF or HTML is computed afresh. Measurements that write annotated photos (``calibrate``)
    are never cached."""
    import demcal.measure.pipeline as pipeline
    import demcal.report.audit as audit_module
    import demcal.report.render as render_module

    measure, words, write_pdf = pipeline.measure_workbook, audit_module.pdf_words, render_module.write_pdf
    measured, read, rendered = {}, {}, {}

    def measure_workbook(wb, **kwargs):
        if not isinstance(wb, (str, Path)) or kwargs.get("annotate_dir") or kwargs.get("photo_estimator"):
            return measure(wb, **kwargs)
        path = Path(wb).resolve()
        key = (str(path), repr(sorted(kwargs.items())), _folder_digest(path.parent))
        if key not in measured:
            measured[key] = measure(wb, **kwargs)
        return copy.deepcopy(measured[key])

    def pdf_words(path):
        key = hashlib.sha256(Path(path).read_bytes()).hexdigest()
        if key not in read:
            read[key] = words(path)
        return list(read[key])

    def memo_pdf(text, path, base_url):
        key = hashlib.sha256(text.encode()).hexdigest()   # the HTML needs no file (test_html_works_offline)
        if key not in rendered:
            rendered[key] = Path(write_pdf(text, path, base_url)).read_bytes()
        else:
            Path(path).write_bytes(rendered[key])
        return path

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(pipeline, "measure_workbook", measure_workbook)
        mp.setattr(audit_module, "pdf_words", pdf_words)
        mp.setattr(render_module, "write_pdf", memo_pdf)
        yield


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    data, out = _campaign(tmp_path_factory.mktemp("report"), "campaign")
    paths = build_report(out)
    return {"data": data, "out": out, "html": paths[0], "pdf": paths[1],
            "tables": {t["id"]: t for t in json.loads((out / "tables.json").read_text())["tables"]},
            "results": json.loads((out / "results.json").read_text())}


def _column(table: dict, name: str) -> list:
    j = table["columns"].index(name)
    return [row[j] for row in table["rows"]]


def _row(table: dict, label: str) -> dict:
    row = next(r for r in table["rows"] if r[0] == label)
    return dict(zip(table["columns"], row))


def _audit(capsys, out: Path) -> tuple[int, str]:
    capsys.readouterr()
    code = main(["audit", str(out)])
    return code, capsys.readouterr().out


# ----------------------------------------------------------------------------------------------
# what the PDF shows

def test_pdf_holds_the_nine_tables_the_equation_and_the_figures(campaign):
    from pypdf import PdfReader

    reader = PdfReader(str(campaign["pdf"]))
    text = "\n".join(page.extract_text() for page in reader.pages)
    flat = re.sub(r"\s+", " ", text)
    for tid in ("1", "2", "3", "4", "5", "6", "7", "8", "9"):
        t = campaign["tables"][tid]
        assert f"Table {tid}" in text, tid
        assert t["title"] in flat, t["title"]
    for tid in ("9a", "9b", "10", "11", "12", "A1", "A2"):
        assert f"Table {tid}" in text, tid
    assert "0.01<P<0.05, significant effect" in flat and "P<0.01, highly significant" in flat
    # eq. (5): ours in coded terms (intercept as stored) and the paper's beside it
    fit = campaign["results"]["box_behnken"]["fit"]
    assert f"θ = {fit['coefficients']['Intercept']:.4g}" in flat
    assert f"R² {fit['fit']['r2']:.4g} 0.9717" in flat  # Table 9a: ours beside the paper's
    assert "θ = 35.65 − 0.5775 A − 0.66 B + 0.22 C + 2.45 AB" in flat
    for n, words in enumerate(("Image processing of the heap photos", "Pareto chart",
                               "Steepest climb", "Response surfaces", "Validation"), 1):
        assert f"Fig. {n} - {words}" in flat, words
    images = sum(len(page.images) for page in reader.pages)
    assert images >= 5
    width, height = (float(v) for v in reader.pages[0].mediabox.upper_right)
    assert (round(width), round(height)) == (595, 842)  # A4 [pt]


#: The stages of the paper's procedure: name in the report, section of results.json.
STAGES = (("Plackett-Burman", "plackett_burman"), ("noise", "noise"), ("steepest climb", "steepest_climb"),
          ("Box-Behnken", "box_behnken"), ("validation", "validation"))


def _records(out: Path) -> dict:
    return {p.stem: json.loads(p.read_text()) for p in (out / "runs").glob("*.json")}


def _read_csv(path: Path) -> list[list[str]]:
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.reader(f))


def test_pdf_sums_the_runs_up_by_stage_in_at_most_15_pages(campaign):
    """Table A2 has one row per stage, recomputed here from the run records; no run key is
    printed in full (runs.csv lists them)."""
    from pypdf import PdfReader

    reader = PdfReader(str(campaign["pdf"]))
    assert len(reader.pages) <= 15
    text = "\n".join(page.extract_text() for page in reader.pages)
    squeezed = re.sub(r"\s+", "", text)
    a2 = campaign["tables"]["A2"]
    assert re.sub(r"\s+", "", f"Table A2{a2['title']}") in squeezed and "runs.csv" in a2["title"]
    assert re.sub(r"\s+", "", a2["notes"][0]) in squeezed and a2["notes"][0].startswith(
        "Every run is listed in runs.csv beside this report, one row each: its key")
    records = _records(campaign["out"])
    assert not [key for key in records if key in squeezed]
    assert _column(a2, "Stage") == [name for name, _ in STAGES] + ["all runs"]
    for name, part in STAGES:
        keys = list(dict.fromkeys(run["key"] for run in campaign["results"][part]["runs"]))
        wall = [records[k]["wall_s"] for k in keys]
        angles = [records[k]["result"]["observable"]["angle_deg"] for k in keys]
        row = _row(a2, name)
        assert (row["Runs"], row["Finished"], row["Failed"]) == (len(keys), len(keys), 0)
        assert row["Seeds"] == len({records[k]["inputs"]["seed"] for k in keys})
        assert row["Wall time, total"] == pytest.approx(sum(wall), rel=1e-12)
        assert row["Wall time, median"] == pytest.approx(np.median(wall), rel=1e-12)
        assert row["Observable"] == "angle_deg"
        assert row["Mean"] == pytest.approx(np.mean(angles), rel=1e-12)
        assert row["SD"] == pytest.approx(np.std(angles, ddof=1), rel=1e-9)
        assert f"{name} {len(keys)} {len(keys)} 0 " in text                  # the row as printed
    assert _row(a2, "all runs")["Runs"] == len(records)


def test_runs_csv_has_one_row_per_run_record(campaign):
    out = campaign["out"]
    rows = _read_csv(out / "runs.csv")
    header, rows = rows[0], [dict(zip(rows[0], r)) for r in rows[1:]]
    assert header[:8] == ["key", "stage", "rig", "seed", "status", "attempts", "wall_s", "error"]
    records = _records(out)
    assert sorted(r["key"] for r in rows) == sorted(records)
    for row in rows:
        rec = records[row["key"]]
        assert int(row["seed"]) == rec["inputs"]["seed"] and row["status"] == rec["status"] == "ok"
        assert float(row["wall_s"]) == rec["wall_s"] and int(row["attempts"]) == rec["attempts"]
        for name, value in rec["result"]["observable"].items():
            assert float(row[name]) == value
    # each run names every stage of results.json that used it
    stages = {row["key"]: row["stage"].split("; ") for row in rows}
    for name, part in STAGES:
        assert all(name in stages[run["key"]] for run in campaign["results"][part]["runs"]), name
    doc = json.loads((out / "tables.json").read_text())
    assert doc["artefacts"]["runs.csv"] == hashlib.sha256((out / "runs.csv").read_bytes()).hexdigest()


def test_runs_csv_keeps_a_run_on_one_row_and_no_cell_a_formula(campaign, tmp_path):
    """A failed run whose error holds line breaks and starts like a formula stays on its row,
    its error one line and quoted; Table A2 counts it as failed."""
    from dataclasses import replace

    from demcal.report.runs_csv import write_runs_csv
    from demcal.report.tables import load_campaign, table_runs

    c = load_campaign(campaign["out"])
    key = campaign["results"]["validation"]["runs"][0]["key"]
    failed = {**c.runs[key], "status": "failed", "error": "=cmd|' /C calc'!A0\nValueError: two\r\nlines"}
    c = replace(c, runs={**c.runs, key: failed})
    path = write_runs_csv(c, tmp_path / "runs.csv")
    rows = _read_csv(path)
    assert len(rows) == 1 + len(c.runs)
    assert path.read_bytes().count(b"\n") == len(rows)          # no line break inside a cell
    row = dict(zip(rows[0], next(r for r in rows if r[0] == key)))
    assert (row["status"], row["error"]) == ("failed", "'=cmd|' /C calc'!A0 ValueError: two lines")
    validation = _row(table_runs(c).to_dict(), "validation")
    assert (validation["Finished"], validation["Failed"]) == (validation["Runs"] - 1, 1)


def test_plausible_pdf_fits_in_15_pages_and_runs_csv_lists_its_runs(tmp_path):
    """The plausible workflow (noisy stand-in heap and twins) makes hundreds of runs: the PDF
    sums them up, each twin stage by its own observable; runs.csv lists every one."""
    from pypdf import PdfReader

    data = tmp_path / "data"
    shutil.copytree(EXAMPLE, data)
    out = tmp_path / "plausible"
    results = calibrate(data / "workbook.xlsx", out, CampaignConfig(workers=1, progress=False, seed=3),
                        runner=heap_standin_runner)
    _, pdf = build_report(out)
    assert len(PdfReader(str(pdf)).pages) <= 15
    records = _records(out)
    assert sorted(r[0] for r in _read_csv(out / "runs.csv")[1:]) == sorted(records)
    a2 = {t["id"]: t for t in json.loads((out / "tables.json").read_text())["tables"]}["A2"]
    for name, observable in (("e_pp", "apparent_restitution"), ("mu_s_pp", "static_friction_apparent"),
                             ("mu_r_pw", "rolling_friction_apparent")):
        twin = results.calibration.twins[name]
        values = [records[run["key"]]["result"]["observable"][observable] for run in twin["runs"]]
        row = _row(a2, f"{twin['rig']} twins, {name}")
        assert (row["Runs"], row["Observable"]) == (len(values), observable)
        assert row["Mean"] == pytest.approx(np.mean(values), rel=1e-12)
    assert _row(a2, "all runs")["Runs"] == len(records)


# ----------------------------------------------------------------------------------------------
# the tables against independent recomputations

def test_dimensions_and_mass_match_the_workbook(campaign):
    sheet = pd.read_excel(campaign["data"] / "workbook.xlsx", sheet_name="specimens")
    t1, t2 = campaign["tables"]["1"], campaign["tables"]["2"]
    for label, col in (("Length", "length_mm"), ("Diameter", "diameter_mm")):
        row = _row(t1, label)
        assert row["Mean"] == pytest.approx(sheet[col].mean(), rel=1e-12)
        assert row["SD"] == pytest.approx(sheet[col].std(ddof=1), rel=1e-12)
        assert (row["Min"], row["Max"]) == (sheet[col].min(), sheet[col].max())
    mass = _row(t2, "Mass of one segment")
    assert mass["Mean"] == pytest.approx(sheet["mass_g"].mean(), rel=1e-12)
    # the paper's printed means stand beside ours
    assert _row(t1, "Length")["Paper"] == 25.0
    assert _row(t2, "Restitution coefficient, segment-segment")["Paper"] == 0.3


def _soybean(measurement: dict) -> dict:
    """The example's measurement as a workbook of soybean seeds modelled as spheres would give
    it: callipers read the diameter only."""
    m = copy.deepcopy(measurement)
    m["material"] = "Soybean seeds"
    m["shape"] = {"shape": "sphere", "diameter_m": 0.0066}
    del m["quantities"]["length_mm"]
    return m


def test_tables_speak_of_the_workbooks_particle_and_show_the_paper_for_its_material_only(campaign):
    c = load_campaign(campaign["out"])
    soy = replace(c, measurement=_soybean(c.measurement))
    t = {tb.id: tb.to_dict() for tb in build_tables(soy)}
    t1, t2 = t["1"], t["2"]
    for tb in (t1, t2):
        words = [tb["title"], *tb["notes"], *(row[0] for row in tb["rows"])]
        assert not [w for w in words if "segment" in w.lower()], tb["id"]
    assert t1["title"] == "External dimensions of the particles"
    assert [(row[0], row[1]) for row in t1["rows"]] == [("Diameter", "D")]
    assert _column(t1, "Paper") == [None]
    assert "Restitution coefficient, particle-particle" in [row[0] for row in t2["rows"]]
    assert not {"Length", "Diameter"} & {row[0] for row in t2["rows"]}
    # the paper's figures of Astragalus stand beside no other material; its steel plate's do
    own = [r for r in t2["rows"] if "steel plate" not in r[0]]
    assert {r[t2["columns"].index("Paper")] for r in own} == {None}
    assert any("belong to its own material" in n for n in t1["notes"] + t2["notes"])
    assert set(_column(t["3"], "Paper mean")) == {None}
    assert set(_column(t["11"], "Paper calibrated")) | set(_column(t["11"], "Paper measured")) == {None}
    assert set(_column(t["12"], "Paper")) == {None}
    html = unescape(re.sub(r"<[^>]+>", " ", render_html(soy, list(t.values()), [])))
    assert "The particles were measured one by one: diameter with callipers" in html
    assert "paper's values beside ours" not in html
    assert "particles measured with callipers" in abstract(soy)["text"] and abstract(soy)["paper"] == ""
    # the example itself is the paper's material: its figures stand beside ours
    assert _column(campaign["tables"]["1"], "Paper") == [25.0, 11.0]
    assert campaign["tables"]["1"]["title"] == "External dimensions of the segments"


def test_tables_name_their_sources_with_file_hashes(campaign):
    wb = campaign["data"] / "workbook.xlsx"
    wb_hash = sha256_file(wb)
    runs_dir = campaign["out"] / "runs"
    for t in campaign["tables"].values():
        assert t["sources"], t["id"]
        for s in t["sources"]:
            if s["kind"] == "workbook":
                assert s["sha256"] == wb_hash and s["sheet"]
            if s["kind"] == "runs":
                assert all((runs_dir / f"{k}.json").exists() for k in s["keys"])
    t1_rows = [s for s in campaign["tables"]["1"]["sources"] if s["kind"] == "workbook"]
    assert t1_rows[0]["sheet"] == "specimens" and t1_rows[0]["rows"] == "1-30"
    inputs = json.loads((campaign["out"] / "tables.json").read_text())["inputs"]
    assert inputs[str(wb)] == wb_hash


def test_design_tables_match_the_run_records(campaign):
    out, tables = campaign["out"], campaign["tables"]

    def angle(key):
        return json.loads((out / "runs" / f"{key}.json").read_text())["result"]["observable"]["angle_deg"]

    # each design point's angle is the median of its replicate runs, stored point by point
    k = json.loads((out / "results.json").read_text())["config"]["replicates"]
    for table in ("4", "8"):
        keys = next(s for s in tables[table]["sources"] if s["kind"] == "runs")["keys"]
        runs = np.array([angle(key) for key in keys]).reshape(-1, k)
        assert _column(tables[table], "Angle of repose") == pytest.approx(np.median(runs, axis=1), abs=0)
        assert _column(tables[table], "Replicates") == [" / ".join(f"{a:.4g}" for a in row) for row in runs]
    # Plackett-Burman effects: mean(+1) - mean(-1) of Table 4's columns
    y = np.array(_column(tables["4"], "Angle of repose"))
    effects = dict(zip(_column(tables["5"], "Source"), _column(tables["5"], "Effect")))
    for f in "ABCDEFG":
        x = np.array(_column(tables["4"], f))
        assert effects[f] == pytest.approx(y[x > 0].mean() - y[x < 0].mean(), rel=1e-9)
    # validation: relative error of the mean of the validation points (medians of their runs)
    val = [run["key"] for run in campaign["results"]["validation"]["runs"]]
    mean = np.mean(np.median(np.array([angle(key) for key in val]).reshape(-1, k), axis=1))
    target = _row(tables["12"], "measured angle (target)")["Angle compared (angle_deg)"]
    err = _row(tables["12"], "relative error of the mean [%]")["Angle compared (angle_deg)"]
    assert err == pytest.approx(100 * abs(mean - target) / target, rel=1e-9)


def test_fit_statistics_match_an_independent_least_squares_fit(campaign):
    """R2 and adjusted R2 of Table 9a from numpy's least squares on Table 8."""
    t8 = campaign["tables"]["8"]
    x = np.array([[row[t8["columns"].index(c)] for c in "ABC"] for row in t8["rows"]], float)
    y = np.array(_column(t8, "Angle of repose"))
    a, b, c = x.T
    design = np.column_stack([np.ones_like(a), a, b, c, a * b, a * c, b * c, a * a, b * b, c * c])
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    ss_res = float(np.sum((y - design @ coef) ** 2))
    ss_tot = float(np.sum((y - y.mean()) ** 2))
    r2 = 1 - ss_res / ss_tot
    adj = 1 - (ss_res / (len(y) - 10)) / (ss_tot / (len(y) - 1))
    t9a = campaign["tables"]["9a"]
    assert _row(t9a, "R²")["Ours"] == pytest.approx(r2, rel=1e-9)
    assert _row(t9a, "Adjusted R²")["Ours"] == pytest.approx(adj, rel=1e-9)
    assert _row(t9a, "R²")["Paper"] == 0.9717
    coded = dict(zip(_column(campaign["tables"]["9b"], "Term (coded)"),
                     _column(campaign["tables"]["9b"], "Coefficient (coded)")))
    assert coded["Intercept"] == pytest.approx(coef[0], rel=1e-9)
    assert coded["AB"] == pytest.approx(coef[4], rel=1e-9)


# ----------------------------------------------------------------------------------------------
# audit

def test_audit_passes_on_a_fresh_report(campaign, capsys):
    code, out = _audit(capsys, campaign["out"])
    assert code == 0, out
    for tid in ("1", "2", "3", "4", "5", "6", "7", "8", "9", "A1", "A2"):
        assert re.search(rf"^Table {tid} \(.*\): OK$", out, re.M), tid
    for artefact in ("results.json", "runs.csv", "report.html", "report.pdf", "figures"):
        assert re.search(rf"^{re.escape(artefact)}: OK$", out, re.M), artefact
    assert "audit: OK" in out


def test_audit_names_a_changed_table_cell(campaign, capsys, tmp_path):
    out = tmp_path / "copy"
    shutil.copytree(campaign["out"], out)
    doc = json.loads((out / "tables.json").read_text())
    t9a = next(t for t in doc["tables"] if t["id"] == "9a")
    j = t9a["columns"].index("Ours")
    row = next(r for r in t9a["rows"] if r[0] == "R²")
    true_r2 = row[j]
    row[j] = true_r2 * 0.99
    (out / "tables.json").write_text(json.dumps(doc))
    code, text = _audit(capsys, out)
    assert code == 1
    line = next(ln for ln in text.splitlines() if ln.strip().startswith("Table 9a, row"))
    assert "(R²)" in line and "column 'Ours'" in line
    assert repr(true_r2 * 0.99) in line and repr(true_r2) in line
    assert re.search(r"^Table 9 \(.*\): OK$", text, re.M)  # the others still match
    assert "audit: FAILED" in text


def test_audit_finds_the_papers_numbers_on_any_install(campaign, capsys, tmp_path, monkeypatch):
    """The report names the paper's numbers by the package, not by this install's path, so a
    copy audits elsewhere; a changed copy of the file is named."""
    doc = json.loads((campaign["out"] / "tables.json").read_text())
    assert doc["inputs"][PAPER_NAME] == sha256_file(PAPER_FILE)
    assert str(PAPER_FILE) not in (campaign["out"] / "tables.json").read_text()
    moved = tmp_path / "elsewhere" / "paper_defaults.json"
    moved.parent.mkdir()
    moved.write_text(PAPER_FILE.read_text().replace("35.79", "35.80"))
    monkeypatch.setattr("demcal.report.tables.DATA_DIR", moved.parent)     # where the package's data are
    code, text = _audit(capsys, campaign["out"])
    assert code == 1
    assert f"CHANGED  {PAPER_NAME}: SHA-256 recorded {sha256_file(PAPER_FILE)}" in text


def _copy(campaign, tmp_path) -> Path:
    out = tmp_path / "copy"
    shutil.copytree(campaign["out"], out)
    return out


def test_audit_draws_the_figures_again_when_the_reports_are_gone(campaign, capsys, tmp_path):
    """The audit renders with the report's own PNGs; without them it draws them again, and the
    report still agrees with its sources."""
    out = _copy(campaign, tmp_path)
    shutil.rmtree(out / "figures")
    code, text = _audit(capsys, out)
    assert code == 0, text
    assert re.search(r"^report\.pdf: OK$", text, re.M) and not (out / "figures").exists()


def _embedded(html: str) -> list[tuple[str, str]]:
    """(base64 PNG, figure number) of each figure report.html embeds."""
    return re.findall(r'<img src="data:image/png;base64,([A-Za-z0-9+/=]*)" alt="Fig\. (\d+)">', html)


def test_audit_names_a_figure_swapped_in_report_html(campaign, capsys, tmp_path):
    """Two figures' images exchanged in the HTML: every number in the text still agrees, the
    figures do not."""
    out = _copy(campaign, tmp_path)
    html = (out / "report.html").read_text(encoding="utf-8")
    (a, _), (b, _) = _embedded(html)[:2]
    html = html.replace(a, "\0").replace(b, a).replace("\0", b)
    (out / "report.html").write_text(html, encoding="utf-8")
    record = json.loads((out / "tables.json").read_text())["artefacts"]["figures"]["sha256"]
    first = next(iter(record))
    code, text = _audit(capsys, out)
    assert code == 1
    assert (f"figures, report.html, Fig. 1, SHA-256 ({first}): reads "
            f"'{hashlib.sha256(base64.b64decode(b)).hexdigest()}', re-derived '{record[first]}'") in text
    assert re.search(r"^report\.html: OK$", text, re.M) and re.search(r"^report\.pdf: OK$", text, re.M)
    assert "audit: FAILED" in text and "differs: figures" in text


def test_audit_draws_each_figure_again_and_names_one_the_sources_do_not_give(campaign, capsys, tmp_path):
    """A figure replaced everywhere the report keeps it (its PNG, the HTML, the PDF and the
    SHA-256 in tables.json): drawn again from the results, it differs. Under another
    matplotlib the figures are not compared, and the audit says so and fails."""
    from demcal.report.figures import make_figures
    from demcal.report.render import write_pdf

    out = _copy(campaign, tmp_path)
    figures = make_figures(load_campaign(out), out / "figures", draw=False)
    true, other = figures[-1].path, figures[0].path
    drawn = sha256_file(true)
    shutil.copyfile(other, true)
    doc = json.loads((out / "tables.json").read_text())
    name = f"figures/{true.name}"
    doc["artefacts"]["figures"]["sha256"][name] = sha256_file(true)
    (out / "tables.json").write_text(json.dumps(doc))
    c = load_campaign(out)
    html = render_html(c, doc["tables"], figures)
    (out / "report.html").write_text(html, encoding="utf-8")
    write_pdf(html, out / "report.pdf", base_url=out)
    code, text = _audit(capsys, out)
    assert code == 1
    assert f"figures, {name}, SHA-256 (drawn again from the sources): reads '{sha256_file(true)}', re-derived '{drawn}'" in text
    assert f"figures, report.html, Fig. {len(figures)}, SHA-256 (drawn again from the sources)" in text
    assert re.search(r"^report\.html: OK$", text, re.M) and re.search(r"^report\.pdf: OK$", text, re.M)

    doc["artefacts"]["figures"]["matplotlib"] = "0.0"
    (out / "tables.json").write_text(json.dumps(doc))
    code, text = _audit(capsys, out)
    assert code == 1
    assert re.search(r"^figures: NOT COMPARED: drawn with matplotlib 0\.0, drawn again with ", text, re.M)


def test_audit_names_an_image_changed_in_report_pdf(campaign, capsys, tmp_path):
    from demcal.report.audit import pdf_images
    from demcal.report.render import write_pdf

    out = _copy(campaign, tmp_path)
    html = (out / "report.html").read_text(encoding="utf-8")
    (a, _), (b, _) = _embedded(html)[:2]
    write_pdf(html.replace(a, b), out / "report.pdf", base_url=out)
    code, text = _audit(capsys, out)
    assert code == 1
    page, image = pdf_images(campaign["pdf"])[0]
    assert re.search(rf"^  report\.pdf, page {page}, image 1, SHA-256: reads '[0-9a-f]{{64}}', re-derived '{image}'$",
                     text, re.M)
    assert re.search(r"^report\.html: OK$", text, re.M) and re.search(r"^figures: OK$", text, re.M)


def test_audit_names_a_changed_number_in_results_json(campaign, capsys, tmp_path):
    out = _copy(campaign, tmp_path)
    res = json.loads((out / "results.json").read_text())
    true = res["validation"]["mean_deg"]
    res["validation"]["mean_deg"] = true + 0.5
    (out / "results.json").write_text(json.dumps(res))
    code, text = _audit(capsys, out)
    assert code == 1
    assert f"results.json, validation.mean_deg: reads {true + 0.5!r}, re-derived {true!r}" in text
    # the report was built from the true value: it still agrees with the sources
    assert re.search(r"^report\.html: OK$", text, re.M) and re.search(r"^report\.pdf: OK$", text, re.M)
    assert "audit: FAILED" in text and "differs: results.json" in text


def test_audit_names_a_changed_cell_of_report_html(campaign, capsys, tmp_path):
    out = _copy(campaign, tmp_path)
    html = (out / "report.html").read_text(encoding="utf-8")
    label, cells = next((r[1][0], r[1]) for r in _html_rows(html, "2") if r[1][0].startswith("Mass"))
    j = next(j for j, c in enumerate(cells) if j > 0 and re.fullmatch(r"\d+\.\d+", c))
    start = html.index('id="table-2"')
    row_at = html.index(f">{label}</td>", start)
    cell_at = html.index(f">{cells[j]}</td>", row_at)
    changed = f"{float(cells[j]) + 1:.{len(cells[j].split('.')[1])}f}"
    html = html[:cell_at + 1] + changed + html[cell_at + 1 + len(cells[j]):]
    (out / "report.html").write_text(html, encoding="utf-8")
    code, text = _audit(capsys, out)
    assert code == 1
    column = campaign["tables"]["2"]["columns"][j]
    line = next(ln for ln in text.splitlines() if ln.strip().startswith("report.html, Table 2"))
    assert f"row 3 ({label})" in line or f"({label})" in line
    assert f"column '{column}" in line and repr(changed) in line and repr(cells[j]) in line
    assert re.search(r"^results\.json: OK$", text, re.M) and re.search(r"^report\.pdf: OK$", text, re.M)


def test_audit_names_a_changed_number_in_report_pdf(campaign, capsys, tmp_path):
    from demcal.report.render import write_pdf

    out = _copy(campaign, tmp_path)
    html = (out / "report.html").read_text(encoding="utf-8")
    m = re.search(r"The mean\s+over the photos, (\d+\.\d+)°", html)
    true = m.group(1)
    changed = f"{float(true) + 2:.{len(true.split('.')[1])}f}"
    write_pdf(html[:m.start(1)] + changed + html[m.end(1):], out / "report.pdf", base_url=out)
    code, text = _audit(capsys, out)
    assert code == 1
    line = next(ln for ln in text.splitlines() if ln.strip().startswith("report.pdf, page"))
    assert f"{changed}°" in line and f"{true}°" in line
    assert re.search(r"^report\.html: OK$", text, re.M) and re.search(r"^results\.json: OK$", text, re.M)


def test_audit_names_a_changed_number_in_runs_csv(campaign, capsys, tmp_path):
    out = _copy(campaign, tmp_path)
    rows = _read_csv(out / "runs.csv")
    j = rows[0].index("angle_deg")
    true = rows[3][j]
    rows[3][j] = repr(float(true) + 0.5)
    with open(out / "runs.csv", "w", newline="", encoding="utf-8") as f:
        csv.writer(f).writerows(rows)
    code, text = _audit(capsys, out)
    assert code == 1
    assert (f"runs.csv, row 3 (key {rows[3][0]}), column 'angle_deg': reads {rows[3][j]!r}, "
            f"re-derived {true!r}") in text
    assert re.search(r"^results\.json: OK$", text, re.M) and re.search(r"^report\.pdf: OK$", text, re.M)
    assert "audit: FAILED" in text and "differs: runs.csv" in text


def test_audit_finds_runs_csv_rewritten_with_the_same_cells(campaign, tmp_path):
    """Every cell the same, the bytes not: the SHA-256 recorded in tables.json tells."""
    from demcal.report.audit import compare_runs_csv
    from demcal.report.tables import load_campaign

    out = _copy(campaign, tmp_path)
    recorded = json.loads((out / "tables.json").read_text())["artefacts"]["runs.csv"]
    c = load_campaign(out)
    assert compare_runs_csv(out / "runs.csv", c, recorded) == []
    rows = _read_csv(out / "runs.csv")
    with open(out / "runs.csv", "w", newline="", encoding="utf-8") as f:
        csv.writer(f, quoting=csv.QUOTE_ALL).writerows(rows)
    diffs = compare_runs_csv(out / "runs.csv", c, recorded)
    assert [(d.stored, d.derived) for d in diffs] == [
        (hashlib.sha256((out / "runs.csv").read_bytes()).hexdigest(), recorded)]


def test_audit_names_a_missing_run_record(campaign, capsys, tmp_path):
    out = tmp_path / "copy"
    shutil.copytree(campaign["out"], out)
    key = campaign["results"]["box_behnken"]["runs"][0]["key"]
    (out / "runs" / f"{key}.json").unlink()
    code, text = _audit(capsys, out)
    assert code == 1
    assert f"MISSING  runs/{key}.json" in text
    assert re.search(r"^Table 8 \(.*\): NOT RE-DERIVED: .*" + key, text, re.M)
    assert re.search(r"^Table 1 \(.*\): OK$", text, re.M)


def test_audit_names_a_changed_workbook_and_the_cell(tmp_path, capsys):
    import openpyxl

    data, out = _campaign(tmp_path, "edited")
    write_tables(out)
    book = data / "workbook.xlsx"
    stored_hash = sha256_file(book)
    wb = openpyxl.load_workbook(book)
    ws = wb["specimens"]
    col = [c.value for c in ws[1]].index("mass_g") + 1
    ws.cell(row=4, column=col).value = ws.cell(row=4, column=col).value + 0.5  # data row 3
    wb.save(book)
    code, text = _audit(capsys, out)
    assert code == 1
    assert f"CHANGED  {book}: SHA-256 recorded {stored_hash}, now {sha256_file(book)}" in text
    mass = [ln for ln in text.splitlines() if "Table 2, row" in ln and "(Mass of one segment)" in ln]
    assert any("column 'Mean'" in ln for ln in mass)
    assert any(ln.strip().startswith("Table A1, row") and "workbook.xlsx" in ln and "SHA-256" in ln
               for ln in text.splitlines())
    # the mass feeds no DEM run: the analysis replays and its tables still match
    assert re.search(r"^Table 9 \(.*\): OK$", text, re.M)


# ----------------------------------------------------------------------------------------------
# offline HTML, critique section

class _Links(HTMLParser):
    def __init__(self):
        super().__init__()
        self.urls = []

    def handle_starttag(self, tag, attrs):
        self.urls += [(tag, k, v or "") for k, v in attrs if k in ("src", "href")]


def test_html_works_offline(campaign):
    text = campaign["html"].read_text(encoding="utf-8")
    parser = _Links()
    parser.feed(text)
    assert not [u for u in parser.urls if re.match(r"\s*(https?:)?//", u[2])]
    imgs = [u[2] for u in parser.urls if u[0] == "img"]
    assert len(imgs) >= 5
    for src in imgs:
        assert src.startswith("data:image/png;base64,") or (campaign["out"] / src).exists()
    assert "@import" not in text and "@font-face" not in text
    assert not re.search(r"url\(\s*['\"]?(https?:)?//", text)


def test_report_command_renders_critique_json(campaign, tmp_path, capsys):
    out = tmp_path / "copy"
    shutil.copytree(campaign["out"], out)
    critique = {"discrepancies": [{"observable": "restitution.particle-steel", "sheet": "drop", "measured": 0.35,
                                   "measured_ci95": [0.33, 0.37], "simulated": 0.41, "simulated_ci95": None,
                                   "difference": 0.06, "combined_u95": 0.02, "exceeds": True,
                                   "n_measured": 10, "n_simulated": 1}],
                "findings": [{"mechanism": "velocity_dependent_restitution", "verdict": "found",
                              "sheet": "drop", "covariate": "drop_height_mm", "effect": -0.12,
                              "ci95": [-0.2, -0.04], "p_adjusted": 0.003}]}
    (out / "critique.json").write_text(json.dumps(critique))
    assert main(["report", str(out), "--no-pdf"]) == 0
    assert f"report: {out / 'report.html'}" in capsys.readouterr().out
    tables = {t["id"]: t for t in json.loads((out / "tables.json").read_text())["tables"]}
    assert tables["C2"]["columns"][:7] == ["mechanism", "verdict", "sheet", "covariate", "effect", "ci95",
                                           "p_adjusted"]
    assert tables["C2"]["rows"][0][:7] == ["velocity_dependent_restitution", "found", "drop",
                                           "drop_height_mm", -0.12, [-0.2, -0.04], 0.003]
    assert tables["C1"]["rows"][0][0] == "restitution.particle-steel" and tables["C3"]["rows"] == []
    html = (out / "report.html").read_text(encoding="utf-8")
    assert "Critique of the calibrated model" in html and "velocity_dependent_restitution" in html
    assert "Table C3" in html and "Table C5" in html and "Table C6" in html
    # no drop twin: the report says the question of sqrt(h2/h1) was not assessed
    assert "Not assessed: this critique ran no drop twin" in html
    assert tables["C4"]["rows"] == [] and "None: critique.json holds no covariate tests." in tables["C4"]["notes"]
    assert tables["C5"]["rows"] == [] and tables["C6"]["rows"] == [] and tables["C7"]["rows"] == []
    # a critique.json missing a documented key is refused by name, not half-rendered
    del critique["discrepancies"][0]["measured_ci95"]
    (out / "critique.json").write_text(json.dumps(critique))
    assert main(["report", str(out), "--no-pdf"]) == 2
    assert "critique.json: not a critique of this layout" in capsys.readouterr().err
    (out / "critique.json").write_text(json.dumps({**critique, "discrepancies": []}))
    assert main(["report", str(out), "--no-pdf"]) == 0
    assert (out / "tables.json").read_text().count("critique.json") >= 3  # hashed and named as source


def test_tables_render_when_lenth_has_no_pse(campaign, tmp_path):
    """Lenth's PSE is stored as null when most contrasts are exactly zero; Table 5 says n/a."""
    import json
    import shutil

    from demcal.report.tables import build_tables, load_campaign

    out = tmp_path / "campaign"
    shutil.copytree(campaign["out"], out)
    results = json.loads((out / "results.json").read_text())
    results["plackett_burman"]["screening"]["lenth"] = {"pse": None, "me": None, "active": None}
    (out / "results.json").write_text(json.dumps(results))
    table5 = next(t for t in build_tables(load_campaign(out)) if t.id == "5")
    assert any("PSE n/a deg" in note for note in table5.notes)


# ----------------------------------------------------------------------------------------------
# critique section: summary, whether sqrt(h2/h1) may feed the DEM, every covariate test (C4)

def _test(i, series, covariate, method, effect, ci, unit, practical, threshold, p, p_adj, *, source="measured",
          sheet="drop", significant=False, relevant=False, ci_selected=None, explained_by=None, levels=None):
    """One entry of critique.json's tests, with every field of diagnosis.CovariateTest."""
    return {"series": series, "sheet": sheet, "source": source, "covariate": covariate, "method": method,
            "n": 20 + i, "effect": effect, "ci95": ci, "effect_unit": unit,
            "span": None if method in ("anova", "mean") else 300.0, "practical": practical,
            "threshold": threshold, "p_value": p, "se": 0.01 * (i + 1), "dof": 18 + i,
            "p_curvature": 0.5 if method == "trend" else None, "p_adjusted": p_adj,
            "significant": significant, "relevant": relevant, "ci_selected": ci_selected,
            "explained_by": explained_by, "levels": levels or {}}


#: A small critique.json in the layout analyse.critique.loop writes (sentences in its words).
CRITIQUE = {
    "discrepancies": [
        {"observable": "restitution.particle-steel (drop twin, apparent sqrt(h2/h1))", "sheet": "drop",
         "measured": 0.352, "measured_ci95": [0.339, 0.365], "simulated": 0.281,
         "simulated_ci95": [0.268, 0.294], "difference": 0.0712, "combined_u95": 0.0121, "exceeds": True,
         "n_measured": 20, "n_simulated": 20,
         "note": "contact e_pw = 0.352; each drop at its height and logged orientation; twin apparent / "
                 "contact = 0.798: sqrt(h2/h1) may not feed the DEM directly"},
        {"observable": "restitution.particle-wood (drop twin, apparent)", "sheet": "drop", "measured": 0.41,
         "measured_ci95": [0.38, 0.44], "simulated": None, "simulated_ci95": None, "difference": None,
         "combined_u95": None, "exceeds": None, "n_measured": 6, "n_simulated": 0,
         "note": "not simulated: no DEM contact parameters for particle-wood (the DEM knows "
                 "particle-particle and particle-steel)"},
        {"observable": "repose_angle_deg (photo method)", "sheet": "repose", "measured": 35.64,
         "measured_ci95": [31.45, 39.82], "simulated": 35.64, "simulated_ci95": [34.91, 36.38],
         "difference": -0.0092, "combined_u95": 4.02, "exceeds": False, "n_measured": 3, "n_simulated": 3,
         "note": "3 validation runs of the campaign (DIR/runs)"}],
    "findings": [{"mechanism": "orientation_rotation", "verdict": "found", "sheet": "drop",
                  "covariate": "orientation_deg", "effect": 0.00052, "ci95": [0.00031, 0.00073],
                  "p_adjusted": 0.00042, "quantity": "residual:restitution.particle-steel",
                  "source": "twin residual", "effect_unit": "1/deg", "evidence": "see Table C4, test 3"}],
    "extensions": [{"name": "inverted_restitution", "mechanism": "orientation_rotation", "before": 0.0712,
                    "after": 0.00814, "gain": 0.0631, "ci95": [0.0512, 0.0748],
                    "measure": "abs_mean_residual of restitution.particle-steel",
                    "held_out": "20 drops, each judged by the inversion of the other half (two-fold cross-fit)",
                    "before_ci95": [0.06, 0.082], "after_ci95": [0.002, 0.019], "n_held_out": 20,
                    "fitted": "half 1: e_pw = 0.441 [0.425, 0.458] from 10 drops; half 2: e_pw = 0.452 "
                              "[0.436, 0.469] from 10 drops (calibrated 0.352)", "note": ""}],
    "extension_records": [
        {"name": "inverted_restitution", "mechanism": "orientation_rotation", "measure": "abs_mean_residual",
         "quantity": "restitution.particle-steel",
         "held_out": "20 drops, each judged by the inversion of the other half (two-fold cross-fit)",
         "before": 0.0712, "before_ci95": [0.06, 0.082], "after": 0.00814, "after_ci95": [0.002, 0.019],
         "gain": 0.0631, "ci95": [0.0512, 0.0748], "n_held_out": 20,
         "fitted": "half 1: e_pw = 0.441 [0.425, 0.458] from 10 drops; half 2: e_pw = 0.452 "
                   "[0.436, 0.469] from 10 drops (calibrated 0.352)", "note": "",
         "extension": {"extension": "inverted_restitution", "pair": "particle-steel"}, "heap_settings": {}}],
    "heap_gains": [
        {"extension": "contact_effective_mass", "mechanism": "contact_effective_mass",
         "settings": {"contact_effective_mass": True}, "campaign": "heap_gain/contact_effective_mass",
         "verdict_before": "equivalent", "verdict_after": "equivalent",
         "parameters": [{"name": "e_pw", "before": 0.71, "after": 0.36, "before_ci95": [0.62, 0.8],
                         "after_ci95": [0.3, 0.42], "shift": -0.35, "within_uncertainty": False},
                        {"name": "mu_s_pw", "before": 0.18, "after": 0.19, "before_ci95": [0.09, 0.39],
                         "after_ci95": [0.1, 0.38], "shift": 0.01, "within_uncertainty": True}],
         "observables": [{"name": "outflow fraction", "unit": "-", "fitted": False, "before": 0.094,
                          "before_sd": 0.02, "n_before": 20, "after": 0.121, "after_sd": 0.025, "n_after": 20,
                          "difference": 0.027, "ci95": [0.0125, 0.0415], "beyond_noise": True}],
         "conclusion": "Recalibrated with contact_effective_mass: e_pw moved beyond its uncertainty."}],
    "summary": [
        "restitution.particle-steel: the lab's sqrt(h2/h1) is 0.352; the drop twin with contact e_pw = 0.352, "
        "at the lab's 20 drop heights and orientations, rebounds with an apparent 0.281 [0.268, 0.294] "
        "(ratio 0.798). sqrt(h2/h1) may not feed the DEM directly: the twin's apparent restitution differs "
        "from its contact restitution by -0.0711 (part of the energy goes into rotation). The contact "
        "restitution that reproduces the drops is e_pw = 0.447 (halves 0.441, 0.452; interval [0.43, 0.465]).",
        "Extension inverted_restitution (restitution.particle-steel): abs_mean_residual on 20 drops, each "
        "judged by the inversion of the other half (two-fold cross-fit) 0.0712 before, 0.00814 after, gain "
        "0.0631 [0.0512, 0.0748]: it helps. Fitted: half 1: e_pw = 0.441 [0.425, 0.458] from 10 drops; "
        "half 2: e_pw = 0.452 [0.436, 0.469] from 10 drops (calibrated 0.352).",
        "Found: orientation_rotation. orientation_rotation: residual:restitution.particle-steel (twin "
        "residual, sheet drop) vs orientation_deg: trend effect 0.00052 1/deg [0.00031, 0.00073] "
        "(marginal 95 %), 0.0468 over the observed range of orientation_deg; p 1.2e-05, adjusted 0.00042; "
        "practical threshold 0.03."],
    "tests": [
        _test(0, "length_mm", "moisture_pct", "trend", -0.205, [-0.395, -0.0146], "mm/%", 2.29, 0.5, 0.1045,
              0.9345, sheet="specimens"),
        _test(1, "length_mm", "batch", "anova", 0.885, [-0.379, 2.15], "mm", 0.885, 0.5, 0.368, 0.9345,
              sheet="specimens", levels={"B1": [25.06, 11], "B2": [24.7, 9]}),
        _test(2, "residual:restitution.particle-steel", "orientation_deg", "trend", 0.00052,
              [0.00031, 0.00073], "1/deg", 0.0468, 0.03, 1.2e-05, 0.00042, source="twin residual",
              significant=True, relevant=True, ci_selected=[0.00025, 0.00079]),
        _test(3, "residual:restitution.particle-steel", "drop_height_mm", "trend", 0.00011, [4e-05, 0.00018],
              "1/mm", 0.033, 0.03, 0.0003, 0.0042, source="twin residual", significant=True, relevant=True,
              explained_by="orientation_deg"),
        _test(4, "restitution.particle-steel", "drop_height_mm", "line", 2.1e-05, [8e-06, 3.4e-05], "1/mm",
              0.0063, 0.03, 0.0009, 0.0084, significant=True),
        _test(5, "twin_minus_contact:restitution.particle-steel", "orientation_deg", "mean", -0.0711,
              [-0.084, -0.058], "1", 0.0711, 0.03, 0.047, 0.094, source="twin", relevant=True),
        _test(6, "restitution.particle-steel", "specimen_mass_g", "trend", 0.0031, [-0.01, 0.016], "1/g",
              0.0012, 0.03, None, None),
        _test(7, "static_friction.steel", "operator", "anova", 0.021, [-0.006, 0.048], "1", 0.021, 0.03, 0.21,
              0.52, sheet="incline", levels={"A": [0.6, 5], "B": [0.62, 5]})],
    "untestable": [], "catalogue": [], "parameters": {}, "twin_runs": [],
    "provenance": {"options": {"alpha": 0.01, "correction": "bh"}},
}


@pytest.fixture(scope="module")
def critique_report(campaign, tmp_path_factory):
    """The example campaign with the critique.json above, its report built (HTML and PDF)."""
    out = tmp_path_factory.mktemp("critique") / "campaign"
    shutil.copytree(campaign["out"], out)
    (out / "critique.json").write_text(json.dumps(CRITIQUE))
    html_path, pdf_path = build_report(out)
    return {"out": out, "html": html_path.read_text(encoding="utf-8"), "pdf": pdf_path,
            "tables": {t["id"]: t for t in json.loads((out / "tables.json").read_text())["tables"]}}


def _html_rows(text: str, table_id: str) -> list[tuple[str, list[str]]]:
    """(tr attributes, cell HTML) of every body row of one table of the report."""
    block = text[text.index(f'id="table-{table_id}"'):]
    body = block[block.index("<tbody>"):block.index("</tbody>")]
    return [(attrs, [c.strip() for c in re.findall(r"<td[^>]*>(.*?)</td>", row, re.S)])
            for attrs, row in re.findall(r"<tr([^>]*)>(.*?)</tr>", body, re.S)]


def test_critique_summary_opens_the_critique_section(critique_report):
    import markupsafe  # the escaping of the report's template (jinja2 autoescape)

    text = critique_report["html"]
    start, c1 = text.index("Critique of the calibrated model"), text.index('id="table-C1"')
    for sentence in CRITIQUE["summary"]:
        para = f"<p>{markupsafe.escape(sentence)}</p>"
        assert text.count(para) == 1, sentence[:40]                  # each sentence once, as a paragraph
        assert start < text.index(para) < c1                         # before the tables
    # the answer on sqrt(h2/h1) leads, with the twin's apparent restitution against the measured one
    box = text[text.index('<div class="direct-use">'):]
    box = box[:box.index("</div>")]
    assert ("<b>restitution.particle-steel: sqrt(h2/h1) may not feed the DEM directly. The lab&#39;s drops "
            "give sqrt(h2/h1) = 0.352 [0.339, 0.365] (n 20); the drop twin rebounds with an apparent 0.281 "
            "[0.268, 0.294] (n 20): measured minus twin 0.0712, beyond its 95 % uncertainty ±0.0121 "
            "(Table C1).</b>") in box
    # ... and the gain of the extension that fixes it, from the summary
    assert "gain 0.0631 [0.0512, 0.0748]: it helps" in box and "0.0712 before, 0.00814 after" in box
    assert "restitution.particle-wood: not assessed; the lab&#39;s sqrt(h2/h1) is 0.41 [0.38, 0.44]" in box
    assert str(markupsafe.escape(CRITIQUE["summary"][2])) not in box         # the finding follows the box
    assert box.index("restitution.particle-steel: sqrt") < box.index("restitution.particle-wood")


def test_table_c4_lists_every_covariate_test_sorted_and_marked(critique_report):
    from demcal.report.render import format_cell

    c4 = critique_report["tables"]["C4"]
    tests = CRITIQUE["tests"]
    assert len(c4["rows"]) == len(tests)
    # sorted by adjusted p (ties by p, then list order), the untested one (p None) last
    assert _column(c4, "Test") == [3, 4, 5, 6, 8, 1, 2, 7]
    for row in c4["rows"]:
        r, t = dict(zip(c4["columns"], row)), tests[row[0] - 1]
        assert (r["Series"], r["Covariate"], r["Method"], r["n"], r["Effect"], r["95 % CI"], r["p"],
                r["Adjusted p"]) == (t["series"], t["covariate"], f"{t['method']} ({t.get('tier', 'primary')})",
                                     t["n"], t["effect"], t["ci95"],
                                     t["p_value"], t["p_adjusted"])
    verdicts = dict(zip(_column(c4, "Test"), _column(c4, "Verdict")))
    assert verdicts == {3: "significant: cause", 4: "significant, explained by orientation_deg",
                        5: "significant, below threshold", 6: "not significant", 8: "not significant",
                        1: "not significant", 2: "not significant", 7: "not significant"}
    assert "Test 3: interval after selection (false-coverage rate, Benjamini & Yekutieli 2005) " \
           "[0.00025, 0.00079] 1/deg." in c4["notes"]
    assert c4["notes"][0].startswith("Sorted by adjusted p-value (Benjamini-Hochberg within each tier; share of "
                                     "the level: primary 0.8, follow-up 0.2); significant rows in bold "
                                     "(adjusted p < 0.01).")
    # every row in the HTML, cell by cell as stored, the significant ones in bold
    rows = _html_rows(critique_report["html"], "C4")
    assert [cells for _, cells in rows] == [[format_cell(v, f) for v, f in zip(row, c4["formats"])]
                                            for row in c4["rows"]]
    assert [int(cells[0]) for attrs, cells in rows if 'class="marked"' in attrs] == [3, 4, 5]
    cause = next(cells for _, cells in rows if cells[0] == "3")
    assert cause[1:7] == ["residual:restitution.particle-steel", "drop", "twin residual", "orientation_deg",
                          "trend (primary)", "trial"]         # files without a level or tier: primary, independent trials
    assert cause[8:] == ["0.00052", "[0.00031, 0.00073]", "1/deg", "0.0468", "0.03", "&lt; 0.0001", "0.0004",
                         "significant: cause"]


def test_pdf_shows_the_critique_summary_and_table_c4(critique_report):
    from pypdf import PdfReader

    reader = PdfReader(str(critique_report["pdf"]))
    # compared without whitespace: the PDF breaks lines at spaces and after hyphens
    flat = re.sub(r"\s+", "", "".join(page.extract_text() for page in reader.pages))

    def squeeze(s):
        return re.sub(r"\s+", "", s)

    assert squeeze("Table C4" + critique_report["tables"]["C4"]["title"]) in flat
    assert squeeze(CRITIQUE["summary"][0]) in flat
    assert squeeze("restitution.particle-steel: sqrt(h2/h1) may not feed the DEM directly.") in flat
    assert squeeze("residual:restitution.particle-steel") in flat and squeeze("significant: cause") in flat


def test_table_c7_says_which_target_codes_can_run_each_accepted_extension(critique_report):
    from demcal.simulate.export import TARGET_HOOKS

    c7 = critique_report["tables"]["C7"]
    # contact_effective_mass is a demcal engine hook none of the three codes has
    assert "contact_effective_mass" not in TARGET_HOOKS["liggghts"] | TARGET_HOOKS["yade"] | TARGET_HOOKS["edem"]
    assert [(r[0], r[2], r[3]) for r in c7["rows"]] == [("contact_effective_mass", t, "no")
                                                        for t in ("LIGGGHTS", "Yade", "EDEM")]
    assert all(r[4].startswith("calibrated without it (Table C5, Before): it compensates") for r in c7["rows"])
    assert c7["notes"] == ["LIGGGHTS, Yade, EDEM cannot express contact_effective_mass: the export gives them the "
                           "parameters calibrated without it, and the set calibrated with it (Table C5, After; "
                           "heap_gain/contact_effective_mass) beside them, for demcal."]
    assert 'id="table-C7"' in critique_report["html"]


def test_audit_rederives_the_critique_tables(critique_report, capsys, tmp_path):
    code, text = _audit(capsys, critique_report["out"])
    assert code == 0, text
    for tid in ("C1", "C2", "C3", "C4", "C7", "C8"):
        assert re.search(rf"^Table {tid} \(.*\): OK$", text, re.M), tid
    # a changed C4 cell is named
    out = tmp_path / "copy"
    shutil.copytree(critique_report["out"], out)
    doc = json.loads((out / "tables.json").read_text())
    c4 = next(t for t in doc["tables"] if t["id"] == "C4")
    c4["rows"][0][c4["columns"].index("Adjusted p")] = 0.5
    (out / "tables.json").write_text(json.dumps(doc))
    code, text = _audit(capsys, out)
    assert code == 1
    assert "Table C4, row 1 (3), column 'Adjusted p': stored 0.5, re-derived 0.00042" in text


# ----------------------------------------------------------------------------------------------
# workbook text: printed as typed, and checked before the campaign

#: Workbook text a report could trip over: mathtext, markup, template syntax, quotes, a
#: backslash, Unicode (no control character: the workbook reader refuses those).
MATERIAL = "Astragalus $\\frac$ $$ <script>alert(1)</script> {{ x }} {% raw %} \"q\" 'q' 100% \\ ü–µ"
PHOTO_IDS = ("heap $\\frac$ 1", "a$b$c$", "$$ <b>{{ x }}</b> {% raw %}")
PHOTO_FILE = "heap <i>{{ x }} $$ {% raw %} 'q' ü.jpg"
COVARIATE = "note $\\frac$ {{ x }} <b>"
SHEET = "{{ x }} $$ <b> %"


def _hostile_workbook(folder: Path) -> Path:
    """A copy of the example with that text as its material, three photo ids, a photo's file
    name, a covariate's name and values, and an unknown sheet's name."""
    from demcal.measure.workbook import read_workbook, write_workbook

    shutil.copytree(EXAMPLE, folder)
    book = folder / "workbook.xlsx"
    sheets = {name: sheet.frame.reset_index(drop=True) for name, sheet in read_workbook(book).sheets.items()}
    meta = sheets["meta"]
    meta.loc[meta["key"] == "material", "value"] = MATERIAL
    repose = sheets["repose"]
    repose["photo_id"] = list(PHOTO_IDS) + list(repose["photo_id"][len(PHOTO_IDS):])
    photo = folder / repose.at[0, "file"]
    photo.rename(photo.with_name(PHOTO_FILE))
    repose.at[0, "file"] = f"{Path(repose.at[0, 'file']).parent}/{PHOTO_FILE}"
    sheets["specimens"][COVARIATE] = [f"{{% raw %}} $$ <{i}>" for i in range(len(sheets["specimens"]))]
    sheets[SHEET] = pd.DataFrame({"note": ["{{ x }}", "$\\frac$"]})
    write_workbook(sheets, book)
    return book


class _Text(HTMLParser):
    """The text of an HTML document as a reader reads it (character references resolved), and
    its title."""

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.parts, self.title, self._in_title = [], "", False

    def handle_starttag(self, tag, attrs):
        self._in_title = tag == "title"

    def handle_endtag(self, tag):
        self._in_title = False

    def handle_data(self, data):
        self.parts.append(data)
        if self._in_title:
            self.title += data

    @property
    def text(self) -> str:
        return " ".join(" ".join(self.parts).split())


@pytest.fixture(scope="module")
def hostile(tmp_path_factory):
    """That workbook through ``demcal calibrate`` (stand-in DEM), then ``demcal report`` with a
    critique that names the covariate."""
    root = tmp_path_factory.mktemp("hostile")
    book = _hostile_workbook(root / "data")
    out = root / "campaign"
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr("demcal.analyse.campaign.campaign_runner", standin_runner)
        calibrated = main(["calibrate", str(book), "--out", str(out), "--workflow", "design-expert",
                           "--workers", "1"])
    critique = json.loads(json.dumps(CRITIQUE))
    critique["tests"][7]["covariate"] = COVARIATE
    (out / "critique.json").write_text(json.dumps(critique))
    reported = main(["report", str(out)])
    return {"book": book, "out": out, "codes": (calibrated, reported),
            "html": (out / "report.html").read_text(encoding="utf-8")}


def test_workbook_text_is_printed_as_typed(hostile):
    from pypdf import PdfReader

    assert hostile["codes"] == (0, 0)
    html = hostile["html"]
    parsed = _Text()
    parsed.feed(html)
    assert parsed.title == f"Calibration of DEM parameters of {MATERIAL}"
    assert f"Calibration of discrete element simulation parameters of {MATERIAL}" in parsed.text
    assert f"photos/{PHOTO_FILE}" in parsed.text                     # Table A1
    assert [unescape(cell) for _, cells in _html_rows(html, "C4") for cell in cells].count(COVARIATE) == 1
    # none of it became markup or was run as a template
    for raw in ("<script>", "<b>{{ x }}</b>", "<i>{{ x }}", "<b> %"):
        assert raw not in html
    assert parsed.text.count("{{ x }}") >= 3 and "{% raw %}" in parsed.text
    pdf = PdfReader(str(hostile["out"] / "report.pdf"))
    flat = re.sub(r"\s+", "", "".join(page.extract_text() for page in pdf.pages))
    assert re.sub(r"\s+", "", MATERIAL) in flat and re.sub(r"\s+", "", COVARIATE) in flat


def test_calibrate_refuses_text_the_report_cannot_render_before_any_run(hostile, tmp_path, monkeypatch,
                                                                          capsys):
    """Were photo ids drawn as mathtext, "heap $\\frac$ 1" could not be drawn: calibrate says so on
    one line and exits 2 before its first DEM run."""
    monkeypatch.setattr("demcal.report.figures.PLAIN_TEXT", {})
    ran = []
    monkeypatch.setattr("demcal.analyse.campaign.campaign_runner", ran.append)
    out = tmp_path / "refused"
    capsys.readouterr()
    code = main(["calibrate", str(hostile["book"]), "--out", str(out), "--workflow", "design-expert",
                 "--workers", "1"])
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith(f"demcal calibrate: error: the report cannot be rendered from the workbook "
                          f"{hostile['book']}: ValueError: ") and err.count("\n") == 1
    assert "\\frac" in err
    assert ran == [] and not (out / "runs").exists() and not (out / "results.json").exists()


def test_the_report_states_the_time_step_and_the_runs_it_divided(campaign):
    """By hand: the paper's step 7.43678e-5 s against T_R = pi 0.0055 sqrt(912 / 1e7) /
    (0.1631 x 0.25 + 0.8766) = 1.7987e-4 s of the example's 5.5 mm spheres (the measured
    diameter, density and Poisson's ratio move it in the fourth digit). The step f T_R is divided below the
    restitution whose tangential damping ratio z has sqrt(1 + z^2) - z = f, inverted in closed
    form: z = (1 - f^2) / (2 f), |beta| = z / sqrt(3.5 x 5/6), ln e = -pi |beta| / sqrt(1 -
    beta^2) (``simulate.timestep``). A run recorded at half the step is counted."""
    from demcal.report.render import time_step_text

    c = load_campaign(campaign["out"])
    base = c.results.base_parameters
    radius = base["shape"]["diameter_m"] / 2     # the measured mean diameter, 10.999 mm
    t_r = math.pi * radius * math.sqrt(base["particle_density_kg_m3"] / 1e7) / (
        0.1631 * base["poisson_ratio"] + 0.8766)
    text = time_step_text(c)
    assert text.startswith(f"The time step is 7.437e-05 s, {7.43678e-5 / t_r:.3f} of the Rayleigh time "
                           f"({t_r:.4g} s) of the smallest sphere (5.5 mm radius)")
    assert "as the workbook states (meta time_step_s)" in text
    bulk = [k for k, rec in c.runs.items() if rec["inputs"].get("rig") != "drop"]
    f = 7.43678e-5 / t_r
    beta = (1 - f * f) / (2 * f) / math.sqrt(3.5 * 5 / 6)
    e_safe = math.exp(-math.pi * beta / math.sqrt(1 - beta * beta))
    assert 0.1 < e_safe < 0.105
    assert f"below {e_safe:.3g} damps too hard" in text and f"0 of the {len(bulk)} runs" in text
    runs = copy.deepcopy(c.runs)
    runs[bulk[0]]["result"]["meta"] = {"dt": 7.43678e-5 / 2}      # as a heap rig records it
    assert f"1 of the {len(bulk)} runs" in time_step_text(replace(c, runs=runs))
    runs[bulk[1]]["result"]["dt"] = 7.43678e-5 / 3                 # as the incline twin does
    assert f"2 of the {len(bulk)} runs" in time_step_text(replace(c, runs=runs))
    assert text in unescape(campaign["html"].read_text())


def test_line_breaks_in_workbook_text_leave_the_report_one_line(campaign):
    """The workbook reader refuses control characters; the report does not rely on it: a material
    and photo ids with line breaks render, the title on one line."""
    from dataclasses import replace

    from demcal.measure.pipeline import Measurement
    from demcal.report.render import preflight, render_html
    from demcal.report.tables import load_campaign

    c = load_campaign(campaign["out"])
    measurement = json.loads(json.dumps(c.measurement))
    measurement["material"] = "Astragalus\nmembranaceus\u2028<b>\r\n{{ x }}"
    for rec, name in zip(measurement["per_row"]["repose_angle_deg"], ("P\n1", "$\\frac$\r\n2", "\t$$")):
        rec["id"] = name
    preflight(Measurement.from_dict(measurement), campaign["out"])
    parsed = _Text()
    parsed.feed(render_html(replace(c, measurement=measurement), list(campaign["tables"].values()), []))
    assert parsed.title == "Calibration of DEM parameters of Astragalus membranaceus <b> {{ x }}"


def test_table_c8_states_the_benchmarked_power_and_false_alarms_with_their_bounds(critique_report):
    """Table C8's counts are those of benchmarks/critique_power.md, and its Clopper-Pearson bounds,
    computed from the counts, round to the bounds printed there."""
    root = Path(__file__).resolve().parents[2]
    printed = {}
    for line in (root / "benchmarks/critique_power.md").read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) in (4, 6) and cells[1].isdigit():
            printed[cells[0]] = (int(cells[1]), int(cells[2]), float(cells[3]))
    c8 = critique_report["tables"]["C8"]
    rows = {r[0]: r for r in c8["rows"]}
    assert set(rows) == set(printed)
    for name, (n, k, bound) in printed.items():
        r = rows[name]
        assert (r[2], r[3]) == (n, k)
        assert round(r[4] if r[1] == "planted" else r[5], 3) == pytest.approx(bound, abs=1e-3), name
    assert all(r[4] >= 0.8 for r in c8["rows"] if r[1] == "planted")
    assert all(r[5] <= 0.05 for r in c8["rows"] if r[1] == "clean")
    assert c8["sources"][0]["file"] == "demcal:data/critique_power.json"
