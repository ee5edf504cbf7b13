"""An extra target (the heaps' crest height, off by default) joins the calibration beside the
angle: the stand-in's crest height reads the particle-particle restitution, which its angle
ignores, so the crest pins down what the angle cannot, by as much as the closed-form posterior
of a linear reading with a normal prior says."""

import hashlib
import json
import math
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from demcal.analyse.campaign import CampaignConfig, calibrate
from demcal.errors import InputError
from demcal.measure.pipeline import measure_workbook
from demcal.measure.workbook import write_workbook
from demcal.simulate.render import PHOTO_PX_PER_M
from tests.analyse.test_several_rigs import TRUTH, _normal_posterior_sd, _workbook, two_rig_runner

#: The stand-in's crest height rises CREST_SLOPE mm per unit of e_pp from the lab's mean at the truth.
CREST_SLOPE = 400.0
CREST_NOISE_MM = 1.0
LAB = {}


def crest_runner(inputs: dict) -> dict:
    """``two_rig_runner``'s heaps, with a crest height [m] linear in e_pp plus fresh noise."""
    out = two_rig_runner(inputs)
    if inputs.get("rig", "repose") == "repose":
        rng = np.random.default_rng(int.from_bytes(hashlib.sha256(json.dumps([inputs, "crest"], sort_keys=True)
                                                                  .encode()).digest()[:8], "little"))
        mm = LAB["crest_mm"] + CREST_SLOPE * (inputs["params"]["e_pp"] - TRUTH.params.e_pp) + rng.normal(0, CREST_NOISE_MM)
        out["observable"]["crest_height_m"] = mm * 1e-3
    return out


def _with_scale(path):
    """The workbook with every heap photo's scale (the analytic photos' renderer scale)."""
    sheets = pd.read_excel(path, sheet_name=None)
    sheets["repose"]["scale_mm_per_px"] = 1e3 / PHOTO_PX_PER_M
    out = path.parent / "scaled.xlsx"
    write_workbook(sheets, out)
    return out


@pytest.fixture(scope="module")
def crest(tmp_path_factory):
    folder = tmp_path_factory.mktemp("crest")
    path = _with_scale(_workbook(folder, rigs="lifted_plate"))
    m = measure_workbook(path)
    LAB["crest_mm"] = m.quantities["crest_height_mm"].value
    config = CampaignConfig(workers=1, progress=False, seed=4, likelihood="heap", budget_runs=32, refine_rounds=2,
                            validation_cap=20, extra_targets=("crest_height_mm",))
    return path, m, config, calibrate(path, folder / "out", config, runner=crest_runner, measurement=m)


def test_the_photos_measure_the_crest_height_only_with_their_scale(crest, tmp_path):
    path, m, _, _ = crest
    est = m.quantities["crest_height_mm"]
    assert est.n == 6 and est.unit == "mm"
    # the analytic heaps stand 100 mm high: their crests, read at the photos' scale, within a few mm
    assert est.value == pytest.approx(100.0, abs=8.0)
    rows = [r["crest_height_mm"] for r in m.quantities["repose_angle_deg"].per_row]
    assert est.value == pytest.approx(np.mean(rows))
    unscaled = measure_workbook(path.parent / "workbook.xlsx")
    assert "crest_height_mm" not in unscaled.quantities
    with pytest.raises(InputError, match="no crest_height_mm.*scale_mm_per_px"):
        calibrate(path.parent / "workbook.xlsx", tmp_path / "x", replace(crest[2]), runner=crest_runner,
                  measurement=unscaled)


