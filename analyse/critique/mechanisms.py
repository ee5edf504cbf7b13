"""The catalogue of candidate mechanisms: what could make the calibrated model wrong, the
statistical signature that tests each one, and its verdict.

Every mechanism is judged from tests (``analyse.critique.diagnosis``), never asserted:

- ``found``: at least one test of its signature is significant after the multiple-testing
  correction *and* reaches the practical threshold (and has the expected sign, where the
  mechanism has one), and no other selected covariate of the same series explains it
  (``diagnosis.explain_away``); one finding per such test, the strongest first;
- ``ruled_out``: the data exclude a relevant effect: every test of its signature has its 95 %
  interval within the practical threshold (``CovariateTest.excludes_relevant``), or is
  explained by another covariate; the finding shows the test that comes closest to the
  threshold, so the reader sees how large an effect is excluded;
- ``inconclusive``: neither: some test's interval reaches the threshold without the test
  being significant after the correction. The finding shows the test closest to significance
  and the rows of that design that would find an effect of the threshold's size with 80 %
  power (``CovariateTest.rows_to_decide``);
- ``not_testable``: the data lack the covariate or its variation (one drop height, no
  orientation logged, no two-flank photo, no campaign), with the reason.

Every finding carries its ``reason``: the bar it passed or missed, in words.

Catalogue (``CATALOGUE``):

=================================  ==========================================================
mechanism                          signature
=================================  ==========================================================
velocity_dependent_restitution     a drop sheet series (restitution or its twin residual)
                                   falls with ``drop_height_mm`` (slope < 0)
orientation_rotation               data: a drop series varies with ``orientation_deg``; model:
                                   the drop twin, its damping corrected, rebounds below its
                                   contact restitution (an elongated body turns part of its
                                   energy into rotation: sqrt(h2/h1) is not the contact
                                   restitution) (``attribution``)
contact_effective_mass             model only: at the logged orientations the twin rebounds
                                   below the rigid-body reference (``rigid_impact``; landing
                                   flat, the contact restitution), and the twin with the hook
                                   on against off closes the gap to the drops (``attribution``)
size_dependence                    a series of a test sheet varies with the specimen's
                                   calliper sizes (``length_mm``, ``diameter_mm``, ...) or ``mass_g``
block_effect                       a series differs between the levels of a categorical
                                   covariate (operator, date, batch, ...)
trial_order_drift                  a series trends with trial order
moisture_dependence                a series tracks ``moisture_pct``
camera_tilt                        the heap photos' left and right flanks differ on average,
                                   or the floor is tilted on average
ill_conditioned_parameter          a parameter carried into the response-surface design has
                                   no term exceeding the DEM's seed-to-seed noise (the repose
                                   response cannot identify it), from the campaign's
                                   ``effects_vs_noise`` / ``terms_vs_noise``
=================================  ==========================================================

A significant and relevant test that matches no signature (a numeric covariate the catalogue
does not know, or a rising restitution with drop height) is reported as ``other_covariate``
so that nothing found is hidden.
"""

from __future__ import annotations

import math
import re
from dataclasses import asdict, dataclass

import numpy as np
from scipy import stats

from demcal.analyse.critique.diagnosis import SPECIMEN_SIZE, adjust_pvalues

#: Column-name patterns of trial order.
ORDER_NAMES = re.compile(r"(^|_)(trial_?order|order|sequence|run_?order|trial_?no|trial_?number)$")


@dataclass(frozen=True)
class Mechanism:
    """A catalogue entry.

    Attributes
    ----------
    id : str
    title : str
    signature : str
        What is tested.
    remedy : str
        Model extension (``simulate.extensions``) or lab action that answers it.
    sign : int
        Expected sign of the effect (-1, +1), 0 for any.
    model_only : bool
        A cause of a twin's discrepancy with no signature in the lab data alone
        (``analyse.critique.attribution``); ``judge`` does not rule on it.
    """

    id: str
    title: str
    signature: str
    remedy: str
    sign: int = 0
    model_only: bool = False

    def to_dict(self) -> dict:
        return asdict(self)


