"""The plausible workflow end to end on the example workbook, with a stand-in heap whose noise
is a fresh draw for every (parameters, seed), as the chaotic DEM's is (a stand-in whose noise
depended on the seed alone would hide what this workflow is for)."""

import math

import numpy as np
import pytest

from demcal.analyse.campaign import CampaignConfig, calibrate, derive_results
from demcal.analyse.plausible import SeedStream
from tests.analyse.conftest import EXAMPLE
from tests.analyse.standin import DROP_RATIO, HEAP_NOISE_SD, heap_standin_angle, heap_standin_runner



@pytest.fixture(scope="module")
def campaign(measurement, tmp_path_factory):
    out = tmp_path_factory.mktemp("plausible")
    config = CampaignConfig(workers=1, progress=False, seed=3)
    return out, config, calibrate(EXAMPLE, out, config, runner=heap_standin_runner, measurement=measurement)


def test_noise_is_measured_and_sizes_the_replicates(campaign):
    _, _, res = campaign
    noise = res.noise
    # the pooled run sd's 95 % interval holds the stand-in's true sd
    lo, hi = noise.all_points.ci95
    assert lo <= HEAP_NOISE_SD <= hi
    # k from the measured noise: run sd / sqrt(k) <= 3 x tolerance (tolerance 1 deg here)
    k = noise.replicates
    assert k == max(2, int(np.ceil((noise.centre.sd / 3.0) ** 2)))
    points = res.design.points[2:]
    assert all(len(p.responses) == k for p in points if not p.stage.startswith("refine"))
    # the refinement rounds run refine_runs times at the recommended point of their round
    refine = [p for p in points if p.stage.startswith("refine")]
    assert [p.stage for p in refine] == [f"refine {r}" for r in range(1, CampaignConfig().refine_rounds + 1)]
    assert all(len(p.responses) == CampaignConfig().refine_runs for p in refine)
    # the validation runs where the mean angle was measured: at one of the refined points
    rec = res.calibration.recommended
    assert rec.values in [p.settings for p in refine]
    assert rec.chosen.startswith("refined point of round")
    assert res.validation.settings == rec.values
    assert -1.0 <= noise.seed_correlation.r <= 1.0


def test_every_run_has_its_own_seed_and_the_budget_holds(campaign):
    _, config, res = campaign
    points = res.design.points
    seeds = [s for p in points[2:] for s in p.seeds] + res.validation.seeds
    assert len(seeds) == len(set(seeds))                  # independent draws everywhere ...
    assert points[0].seeds == points[1].seeds        # ... but the noise pair, by design
    design_runs = sum(len(p.responses) for p in points[2:] if not p.stage.startswith("refine"))
    assert design_runs <= config.budget_runs
    assert res.validation.n_runs <= config.validation_cap
    assert {p.stage for p in points} >= {"noise", "design", "sequential 1"}


def test_the_set_holds_the_truth_and_names_what_the_heap_cannot_identify(campaign):
    _, _, res = campaign
    cal = res.calibration
    params = cal.parameters
    # the stand-in ignores these: the heap says nothing about them
    for name in ("poisson_ratio", "e_pw", "mu_r_pw"):
        assert params[name].identifiability == "not identified", name
        assert params[name].sd_ratio > 0.9
    # it is steep in mu_s_pw: the heap narrows it
    assert params["mu_s_pw"].sd_ratio < 0.9
    # the recommended point lies in every interval and its true mean angle is on target
    rec = cal.recommended.values
    for name, p in params.items():
        assert p.ci95[0] <= rec[name] <= p.ci95[1]
        assert p.value == rec[name]
    true_angle = heap_standin_angle({**res.calibrated_parameters})
    assert abs(true_angle - res.target_angle_deg) < 3 * cal.recommended.predicted_sd + 0.5


def test_validation_reports_the_issue_keys(campaign, measurement):
    _, _, result = campaign
    res = result.to_dict()      # the keys of results.json that scripts rely on
    v = res["validation"]
    assert v["verdict"] in ("equivalent", "different", "undecided")
    for key in ("mean_deg", "ci95", "tolerance_deg", "target_deg", "n_runs", "detectable_bias_deg"):
        assert key in v
    assert v["n_runs"] == len(v["responses"]) == len(v["runs"])
    # the default tolerance: the larger of 1 deg and the lab's heap-to-heap sd
    lab_sd = measurement.quantities["repose_angle_deg"].sd
    assert v["tolerance_deg"] == pytest.approx(max(1.0, lab_sd))
    for name, p in res["calibration"]["parameters"].items():
        assert set(p) >= {"value", "ci95", "prior_mean", "prior_sd", "sd_ratio"}


