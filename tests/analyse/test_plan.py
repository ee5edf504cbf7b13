"""``demcal plan``: the smallest detectable effect it prints is detected as often as it says when
the effect is planted in fresh virtual workbooks and the critique run on each; its search and
intervals against hand-made curves and the binomial tails; the design it reads from a workbook."""

import json
import math
import re

import pytest
import yaml
from scipy import stats

from demcal.analyse.critique import run_critique
from demcal.analyse.critique.plan import (ORIENTATION_GRID, choose_target, clopper_pearson, design_from_workbook,
                                          orientation_design, read_design, smallest_reaching)
from demcal.cli import main
from demcal.errors import DemcalError, InputError
from demcal.simulate.virtual_lab import PlantedEffect, Truth, write_virtual_workbook

#: A small design (one drop pair from three heights, no incline, compression or photos): the
#: workbooks take a few hundredths of a second each.
SMALL = {"design": {"pairs": ["particle-steel"], "drop_heights_mm": [200, 400, 600], "n_drop": 8,
                    "surfaces": [], "n_compression": 0, "n_tracks": 0, "n_specimens": 12, "n_density": 3,
                    "photos": "none"}}


@pytest.mark.parametrize("k,n", [(0, 20), (3, 20), (16, 20), (20, 20), (117, 150)])
def test_clopper_pearson_bounds_have_their_defining_binomial_tails(k, n):
    """The exact interval's bounds are where each binomial tail of k holds 2.5 %: P(X >= k | lo)
    and P(X <= k | hi); 0 and 1 at the edges."""
    lo, hi = clopper_pearson(k, n)
    assert lo == 0.0 if k == 0 else stats.binom.sf(k - 1, n, lo) == pytest.approx(0.025, abs=1e-9)
    assert hi == 1.0 if k == n else stats.binom.cdf(k, n, hi) == pytest.approx(0.025, abs=1e-9)
    assert clopper_pearson(k, n, level=0.99)[0] <= lo and clopper_pearson(k, n, level=0.99)[1] >= hi


def _probit_rate(x80, n=1000, slope=4.0):
    """Detection counts of a known power curve, Phi(0.8416 + slope log(x / x80))."""
    def rate(x):
        return int(round(n * stats.norm.cdf(stats.norm.ppf(0.8) + slope * math.log(x / x80)))), n
    return rate


@pytest.mark.parametrize("start", [1e-3, 0.04, 1.0])
def test_search_brackets_and_bisects_a_known_power_curve(start):
    found = smallest_reaching(_probit_rate(0.037), start, steps=6)
    assert found.reached and not found.at_floor
    assert found.hits >= 0.8 * found.n
    below = [x for x, k, n in found.points if k < 0.8 * n]
    assert 0.037 <= found.strength <= 0.037 * 2 ** (1 / 2 ** 6) * 1.01       # within one step above
    assert max(below) < found.strength


def test_search_says_when_the_target_is_out_of_reach():
    never = smallest_reaching(lambda x: (int(10 * min(x / 100, 0.5)), 10), 10.0, limit=90.0)
    assert not never.reached and never.strength == 90.0
    always = smallest_reaching(lambda x: (10, 10), 1.0)
    assert always.reached and always.at_floor and always.strength == pytest.approx(2.0 ** -6, rel=0.01)
    with pytest.raises(InputError, match="target power"):
        smallest_reaching(lambda x: (1, 1), 1.0, target=1.0)


def _table_row(out: str, mechanism: str) -> list:
    line = next(line for line in out.splitlines() if line.startswith(mechanism))
    return line.split()


def test_printed_power_is_the_direct_detection_rate(tmp_path, capsys):
    """The plan says size S is detected in at least 80 % of its workbooks; the critique on 200
    fresh workbooks (other seeds) with S planted detects it as often: the two rates are one
    binomial proportion (Fisher's exact test), and the target 80 % lies within two joint standard
    errors of the direct rate."""
    truth = tmp_path / "truth.yaml"
    truth.write_text(yaml.safe_dump(SMALL))
    kind = "velocity_dependent_restitution"
    assert main(["plan", str(truth), "--mechanisms", kind, "--reps", "60", "--seed", "7",
                 "--json", str(tmp_path / "plan.json")]) == 0
    out = capsys.readouterr().out
    plan = json.loads((tmp_path / "plan.json").read_text())
    (row,) = plan["mechanisms"]
    assert row["reached"] and row["n"] == 60 and row["sheet"] == "drop"
    # the printed row: mechanism, sheet, covariate, size, hits/n, interval
    cells = _table_row(out, kind)
    assert cells[1:3] == ["drop", "drop_height_mm"]
    assert float(cells[3]) == pytest.approx(row["size"], rel=1e-3)
    hits, n = (int(v) for v in cells[4].split("/"))
    assert (hits, n) == (row["hits"], row["n"]) and hits >= 0.8 * n
    ci = [float(v) for v in re.findall(r"[\d.]+", " ".join(cells[5:7]))]
    assert ci == pytest.approx(clopper_pearson(hits, n), abs=0.006)
    # a smaller size tried fell short of 80 %
    assert any(p["hits"] < 0.8 * p["n"] and abs(p["size"]) < abs(row["size"]) for p in row["points"])
    # where to drop: every pair of the design at every orientation of the grid, printed and kept
    assert "where to drop" in out
    assert {(r["pair"], r["orientation_deg"]) for r in plan["drop_orientations"]} == \
        {(pair, float(a)) for pair in SMALL["design"]["pairs"] for a in ORIENTATION_GRID}

    spec = read_design(truth)
    direct, reps = 0, 200
    for seed in range(10_000, 10_000 + reps):              # plain seeds, not the plan's SeedSequence
        vw = write_virtual_workbook(spec.truth, tmp_path / "direct", rng=seed,
                                    effects=(PlantedEffect(kind, size=row["size"]),), **spec.design)
        try:
            critique = run_critique(vw.path, twins=False, extensions=())
        except DemcalError:
            continue                    # a workbook the critique cannot read names nothing
        direct += any(f.mechanism == kind for f in critique.found())
    # the plan's rate at S and the direct one are one binomial proportion
    p_same = stats.fisher_exact([[hits, n - hits], [direct, reps - direct]]).pvalue
    assert p_same > 0.05, (hits, n, direct, reps)
    # and the target power is the direct rate within their joint sampling error (S was chosen on
    # the plan's 60 workbooks, so its power is known to about 5 %, the direct rate to about 3 %)
    rate = direct / reps
    se = math.sqrt(0.8 * 0.2 / n + rate * (1 - rate) / reps)
    assert abs(rate - 0.8) < 1.96 * se, (direct, reps)


