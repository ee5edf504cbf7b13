"""Residual structure: every per-row value and twin residual tested against every covariate.

A *series* is one quantity's per-row values (``restitution.particle-steel`` from the drop
sheet), or the residuals of a twin (measured minus simulated, per trial), or a per-photo
difference (left minus right flank). Each series is tested against each covariate of its rows:
the sheet's own covariates, the design columns that vary (``drop_height_mm``), and, for rows
that name a ``specimen_id``, the specimen's calliper size and covariates from the
``specimens`` sheet (``length_mm``, ``diameter_mm``, ``mass_g``, ``moisture_pct``, ``batch``).

Tests (one p-value per series and covariate):

numeric covariate (``line`` and ``trend``)
    ``line``: least squares y = a + b x, the t-test of the slope b; the effect is b [unit of y
    per unit of x] with its Student-t 95 % interval. ``trend`` (three or more distinct
    values): y = b0 + b1 z + b2 z^2 (z the centred and scaled x; degree ``CURVED_DEGREE`` for
    the covariates of ``CURVED_COVARIATES``), the F-test of all its terms (a trend or a
    curvature); its effect and interval are the straight line's, and the curvature's own
    p-value is reported.
categorical covariate (``anova``)
    One-way analysis of variance over the levels with at least two rows (Fisher 1925). The
    effect is the range of the level means (largest minus smallest); its interval is the
    pooled-variance t interval of the difference of those two levels (optimistic: the two
    extreme levels are chosen after seeing the data).
paired difference or offset (``mean``)
    One-sample t-test of the mean (flank difference, floor tilt, twin-minus-contact).

Multiple testing. The tests come in two tiers, each adjusted on its own by Benjamini &
Hochberg (1995) (``"bh"``, default; false discovery rate) or Holm (1979) (``"holm"``;
family-wise error rate) and each spending its share of ``alpha`` (``TIER_SHARES``: 0.8 and
0.2; Bonferroni over the tiers, so with nothing there the chance of any significant test stays
below alpha):

- ``primary``: what the catalogue's mechanisms predict, with the fewest tests: the straight
  lines, anovas and means of the pooled series (an effect the drop pairs or incline surfaces
  share) and of the series measured once (sizes, density, repose, flanks), and, for a
  covariate expected to act in a V (``CURVED_COVARIATES``: orientation), its trend on every
  series;
- ``follow-up``: the per-pair and per-surface series that a pooled series holds (an effect
  on one pair only), and the trends (curvature) of the other covariates.

At a lab's sample size (21 drops per pair over three heights, 20 slide and 20 roll trials per
surface) the tiers find each planted effect of the virtual lab in about 9 of 10 workbooks,
where one adjustment of every test together finds a drift in about 5 of 10
(benchmarks/critique_power.md); the price is a U-shaped dependence on a covariate expected to
act in a line, a follow-up, found less often than a line of its size. A test is *significant* when its adjusted p-value (the
tier's, over its share) is below ``alpha`` and *relevant* when its effect over the data (trend:
the range of the fitted curve over the covariate's observed values, so that a U-shape counts;
line: |slope| x range; block: the range of level means; mean: |mean|) reaches the practical
threshold of its quantity (``PRACTICAL_THRESHOLDS``), so that a tiny but significant effect is
not reported as a cause. A test *excludes* a relevant effect when its 95 % interval lies within
the threshold (``CovariateTest.excludes_relevant``): only then may a mechanism be ruled out;
a relevant interval that misses the corrected level leaves it ``inconclusive``, with the rows
that would decide it (``CovariateTest.rows_to_decide``, ``mechanisms.judge``).

Pooled series. An effect several pairs share (a velocity dependence or a drift on every drop
pair) is also tested on all their rows at once (``pooled_series``): each value relative to its
own pair's mean, so the pairs' different levels do not hide it, with the family's threshold
over the mean level.

Level. ``DEFAULT_ALPHA`` is 0.01: over 200 clean virtual-lab workbooks of a lab's size, with
independent trials and with three or five trials per specimen (intraclass correlation 0.5),
1 to 3 named a cause; at 0.02, 5 to 6 of the clustered ones did, beyond a bound of 5 %
(benchmarks/critique_power.md).

Intervals after selection. A cause is named because its test came out significant, so its
ordinary 95 % interval covers the true size less often than 95 % (the selected estimates are
the large ones). A named effect therefore carries the false-coverage-rate interval of
Benjamini & Yekutieli (2005): the marginal interval at level 1 - R q / m for R effects selected
among the m tests of its tier, q = ``FCR_LEVEL`` times the tier's share, so that on average at
most 5 % of the named intervals miss.

Repeated trials. Trials on one specimen share its properties, so they are not independent
(with an intraclass correlation of 0.5, ten specimens of three trials gave a false alarm on a
specimen-level covariate in about one clean workbook in four when tested trial by trial).
With repeats, every test carries a random intercept per specimen (feasible GLS with moment
estimates of the variance components, the specimen variance taken as nil unless the specimens
differ at ``PRELIMINARY_LEVEL``) and the between-within degrees of freedom (``series_tests``).

Identifiers (``*_id``), file columns, and labels that are unique to almost every row are not
covariates; a covariate with no variation, or too few rows (``MIN_ROWS``), is listed as
untestable with the reason.

References
----------
Bancroft, T. A. (1964). Analysis and inference for incompletely specified models involving the
use of preliminary test(s) of significance. Biometrics 20(3), 427-442.
Benjamini, Y., Hochberg, Y. (1995). Controlling the false discovery rate: a practical and
powerful approach to multiple testing. J. R. Stat. Soc. B 57(1), 289-300.
Benjamini, Y., Yekutieli, D. (2005). False discovery rate-adjusted multiple confidence
intervals for selected parameters. J. Am. Stat. Assoc. 100(469), 71-81.
Cohen, J. (1988). Statistical Power Analysis for the Behavioral Sciences, 2nd ed. Erlbaum.
Paull, A. E. (1950). On a preliminary test for pooling mean squares in the analysis of
variance. Ann. Math. Stat. 21(4), 539-556.
Holm, S. (1979). A simple sequentially rejective multiple test procedure. Scand. J. Stat. 6,
65-70.
Fisher, R. A. (1925). Statistical Methods for Research Workers. Oliver & Boyd (analysis of
variance).
Wooldridge, J. M. (2010). Econometric Analysis of Cross Section and Panel Data, 2nd ed. MIT
Press, ch. 10 (random-effects GLS, the between-within degrees of freedom).
Montgomery, D. C., Peck, E. A., Vining, G. G. (2012). Introduction to Linear Regression
Analysis, 5th ed. Wiley, sec. 2.3 and 3.3 (t and F tests of regression coefficients).
"""

