"""Heap-side gain: the campaign recalibrated with an accepted extension and compared with the one
under critique, on a stand-in whose answer is known in closed form (``standin``: flat drops that
rebound at a seventh of the contact restitution without shared damping and at it with it; an
outflow fraction linear in e_pw)."""

import json

import numpy as np
import pytest
from scipy import stats

from demcal.analyse.campaign import CampaignConfig, calibrate
from demcal.analyse.critique import run_critique
from demcal.analyse.critique.heap_gain import welch_interval
from demcal.analyse.critique.loop import Critique
from demcal.analyse.results import CampaignResult
from demcal.errors import InputError
from demcal.jsonio import read_json, to_jsonable, write_json
from demcal.measure.pipeline import measure_workbook
from demcal.simulate.virtual_lab import Truth, write_virtual_workbook
from tests.analyse.standin import OUTFLOW_SLOPE, extension_standin_runner


def test_welch_interval_against_scipy():
    rng = np.random.default_rng(0)
    a, b = rng.normal(0.0, 1.0, 12), rng.normal(0.5, 2.0, 9)
    d, ci = welch_interval(a, b)
    ref = stats.ttest_ind(b, a, equal_var=False).confidence_interval(0.95)
    assert d == pytest.approx(b.mean() - a.mean())
    assert ci == pytest.approx((ref.low, ref.high))
    assert np.isnan(welch_interval([1.0], [2.0, 3.0])[1][0])


@pytest.fixture(scope="module")
def flat_lab(tmp_path_factory):
    """A lab whose drops all land flat and rebound at the contact restitution, and a campaign
    calibrated on it with the stand-in (the default model, whose flat drops overdamp)."""
    root = tmp_path_factory.mktemp("heap_gain")
    vw = write_virtual_workbook(Truth(), root / "lab", rng=21, n_photos=3, drop_heights_mm=(400.0,), n_drop=12,
                                orientation_range_deg=(0.0, 0.0), n_tracks=0, n_incline=8)
    out = root / "campaign"
    config = CampaignConfig(workers=1, progress=False, seed=4, noise_repeats=4, initial_points=8, batch=2,
                            budget_runs=24, refine_rounds=1, refine_runs=4, validation_first=8,
                            validation_step=8, validation_cap=16)
    calibrate(vw.path, out, config, runner=extension_standin_runner, measurement=measure_workbook(vw.path))
    return vw, out


def test_a_workbook_gives_no_heap_gain(flat_lab):
    vw, _ = flat_lab
    with pytest.raises(InputError, match="campaign folder"):
        run_critique(vw.path, rigs=("drop",), heap_gain=True)


