"""Small exact cases of the report's helpers: cell comparison of the audit, cell formatting,
row ranges, the stored-polynomial evaluator of the contour plots."""

import math

import numpy as np
import pytest

from report.audit import compare_tables
from report.figures import polynomial
from report.render import format_cell
from report.tables import Table, row_ranges


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
    from report.figures import heap_profile

    standin = {"result": {"record": {"profile": {"x": [0.0, 0.1, 0.2], "z": [0.08, 0.08, 0.0]}}}}
    rig = {"result": {"record": {"profile_x": [0.0, 0.1, 0.2, 0.3], "profile_z": [0.05, float("nan"), 0.02, 0.0],
                                 "geometry": {"box_length": 0.12}}}}
    a, b = heap_profile(standin), heap_profile(rig)
    assert a["x"].tolist() == [0.0, 0.1, 0.2] and a["plate_x"] is None
    assert b["x"].tolist() == [0.0, 0.2, 0.3] and b["z"].tolist() == [0.05, 0.02, 0.0]
    assert b["plate_x"] == 0.12
    assert heap_profile({"result": {"record": {}}}) is None
