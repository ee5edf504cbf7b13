"""The calibration campaign end to end, on the example workbook, with an analytic stand-in for
the repose rig whose active factors and optimum are known. (The campaign on the real DEM is
exercised by ``demcal calibrate`` and the opt-in validation run.)"""

import pytest

from demcal.analyse.campaign import CampaignConfig, calibrate, factor_levels
from demcal.analyse.results import CampaignResult
from demcal.errors import InputError
from demcal.jsonio import read_json
from tests.analyse.conftest import EXAMPLE
from tests.analyse.standin import standin_angle, standin_runner


def test_levels_are_the_measured_extremes(measurement):
    levels = factor_levels(measurement, "minmax")
    est = measurement.quantities["restitution.particle-particle"]
    used = [r["value"] for r in est.per_row if r["used"]]
    assert levels["B"]["low"] == pytest.approx(min(used))
    assert levels["B"]["high"] == pytest.approx(max(used))
    assert levels["E"]["quantity"] == "restitution.particle-steel"
    sd_levels = factor_levels(measurement, "sd")
    assert sd_levels["C"]["high"] - sd_levels["C"]["low"] == pytest.approx(
        2 * measurement.quantities["static_friction.particle"].sd)


def test_campaign_finds_the_active_factors_and_the_target(measurement, tmp_path):
    config = CampaignConfig(workers=1, progress=False, workflow="design-expert")
    res = calibrate(EXAMPLE, tmp_path, config, runner=standin_runner, measurement=measurement)
    assert set(res.significant.carried_forward) == {"B", "E", "F"}
    assert set(res.plackett_burman.screening.significant) == {"B", "E", "F"}
    # the noise repeats measure the stand-in's noise (4 seeds: loose bound)
    assert 0.02 < res.noise.sd < 0.5
    # optimisation: the preferred solution sits on the target surface of the fitted model
    opt = res.optimisation
    assert opt.reached
    assert opt.preferred.predicted == pytest.approx(res.target_angle_deg, abs=1e-3)
    # validation with fresh seeds: the true response at the solution is the target within noise
    settings = res.validation.settings
    base = res.calibrated_parameters
    assert standin_angle({**base, **settings}) == pytest.approx(res.target_angle_deg, abs=0.5)
    assert res.validation.result["relative_error_pct"] < 2.0
    # Design-Expert's confirmation: the prediction interval of the mean of the validation runs
    conf = res.validation.confirmation
    assert conf["pi95"][0] < conf["predicted"] < conf["pi95"][1]
    assert res.validation.verdict in ("equivalent", "different", "undecided")
    # every run is in the store and the rerun reuses them all
    again = calibrate(EXAMPLE, tmp_path, config, runner=standin_runner, measurement=measurement)
    assert all(stage["ran"] == 0 for stage in again.stages)
    assert again.box_behnken.response == res.box_behnken.response
    # results.json reads back into the same typed sections; a key renamed deep inside is
    # refused where it is read, with its place
    stored = read_json(tmp_path / "results.json")
    back = CampaignResult.from_dict(stored)
    assert back.to_dict() == stored
    assert back.box_behnken.fit.anova_row("Lack of Fit") == res.box_behnken.fit.anova_row("Lack of Fit")
    assert back.optimisation.preferred == back.optimisation.solutions[0]
    anova = stored["box_behnken"]["fit"]["anova"]
    anova[0] = {**anova[0], "F": anova[0]["f"]}
    with pytest.raises(InputError, match=r"box_behnken\.fit\.anova\[0\]: unknown key.*F"):
        CampaignResult.from_dict(stored)


def test_response_falls_back_to_the_profile_fit_when_the_photo_method_finds_no_slope():
    from demcal.analyse.campaign import _responses
    from demcal.errors import AnalysisError

    records = [{"key": "a", "result": {"observable": {"angle_deg": 31.0, "angle_profile_deg": 30.0}}},
               {"key": "b", "result": {"observable": {"angle_deg": None, "angle_profile_deg": 0.03}}},
               {"key": "c", "result": {"observable": {"angle_deg": None, "angle_profile_deg": None,
                                                      "angle_outside_deg": 2.6}}}]
    fallbacks = []
    assert _responses(records, fallbacks).tolist() == [31.0, 0.03, 2.6]
    assert fallbacks == [{"key": "b", "used": "angle_profile_deg"},
                         {"key": "c", "used": "angle_outside_deg"}]
    records[1]["result"]["observable"]["angle_profile_deg"] = float("nan")
    with pytest.raises(AnalysisError, match="run b"):
        _responses(records)