from __future__ import annotations

import functools
import math
import numbers
from dataclasses import asdict, dataclass, field, replace

import numpy as np
from scipy import optimize, special, stats

from demcal.errors import InputError
from demcal.jsonio import restore_nan
from demcal.simulate.shapes import size_columns

#: Practical threshold of each quantity family [its unit]: the smallest change over the
#: covariate's range that matters for a calibration. Restitution and friction: 0.03, about a
#: third of the spread the source paper reports between specimens (e 0.3 +- 0.1, mu_s 0.65 +-
#: 0.03, mu_r 0.53 +- 0.03) and the step that moves the paper's regression by about 0.5 deg;
#: angles: 1 deg, the repose-angle error the paper calls a good validation (0.39 %, 0.14 deg,
#: with a spread of about 0.3 deg between seeds, is well inside); sizes: 0.5 mm / 0.3 mm /
#: 0.1 g, the calliper and balance reading a lab reports. Quantities not listed use 5 % of the
#: series mean (``RELATIVE_THRESHOLD``).
PRACTICAL_THRESHOLDS = {
    "restitution": 0.03, "static_friction": 0.03, "rolling_friction": 0.03,
    "repose_angle_deg": 1.0, "flank_difference_deg": 1.0, "base_tilt_deg": 1.0,
    "length_mm": 0.5, "diameter_mm": 0.3, "mass_g": 0.1, "poisson_ratio": 0.03,
}
RELATIVE_THRESHOLD = 0.05

#: Fewest rows for a test.
MIN_ROWS = 6

#: Significance level after the correction (see the module docstring).
DEFAULT_ALPHA = 0.01

#: False coverage-statement rate of the intervals of selected effects (Benjamini & Yekutieli 2005).
FCR_LEVEL = 0.05

CORRECTIONS = ("bh", "holm")

#: Share of ``alpha`` spent on each tier of tests (see the module docstring, Multiple testing).
TIER_SHARES = {"primary": 0.8, "follow-up": 0.2}

#: Level of the preliminary test of the specimen variance (``_random_effects_fit``): 0.25, the
#: level at which pooling after a preliminary test keeps the final test close to its nominal
#: size (Bancroft 1964; Paull 1950).
PRELIMINARY_LEVEL = 0.25

#: Covariates whose expected effect is not a line: a segment rebounds at its contact
#: restitution landing flat and end on, and far lower in between, down to no rebound at all
#: where it pivots on its end (``simulate.rigid_impact``, the drop twin), and that V lies at a
#: different angle on each plate. A parabola fits it poorly: their trend is a polynomial of
#: degree ``CURVED_DEGREE`` and is their primary test on every series, pooled or not (their
#: straight line is a follow-up).
CURVED_COVARIATES = ("orientation_deg",)
CURVED_DEGREE = 4

#: Covariates that are never tested (files and identifiers are recognised by name too).
NOT_COVARIATES = {"id", "file", "track_file", "curve_file", "side", "annotated"}

#: Specimen columns joined to rows that name a specimen: every shape's calliper columns, and the mass.
SPECIMEN_SIZE = (*size_columns(), "mass_g")


@dataclass(frozen=True)
class Series:
    """Per-row values to test.

    Attributes
    ----------
    name : str
        Quantity name (``restitution.particle-steel``), or ``flank_difference_deg`` /
        ``base_tilt_deg`` (critique files of earlier versions also hold ``residual:<quantity>``
        series of twin residuals).
    sheet : str
        Workbook sheet of the rows.
    source : str
        ``measured``, ``twin residual`` or ``twin``.
    family : str
        Key of its practical threshold (``restitution``, ``static_friction``...).
    unit : str
        Unit of the values.
    rows : tuple of int
        Data rows (1 = first row under the header).
    values : tuple of float
    covariates : dict
        Covariate name -> tuple of values (None where missing), one per row.
    test : str
        ``covariates`` (against each covariate) or ``mean`` (one-sample test of the mean).
    practical_threshold : float or None
        The practical threshold in the series' unit when its family's does not apply (a pooled
        series of values relative to their pair's mean).
    members : tuple of str
        For a pooled series, the names of the series it pools (tested as follow-ups).
    """

    name: str
    sheet: str
    source: str
    family: str
    unit: str
    rows: tuple
    values: tuple
    covariates: dict = field(default_factory=dict)
    test: str = "covariates"
    practical_threshold: float | None = None
    members: tuple = ()

    @property
    def threshold(self) -> float:
        if self.practical_threshold is not None:
            return self.practical_threshold
        if self.family in PRACTICAL_THRESHOLDS:
            return PRACTICAL_THRESHOLDS[self.family]
        y = np.asarray(self.values, dtype=float)
        return RELATIVE_THRESHOLD * abs(float(np.mean(y))) if y.size else math.nan


@functools.lru_cache(maxsize=256)
def noncentrality(alpha: float, df: int, power: float) -> float:
    """The noncentrality at which a chi-square test of ``df`` degrees of freedom at level
    ``alpha`` rejects with probability ``power`` (a root-find over the noncentral chi-square:
    a critique asks it of every test for a handful of distinct arguments, so it is kept)."""
    crit = float(stats.chi2.isf(alpha, df))
    return optimize.brentq(lambda nc: float(stats.ncx2.sf(crit, df, nc)) - power, 1e-9, 1e6)