def test_heap_side_gain_of_shared_damping(flat_lab, tmp_path):
    vw, out = flat_lab
    c = run_critique(out, rigs=("drop",), store_dir=tmp_path / "store", heap_gain=True,
                     campaign_runner=extension_standin_runner)
    damping = [m for m in c.model_findings if m.mechanism == "contact_effective_mass"]
    assert damping and all(m.verdict == "found" for m in damping)
    # one recalibration, though both pairs accept the same switch
    (h,) = c.heap_gains
    assert h.extension == "contact_effective_mass" and h.settings == {"contact_effective_mass": True}
    folder = out / h.campaign
    after = CampaignResult.from_dict(read_json(folder / "results.json"))
    before = CampaignResult.from_dict(read_json(out / "results.json"))
    assert after.config["model_extensions"] == {"contact_effective_mass": True}
    assert all(read_json(p)["inputs"]["params"].get("contact_effective_mass") for p in (folder / "runs").glob("*.json"))
    # the twin without shared damping cannot reach the flat rebounds at any e_pw (a seventh of
    # it): the drops' Student-t likelihood then barely tells one e_pw from another, and its interval
    # spans most of the prior; with it, the measured sqrt(h2/h1) is the contact restitution,
    # pinned down by the drops
    e = {p.name: p for p in h.parameters}["e_pw"]
    measured = before.measurement["quantities"]["restitution.particle-steel"]["value"]
    assert e.after == pytest.approx(measured, abs=0.03)
    width = {k: ci[1] - ci[0] for k, ci in (("before", e.before_ci95), ("after", e.after_ci95))}
    assert width["before"] > 0.5 and width["after"] < 0.2 * width["before"]
    assert e.within_uncertainty == (e.before_ci95[0] <= e.after <= e.before_ci95[1])
    assert ("e_pw: its 95 % interval narrowed" if e.within_uncertainty else "e_pw moved beyond its uncertainty") \
        in h.conclusion
    # the outflow fraction moves by OUTFLOW_SLOPE x the change of e_pw at the validation points
    outflow = next(o for o in h.observables if o.name == "outside_fraction")
    expected = OUTFLOW_SLOPE * (after.validation.settings["e_pw"] - before.validation.settings["e_pw"])
    assert outflow.n_before == before.validation.n_runs and outflow.n_after == after.validation.n_runs
    assert outflow.ci95[0] <= expected <= outflow.ci95[1] and outflow.beyond_noise
    assert not outflow.fitted and next(o for o in h.observables if o.name == "angle_deg").fitted
    # every observable the carton rig declares, and only those
    from demcal.simulate.rigs import rig
    assert [o.name for o in h.observables] == list(rig("repose").observables)
    crest = next(o for o in h.observables if o.name == "crest_height_m")
    assert crest.unit == "mm" and crest.before == pytest.approx(80.0, abs=1.0)     # 0.08 m in the records
    assert any(s.startswith("Heap-side gain of contact_effective_mass") for s in c.conclusions)
    # critique.json reads back, and the report's tables C5 and C6 show it
    doc = json.loads(json.dumps(to_jsonable(c.to_dict())))
    assert Critique.from_dict(doc).heap_gains == c.heap_gains
    write_json(out / "critique.json", doc)
    from demcal.report.tables import critique_tables, load_campaign

    tables = {t.id: t for t in critique_tables(load_campaign(out))}
    rows = {r[1]: r for r in tables["C5"].rows}
    assert rows["e_pw"][0] == "contact_effective_mass" and rows["e_pw"][-1] == e.verdict
    assert e.verdict in ("beyond its uncertainty", "within its uncertainty, interval narrowed")
    assert len(tables["C6"].rows) == len(h.observables)
    assert any(h.conclusion in note for note in tables["C5"].notes)


def test_a_parameter_pinned_down_by_the_extension_is_said_to_narrow():
    from demcal.analyse.critique.heap_gain import ParameterShift, _conclusion

    pinned = ParameterShift("e_pw", 0.75, 0.35, (0.06, 0.97), (0.32, 0.38), -0.4, True)
    loose = ParameterShift("mu_s_pw", 0.30, 0.31, (0.20, 0.40), (0.22, 0.41), 0.01, True)
    moved = ParameterShift("e_pp", 0.70, 0.35, (0.60, 0.80), (0.30, 0.40), -0.35, False)
    assert [p.verdict for p in (pinned, loose, moved)] == [
        "within its uncertainty, interval narrowed", "within its uncertainty", "beyond its uncertainty"]
    text = _conclusion("x", [pinned, loose], [], "equivalent", "equivalent")
    assert "e_pw: its 95 % interval narrowed from [0.06, 0.97] to [0.32, 0.38]" in text
    assert "does not change the calibration" not in text
    assert "does not change the calibration" in _conclusion("x", [loose], [], "equivalent", "equivalent")
    assert "e_pp moved beyond its uncertainty" in _conclusion("x", [moved, pinned], [], "equivalent", "equivalent")
    # an interval a file stores as nulls says nothing about narrowing
    assert not ParameterShift("e_pw", 0.75, 0.35, (None, None), (0.32, 0.38), -0.4, True).narrowed
