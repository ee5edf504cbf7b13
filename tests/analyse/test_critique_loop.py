"""The critique loop end to end: twins and discrepancies, a campaign's ill-conditioned parameter,
``demcal critique`` and the report's critique tables."""

import argparse
import json
import math
from pathlib import Path

import numpy as np
import pytest

from demcal.analyse.campaign import CampaignConfig, calibrate
from demcal.analyse.critique import run_critique
from demcal.analyse.critique.cli import register
from demcal.analyse.critique.loop import Critique
from demcal.analyse.critique.twins import independent_discrepancy, paired_discrepancy
from demcal.errors import InputError
from demcal.jsonio import to_jsonable
from demcal.measure.pipeline import measure_workbook
from demcal.simulate.virtual_lab import Truth, write_virtual_workbook

NOISE_SD = 0.3


def friction_only_runner(inputs: dict) -> dict:
    """A repose stand-in whose angle depends on mu_s_pw and mu_r_pp only, with seed noise: the
    campaign must carry a third factor that the angle cannot identify."""
    p = inputs["params"]
    noise = np.random.default_rng(inputs["seed"]).normal(0.0, NOISE_SD)
    angle = 35.0 + 40.0 * (p["mu_s_pw"] - 0.2) + 60.0 * (p["mu_r_pp"] - 0.53) + noise
    return {"rig": "repose", "observable": {"angle_deg": angle, "angle_profile_deg": angle},
            "record": {}, "wall_s": 0.0, "steps": 0, "spheres": 0, "sphere_steps_per_s": 0.0,
            "seed": inputs["seed"]}


def test_discrepancy_intervals_hand_calculation():
    d = paired_discrepancy("x", "drop", [0.40, 0.36, 0.38, 0.34], [0.30, 0.30, 0.31, 0.29])
    diffs = np.array([0.10, 0.06, 0.07, 0.05])
    half = 3.182446305284263 * diffs.std(ddof=1) / 2.0            # t(0.975, 3) s / sqrt(4)
    assert d.difference == pytest.approx(diffs.mean()) and d.combined_u95 == pytest.approx(half)
    assert d.exceeds
    w = independent_discrepancy("angle", "repose", [35.0, 36.0, 35.5], [35.2, 35.9])
    se = math.sqrt(np.var([35.0, 36.0, 35.5], ddof=1) / 3 + np.var([35.2, 35.9], ddof=1) / 2)
    assert w.difference == pytest.approx(35.5 - 35.55)
    assert not w.exceeds and w.combined_u95 > 2 * se       # Welch's t with few degrees of freedom


def test_drop_and_incline_twins_of_a_clean_lab(tmp_path):
    """Segments released end on: the drop twin reproduces sqrt(h2/h1), so it may feed the DEM."""
    vw = write_virtual_workbook(Truth(), tmp_path / "lab", rng=3, photos="none", pairs=("particle-steel",),
                                drop_heights_mm=(400.0,), n_drop=4, surfaces=("steel",), n_incline=6,
                                n_tracks=0)
    c = run_critique(vw.path, rigs=("drop", "incline"), store_dir=tmp_path / "store")
    rows = {d.observable.split(" ")[0]: d for d in c.discrepancies}
    drop = rows["restitution.particle-steel"]
    assert drop.n_simulated == 4 and not drop.exceeds
    assert drop.simulated == pytest.approx(drop.measured, abs=0.04)
    slide = rows["static_friction.steel"]
    # the twins run with the measured means; tan(slide angle) of the twin is its mu_s
    assert c.parameters["values"]["mu_s_pw"] == pytest.approx(slide.measured)
    assert slide.simulated == pytest.approx(slide.measured, abs=0.01) and not slide.exceeds
    assert any("may feed the DEM directly" in s for s in c.conclusions)
    assert not c.found()
    # a second critique reuses every twin run from the store
    again = run_critique(vw.path, rigs=("drop", "incline"), store_dir=tmp_path / "store")
    assert sum(r["ran"] for r in again.twin_runs) == 0
    doc = json.loads(json.dumps(to_jsonable(c.to_dict())))
    assert {"discrepancies", "findings", "extensions", "summary", "tests", "schema_version"} <= set(doc)
    # critique.json reads back into the same typed result
    back = Critique.from_dict(doc)
    assert json.loads(json.dumps(to_jsonable(back.to_dict()))) == doc
    assert back.summary() == c.summary() and "discrepancies beyond their 95 % interval: 0 of" in c.summary()


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    root = tmp_path_factory.mktemp("critique_campaign")
    vw = write_virtual_workbook(Truth(), root / "lab", rng=5, n_photos=3, n_drop=4)
    out = root / "campaign"
    calibrate(vw.path, out, CampaignConfig(workers=1, progress=False, noise_repeats=4,
                                           workflow="design-expert"),
              runner=friction_only_runner, measurement=measure_workbook(vw.path))
    return out


