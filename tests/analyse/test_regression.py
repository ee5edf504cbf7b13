"""Response-surface regression and ANOVA against published fits (rsm vignette output for the
Myers et al. and BHH data, the source paper's equation 5 and fit statistics), statsmodels'
Type III ANOVA, and a brute-force leave-one-out PRESS."""

import numpy as np
import pytest

from demcal.analyse.designs import box_behnken, plackett_burman, to_coded
from demcal.analyse.regression import fit_response_surface, significance
from demcal.errors import AnalysisError, InputError
from tests.analyse.reference import PAPER_EQ5, paper_eq5


def chemreact(external):
    d = external("rsm_reference/chemreact_myers2009_table7_6.csv")
    # rsm coding: x1 = (Time - 85)/5, x2 = (Temp - 175)/5
    coded = to_coded(d[["Time", "Temp"]].to_numpy(), [80, 170], [90, 180])
    return d, coded


# --- ChemReact, block 1, first order ------------------------------------------------------
# Published (rsm vignette article-JSS v2.10.6, rsm(Yield ~ FO(x1, x2), data = CR1)):
# b = 82.81429, 0.87500, 0.62500; se 0.54719, 0.72386; lack of fit F 95.7335 p 0.01034,
# pure error SS 0.0867 (2 df); R2 0.3555, adj R2 0.0333.
def test_chemreact_block1_first_order_myers2009(external):
    d, coded = chemreact(external)
    b1 = (d.Block == "B1").to_numpy()
    fit = fit_response_surface(coded[b1], d.Yield[b1], "linear", factors=("Time", "Temp"),
                               low=[80, 170], high=[90, 180])
    c = fit.coefficients
    assert c["Intercept"] == pytest.approx(82.81429, abs=5e-6)
    assert c["A"] == pytest.approx(0.875, abs=5e-6)
    assert c["B"] == pytest.approx(0.625, abs=5e-6)
    assert fit.std_errors["Intercept"] == pytest.approx(0.54719, abs=5e-6)
    assert fit.std_errors["A"] == pytest.approx(0.72386, abs=5e-6)
    lof = fit.anova_row("Lack of Fit")
    assert lof.f == pytest.approx(95.7335, abs=5e-5)
    assert lof.p == pytest.approx(0.01034, abs=5e-6)
    assert (lof.df, fit.anova_row("Pure Error").df) == (2, 2)
    assert fit.anova_row("Pure Error").ss == pytest.approx(0.0867, abs=5e-5)
    assert fit.fit.r2 == pytest.approx(0.3555, abs=5e-5)
    assert fit.fit.adj_r2 == pytest.approx(0.0333, abs=5e-5)
    assert lof.significance == "significant"