def test_replay_from_the_store_gives_the_same_answer_and_reruns_nothing(campaign, measurement):
    out, config, res = campaign
    replay = derive_results(measurement, config, out / "runs")
    assert replay.calibration.parameters == res.calibration.parameters
    assert replay.validation.verdict == res.validation.verdict
    again = calibrate(EXAMPLE, out, config, runner=heap_standin_runner, measurement=measurement)
    assert all(stage["ran"] == 0 for stage in again.stages)


def test_another_seed_draws_other_runs_and_a_consistent_answer(campaign, measurement, tmp_path):
    _, config, res = campaign
    other = calibrate(EXAMPLE, tmp_path, CampaignConfig(workers=1, progress=False, seed=4),
                      runner=heap_standin_runner, measurement=measurement)
    seeds_a = {s for p in res.design.points for s in p.seeds}
    seeds_b = {s for p in other.design.points for s in p.seeds}
    assert not seeds_a & seeds_b
    # the two plausible sets overlap and each recommended point lies in the other's intervals
    for name, p in res.calibration.parameters.items():
        q = other.calibration.parameters[name]
        assert p.ci95[0] <= q.ci95[1] and q.ci95[0] <= p.ci95[1], name
        assert q.ci95[0] <= p.value <= q.ci95[1], name
        assert p.ci95[0] <= q.value <= p.ci95[1], name


def test_seed_streams_are_distinct_and_reproducible():
    a, b = SeedStream(1), SeedStream(1)
    first = a.take("design", 5) + a.take("design", 5)
    assert first == b.take("design", 10)
    assert len(set(first + a.take("validation", 10))) == 20
    assert SeedStream(2).take("design", 10) != first


def test_the_critique_names_what_the_heap_cannot_identify(campaign):
    from demcal.analyse.critique.mechanisms import ill_conditioned

    _, _, res = campaign
    found = {f.covariate for f in ill_conditioned(res) if f.verdict == "found"}
    expected = {n for n, p in res.calibration.parameters.items() if p.sd_ratio > 0.9}
    assert found == expected and {"poisson_ratio", "e_pw", "mu_r_pw"} <= found


def test_joint_calibration_reads_the_restitutions_through_the_drop_twin(campaign, measurement):
    # the stand-in's segment rebounds at DROP_RATIO times its contact restitution, so the
    # contact value that reproduces the lab's drops is the measured one over DROP_RATIO
    _, _, res = campaign
    cal = res.calibration
    assert cal.likelihood == "joint"
    for name, quantity in (("e_pw", "restitution.particle-steel"), ("e_pp", "restitution.particle-particle")):
        twin = cal.twins[name]
        est = measurement.quantities[quantity]
        assert twin["mean"] == pytest.approx(est.value / DROP_RATIO, abs=3 * twin["sd_of_mean"] + 0.005)
        # the spread of single drops through the twin; the Student-t likelihood of n trials'
        # mean has the sd of t with n - 1 degrees of freedom, sqrt((n - 1) / (n - 3)) se
        n = twin["trials"]
        assert twin["sd"] == pytest.approx(est.sd / DROP_RATIO * math.sqrt((n - 1) / (n - 3)), rel=0.1)
        assert cal.parameters[name].prior_mean == pytest.approx(twin["mean"])
        # the heap-only calibration takes sqrt(h2/h1) at its word
        assert cal.heap_only.parameters[name].prior_mean == pytest.approx(est.value)
    # the incline twin reads the friction itself: it reproduces the measured mean
    assert cal.twins["mu_s_pw"]["mean"] == pytest.approx(
        measurement.quantities["static_friction.steel"].value, abs=0.01)
    assert "poisson_ratio" not in cal.twins


def test_heap_only_calibration_runs_no_twin(measurement, tmp_path):
    res = calibrate(EXAMPLE, tmp_path, CampaignConfig(workers=1, progress=False, seed=5, likelihood="heap",
                                                      budget_runs=40, validation_cap=20),
                    runner=heap_standin_runner, measurement=measurement)
    assert res.calibration.likelihood == "heap" and not res.calibration.twins
    assert res.calibration.heap_only is None
    assert res.calibration.parameters["e_pw"].prior_mean == pytest.approx(
        measurement.quantities["restitution.particle-steel"].value)
    assert not [s for s in res.stages if "twins" in s["stage"]]


