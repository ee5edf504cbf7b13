"""The workbook is untrusted input: hostile or malformed copies of a small workbook, each with
one thing changed, are refused naming file, sheet, row and column, or read with a note naming
the cells; legitimate variants are still read as before.

Every hostile file is built here from the small workbook of conftest.py; nothing large is
committed. The resource tests run the reader in a child process under an address-space cap
and check its peak memory.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import openpyxl
import pandas as pd
import pytest

from demcal.cli import main
from demcal.errors import WorkbookError
from demcal.measure import rawsheets
from demcal.measure.workbook import ReadOptions, read_workbook

from tests.measure.conftest import base_sheets, save, write_attachments

ROOT = Path(__file__).resolve().parents[2]


def _error(path, options=None) -> WorkbookError:
    with pytest.raises(WorkbookError) as info:
        read_workbook(path, options)
    return info.value


def _csv_workbook(tmp_path, edit=None) -> Path:
    sheets = base_sheets()
    if edit is not None:
        edit(sheets)
    root = tmp_path / "campaign"
    write_attachments(root)
    return save(root, sheets, "csv")


# ---------------------------------------------------------------------------------------------
# CSV: strict records, separator and decimal mark given or detected and stated

def _european(path: Path, separator: str) -> None:
    """Rewrite a CSV sheet the way a European spreadsheet exports it: decimal commas."""
    frame = pd.read_csv(path, dtype=str, keep_default_na=False)
    lines = [separator.join(frame.columns)]
    for _, row in frame.iterrows():
        lines.append(separator.join(c.replace(".", ",") if c.replace(".", "", 1).isdigit() else c
                                    for c in row))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def test_decimal_commas_in_a_comma_separated_sheet_are_refused_naming_the_line(tmp_path):
    path = _csv_workbook(tmp_path)
    _european(path / "specimens.csv", ",")
    err = _error(path)
    assert err.file == str(path / "specimens.csv") and err.sheet == "specimens"
    # S1 (line 2) S1,24,10,1.6,9.5,A becomes S1,24,10,1,6,9,5,A: 8 fields where the header has 6
    assert "line 2 has 8 fields where the header has 6" in str(err)
    assert "--csv-decimal" in str(err)


def test_semicolon_sheets_with_decimal_commas_read_the_same_numbers_and_say_so(tmp_path):
    plain = read_workbook(_csv_workbook(tmp_path / "a"))
    path = _csv_workbook(tmp_path / "b")
    for csv in path.rglob("*.csv"):                  # sheets, curves and tracks, as a European
        _european(csv, ";")                          # spreadsheet exports them
    wb = read_workbook(path)
    given = read_workbook(path, ReadOptions(csv_decimal=",", csv_separator=";"))
    for name in ("specimens", "drop", "incline", "compression", "density"):
        pd.testing.assert_frame_equal(wb.sheets[name].frame, plain.sheets[name].frame)
        pd.testing.assert_frame_equal(given.sheets[name].frame, plain.sheets[name].frame)
    for key, frame in plain.attachments.items():
        pd.testing.assert_frame_equal(wb.attachments[key.replace("/a/", "/b/")], frame)
    assert any(n.startswith("specimens.csv: decimal comma detected (separator semicolon)")
               for n in wb.notes)
    assert any(n.startswith("c1.csv: decimal comma detected") for n in wb.notes)
    # given, nothing is detected, so nothing is noted
    assert not any("decimal comma" in n for n in given.notes)


def test_mixed_decimal_marks_are_refused(tmp_path):
    path = _csv_workbook(tmp_path)
    (path / "density.csv").write_text("sample_id;mass_g;volume_before_ml;volume_after_ml\n"
                                      "D1;10,5;50;61\nD2;12.5;50;63\n")
    err = _error(path)
    assert "decimal comma" in str(err) and "decimal point" in str(err) and "--csv-decimal" in str(err)
    # given, the mark holds for every CSV of the workbook: the first point is refused
    err = _error(path, ReadOptions(csv_decimal=","))
    assert err.row is not None and err.column is not None and "decimal point" in str(err)


@pytest.mark.parametrize("line", ["D3,11,40", "D3,11,40,52,9"])
def test_a_record_with_more_or_fewer_fields_is_refused_naming_its_line(tmp_path, line):
    path = _csv_workbook(tmp_path)
    text = (path / "density.csv").read_text().rstrip("\n").split("\n")
    text[3] = line
    (path / "density.csv").write_text("\n".join(text) + "\n")
    err = _error(path)
    assert err.file == str(path / "density.csv")
    assert f"line 4 has {len(line.split(','))} fields where the header has 4" in str(err)


@pytest.mark.parametrize("fmt", ["xlsx", "csv"])
def test_a_column_given_twice_is_refused_by_name(tmp_path, fmt):
    root = tmp_path / "campaign"
    write_attachments(root)
    sheets = base_sheets()
    path = save(root, sheets, fmt)
    if fmt == "csv":
        text = (path / "specimens.csv").read_text().split("\n")
        text = [line + ("," + line.split(",")[1] if line else "") for line in text]
        text[0] = text[0].rsplit(",", 1)[0] + ",Length_mm"
        (path / "specimens.csv").write_text("\n".join(text))
    else:
        book = openpyxl.load_workbook(path)
        ws = book["specimens"]
        col = ws.max_column + 1
        ws.cell(1, col, "Length_mm")
        for r in range(2, ws.max_row + 1):
            ws.cell(r, col, ws.cell(r, 2).value)
        book.save(path)
    err = _error(path)
    assert (err.sheet, err.column) == ("specimens", "length_mm") and "duplicate column" in str(err)


# ---------------------------------------------------------------------------------------------
# ids and files given twice

@pytest.mark.parametrize("sheet,index,column,other", [
    ("specimens", 2, "specimen_id", 1), ("drop", 3, "trial_id", 1), ("incline", 5, "trial_id", 4),
    ("repose", 1, "photo_id", 1), ("density", 2, "sample_id", 1)])
def test_an_id_given_twice_is_refused_naming_both_rows(campaign, fmt, sheet, index, column, other):
    def edit(s):
        s[sheet][index][column] = s[sheet][other - 1][column]
    path = campaign(edit)
    err = _error(path)
    assert (err.sheet, err.row, err.column) == (sheet, index + 1, column)
    assert f"row {other} has it too" in str(err)


def test_a_specimen_compressed_on_both_axes_is_not_a_duplicate(campaign):
    def edit(s):
        s["compression"][2]["specimen_id"] = "S1"        # S1 radial (row 1), S1 axial (row 3)
    wb = read_workbook(campaign(edit))
    assert list(wb.sheets["compression"].frame["specimen_id"]) == ["S1", "S2", "S1"]


@pytest.mark.parametrize("second", ["photos/p1.png", "./photos/p1.png", "photos/../photos/p1.png"])
def test_the_same_photo_twice_is_refused(campaign, fmt, second):
    def edit(s):
        s["repose"][1]["file"] = second
    err = _error(campaign(edit))
    assert (err.sheet, err.row, err.column) == ("repose", 2, "file")
    assert "same file as row 1" in str(err)


# ---------------------------------------------------------------------------------------------
# every number plausible, every estimate finite

@pytest.mark.parametrize("sheet,index,column,value", [
    ("specimens", 1, "length_mm", 1e308), ("specimens", 0, "diameter_mm", 1e-300),
    ("specimens", 2, "mass_g", 5e6), ("drop", 0, "drop_height_mm", 1e9),
    ("compression", 1, "width_after_mm", 1e12)])
def test_implausible_numbers_are_refused_naming_the_cell(campaign, fmt, sheet, index, column, value):
    def edit(s):
        s[sheet][index][column] = value
    err = _error(campaign(edit))
    assert (err.sheet, err.row, err.column) == (sheet, index + 1, column)
    assert "plausible range" in str(err) and f"--range {column}=" in str(err)


def test_a_stated_range_can_be_widened(campaign):
    def edit(s):
        s["specimens"][1]["length_mm"] = 1500.0       # a 1.5 m stalk
    path = campaign(edit)
    _error(path)
    wb = read_workbook(path, ReadOptions(ranges={"length_mm": (0.05, 2000.0)}))
    assert wb.sheets["specimens"].frame.at[2, "length_mm"] == 1500.0


def test_implausible_meta_and_attachment_values_are_refused(campaign, fmt):
    def edit(s):
        s["meta"]["fill_count"] = 10**9
    err = _error(campaign(edit))
    assert (err.sheet, err.column) == ("meta", "value") and "fill_count" in str(err)

    path = campaign()
    root = path.parent if fmt == "xlsx" else path
    curve = pd.read_csv(root / "curves" / "c1.csv")
    curve.loc[3, "force_N"] = 1e300
    curve.to_csv(root / "curves" / "c1.csv", index=False)
    err = _error(path)
    assert (err.sheet, err.row, err.column) == ("compression", 1, "curve_file")
    assert "data row 4, column 'force_N'" in str(err) and "plausible range" in str(err)


def test_a_huge_covariate_is_refused_and_a_missing_marker_keeps_it_numeric(campaign, fmt):
    def huge(s):
        s["specimens"][0]["moisture_pct"] = 1e200
    err = _error(campaign(huge))
    assert (err.sheet, err.row, err.column) == ("specimens", 1, "moisture_pct")

    def marker(s):
        s["specimens"][1]["moisture_pct"] = "NaN"
    wb = read_workbook(campaign(marker))
    col = wb.sheets["specimens"].frame["moisture_pct"]
    assert col.dtype == float and pd.isna(col[2]) and col[1] == 9.5
    assert any("'moisture_pct': row(s) 2 ('NaN') read as missing" in n for n in wb.notes)


def test_text_in_a_numeric_covariate_is_named(campaign):
    def edit(s):
        s["specimens"][2]["moisture_pct"] = "dry"
    wb = read_workbook(campaign(edit))
    assert wb.sheets["specimens"].frame["moisture_pct"].dtype == object
    assert any("'moisture_pct' is read as text" in n and "row 3: 'dry'" in n for n in wb.notes)


def test_measure_json_of_the_example_holds_no_null_estimate(tmp_path):
    out = tmp_path / "m.json"
    assert main(["measure", str(ROOT / "data" / "astragalus"), "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    for name, q in doc["quantities"].items():
        if q.get("extra", {}).get("override"):
            continue
        assert all(isinstance(x, float) for x in (q["value"], q["sd"], *q["ci95"])), name


# ---------------------------------------------------------------------------------------------
# what a spreadsheet program shows differently from the cells (xlsx)

def _xlsx(campaign_factory):
    path = campaign_factory()
    return path, openpyxl.load_workbook(path)


@pytest.mark.parametrize("fmt", ["xlsx"])
def test_hidden_rows_columns_and_sheets_are_read_and_named(campaign, fmt):
    path, book = _xlsx(campaign)
    book["specimens"].row_dimensions[3].hidden = True          # data row 2
    book["specimens"].column_dimensions["E"].hidden = True     # moisture_pct
    book["notes"].sheet_state = "hidden"
    book.save(path)
    wb = read_workbook(path)
    assert wb.sheets["specimens"].rows == [1, 2, 3]
    notes = " | ".join(wb.notes)
    assert "sheet 'specimens': rows 2 are hidden" in notes
    assert "'moisture_pct'" in notes and "hidden" in notes
    assert "sheet 'notes' is hidden" in notes


@pytest.mark.parametrize("fmt", ["xlsx"])
def test_cells_merged_in_a_covariate_give_each_row_the_value_with_a_note(campaign, fmt):
    path, book = _xlsx(campaign)
    ws = book["specimens"]
    ws["F3"] = None                                            # batch of S2, merged under S1's
    ws.merge_cells("F2:F3")
    book.save(path)
    wb = read_workbook(path)
    assert list(wb.sheets["specimens"].frame["batch"]) == ["A", "A", "B"]
    assert any("cells F2:F3 are merged" in n and "rows 1-2" in n for n in wb.notes)


@pytest.mark.parametrize("fmt", ["xlsx"])
def test_cells_merged_across_columns_are_refused(campaign, fmt):
    path, book = _xlsx(campaign)
    book["specimens"].merge_cells("E2:F2")
    book.save(path)
    err = _error(path)
    assert (err.sheet, err.row) == ("specimens", 1) and "merged across columns" in str(err)


@pytest.mark.parametrize("fmt", ["xlsx"])
def test_a_formula_without_a_value_is_refused_where_required_and_named_in_a_covariate(campaign, fmt):
    path, book = _xlsx(campaign)
    book["specimens"]["E3"] = "=E2+1"                          # moisture_pct of S2
    book.save(path)                                            # openpyxl stores no value
    wb = read_workbook(path)
    assert pd.isna(wb.sheets["specimens"].frame.at[2, "moisture_pct"])
    assert any("row(s) 2 hold formulas without a stored value" in n for n in wb.notes)

    book["specimens"]["B4"] = "=B3+1"                          # length_mm of S3
    book.save(path)
    err = _error(path)
    assert (err.sheet, err.row, err.column) == ("specimens", 3, "length_mm")
    assert "formula without a stored value" in str(err)


# ---------------------------------------------------------------------------------------------
# text that would print as a fake line or end a comment in an export

@pytest.mark.parametrize("fmt,name", [
    ("xlsx", "Soy\nshell touch x"), ("csv", "Soy\nshell touch x"), ("xlsx", "Soy\r\nimport os"),
    ("csv", "Soy\u2028x"), ("csv", "a\x1b[2J")])      # an .xlsx cannot hold ESC
def test_a_material_name_with_a_control_character_is_refused(campaign, fmt, name, capsys):
    def edit(s):
        s["meta"]["material"] = name
    path = campaign(edit)
    err = _error(path)
    assert (err.sheet, err.column) == ("meta", "value") and "control character" in str(err)
    capsys.readouterr()
    assert main(["measure", str(path)]) == 2
    out = capsys.readouterr()
    assert out.out == "" and out.err.count("\n") == 1 and "Traceback" not in out.err


@pytest.mark.parametrize("sheet,index,column", [("specimens", 0, "specimen_id"),
                                                ("drop", 2, "trial_id"), ("repose", 0, "photo_id")])
def test_an_id_with_a_line_break_is_refused(campaign, fmt, sheet, index, column):
    def edit(s):
        s[sheet][index][column] = "S\n9"
    err = _error(campaign(edit))
    assert (err.sheet, err.row, err.column) == (sheet, index + 1, column)


def test_a_line_break_in_a_covariate_reads_as_a_space_with_a_note(campaign):
    def edit(s):
        s["specimens"][0]["batch"] = "A\nsecond line"
    wb = read_workbook(campaign(edit))
    assert wb.sheets["specimens"].frame.at[1, "batch"] == "A second line"
    assert any("'batch': line breaks and control characters in row(s) 1" in n for n in wb.notes)


# ---------------------------------------------------------------------------------------------
# the workbook's folder is the boundary

def _outside_curve(tmp_path, fmt, campaign, cell):
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    write_attachments(outside)            # a valid curve, outside the workbook's folder

    def edit(s):
        s["compression"][0]["curve_file"] = cell(outside)
    return campaign(edit), outside


@pytest.mark.parametrize("cell", [lambda o: "../elsewhere/curves/c1.csv",
                                  lambda o: str(o / "curves" / "c1.csv")])
def test_a_path_out_of_the_workbook_folder_is_refused_before_it_is_opened(
        tmp_path, campaign, fmt, cell, monkeypatch):
    path, outside = _outside_curve(tmp_path, fmt, campaign, cell)
    opened = []
    real = rawsheets.read_csv
    monkeypatch.setattr(rawsheets, "read_csv", lambda p, **k: opened.append(Path(p)) or real(p, **k))
    err = _error(path)
    assert (err.sheet, err.row, err.column) == ("compression", 1, "curve_file")
    assert "outside the workbook's folder" in str(err) and "--allow-folder" in str(err)
    assert not any(p.resolve().is_relative_to(outside) for p in opened)
    # allowed explicitly: read, and provenance names the resolved file
    wb = read_workbook(path, ReadOptions(allowed_folders=(str(outside),)))
    assert str((outside / "curves" / "c1.csv").resolve()) in wb.files


def test_a_link_out_of_the_workbook_folder_is_refused(tmp_path, campaign, fmt):
    path = campaign()
    root = path.parent if fmt == "xlsx" else path
    (tmp_path / "secret.csv").write_text("displacement_mm,force_N\n0,0\n0.1,50\n0.2,100\n")
    (root / "curves" / "c1.csv").unlink()
    (root / "curves" / "c1.csv").symlink_to(tmp_path / "secret.csv")
    err = _error(path)
    assert (err.sheet, err.row, err.column) == ("compression", 1, "curve_file")
    assert "outside the workbook's folder" in str(err)


@pytest.mark.parametrize("target", ["/etc/passwd", "/proc/self/environ", "../../../../etc/passwd"])
def test_system_files_are_refused(campaign, fmt, target):
    def edit(s):
        s["repose"][0]["file"] = target
    err = _error(campaign(edit))
    assert (err.sheet, err.row, err.column) == ("repose", 1, "file")
    assert "outside the workbook's folder" in str(err)
    assert "root:" not in str(err)


def test_a_csv_sheet_linked_out_of_the_folder_is_refused(tmp_path):
    path = _csv_workbook(tmp_path)
    (tmp_path / "notes.csv").write_text("note\nx\n")
    (path / "notes.csv").unlink()
    (path / "notes.csv").symlink_to(tmp_path / "notes.csv")
    err = _error(path)
    assert "outside the workbook's folder" in str(err)


# ---------------------------------------------------------------------------------------------
# bounded resources: refused within seconds, well under 1 GB

_CHILD = textwrap.dedent("""
    import resource, sys, time
    cap = int(sys.argv[2])
    resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
    from demcal.cli import main
    t = time.perf_counter()
    code = main(["measure", sys.argv[1]])
    print(f"EXIT {code} {time.perf_counter() - t:.2f} "
          f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss}", file=sys.stderr)