def test_the_crest_pins_down_what_the_angle_cannot(crest):
    _, _, config, res = crest
    cal = res.calibration
    (extra,) = res.extra_targets
    assert extra.quantity == "crest_height_mm" and extra.observable == "crest_height_m" and extra.unit == "mm"
    assert extra.run_sd == pytest.approx(CREST_NOISE_MM, rel=0.3)
    angle_only = cal.by_rig["lifted_plate angle only"]["e_pp"]["sd_ratio"]
    assert angle_only > 0.9                                    # the angle ignores e_pp
    prior = res.prior["e_pp"]
    var = extra.target_var + config.discrepancy_sd ** 2 + extra.predicted["sd"] ** 2
    expected = _normal_posterior_sd({"e_pp": prior.sd}, [({"e_pp": CREST_SLOPE}, var)])["e_pp"] / prior.truncated_sd
    assert cal.parameters["e_pp"].sd_ratio == pytest.approx(expected, abs=0.08)
    assert cal.parameters["e_pp"].sd_ratio < angle_only - 0.3
    truth = TRUTH.params.e_pp
    assert cal.parameters["e_pp"].ci95[0] <= truth <= cal.parameters["e_pp"].ci95[1]
    # the validation runs read the crest as the lab did, near its mean
    assert extra.validation["n"] == res.validation.n_runs
    assert abs(extra.validation["mean"] - extra.target) < 4 * math.hypot(extra.target_sd / math.sqrt(extra.target_n),
                                                                          CREST_NOISE_MM)


def test_an_extra_target_no_rig_reads_is_refused(crest, tmp_path):
    path, m, config, _ = crest
    with pytest.raises(InputError, match=r"extra target angle_cone_deg: no repose rig of the workbook \(lifted_plate\) "
                                         "reads it; they offer crest_height_mm"):
        calibrate(path, tmp_path / "y", replace(config, extra_targets=("angle_cone_deg",)), runner=crest_runner,
                  measurement=m)


def test_the_report_shows_the_extra_target_and_the_audit_rederives_it(crest):
    from demcal.report.audit import audit
    from demcal.report.render import build_report
    from demcal.report.tables import build_tables, load_campaign

    path, _, _, _ = crest
    out = path.parent / "out"
    build_report(out, pdf=False)          # the PDF's own audit is report/'s test
    tables = {t.id: t for t in build_tables(load_campaign(out))}
    assert tables["P8"].rows[0][:2] == ("crest_height_mm", "lifted_plate")
    assert tables["P5b"].columns[1:3] == ("lifted_plate angle only", "lifted_plate alone")
    checked = audit(out)
    assert all(f.status == "ok" for f in checked.files) and all(t.status == "ok" for t in checked.tables)
    assert {a.artefact: a.status for a in checked.artefacts} == {"results.json": "ok", "runs.csv": "ok",
                                                                 "report.html": "ok", "report.pdf": "missing",
                                                                 "figures": "ok"}
    assert not checked.problems


class _Fixed:
    """A surrogate whose mean and sd are given."""

    def __init__(self, m, s):
        self.m, self.s = np.atleast_1d(m), np.atleast_1d(s)

    def predict(self, x):
        return self.m, self.s


def test_a_reading_from_the_angles_photos_is_their_bivariate_normal_with_its_own_discrepancy():
    from scipy.stats import multivariate_normal, norm

    from demcal.analyse.surrogate import HeapDatum

    angle = HeapDatum(_Fixed(35.0, 0.3), 36.0, 0.2)                    # the posterior's discrepancy
    crest = HeapDatum(_Fixed(98.0, 0.5), 100.0, 1.5, discrepancy_var=0.0, given=angle, lab_cov=0.4)
    disc = 0.25                                                         # deg^2: the angle's alone
    va, vc = 0.3 ** 2 + 0.2 + disc, 0.5 ** 2 + 1.5
    joint = multivariate_normal([35.0, 98.0], [[va, 0.4], [0.4, vc]]).logpdf([36.0, 100.0])
    marginal = norm(35.0, np.sqrt(va)).logpdf(36.0)
    ll, imp = crest.terms(np.zeros((1, 1)), disc)
    assert ll[0] + angle.terms(np.zeros((1, 1)), disc)[0][0] == pytest.approx(joint + np.log(2 * np.pi), abs=1e-12)
    assert ll[0] - np.log(2 * np.pi) / 2 == pytest.approx(joint - marginal, abs=1e-12)
    assert imp[0] == pytest.approx(2.0 / np.sqrt(vc))