def test_campaign_ill_conditioned_parameter_and_repose_twin(campaign):
    c = run_critique(campaign, twins=True, rigs=("repose",))
    ill = [f for f in c.findings if f.mechanism == "ill_conditioned_parameter"]
    results = json.loads((campaign / "results.json").read_text())
    carried = results["box_behnken"]["factors"]
    param = {f: results["factors"][f]["parameter"] for f in carried}
    # mu_s_pw and mu_r_pp move the angle; the third factor carried cannot be identified
    assert {f.covariate for f in ill if f.verdict == "found"} == set(param.values()) - {"mu_s_pw", "mu_r_pp"}
    assert all(f.ci95[0] < 0 < f.ci95[1] for f in ill if f.verdict == "found")
    repose = [d for d in c.discrepancies if d.observable.startswith("repose_angle_deg")][0]
    # every single validation run (3 seeds x replicates), each one heap as each photo is
    runs = np.array(results["validation"]["replicate_responses"])
    assert repose.n_simulated == runs.size == 3 * results["config"]["replicates"]
    assert repose.simulated == pytest.approx(runs.mean())


def test_cli_writes_critique_json_and_the_report_renders_it(campaign, tmp_path):
    from demcal.report.tables import critique_tables, load_campaign

    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    out = tmp_path / "critique.json"
    args = parser.parse_args(["critique", str(campaign), "--json", str(out), "--rigs", "repose"])
    assert args.handler(args) == 0
    doc = json.loads(out.read_text())
    assert json.loads((campaign / "critique.json").read_text())["findings"] == doc["findings"]
    for f in doc["findings"]:
        assert {"mechanism", "verdict", "sheet", "covariate", "effect", "ci95", "p_adjusted"} <= set(f)
    assert {f["mechanism"] for f in doc["findings"]} >= {"velocity_dependent_restitution", "camera_tilt",
                                                        "ill_conditioned_parameter"}
    tables = {t.id: t for t in critique_tables(load_campaign(campaign))}
    assert tables["C2"].columns[:7] == ("mechanism", "verdict", "sheet", "covariate", "effect", "ci95",
                                        "p_adjusted")
    assert len(tables["C2"].rows) == len(doc["findings"]) and tables["C1"].rows


def _drop_lab(tmp_path, orientation_range):
    vw = write_virtual_workbook(Truth(), tmp_path / "lab", rng=11, photos="none", pairs=("particle-steel",),
                                drop_heights_mm=(400.0,), n_drop=12, surfaces=("steel",), n_incline=6, n_tracks=0,
                                orientation_range_deg=orientation_range)
    return run_critique(vw.path, rigs=("drop",), store_dir=tmp_path / "store")


def test_a_round_seeds_size_extension_drops_each_specimen_at_its_own_size(tmp_path):
    """Rebound planted to track a sphere's calliper diameter is found against ``diameter_mm``;
    the size extension drops each held-out seed at its specimen's diameter. A sphere's rebound
    at a given contact restitution does not depend on its size (Hertz-Mindlin sets the damping
    ratio from e alone), so the twins move only by the integration error: the effect stays one
    the DEM's sizes cannot express."""
    from demcal.simulate.params import DEMParameters, parse_shape
    from demcal.simulate.virtual_lab import PlantedEffect

    truth = Truth(params=DEMParameters(shape=parse_shape("sphere:0.0066"), particle_density_kg_m3=1200.0,
                                       shear_modulus_pa=1.04e6, e_pw=0.6, dt=None))
    vw = write_virtual_workbook(truth, tmp_path / "lab", effects=(PlantedEffect("size_dependence", size=0.1),),
                                rng=5, photos="none", pairs=("particle-steel",), n_drop=15, surfaces=("steel",),
                                n_incline=6, n_tracks=0)
    c = run_critique(vw.path, rigs=("drop",), extensions=("size_distribution",), store_dir=tmp_path / "store")
    assert {(f.mechanism, f.covariate) for f in c.found()} == {("size_dependence", "diameter_mm")}
    gain = next(g for g in c.extensions if g.name == "size_distribution")
    assert gain.n_held_out >= 20
    # the rms residual moves by no more than the twins do: the integration error, below 0.002 in e
    assert abs(gain.after - gain.before) < 0.002 < 0.1 * gain.before
    assert "each sphere has its specimen's diameter" in gain.fitted


