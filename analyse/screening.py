"""Screening two-level designs: effects, Plackett-Burman ANOVA with dummy columns pooled as
error, Pareto chart data, Lenth's pseudo standard error and Box & Meyer's Bayesian screening.

References
----------
.. [1] Plackett, R. L. & Burman, J. P. (1946). Biometrika 33(4), 305-325.
.. [2] Lenth, R. V. (1989). Quick and easy analysis of unreplicated factorials.
   Technometrics 31(4), 469-473.
.. [3] Box, G. E. P. & Meyer, R. D. (1993). Finding the active factors in fractionated
   screening experiments. Journal of Quality Technology 25(2), 94-105.
.. [4] Box, G. E. P., Hunter, J. S. & Hunter, W. G. (2005). Statistics for Experimenters,
   2nd ed. Wiley. Effects as mean(+) - mean(-).
.. [5] Stat-Ease Inc., Design-Expert help: Pareto chart of |t| values with the t-value limit
   and the Bonferroni limit.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from scipy import stats

from demcal.analyse.designs import factor_letters
from demcal.analyse.regression import ResponseSurface, fit_response_surface
from demcal.errors import AnalysisError, InputError


def _two_level(coded, name="coded"):
    x = np.asarray(coded, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    snapped = np.round(x)
    # coding actual levels leaves rounding noise of order 1e-16
    bad = (np.abs(x - snapped) > 1e-9) | (np.abs(snapped) > 1)
    if np.any(bad):
        r, c = map(int, np.argwhere(bad)[0])
        raise InputError(f"{name} must hold coded levels -1/+1 (0 for centre points); "
                         f"run {r + 1}, column {c + 1} holds {float(x[r, c])!r}")
    return snapped


def two_level_effects(coded, response, names=None, max_order: int = 1) -> dict:
    """Effects mean(y | +) - mean(y | -) of each column and of its interactions (BHH 2005).

    Parameters
    ----------
    coded : array_like
        (n, k) levels -1/+1 [-] (centre points at 0 take part in neither mean).
    response : array_like
        (n,) response [response units].
    names : sequence of str, optional
        Column names (default A, B, C, ...); interactions concatenate them (``BD``).
    max_order : int
        1 for main effects only, 2 adds two-factor interactions, ... up to k.

    Returns
    -------
    dict
        Effect name -> effect [response units], main effects first, then by order.
    """
    x = _two_level(coded)
    y = np.asarray(response, dtype=float).ravel()
    if y.size != x.shape[0]:
        raise InputError(f"response has {y.size} values but the design has {x.shape[0]} runs")
    k = x.shape[1]
    names = tuple(names) if names is not None else factor_letters(k)
    out = {}
    for order in range(1, min(max_order, k) + 1):
        for combo in itertools.combinations(range(k), order):
            col = np.prod(x[:, combo], axis=1)
            plus, minus = col > 0, col < 0
            if not plus.any() or not minus.any():
                raise AnalysisError(f"column {''.join(names[i] for i in combo)} has no runs at "
                                    f"one of its levels")
            out["".join(names[i] for i in combo)] = float(y[plus].mean() - y[minus].mean())
    return out


# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class LenthResult:
    """Lenth's (1989) margins for unreplicated two-level designs.

    Attributes
    ----------
    pse : float
        Pseudo standard error [response units].
    me, sme : float
        Margin of error t(1 - alpha/2, d) PSE and simultaneous margin of error
        t(gamma, d) PSE, gamma = (1 + (1 - alpha)^(1/m)) / 2 [response units].
    d : float
        Degrees of freedom m / 3.
    alpha : float
    active : tuple of str
        Effects with |effect| > ME, largest first.
    strongly_active : tuple of str
        Effects with |effect| > SME, largest first.
    """

    pse: float
    me: float
    sme: float
    d: float
    alpha: float
    active: tuple[str, ...]
    strongly_active: tuple[str, ...]

    def to_dict(self) -> dict:
        return {"pse": self.pse, "me": self.me, "sme": self.sme, "d": self.d, "alpha": self.alpha,
                "active": list(self.active), "strongly_active": list(self.strongly_active)}


def lenth(effects: dict, alpha: float = 0.05) -> LenthResult:
    """Lenth's pseudo standard error, margin of error and simultaneous margin of error.

    s0 = 1.5 median |c_j|; PSE = 1.5 median{|c_j| : |c_j| < 2.5 s0}; d = m/3;
    ME = t(1 - alpha/2, d) PSE; SME = t(gamma, d) PSE with gamma = (1 + (1 - alpha)^(1/m))/2
    (Lenth 1989, eqs. 2-4).

    Parameters
    ----------
    effects : dict
        Name -> effect (contrast) [response units], all m estimable contrasts of the design.
    alpha : float
        Significance level.
    """
    if len(effects) < 3:
        raise AnalysisError(f"Lenth's method needs at least 3 effects, got {len(effects)}")
    if not 0 < alpha < 1:
        raise InputError(f"alpha must be in (0, 1), got {alpha!r}")
    names = list(effects)
    c = np.abs(np.array([effects[n] for n in names], dtype=float))
    m = c.size
    s0 = 1.5 * np.median(c)
    trimmed = c[c < 2.5 * s0]
    # more than half the contrasts exactly zero (a noiseless stand-in): no pseudo standard error
    pse = float(1.5 * np.median(trimmed)) if trimmed.size else float("nan")
    d = m / 3.0
    me = float(stats.t.ppf(1 - alpha / 2, d) * pse)
    gamma = (1 + (1 - alpha) ** (1 / m)) / 2
    sme = float(stats.t.ppf(gamma, d) * pse)
    order = np.argsort(-c, kind="stable")
    active = tuple(names[i] for i in order if c[i] > me)
    strong = tuple(names[i] for i in order if c[i] > sme)
    return LenthResult(pse, me, sme, d, alpha, active, strong)


# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class ParetoChart:
    """Data of Design-Expert's Pareto chart of effects.

    Attributes
    ----------
    names : tuple of str
        Effects sorted by decreasing |t|.
    t_values : tuple of float
        |t| of each effect (coefficient / standard error, or effect / PSE) [-].
    signs : tuple of int
        Sign of each effect (+1 / -1).
    t_limit : float
        t(1 - alpha/2, df) [-].
    bonferroni_limit : float
        t(1 - alpha/(2 m), df), m the number of effects [-].
    df : float
        Degrees of freedom of the limits.
    basis : str
        ``residual`` (standard errors from the residual mean square) or ``lenth`` (PSE).
    """

    names: tuple[str, ...]
    t_values: tuple[float, ...]
    signs: tuple[int, ...]
    t_limit: float
    bonferroni_limit: float
    df: float
    basis: str

    def to_dict(self) -> dict:
        return {"names": list(self.names), "t_values": list(self.t_values),
                "signs": list(self.signs), "t_limit": self.t_limit,
                "bonferroni_limit": self.bonferroni_limit, "df": self.df, "basis": self.basis}


def pareto(t_values: dict, df: float, alpha: float = 0.05, basis: str = "residual") -> ParetoChart:
    """Sort signed t values for a Pareto chart and compute its two limits.

    Parameters
    ----------
    t_values : dict
        Name -> signed t value [-].
    df : float
        Degrees of freedom of the standard error (residual df, or m/3 for Lenth's PSE).
    alpha : float
        Significance level of the limits.
    basis : str
        Where the standard error came from, recorded in the result.
    """
    if df <= 0:
        raise AnalysisError("the Pareto limits need an error estimate with df > 0")
    names = list(t_values)
    t = np.array([t_values[n] for n in names], dtype=float)
    order = np.argsort(-np.abs(t), kind="stable")
    m = len(names)
    return ParetoChart(
        names=tuple(names[i] for i in order),
        t_values=tuple(float(abs(t[i])) for i in order),
        signs=tuple(int(np.sign(t[i]) or 1) for i in order),
        t_limit=float(stats.t.ppf(1 - alpha / 2, df)),
        bonferroni_limit=float(stats.t.ppf(1 - alpha / (2 * m), df)),
        df=float(df), basis=basis)


# --------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class PlackettBurmanScreening:
    """Result of a Plackett-Burman (or any two-level main-effects) screening.

    Attributes
    ----------
    factors : tuple of str
        Factor names, in the order of the letters.
    letters : tuple of str
        Factor letters A, B, ...
    effects : dict
        Letter -> effect mean(+) - mean(-) [response units].
    coefficients : dict
        Coded coefficients (effect / 2 for orthogonal designs), Intercept first.
    contribution_pct : dict
        Letter -> 100 SS_effect / SS_total [%] (Design-Expert's % contribution).
    ranking : tuple of str
        Letters by decreasing |effect|.
    significant : tuple of str
        Letters with ANOVA p < alpha, by decreasing |effect|.
    alpha : float
    regression : ResponseSurface
        First-order fit; its ANOVA pools the dummy columns into the residual.
    pareto : ParetoChart or None
    lenth : LenthResult or None
        Over the factor and dummy effects, when at least 3 contrasts exist.
    dummy_effects : dict
        Effects of the dummy columns, when given [response units].
    """

    factors: tuple[str, ...]
    letters: tuple[str, ...]
    effects: dict
    coefficients: dict
    contribution_pct: dict
    ranking: tuple[str, ...]
    significant: tuple[str, ...]
    alpha: float
    regression: ResponseSurface
    pareto: ParetoChart | None
    lenth: LenthResult | None
    dummy_effects: dict

    def to_dict(self) -> dict:
        out = self.regression.to_dict()
        out.update({
            "effects": dict(self.effects),
            "dummy_effects": dict(self.dummy_effects),
            "contribution_pct": dict(self.contribution_pct),
            "ranking": list(self.ranking),
            "significant": list(self.significant),
            "alpha": self.alpha,
            "pareto": None if self.pareto is None else self.pareto.to_dict(),
            "lenth": None if self.lenth is None else self.lenth.to_dict(),
        })
        return out


def plackett_burman_screening(coded, response, factors=None, *, dummies=None,
                              alpha: float = 0.05, response_name: str = "y",
                              low=None, high=None) -> PlackettBurmanScreening:
    """Screen factors of a two-level design the way the source paper does in Design-Expert.

    Main effects mean(+) - mean(-), coefficients from a first-order least-squares fit, Type III
    ANOVA in which the unassigned (dummy) columns are pooled into the residual, significance at
    ``alpha``, Design-Expert's % contribution and Pareto chart, and Lenth's margins over all
    contrasts (factors and dummies).

    Parameters
    ----------
    coded : array_like
        (n, k) factor levels -1/+1 [-].
    response : array_like
        (n,) response [response units].
    factors : sequence of str, optional
        Factor names (default A, B, ...).
    dummies : array_like, optional
        (n, m) dummy columns -1/+1; only used for Lenth's margins and reported effects (the
        residual of the first-order fit already contains them).
    alpha : float
        Significance level.
    response_name : str
    low, high : array_like, optional
        Actual levels coded -1/+1, for the actual equation.
    """
    x = _two_level(coded)
    y = np.asarray(response, dtype=float).ravel()
    n, k = x.shape
    fit = fit_response_surface(x, y, "linear", factors=factors, response_name=response_name,
                               low=low, high=high)
    letters = fit.letters
    effects = two_level_effects(x, y, letters)
    dummy_effects = {}
    if dummies is not None:
        dz = _two_level(dummies, "dummies")
        if dz.shape[0] != n:
            raise InputError(f"dummies have {dz.shape[0]} rows but the design has {n} runs")
        dummy_effects = two_level_effects(dz, y, [f"dummy_{i + 1}" for i in range(dz.shape[1])])
    ss_total = fit.anova_row("Cor Total").ss
    contribution = {t: 100.0 * fit.anova_row(t).ss / ss_total if ss_total > 0 else float("nan")
                    for t in letters}
    ranking = tuple(sorted(letters, key=lambda t: -abs(effects[t])))
    significant = tuple(t for t in ranking
                        if fit.anova_row(t).p is not None and fit.anova_row(t).p < alpha)

    all_effects = {**effects, **dummy_effects}
    len_res = lenth(all_effects, alpha) if len(all_effects) >= 3 else None
    if fit.fit.df_residual > 0 and np.isfinite(fit.fit.std_dev) and fit.fit.std_dev > 0:
        tvals = {t: fit.coefficients[t] / fit.std_errors[t] for t in letters}
        chart = pareto(tvals, fit.fit.df_residual, alpha, "residual")
    elif len_res is not None and len_res.pse > 0:
        chart = pareto({t: e / len_res.pse for t, e in all_effects.items()}, len_res.d, alpha,
                       "lenth")
    else:
        chart = None
    return PlackettBurmanScreening(
        factors=fit.factors, letters=letters, effects=effects, coefficients=dict(fit.coefficients),
        contribution_pct=contribution, ranking=ranking, significant=significant, alpha=alpha,
        regression=fit, pareto=chart, lenth=len_res, dummy_effects=dummy_effects)


# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class BoxMeyerResult:
    """Box & Meyer (1993) Bayesian screening.

    Attributes
    ----------
    factor_probability : dict
        Factor name -> marginal posterior probability of being active [-].
    none_probability : float
        Posterior probability of the model with no active factor [-].
    top_models : tuple of dict
        The most probable models: ``factors`` (names), ``probability``, ``sigma2`` (the model's
        Bayesian residual sum of squares / (n - 1)) [response units^2].
    prior : float
        Prior probability pi that a factor is active.
    gamma : float
        Prior effect scale: effects ~ N(0, gamma^2 sigma^2).
    max_interaction : int
        Highest interaction order included in each model.
    n_models : int
        Number of models evaluated.
    """

    factor_probability: dict
    none_probability: float
    top_models: tuple
    prior: float
    gamma: float
    max_interaction: int
    n_models: int

    def active(self, threshold: float = 0.5) -> tuple[str, ...]:
        """Factors with posterior probability above ``threshold``, most probable first."""
        items = sorted(self.factor_probability.items(), key=lambda kv: -kv[1])
        return tuple(name for name, p in items if p > threshold)

    def to_dict(self) -> dict:
        return {"factor_probability": dict(self.factor_probability),
                "none_probability": self.none_probability,
                "top_models": [dict(m, factors=list(m["factors"])) for m in self.top_models],
                "prior": self.prior, "gamma": self.gamma,
                "max_interaction": self.max_interaction, "n_models": self.n_models}


def box_meyer(coded, response, factors=None, *, prior: float = 0.25, gamma: float = 2.0,
              max_factors: int | None = None, max_interaction: int = 2,
              n_top: int = 10) -> BoxMeyerResult:
    """Posterior probability that each factor is active (Box & Meyer 1993).

    Every subset M of at most ``max_factors`` factors is a model holding the subset's main
    effects and all its interactions up to order ``max_interaction`` (t terms). With effects
    ~ N(0, gamma^2 sigma^2) and an improper prior on the intercept and sigma,

        P(M | y) ∝ (pi/(1-pi))^f gamma^-t sqrt(n) |Gamma + X'X|^-1/2 (S_M / S_0)^(-(n-1)/2)

    with Gamma = diag(0, gamma^-2 I), S_M = y'y - y'X beta_M the Bayesian residual sum of
    squares, beta_M = (Gamma + X'X)^-1 X'y, S_0 the corrected total sum of squares and f the
    number of factors in M (the formula of Meyer's program ``mbcqpi5``, distributed with
    BsMD). A factor's marginal probability sums P(M | y) over the models that hold it.

    Parameters
    ----------
    coded : array_like
        (n, k) factor columns, usually -1/+1 [-].
    response : array_like
        (n,) response [response units].
    factors : sequence of str, optional
        Factor names (default A, B, ...).
    prior : float
        Prior probability pi that a factor is active, 0 < pi < 1.
    gamma : float
        Ratio of the prior standard deviation of an active effect to sigma (> 0).
    max_factors : int, optional
        Largest number of factors in a model (default all).
    max_interaction : int
        Highest interaction order in a model (1 = main effects only).
    n_top : int
        Number of most probable models to keep.
    """
    x = np.asarray(coded, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    y = np.asarray(response, dtype=float).ravel()
    n, k = x.shape
    if y.size != n:
        raise InputError(f"response has {y.size} values but the design has {n} runs")
    if not 0 < prior < 1:
        raise InputError(f"prior must be in (0, 1), got {prior!r}")
    if not gamma > 0:
        raise InputError(f"gamma must be positive, got {gamma!r}")
    if max_interaction < 1:
        raise InputError(f"max_interaction must be >= 1, got {max_interaction}")
    names = tuple(factors) if factors is not None else factor_letters(k)
    max_factors = k if max_factors is None else int(max_factors)
    if not 1 <= max_factors <= k:
        raise InputError(f"max_factors must be 1..{k}, got {max_factors}")

    yc = y - y.mean()
    s0 = float(yc @ yc)
    if s0 <= 0:
        raise AnalysisError("the response does not vary; nothing to screen")
    # With the intercept profiled out (centred columns Xc) and Sylvester's identity,
    # |Gamma + X'X| = n gamma^(-2t) |K| and S_M = yc' K^-1 yc with K = I_n + gamma^2 Xc Xc',
    # so gamma^-t cancels and each model costs one n x n factorisation.
    log_ratio = np.log(prior / (1 - prior))
    g2 = gamma ** 2
    eye = np.eye(n)
    logw, models, sig2 = [], [], []
    for f in range(0, max_factors + 1):
        for subset in itertools.combinations(range(k), f):
            cols = [np.prod(x[:, combo], axis=1)
                    for order in range(1, min(max_interaction, f) + 1)
                    for combo in itertools.combinations(subset, order)]
            if cols:
                Xc = np.column_stack(cols)
                Xc = Xc - Xc.mean(axis=0)
                K = eye + g2 * (Xc @ Xc.T)
            else:
                K = eye
            L = np.linalg.cholesky(K)
            z = np.linalg.solve(L, yc)
            sr = float(z @ z)
            logdet_k = 2.0 * float(np.sum(np.log(np.diag(L))))
            logw.append(f * log_ratio - 0.5 * logdet_k - 0.5 * (n - 1) * np.log(sr / s0))
            models.append(subset)
            sig2.append(sr / (n - 1))
    logw = np.array(logw)
    w = np.exp(logw - logw.max())
    post = w / w.sum()
    probs = {name: 0.0 for name in names}
    none = 0.0
    for pm, subset in zip(post, models):
        if not subset:
            none += pm
        for i in subset:
            probs[names[i]] += pm
    top = np.argsort(-post, kind="stable")[:n_top]
    top_models = tuple({"factors": tuple(names[i] for i in models[j]),
                        "probability": float(post[j]), "sigma2": float(sig2[j])} for j in top)
    return BoxMeyerResult({k_: float(v) for k_, v in probs.items()}, float(none), top_models,
                          prior, gamma, max_interaction, len(models))


__all__ = ["two_level_effects", "lenth", "LenthResult", "pareto", "ParetoChart",
           "plackett_burman_screening", "PlackettBurmanScreening", "box_meyer", "BoxMeyerResult"]