@dataclass(frozen=True)
class CovariateTest:
    """One test of a series against a covariate (or of its mean).

    Attributes
    ----------
    series, sheet, source : str
        As in :class:`Series`.
    covariate : str
        Covariate tested (``side`` for a flank difference, ``floor`` for a floor tilt,
        ``orientation_deg`` for the twin-minus-contact offset).
    method : str
        ``line`` (straight line, 1 degree of freedom), ``trend`` (line and curvature, 2),
        ``anova`` or ``mean``.
    n : int
        Rows used.
    effect : float
        Slope [unit per covariate unit], range of level means [unit] or mean [unit].
    ci95 : tuple of float
        95 % interval of ``effect``.
    effect_unit : str
    span : float or None
        Range of the covariate over the rows (numeric covariates).
    se : float
        Standard error of ``effect``; ``ci95`` is effect +- t(0.975, dof) se.
    dof : int
        Degrees of freedom of the t quantile.
    practical : float
        Size of the effect over the data [unit]: the range of the fitted curve (line and
        quadratic) over the covariate's observed values for ``trend``, |slope| x range for
        ``line``, |effect| otherwise.
    threshold : float
        Practical threshold [unit].
    p_value : float
        Unadjusted p-value.
    p_curvature : float or None
        p-value of the quadratic term (``trend``).
    p_adjusted : float
        After the multiple-testing correction (NaN before :func:`adjust`).
    significant : bool
        ``p_adjusted < alpha``.
    relevant : bool
        ``practical >= threshold``.
    ci_selected : tuple of float or None
        For a test selected as a cause (significant and relevant): its false-coverage-rate
        interval (Benjamini & Yekutieli 2005), effect +- t(1 - R q / (2 m), dof) se with R
        tests selected out of m and q = ``FCR_LEVEL``: the interval keeps its 95 % meaning
        after the effect was chosen for being large.
    explained_by : str or None
        Another selected covariate of the same series that accounts for this one
        (``explain_away``); such a test names no cause.
    levels : dict
        Level -> (mean, n) for ``anova``.
    level : str
        ``trial`` (independent rows), ``specimen`` (a covariate of the specimen, rows with a
        random specimen intercept and the specimens' degrees of freedom) or ``trial within
        specimens`` (a trial covariate, random specimen intercept, within degrees of freedom).
    alpha_test : float
        The unadjusted level at which this test alone in its tier would be significant
        (alpha x the tier's share / m): the level :meth:`rows_to_decide` plans for.
    tier : str
        ``primary`` or ``follow-up`` (``TIER_SHARES``; the module docstring says which tests
        are which).
    df_test : int
        Numerator degrees of freedom of the test (a trend's terms; 1 for a line or a mean).
    """

    series: str
    sheet: str
    source: str
    covariate: str
    method: str
    n: int
    effect: float
    ci95: tuple
    effect_unit: str
    span: float | None
    practical: float
    threshold: float
    p_value: float
    se: float = math.nan
    dof: int = 0
    p_curvature: float | None = None
    p_adjusted: float = math.nan
    significant: bool = False
    relevant: bool = False
    ci_selected: tuple | None = None
    explained_by: str | None = None
    levels: dict = field(default_factory=dict)
    level: str = "trial"
    alpha_test: float = math.nan
    tier: str = "primary"
    df_test: int = 1

    @property
    def quantity(self) -> str:
        """The quantity behind the series (``residual:`` and similar prefixes removed)."""
        return self.series.split(":", 1)[-1]

    def largest_admitted(self, sign: int = 0) -> float:
        """The largest size over the data that the 95 % interval admits [unit]: the interval's
        larger end in magnitude (with ``sign`` +1 or -1, in that direction only), times the
        covariate's range for a slope."""
        lo, hi = self.ci95
        bound = max(abs(lo), abs(hi)) if sign == 0 else max(sign * lo, sign * hi, 0.0)
        return bound * self.span if self.span is not None else bound

    def excludes_relevant(self, sign: int = 0) -> bool:
        """Whether the data exclude a relevant effect (of ``sign``, if given): the 95 % interval
        lies within the practical threshold (for a trend, with its curvature not significant at
        5 %, since the interval is the straight line's)."""
        curved = self.p_curvature is not None and self.p_curvature < 0.05
        size = self.largest_admitted(sign)
        return bool(math.isfinite(size) and size < self.threshold and not curved)

    def rows_to_decide(self, power: float = 0.8) -> int | None:
        """Rows of this design that would find an effect of the practical threshold's size with
        probability ``power`` at :attr:`alpha_test`: n lambda (se / delta)^2, where delta is the
        threshold in the effect's unit (over the covariate's range for a slope), the standard
        error falls as 1 / sqrt(rows), and lambda is the noncentrality at which the test's
        chi-square (2 degrees of freedom for a trend's line and curvature, levels - 1 for a
        block, the terms of a trend (``df_test``), else 1) reaches ``power`` (Cohen 1988, ch.
        8-9). None without a standard error."""
        delta = self.threshold / self.span if self.span else self.threshold
        alpha = self.alpha_test if math.isfinite(self.alpha_test) else DEFAULT_ALPHA
        if not (math.isfinite(self.se) and self.se > 0 and delta > 0):
            return None
        df = max(len(self.levels) - 1, 1) if self.method == "anova" else self.df_test
        return int(math.ceil(self.n * noncentrality(alpha, df, power) * (self.se / delta) ** 2))

    def to_dict(self) -> dict:
        d = asdict(self)
        d["ci95"] = list(self.ci95)
        d["ci_selected"] = None if self.ci_selected is None else list(self.ci_selected)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "CovariateTest":
        d = restore_nan(d, "effect", "practical", "threshold", "p_value", "se", "p_adjusted")
        ci = d.get("ci95")
        return cls(**{**d, "ci95": tuple(math.nan if c is None else c for c in ci),
                      "ci_selected": None if d.get("ci_selected") is None else tuple(d["ci_selected"])})


@dataclass(frozen=True)
class Untestable:
    """A series-covariate pair that could not be tested, and why."""

    series: str
    sheet: str
    source: str
    covariate: str
    reason: str
    kind: str = "numeric"

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "Untestable":
        return cls(**d)


# ----------------------------------------------------------------------------------------------
# multiple testing


def adjust_pvalues(p, method: str = "bh") -> np.ndarray:
    """Adjusted p-values of a family of tests.

    ``"bh"``: Benjamini & Hochberg (1995) step-up, p_(i) m / i made monotone from the largest;
    ``"holm"``: Holm (1979) step-down, (m - i + 1) p_(i) made monotone from the smallest; both
    capped at 1. NaN p-values are returned as NaN and do not count in m.
    """
    if method not in CORRECTIONS:
        raise InputError(f"unknown multiple-testing correction {method!r}; valid: {', '.join(CORRECTIONS)}")
    p = np.asarray(p, dtype=float)
    out = np.full(p.shape, np.nan)
    ok = np.isfinite(p)
    q = p[ok]
    m = q.size
    if m == 0:
        return out
    order = np.argsort(q)
    ranked = q[order]
    i = np.arange(1, m + 1)
    if method == "bh":
        adj = np.minimum.accumulate((ranked * m / i)[::-1])[::-1]
    else:
        adj = np.maximum.accumulate(ranked * (m - i + 1))
    adj = np.minimum(adj, 1.0)
    back = np.empty(m)
    back[order] = adj
    out[ok] = back
    return out