def test_a_round_seed_dropped_at_any_orientation_shows_no_orientation_effect(tmp_path):
    """A sphere has no orientation: drops logged at random orientations show no effect in the
    lab's data, and the twin rebounds alike at every orientation (no slope against
    orientation_deg), so the discrepancy is not named and orientation_rotation is ruled out."""
    from demcal.simulate.params import DEMParameters, parse_shape

    truth = Truth(params=DEMParameters(shape=parse_shape("sphere:0.0066"), particle_density_kg_m3=1200.0,
                                       shear_modulus_pa=1.04e6, e_pw=0.6, dt=None))
    vw = write_virtual_workbook(truth, tmp_path / "lab", rng=11, photos="none", pairs=("particle-steel",),
                                drop_heights_mm=(400.0,), n_drop=12, surfaces=("steel",), n_incline=6, n_tracks=0,
                                orientation_range_deg=(0.0, 90.0))
    c = run_critique(vw.path, rigs=("drop",), store_dir=tmp_path / "store")
    assert c.found() == []
    slope = next(d for d in c.discrepancies if "slope against orientation_deg" in d.observable)
    assert not slope.exceeds and abs(slope.simulated) < 1e-6
    assert {m.mechanism: m.verdict for m in c.model_findings}.get("orientation_rotation") == "ruled_out"


def test_twin_only_orientation_dependence_is_a_model_discrepancy_not_a_data_effect(tmp_path):
    """Drops at random orientations whose rebound does not depend on it: no data effect; the
    twin's strong dependence on orientation is a discrepancy of its own, and its causes are
    tested, with shares that add up to the twin's deficit."""
    c = _drop_lab(tmp_path, (0.0, 90.0))
    assert c.found() == []
    slope = next(d for d in c.discrepancies if "slope against orientation_deg" in d.observable)
    assert slope.exceeds and slope.measured_ci95[0] < 0 < slope.measured_ci95[1]
    assert abs(slope.simulated) > 3 * abs(slope.measured)
    assert "the twin predicts" in slope.note and "the lab shows" in slope.note
    causes = {m.mechanism: m for m in c.model_findings}
    assert set(causes) == {"contact_effective_mass", "orientation_rotation"}
    assert causes["orientation_rotation"].verdict == "found"
    total = causes["orientation_rotation"].measured - causes["orientation_rotation"].simulated
    parts = sum(m.part for m in causes.values())
    contact = c.parameters["values"]["e_pw"]
    assert parts + (causes["orientation_rotation"].measured - contact) == pytest.approx(total, abs=1e-12)
    doc = json.loads(json.dumps(to_jsonable(c.to_dict())))
    assert {"mechanism", "verdict", "observable", "measured", "simulated", "share", "evidence"} <= set(doc["model_findings"][0])
    assert Critique.from_dict(doc).model_findings == c.model_findings


def test_flat_drops_name_contact_effective_mass_and_the_extension_closes_the_gap(tmp_path):
    """Segments landing flat that rebound at the contact restitution: the twin's glued-sphere
    damping is found, rotation is ruled out, and with the mass shared the held-out drops agree
    within their uncertainty."""
    c = _drop_lab(tmp_path, (0.0, 0.0))
    assert c.found() == []
    causes = {m.mechanism: m for m in c.model_findings}
    assert causes["contact_effective_mass"].verdict == "found" and causes["contact_effective_mass"].share > 0.9
    assert causes["orientation_rotation"].verdict == "ruled_out"
    gain = next(g for g in c.extensions if g.name == "contact_effective_mass")
    assert gain.ci95[0] > 0 and gain.extension["extension"] == "contact_effective_mass"
    assert "inside its uncertainty" in gain.note
    assert not any(g.name == "inverted_restitution" for g in c.extensions)   # no parameter absorbs it


def test_drops_within_five_degrees_of_flat_split_the_gap_between_damping_and_rotation(tmp_path):
    """Drops logged at 0-5 deg that rebound at the contact restitution. A segment tilted by a
    few degrees strikes with one end sphere first; its rim lies below the axis, so with
    friction part of the rebound goes into spin, as for any rigid body. The critique names both
    causes, the damping as the larger, and the extension removes most of the gap; the rest is
    the rotation the lab's drops do not show."""
    c = _drop_lab(tmp_path, (0.0, 5.0))
    assert c.found() == []
    causes = {m.mechanism: m for m in c.model_findings}
    assert causes["contact_effective_mass"].verdict == "found"
    assert causes["orientation_rotation"].verdict == "found"
    assert causes["contact_effective_mass"].share > causes["orientation_rotation"].share > 0
    gain = next(g for g in c.extensions if g.name == "contact_effective_mass")
    assert gain.ci95[0] > 0 and gain.after < gain.before / 3


