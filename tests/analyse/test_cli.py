"""``demcal analyse pb|bbd``: JSON layout, level coding, workbook input and located errors."""

import json

import numpy as np
import pandas as pd
import pytest

from demcal.cli import main
from tests.analyse.conftest import EXTERNAL

FIT_KEYS = {"std_dev", "mean", "cv_pct", "r2", "adj_r2", "pred_r2", "press", "adeq_precision"}


def run(args):
    return main(["analyse", *map(str, args)])


def needs(relpath):
    path = EXTERNAL / relpath
    if not path.exists():
        pytest.skip(f"reference data not found: {path}")
    return path


def test_pb_json(tmp_path, capsys):
    table = needs("screening_pb/bm93_ex1_reactor_pb12.csv")
    out = tmp_path / "pb.json"
    assert run(["pb", table, "--factors", "A,B,C,D,E", "--response", "y", "--json", out]) == 0
    d = json.loads(out.read_text())
    assert list(d["coefficients"]) == ["Intercept", "A", "B", "C", "D", "E"]
    assert [r["source"] for r in d["anova"]] == ["Model", "A", "B", "C", "D", "E", "Residual",
                                                 "Cor Total"]
    assert set(d["anova"][0]) >= {"source", "ss", "df", "ms", "f", "p"}
    assert FIT_KEYS <= set(d["fit"])
    assert d["effects"]["B"] == pytest.approx(127 / 6 * 1, rel=1e-12)  # 21.1667: by hand
    assert d["significant"] == ["B"] and d["stationary_point"] is None
    assert isinstance(d["equation_actual"], str)
    assert d["provenance"]["inputs"][str(table)]
    assert "significant at 0.05: B" in capsys.readouterr().out


def test_pb_actual_levels_coded_from_table_range(tmp_path):
    # The paper's seven contact parameters at their measured min/max (PB coding -1/+1).
    design = pd.read_csv(needs("screening_pb/pb12_design_matrix_bhh.csv")).iloc[:, 1:8]
    low = np.array([0.20, 0.2, 0.62, 0.50, 0.30, 0.1, 0.10])
    high = np.array([0.30, 0.4, 0.68, 0.56, 0.40, 0.3, 0.20])
    names = ["poisson", "e_pp", "mus_pp", "mur_pp", "e_ps", "mus_ps", "mur_ps"]
    x = design.to_numpy(float)
    actual = (low + high) / 2 + x * (high - low) / 2
    y = 35 - 1.5 * x[:, 1] - 1.0 * x[:, 4] + 2.0 * x[:, 5] + 0.1 * np.sin(np.arange(12))
    frame = pd.DataFrame(actual, columns=names).assign(angle_deg=y)
    table = tmp_path / "pb_actual.csv"
    frame.to_csv(table, index=False)
    out = tmp_path / "pb.json"
    assert run(["pb", table, "--factors", ",".join(names), "--response", "angle_deg",
                "--levels", "actual", "--json", out]) == 0
    d = json.loads(out.read_text())
    assert d["low"] == pytest.approx(dict(zip(names, low)))
    assert d["effects"]["B"] == pytest.approx(-3.0, abs=0.2)
    assert d["ranking"][:3] == ["F", "B", "E"]
    assert set(d["significant"]) == {"B", "E", "F"}
    assert "e_pp" in d["equation_actual"]


def test_bbd_blocked_json_with_target(tmp_path):
    table = needs("rsm_reference/chemreact_myers2009_table7_6.csv")
    out = tmp_path / "bbd.json"
    rc = run(["bbd", table, "--factors", "Time,Temp", "--response", "Yield", "--block", "Block",
              "--levels", "actual", "--low", "80,170", "--high", "90,180", "--json", out,
              "--target", "82", "--reference", "85,175"])
    assert rc == 0
    d = json.loads(out.read_text())
    assert list(d["coefficients"]) == ["Intercept", "A", "B", "AB", "A^2", "B^2"]
    sources = [r["source"] for r in d["anova"]]
    assert sources == ["Block", "Model", "A", "B", "AB", "A^2", "B^2", "Residual", "Lack of Fit",
                       "Pure Error", "Cor Total"]
    lof = d["anova"][sources.index("Lack of Fit")]
    assert lof["p"] == pytest.approx(0.6851, abs=5e-5)  # published (rsm vignette)
    assert d["stationary_point"]["actual"]["Time"] == pytest.approx(86.86148, abs=5e-5)
    assert d["canonical"]["verdict"] == "maximum"
    t = d["target_optimisation"]
    assert t["reached"] and t["preferred"]["predicted"] == pytest.approx(82.0, abs=1e-5)
    assert set(t["preferred"]["actual"]) == {"Time", "Temp"}


def test_bbd_reads_xlsx_sheet(tmp_path):
    frame = pd.read_csv(needs("rsm_reference/zhang2021_scirep_bbd17_essential_oil.csv"))
    book = tmp_path / "runs.xlsx"
    with pd.ExcelWriter(book) as w:
        pd.DataFrame({"note": ["other sheet"]}).to_excel(w, sheet_name="meta", index=False)
        frame.to_excel(w, sheet_name="bbd", index=False)
    out = tmp_path / "z.json"
    assert run(["bbd", book, "--sheet", "bbd", "--factors", "R_mL_per_g,t_min,P_W",
                "--response", "Y_yield_pct", "--levels", "actual", "--json", out]) == 0
    d = json.loads(out.read_text())
    sp = d["stationary_point"]["actual"]
    assert sp["R_mL_per_g"] == pytest.approx(52, abs=2) and sp["P_W"] == pytest.approx(435, abs=2)
    assert d["high"] == {"R_mL_per_g": 60, "t_min": 30, "P_W": 500}


