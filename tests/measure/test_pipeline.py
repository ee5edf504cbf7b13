"""The measure stage end to end on the hand-checkable workbook of conftest.py."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

import demcal.measure.pipeline as pipeline
from demcal.errors import InputError, WorkbookError
from demcal.jsonio import read_json, write_json
from demcal.measure.images import MAX_PHOTO_PIXELS
from demcal.measure.pipeline import Measurement, measure_workbook
from demcal.measure.workbook import ReadOptions, read_workbook
from tests.measure.conftest import curve_frame, stub_photo_estimator

T = math.tan
R = math.radians
PHOTOS = {"p1.png": 34.0, "p2.png": 36.0}


def run(path, reading=None, **kw):
    kw.setdefault("photo_estimator", stub_photo_estimator(PHOTOS))
    return measure_workbook(read_workbook(path, reading), **kw)


def test_hand_values(campaign):
    q = run(campaign()).quantities
    assert list(q) == ["length_mm", "diameter_mm", "mass_g", "particle_density_kg_m3",
                       "envelope_density_kg_m3", "restitution.particle-particle",
                       "restitution.particle-steel", "static_friction.particle",
                       "static_friction.steel", "rolling_friction.particle", "rolling_friction.steel",
                       "poisson_ratio", "elastic_modulus_pa", "shear_modulus_pa", "repose_angle_deg"]
    # specimens: 24/25/26 mm, 10/11/12 mm, 1.6/2.0/2.4 g
    assert (q["length_mm"].value, q["length_mm"].sd, q["length_mm"].unit) == (25.0, pytest.approx(1.0), "mm")
    assert q["length_mm"].ci95 == pytest.approx((25 - 4.3027 / 3**0.5, 25 + 4.3027 / 3**0.5), abs=1e-3)
    assert q["diameter_mm"].value == 11.0 and q["mass_g"].value == pytest.approx(2.0)
    assert q["mass_g"].sd == pytest.approx(0.4)
    assert q["length_mm"].extra["min"] == 24.0 and q["length_mm"].extra["max"] == 26.0
    # displacement: 10/11, 12/13, 11/12 g/ml
    assert q["particle_density_kg_m3"].value == pytest.approx(1e3 * (10 / 11 + 12 / 13 + 11 / 12) / 3)
    # envelope: m / (pi d^2 L / 4) per specimen
    env = [1.6e-3 / (math.pi * 0.010**2 * 0.024 / 4), 2.0e-3 / (math.pi * 0.011**2 * 0.025 / 4),
           2.4e-3 / (math.pi * 0.012**2 * 0.026 / 4)]
    assert q["envelope_density_kg_m3"].value == pytest.approx(np.mean(env))
    # drops: sqrt(49/400), sqrt(36/400), sqrt(18/200), sqrt(24.5/200) and the track (e = 0.4)
    steel = q["restitution.particle-steel"]
    assert steel.value == pytest.approx((0.35 + 0.30 + 0.30 + 0.35 + 0.40) / 5, abs=1e-6)
    assert steel.n == 5 and steel.rows_used == [1, 2, 3, 4, 5]
    assert steel.extra["n_from_track"] == 1
    # regression over the four height drops: means 42.5 and 21.25 mm at 400 and 200 mm -> B 0.10625
    reg = steel.extra["height_regression"]
    assert reg["slope"] == pytest.approx(0.10625) and reg["e"] == pytest.approx(0.10625**0.5)
    assert reg["rows"] == [1, 2, 3, 4]
    pp = q["restitution.particle-particle"]
    assert (pp.value, pp.rows_used) == (pytest.approx(0.35), [6, 7])
    assert q["static_friction.particle"].value == pytest.approx((T(R(33)) + T(R(34)) + T(R(32))) / 3)
    assert q["static_friction.steel"].value == pytest.approx((T(R(11)) + T(R(12))) / 2)
    assert q["rolling_friction.particle"].value == pytest.approx((T(R(28)) + T(R(27))) / 2)
    s, c = math.sin(R(30)), math.cos(R(30))
    rollout = [50 * s / (50 * c + 150 * s), 50 * s / (50 * c + 200 * s)]
    assert q["rolling_friction.steel"].value == pytest.approx(np.mean(rollout))
    assert q["rolling_friction.steel"].rows_used == [8, 9]
    # Poisson: 0.5, 0.18, 0.1515; eq. (1): 0.5, 0.15, 0.0667
    nu = (0.5 + 0.18 + (0.2 / 11) / 0.12) / 3
    assert q["poisson_ratio"].value == pytest.approx(nu)
    assert q["poisson_ratio"].extra["eq1"]["value"] == pytest.approx((0.5 + 0.15 + 0.2 / 3) / 3)
    # E: radial 2e5 N/m x 11 mm / (11 x 24 mm^2); axial 1e5 N/m x 25 mm / (pi 11^2 / 4 mm^2)
    E = [2e5 * 0.011 / (0.011 * 0.024), 1e5 * 0.025 / (math.pi * 0.011**2 / 4)]
    assert q["elastic_modulus_pa"].value == pytest.approx(np.mean(E))
    assert q["elastic_modulus_pa"].rows_used == [1, 3]
    assert q["shear_modulus_pa"].value == pytest.approx(np.mean(E) / (2 * (1 + nu)))
    rep = q["repose_angle_deg"]
    assert (rep.value, rep.n, rep.unit) == (35.0, 2, "deg")
    assert rep.extra["manual_comparison"]["mean_photo_minus_manual_deg"] == pytest.approx(-0.5)
    assert rep.extra["flank_mean_deg"] == {"left": 34.0, "right": 35.0}



def test_rebounds_that_do_not_grow_with_height_keep_their_per_drop_values(campaign):
    # 200 mm drops rebound 45 and 50 mm, higher than the 400 mm ones (49, 36): the height
    # regression has a negative slope; the per-drop values still stand, the regression says why not
    def edit(sheets):
        sheets["drop"][2]["rebound_height_mm"] = 45
        sheets["drop"][3]["rebound_height_mm"] = 50
    steel = run(campaign(edit)).quantities["restitution.particle-steel"]
    assert steel.value == pytest.approx((0.35 + 0.30 + (45 / 200) ** 0.5 + (50 / 200) ** 0.5 + 0.40) / 5,
                                        abs=1e-6)
    reg = steel.extra["height_regression"]
    assert reg["rows"] == [1, 2, 3, 4] and "does not grow with drop height" in reg["unavailable"]

def test_sources_name_sheet_file_and_hash(campaign, fmt):
    path = campaign()
    m = run(path)
    src = m.quantities["restitution.particle-steel"].source
    assert src["sheet"] == "drop"
    assert src["file"] == str(path if fmt == "xlsx" else path / "drop.csv")
    assert src["sha256"] == m.workbook["files"][src["file"]]
    assert m.provenance.inputs == m.workbook["files"]
    assert m.workbook["unknown_sheets"] == ["notes"]


def test_json_layout(campaign, tmp_path):
    m = run(campaign())
    out = write_json(tmp_path / "m.json", m.to_dict())
    d = read_json(out)
    assert d["material"] == "test segments"
    assert d["unknown_sheets"] == ["notes"]
    for name, qd in d["quantities"].items():
        assert {"value", "sd", "n", "ci95", "unit", "rows_used", "rows_rejected", "source"} <= set(qd)
        assert len(qd["ci95"]) == 2 and set(qd["source"]) == {"file", "sheet", "sha256"}
    again = Measurement.from_dict(d)
    assert again.quantities["poisson_ratio"] == m.quantities["poisson_ratio"]
    assert again.quantities["repose_angle_deg"].per_row == json.loads(
        json.dumps(m.to_dict()["per_row"]["repose_angle_deg"]))


def test_per_row_values_carry_covariates(campaign):
    m = run(campaign())
    rows = m.to_dict()["per_row"]
    drop = rows["restitution.particle-steel"]
    assert [r["row"] for r in drop] == [1, 2, 3, 4, 5]
    assert drop[1]["value"] == pytest.approx(0.3) and drop[1]["method"] == "heights"
    assert drop[1]["covariates"] == {"specimen_id": "S2", "date": "2024-05-01", "operator": "ben",
                                     "orientation_deg": 45.0, "trial_order": 2.0}
    assert drop[4]["method"] == "track" and drop[4]["e_heights"] == pytest.approx(0.3)
    incline = rows["rolling_friction.steel"]
    assert incline[0]["method"] == "rollout" and incline[1]["covariates"] == {"moisture_pct": 12.0}
    assert rows["static_friction.particle"][2]["angle_rad"] == pytest.approx(R(32))
    assert rows["length_mm"][2]["covariates"] == {"moisture_pct": 11.0, "batch": "B"}


def test_track_row_uses_the_track_not_the_heights(campaign):
    m = run(campaign(lambda s: s["drop"][4].__setitem__("rebound_height_mm", 3.0)))
    rec = m.quantities["restitution.particle-steel"].per_row[4]
    assert rec["value"] == pytest.approx(0.4, abs=1e-6)
    assert rec["e_heights"] == pytest.approx(0.1)
    assert "track" in m.quantities["restitution.particle-steel"].method


def test_outlier_rejected_visibly(campaign):
    def edit(s):
        extra = [(400, 36), (400, 51.84), (400, 43.56), (400, 57.76), (400, 256)]  # e .30 .36 .33 .38 .80
        for i, (h1, h2) in enumerate(extra):
            s["drop"].append({"trial_id": f"X{i}", "pair": "particle-particle", "drop_height_mm": h1,
                              "rebound_height_mm": h2, "operator": "ana"})
    est = run(campaign(edit), outliers="mad").quantities["restitution.particle-particle"]
    assert est.rows_rejected == [{"row": 12, "reason": est.rows_rejected[0]["reason"]}]
    assert "outlier" in est.rows_rejected[0]["reason"] and 12 not in est.rows_used
    assert est.n == 6
    none = run(campaign(edit)).quantities["restitution.particle-particle"]  # default: no screening
    assert none.n == 7 and none.rows_rejected == []
    grubbs = run(campaign(edit), outliers="grubbs").quantities["restitution.particle-particle"]
    assert [r["row"] for r in grubbs.rows_rejected] == [12] and "Grubbs" in grubbs.rows_rejected[0]["reason"]


def test_target_repose_overrides_photos(campaign):
    def edit(s):
        s["meta"]["target_repose_deg"] = 35.79
    m = run(campaign(edit))
    rep = m.quantities["repose_angle_deg"]
    assert rep.value == 35.79 and rep.extra["override"] is True
    assert rep.extra["photo_estimate"]["value"] == 35.0
    assert rep.source["sheet"] == "meta" and rep.rows_used == [13]
    assert any("overrides" in n for n in m.notes)
    assert "(override)" in m.table()


def test_photo_estimator_gets_side_annotation_path_and_pixel_limit(campaign, tmp_path):
    stub = stub_photo_estimator(PHOTOS)
    run(campaign(), photo_estimator=stub, annotate_dir=tmp_path / "ann")
    assert [c["side"] for c in stub.calls] == ["both", "left"]
    assert [c["path"].name for c in stub.calls] == ["p1.png", "p2.png"]
    assert stub.calls[0]["annotate_to"] == tmp_path / "ann" / "P1_annotated.png"
    assert [c["max_pixels"] for c in stub.calls] == [MAX_PHOTO_PIXELS] * 2
    stub = stub_photo_estimator(PHOTOS)
    run(campaign(), ReadOptions(max_photo_pixels=12_345), photo_estimator=stub)
    assert [c["max_pixels"] for c in stub.calls] == [12_345] * 2


def test_annotated_photo_names_are_unique(campaign, tmp_path):
    """Ids that make the same file name (a/b and a_b; A and a on a case-insensitive file
    system) get their row number; the report finds each by the name recorded."""
    def edit(s):
        s["repose"] = [dict(s["repose"][0], photo_id="a/b"), dict(s["repose"][1], photo_id="a_b"),
                       dict(s["repose"][0], photo_id="P1", file="photos/p3.png"),
                       dict(s["repose"][1], photo_id="Q", file="photos/p4.png"),
                       dict(s["repose"][1], photo_id="q", file="photos/p5.png")]
    root = campaign(edit)
    photos = (root.parent if root.is_file() else root) / "photos"
    for name in ("p3.png", "p4.png", "p5.png"):
        (photos / name).write_bytes((photos / "p1.png").read_bytes())
    stub = stub_photo_estimator(dict(PHOTOS, **{"p3.png": 35.0, "p4.png": 35.0, "p5.png": 35.0}))
    m = run(root, photo_estimator=stub, annotate_dir=tmp_path / "ann")
    names = [c["annotate_to"].name for c in stub.calls]
    assert names == ["a_b@row1_annotated.png", "a_b@row2_annotated.png", "P1_annotated.png",
                     "Q@row4_annotated.png", "q@row5_annotated.png"]
    assert [Path(r["annotated"]).name for r in m.quantities["repose_angle_deg"].per_row] == names


def test_no_photo_estimator_is_a_note(campaign, monkeypatch):
    monkeypatch.setattr(pipeline, "_default_photo_estimator", lambda: None)
    m = measure_workbook(read_workbook(campaign()))
    assert "repose_angle_deg" not in m.quantities
    assert any("repose photos not measured" in n for n in m.notes)


def test_photo_estimator_error_names_the_row(campaign, fmt):
    def broken(path, side="both", annotate_to=None, max_pixels=None):
        raise InputError("no heap found")
    with pytest.raises(WorkbookError) as info:
        run(campaign(), photo_estimator=broken)
    assert (info.value.sheet, info.value.row, info.value.column) == ("repose", 1, "file")
    assert "no heap found" in str(info.value)


def test_track_without_rebound_names_the_row(campaign):
    import pandas as pd
    flat = pd.DataFrame({"t_s": np.arange(50) * 0.01, "y_mm": np.r_[300 - 0.5 * 9810 * (np.arange(25) * 0.01) ** 2,
                                                                     np.zeros(25)]})
    with pytest.raises(WorkbookError) as info:
        run(campaign(tracks={"t5.csv": flat}))
    assert (info.value.sheet, info.value.row, info.value.column) == ("drop", 5, "track_file")
    assert "no rebound" in str(info.value) and "t5.csv" in str(info.value)


def test_curve_without_linear_part_names_the_row(campaign):
    import pandas as pd
    d = np.linspace(0, 1, 40)
    wavy = pd.DataFrame({"displacement_mm": d, "force_N": 20 * d + 3 * np.sin(25 * d)})
    with pytest.raises(WorkbookError) as info:
        run(campaign(curves={"c1.csv": wavy, "c3.csv": curve_frame(100.0, 0.5)}), r2_min=0.999)
    assert (info.value.sheet, info.value.row, info.value.column) == ("compression", 1, "curve_file")
    assert "linear" in str(info.value)


def test_radial_curve_needs_a_segment_length(campaign):
    def edit(s):
        s["compression"][0]["specimen_id"] = "S9"
    with pytest.raises(WorkbookError) as info:
        run(campaign(edit))
    assert (info.value.sheet, info.value.row, info.value.column) == ("compression", 1, "specimen_id")
    # a length_mm column on the compression row is used instead
    def with_length(s):
        edit(s)
        s["compression"][0]["length_mm"] = 24.0
    m = run(campaign(with_length))
    assert m.quantities["elastic_modulus_pa"].per_row[0]["length_m"] == pytest.approx(0.024)


def test_minimal_workbook(campaign):
    def edit(s):
        for k in ("density", "drop", "incline", "compression", "repose", "notes"):
            s.pop(k)
    m = run(campaign(edit))
    assert list(m.quantities) == ["length_mm", "diameter_mm", "mass_g", "envelope_density_kg_m3"]
    assert m.notes == []
