"""``demcal measure`` on the command line."""

from __future__ import annotations

import subprocess
import sys

import demcal.measure.pipeline as pipeline
from demcal.cli import main
from demcal.jsonio import read_json
from tests.measure.conftest import stub_photo_estimator


def test_measure_writes_json_and_prints_a_table(campaign, tmp_path, capsys, monkeypatch):
    stub = stub_photo_estimator({"p1.png": 34.0, "p2.png": 36.0})
    monkeypatch.setattr(pipeline, "_default_photo_estimator", lambda: stub)
    out = tmp_path / "out" / "measure.json"
    assert main(["measure", str(campaign()), "--json", str(out)]) == 0
    d = read_json(out)
    assert d["quantities"]["restitution.particle-steel"]["value"] == pytest_approx(0.34)
    printed = capsys.readouterr()
    assert "restitution.particle-steel" in printed.out and "repose_angle_deg" in printed.out
    assert "unknown sheets kept" in printed.err
    # annotated photos default to a folder beside OUT
    assert stub.calls[0]["annotate_to"].parent == out.parent / "measure_annotated"


def pytest_approx(x):
    import pytest
    return pytest.approx(x, abs=1e-6)


def test_outlier_option_reaches_every_quantity(campaign, tmp_path, monkeypatch):
    monkeypatch.setattr(pipeline, "_default_photo_estimator",
                        lambda: stub_photo_estimator({"p1.png": 34.0, "p2.png": 36.0}))

    def edit(s):
        for i, h2 in enumerate((36, 51.84, 43.56, 57.76, 256)):  # e .30 .36 .33 .38 .80
            s["drop"].append({"trial_id": f"X{i}", "pair": "particle-particle", "drop_height_mm": 400,
                              "rebound_height_mm": h2})
    path = campaign(edit)
    out = tmp_path / "m.json"
    assert main(["measure", str(path), "--json", str(out), "--outliers", "mad:3.5"]) == 0
    q = read_json(out)["quantities"]["restitution.particle-particle"]
    assert [r["row"] for r in q["rows_rejected"]] == [12] and q["extra"]["outlier_rule"] == "mad:3.5"
    assert read_json(out)["provenance"]["options"]["outliers"] == "mad:3.5"


def test_bad_workbook_exit_code_2_message_no_traceback(campaign, fmt):
    path = campaign(lambda s: s["drop"][2].__setitem__("rebound_height_mm", 250))
    proc = subprocess.run([sys.executable, "-m", "demcal.cli", "measure", str(path)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1
    expected_file = path if fmt == "xlsx" else path / "drop.csv"
    assert f"file {expected_file}" in lines[0]
    assert "sheet 'drop'" in lines[0] and "row 3" in lines[0] and "column 'rebound_height_mm'" in lines[0]


def test_bad_options_exit_code_2(campaign, capsys):
    assert main(["measure", str(campaign()), "--outliers", "median"]) == 2
    assert "unknown outlier rule" in capsys.readouterr().err
    assert main(["measure", "/nonexistent/workbook.xlsx"]) == 2
