"""Small exact cases of the report's helpers: cell comparison of the audit, cell formatting,
row ranges, the stored-polynomial evaluator of the contour plots."""

import math

import numpy as np
import pytest

from demcal.report.audit import compare_tables
from demcal.report.figures import polynomial
from demcal.report.render import format_cell
from demcal.report.tables import Table, row_ranges


def _table(rows):
    return Table("9a", "Fit", ("Statistic", "Ours"), ("", ""), tuple(rows)).to_dict()


def test_compare_tables_float_tolerance_and_exact_text():
    stored = _table([("R²", 0.9717), ("n", 17), ("note", "ok")])
    assert compare_tables(stored, _table([("R²", 0.9717 * (1 + 5e-10)), ("n", 17), ("note", "ok")])) == []
    diffs = compare_tables(stored, _table([("R²", 0.9717 * (1 + 2e-9)), ("n", 18), ("note", "OK")]))
    assert [(d.row, d.row_label, d.column) for d in diffs] == [(1, "R²", "Ours"), (2, "n", "Ours"),
                                                               (3, "note", "Ours")]
    assert diffs[1].stored == 17 and diffs[1].derived == 18
    # numerical zeros (a term the design cannot see) compare equal
    assert compare_tables(_table([("AC", 3.3e-16)]), _table([("AC", -2.8e-16)])) == []
    # a missing row is reported
    diffs = compare_tables(stored, _table([("R²", 0.9717), ("n", 17)]))
    assert diffs[0].row_label == "number of rows" and (diffs[0].stored, diffs[0].derived) == (3, 2)


def test_format_cell_design_expert_conventions():
    assert format_cell(3.5e-8, "p") == "&lt; 0.0001"
    assert format_cell(0.01872744910472106, "p") == "0.0187"
    assert format_cell(1, "coded") == "+1" and format_cell(-1, "coded") == "-1" and format_cell(0, "coded") == "0"
    assert format_cell(23572885.3, ".4g") == "2.357×10<sup>7</sup>"
    assert format_cell(None, ".4g") == "–" and format_cell(math.nan, ".4g") == "–"
    assert format_cell([0.2, 0.3], ".3g") == "[0.2, 0.3]"
    assert format_cell("a<b") == "a&lt;b"


def test_row_ranges():
    assert row_ranges([5, 1, 2, 3, 7, 8]) == "1-3, 5, 7-8"
    assert row_ranges([]) == ""


def test_polynomial_evaluates_design_expert_terms():
    coef = {"Intercept": 35.65, "A": -0.5775, "B": -0.66, "C": 0.22, "AB": 2.45, "AC": -0.4925,
            "BC": 1.41, "A^2": 0.7408, "B^2": 0.6557, "C^2": -1.11}
    x = {"A": np.array([0.0, 1.0]), "B": np.array([0.0, -1.0]), "C": np.array([0.0, 0.5])}
    # hand calculation at (1, -1, 0.5): 35.65 - 0.5775 + 0.66 + 0.11 - 2.45 - 0.24625 - 0.705
    #                                   + 0.7408 + 0.6557 - 0.2775
    expected = 35.65 - 0.5775 + 0.66 + 0.11 - 2.45 - 0.24625 - 0.705 + 0.7408 + 0.6557 - 0.2775
    assert polynomial(coef, x) == pytest.approx([35.65, expected], rel=1e-12)


def test_heap_profile_reads_both_record_layouts():
    from demcal.report.figures import heap_profile

    standin = {"result": {"record": {"profile": {"x": [0.0, 0.1, 0.2], "z": [0.08, 0.08, 0.0]}}}}
    rig = {"result": {"record": {"profile_x": [0.0, 0.1, 0.2, 0.3], "profile_z": [0.05, float("nan"), 0.02, 0.0],
                                 "geometry": {"box_length": 0.12}}}}
    a, b = heap_profile(standin), heap_profile(rig)
    assert a["x"].tolist() == [0.0, 0.1, 0.2] and a["plate_x"] is None
    assert b["x"].tolist() == [0.0, 0.2, 0.3] and b["z"].tolist() == [0.05, 0.02, 0.0]
    assert b["plate_x"] == 0.12
    assert heap_profile({"result": {"record": {}}}) is None