# --- ChemReact, all 14 runs, block + second order ------------------------------------------
# Published (rsm vignette, rsm(Yield ~ Block + SO(x1, x2))), treatment coding of the block:
# Intercept 84.095427, Block2 -4.457530, x1 0.932541, x2 0.577712, x1x2 0.125, x1^2 -1.308555,
# x2^2 -0.933442; se x1 0.057699, x1x2 0.081592, x1^2 0.060064; R2 0.9981, adj 0.9964;
# lack of fit F 0.5307, p 0.6851 with pure error within blocks (4 df); Block SS 69.531;
# stationary point (86.86148 min, 176.67190 C).
def test_chemreact_blocked_second_order_myers2009(external):
    d, coded = chemreact(external)
    fit = fit_response_surface(coded, d.Yield, "quadratic", factors=("Time", "Temp"),
                               blocks=d.Block, low=[80, 170], high=[90, 180],
                               response_name="Yield")
    c, e = fit.coefficients, fit.block_effects
    # our blocks use sum-to-zero coding; convert to rsm's treatment coding
    assert c["Intercept"] + e["B1"] == pytest.approx(84.095427, abs=5e-6)
    assert e["B2"] - e["B1"] == pytest.approx(-4.457530, abs=5e-6)
    for ours, ref in [("A", 0.932541), ("B", 0.577712), ("AB", 0.125), ("A^2", -1.308555),
                      ("B^2", -0.933442)]:
        assert c[ours] == pytest.approx(ref, abs=5e-6), ours
    assert fit.std_errors["A"] == pytest.approx(0.057699, abs=5e-6)
    assert fit.std_errors["AB"] == pytest.approx(0.081592, abs=5e-6)
    assert fit.std_errors["A^2"] == pytest.approx(0.060064, abs=5e-6)
    assert fit.fit.r2_incl_blocks == pytest.approx(0.9981, abs=5e-5)
    assert fit.fit.adj_r2_incl_blocks == pytest.approx(0.9964, abs=5e-5)
    lof = fit.anova_row("Lack of Fit")
    assert lof.f == pytest.approx(0.5307, abs=5e-5)
    assert lof.p == pytest.approx(0.6851, abs=5e-5)
    assert (lof.df, fit.anova_row("Pure Error").df) == (3, 4)
    assert fit.anova_row("Block").ss == pytest.approx(69.531, abs=5e-4)
    sp = fit.stationary_point()
    assert sp["actual"]["Time"] == pytest.approx(86.86148, abs=5e-5)
    assert sp["actual"]["Temp"] == pytest.approx(176.67190, abs=5e-5)
    # Design-Expert convention: the block SS is removed from R2's denominator and from Model
    ss_block = fit.anova_row("Block").ss
    ss_tot = fit.anova_row("Cor Total").ss
    ss_res = fit.anova_row("Residual").ss
    assert fit.fit.r2 == pytest.approx(1 - ss_res / (ss_tot - ss_block), rel=1e-12)
    assert fit.anova_row("Model").ss + ss_block + ss_res == pytest.approx(ss_tot, rel=1e-12)


def test_pure_error_is_taken_within_blocks(external):
    d, coded = chemreact(external)
    blocked = fit_response_surface(coded, d.Yield, blocks=d.Block)
    # the 3 + 3 centre runs of the two blocks: 2 + 2 df within blocks
    y = d.Yield.to_numpy()
    centres = np.all(coded == 0, axis=1)
    by_hand = sum(np.sum((y[centres & (d.Block == b)] - y[centres & (d.Block == b)].mean()) ** 2)
                  for b in ("B1", "B2"))
    assert blocked.anova_row("Pure Error").ss == pytest.approx(by_hand, rel=1e-12)
    assert blocked.anova_row("Pure Error").df == 4


# --- Helicopter, BHH 2005 Table 12.5 -------------------------------------------------------
# Published (rsm vignette, ave ~ block + SO(x1..x4)): all 16 coefficients (treatment-coded
# block), R2 0.9555, adj 0.9078, lack of fit F 4.666 p 0.0755; se linear 0.636560,
# interaction 0.779623, quadratic 0.603894.
HELI_COEF = {"x1": -0.083333, "x2": 5.083333, "x3": 0.250000, "x4": -6.083333,
             "x1x2": -2.875, "x1x3": -3.750, "x1x4": 4.375, "x2x3": 4.625, "x2x4": -1.500,
             "x3x4": -2.125, "x1sq": -2.0375, "x2sq": -1.6625, "x3sq": -2.5375, "x4sq": -0.1625}


def heli_name(ref):
    letters = {"1": "A", "2": "B", "3": "C", "4": "D"}
    if ref.endswith("sq"):
        return letters[ref[1]] + "^2"
    return "".join(letters[ch] for ch in ref if ch.isdigit())


def test_helicopter_bhh2005(external):
    d = external("rsm_reference/heli_bhh2005_table12_5.csv")
    fit = fit_response_surface(d[["x1", "x2", "x3", "x4"]], d.ave_flight_csec, blocks=d.block)
    c, e = fit.coefficients, fit.block_effects
    assert c["Intercept"] + e["1"] == pytest.approx(372.8, abs=5e-6)
    assert e["2"] - e["1"] == pytest.approx(-2.95, abs=5e-6)
    for ref, value in HELI_COEF.items():
        assert c[heli_name(ref)] == pytest.approx(value, abs=5e-6), ref
    assert fit.std_errors["A"] == pytest.approx(0.636560, abs=5e-6)
    assert fit.std_errors["AB"] == pytest.approx(0.779623, abs=5e-6)
    assert fit.std_errors["A^2"] == pytest.approx(0.603894, abs=5e-6)
    assert fit.fit.r2_incl_blocks == pytest.approx(0.9555, abs=5e-5)
    assert fit.fit.adj_r2_incl_blocks == pytest.approx(0.9078, abs=5e-5)
    lof = fit.anova_row("Lack of Fit")
    assert lof.f == pytest.approx(4.666, abs=5e-4)
    assert lof.p == pytest.approx(0.0755, abs=5e-5)