""")


def _measure_capped(path: Path, cap_bytes: int = 3 * 2**30):
    """``demcal measure path`` in a child with its address space capped; (exit, s, peak MB, err)."""
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    proc = subprocess.run([sys.executable, "-c", _CHILD, str(path), str(cap_bytes)],
                          capture_output=True, text=True, timeout=120, env=env, cwd=ROOT)
    last = proc.stderr.strip().splitlines()[-1].split()
    assert last[0] == "EXIT", proc.stderr[-2000:]
    return int(last[1]), float(last[2]), int(last[3]) / 1024, proc.stderr


@pytest.mark.parametrize("fmt", ["xlsx"])
def test_a_stray_cell_at_the_sheet_corner_is_refused_quickly_in_little_memory(campaign, fmt):
    path, book = _xlsx(campaign)
    book["specimens"]["XFD1048576"] = 1.0
    book.save(path)
    assert path.stat().st_size < 64_000
    code, seconds, peak_mb, err = _measure_capped(path)
    assert code == 2 and "column XFD has data but no header" in err and "Traceback" not in err
    assert seconds < 10 and peak_mb < 1024


def _string_bomb(path: Path, megabytes: int) -> None:
    """Replace the shared-string table of ``path`` by one string of ``megabytes`` MB."""
    src = path.with_suffix(".orig.xlsx")
    path.rename(src)
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.infolist():
            if item.filename == "xl/sharedStrings.xml":
                continue
            zout.writestr(item, zin.read(item.filename))
        with zout.open("xl/sharedStrings.xml", "w", force_zip64=True) as f:
            f.write(b'<?xml version="1.0"?><sst xmlns="http://schemas.openxmlformats.org/'
                    b'spreadsheetml/2006/main" count="1" uniqueCount="1"><si><t>')
            chunk = b"A" * 2**20
            for _ in range(megabytes):
                f.write(chunk)
            f.write(b"</t></si></sst>")
    src.unlink()


@pytest.mark.parametrize("fmt", ["xlsx"])
def test_an_xlsx_that_unpacks_to_half_a_gigabyte_is_refused_quickly_in_little_memory(campaign, fmt):
    path = campaign()
    _string_bomb(path, 512)
    assert path.stat().st_size < 2 * 2**20
    code, seconds, peak_mb, err = _measure_capped(path)
    assert code == 2 and "unpacks to 512 MB" in err and "--max-file-mb" in err
    assert seconds < 10 and peak_mb < 1024


def test_a_huge_csv_sheet_is_refused_before_it_is_read(tmp_path):
    path = _csv_workbook(tmp_path)
    with open(path / "notes.csv", "a") as f:
        f.write(("x" * 1023 + "\n") * 1024 * 8)                 # 8 MB
    err = _error(path, ReadOptions(max_file_bytes=4 * 2**20))
    assert err.file == str(path / "notes.csv") and "above the 4 MB limit" in str(err)


def test_a_long_cell_is_refused_naming_it(campaign, fmt):
    def edit(s):
        s["specimens"][1]["batch"] = "B" * (rawsheets.MAX_CELL_CHARS + 1)
    err = _error(campaign(edit))
    assert (err.sheet, err.row, err.column) == ("specimens", 2, "batch")


# ---------------------------------------------------------------------------------------------
# what was legitimate stays accepted

def test_the_example_and_its_csv_form_read_alike_without_notes(tmp_path):
    xlsx = read_workbook(ROOT / "data" / "astragalus")
    assert xlsx.notes == []
    from demcal.measure.workbook import write_workbook
    folder = tmp_path / "astragalus_csv"
    folder.mkdir()
    for sub in ("photos", "tracks", "curves"):
        (folder / sub).symlink_to(ROOT / "data" / "astragalus" / sub)
    write_workbook(xlsx, folder)
    # the attachment folders are links into the example: allow it
    csv = read_workbook(folder, ReadOptions(allowed_folders=(str(ROOT / "data" / "astragalus"),)))
    for name in ("specimens", "drop", "incline", "compression", "repose"):
        pd.testing.assert_frame_equal(csv.sheets[name].frame, xlsx.sheets[name].frame,
                                      check_dtype=False)


def test_bom_unicode_ids_unknown_sheets_and_columns_are_accepted(tmp_path):
    def edit(s):
        s["specimens"][0]["specimen_id"] = "Échantillon-α"
        s["specimens"][0]["Feuchte (%)"] = 9.0
    path = _csv_workbook(tmp_path, edit)
    text = (path / "meta.csv").read_text(encoding="utf-8")
    (path / "meta.csv").write_text("\ufeff" + text, encoding="utf-8")
    wb = read_workbook(path)
    assert wb.sheets["specimens"].frame.at[1, "specimen_id"] == "Échantillon-α"
    assert "Feuchte (%)" in wb.sheets["specimens"].covariates
    assert wb.unknown_sheets == ["notes"]
    assert wb.meta["material"] == "test segments"


def test_docs_state_every_plausible_range():
    from demcal.measure.workbook import RANGES

    stated = {}
    for line in (ROOT / "docs" / "workbook.md").read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 3 and cells[0].startswith("`"):
            for name in cells[0].split(","):
                stated[name.strip().split("`")[1]] = (float(cells[1]), float(cells[2]))
    assert stated == RANGES