CATALOGUE = (
    Mechanism("velocity_dependent_restitution", "restitution falls with impact speed",
              "drop restitution (or its twin residual) against drop_height_mm, slope < 0",
              "extension velocity_dependent_restitution (e(v) fitted from the drops)", sign=-1),
    Mechanism("orientation_rotation", "elongated body: energy into rotation at impact",
              "data: drop restitution against orientation_deg; model: the twin's apparent restitution "
              "below its contact e with the damping corrected",
              "extension inverted_restitution (contact e from the drop twin); more_spheres"),
    Mechanism("contact_effective_mass", "dashpots damp the whole mass where a contact moves less of it",
              "model: the twin's rebound at the logged orientations below the rigid-body reference (a flat "
              "landing's: its contact e), and the twin with the hook on against off closes the gap to the drops",
              "extension contact_effective_mass (dashpots damp the effective mass at each contact)",
              model_only=True),
    Mechanism("size_dependence", "response depends on particle size",
              "series against the specimen's calliper sizes (length_mm, diameter_mm, ...) and mass_g",
              "extension size_distribution (particles drawn from the callipers)"),
    Mechanism("block_effect", "operator, day or batch effect",
              "one-way ANOVA over a categorical covariate",
              "lab: correct or randomise the blocks; calibrate per block"),
    Mechanism("trial_order_drift", "drift with trial order (wear, drying, fatigue)",
              "series against trial order", "lab: randomise the order, renew specimens"),
    Mechanism("moisture_dependence", "friction or restitution tracks moisture",
              "series against moisture_pct", "lab: condition the specimens; calibrate at the target moisture"),
    Mechanism("camera_tilt", "camera roll or floor tilt in the heap photos",
              "mean left-minus-right flank difference; mean floor tilt",
              "lab: level the camera and floor, photograph both flanks"),
    Mechanism("ill_conditioned_parameter", "calibrated parameter not identifiable by the repose angle",
              "response-surface terms of the parameter against the seed-to-seed noise",
              "fix the parameter from its own test (e.g. restitution from the drop twin)"),
)

MECHANISMS = {m.id: m for m in CATALOGUE}


def classify(series: str, sheet: str, covariate: str, categorical: bool) -> str:
    """Catalogue id whose signature a test of ``series`` against ``covariate`` belongs to
    (``other_covariate`` if none)."""
    cov = covariate.lower()
    if series.endswith("flank_difference_deg") or series.endswith("base_tilt_deg"):
        return "camera_tilt"
    if cov == "orientation_deg":
        return "orientation_rotation"
    if cov == "drop_height_mm" and sheet == "drop":
        return "velocity_dependent_restitution"
    if categorical:
        return "block_effect"
    if cov in SPECIMEN_SIZE and sheet != "specimens":
        return "size_dependence"
    if ORDER_NAMES.search(cov):
        return "trial_order_drift"
    if "moisture" in cov:
        return "moisture_dependence"
    return "other_covariate"


def mechanism_of(test) -> str:
    """Catalogue id of a :class:`~analyse.critique.diagnosis.CovariateTest`."""
    return classify(test.series, test.sheet, test.covariate, test.method == "anova")


#: Verdicts on a mechanism (see the module docstring).
VERDICTS = ("found", "ruled_out", "inconclusive", "not_testable")


@dataclass(frozen=True)
class Finding:
    """The verdict on a mechanism, with the evidence of one test.

    Attributes
    ----------
    mechanism : str
    verdict : str
        ``found``, ``ruled_out``, ``inconclusive`` or ``not_testable`` (``VERDICTS``).
    sheet, covariate, quantity : str or None
        Where the evidence is (``quantity``: the series, e.g. ``restitution.particle-steel``,
        ``residual:restitution.particle-steel``).
    source : str or None
        ``measured``, ``twin residual``, ``twin`` or ``campaign``.
    effect : float or None
        Effect size in natural units (slope per covariate unit, range of level means, mean).
    ci95 : list of float or None
        95 % interval of ``effect``: for a found effect the false-coverage-rate interval of
        the selected effects (``diagnosis``, Benjamini & Yekutieli 2005), else the marginal
        Student-t interval (also in ``evidence``).
    effect_unit : str or None
    p_adjusted : float or None
    evidence : str
        One sentence with the numbers.
    reason : str
        Why the verdict: the bars the test passed or missed.
    rows_to_decide : int or None
        For ``inconclusive``: rows of that design that would find an effect of the practical
        threshold's size with 80 % power.
    """

    mechanism: str
    verdict: str
    sheet: str | None = None
    covariate: str | None = None
    quantity: str | None = None
    source: str | None = None
    effect: float | None = None
    ci95: list | None = None
    effect_unit: str | None = None
    p_adjusted: float | None = None
    evidence: str = ""
    reason: str = ""
    rows_to_decide: int | None = None

    def to_dict(self) -> dict:
        """Flat, JSON-ready (the keys the report's critique table shows)."""
        return {"mechanism": self.mechanism, "verdict": self.verdict, "sheet": self.sheet,
                "covariate": self.covariate, "effect": self.effect,
                "ci95": None if self.ci95 is None else [float(c) for c in self.ci95],
                "p_adjusted": self.p_adjusted, "quantity": self.quantity, "source": self.source,
                "effect_unit": self.effect_unit, "evidence": self.evidence, "reason": self.reason,
                "rows_to_decide": self.rows_to_decide}

    @classmethod
    def from_dict(cls, d: dict) -> "Finding":
        return cls(**d)