def adjust(tests, *, method: str = "bh", alpha: float = DEFAULT_ALPHA) -> list:
    """The tests with ``p_adjusted``, ``significant`` and ``relevant`` set.

    Each tier (``CovariateTest.tier``) is adjusted on its own and spends its share of
    ``alpha`` (``TIER_SHARES``): ``p_adjusted`` is the tier's adjusted p-value over its share
    (capped at 1), so that ``p_adjusted < alpha`` is significance in every tier. With nothing
    there the chance of any significant test is at most the sum of the tiers' levels, alpha
    (Bonferroni over the tiers). Intervals after selection are those of each tier.
    """
    if not 0 < alpha < 1:
        raise InputError(f"alpha must be in (0, 1), got {alpha!r}")
    out = list(tests)
    unknown = {t.tier for t in out} - set(TIER_SHARES)
    if unknown:
        raise InputError(f"unknown test tier(s) {sorted(unknown)}; valid: {', '.join(TIER_SHARES)}")
    for tier, share in TIER_SHARES.items():
        idx = [i for i, t in enumerate(out) if t.tier == tier]
        adj = np.minimum(adjust_pvalues([out[i].p_value for i in idx], method) / share, 1.0)
        m = int(np.isfinite(adj).sum())
        for i, a in zip(idx, adj):
            t = out[i]
            out[i] = replace(t, p_adjusted=float(a), significant=bool(np.isfinite(a) and a < alpha),
                             relevant=bool(np.isfinite(t.practical) and t.practical >= t.threshold),
                             alpha_test=alpha * share / max(m, 1))
        selected = [i for i in idx if out[i].significant and out[i].relevant]
        if selected:
            tail = len(selected) * FCR_LEVEL * share / m / 2.0
            for i in selected:
                out[i] = replace(out[i], ci_selected=_interval(out[i], tail))
    return out


def _interval(t, tail: float) -> tuple:
    half = float(stats.t.ppf(1.0 - tail, t.dof)) * t.se if t.dof > 0 else math.nan
    return (t.effect - half, t.effect + half)


# ----------------------------------------------------------------------------------------------
# single tests


@functools.lru_cache(maxsize=None)
def _t95(dof: int) -> float:
    return float(stats.t.ppf(0.975, dof)) if dof > 0 else math.nan


def _f_sf(F: float, dfn: int, dfd: int) -> float:
    """``stats.f.sf(F, dfn, dfd)``, by the special function it calls, without the distribution
    machinery's overhead (the specimen tests take it thousands of times per workbook)."""
    return 1.0 if F <= 0 else float(special.fdtrc(dfn, dfd, F))