def test_errors_name_file_row_and_column(tmp_path, capsys):
    table = tmp_path / "runs.csv"
    table.write_text("A,B,C,y\n-1,-1,0,1.0\n1,oops,0,2.0\n1,1,0,3.0\n")
    out = tmp_path / "x.json"
    assert run(["bbd", table, "--factors", "A,B,C", "--response", "y", "--json", out]) == 2
    err = capsys.readouterr().err
    assert f"file {table}" in err and "row 2" in err and "column 'B'" in err and "'oops'" in err
    assert run(["bbd", table, "--factors", "A,B,D", "--response", "y", "--json", out]) == 2
    err = capsys.readouterr().err
    assert "column 'D'" in err and "missing column" in err and "Traceback" not in err
    table.write_text("A,B,y\n-1,-1,1\n1,-1,2\n-1,1,3\n1,1,\n")
    assert run(["pb", table, "--factors", "A,B", "--response", "y", "--json", out]) == 2
    assert "row 4, column 'y': expected a finite number" in capsys.readouterr().err
    table.write_text("A,B,y\n-1,-1,1\n1,-1,2,7\n")
    assert run(["pb", table, "--factors", "A,B", "--response", "y", "--json", out]) == 2
    assert "cannot read the table" in capsys.readouterr().err
    table.write_text("A,B,y\n-1,-1,1\n1,-1,2\n-1,0.5,3\n1,1,4\n")
    assert run(["pb", table, "--factors", "A,B", "--response", "y", "--json", out]) == 2
    assert "run 3, column 2 holds 0.5" in capsys.readouterr().err
    assert run(["bbd", table, "--factors", "A,B", "--response", "y", "--json", out,
                "--levels", "actual", "--low", "1"]) == 2
    assert "--low and --high" in capsys.readouterr().err
    assert not out.exists()


def test_calibrate_passes_its_options_and_prints_the_validation(tmp_path, capsys, monkeypatch):
    """``demcal calibrate``: the options reach the campaign's settings, and the verdict printed
    is the stored validation's (the campaign itself is tested in test_campaign*.py)."""
    import demcal.analyse.campaign as campaign
    from pathlib import Path

    from demcal.analyse.results import CampaignResult, Validation
    from demcal.provenance import Provenance

    seen = {}

    def fake_calibrate(workbook, out, config, measurement=None):
        seen.update(workbook=Path(workbook), config=config, measurement=measurement)
        validation = Validation(settings={"mu_s_pw": 0.19}, verdict="undecided", tolerance_deg=1.0,
                                mean_deg=36.5, n_runs=3, ci95=(33.02, 39.99), target_deg=36.1,
                                detectable_bias_deg=4.2, responses=[], seeds=[], runs=[],
                                confirmation={"predicted": 36.2, "pi95": [33.1, 39.3], "target_inside": True})
        return CampaignResult(workflow=config.workflow, response={}, material="", target_angle_deg=36.1,
                              config={"replicates": config.replicates}, measurement={}, factors={},
                              base_parameters={}, geometry={}, validation=validation,
                              calibrated_parameters={}, stages=[], provenance=Provenance())

    monkeypatch.setattr(campaign, "calibrate", fake_calibrate)
    root = Path(__file__).resolve().parents[2] / "data" / "astragalus"
    rc = main(["calibrate", str(root), "--out", str(tmp_path), "--profile", "paper",
               "--replicates", "2", "--workers", "1", "--seed", "7", "--tolerance", "1.5",
               "--no-report"])
    assert rc == 0
    assert seen["workbook"].name == "workbook.xlsx"
    # the front door measured the workbook before handing it to the campaign
    assert "repose_angle_deg" in seen["measurement"].quantities
    cfg = seen["config"]
    assert (cfg.profile, cfg.workflow, cfg.replicates, cfg.workers, cfg.seed, cfg.tolerance) == \
        ("paper", "design-expert", 2, 1, 7, 1.5)
    out = capsys.readouterr().out
    assert "mu_s_pw = 0.19" in out and "design-expert workflow" in out
    assert "validation: undecided (tolerance 1.00 deg)" in out
    assert "95 % CI [33.02, 39.99]" in out and "smallest bias it would detect 4.20 deg" in out
    assert "95 % PI of the mean of 3 runs [33.10, 39.30]: the target lies inside" in out

    rc = main(["calibrate", str(root), "--out", str(tmp_path), "--budget", "40",
               "--validation-cap", "20", "--no-report"])
    assert rc == 0
    cfg = seen["config"]
    assert (cfg.profile, cfg.workflow, cfg.budget_runs, cfg.validation_cap, cfg.seed) == \
        ("quick", "plausible", 40, 20, 1)

    # model settings the user chooses reach every run; measured and calibrated parameters do not
    rc = main(["calibrate", str(root), "--out", str(tmp_path), "--no-report", "--set", "dt=5e-5",
               "--set", "rolling_lever=edem_com", "--set", "spheres_per_clump=7",
               "--set", "contact_effective_mass=true"])
    assert rc == 0
    assert seen["config"].model_extensions == {"dt": 5e-5, "rolling_lever": "edem_com", "spheres_per_clump": 7,
                                               "contact_effective_mass": True}
    capsys.readouterr()
    for item in ("segment_length_m=0.02", "e_pw=0.5"):
        assert main(["calibrate", str(root), "--out", str(tmp_path), "--no-report", "--set", item]) == 2
        err = capsys.readouterr().err
        assert "not a model setting; valid:" in err and "rolling_lever" in err and len(err.splitlines()) == 1