def test_first_validation_look_is_sized_by_power(measurement, tmp_path):
    from demcal.analyse.equivalence import runs_for_power

    # a loose tolerance makes equivalence reachable: the first look comes at the runs that give
    # 80 % power at the predicted bias, not at validation_first
    res = calibrate(EXAMPLE, tmp_path, CampaignConfig(workers=1, progress=False, seed=6, likelihood="heap",
                                                      tolerance=3.0, budget_runs=24, validation_first=2),
                    runner=heap_standin_runner, measurement=measurement)
    cal, v = res.calibration, res.validation
    n = runs_for_power(cal.recommended.predicted - v.target_deg, res.noise.all_points.sd,
                       3.0, 0.8, v.test["target_sd_deg"], v.test["target_n"], n_max=40)
    assert n is not None and n > 2
    assert v.test["looks"][0]["n_runs"] == n


def test_results_json_reads_back_into_the_same_typed_result(campaign):
    from demcal.analyse.results import SCHEMA_VERSION, CampaignResult
    from demcal.errors import InputError
    from demcal.jsonio import read_json

    out, _, res = campaign
    stored = read_json(out / "results.json")
    assert stored["schema_version"] == SCHEMA_VERSION
    back = CampaignResult.from_dict(stored)
    assert back.to_dict() == stored
    assert back.calibration.parameters["mu_s_pw"].ci95 == res.calibration.parameters["mu_s_pw"].ci95
    assert back.summary() == res.summary()
    assert f"validation: {res.validation.verdict}" in back.summary()
    # the working sections come back typed, element by element
    assert back.design.points[0] == res.design.points[0]
    assert back.noise.all_points.sd == res.noise.all_points.sd
    assert back.prior["mu_s_pw"].sd == res.prior["mu_s_pw"].sd
    # a renamed key is refused where the file is read, by name
    renamed = {**stored, "validation": {**stored["validation"], "verdict_": stored["validation"]["verdict"]}}
    del renamed["validation"]["verdict"]
    with pytest.raises(InputError, match="validation: unknown key.*verdict_"):
        CampaignResult.from_dict(renamed)
    with pytest.raises(InputError, match="schema version 99"):
        CampaignResult.from_dict({**stored, "schema_version": 99})


def unreadable_heap_runner(inputs):
    """The noisy stand-in, whose heap no method can read for one seed in eleven (as a run
    that left nothing outside the carton), whatever the parameters."""
    out = heap_standin_runner(inputs)
    if inputs.get("rig", "repose") == "repose" and inputs["seed"] % 11 == 0:
        out["observable"] = {name: None for name in out["observable"]}
    return out


def never_readable_runner(inputs):
    out = heap_standin_runner(inputs)
    if inputs.get("rig", "repose") == "repose":
        out["observable"] = {name: None for name in out["observable"]}
    return out


def test_a_heap_no_method_can_read_is_poured_again_and_the_replay_does_the_same(measurement, tmp_path):
    """A run whose heap neither the photo method nor its fallbacks can read is poured again with
    a fresh seed, as the lab pours again a heap it cannot measure: the campaign finishes, every
    discarded run is listed (stage, key, seed, the seed that replaced it) and counted in the
    report's runs table, no response comes from an unreadable heap, and a replay from the store
    takes the same decisions."""
    from demcal.analyse.runs import RunStore
    from demcal.report.tables import run_stages

    config = CampaignConfig(workers=1, progress=False, seed=4, budget_runs=40, validation_cap=16)
    res = calibrate(EXAMPLE, tmp_path, config, runner=unreadable_heap_runner, measurement=measurement)
    repoured = res.response["repoured_runs"]
    assert repoured and "poured again" in res.response["note"]
    store = RunStore(tmp_path / "runs")
    for r in repoured:
        assert r["seed"] % 11 == 0 and store.get(r["key"])["inputs"]["seed"] == r["seed"]
        assert r["poured_again_with_seed"] != r["seed"]
    used = [s for p in res.design.points for s in p.seeds] + list(res.validation.seeds)
    assert all(s % 11 for s in used) and {r["poured_again_with_seed"] for r in repoured} <= set(used) | {
        r["seed"] for r in repoured}
    assert all(np.isfinite(p.responses).all() for p in res.design.points)
    assert dict(run_stages(res))["unreadable heaps, each poured again"] == repoured
    replay = derive_results(measurement, config, tmp_path / "runs")
    assert replay.response == res.response and replay.calibration.parameters == res.calibration.parameters


def test_a_heap_unreadable_at_every_pour_ends_the_campaign_naming_its_run(measurement, tmp_path):
    from demcal.analyse.plausible import MAX_POURS
    from demcal.errors import AnalysisError

    config = CampaignConfig(workers=1, progress=False, seed=4, budget_runs=40, likelihood="heap")
    with pytest.raises(AnalysisError, match=f"{MAX_POURS} heaps in a row of one run could not be read .*runs/"):
        calibrate(EXAMPLE, tmp_path, config, runner=never_readable_runner, measurement=measurement)