def trend_test(x, y, degree: int = 2) -> dict:
    """Straight line and polynomial of y on a numeric x (see the module docstring).

    The trend is y = b0 + b1 z + ... + b_d z^d (z the centred and scaled x, d = ``degree``,
    lowered to the distinct values of x less one); its p-value is the F-test of all its terms,
    ``p_curvature`` the F-test of the terms beyond the straight line (for d = 2 the quadratic
    term's t-test). With two distinct values, only the line.

    Returns ``{"method", "n", "effect", "ci95", "se", "dof", "p_value", "p_line", "p_curvature",
    "span", "df_test"}`` (and ``curve_range`` for a trend): ``effect`` and ``ci95`` are the
    straight line's slope and its Student-t interval, ``p_line`` its t-test, ``df_test`` the
    numerator degrees of freedom of ``p_value``.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    n = x.size
    span = float(x.max() - x.min())
    xc = x - x.mean()
    sxx = float(xc @ xc)
    b = float(xc @ (y - y.mean())) / sxx
    resid1 = y - y.mean() - b * xc
    rss1 = float(resid1 @ resid1)
    dof1 = n - 2
    se_b = math.sqrt(rss1 / dof1 / sxx) if dof1 > 0 else math.nan
    t = _t95(dof1)
    ci = (b - t * se_b, b + t * se_b)
    if se_b > 0:
        p_line = float(2.0 * stats.t.sf(abs(b / se_b), dof1))
    else:
        p_line = 0.0 if b != 0 else 1.0
    line = {"n": n, "effect": b, "ci95": ci, "se": se_b, "dof": dof1, "p_line": p_line, "span": span}
    d = min(degree, np.unique(x).size - 1, n - 2)
    if d < 2:
        return {**line, "method": "line", "p_value": p_line, "p_curvature": None, "df_test": 1}
    z = xc / math.sqrt(sxx / n)
    X = np.column_stack([z ** k for k in range(d + 1)])
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    rss = float(np.sum((y - X @ coef) ** 2))
    rss0 = float(((y - y.mean()) ** 2).sum())
    dof = n - d - 1
    if rss > 0:
        p = float(stats.f.sf((rss0 - rss) / d / (rss / dof), d, dof))
        p_curv = float(stats.f.sf(max(rss1 - rss, 0.0) / (d - 1) / (rss / dof), d - 1, dof))
    else:
        p, p_curv = (0.0, 0.0) if rss0 > 0 else (1.0, 1.0)
    fitted = X @ coef
    return {**line, "method": "trend", "p_value": p, "p_curvature": p_curv, "df_test": d,
            "curve_range": float(fitted.max() - fitted.min())}


def block_test(levels, y) -> dict:
    """One-way ANOVA of y over the levels with at least two rows (see the module docstring).

    Returns ``{"method", "n", "effect", "ci95", "p_value", "levels"}``.
    """
    y = np.asarray(y, dtype=float)
    labels = [str(v) for v in levels]
    groups: dict = {}
    for lab, v in zip(labels, y):
        groups.setdefault(lab, []).append(v)
    groups = {k: np.asarray(v) for k, v in groups.items() if len(v) >= 2}
    if len(groups) < 2:
        raise InputError("a block test needs two levels with at least two rows each")
    n = sum(g.size for g in groups.values())
    k = len(groups)
    means = {lev: float(g.mean()) for lev, g in groups.items()}
    ss_within = sum(float(((g - g.mean()) ** 2).sum()) for g in groups.values())
    dof = n - k
    mse = ss_within / dof if dof > 0 else math.nan
    grand = float(np.concatenate(list(groups.values())).mean())
    ss_between = sum(g.size * (g.mean() - grand) ** 2 for g in groups.values())
    if mse > 0:
        F = ss_between / (k - 1) / mse
        p = float(stats.f.sf(F, k - 1, dof))
    else:
        p = 0.0 if ss_between > 0 else 1.0
    hi = max(means, key=means.get)
    lo = min(means, key=means.get)
    effect = means[hi] - means[lo]
    se = math.sqrt(mse * (1.0 / groups[hi].size + 1.0 / groups[lo].size))
    half = _t95(dof) * se
    return {"method": "anova", "n": n, "effect": effect, "ci95": (effect - half, effect + half),
            "se": se, "dof": dof,
            "p_value": p, "levels": {lev: [means[lev], int(groups[lev].size)] for lev in groups}}


def _random_effects_fit(y, X, groups):
    """Feasible GLS of y on [1, X] with a random intercept per group (Wooldridge 2010, sec.
    10.4): the variance components from the one-way ANOVA of the OLS residuals (moments,
    truncated at 0), then OLS on the quasi-demeaned data y - theta_g mean_g(y),
    theta_g = 1 - sqrt(s_w^2 / (s_w^2 + n_g s_b^2)), which is GLS under that covariance.

    Returns (design columns transformed, y transformed, s_b^2, s_w^2)."""
    n = y.size
    A = np.column_stack([np.ones(n), X])
    e = y - A @ np.linalg.lstsq(A, y, rcond=None)[0]
    names, index, sizes = np.unique(groups, return_inverse=True, return_counts=True)
    G = names.size
    means = np.bincount(index, e) / sizes
    msw = float(np.sum((e - means[index]) ** 2)) / max(n - G, 1)
    msb = float(np.sum(sizes * (means - e.mean()) ** 2)) / max(G - 1, 1)
    n0 = (n - float(np.sum(sizes ** 2)) / n) / max(G - 1, 1)
    # "sometimes pool": the specimen variance is taken as nil unless the specimens differ at the
    # preliminary level (Bancroft 1964), so that a chance excess of msb over msw does not cost a
    # trial covariate the degrees of freedom of the specimens
    differ = G > 1 and n > G and msw > 0 and _f_sf(msb / msw, G - 1, n - G) < PRELIMINARY_LEVEL
    s_b2 = max(0.0, (msb - msw) / n0) if n0 > 0 and differ else 0.0
    theta = 1.0 - np.sqrt(msw / (msw + sizes * s_b2)) if s_b2 > 0 and msw > 0 else np.zeros(G)
    t = theta[index]

    def quasi(v):
        v = np.asarray(v, dtype=float)
        gm = np.stack([np.bincount(index, v[:, j]) / sizes for j in range(v.shape[1])], axis=1)
        return v - t[:, None] * gm[index]

    return quasi(A), quasi(y[:, None])[:, 0], s_b2, msw


def _clustered(y, X, groups, between: bool, controls: int = 0):
    """Fit and F-test of the columns X (beyond the intercept and the first ``controls`` columns
    of X, which the null model keeps) with a random specimen intercept.
    Degrees of freedom by the between-within rule: a covariate constant within specimens has
    specimens - 1 - columns and is judged against the scatter between specimens; one varying
    within them has trials - specimens - columns, or, with no specimen variance estimated, the
    OLS trials - 1 - columns."""
    y = np.asarray(y, dtype=float)
    X = np.asarray(X, dtype=float).reshape(y.size, -1)
    As, ys, s_b2, _ = _random_effects_fit(y, X, groups)
    k = X.shape[1]
    q = k - controls
    G = np.unique(groups).size
    # a covariate of the specimen is judged against the specimens whatever the variance
    # estimate says (fitted first, it has taken up the between-specimen scatter itself)
    dof = G - 1 - k if between else (y.size - 1 - k if s_b2 == 0 else y.size - G - k)
    coef, *_ = np.linalg.lstsq(As, ys, rcond=None)
    rss1 = float(np.sum((ys - As @ coef) ** 2))
    null = As[:, : 1 + controls]
    c0, *_ = np.linalg.lstsq(null, ys, rcond=None)
    rss0 = float(np.sum((ys - null @ c0) ** 2))
    s2 = rss1 / (y.size - 1 - k)
    if between and dof > 0:
        # a specimen covariate is judged against the scatter between specimens alone: in a
        # balanced design this is the regression on the specimens' means, exactly
        _, index, sizes = np.unique(groups, return_inverse=True, return_counts=True)
        r = ys - As @ coef
        s2 = float(np.sum(sizes * (np.bincount(index, r) / sizes) ** 2)) / dof
    cov = s2 * np.linalg.pinv(As.T @ As)
    if dof <= 0:
        p = math.nan
    elif s2 <= 0:
        p = 0.0 if rss0 > rss1 else 1.0
    else:
        p = _f_sf((rss0 - rss1) / q / s2, q, dof)
    lead = 1 + controls
    return coef[lead:], cov[lead:, lead:], p, dof


def clustered_trend_test(x, y, groups, between: bool, degree: int = 2) -> dict:
    """``trend_test`` with a random specimen intercept (``_clustered``): repeated trials on one
    specimen count as much as their correlation allows, once for a covariate of the specimen."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    scale = x.std() or 1.0
    z = (x - x.mean()) / scale
    b, cov, p_line, dof = _clustered(y, z, groups, between)
    slope, se = float(b[0]) / scale, math.sqrt(max(cov[0, 0], 0.0)) / scale
    t = _t95(dof)
    out = {"n": x.size, "effect": slope, "ci95": (slope - t * se, slope + t * se), "se": se, "dof": dof,
           "span": float(x.max() - x.min()), "p_line": p_line}
    d = min(degree, np.unique(x).size - 1, dof)
    if d >= 2:
        Z = np.column_stack([z ** k for k in range(1, d + 1)])
        bd, _, p, _ = _clustered(y, Z, groups, between)
        *_, p_curv, _ = _clustered(y, Z, groups, between, controls=1)
        curve = Z @ bd
        return {**out, "method": "trend", "p_value": p, "p_curvature": p_curv, "df_test": d,
                "curve_range": float(curve.max() - curve.min())}
    return {**out, "method": "line", "p_value": p_line, "p_curvature": None, "df_test": 1}