def test_workflow_and_replicates_default_by_profile_and_survive_the_stored_config():
    quick = CampaignConfig(progress=False)
    assert (quick.workflow, quick.replicates) == ("plausible", None)   # replicates from the noise
    paper = CampaignConfig(profile="paper", progress=False)
    assert (paper.workflow, paper.replicates) == ("design-expert", 1)
    with pytest.raises(Exception, match="workflow must be one of"):
        CampaignConfig(workflow="best-guess")
    # a campaign stored before workflows existed was a design-expert one, and is replayed as such
    old = {k: v for k, v in CampaignConfig(workflow="design-expert", replicates=3).__dict__.items()
           if k in ("profile", "levels", "seed", "replicates", "noise_repeats", "climb_levels")}
    assert CampaignConfig.from_dict(old).workflow == "design-expert"
    stored = {k: v for k, v in CampaignConfig(profile="paper", replicates=2).__dict__.items()}
    assert CampaignConfig.from_dict(stored).replicates == 2
    with pytest.raises(Exception, match="replicates must be a positive integer"):
        CampaignConfig(replicates=0)


def test_design_point_response_is_the_median_of_its_replicates():
    from demcal.analyse.campaign import _point_responses

    y, y_all = _point_responses([30.0, 47.5, 31.0, 20.0, 22.0, 21.0], 3)
    assert y.tolist() == [31.0, 21.0] and y_all.shape == (2, 3)


def unreadable_heap_runner(inputs):
    """The stand-in, whose heap no method can read for one seed in eleven (as a run that
    left nothing outside the carton), whatever the parameters."""
    out = standin_runner(inputs)
    if inputs["seed"] % 11 == 0:
        out["observable"] = {name: None for name in out["observable"]}
    return out


def test_the_paper_workflow_pours_an_unreadable_heap_again_and_the_replay_does_the_same(measurement, tmp_path):
    """The design-expert workflow, as the plausible one, pours again with a fresh seed a heap
    neither the photo method nor its fallbacks can read, instead of stopping the campaign: at
    seed 11 every screening and climb run is such a heap. Every run set aside is listed with
    the seed that replaced it, counted in the report's runs table, no response comes from an
    unreadable heap, and a replay from the store takes the same decisions."""
    from demcal.analyse.campaign import derive_results
    from demcal.analyse.runs import RunStore
    from demcal.report.tables import load_campaign, run_stages, table_runs

    config = CampaignConfig(workers=1, progress=False, workflow="design-expert", seed=11)
    res = calibrate(EXAMPLE, tmp_path, config, runner=unreadable_heap_runner, measurement=measurement)
    repoured = res.response["repoured_runs"]
    assert len(repoured) >= 12 and "poured again" in res.response["note"]
    store = RunStore(tmp_path / "runs")
    for r in repoured:
        assert r["seed"] % 11 == 0 and store.get(r["key"])["inputs"]["seed"] == r["seed"]
        assert r["poured_again_with_seed"] % 11 != 0 or any(q["seed"] == r["poured_again_with_seed"] for q in repoured)
    assert {r["stage"] for r in repoured} >= {"Plackett-Burman", "steepest climb"}
    for part in (res.plackett_burman, res.steepest_climb, res.box_behnken, res.validation):
        assert all(run["seed"] % 11 for run in part.runs)
    assert dict(run_stages(res))["unreadable heaps, each poured again"] == repoured
    a2 = table_runs(load_campaign(tmp_path))
    row = next(r for r in a2.rows if r[0] == "unreadable heaps, each poured again")
    assert row[1] == len({r["key"] for r in repoured})
    assert any(n.startswith(f"{len(repoured)} heap(s) could be read by no method") for n in a2.notes)
    replay = derive_results(measurement, config, tmp_path / "runs")
    assert replay.response == res.response and replay.box_behnken.response == res.box_behnken.response


def test_a_time_step_above_the_safe_limit_is_refused_before_any_run(measurement, tmp_path):
    from demcal.errors import UnsafeTimeStepError

    calls = []

    def runner(task):
        calls.append(task)
        return standin_runner(task)

    config = CampaignConfig(workers=1, progress=False, model_extensions={"dt": 2e-4})
    with pytest.raises(UnsafeTimeStepError, match="--set dt=SECONDS"):
        calibrate(EXAMPLE, tmp_path / "out", config, runner=runner, measurement=measurement)
    assert calls == [] and not list((tmp_path / "out").glob("runs/*.json"))
