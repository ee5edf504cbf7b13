"""Screening against published analyses: Box & Meyer (1993) posteriors as printed by BsMD,
BHH's 2^5 reactor effects, Lenth's (1989) margins for Box & Meyer's (1986) y2, and the Pareto
limits by hand."""

import numpy as np
import pytest
from scipy import stats

from demcal.analyse.designs import plackett_burman
from demcal.analyse.screening import (box_meyer, lenth, pareto, plackett_burman_screening,
                               two_level_effects)
from demcal.errors import AnalysisError, InputError

FACTORS5 = list("ABCDE")


def ex1(external):
    d = external("screening_pb/bm93_ex1_reactor_pb12.csv")
    return d[FACTORS5].to_numpy(float), d.y.to_numpy(float)


# Published (BsMD vignette, BsProb(X, y, mFac=5, mInt=3, p=0.25, g=1.6) on BM93.e1.data;
# Box & Meyer 1993 Example 1): factor posteriors none 0.025, A 0.011, B 0.964, C 0.009,
# D 0.899, E 0.577; top models {B,D,E} 0.563 (sigma2 8.67), {B,D} 0.324 (sigma2 39.51).
# Printed to 3 decimals (sigma2 to 2).
def test_box_meyer_reactor_pb12_box_meyer1993(external):
    x, y = ex1(external)
    r = box_meyer(x, y, FACTORS5, prior=0.25, gamma=1.6, max_interaction=3)
    published = {"A": 0.011, "B": 0.964, "C": 0.009, "D": 0.899, "E": 0.577}
    for name, p in published.items():
        assert r.factor_probability[name] == pytest.approx(p, abs=5e-4), name
    assert r.none_probability == pytest.approx(0.025, abs=5e-4)
    top = r.top_models
    assert top[0]["factors"] == ("B", "D", "E") and top[1]["factors"] == ("B", "D")
    assert top[0]["probability"] == pytest.approx(0.563, abs=5e-4)
    assert top[1]["probability"] == pytest.approx(0.324, abs=5e-4)
    assert top[0]["sigma2"] == pytest.approx(8.67, abs=5e-3)
    assert top[1]["sigma2"] == pytest.approx(39.51, abs=5e-3)
    assert r.active() == ("B", "D", "E")  # the published active factors, B first
    assert r.n_models == 32


# Published (BsMD vignette, all 11 columns of PB12Des, same prior): x1 0.056, x2 0.881,
# x3 0.053, x4 0.823, x5 0.531, x6 0.065, x7 0.052, x8 0.067, x9 0.110, x10 0.052, x11 0.090.
def test_box_meyer_all_eleven_columns_box_meyer1993(external):
    _, y = ex1(external)
    x = plackett_burman(11, 12).coded  # the BHH matrix; rows match BM93.e1.data's
    names = [f"x{i + 1}" for i in range(11)]
    r = box_meyer(x, y, names, prior=0.25, gamma=1.6, max_interaction=3)
    published = [0.056, 0.881, 0.053, 0.823, 0.531, 0.065, 0.052, 0.067, 0.110, 0.052, 0.090]
    for name, p in zip(names, published):
        assert r.factor_probability[name] == pytest.approx(p, abs=5e-4), name


def test_pb_screening_reactor_ranks_b_first(external):
    x, y = ex1(external)
    dummies = plackett_burman(11, 12).coded[:, 5:]
    s = plackett_burman_screening(x, y, FACTORS5, dummies=dummies)
    assert s.ranking[0] == "B"
    assert set(s.ranking[:3]) == {"B", "D", "E"}  # published active factors lead the effects
    # Main-effects ANOVA with the 6 dummy columns as error flags B only: BD and DE are aliased
    # with main effects in a 12-run PB and swell the residual (why Box & Meyer's analysis is
    # needed to recover D and E).
    assert s.significant == ("B",)
    assert s.regression.fit.df_residual == 6
    # effects are twice the coefficients of the orthogonal fit; contributions add up with the
    # residual to 100 %
    for t in FACTORS5:
        assert s.effects[t] == pytest.approx(2 * s.coefficients[t], rel=1e-12)
    resid_pct = 100 * s.regression.anova_row("Residual").ss / s.regression.anova_row("Cor Total").ss
    assert sum(s.contribution_pct.values()) + resid_pct == pytest.approx(100.0, rel=1e-12)
    assert len(s.dummy_effects) == 6 and s.lenth is not None