def clustered_block_test(levels, y, groups, between: bool) -> dict:
    """``block_test`` with a random specimen intercept: the F-test of the levels, the effect
    the range of the levels' coefficients with the interval of the two extreme levels."""
    labels = np.array([str(v) for v in levels])
    y = np.asarray(y, float)
    names = sorted(set(labels))
    D = np.column_stack([(labels == lev).astype(float) for lev in names[1:]])
    coef, cov, p, dof = _clustered(y, D, groups, between)
    effects = np.concatenate([[0.0], coef])          # relative to the first level
    full = np.zeros((len(names),) * 2)
    full[1:, 1:] = cov
    hi, lo = int(np.argmax(effects)), int(np.argmin(effects))
    se = math.sqrt(max(full[hi, hi] + full[lo, lo] - 2 * full[hi, lo], 0.0))
    effect = float(effects[hi] - effects[lo])
    half = _t95(dof) * se
    return {"method": "anova", "n": int(y.size), "effect": effect, "ci95": (effect - half, effect + half),
            "se": se, "dof": int(dof), "p_value": p,
            "levels": {lev: [float(y[labels == lev].mean()), int((labels == lev).sum())] for lev in names}}


def mean_test(y) -> dict:
    """One-sample t-test of the mean of y against 0. Returns ``{"method", "n", "effect", "ci95",
    "p_value"}``."""
    y = np.asarray(y, dtype=float)
    n = y.size
    m = float(y.mean())
    sd = float(y.std(ddof=1)) if n > 1 else math.nan
    half = _t95(n - 1) * sd / math.sqrt(n)
    if sd > 0:
        p = float(2.0 * stats.t.sf(abs(m / (sd / math.sqrt(n))), n - 1))
    else:
        p = 0.0 if m != 0 else 1.0
    return {"method": "mean", "n": n, "effect": m, "ci95": (m - half, m + half),
            "se": sd / math.sqrt(n), "dof": n - 1, "p_value": p}


# ----------------------------------------------------------------------------------------------
# series against covariates


def _unit_of(name: str) -> str:
    for suffix, unit in (("_mm", "mm"), ("_deg", "deg"), ("_pct", "%"), ("_g", "g"), ("_s", "s"),
                         ("_n", "N"), ("_ml", "ml")):
        if name.lower().endswith(suffix):
            return unit
    return "trial" if "order" in name.lower() else "unit"


def _is_number(v) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, bool) and math.isfinite(float(v))


def is_identifier(name: str) -> bool:
    """Whether a column names files or identifiers rather than conditions."""
    low = name.lower()
    return low in NOT_COVARIATES or low.endswith("_id") or low.endswith("_file")


def specimen_groups(series: Series) -> np.ndarray | None:
    """The specimen of each row (rows naming none are their own) as integer codes in the order
    of the specimens' names, when some specimen has repeated trials in the series; None
    otherwise (every row independent). Codes, because the tests group by them many times and
    sorting integers is far cheaper than sorting names."""
    raw = series.covariates.get("specimen_id")
    if raw is None:
        return None
    labels = np.array([f"row {i}" if v is None else str(v) for i, v in enumerate(raw)])
    _, codes, counts = np.unique(labels, return_inverse=True, return_counts=True)
    return codes if counts.max() >= 2 else None


def of_specimen(groups, values) -> bool:
    """Whether a covariate is constant within every specimen (a covariate of the specimen)."""
    seen: dict = {}
    return all(seen.setdefault(g, v) == v for g, v in zip(groups, values))


def series_tests(series: Series) -> tuple[list, list]:
    """Test one series against each of its covariates (or its mean).

    With repeated trials on a specimen (``specimen_groups``) the trials are not independent:
    the tests carry a random intercept per specimen (``clustered_trend_test``,
    ``clustered_block_test``), and a covariate constant within every specimen (its size, batch,
    moisture) gets the degrees of freedom of the specimens, one that varies within them (trial
    order, drop height, operator) those of the trials within specimens. The test's ``level``
    says which.

    Returns
    -------
    (list of CovariateTest, list of Untestable)
        Unadjusted tests and the pairs that could not be tested.
    """
    y_all = np.asarray(series.values, dtype=float)
    groups = specimen_groups(series)
    tests, skipped = [], []

    def skip(cov, reason, kind="numeric"):
        skipped.append(Untestable(series.name, series.sheet, series.source, cov, reason, kind))

    def make(cov, res, unit, level="trial"):
        span = res.get("span")
        common = dict(series=series.name, sheet=series.sheet, source=series.source, covariate=cov,
                      n=int(res["n"]), effect=float(res["effect"]), ci95=tuple(float(c) for c in res["ci95"]),
                      se=float(res["se"]), dof=int(res["dof"]), effect_unit=unit, span=span,
                      threshold=float(series.threshold), p_curvature=res.get("p_curvature"),
                      levels=res.get("levels", {}), level=level)
        if res["method"] in ("line", "trend"):
            # the straight line, and with three values or more its curvature too (a U-shape)
            tests.append(CovariateTest(method="line", practical=abs(res["effect"]) * span,
                                       p_value=float(res["p_line"]), **common))
        if res["method"] != "line":
            # relevance of a trend on the fitted curve's range over the data, so that a U-shape counts
            practical = res["curve_range"] if "curve_range" in res else abs(res["effect"])
            tests.append(CovariateTest(method=res["method"], practical=float(practical),
                                       p_value=float(res["p_value"]), df_test=int(res.get("df_test", 1)),
                                       **common))

    if series.test == "mean":
        cov = next(iter(series.covariates), "mean")
        if y_all.size < 3:
            skip(cov, f"{y_all.size} values; a mean test needs at least 3", "mean")
        else:
            make(cov, mean_test(y_all), series.unit)
        return tests, skipped
    for cov, raw in series.covariates.items():
        if is_identifier(cov):
            continue
        keep = [i for i, v in enumerate(raw) if v is not None and not (isinstance(v, float) and math.isnan(v))]
        vals = [raw[i] for i in keep]
        numeric = all(_is_number(v) for v in vals)
        if len(keep) < MIN_ROWS:
            skip(cov, f"{len(keep)} rows with a value; at least {MIN_ROWS} needed",
                 "numeric" if numeric else "categorical")
            continue
        y = y_all[keep]
        level = "trial"
        if groups is not None:
            g = groups[keep]
            level = "specimen" if of_specimen(g, vals) else "trial within specimens"
            n_specimens = np.unique(g).size
            if level == "specimen" and n_specimens < MIN_ROWS:
                skip(cov, f"a specimen-level covariate over {n_specimens} specimens; at least {MIN_ROWS} needed",
                     "numeric" if numeric else "categorical")
                continue
        if numeric:
            x = np.asarray(vals, dtype=float)
            if np.unique(x).size < 2:
                skip(cov, f"no variation (every row {x[0]:g})")
                continue
            degree = CURVED_DEGREE if cov in CURVED_COVARIATES else 2
            res = (trend_test(x, y, degree) if level == "trial"
                   else clustered_trend_test(x, y, g, level == "specimen", degree))
            unit = f"{series.unit}/{_unit_of(cov)}"
        else:
            labels = [str(v) for v in vals]
            distinct = set(labels)
            if len(distinct) < 2:
                skip(cov, f"no variation (every row {labels[0]!r})", "categorical")
                continue
            if len(distinct) > 0.5 * len(labels):
                skip(cov, f"{len(distinct)} labels for {len(labels)} rows: an identifier, not a block",
                     "categorical")
                continue
            counts = {lab: labels.count(lab) for lab in distinct}
            if sum(c >= 2 for c in counts.values()) < 2:
                skip(cov, "fewer than two levels with two rows or more", "categorical")
                continue
            if level == "trial":
                res = block_test(labels, y)
            else:
                kept = np.isin(labels, [lab for lab, c in counts.items() if c >= 2])
                res = clustered_block_test(np.array(labels)[kept], y[kept], g[kept], level == "specimen")
            unit = series.unit
        if not res["dof"] > 0 or not math.isfinite(res["p_value"]):
            skip(cov, f"too few {'specimens' if level == 'specimen' else 'trials'} for a test with "
                      "an effect per specimen", "numeric" if numeric else "categorical")
            continue
        make(cov, res, unit, level)
    return tests, skipped


