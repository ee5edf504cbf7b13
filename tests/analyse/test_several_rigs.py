"""A workbook with two repose rigs (the lifted plate and the drum): the measurement gives each rig
its angle, the plausible workflow conditions on both heaps, and the report says what each rig
says alone.

The stand-in heaps are linear in the parameters with a fresh noise draw per (parameters, seed),
the two rigs' angles depending on rolling and steel friction in other combinations: with a
normal prior, the posterior of two linear readings is known in closed form, an independent
reference for what each rig alone and both together pin down."""

import hashlib
import json
from dataclasses import replace

import numpy as np
import pytest

from demcal.analyse.campaign import CampaignConfig, calibrate
from demcal.errors import InputError, WorkbookError
from demcal.measure.pipeline import measure_workbook
from demcal.simulate.virtual_lab import Truth, write_virtual_workbook

#: Truth of the virtual lab: its default parameters, its photos at the stand-ins' common angle.
TRUTH = Truth()
ANGLE = 36.0
#: Slopes of the two stand-ins' mean angles [deg per unit of the parameter]: the heap rises
#: with both frictions, the drum with rolling and against steel friction.
SLOPES = {"repose": {"mu_r_pp": 40.0, "mu_s_pw": 40.0}, "drum": {"mu_r_pp": 40.0, "mu_s_pw": -40.0}}
NOISE_SD = 0.3
DRUM = {"drum_diameter_mm": 400, "drum_width_mm": 150, "drum_speed_rpm": 5}


def linear_angle(rig: str, p: dict) -> float:
    truth = TRUTH.params.to_dict()
    return ANGLE + sum(k * (p[n] - truth[n]) for n, k in SLOPES[rig].items())


def two_rig_runner(inputs: dict) -> dict:
    """Drops and inclines read the parameter itself; heaps and drums their linear angle plus
    noise drawn afresh for every task."""
    rng = np.random.default_rng(int.from_bytes(hashlib.sha256(json.dumps(inputs, sort_keys=True).encode())
                                               .digest()[:8], "little"))
    p, rig = inputs["params"], inputs.get("rig", "repose")
    if rig == "drop":
        e = p["e_pp"] if inputs["pair"] == "particle-particle" else p["e_pw"]
        return {"rig": rig, "observable": {"apparent_restitution": e + rng.normal(0.0, 0.01)}}
    if rig == "incline":
        on = "pp" if inputs["surface"] == "particle" else "pw"
        name = "static_friction_apparent" if inputs["mode"] == "slide" else "rolling_friction_apparent"
        return {"rig": rig, "observable": {name: p[f"mu_{'s' if inputs['mode'] == 'slide' else 'r'}_{on}"]}}
    angle = linear_angle(rig, p) + rng.normal(0.0, NOISE_SD)
    return {"rig": rig, "observable": {"angle_deg": angle, "angle_profile_deg": angle}, "record": {},
            "wall_s": 0.0, "steps": 0, "spheres": 0, "sphere_steps_per_s": 0.0, "seed": inputs["seed"]}


def _workbook(folder, rigs="lifted_plate, drum", **meta):
    return write_virtual_workbook(replace(TRUTH, repose_angle_deg=ANGLE), folder / "workbook.xlsx", rng=5,
                                  repose_rig={"repose_rig": rigs, **(DRUM if "drum" in rigs else {}), **meta},
                                  n_photos=6, n_drop=6,
                                  drop_heights_mm=(400.0,), n_tracks=0).path


@pytest.fixture(scope="module")
def two(tmp_path_factory):
    folder = tmp_path_factory.mktemp("two_rigs")
    path = _workbook(folder)
    config = CampaignConfig(workers=1, progress=False, seed=3, likelihood="heap", budget_runs=32, refine_rounds=2,
                            validation_cap=20)
    return path, config, calibrate(path, folder / "out", config, runner=two_rig_runner)


def test_each_rig_has_its_angle_and_a_photo_of_no_named_rig_is_refused(two):
    path, _, _ = two
    m = measure_workbook(path)
    assert m.quantities["repose_angle_deg"].n == 6 and m.quantities["repose_angle_deg.drum"].n == 6
    assert {r["side"] for r in m.quantities["repose_angle_deg.drum"].per_row} == {"drum"}
    # the same workbook naming only the lifted plate, its drum photos still there: refused by row
    import pandas as pd

    from demcal.measure.workbook import write_workbook

    sheets = pd.read_excel(path, sheet_name=None)
    meta = sheets["meta"]
    meta = meta[~meta["key"].astype(str).str.startswith(("drum_", "lifted_plate_"))]
    sheets["meta"] = meta.replace({"value": {"lifted_plate, drum": "lifted_plate"}})
    write_workbook(sheets, path.parent / "single.xlsx")
    with pytest.raises(WorkbookError, match=r"sheet 'repose'.*row \d+.*column 'rig'.*rig drum: meta repose_rig "
                                            r"names lifted_plate, not this rig"):
        measure_workbook(path.parent / "single.xlsx")


