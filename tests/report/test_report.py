"""The report of the example campaign (analytic stand-in rig): the PDF holds the paper's tables,
equation and figures; the tables agree with independent recomputations from the workbook and
the run records; ``demcal audit`` passes on a fresh report and names the table and cell, or
the file, that was changed; the HTML needs no network."""

import json
import re
import shutil
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analyse.campaign import CampaignConfig, calibrate
from demcal.cli import main
from demcal.provenance import sha256_file
from report.render import build_report, write_tables
from tests.analyse.standin import standin_runner

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "data" / "astragalus"
CONFIG = CampaignConfig(workers=1, progress=False)


def _campaign(tmp_root: Path, name: str) -> tuple[Path, Path]:
    """Copy the example workbook folder and run the stand-in campaign on the copy."""
    if not (EXAMPLE / "workbook.xlsx").exists():
        pytest.skip(f"example workbook missing: {EXAMPLE}")
    data = tmp_root / f"{name}_data"
    shutil.copytree(EXAMPLE, data)
    out = tmp_root / name
    calibrate(data / "workbook.xlsx", out, CONFIG, runner=standin_runner)
    return data, out


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
    # every DEM run appears in the appendix with its full key
    for run in campaign["results"]["validation"]["runs"]:
        assert run["key"] in flat.replace(" ", "")


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

    pb_keys = next(s for s in tables["4"]["sources"] if s["kind"] == "runs")["keys"]
    assert _column(tables["4"], "Angle of repose") == [angle(k) for k in pb_keys]
    # Plackett-Burman effects: mean(+1) - mean(-1) of Table 4's columns
    y = np.array(_column(tables["4"], "Angle of repose"))
    effects = dict(zip(_column(tables["5"], "Source"), _column(tables["5"], "Effect")))
    for f in "ABCDEFG":
        x = np.array(_column(tables["4"], f))
        assert effects[f] == pytest.approx(y[x > 0].mean() - y[x < 0].mean(), rel=1e-9)
    # validation: relative error of the mean of the stored run angles
    val = [r for r in tables["A2"]["rows"] if r[0] == "validation"]
    mean = np.mean([angle(r[2]) for r in val])
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
    critique = {"discrepancies": [{"observable": "restitution.particle-steel", "measured": 0.35,
                                   "simulated": 0.41, "difference": 0.06, "exceeds": True}],
                "findings": [{"mechanism": "velocity-dependent restitution", "verdict": "supported",
                              "sheet": "drop", "covariate": "drop_height_mm", "effect": -0.12,
                              "ci95": [-0.2, -0.04], "p_adjusted": 0.003}],
                "extensions": []}
    (out / "critique.json").write_text(json.dumps(critique))
    assert main(["report", str(out), "--no-pdf"]) == 0
    assert f"report: {out / 'report.html'}" in capsys.readouterr().out
    tables = {t["id"]: t for t in json.loads((out / "tables.json").read_text())["tables"]}
    assert tables["C2"]["columns"] == ["mechanism", "verdict", "sheet", "covariate", "effect", "ci95",
                                       "p_adjusted"]
    assert tables["C2"]["rows"] == [["velocity-dependent restitution", "supported", "drop",
                                     "drop_height_mm", -0.12, [-0.2, -0.04], 0.003]]
    assert tables["C1"]["rows"][0][0] == "restitution.particle-steel" and tables["C3"]["rows"] == []
    html = (out / "report.html").read_text(encoding="utf-8")
    assert "Critique of the calibrated model" in html and "velocity-dependent restitution" in html
    assert "Table C3" in html
    assert (out / "tables.json").read_text().count("critique.json") >= 3  # hashed and named as source


def test_tables_render_when_lenth_has_no_pse(campaign, tmp_path):
    """Lenth's PSE is stored as null when most contrasts are exactly zero; Table 5 says n/a."""
    import json
    import shutil

    from report.tables import build_tables, load_campaign

    out = tmp_path / "campaign"
    shutil.copytree(campaign["out"], out)
    results = json.loads((out / "results.json").read_text())
    results["plackett_burman"]["screening"]["lenth"] = {"pse": None, "me": None, "active": None}
    (out / "results.json").write_text(json.dumps(results))
    table5 = next(t for t in build_tables(load_campaign(out)) if t.id == "5")
    assert any("PSE n/a deg" in note for note in table5.notes)
