"""Reading and validating the lab workbook (docs/workbook.md), as .xlsx and as a CSV folder."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from demcal.errors import InputError, WorkbookError
from demcal.provenance import sha256_file
from demcal.measure.workbook import read_workbook, write_workbook
from tests.measure.conftest import base_sheets, write_attachments


def sheet_file(path, fmt, sheet):
    """The file an error about ``sheet`` must name."""
    return str(path) if fmt == "xlsx" else str(path / f"{sheet}.csv")


def expect_error(path, fmt, sheet, row, column, value=None):
    """Read ``path``; the error must name file, sheet, row and column (and value if given)."""
    with pytest.raises(WorkbookError) as info:
        read_workbook(path)
    err = info.value
    text = str(err)
    assert err.file == sheet_file(path, fmt, sheet)
    assert (err.sheet, err.row, err.column) == (sheet, row, column)
    assert f"file {err.file}" in text and f"sheet '{sheet}'" in text
    if row is not None:
        assert f"row {row}" in text
    if column is not None:
        assert f"column '{column}'" in text
    if value is not None:
        assert repr(value) in text or str(value) in text
    return err


# ---------------------------------------------------------------------------------------------
# a valid workbook

def test_reads_every_sheet_with_types_and_row_numbers(campaign, fmt):
    path = campaign()
    wb = read_workbook(path)
    assert wb.source == path
    assert wb.root == (path.parent if fmt == "xlsx" else path)
    assert set(wb.sheets) == {"meta", "specimens", "density", "drop", "incline", "compression",
                              "repose", "notes"}
    spec = wb.sheets["specimens"]
    assert spec.rows == [1, 2, 3]
    assert spec.frame.loc[2, "length_mm"] == 25.0
    assert spec.frame.loc[3, "specimen_id"] == "S3"
    assert spec.required == ["specimen_id", "length_mm", "diameter_mm", "mass_g"]
    # names are normalised: the workbook wrote 'Particle-Particle'
    assert wb.sheets["drop"].frame.loc[6, "pair"] == "particle-particle"
    # incline has both variants, so both sets of columns are required
    assert wb.sheets["incline"].required == ["trial_id", "surface", "mode", "angle_deg", "slope_deg",
                                             "release_height_mm", "runout_mm"]
    assert math.isnan(wb.sheets["incline"].frame.loc[8, "angle_deg"])


def test_meta_numbers_parsed_and_unknown_keys_kept(campaign):
    wb = read_workbook(campaign())
    assert wb.meta["material"] == "test segments"
    assert wb.meta["fill_count"] == 500 and isinstance(wb.meta["fill_count"], int)
    assert wb.meta["contact_poisson"] == 0.3
    assert wb.meta["contact_shear_modulus_pa"] == 8e10
    assert wb.meta["lab_room"] == "B12"  # unknown to us, kept


def test_covariates_kept_with_each_row(campaign):
    wb = read_workbook(campaign())
    drop = wb.sheets["drop"]
    assert drop.optional == ["track_file"]
    assert drop.covariates == ["specimen_id", "date", "operator", "orientation_deg", "trial_order"]
    assert drop.covariates_of(2) == {"specimen_id": "S2", "date": "2024-05-01", "operator": "ben",
                                     "orientation_deg": 45.0, "trial_order": 2.0}
    assert wb.sheets["specimens"].covariates_of(3) == {"moisture_pct": 11.0, "batch": "B"}
    assert wb.sheets["repose"].covariates == ["day"]


def test_unknown_sheets_kept_and_listed(campaign):
    wb = read_workbook(campaign())
    assert wb.unknown_sheets == ["notes"]
    notes = wb.sheets["notes"]
    assert notes.covariates == ["note", "by"]
    assert notes.frame.loc[1, "note"] == "balance calibrated"


def test_files_hashed_workbook_and_every_reference(campaign, fmt):
    path = campaign()
    wb = read_workbook(path)
    root = wb.root
    expected = {root / "tracks/t5.csv", root / "curves/c1.csv", root / "curves/c3.csv",
                root / "photos/p1.png", root / "photos/p2.png"}
    if fmt == "xlsx":
        expected.add(path)
    else:
        expected |= {path / f"{s}.csv" for s in wb.sheets}
    assert set(wb.files) == {str(p) for p in expected}
    for p, digest in wb.files.items():
        assert digest == sha256_file(p)
    assert wb.sheets["drop"].sha256 == sha256_file(sheet_file(path, fmt, "drop"))


def test_empty_rows_skipped_numbering_kept(campaign, fmt):
    blank = {"specimen_id": None, "length_mm": None, "diameter_mm": None, "mass_g": None,
             "moisture_pct": None, "batch": None}

    def edit(s):
        s["specimens"].insert(1, blank)
        s["specimens"][3]["mass_g"] = -1  # data row 4 once the blank row counts
    path = campaign(edit)
    expect_error(path, fmt, "specimens", 4, "mass_g", -1)

    def edit_ok(s):
        s["specimens"].insert(1, dict(blank))
    wb = read_workbook(campaign(edit_ok))
    assert wb.sheets["specimens"].rows == [1, 3, 4]


def test_case_and_spacing_of_headers_and_sheet_names(tmp_path):
    root = tmp_path / "wb"
    root.mkdir()
    (root / "Meta.csv").write_text("Key, VALUE\nmaterial,roots\n")
    (root / "specimens.csv").write_text("Specimen_ID,LENGTH_mm,diameter_mm,mass_g,Batch\nA,25,11,2,x\n")
    wb = read_workbook(root)
    assert wb.meta == {"material": "roots"}
    assert wb.sheets["specimens"].required == ["specimen_id", "length_mm", "diameter_mm", "mass_g"]
    assert wb.sheets["specimens"].covariates == ["Batch"]


def test_track_row_may_leave_heights_empty(campaign):
    def edit(s):
        s["drop"][4]["drop_height_mm"] = None
        s["drop"][4]["rebound_height_mm"] = None
    wb = read_workbook(campaign(edit))
    assert math.isnan(wb.sheets["drop"].frame.loc[5, "rebound_height_mm"])


def test_windows_separators_in_paths(campaign):
    wb = read_workbook(campaign(lambda s: s["repose"][0].__setitem__("file", "photos\\p1.png")))
    assert wb.resolve(wb.sheets["repose"].frame.loc[1, "file"]) == wb.root / "photos" / "p1.png"


def test_attachments_parsed_in_lab_units(campaign):
    wb = read_workbook(campaign())
    curve = wb.attachment("curves/c1.csv")
    assert list(curve.columns) == ["displacement_mm", "force_N"]
    assert curve["force_N"].iloc[20] == pytest.approx(200.0)


def test_write_workbook_round_trip(campaign, tmp_path, fmt):
    wb = read_workbook(campaign())
    target = tmp_path / "copy" / ("wb.xlsx" if fmt == "xlsx" else "wb")
    write_attachments(target.parent if fmt == "xlsx" else target)
    again = read_workbook(write_workbook(wb, target))
    assert again.meta == wb.meta
    for name in wb.sheets:
        pd.testing.assert_frame_equal(again.sheets[name].frame, wb.sheets[name].frame,
                                      check_dtype=False)


# ---------------------------------------------------------------------------------------------
# bad input: every error names file, sheet, row and column

@pytest.mark.parametrize("sheet", ["meta", "specimens"])
def test_missing_required_sheet(campaign, fmt, sheet):
    path = campaign(lambda s: s.pop(sheet))
    err = expect_error(path, fmt, sheet, None, None)
    assert "missing sheet" in str(err)


def test_required_sheet_without_rows(campaign, fmt):
    path = campaign(lambda s: s.__setitem__("specimens", pd.DataFrame(
        columns=["specimen_id", "length_mm", "diameter_mm", "mass_g"])))
    err = expect_error(path, fmt, "specimens", None, None)
    assert "no data rows" in str(err)


def test_optional_sheet_may_be_absent(campaign):
    wb = read_workbook(campaign(lambda s: [s.pop(k) for k in ("density", "drop", "incline",
                                                              "compression", "repose")]))
    assert set(wb.sheets) == {"meta", "specimens", "notes"}


@pytest.mark.parametrize("sheet,column", [
    ("specimens", "mass_g"), ("density", "volume_after_ml"), ("drop", "rebound_height_mm"),
    ("drop", "pair"), ("incline", "mode"), ("compression", "thickness_after_mm"),
    ("repose", "file"), ("meta", "value"),
])
def test_missing_required_column(campaign, fmt, sheet, column):
    def edit(s):
        if sheet == "meta":
            s["meta"] = [{"key": k} for k in s["meta"]]
        else:
            for row in s[sheet]:
                row.pop(column)
    err = expect_error(campaign(edit), fmt, sheet, None, column)
    assert "missing required column" in str(err)


def test_incline_needs_angle_or_rollout_columns(campaign, fmt):
    def edit(s):
        for row in s["incline"]:
            for c in ("angle_deg", "slope_deg", "release_height_mm", "runout_mm"):
                row.pop(c)
    expect_error(campaign(edit), fmt, "incline", None, "angle_deg")

    def partial(s):
        for row in s["incline"]:
            row.pop("runout_mm")
    expect_error(campaign(partial), fmt, "incline", None, "runout_mm")


@pytest.mark.parametrize("sheet,index,column,value", [
    ("specimens", 1, "length_mm", "12,5"),
    ("specimens", 0, "mass_g", "heavy"),
    ("density", 2, "volume_before_ml", "n/a"),
    ("drop", 3, "drop_height_mm", "40 cm"),
    ("incline", 1, "angle_deg", "thirty"),
    ("compression", 2, "width_after_mm", "?"),
    ("repose", 0, "scale_mm_per_px", "x"),
])
def test_non_numeric_cell(campaign, fmt, sheet, index, column, value):
    path = campaign(lambda s: s[sheet][index].__setitem__(column, value))
    err = expect_error(path, fmt, sheet, index + 1, column, value)
    assert "not a number" in str(err)


@pytest.mark.parametrize("sheet,index,column,value", [
    ("specimens", 0, "length_mm", 0),
    ("specimens", 1, "diameter_mm", -11),
    ("specimens", 2, "mass_g", 0),
    ("density", 0, "mass_g", -10),
    ("density", 1, "volume_before_ml", 0),
    ("drop", 0, "drop_height_mm", 0),
    ("drop", 1, "rebound_height_mm", -3),
    ("incline", 7, "release_height_mm", 0),
    ("incline", 8, "runout_mm", -1),
    ("compression", 0, "width_before_mm", 0),
    ("compression", 1, "thickness_after_mm", -2),
])
def test_zero_or_negative_size_height_mass_volume(campaign, fmt, sheet, index, column, value):
    path = campaign(lambda s: s[sheet][index].__setitem__(column, value))
    err = expect_error(path, fmt, sheet, index + 1, column, value)
    assert "positive" in str(err) or "negative" in str(err)


def test_zero_rebound_is_allowed(campaign):
    wb = read_workbook(campaign(lambda s: s["drop"][0].__setitem__("rebound_height_mm", 0)))
    assert wb.sheets["drop"].frame.loc[1, "rebound_height_mm"] == 0.0


def test_rebound_above_drop_height(campaign, fmt):
    path = campaign(lambda s: s["drop"][2].__setitem__("rebound_height_mm", 250))
    err = expect_error(path, fmt, "drop", 3, "rebound_height_mm", 250.0)
    assert "above its drop height" in str(err)


def test_volume_after_not_above_before(campaign, fmt):
    path = campaign(lambda s: s["density"][1].__setitem__("volume_after_ml", 50))
    expect_error(path, fmt, "density", 2, "volume_after_ml", 50.0)


def test_thickness_unchanged(campaign, fmt):
    path = campaign(lambda s: s["compression"][1].__setitem__("thickness_after_mm", 12))
    expect_error(path, fmt, "compression", 2, "thickness_after_mm", 12.0)


@pytest.mark.parametrize("sheet,index,column,value", [
    ("incline", 0, "angle_deg", 90),
    ("incline", 1, "angle_deg", 0),
    ("incline", 2, "angle_deg", -5),
    ("incline", 7, "slope_deg", 95),
    ("repose", 1, "angle_deg_manual", 90.5),
])
def test_angle_outside_0_90(campaign, fmt, sheet, index, column, value):
    path = campaign(lambda s: s[sheet][index].__setitem__(column, value))
    err = expect_error(path, fmt, sheet, index + 1, column, value)
    assert "between 0 and 90" in str(err)


@pytest.mark.parametrize("sheet,index,column,value,valid", [
    ("drop", 0, "pair", "steel", "particle-steel"),
    ("drop", 1, "pair", "particle-", "particle-<material>"),
    ("drop", 2, "pair", "particle steel", "particle-rubber"),
    ("drop", 3, "pair", "particle-3d", "particle-particle"),
    ("incline", 0, "surface", "st eel", "particle, steel"),
    ("incline", 3, "surface", 3, "particle, steel"),
    ("incline", 4, "surface", "particle-steel", "particle, steel"),
    ("incline", 1, "mode", "slid", "slide, roll"),
    ("compression", 0, "axis", "diagonal", "radial, axial"),
    ("repose", 1, "side", "top", "left, right, both"),
])
def test_unknown_names_list_the_valid_ones(campaign, fmt, sheet, index, column, value, valid):
    path = campaign(lambda s: s[sheet][index].__setitem__(column, value))
    err = expect_error(path, fmt, sheet, index + 1, column, value)
    assert f"unknown {column}" in str(err) and valid in str(err)


@pytest.mark.parametrize("sheet,index,column", [
    ("drop", 1, "pair"), ("incline", 2, "surface"), ("incline", 2, "mode"),
])
def test_empty_name_is_unknown(campaign, fmt, sheet, index, column):
    path = campaign(lambda s: s[sheet][index].__setitem__(column, None))
    err = expect_error(path, fmt, sheet, index + 1, column)
    assert f"unknown {column}" in str(err)


@pytest.mark.parametrize("sheet,index,column", [
    ("specimens", 1, "mass_g"), ("specimens", 2, "specimen_id"), ("drop", 0, "rebound_height_mm"),
    ("incline", 0, "trial_id"), ("compression", 2, "width_before_mm"), ("repose", 0, "file"),
])
def test_missing_required_value(campaign, fmt, sheet, index, column):
    path = campaign(lambda s: s[sheet][index].__setitem__(column, None))
    err = expect_error(path, fmt, sheet, index + 1, column)
    assert "missing value" in str(err)


def test_incline_row_without_angle_or_rollout(campaign, fmt):
    path = campaign(lambda s: s["incline"][0].__setitem__("angle_deg", None))
    expect_error(path, fmt, "incline", 1, "angle_deg")


def test_incline_row_with_both_variants(campaign, fmt):
    path = campaign(lambda s: s["incline"][0].__setitem__("slope_deg", 20))
    err = expect_error(path, fmt, "incline", 1, "slope_deg", 20.0)
    assert "not both" in str(err)


def test_rollout_row_must_be_roll_mode(campaign, fmt):
    path = campaign(lambda s: s["incline"][7].__setitem__("mode", "slide"))
    expect_error(path, fmt, "incline", 8, "mode", "slide")


def test_rollout_row_incomplete(campaign, fmt):
    path = campaign(lambda s: s["incline"][8].__setitem__("runout_mm", None))
    expect_error(path, fmt, "incline", 9, "runout_mm")


@pytest.mark.parametrize("key,row,value,message", [
    ("contact_density_kg_m3", 3, "heavy", "not a number"),
    ("fill_count", 11, 0, "positive"),
    ("fill_count", 11, 12.5, "whole number"),
    ("contact_poisson", 4, 0.7, "(-1, 0.5)"),
    ("target_repose_deg", 13, 95, "between 0 and 90"),
])
def test_bad_meta_value(campaign, fmt, key, row, value, message):
    def edit(s):
        s["meta"][key] = value  # existing keys keep their row; a new key is row 13
    err = expect_error(campaign(edit), fmt, "meta", row, "value", value)
    assert message in str(err)


def test_a_sphere_count_the_shape_cannot_take_is_refused_in_the_meta(campaign, fmt):
    def edit(s):
        s["meta"]["shape"] = "kernel"                 # new keys: rows 13 and 14
        s["meta"]["spheres_per_particle"] = 2
    err = expect_error(campaign(edit), fmt, "meta", 14, "value", 2)
    assert "tips" in str(err) and "3 or more" in str(err)


def test_meta_material_missing(campaign, fmt):
    def edit(s):
        s["meta"].pop("material")
    expect_error(campaign(edit), fmt, "meta", None, "key")

    def empty(s):
        s["meta"]["material"] = None
    expect_error(campaign(empty), fmt, "meta", 1, "value")


# referenced files

def test_photo_missing(campaign, fmt):
    path = campaign(lambda s: s["repose"][1].__setitem__("file", "photos/nothere.png"))
    err = expect_error(path, fmt, "repose", 2, "file", "photos/nothere.png")
    assert "photo file not found" in str(err)


def test_photo_unreadable(campaign, fmt):
    path = campaign()
    root = path.parent if fmt == "xlsx" else path
    (root / "photos" / "p2.png").write_bytes(b"not a png at all")
    err = expect_error(path, fmt, "repose", 2, "file", "photos/p2.png")
    assert "not a readable image file" in str(err)


@pytest.mark.parametrize("content,reason", [
    ("displacement_mm,load\n0,0\n0.1,1\n0.2,2\n", "lacks column 'force_N'"),
    ("displacement_mm,force_N\n0,0\n0.1,abc\n0.2,2\n", "not a number"),
    ('displacement_mm,force_N\n0,0\n0.1,1,7,8\n"0.2,2\n', "cannot parse"),
    ("displacement_mm,force_N\n0,0\n", "at least 3"),
    ("", "cannot parse"),
])
def test_curve_file_unusable(campaign, fmt, content, reason):
    path = campaign()
    root = path.parent if fmt == "xlsx" else path
    (root / "curves" / "c3.csv").write_text(content)
    err = expect_error(path, fmt, "compression", 3, "curve_file", "curves/c3.csv")
    assert reason in str(err) and "c3.csv" in str(err)


def test_curve_file_missing(campaign, fmt):
    path = campaign(lambda s: s["compression"][0].__setitem__("curve_file", "curves/none.csv"))
    err = expect_error(path, fmt, "compression", 1, "curve_file", "curves/none.csv")
    assert "curve file not found" in str(err)


@pytest.mark.parametrize("content,reason", [
    ("t_s,height_mm\n0,1\n0.1,2\n0.2,3\n", "lacks column 'y_mm'"),
    ("t_s,y_mm\n0,1\n0.1,two\n0.2,3\n", "not a number"),
])
def test_track_file_unusable(campaign, fmt, content, reason):
    path = campaign()
    root = path.parent if fmt == "xlsx" else path
    (root / "tracks" / "t5.csv").write_text(content)
    err = expect_error(path, fmt, "drop", 5, "track_file", "tracks/t5.csv")
    assert reason in str(err)


def test_track_file_missing(campaign, fmt):
    path = campaign(lambda s: s["drop"][0].__setitem__("track_file", "tracks/t1.csv"))
    expect_error(path, fmt, "drop", 1, "track_file", "tracks/t1.csv")


def test_not_a_workbook(tmp_path):
    with pytest.raises(InputError, match="not found"):
        read_workbook(tmp_path / "missing.xlsx")
    (tmp_path / "book.ods").write_bytes(b"x")
    with pytest.raises(InputError, match="xlsx"):
        read_workbook(tmp_path / "book.ods")
    (tmp_path / "broken.xlsx").write_bytes(b"PK\x03\x04 broken")
    with pytest.raises(WorkbookError, match="broken.xlsx"):
        read_workbook(tmp_path / "broken.xlsx")


def test_header_without_name_but_with_data(tmp_path):
    root = tmp_path / "wb"
    root.mkdir()
    (root / "meta.csv").write_text("key,value\nmaterial,roots\n")
    (root / "specimens.csv").write_text("specimen_id,length_mm,diameter_mm,mass_g,\nA,25,11,2,oops\n")
    with pytest.raises(WorkbookError) as info:
        read_workbook(root)
    assert info.value.sheet == "specimens" and info.value.column == "#5"


def test_numbers_are_finite(tmp_path):
    root = tmp_path / "wb"
    root.mkdir()
    (root / "meta.csv").write_text("key,value\nmaterial,roots\n")
    (root / "specimens.csv").write_text("specimen_id,length_mm,diameter_mm,mass_g\nA,inf,11,2\n")
    with pytest.raises(WorkbookError) as info:
        read_workbook(root)
    assert (info.value.row, info.value.column) == (1, "length_mm")
    assert np.isinf(float(info.value.value))


# ---------------------------------------------------------------------------------------------
# the particle's shape: its own calliper columns, each reading checked as the shape reads it

def _shape(name, **columns):
    def edit(s):
        s["meta"]["shape"] = name
        for row in s["specimens"]:
            row.update(columns)
    return edit


def test_a_shape_whose_columns_are_missing_is_refused_naming_the_column(campaign, fmt):
    err = expect_error(campaign(_shape("kernel")), fmt, "specimens", None, "width_mm")
    assert "shape kernel (meta shape) is measured by (length_mm, width_mm, thickness_mm)" in str(err)


def test_a_kernel_wider_than_long_is_refused_naming_row_and_column(campaign, fmt):
    def edit(s):
        _shape("kernel", width_mm=8.0, thickness_mm=5.0)(s)
        s["specimens"][1]["width_mm"] = 30.0
    err = expect_error(campaign(edit), fmt, "specimens", 2, "width_mm", 30.0)
    assert "width 30 mm exceeds the length 25 mm" in str(err)


def test_a_segment_wider_than_long_is_refused_and_a_sphere_suggested(campaign, fmt):
    def edit(s):
        s["specimens"][2]["diameter_mm"] = 27.0
    err = expect_error(campaign(edit), fmt, "specimens", 3, "diameter_mm", 27.0)
    assert "meta key shape: sphere or kernel" in str(err)
    wb = read_workbook(campaign(_shape("sphere")))              # the same rows read as spheres
    assert wb.sheet("specimens").required[:2] == ["specimen_id", "diameter_mm"]


def test_an_unknown_shape_is_refused_listing_the_valid_ones(campaign, fmt):
    def edit(s):
        s["meta"]["shape"] = "cube"
    row = list(base_sheets()["meta"]).index("material") + 1 + len(base_sheets()["meta"])
    with pytest.raises(WorkbookError) as info:
        read_workbook(campaign(edit))
    err = info.value
    assert (err.sheet, err.row, err.column) == ("meta", row, "value")
    assert "unknown shape 'cube'; valid shapes: segment, sphere, kernel, clump" in str(err)


def test_a_clump_sheet_with_a_negative_radius_is_refused_naming_row_and_column(campaign, fmt):
    def edit(s):
        s["meta"]["shape"] = "clump"
        s["clump"] = [{"x_mm": 0, "y_mm": 0, "z_mm": 0, "radius_mm": 2.0},
                      {"x_mm": 3, "y_mm": 0, "z_mm": 0, "radius_mm": -1.5}]
    expect_error(campaign(edit), fmt, "clump", 2, "radius_mm", -1.5)


def test_a_clump_shape_needs_its_sheet(campaign, fmt):
    with pytest.raises(WorkbookError, match="the meta shape clump needs the clump sheet"):
        read_workbook(campaign(_shape("clump")))