def run_tests(series_list, *, method: str = "bh", alpha: float = DEFAULT_ALPHA) -> tuple[list, list]:
    """Test every series, put each test in its tier and adjust the tiers (``adjust``).

    Follow-ups are the tests of a series that a pooled series holds (one drop pair of the
    pooled restitution) and the trends (line and curvature) of every series; the rest are
    primary: lines, anovas and means of the pooled series and of the series measured once.

    Returns
    -------
    (list of CovariateTest, list of Untestable)
    """
    pooled = {name for s in series_list for name in s.members}

    def tier(series, test):
        if test.covariate in CURVED_COVARIATES and test.method in ("line", "trend"):
            return "primary" if test.method == "trend" else "follow-up"
        return "follow-up" if series.name in pooled or test.method == "trend" else "primary"

    tests, skipped = [], []
    for s in series_list:
        t, u = series_tests(s)
        tests += [replace(x, tier=tier(s, x)) for x in t]
        skipped += u
    tests = adjust(tests, method=method, alpha=alpha)
    return explain_away(tests, series_list), skipped


def _columns(raw, keep) -> np.ndarray | None:
    """Design columns of a covariate on the rows ``keep``: centred x (and x^2 with three or more
    values) for a numeric covariate, level dummies (first level dropped) for a categorical one."""
    vals = [raw[i] for i in keep]
    if all(_is_number(v) for v in vals):
        x = np.asarray(vals, dtype=float)
        x = x - x.mean()
        return np.column_stack([x, x * x]) if np.unique(x).size >= 3 else x[:, None]
    labels = [str(v) for v in vals]
    levels = sorted(set(labels))
    return np.column_stack([[lab == lev for lab in labels] for lev in levels[1:]]).astype(float)


def partial_pvalue(series: Series, covariate: str, control: str) -> float:
    """p-value of ``covariate`` in a model of the series that already holds ``control`` (F-test
    of the covariate's columns, ``_columns``), on the rows having both.

    With repeated trials on a specimen (``specimen_groups``) the model carries a random
    specimen intercept and the degrees of freedom of the level the covariate varies at, as in
    ``series_tests``; otherwise it is ordinary least squares."""
    a, b = series.covariates[covariate], series.covariates[control]
    keep = [i for i in range(len(series.values)) if a[i] is not None and b[i] is not None]
    y = np.asarray(series.values, dtype=float)[keep]
    Xc = np.column_stack([np.ones(len(keep)), _columns(b, keep)])
    Xf = np.column_stack([Xc, _columns(a, keep)])
    rank_c, rank_f = np.linalg.matrix_rank(Xc), np.linalg.matrix_rank(Xf)
    if rank_f <= rank_c:
        return 1.0              # the covariate adds nothing the control does not hold
    groups = specimen_groups(series)
    if groups is not None:
        g = groups[keep]
        between = of_specimen(g, [a[i] for i in keep])
        # a full-rank design: columns in order, each kept if it adds to the rank
        cols, kept = Xf[:, 1:], []
        for j in range(cols.shape[1]):
            if np.linalg.matrix_rank(np.column_stack([np.ones(len(keep)), cols[:, kept + [j]]])) == len(kept) + 2:
                kept.append(j)
        n_control = sum(j < Xc.shape[1] - 1 for j in kept)
        *_, p, dof = _clustered(y, cols[:, kept], g, between, controls=n_control)
        return 1.0 if not dof > 0 or not math.isfinite(p) else p
    dof = len(keep) - rank_f
    if dof <= 0:
        return 1.0
    rss = [float(np.sum((y - X @ np.linalg.lstsq(X, y, rcond=None)[0]) ** 2)) for X in (Xc, Xf)]
    if rss[1] <= 0:
        return 0.0
    F = (rss[0] - rss[1]) / (rank_f - rank_c) / (rss[1] / dof)
    return float(stats.f.sf(F, rank_f - rank_c, dof))


def explain_away(tests, series_list) -> list:
    """Mark selected covariate effects that another selected covariate of the same series explains.

    Covariates can be confounded (a batch whose segments happen to be longer carries a size
    effect; a day carries a drift). For every pair of selected (significant and relevant) tests
    on the same series, the covariate's p-value is recomputed with the other covariate in the
    model (``partial_pvalue``); if it is no longer below the cut-off that selected it (the
    largest unadjusted p-value among the significant tests of its tier), the test is marked
    ``explained_by`` the other covariate and names no cause. Where each of two covariates
    vanishes with the other, the one with the smaller p-value stands and explains the other.
    """
    selected = [t for t in tests if t.significant and t.relevant and t.method != "mean"]
    if len(selected) < 2:
        return tests
    # the cut-off of each tier: its largest selected unadjusted p-value
    cut = {tier: max((t.p_value for t in tests if t.significant and t.tier == tier), default=0.0)
           for tier in TIER_SHARES}
    by_name = {s.name: s for s in series_list}
    vanishes: dict = {}         # (series, covariate, other) -> whether it vanishes with other

    def vanishes_with(t, other):
        key = (t.series, t.covariate, other.covariate)
        if key not in vanishes:
            s = by_name.get(t.series)
            vanishes[key] = (s is not None and t.covariate in s.covariates and other.covariate in s.covariates
                             and partial_pvalue(s, t.covariate, other.covariate) > cut[t.tier])
        return vanishes[key]

    explained = {}
    for t in selected:
        for other in selected:
            if other is t or other.series != t.series or other.covariate == t.covariate:
                continue
            # two covariates that each vanish with the other (length and mass of a segment):
            # the data cannot tell them apart, and the stronger one stands for both
            mutual_and_weaker = other.p_value < t.p_value or (other.p_value == t.p_value
                                                              and other.covariate < t.covariate)
            if vanishes_with(t, other) and (mutual_and_weaker or not vanishes_with(other, t)):
                explained[id(t)] = other.covariate
                break
    return [replace(t, explained_by=explained[id(t)], ci_selected=None) if id(t) in explained else t
            for t in tests]