def _fmt(x, digits=3) -> str:
    return "nan" if x is None or not np.isfinite(x) else f"{x:.{digits}g}"


def _evidence(t, verdict: str) -> str:
    size = (f"{_fmt(t.effect)} {t.effect_unit} [{_fmt(t.ci95[0])}, {_fmt(t.ci95[1])}] (marginal 95 %)")
    over = (f", {_fmt(t.practical)} over the observed range of {t.covariate}" if t.span is not None
            else "")
    bar = f"practical threshold {_fmt(t.threshold)}"
    return (f"{t.series} ({t.source}, sheet {t.sheet}) vs {t.covariate}: {t.method} effect {size}{over}; "
            f"p {_fmt(t.p_value)}, adjusted {_fmt(t.p_adjusted)}; {bar}")


def _finding(mech: str, verdict: str, t, note: str = "", reason: str = "", rows=None) -> Finding:
    ci = t.ci_selected if verdict == "found" and t.ci_selected is not None else t.ci95
    return Finding(mechanism=mech, verdict=verdict, sheet=t.sheet, covariate=t.covariate,
                   quantity=t.series, source=t.source, effect=float(t.effect),
                   ci95=[float(ci[0]), float(ci[1])], effect_unit=t.effect_unit,
                   p_adjusted=float(t.p_adjusted), evidence=(note + _evidence(t, verdict)),
                   reason=reason, rows_to_decide=rows)


FOUND_REASON = "significant after the multiple-testing correction and above the practical threshold"


def _excluded_reason(t, sign: int = 0) -> str:
    if t.explained_by:
        return f"explained by {t.explained_by} (its effect vanishes with {t.explained_by} in the model)"
    return (f"95 % interval within the practical threshold: at most {_fmt(t.largest_admitted(sign))} "
            f"over the data against {_fmt(t.threshold)}")


def _open_reason(t, rows, sign: int = 0) -> str:
    why = f"adjusted p {_fmt(t.p_adjusted)}" + (", below the level but under the threshold"
                                                if t.significant else "")
    need = (f"; about {rows} rows of this design (it has {t.n}) would find an effect of the "
            f"threshold's size with 80 % power" if rows is not None else "")
    return (f"not excluded: its 95 % interval admits {_fmt(t.largest_admitted(sign))} over the data, "
            f"beyond the practical threshold {_fmt(t.threshold)}; not found: {why}{need}")


