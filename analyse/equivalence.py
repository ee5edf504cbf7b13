"""Equivalence of a noisy simulator with a lab target: two one-sided tests (TOST).

A DEM heap's angle of repose scatters from seed to seed, so each simulator run is an
independent draw. The lab target is itself a mean of a few photographed heaps. Validation asks
whether the simulated mean equals the lab mean within a tolerance ``tol`` [deg]; a plain test of
"no difference" cannot show that (failing to reject is not evidence of equality), so the
hypotheses are reversed (Schuirmann 1987):

    H0: |d| >= tol    against    H1: |d| < tol,    d = mean(simulated) - mean(lab).

H0 is rejected at level alpha when both one-sided t tests reject, i.e. when the 1 - 2 alpha
confidence interval of d lies inside (-tol, tol). The standard error combines the run scatter
and, when the lab's heap-to-heap sd and heap count are given, the lab mean's own uncertainty:

    SE^2 = s^2 / n + s_lab^2 / n_lab,

and degrees of freedom min(n - 1, n_lab - 1) by default (Hsu 1938), which keeps the test's
size at or below alpha whatever the two variances are (Scheffe 1970); ``df_rule="welch"`` uses
the Welch-Satterthwaite value (Welch 1947)

    df = SE^4 / ((s^2/n)^2 / (n - 1) + (s_lab^2/n_lab)^2 / (n_lab - 1)),

more powerful but above alpha when the lab mean of very few heaps dominates the SE (see
``DF_RULES``). Without the lab sd (or with fewer than two lab heaps) the target is treated as
exact and df = n - 1. A lab target from a few heaps limits what any number of runs can show:
with 3 heaps the t quantile has 2 df. When t_{1-alpha,df} SE is not much smaller than ``tol`` the
interval is nearly as wide as the equivalence band and TOST becomes conservative; when it
exceeds ``tol`` "equivalent" cannot be reached at all, however close the means are.

The verdict is three-way: "equivalent" (interval inside the band), "different" (interval
entirely beyond +tol or -tol, i.e. a one-sided test of non-equivalence rejects) or
"undecided". :func:`sequential_equivalence` looks repeatedly while adding runs and keeps the
overall error rate at alpha with a Haybittle-Peto split (Haybittle 1971; Peto et al. 1976):
every interim look is tested at a strict ``INTERIM_ALPHA`` and the final look at what is left,
alpha - (interim looks) x INTERIM_ALPHA, so that by Bonferroni's inequality the levels sum to
alpha while the final look keeps nearly all of it.

References
----------
.. [1] Schuirmann, D. J. (1987). A comparison of the two one-sided tests procedure and the
   power approach for assessing the equivalence of average bioavailability. Journal of
   Pharmacokinetics and Biopharmaceutics 15(6), 657-680.
.. [5] Hsu, P. L. (1938). Contribution to the theory of "Student's" t-test as applied to the
   problem of two samples. Statistical Research Memoirs 2, 1-24.
.. [6] Scheffe, H. (1970). Practical solutions of the Behrens-Fisher problem. Journal of the
   American Statistical Association 65(332), 1501-1508.
.. [3] Haybittle, J. L. (1971). Repeated assessment of results in clinical trials of cancer
   treatment. British Journal of Radiology 44(526), 793-797.
.. [4] Peto, R. et al. (1976). Design and analysis of randomized clinical trials requiring
   prolonged observation of each patient. I. British Journal of Cancer 34(6), 585-612.
.. [2] Welch, B. L. (1947). The generalization of "Student's" problem when several different
   population variances are involved. Biometrika 34(1-2), 28-35.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import special

from demcal.errors import InputError

DECIDED = ("equivalent", "different")
#: Level of each interim look of a sequential validation (Haybittle-Peto).
INTERIM_ALPHA = 0.001

# Quadrature nodes (equal-probability midpoints) over the sampling distributions of the run
# variance and the lab variance in tost_power; enough for about 1e-3 absolute accuracy.
_RUN_NODES = 96
_LAB_NODES = 64


# -- input checks ---------------------------------------------------------------------------------

def _finite(value, name: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise InputError(f"{name} must be finite, got {value!r}")
    return v


def _positive(value, name: str) -> float:
    v = _finite(value, name)
    if v <= 0:
        raise InputError(f"{name} must be positive, got {value!r}")
    return v


def _alpha(alpha) -> float:
    a = _finite(alpha, "alpha")
    # the 1 - 2 alpha interval only exists for alpha < 0.5
    if not 0 < a < 0.5:
        raise InputError(f"alpha must lie in (0, 0.5), got {alpha!r}")
    return a


def _count(value, name: str, minimum: int) -> int:
    v = _finite(value, name)
    if v != int(v) or v < minimum:
        raise InputError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(v)


def _lab(target_sd, target_n) -> tuple[float | None, int | None, bool]:
    """Checked lab sd and heap count, and whether the lab term enters the SE."""
    sd = None
    if target_sd is not None:
        try:
            sd = float(target_sd)
        except (TypeError, ValueError):
            raise InputError(f"target_sd must be a number, got {target_sd!r}") from None
        if math.isnan(sd):
            sd = None  # an unknown lab sd, as a blank workbook cell gives
        elif not math.isfinite(sd) or sd < 0:
            raise InputError(f"target_sd must be finite and >= 0, got {target_sd!r}")
    m = None if target_n is None else _count(target_n, "target_n", 1)
    return sd, m, sd is not None and m is not None and m >= 2


def _rule(df_rule) -> str:
    if df_rule not in DF_RULES:
        raise InputError(f"df_rule must be one of {', '.join(DF_RULES)}, got {df_rule!r}")
    return df_rule


def _runs(runs) -> np.ndarray:
    try:
        x = np.asarray(runs, dtype=float).ravel()
    except (TypeError, ValueError):
        raise InputError("runs must be a sequence of numbers [deg]") from None
    if x.size < 2:
        raise InputError(f"an equivalence test needs at least 2 runs to estimate the run "
                         f"scatter, got {x.size}")
    if not np.all(np.isfinite(x)):
        raise InputError(f"runs must all be finite; run {int(np.argmin(np.isfinite(x))) + 1} "
                         f"is {x[np.argmin(np.isfinite(x))]!r}")
    return x


def _welch_df(a, b, n, m):
    """Welch-Satterthwaite df of a + b, variance terms with n - 1 and m - 1 df."""
    return (a + b) ** 2 / (a ** 2 / (n - 1) + b ** 2 / (m - 1))


#: Degrees of freedom of the t quantile when the lab term is present: ``conservative`` is
#: min(n - 1, n_lab - 1) (Hsu 1938; never above alpha, Scheffe 1970), ``welch`` the
#: Welch-Satterthwaite value (closer to alpha, but above it when a term with very few df, such
#: as the lab mean of 3 heaps, dominates: 5.1 % at a nominal 5 % with 40 runs of sd 2 against 3
#: heaps of sd 0.5).
DF_RULES = ("conservative", "welch")


def _df(a, b, n, m, rule):
    if rule == "welch":
        return _welch_df(a, b, n, m)
    return np.minimum(n - 1.0, m - 1.0) + 0.0 * (a + b)


# -- tolerance ------------------------------------------------------------------------------------

def default_tolerance(target_sd: float | None, floor_deg: float = 1.0) -> float:
    """Equivalence tolerance: the larger of ``floor_deg`` and the lab's heap-to-heap sd.

    A simulator cannot be asked to match the lab more closely than two lab heaps match each
    other.

    Parameters
    ----------
    target_sd : float or None
        Sample sd of the lab heaps [deg]; None or NaN gives the floor.
    floor_deg : float
        Smallest tolerance [deg].

    Returns
    -------
    float
        Tolerance [deg].
    """
    floor = _positive(floor_deg, "floor_deg")
    sd, _, _ = _lab(target_sd, None)
    return floor if sd is None else max(floor, sd)


# -- the test -------------------------------------------------------------------------------------

@dataclass(frozen=True)
class EquivalenceResult:
    """Outcome of a TOST of simulated against lab mean angle; angles and differences in deg.

    ``difference_ci90`` is the 1 - 2 alpha interval of the difference (90 % at alpha 0.05);
    ``ci95`` is the 95 % interval of the simulated mean itself (run scatter only).
    """

    verdict: str
    mean_deg: float
    ci95: tuple[float, float]
    difference_deg: float
    difference_ci90: tuple[float, float]
    se_deg: float
    df: float
    p_tost: float
    p_lower: float
    p_upper: float
    tolerance_deg: float
    target_deg: float
    target_sd_deg: float | None
    target_n: int | None
    lab_term: bool
    n_runs: int
    run_sd_deg: float
    detectable_bias_deg: float
    alpha: float
    note: str

    def to_dict(self) -> dict:
        return {"verdict": self.verdict, "mean_deg": self.mean_deg, "ci95": list(self.ci95),
                "difference_deg": self.difference_deg,
                "difference_ci90": list(self.difference_ci90), "se_deg": self.se_deg,
                "df": self.df, "p_tost": self.p_tost, "p_lower": self.p_lower,
                "p_upper": self.p_upper, "tolerance_deg": self.tolerance_deg,
                "target_deg": self.target_deg, "target_sd_deg": self.target_sd_deg,
                "target_n": self.target_n, "lab_term": self.lab_term, "n_runs": self.n_runs,
                "run_sd_deg": self.run_sd_deg, "detectable_bias_deg": self.detectable_bias_deg,
                "alpha": self.alpha, "note": self.note}


def equivalence_test(runs, target_mean: float, target_sd: float | None = None,
                     target_n: int | None = None, tolerance: float = 1.0,
                     alpha: float = 0.05, df_rule: str = "conservative") -> EquivalenceResult:
    """Two one-sided tests of |mean(runs) - target_mean| < tolerance (Schuirmann 1987).

    Parameters
    ----------
    runs : array_like
        Simulated angles, one per independent run [deg]; at least 2.
    target_mean : float
        Lab mean angle [deg].
    target_sd, target_n : float, int, optional
        Lab heap-to-heap sample sd [deg] and number of heaps. Both are needed (and
        ``target_n >= 2``) for the lab mean's uncertainty to enter the SE; otherwise the target
        is treated as exact and df = n - 1.
    tolerance : float
        Equivalence margin [deg].
    alpha : float
        Level of each one-sided test; the verdict uses the 1 - 2 alpha interval.
    df_rule : {"conservative", "welch"}
        Degrees of freedom with the lab term (``DF_RULES``).

    Returns
    -------
    EquivalenceResult
        ``p_tost = max(p_lower, p_upper)``; verdict "equivalent", "different" or "undecided".

    Raises
    ------
    InputError
        Fewer than 2 runs, non-finite values, non-positive tolerance or alpha outside (0, 0.5).
    """
    x = _runs(runs)
    target = _finite(target_mean, "target_mean")
    tol = _positive(tolerance, "tolerance")
    a_lvl = _alpha(alpha)
    sd_lab, m, lab = _lab(target_sd, target_n)
    rule = _rule(df_rule)

    n = x.size
    mean = float(x.mean())
    s = float(x.std(ddof=1))
    d = mean - target
    a = s * s / n
    b = sd_lab * sd_lab / m if lab else 0.0
    se2 = a + b
    se = math.sqrt(se2)
    df = float(_df(a, b, n, m, rule)) if lab and se2 > 0 else float(n - 1)

    t_q = float(special.stdtrit(df, 1 - a_lvl))
    ci = (d - t_q * se, d + t_q * se)
    if se > 0:
        # p_lower tests H0: d <= -tol, p_upper tests H0: d >= +tol
        p_lower = float(special.stdtr(df, -(d + tol) / se))
        p_upper = float(special.stdtr(df, (d - tol) / se))
    else:
        # identical runs and an exact target: the difference is known without error
        p_lower = 0.0 if d > -tol else 1.0
        p_upper = 0.0 if d < tol else 1.0

    if -tol < ci[0] and ci[1] < tol:
        verdict = "equivalent"
    elif ci[0] > tol or ci[1] < -tol:
        verdict = "different"
    else:
        verdict = "undecided"

    half95 = float(special.stdtrit(n - 1, 0.975)) * s / math.sqrt(n)
    detectable = (float(special.stdtrit(df, 1 - a_lvl / 2))
                  + float(special.stdtrit(df, 0.80))) * se

    notes = []
    if lab:
        how = "Welch-Satterthwaite" if rule == "welch" else "conservative, min(n - 1, n_lab - 1)"
        notes.append(f"SE combines the run scatter and the lab mean's scatter ({m} heaps); "
                     f"df {how} = {df:.1f}.")
    else:
        why = ("no lab sd given" if sd_lab is None else
               "no lab heap count given" if m is None else "fewer than 2 lab heaps")
        notes.append(f"Lab target treated as exact ({why}); SE holds only the run scatter, "
                     f"df = n - 1 = {n - 1}.")
    if t_q * se >= tol:
        notes.append(f"The 1 - 2 alpha interval half-width {t_q * se:.2f} deg is not below the "
                     f"tolerance {tol:g} deg: 'equivalent' cannot be reached with these runs; "
                     f"more runs (or a tighter lab mean) are needed.")

    return EquivalenceResult(
        verdict=verdict, mean_deg=mean, ci95=(mean - half95, mean + half95), difference_deg=d,
        difference_ci90=ci, se_deg=se, df=df, p_tost=max(p_lower, p_upper), p_lower=p_lower,
        p_upper=p_upper, tolerance_deg=tol, target_deg=target, target_sd_deg=sd_lab,
        target_n=m, lab_term=lab, n_runs=int(n), run_sd_deg=s, detectable_bias_deg=detectable,
        alpha=a_lvl, note=" ".join(notes))


# -- power and sample size ------------------------------------------------------------------------

def _variance_ratio_nodes(df: int, k: int) -> np.ndarray:
    """Equal-probability nodes of chi2(df) / df, the ratio of a sample to a true variance."""
    u = (np.arange(k) + 0.5) / k
    return special.chdtri(df, 1.0 - u) / df


def _power(bias, run_sd, n, tol, lab_sd, lab_n, alpha, lab_nodes, rule="conservative") -> float:
    a_true = run_sd ** 2 / n
    b_true = lab_sd ** 2 / lab_n if lab_nodes is not None else 0.0
    sd_d = math.sqrt(a_true + b_true)
    if sd_d == 0:
        return 1.0 if abs(bias) < tol else 0.0
    a_hat = a_true * _variance_ratio_nodes(n - 1, _RUN_NODES)[:, None]
    if lab_nodes is None:
        b_hat = np.zeros((1, 1))
        df = np.full_like(a_hat, n - 1.0)
    else:
        b_hat = b_true * lab_nodes[None, :]
        with np.errstate(invalid="ignore", divide="ignore"):
            df = _df(a_hat, b_hat, n, lab_n, rule)
        # zero true variances give 0/0; the df is then that of the other term
        df = np.where(np.isfinite(df), df, n - 1.0 if b_true == 0 else lab_n - 1.0)
    se_hat = np.sqrt(a_hat + b_hat)
    # "equivalent" <=> |d_hat| < tol - t SE_hat; d_hat is normal and independent of SE_hat
    half = tol - special.stdtrit(df, 1 - alpha) * se_hat
    prob = special.ndtr((half - bias) / sd_d) - special.ndtr((-half - bias) / sd_d)
    return float(np.mean(np.where(half > 0, prob, 0.0)))


def tost_power(bias: float, run_sd: float, n: int, tolerance: float,
               target_sd: float | None = None, target_n: int | None = None,
               alpha: float = 0.05, df_rule: str = "conservative") -> float:
    """Probability that :func:`equivalence_test` returns "equivalent".

    Exact for normally distributed runs and lab heaps (no normal or noncentral-t
    approximation): given the estimated variances, the observed difference is normal and
    independent of them, so the power is the normal probability of
    ``|d_hat| < tol - t_{1-alpha,df} SE_hat`` averaged over the chi-square distributions of
    the run variance and the lab variance (df and SE_hat vary with them), by equal-probability
    quadrature (about 1e-3 absolute accuracy).

    Parameters
    ----------
    bias : float
        True difference simulated - lab [deg].
    run_sd : float
        True run-to-run sd [deg].
    n : int
        Number of runs (>= 2).
    tolerance : float
        Equivalence margin [deg].
    target_sd, target_n : float, int, optional
        True lab heap-to-heap sd [deg] and number of lab heaps; the lab term enters as in
        :func:`equivalence_test`.
    alpha : float
        Level of each one-sided test.

    Returns
    -------
    float
        Probability of the verdict "equivalent".
    """
    bias = _finite(bias, "bias")
    run_sd = _finite(run_sd, "run_sd")
    if run_sd < 0:
        raise InputError(f"run_sd must be >= 0, got {run_sd!r}")
    n = _count(n, "n", 2)
    tol = _positive(tolerance, "tolerance")
    a_lvl = _alpha(alpha)
    sd_lab, m, lab = _lab(target_sd, target_n)
    nodes = _variance_ratio_nodes(m - 1, _LAB_NODES) if lab else None
    return _power(bias, run_sd, n, tol, sd_lab, m, a_lvl, nodes, _rule(df_rule))


def runs_for_power(bias: float, run_sd: float, tolerance: float, power: float = 0.8,
                   target_sd: float | None = None, target_n: int | None = None,
                   alpha: float = 0.05, n_max: int = 400,
                   df_rule: str = "conservative") -> int | None:
    """Smallest number of runs for which :func:`tost_power` reaches ``power``.

    More runs shrink only the run term of the SE; the lab term (and its few df) stays, so with
    a scattered lab target the power may level off below ``power`` for any n. Every n from 2 to
    ``n_max`` is evaluated (with the lab term the power need not grow monotonically in n,
    because the Welch df falls towards n_lab - 1).

    Parameters
    ----------
    bias, run_sd, tolerance, target_sd, target_n, alpha
        As in :func:`tost_power`.
    power : float
        Required probability of "equivalent", in (0, 1).
    n_max : int
        Largest number of runs considered.

    Returns
    -------
    int or None
        The number of runs, or None if ``power`` is not reached for any n <= ``n_max``.
    """
    bias = _finite(bias, "bias")
    run_sd = _finite(run_sd, "run_sd")
    if run_sd < 0:
        raise InputError(f"run_sd must be >= 0, got {run_sd!r}")
    tol = _positive(tolerance, "tolerance")
    goal = _finite(power, "power")
    if not 0 < goal < 1:
        raise InputError(f"power must lie in (0, 1), got {power!r}")
    a_lvl = _alpha(alpha)
    n_max = _count(n_max, "n_max", 2)
    sd_lab, m, lab = _lab(target_sd, target_n)
    nodes = _variance_ratio_nodes(m - 1, _LAB_NODES) if lab else None
    if abs(bias) >= tol and goal >= 0.5:
        # "equivalent" needs d_hat on the near side of the margin, which has probability <= 0.5
        return None
    for n in range(2, n_max + 1):
        if _power(bias, run_sd, n, tol, sd_lab, m, a_lvl, nodes, _rule(df_rule)) >= goal:
            return n
    return None


# -- sequential validation ------------------------------------------------------------------------

@dataclass(frozen=True)
class Look:
    """One interim analysis of :func:`sequential_equivalence`."""

    n_runs: int
    verdict: str
    p_tost: float
    difference_ci90: tuple[float, float]

    def to_dict(self) -> dict:
        return {"n_runs": self.n_runs, "verdict": self.verdict, "p_tost": self.p_tost,
                "difference_ci90": list(self.difference_ci90)}


@dataclass(frozen=True)
class SequentialResult(EquivalenceResult):
    """Final look of a sequential validation plus the history of looks.

    The inherited fields describe the last look, tested at its own level (the last entry of
    ``alpha_per_look``; ``difference_ci90`` is the 1 - 2 alpha interval at that level);
    ``alpha`` is the overall level.
    """

    looks: tuple[Look, ...]
    planned_looks: tuple[int, ...]
    alpha_per_look: tuple[float, ...]
    stopped_because: str

    def to_dict(self) -> dict:
        out = super().to_dict()
        out.update({"looks": [look.to_dict() for look in self.looks],
                    "planned_looks": list(self.planned_looks),
                    "alpha_per_look": list(self.alpha_per_look),
                    "stopped_because": self.stopped_because})
        return out


def sequential_equivalence(draw, target_mean: float, target_sd: float | None,
                           target_n: int | None, tolerance: float, *, first: int = 10,
                           step: int = 10, cap: int = 40,
                           alpha: float = 0.05, df_rule: str = "conservative") -> SequentialResult:
    """Add runs in batches and stop as soon as the TOST verdict is decided, or at ``cap`` runs.

    Looks are planned after ``first`` runs, then every ``step`` more, and at ``cap``. Interim
    looks are tested at ``INTERIM_ALPHA`` and the last at alpha minus their sum (Haybittle-Peto;
    the levels add up to alpha, so by Bonferroni's inequality the probability of a false
    "equivalent", or of a false "different", over all looks is at most ``alpha``).

    Parameters
    ----------
    draw : callable
        ``draw(k)`` returns k new, independent run values [deg]; it holds all the randomness,
        so the same ``draw`` replays the same validation.
    target_mean, target_sd, target_n, tolerance
        As in :func:`equivalence_test`.
    first, step, cap : int
        Runs at the first look, runs added between looks, largest number of runs.
    alpha : float
        Overall level.

    Returns
    -------
    SequentialResult
        ``stopped_because`` is "decided" or "cap".
    """
    first = _count(first, "first", 2)
    step = _count(step, "step", 1)
    cap = _count(cap, "cap", first)
    a_all = _alpha(alpha)
    planned = list(range(first, cap + 1, step))
    if planned[-1] != cap:
        planned.append(cap)
    interim = min(INTERIM_ALPHA, a_all / (2 * len(planned)))
    levels = [interim] * (len(planned) - 1) + [a_all - interim * (len(planned) - 1)]

    runs: list[float] = []
    looks: list[Look] = []
    result = None
    for n_k, a_look in zip(planned, levels):
        k = n_k - len(runs)
        new = np.asarray(draw(k), dtype=float).ravel()
        if new.size != k:
            raise InputError(f"draw({k}) returned {new.size} values, expected {k}")
        runs.extend(new.tolist())
        result = equivalence_test(runs, target_mean, target_sd, target_n, tolerance, a_look, df_rule)
        looks.append(Look(n_k, result.verdict, result.p_tost, result.difference_ci90))
        if result.verdict in DECIDED:
            break

    stopped = "decided" if result.verdict in DECIDED else "cap"
    note = (f"{result.note} Sequential: {len(looks)} of {len(planned)} planned looks "
            f"({', '.join(map(str, planned))} runs), interim looks at {interim:.4g} and the last at "
            f"{levels[-1]:.4g} (Haybittle-Peto) for an overall level {a_all:g}; stopped: {stopped}.")
    fields = {f: getattr(result, f) for f in EquivalenceResult.__dataclass_fields__}
    fields.update(alpha=a_all, note=note)
    return SequentialResult(**fields, looks=tuple(looks), planned_looks=tuple(planned),
                            alpha_per_look=tuple(levels[:len(looks)]), stopped_because=stopped)


def lab_heaps_for_power(run_sd: float, n_runs: int, tolerance: float, target_sd: float,
                        power: float = 0.8, bias: float = 0.0, alpha: float = 0.05,
                        df_rule: str = "conservative", n_max: int = 50) -> int | None:
    """Fewest lab heaps for which ``n_runs`` validation runs reach ``power`` of showing
    equivalence (at a true difference ``bias``): what the lab would need to photograph for the
    validation to be able to succeed. None if not reached with ``n_max`` heaps."""
    target_sd = _positive(target_sd, "target_sd")
    for m in range(2, n_max + 1):
        if tost_power(bias, run_sd, n_runs, tolerance, target_sd, m, alpha, df_rule) >= power:
            return m
    return None