def test_covariate_tests_table_sorts_by_adjusted_p_and_keeps_every_test():
    from demcal.analyse.critique.loop import Critique
    from demcal.report.tables import Campaign, table_covariate_tests

    def t(series, p, p_adj, **kw):
        return {"series": series, "sheet": "drop", "source": "measured", "covariate": "drop_height_mm",
                "method": "trend", "n": 10, "effect": 0.1, "ci95": [0.0, 0.2], "effect_unit": "1/mm",
                "span": 300.0, "practical": 0.05, "threshold": 0.03, "p_value": p, "p_adjusted": p_adj, **kw}

    tests = [t("a", 0.2, 0.4), t("b", None, None), t("c", 0.001, 0.004, significant=True, relevant=True,
                                                      ci_selected=[0.01, 0.3]),
             t("d", 0.1, 0.4, level="specimen")]
    critique = Critique.from_dict({"discrepancies": [], "findings": [], "tests": tests,
                                   "provenance": {"options": {"alpha": 0.01, "correction": "bh"}}})
    c = Campaign(measurement={}, results=None, critique=critique,
                 critique_source={"file": "critique.json", "sha256": "00"})
    table = table_covariate_tests(c)
    # adjusted p, then raw p, then list order; a test without p-values last, none dropped
    assert [(r[0], r[1], r[-1]) for r in table.rows] == [(3, "c", "significant: cause"), (4, "d", "not significant"),
                                                         (1, "a", "not significant"), (2, "b", "not significant")]
    assert "Test 3: interval after selection (false-coverage rate, Benjamini & Yekutieli 2005) " \
           "[0.01, 0.3] 1/mm." in table.notes
    assert [r[6] for r in table.rows] == ["trial", "specimen", "trial", "trial"]   # the unit of each test
    assert table.notes[0].startswith("Sorted by adjusted p-value (Benjamini-Hochberg within each tier; share of "
                                     "the level: primary 0.8, follow-up 0.2)")
    assert table.sources == ({"kind": "critique", "file": "critique.json", "sha256": "00", "path": "tests"},)
    empty = table_covariate_tests(Campaign(measurement={}, results=None, critique=None))
    assert empty.rows == () and "None: critique.json holds no covariate tests." in empty.notes


def test_critique_text_states_direct_use_and_each_summary_sentence_once():
    from demcal.analyse.critique.loop import Critique
    from demcal.report.render import critique_text

    def critique(**parts):
        return Critique.from_dict({"discrepancies": [], "findings": [], **parts})

    drop = {"observable": "restitution.particle-particle (drop twin, apparent sqrt(h2/h1))", "measured": 0.3,
            "measured_ci95": [0.28, 0.32], "simulated": 0.29, "simulated_ci95": [0.27, 0.31], "difference": 0.01,
            "combined_u95": 0.02, "exceeds": False, "n_measured": 8, "n_simulated": 8,
            "note": "contact e_pp = 0.3; twin apparent / contact = 0.967: whether sqrt(h2/h1) may feed the DEM "
                    "directly is undetermined with these drops"}
    ext = {"name": "velocity_dependent_restitution", "mechanism": "velocity_dependent_restitution",
           "measure": "rms_residual", "quantity": "restitution.particle-particle", "held_out": "4 drops",
           "before": 0.02, "before_ci95": [0.01, 0.03], "after": 0.019, "after_ci95": [0.01, 0.028],
           "gain": 0.001, "ci95": [-0.004, 0.006], "n_held_out": 4}
    summary = ["restitution.particle-particle: the lab's sqrt(h2/h1) is 0.3; ... undetermined ...",
               "Found: velocity_dependent_restitution."]
    text = critique_text(critique(discrepancies=[{"sheet": "drop", **drop}], extension_records=[ext],
                                  summary=summary))
    (d,) = text["direct"]
    assert d["headline"] == (
        "restitution.particle-particle: whether sqrt(h2/h1) may feed the DEM directly is undetermined. The lab's "
        "drops give sqrt(h2/h1) = 0.3 [0.28, 0.32] (n 8); the drop twin rebounds with an apparent 0.29 "
        "[0.27, 0.31] (n 8): measured minus twin 0.01, within its 95 % uncertainty ±0.02 (Table C1).")
    # the extension the summary does not state is stated from its Table C3 row
    assert d["paragraphs"] == [summary[0], "Extension velocity_dependent_restitution "
                               "(velocity_dependent_restitution): rms_residual of restitution.particle-particle "
                               "on 4 drops 0.02 before, 0.019 after, gain 0.001 [-0.004, 0.006]: no clear gain "
                               "(Table C3)."]
    assert text["summary"] == [summary[1]]
    assert critique_text(critique(summary=summary)) == {"direct": [], "summary": summary}
    assert critique_text(None) == {"direct": [], "summary": []}


def test_annotated_photos_are_found_in_a_moved_campaign_folder(tmp_path):
    """measure.json records the annotated photo's path as the campaign saw it (relative to where
    it ran); a copied folder, or an audit run from elsewhere, finds it in DIR/annotated."""
    from demcal.report.figures import annotated_photos

    (tmp_path / "annotated").mkdir()
    (tmp_path / "annotated" / "heap_1_annotated.png").write_bytes(b"png")
    rows = [{"id": "heap_1", "annotated": "out/astragalus/annotated/heap_1_annotated.png"},
            {"id": "heap_2", "annotated": "out/astragalus/annotated/heap_2_annotated.png"}, {"id": "heap_3"}]
    m = {"per_row": {"repose_angle_deg": rows}}
    assert annotated_photos(m, tmp_path) == [(rows[0], tmp_path / "annotated" / "heap_1_annotated.png")]
    assert annotated_photos(m, None) == []