# --- Type III against statsmodels -----------------------------------------------------------
def test_type3_sums_of_squares_match_statsmodels(external):
    import statsmodels.formula.api as smf
    from statsmodels.stats.anova import anova_lm

    d = external("rsm_reference/heli_bhh2005_table12_5.csv").rename(
        columns={"ave_flight_csec": "y"})
    terms = ["x1", "x2", "x3", "x4", "x1:x2", "x1:x3", "x1:x4", "x2:x3", "x2:x4", "x3:x4",
             "I(x1 ** 2)", "I(x2 ** 2)", "I(x3 ** 2)", "I(x4 ** 2)"]
    sm = smf.ols("y ~ C(block, Sum) + " + " + ".join(terms), data=d).fit()
    table = anova_lm(sm, typ=3)
    ours = fit_response_surface(d[["x1", "x2", "x3", "x4"]], d.y, blocks=d.block)
    names = ["A", "B", "C", "D", "AB", "AC", "AD", "BC", "BD", "CD", "A^2", "B^2", "C^2", "D^2"]
    for sm_name, name in zip(terms, names):
        row = ours.anova_row(name)
        assert row.ss == pytest.approx(table.loc[sm_name, "sum_sq"], rel=1e-9), name
        assert row.f == pytest.approx(table.loc[sm_name, "F"], rel=1e-9), name
        assert row.p == pytest.approx(table.loc[sm_name, "PR(>F)"], rel=1e-7), name
    assert ours.anova_row("Residual").ss == pytest.approx(table.loc["Residual", "sum_sq"],
                                                          rel=1e-9)


def test_press_matches_leave_one_out_refits(external):
    d = external("rsm_reference/zhang2021_scirep_bbd17_essential_oil.csv")
    x = d[["x_R_coded", "x_t_coded", "x_P_coded"]].to_numpy(float)
    y = d.Y_yield_pct.to_numpy(float)
    fit = fit_response_surface(x, y)
    press = 0.0
    for i in range(len(y)):  # second implementation: actually drop each run and refit
        keep = np.arange(len(y)) != i
        sub = fit_response_surface(x[keep], y[keep])
        press += (y[i] - sub.predict(x[i])) ** 2
    assert fit.fit.press == pytest.approx(press, rel=1e-9)
    assert fit.fit.pred_r2 == pytest.approx(1 - press / np.sum((y - y.mean()) ** 2), rel=1e-9)


# --- The source paper's equation 5 ----------------------------------------------------------
# The source paper's eq. 5 and fit statistics: see tests/analyse/reference.py.
def test_paper_eq5_refits_exactly():
    x = box_behnken(3, 5).coded
    fit = fit_response_surface(x, paper_eq5(x), response_name="angle")
    for name, value in PAPER_EQ5.items():
        assert fit.coefficients[name] == pytest.approx(value, abs=1e-10), name
    assert fit.fit.r2 == pytest.approx(1.0, abs=1e-12)