def test_design_and_truth_read_back_from_a_virtual_workbook(tmp_path):
    truth = Truth(params=Truth().params.with_(e_pw=0.5, mu_s_pw=0.3), e_sd=0.02)
    vw = write_virtual_workbook(truth, tmp_path / "wb", rng=3, photos="none", drop_heights_mm=(300.0, 500.0),
                                n_drop=7, surfaces=("steel",), n_incline=12, n_compression=4, n_tracks=1)
    lab = design_from_workbook(vw.path)
    d = lab.design
    assert d["pairs"] == ["particle-particle", "particle-steel"] and d["drop_heights_mm"] == [300.0, 500.0]
    assert (d["n_drop"], d["surfaces"], d["n_incline"], d["n_compression"], d["n_tracks"]) == (7, ["steel"], 12, 4, 1)
    assert (d["n_specimens"], d["n_density"], d["photos"]) == (30, 5, "none")
    lo, hi = d["orientation_range_deg"]
    assert 80.0 <= lo < hi <= 90.0
    p = lab.truth.params
    assert p.e_pw == pytest.approx(0.5, abs=0.02) and p.mu_s_pw == pytest.approx(0.3, abs=0.02)
    assert lab.truth.e_sd == pytest.approx(0.02, abs=0.006) and lab.truth.height_noise_mm == 0.0
    assert lab.truth.operators == ("op1", "op2")
    assert {"drop_height_mm", "operator", "trial_order", "length_mm", "moisture_pct"} <= lab.varied["drop"]
    assert "date" not in lab.varied["incline"]                # one day in a clean virtual workbook


def test_mechanisms_the_design_cannot_test_are_named_not_simulated(tmp_path):
    truth = tmp_path / "truth.yaml"
    truth.write_text(yaml.safe_dump({"design": {"drop_heights_mm": [400], "surfaces": []}}))
    lab = read_design(truth)
    target, reason = choose_target("velocity_dependent_restitution", lab)
    assert target is None and "one height (400 mm)" in reason
    target, _ = choose_target("trial_order_drift", lab)       # no incline: planted in the drops
    assert (target.sheet, target.covariate, target.unit) == ("drop", "trial_order", "e per trial")
    assert choose_target("camera_tilt", lab)[1].startswith("no heap photos")


def test_plan_errors_are_one_line(tmp_path, capsys):
    assert main(["plan", str(tmp_path / "none.yaml")]) == 2
    assert "not found" in capsys.readouterr().err
    truth = tmp_path / "truth.yaml"
    truth.write_text(yaml.safe_dump(SMALL))
    assert main(["plan", str(truth), "--mechanisms", "wet_segments"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "valid: velocity_dependent_restitution" in err


def test_orientation_design_reads_the_twins_sensitivity_to_the_contact_restitution():
    """End on, one contact through the centre of mass: the rebound is the contact restitution,
    d apparent / d e = 1. Tilted, on a stiff frictionless plate, the twin's sensitivity is the
    rigid body's (``simulate.rigid_impact``, differenced the same way) within 0.1."""
    from demcal.simulate.extensions import with_contact_effective_mass
    from demcal.simulate.params import DEMParameters
    from demcal.simulate.rigid_impact import rigid_drop

    (end_on,) = orientation_design(DEMParameters(), ["particle-steel"], 0.4, grid=(90,))
    assert end_on.sensitivity == pytest.approx(1.0, abs=0.03)
    stiff = with_contact_effective_mass(DEMParameters(e_pw=0.36, mu_s_pw=0.0, mu_r_pw=0.0, shear_modulus_pa=1e10))
    body = stiff.template()
    for row in orientation_design(stiff, ["particle-steel"], 0.1, grid=(10, 30, 60)):
        rigid = [rigid_drop(body, row.orientation_deg, e, 0.1).apparent_restitution for e in (0.31, 0.41)]
        assert row.sensitivity == pytest.approx((rigid[1] - rigid[0]) / 0.1, abs=0.1), row