# ----------------------------------------------------------------------------------------------
# series from a measured workbook


def _family(quantity: str) -> str:
    return quantity.split(".", 1)[0]


def specimen_lookup(workbook) -> dict:
    """``specimen_id`` -> covariates of that specimen (its calliper size and the ``specimens``
    sheet's covariates), from a ``measure.workbook.Workbook``."""
    sheet = workbook.sheet("specimens") if workbook is not None else None
    if sheet is None:
        return {}
    f = sheet.frame
    out = {}
    for r in sheet.rows:
        rec = {c: _plain(f.at[r, c]) for c in SPECIMEN_SIZE if c in f}
        rec.update({c: v for c, v in sheet.covariates_of(r).items() if not is_identifier(c)})
        out[str(f.at[r, "specimen_id"])] = rec
    return out


def _plain(v):
    if isinstance(v, (float, np.floating)):
        return None if math.isnan(v) else float(v)
    if isinstance(v, np.integer):
        return int(v)
    return v


def row_covariates(record: dict, sheet: str, specimens: dict) -> dict:
    """Covariates of one per-row record: its own, the design columns that may vary
    (``drop_height_mm``), and its specimen's (size and ``specimens`` covariates)."""
    cov = dict(record.get("covariates") or {})
    if sheet == "drop" and record.get("drop_height_m") is not None:
        cov.setdefault("drop_height_mm", round(float(record["drop_height_m"]) * 1e3, 6))
    spec = cov.get("specimen_id")
    if spec is not None and sheet != "specimens" and str(spec) in specimens:
        for k, v in specimens[str(spec)].items():
            cov.setdefault(k, v)
    return cov


def measured_series(measurement, workbook=None) -> list:
    """Series of the per-row values of every measured quantity, and the flank difference and
    floor tilt of the heap photos.

    Parameters
    ----------
    measurement : measure.pipeline.Measurement
    workbook : measure.workbook.Workbook, optional
        For the specimen join (sizes and covariates of the specimen each row names).
    """
    specimens = specimen_lookup(workbook)
    out = []
    for name, est in measurement.quantities.items():
        used = [r for r in est.per_row if r.get("used", True) and r.get("value") is not None]
        if not used:
            continue
        sheet = est.source.get("sheet", "")
        covs = [row_covariates(r, sheet, specimens) for r in used]
        names = []
        for c in covs:
            names += [k for k in c if k not in names]
        out.append(Series(name=name, sheet=sheet, source="measured", family=_family(name), unit=est.unit,
                          rows=tuple(int(r["row"]) for r in used),
                          values=tuple(float(r["value"]) for r in used),
                          covariates={k: tuple(c.get(k) for c in covs) for k in names}))
        if name == "repose_angle_deg":
            out += _photo_series(used, sheet)
    return out + pooled_series(out)


#: Prefix of a pooled series' name (``pooled:restitution``).
POOLED = "pooled:"


def pooled_series(series_list) -> list:
    """One series per family measured on several pairs or surfaces in one sheet (the drop
    pairs' restitutions, the incline surfaces' frictions), each value relative to its own
    pair's mean (y / mean - 1), over the covariates every member has: an effect the pairs
    share (a velocity dependence, a drift with trial order) is tested with all their rows at
    once. Its practical threshold is the family's over the mean of the pairs' means."""
    groups: dict = {}
    for s in series_list:
        if (s.source == "measured" and s.test == "covariates" and "." in s.name
                and s.family in PRACTICAL_THRESHOLDS and len(s.values) >= MIN_ROWS):
            groups.setdefault((s.family, s.sheet), []).append(s)
    out = []
    for (family, sheet), members in groups.items():
        means = [float(np.mean(s.values)) for s in members]
        if len(members) < 2 or min(abs(m) for m in means) == 0:
            continue
        common = [c for c in members[0].covariates if all(c in s.covariates for s in members[1:])]
        rows, values = [], []
        covs: dict = {c: [] for c in common}
        for s, m in zip(members, means):
            rows += list(s.rows)
            values += [v / m - 1.0 for v in s.values]
            for c in common:
                covs[c] += list(s.covariates[c])
        out.append(Series(name=f"{POOLED}{family}", sheet=sheet, source="measured", family=family, unit="1",
                          rows=tuple(rows), values=tuple(values), covariates={c: tuple(v) for c, v in covs.items()},
                          practical_threshold=PRACTICAL_THRESHOLDS[family] / abs(float(np.mean(means))),
                          members=tuple(s.name for s in members)))
    return out


def _photo_series(records, sheet: str) -> list:
    """Left-minus-right flank difference (two-flank photos) and floor tilt of the heap photos."""
    out = []
    both = [r for r in records if (r.get("flanks") or {}).get("left") is not None
            and (r.get("flanks") or {}).get("right") is not None]
    if both:
        out.append(Series(name="flank_difference_deg", sheet=sheet, source="measured",
                          family="flank_difference_deg", unit="deg", rows=tuple(r["row"] for r in both),
                          values=tuple(r["flanks"]["left"] - r["flanks"]["right"] for r in both),
                          covariates={"side": tuple("left-right" for _ in both)}, test="mean"))
    tilt = [r for r in records if r.get("base_tilt_deg") is not None]
    if tilt:
        out.append(Series(name="base_tilt_deg", sheet=sheet, source="measured", family="base_tilt_deg",
                          unit="deg", rows=tuple(r["row"] for r in tilt),
                          values=tuple(float(r["base_tilt_deg"]) for r in tilt),
                          covariates={"floor": tuple("floor" for _ in tilt)}, test="mean"))
    return out