def judge(tests, untestable=(), *, notes: dict | None = None) -> list:
    """Verdicts of the catalogue's workbook mechanisms (every entry but
    ``ill_conditioned_parameter``) and ``other_covariate`` findings.

    Parameters
    ----------
    tests : list of CovariateTest
        Adjusted tests (``diagnosis.run_tests``).
    untestable : list of Untestable
        Pairs that could not be tested (their reasons feed ``not_testable``).
    notes : dict, optional
        Mechanism -> reason to use for ``not_testable`` when no test of it exists.

    Returns
    -------
    list of Finding
        Found ones first (by adjusted p), then inconclusive, ruled out, not testable.
    """
    notes = dict(notes or {})
    by_mech: dict = {}
    for t in tests:
        by_mech.setdefault(mechanism_of(t), []).append(t)
    skipped: dict = {}
    for u in untestable:
        skipped.setdefault(classify(u.series, u.sheet, u.covariate, u.kind == "categorical"), []).append(u)

    found, open_, ruled, untest = [], [], [], []
    for mech in [m.id for m in CATALOGUE if m.id != "ill_conditioned_parameter" and not m.model_only] + ["other_covariate"]:
        ts = by_mech.get(mech, [])
        sign = MECHANISMS[mech].sign if mech in MECHANISMS else 0
        hits = [t for t in ts if t.significant and t.relevant and t.explained_by is None
                and (sign == 0 or np.sign(t.effect) == sign)]
        # a trend found where its straight line is found too says nothing more
        lines = {(t.series, t.covariate) for t in hits if t.method == "line"}
        hits = [t for t in hits if t.method != "trend" or (t.series, t.covariate) not in lines]
        if mech == "velocity_dependent_restitution":
            # a significant rise with height is not this mechanism: report it as unexplained
            for t in ts:
                if t.significant and t.relevant and t.explained_by is None and np.sign(t.effect) > 0:
                    found.append(_finding("other_covariate", "found", t,
                                          "restitution rises with drop height, against the catalogue's "
                                          "signature: ", reason=FOUND_REASON))
        for t in sorted(hits, key=lambda t: t.p_adjusted):
            found.append(_finding(mech, "found", t, reason=FOUND_REASON))
        if hits or mech == "other_covariate":
            continue
        if ts:
            # ruled out only where the data exclude a relevant effect; a relevant interval that
            # misses the corrected level is open, with the rows that would decide it
            unsettled = [t for t in ts if t.explained_by is None and not t.excludes_relevant(sign)]
            if unsettled:
                best = min(unsettled, key=lambda t: (t.p_value, -t.practical))
                rows = best.rows_to_decide()
                open_.append(_finding(mech, "inconclusive", best,
                                      f"{len(ts)} test(s), none found, {len(unsettled)} not excluding a "
                                      "relevant effect; closest to significance: ",
                                      reason=_open_reason(best, rows, sign), rows=rows))
            else:
                best = max(ts, key=lambda t: t.largest_admitted(sign) / t.threshold)
                ruled.append(_finding(mech, "ruled_out", best,
                                      f"{len(ts)} test(s), each excluding a relevant effect or explained "
                                      "by another covariate; closest to the threshold: ",
                                      reason=_excluded_reason(best, sign)))
            continue
        reason = notes.get(mech)
        if reason is None:
            reasons = [f"{u.series} vs {u.covariate}: {u.reason}" for u in skipped.get(mech, [])]
            reason = "; ".join(reasons[:3]) if reasons else _missing_reason(mech)
        untest.append(Finding(mechanism=mech, verdict="not_testable", evidence=reason,
                              reason="no test of its signature: " + reason))
    return found + open_ + ruled + untest


def _missing_reason(mech: str) -> str:
    return {"velocity_dependent_restitution": "no drop sheet with drops from two or more heights",
            "orientation_rotation": "no drop sheet with an orientation_deg covariate, and no drop twin",
            "size_dependence": "no test rows naming a specimen of the specimens sheet",
            "block_effect": "no categorical covariate (operator, date, batch) with two levels",
            "trial_order_drift": "no trial order covariate",
            "moisture_dependence": "no moisture covariate",
            "camera_tilt": "no heap photo with both flanks or a measured floor line"}.get(
        mech, "no covariate for its signature")


# ----------------------------------------------------------------------------------------------
# ill-conditioned parameters (from a campaign)


def _ill_conditioned_from_posterior(results) -> list:
    """Plausible workflow: a parameter is ill-conditioned when the heap leaves its posterior
    as wide as its prior (posterior sd / prior sd above ``NOT_IDENTIFIED_ABOVE``). The effect
    reported is that ratio, with the parameter's 95 % interval in the evidence."""
    from demcal.analyse.surrogate import NOT_IDENTIFIED_ABOVE

    mech = "ill_conditioned_parameter"
    params = results.calibration.parameters if results.calibration else {}
    if not params:
        return [Finding(mech, "not_testable", evidence="the campaign has no posterior of its parameters")]
    out = []
    for name, p in params.items():
        if p.sd_ratio > NOT_IDENTIFIED_ABOVE:
            lo, hi = p.ci95
            out.append(Finding(mech, "found", sheet="campaign", covariate=name, quantity="angle_deg",
                               source="campaign", effect=float(p.sd_ratio), ci95=[float(lo), float(hi)],
                               effect_unit="posterior sd / prior sd",
                               evidence=f"{name}: posterior sd {_fmt(p.posterior_sd)} is "
                               f"{_fmt(p.sd_ratio)} of its prior sd {_fmt(p.prior_sd)}; 95 % interval "
                               f"[{_fmt(lo)}, {_fmt(hi)}]: the repose angle cannot identify it"))
    if out:
        return out
    name, p = min(params.items(), key=lambda kv: -kv[1].sd_ratio)
    return [Finding(mech, "ruled_out", sheet="campaign", covariate=name, quantity="angle_deg",
                    source="campaign", effect=float(p.sd_ratio), ci95=list(p.ci95),
                    effect_unit="posterior sd / prior sd",
                    evidence=f"the heap narrows every parameter; least: {name}, posterior/prior sd "
                    f"{_fmt(p.sd_ratio)}")]