def test_runs_csv_cells_are_one_line_and_never_formulas():
    from demcal.report.runs_csv import csv_cell

    for text in ("=HYPERLINK(\"http://x\")", "+1", "-1", "@SUM(A1)"):
        assert csv_cell(text) == "'" + text
    assert csv_cell(" \t=1+1") == "'=1+1"                    # leading blanks hide no formula
    assert csv_cell("line 1\nline 2\r\n\u2028end") == "line 1 line 2 end"
    assert csv_cell("drop twins, e_pp") == "drop twins, e_pp"
    # numbers are numbers (a negative one is not a formula), written back exactly
    assert csv_cell(-1.5) == "-1.5" and csv_cell(0.1 + 0.2) == "0.30000000000000004" and csv_cell(7) == "7"
    assert csv_cell(None) == "" and csv_cell(True) == "true"


def test_photo_labels_are_one_line_drawn_as_typed(tmp_path, monkeypatch):
    """Photo ids reach the figure as typed, on one line, never parsed as mathtext ("$\\frac$"
    and "$$" are not formulas)."""
    from matplotlib.image import imsave

    from demcal.report import figures

    image = tmp_path / "photo.png"
    imsave(image, np.zeros((4, 6)))
    labels = {"heap\n$\\frac$ 1": "heap $\\frac$ 1", "$$": "$$", "a$b$c$": "a$b$c$",
              "{{ x }}\r\n{% raw %}\t<script>": "{{ x }} {% raw %} <script>", "x" * 50: "x" * 39 + "…"}
    rows = [{"id": i, "value": 33.0, "flanks": {"left": 33.0}, "annotated": str(image)} for i in labels]
    drawn = []
    save = figures._save
    monkeypatch.setattr(figures, "_save", lambda fig, *args: drawn.append(fig) or save(fig, *args))
    assert figures.heap_photos({"per_row": {"repose_angle_deg": rows}}, tmp_path / "photos.png").is_file()
    titles = [ax.title for ax in drawn[0].axes if ax.get_title()]
    assert [t.get_text() for t in titles] == [f"{label}: 33.00°\nleft 33.00°" for label in labels.values()]
    assert not any(t.get_parse_math() for t in titles)


def test_particle_noun_and_labels_follow_the_workbooks_shape():
    from demcal.report.tables import parameter_label, particle_noun, quantity_label

    assert particle_noun({}) == particle_noun({"shape": {}}) == "segment"  # stored before shapes
    assert particle_noun({"shape": {"shape": "segment", "length_m": 0.025}}, plural=True) == "segments"
    assert particle_noun({"shape": {"shape": "kernel"}}, plural=True) == "kernels"
    assert particle_noun({"shape": {"shape": "sphere"}}) == particle_noun({"shape": {"shape": "clump"}}) == "particle"
    # the segment's wording is the one stored tables carry
    assert parameter_label("e_pw", "steel") == ("Restitution coefficient, segment-steel", "e_pw")
    assert quantity_label("static_friction.particle") == "Static friction coefficient, segment-segment"
    assert parameter_label("mu_s_pp", "steel", "kernel")[0] == "Static friction coefficient, kernel-kernel"
    assert quantity_label("restitution.particle-rubber", "particle") == "Restitution coefficient, particle-rubber"
    assert quantity_label("mass_g", "kernel") == "Mass of one kernel"


def test_table_1_has_a_row_per_calliper_quantity_of_the_shape():
    from demcal.report.tables import Campaign, table_dimensions, table_physical

    def size(value):
        return {"n": 3, "value": value, "sd": 0.1, "ci95": [value - 0.2, value + 0.2], "unit": "mm",
                "extra": {"min": value - 0.1, "max": value + 0.1}, "source": {"sheet": "specimens"},
                "rows_used": [1, 2, 3]}

    kernel = {"material": "Wheat kernels", "shape": {"shape": "kernel"},
              "quantities": {"thickness_mm": size(2.8), "length_mm": size(6.2), "width_mm": size(3.3),
                             "mass_g": {**size(0.04), "unit": "g"}}}
    c = Campaign(measurement=kernel, results=None, paper={"material": "Astragalus membranaceus",
                                                           "segment": {"length_mm": 25.0}})
    t1 = table_dimensions(c)
    assert t1.title == "External dimensions of the kernels"
    assert [r[:2] for r in t1.rows] == [("Length", "L"), ("Width", "W"), ("Thickness", "T")]
    assert [r[-1] for r in t1.rows] == [None, None, None]
    assert [r[0] for r in table_physical(c).rows] == ["Mass of one kernel"]