def test_the_first_rig_runs_as_a_single_rig_campaign_would(two, tmp_path):
    path, config, res = two
    single = calibrate(path, tmp_path / "single", replace(config, refine_rounds=0, validation_cap=10,
                                                          validation_first=10),
                       runner=two_rig_runner, measurement=_first_rig_only(measure_workbook(path)))
    ours = [(p.stage, p.seeds, p.responses) for p in res.design.points if not p.stage.startswith("refine")]
    theirs = [(p.stage, p.seeds, p.responses) for p in single.design.points]
    assert ours == theirs
    # the drum has its own seeds, never the first rig's
    drum = res.other_rigs[0]
    seeds = {s for p in res.design.points for s in p.seeds}
    assert not seeds & {s for p in drum.design.points for s in p.seeds}


def _first_rig_only(m):
    meta = {k.replace("lifted_plate_", ""): v for k, v in m.meta.items() if not k.startswith("drum_")}
    meta["repose_rig"] = "lifted_plate"
    quantities = {k: v for k, v in m.quantities.items() if k != "repose_angle_deg.drum"}
    return replace(m, meta=meta, quantities=quantities)


def _normal_posterior_sd(prior_sd: dict, readings: list) -> dict:
    """Posterior sd of each parameter of a normal prior given linear readings
    ``(slopes, variance)``: (S0^-1 + sum a a^T / v)^-1."""
    names = list(prior_sd)
    precision = np.diag([1.0 / prior_sd[n] ** 2 for n in names])
    for slopes, var in readings:
        a = np.array([slopes.get(n, 0.0) for n in names])
        precision += np.outer(a, a) / var
    cov = np.linalg.inv(precision)
    return {n: float(np.sqrt(cov[i, i])) for i, n in enumerate(names)}


def test_together_the_rigs_pin_down_what_neither_does_alone_as_the_normal_posterior_says(two):
    _, config, res = two
    cal = res.calibration
    prior_sd = {n: p.sd for n, p in res.prior.items()}
    drum = res.other_rigs[0]
    # each reading's variance: the lab mean's, the allowed discrepancy's and the surrogate's own
    # at the recommended point
    heap = (SLOPES["repose"], cal.target_var + config.discrepancy_sd ** 2 + cal.recommended.predicted_sd ** 2)
    drum_r = (SLOPES["drum"], drum.target_var + config.discrepancy_sd ** 2 + drum.predicted["sd_deg"] ** 2)
    expected = {"lifted_plate": _normal_posterior_sd(prior_sd, [heap]), "drum": _normal_posterior_sd(prior_sd, [drum_r]),
                "together": _normal_posterior_sd(prior_sd, [heap, drum_r])}
    truncated = {n: p.truncated_sd for n, p in res.prior.items()}
    for name in ("mu_r_pp", "mu_s_pw"):
        for rig in ("lifted_plate", "drum"):
            assert cal.by_rig[rig][name]["sd_ratio"] == pytest.approx(expected[rig][name] / truncated[name], abs=0.08)
        assert cal.parameters[name].sd_ratio == pytest.approx(expected["together"][name] / truncated[name], abs=0.08)
        best_alone = min(cal.by_rig[r][name]["sd_ratio"] for r in ("lifted_plate", "drum"))
        assert cal.parameters[name].sd_ratio <= best_alone - 0.1, name
    # the parameters neither stand-in reads stay at their priors, alone and together
    for name in ("e_pp", "e_pw", "poisson_ratio"):
        assert cal.parameters[name].sd_ratio > 0.9
    # the truth lies in every combined 95 % interval
    truth = TRUTH.params.to_dict()
    for name, p in cal.parameters.items():
        assert p.ci95[0] <= truth[name] <= p.ci95[1], name