def ill_conditioned(results) -> list:
    """Verdict on ``ill_conditioned_parameter`` from a campaign's result
    (``analyse.results.CampaignResult``, or None without a campaign).

    A parameter carried into the Box-Behnken design is ill-conditioned when none of its terms
    (linear, interactions, quadratic) exceeds twice its standard error under the seed-to-seed
    noise alone (``terms_vs_noise``); if the design's terms are missing, its screening effect
    against the noise (``effects_vs_noise``) decides. The effect reported is the linear
    coefficient [deg per coded unit] with the interval coefficient +- 1.96 se_noise; the
    p-value is the normal test of coefficient / se_noise, Holm-adjusted over the carried
    parameters.
    """
    mech = "ill_conditioned_parameter"
    if not results:
        return [Finding(mech, "not_testable", evidence="no calibration campaign given (pass the "
                        "campaign folder holding results.json)")]
    if results.workflow == "plausible":
        return _ill_conditioned_from_posterior(results)
    factors = results.factors
    bbd = results.box_behnken
    carried = list(bbd.factors if bbd else results.significant.carried_forward if results.significant else [])
    terms = bbd.terms_vs_noise if bbd else {}
    pb = results.plackett_burman.effects_vs_noise if results.plackett_burman else {}
    if not carried or not (terms or pb):
        return [Finding(mech, "not_testable", evidence="the campaign has no noise comparison of its terms")]
    # the response surface names its factors A, B, C... in the order carried (fit "factors")
    coded = {v: k for k, v in (bbd.fit.factors if bbd else {}).items()}
    rows = []
    for f in carried:
        param = factors.get(f, {}).get("parameter", f)
        letter = coded.get(f, f)
        own = {name: v for name, v in terms.items()
               if name != "Intercept" and letter in re.findall(r"[A-Z]", name)}
        if own:
            lin = own.get(letter, next(iter(own.values())))
            coef, se = float(lin["coefficient"]), float(lin["se_noise"])
            exceeds = any(bool(v["exceeds_noise"]) for v in own.values())
            what = (f"{sum(bool(v['exceeds_noise']) for v in own.values())} of {len(own)} response-surface "
                    f"terms of {f} exceed 2 x their noise se")
        elif f in pb:
            coef, se = float(pb[f]["effect"]), float(pb[f]["se_noise"])
            exceeds = bool(pb[f]["exceeds_noise"])
            what = f"screening effect of {f} {'exceeds' if exceeds else 'within'} 2 x noise se"
        else:
            continue
        z = abs(coef) / se if se > 0 else math.inf
        rows.append({"factor": f, "parameter": param, "coef": coef, "se": se, "exceeds": exceeds,
                     "p": float(2.0 * stats.norm.sf(z)), "what": what})
    if not rows:
        return [Finding(mech, "not_testable", evidence="no carried parameter has a noise comparison")]
    adj = adjust_pvalues([r["p"] for r in rows], "holm")
    out = []
    for r, a in zip(rows, adj):
        ci = [r["coef"] - 1.96 * r["se"], r["coef"] + 1.96 * r["se"]]
        text = (f"{r['parameter']} (factor {r['factor']}): linear coefficient {_fmt(r['coef'])} deg per coded "
                f"unit, noise se {_fmt(r['se'])}; {r['what']}")
        if not r["exceeds"]:
            out.append(Finding(mech, "found", sheet="campaign", covariate=r["parameter"], quantity="angle_deg",
                               source="campaign", effect=r["coef"], ci95=ci, effect_unit="deg per coded unit",
                               p_adjusted=float(a), evidence=text + ": the repose angle cannot identify it "
                               "beyond seed noise"))
    if out:
        return out
    best = min(zip(rows, adj), key=lambda ra: abs(ra[0]["coef"]) / ra[0]["se"] if ra[0]["se"] > 0 else math.inf)
    r, a = best
    return [Finding(mech, "ruled_out", sheet="campaign", covariate=r["parameter"], quantity="angle_deg",
                    source="campaign", effect=r["coef"],
                    ci95=[r["coef"] - 1.96 * r["se"], r["coef"] + 1.96 * r["se"]],
                    effect_unit="deg per coded unit", p_adjusted=float(a),
                    evidence=f"every carried parameter has a term above the seed noise; weakest: {r['what']}")]