def test_paper_fit_statistics_from_eq5_and_r2():
    """The paper's adj R2, C.V. and Adeq Precision follow from eq. 5 and its R2 alone.

    Responses = eq. 5 + residuals orthogonal to the model (so the fit returns eq. 5 exactly)
    scaled so that R2 = 0.9717; the published adj R2, C.V. % and Adeq Precision are then
    independent checks of those three formulas (p = 10 parameters, n = 17 runs).
    Tolerances: R2 is printed to 4 decimals (+-5e-5), which moves adj R2 by +-1.1e-4, C.V. by
    +-0.1 % of itself and Adeq Precision by +-0.021; plus the rounding of each published value.
    """
    x = box_behnken(3, 5).coded
    yhat = paper_eq5(x)
    ss_model = np.sum((yhat - yhat.mean()) ** 2)
    ss_res = ss_model * (1 - 0.9717) / 0.9717
    v = np.random.default_rng(5).normal(size=17)
    Xm = np.column_stack([np.ones(17), x, x[:, 0] * x[:, 1], x[:, 0] * x[:, 2], x[:, 1] * x[:, 2],
                          x ** 2])
    e = v - Xm @ np.linalg.lstsq(Xm, v, rcond=None)[0]
    e *= np.sqrt(ss_res / np.sum(e ** 2))
    fit = fit_response_surface(x, yhat + e)
    for name, value in PAPER_EQ5.items():
        assert fit.coefficients[name] == pytest.approx(value, abs=1e-9), name
    assert fit.fit.r2 == pytest.approx(0.9717, abs=1e-12)
    assert fit.fit.adj_r2 == pytest.approx(0.9354, abs=1.7e-4)
    assert fit.fit.cv_pct == pytest.approx(1.25, abs=0.0065)
    assert fit.fit.adeq_precision == pytest.approx(22.7736, abs=0.025)
    assert fit.anova_row("Model").significance == "highly significant"
    assert (fit.fit.n_parameters, fit.fit.n_runs) == (10, 17)


# --- Actual equation and housekeeping -------------------------------------------------------
def test_actual_equation_is_exact_expansion():
    x = box_behnken(3, 5).coded
    low, high = np.array([0.2, 0.30, 0.1]), np.array([0.4, 0.40, 0.3])
    fit = fit_response_surface(x, paper_eq5(x), factors=("e_pp", "e_ps", "mu_s_ps"),
                               low=low, high=high)
    pts = np.random.default_rng(7).uniform(low, high, size=(50, 3))
    ca = fit.coefficients_actual
    a, b, c = pts.T
    by_hand = (ca["Intercept"] + ca["A"] * a + ca["B"] * b + ca["C"] * c + ca["AB"] * a * b
               + ca["AC"] * a * c + ca["BC"] * b * c + ca["A^2"] * a ** 2 + ca["B^2"] * b ** 2
               + ca["C^2"] * c ** 2)
    assert np.allclose(by_hand, fit.predict_actual(pts), rtol=0, atol=1e-10)
    # hand: the A^2 coefficient in actual units is 0.7408 / 0.1^2
    assert ca["A^2"] == pytest.approx(74.08, rel=1e-12)
    assert "e_pp * e_ps" in fit.equation_actual and fit.equation_coded.startswith("y = +35.65")


def test_aliased_model_is_refused_naming_terms():
    x = plackett_burman(5, 12).factors
    with pytest.raises(AnalysisError, match="aliased or inestimable terms: .*\\^2"):
        fit_response_surface(x, np.arange(12.0), "quadratic")


def test_bad_inputs_name_the_problem():
    x = box_behnken(3, 5).coded
    with pytest.raises(InputError, match="unknown model 'cubic'; valid models: linear, 2fi"):
        fit_response_surface(x, np.zeros(17), "cubic")
    with pytest.raises(InputError, match="response has 16 values"):
        fit_response_surface(x, np.zeros(16))
    with pytest.raises(InputError, match="response is not finite at run 3"):
        fit_response_surface(x, np.r_[0, 0, np.nan, np.zeros(14)])
    with pytest.raises(InputError, match="cannot read model term 'AX'"):
        fit_response_surface(x, np.zeros(17), terms=["A", "AX"])


def test_reduced_model_terms_and_significance_bands():
    x = box_behnken(3, 5).coded
    fit = fit_response_surface(x, paper_eq5(x) + 0.01 * np.arange(17), terms=["A", "B", "AB"])
    assert fit.terms == ("A", "B", "AB") and fit.model == "custom"
    assert [significance(p) for p in (0.001, 0.03, 0.2, None)] == [
        "highly significant", "significant", "not significant", None]
    out = fit.to_dict()
    assert [r["source"] for r in out["anova"]] == ["Model", "A", "B", "AB", "Residual",
                                                   "Lack of Fit", "Pure Error", "Cor Total"]
    assert list(out["coefficients"]) == ["Intercept", "A", "B", "AB"]