# Published: Box & Meyer (gamma 1.5, mInt 2, BsMD vignette) - factors F and G stick out;
# ReliaSoft DOE++ names F the most important factor.
def test_cast_fatigue_f_first_box_meyer1993(external):
    d = external("screening_pb/bm93_ex2_castfatigue_pb12.csv")
    names = list("ABCDEFG")
    x, y = d[names].to_numpy(float), d.y.to_numpy(float)
    r = box_meyer(x, y, names, prior=0.25, gamma=1.5, max_interaction=2)
    assert r.active() == ("F", "G")
    s = plackett_burman_screening(x, y, names)
    assert s.ranking[0] == "F"
    assert s.pareto.names[0] == "F"


# Published (BHH): largest effects B 19.5, BD 13.25, DE -11.0, D 10.75, E -6.25 (exact:
# averages of 16 integers).
def test_reactor_2_5_effects_bhh2005(external):
    d = external("screening_pb/bhh_reactor_2_5_full_factorial.csv")
    e = two_level_effects(d[FACTORS5], d.y, max_order=5)
    assert len(e) == 31
    published = {"B": 19.5, "BD": 13.25, "DE": -11.0, "D": 10.75, "E": -6.25}
    for name, value in published.items():
        assert e[name] == pytest.approx(value, abs=1e-12), name
    largest = sorted(e, key=lambda k: -abs(e[k]))[:5]
    assert set(largest) == set(published)


# Published (BsMD vignette; Lenth 1989 on Box & Meyer 1986 column y2): PSE 0.225,
# ME 0.5783809, SME 1.1741965 (alpha 0.05); ME 0.9072322, SME 1.6855749 (alpha 0.01).
def test_lenth_bm86_y2_lenth1989(external):
    d = external("screening_pb/bm86_16run_fractional_factorials.csv")
    cols = [f"X{i}" for i in range(1, 16)]
    e = two_level_effects(d[cols], d.y2, cols)
    r5, r1 = lenth(e, 0.05), lenth(e, 0.01)
    assert r5.pse == pytest.approx(0.225, abs=1e-12)
    assert r5.me == pytest.approx(0.5783809, abs=5e-8)
    assert r5.sme == pytest.approx(1.1741965, abs=5e-8)
    assert r1.me == pytest.approx(0.9072322, abs=5e-8)
    assert r1.sme == pytest.approx(1.6855749, abs=5e-8)
    assert r5.d == 5 and set(r5.strongly_active) == {"X14", "X15"}


def test_pareto_limits_by_hand():
    chart = pareto({"A": -1.0, "B": 4.0, "C": 2.5}, df=6, alpha=0.05)
    assert chart.names == ("B", "C", "A") and chart.signs == (1, 1, -1)
    assert chart.t_limit == pytest.approx(stats.t.ppf(0.975, 6), rel=1e-12)   # 2.4469
    assert chart.bonferroni_limit == pytest.approx(stats.t.ppf(1 - 0.05 / 6, 6), rel=1e-12)
    with pytest.raises(AnalysisError):
        pareto({"A": 1.0}, df=0)


def test_screening_input_errors():
    with pytest.raises(InputError, match="coded levels -1/\\+1"):
        two_level_effects([[0.5, 1], [-1, 1]], [1, 2])
    with pytest.raises(InputError, match="prior must be in"):
        box_meyer(np.ones((4, 1)), [1, 2, 3, 4], prior=1.0)