def test_both_rigs_validate_and_the_report_shows_each(two):
    path, _, res = two
    assert res.validation.n_runs >= 10 and res.other_rigs[0].validation.n_runs >= 10
    assert res.other_rigs[0].validation.settings == res.validation.settings
    assert "validation in the drum rig" in res.summary() and "each rig alone: lifted_plate" in res.summary()
    from demcal.report.audit import audit
    from demcal.report.render import build_report
    from demcal.report.tables import build_tables, load_campaign

    out = path.parent / "out"
    tables = {t.id: t for t in build_tables(load_campaign(out))}
    assert {"P5b", "P6b", "P7"} <= set(tables)
    assert tables["P5b"].columns[1:4] == ("lifted_plate alone", "drum alone", "All together")
    assert tables["P7"].rows[0][0] == "drum"
    # every table, the runs of both rigs and the report's text re-derived from the run store
    build_report(out, pdf=False)
    checked = audit(out)
    assert all(t.status == "ok" for t in checked.tables) and not checked.problems
    assert {a.artefact: a.status for a in checked.artefacts} == {"results.json": "ok", "runs.csv": "ok",
                                                                 "report.html": "ok", "report.pdf": "missing",
                                                                 "figures": "ok"}


def test_the_design_expert_workflow_refuses_two_rigs(two, tmp_path):
    path, config, _ = two
    with pytest.raises(InputError, match="fits the angle of one heap.*2 repose rigs"):
        calibrate(path, tmp_path / "de", replace(config, workflow="design-expert"), runner=two_rig_runner)


def test_a_dimension_two_rigs_share_must_be_named_per_rig(tmp_path):
    with pytest.raises(InputError, match="fill_count: a dimension of each of the rigs lifted_plate, drum; give each "
                                         "its own: lifted_plate_fill_count, drum_fill_count"):
        _workbook(tmp_path, fill_count=500)
    from demcal.simulate.rigs import repose_setups
    setups = repose_setups({"repose_rig": "lifted_plate, drum", **DRUM, "lifted_plate_fill_count": 500,
                            "drum_fill_count": 700})
    assert [s.geometry["fill_count"] for s in setups] == [500, 700]
    # a rig's prefixed name where the workbook has that rig alone, or not at all, is refused by name
    with pytest.raises(WorkbookError, match="meta drum_fill_count: the drum rig's fill_count is meta fill_count"):
        repose_setups({"repose_rig": "drum", **DRUM, "drum_fill_count": 700})
    with pytest.raises(WorkbookError, match="meta drum_fill_count: a dimension of the drum rig, which meta "
                                            "repose_rig does not name"):
        repose_setups({"repose_rig": "lifted_plate", "drum_fill_count": 700})


def test_the_critique_sets_each_rigs_photos_beside_its_validation_runs(two):
    from demcal.analyse.critique.loop import run_critique

    path, _, res = two
    c = run_critique(path.parent / "out", twins=True, rigs=("repose",))
    rows = {d.observable: d for d in c.discrepancies if d.observable.startswith("repose_angle_deg")}
    assert set(rows) == {"repose_angle_deg (photo method)", "repose_angle_deg.drum (drum photos)"}
    for row, validation in ((rows["repose_angle_deg (photo method)"], res.validation),
                            (rows["repose_angle_deg.drum (drum photos)"], res.other_rigs[0].validation)):
        assert row.n_simulated == validation.n_runs
        assert row.simulated == pytest.approx(np.mean(validation.responses))


@pytest.mark.parametrize("rig, meta", [("drum", {"drum_diameter_mm": 1e6, "drum_width_mm": 1e6, "drum_speed_rpm": 1e-3}),
                                       ("drum", {"drum_fill_count": 10 ** 12}),
                                       ("lifted_plate", {"lifted_plate_fill_count": 5 * 10 ** 7})])
def test_a_fill_no_lab_heap_holds_is_refused_before_any_memory_is_taken(rig, meta):
    from demcal.simulate.params import DEMParameters
    from demcal.simulate.rigs import repose_setups, run_rig

    setups = {s.workbook_name: s for s in repose_setups({"repose_rig": "lifted_plate, drum", **DRUM, **meta})}
    setup = setups.pop(rig)
    shape = DEMParameters().shape
    with pytest.raises(WorkbookError, match="more than 1e\\+06, more than any lab heap"):
        setup.check_for(shape)
    with pytest.raises(InputError, match="more than any lab heap"):      # and in the run itself
        run_rig(setup.rig, DEMParameters(), seed=0, geometry=setup.dimensions(), profile="quick")
    for other in setups.values():                                         # the other rig is fine
        other.check_for(shape)