def test_the_effective_mass_signature_reads_the_logged_orientations_or_a_flat_landing():
    """The signature of contact_effective_mass compares the twin with the rigid body at each
    drop's logged orientation and height; drops with no orientation logged are judged by a
    flat landing of the twin, whose rigid-body reference is the contact restitution."""
    from demcal.analyse.critique.attribution import _rigid_body_signature
    from demcal.simulate.params import DEMParameters
    from demcal.simulate.rigid_impact import rigid_drop

    params = DEMParameters(e_pw=0.36)
    on = params.with_(contact_effective_mass=True)
    ran = []

    def runner(function, tasks, desc):
        ran.extend(tasks)
        return [function(t) for t in tasks]

    trials = [(1, 0.3, 0.4, 60.0, {}, None), (2, 0.3, 0.2, 2.0, {}, None)]
    where, reference, off, on_mean = _rigid_body_signature(runner, params, on, "particle-steel", trials,
                                                           {1: (0.1, 0.2), 2: (0.05, 0.35)}, 0.36)
    body = params.template()
    assert reference == pytest.approx(np.mean([rigid_drop(body, 60.0, 0.36, 0.4).apparent_restitution,
                                               rigid_drop(body, 2.0, 0.36, 0.2).apparent_restitution]))
    assert (off, on_mean) == pytest.approx((0.075, 0.275)) and "2 drops" in where and not ran
    unlogged = [(1, 0.3, 0.4, None, {}, None), (2, 0.3, 0.2, None, {}, None)]
    where, reference, off, on_mean = _rigid_body_signature(runner, params, on, "particle-steel", unlogged,
                                                           {1: (0.1, 0.2), 2: (0.05, 0.35)}, 0.36)
    assert where == "landing flat" and reference == pytest.approx(0.36, abs=1e-12)
    assert [t["orientation_deg"] for t in ran] == [0.0, 0.0] and ran[0]["height"] == pytest.approx(0.3)
    assert off < 0.5 * 0.36 and on_mean == pytest.approx(0.36, rel=0.05)
    assert ran[1]["params"]["contact_effective_mass"] and "contact_effective_mass" not in ran[0]["params"]


def test_cli_errors_name_the_option(tmp_path):
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    vw = write_virtual_workbook(Truth(), tmp_path / "lab", rng=1, photos="none", n_drop=1, n_incline=2)
    args = parser.parse_args(["critique", str(vw.path)])
    with pytest.raises(InputError, match="--json"):
        args.handler(args)
    args = parser.parse_args(["critique", str(vw.path), "--json", str(tmp_path / "o.json"),
                              "--extensions", "magic"])
    with pytest.raises(InputError, match="unknown extension"):
        args.handler(args)


# ---------------------------------------------------------------------------------------------
# long runs (opt in with -m validation): the drop twins of a whole workbook and the inversion

EXAMPLE = Path(__file__).resolve().parents[2] / "data" / "astragalus"


@pytest.mark.validation
def test_example_campaign_drop_twin_says_whether_sqrt_h2_h1_may_feed_the_dem(tmp_path):
    """data/astragalus: every drop's twin at its logged orientation, with e = the measured mean."""
    c = run_critique(EXAMPLE, rigs=("drop",), store_dir=tmp_path / "store")
    steel = next(d for d in c.discrepancies if d.observable.startswith("restitution.particle-steel"))
    assert steel.exceeds and steel.simulated < steel.measured            # the twin rebounds lower
    assert "may not feed the DEM directly" in steel.note
    assert any(s.startswith("restitution.particle-steel") and "may not feed the DEM directly" in s
               and "contact restitution that reproduces the drops" in s for s in c.conclusions)
    assert "orientation_rotation" in {m.mechanism for m in c.model_findings if m.verdict == "found"}
    gain = next(g for g in c.extensions if g.name == "inverted_restitution" and g.quantity.endswith("steel"))
    assert gain.n_held_out == 20 and math.isfinite(gain.gain)
    assert gain.after < gain.before                                     # the bias falls on held-out drops


@pytest.mark.validation
def test_loop_recovers_the_contact_restitution_of_hand_dropped_segments(tmp_path):
    """Virtual drops at any orientation, made with the twin's physics at e_pw = 0.35: the loop
    names orientation_rotation and the inverted contact restitution covers 0.35."""
    from demcal.simulate.virtual_lab import PlantedEffect

    vw = write_virtual_workbook(Truth(), tmp_path / "lab", effects=(PlantedEffect("orientation_rotation"),),
                                rng=8, photos="none", pairs=("particle-steel",), drop_heights_mm=(400.0,),
                                n_drop=16, surfaces=("steel",), n_incline=6, n_tracks=0)
    c = run_critique(vw.path, rigs=("drop",), store_dir=tmp_path / "store")
    assert "orientation_rotation" in {f.mechanism for f in c.found()}                 # in the data
    assert "orientation_rotation" in {m.mechanism for m in c.model_findings if m.verdict == "found"}
    gain = next(g for g in c.extensions if g.name == "inverted_restitution")
    halves = gain.extension["values"]
    assert all(abs(v - 0.35) < 0.1 for v in halves), halves
