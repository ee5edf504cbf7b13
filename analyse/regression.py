"""Polynomial response-surface regression and its analysis of variance, as Design-Expert
reports them.

A model (first-order, two-factor interaction, full quadratic, or an explicit list of terms) is
fitted by least squares in coded units, optionally with a block term. The ANOVA has the rows
Design-Expert prints: Block (its sequential sum of squares, entered first and kept out of the
Model), Model, each term with its Type III (partial) sum of squares, Residual, Lack of Fit, Pure
Error (replicated design points, within blocks) and Cor Total; then Std. Dev., Mean, C.V. %,
R-squared, adjusted and predicted R-squared (PRESS) and Adeq Precision; the coded equation and
the same polynomial expanded exactly into actual units.

Terms are named as Design-Expert names them: factor letters ``A``, ``B``, ... (see
:data:`analyse.designs.FACTOR_LETTERS`), interactions ``AB``, ``ABC``, pure quadratics ``A^2``.

References
----------
.. [1] Myers, R. H., Montgomery, D. C. & Anderson-Cook, C. M. (2009). Response Surface
   Methodology, 3rd ed. Wiley. Sections 2.7 (lack of fit), 2.8 (PRESS), 7.3 (blocking).
.. [2] Stat-Ease Inc., Design-Expert help, "ANOVA" pages: Predicted R-Squared
   = 1 - PRESS / (SS_total - SS_block); PRESS = sum (e_i / (1 - h_ii))^2;
   Adeq Precision = (max yhat - min yhat) / sqrt(p MSE / n).
.. [3] Montgomery, D. C. (2017). Design and Analysis of Experiments, 9th ed. Wiley.
   Type III (partial) sums of squares.
"""

from __future__ import annotations

import re
from collections import Counter
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from demcal.analyse.designs import factor_letters, to_actual, to_coded
from demcal.errors import AnalysisError, InputError

#: Model names accepted by :func:`fit_response_surface` (Design-Expert's model orders).
MODELS = ("linear", "2fi", "quadratic")

#: Significance bands of the source paper's table notes (and Design-Expert's defaults).
HIGHLY_SIGNIFICANT = 0.01
SIGNIFICANT = 0.05


def significance(p) -> str | None:
    """Verdict for a p-value: < 0.01 highly significant, < 0.05 significant, else not."""
    if p is None or not np.isfinite(p):
        return None
    if p < HIGHLY_SIGNIFICANT:
        return "highly significant"
    if p < SIGNIFICANT:
        return "significant"
    return "not significant"


# --------------------------------------------------------------------------------------------
# Terms: a term is a sorted tuple of factor indices, () the intercept, (0,) A, (0, 1) AB,
# (0, 0) A^2.

def term_name(powers: tuple[int, ...], letters) -> str:
    """Design-Expert name of a term: ``A``, ``AB``, ``A^2``, ``A^2B``."""
    if not powers:
        return "Intercept"
    counts = Counter(powers)
    return "".join(letters[i] + (f"^{c}" if c > 1 else "") for i, c in sorted(counts.items()))


_TOKEN = re.compile(r"([A-Z])(?:\^(\d+))?")


def parse_term(name: str, letters) -> tuple[int, ...]:
    """Inverse of :func:`term_name` (``"AB"`` -> (0, 1), ``"A^2"`` -> (0, 0))."""
    text = name.replace(" ", "").replace("*", "")
    pos, powers = 0, []
    for m in _TOKEN.finditer(text):
        if m.start() != pos or m.group(1) not in letters:
            break
        powers += [letters.index(m.group(1))] * int(m.group(2) or 1)
        pos = m.end()
    if pos != len(text) or not powers:
        raise InputError(f"cannot read model term {name!r}; use factor letters "
                         f"{', '.join(letters)} as in 'A', 'AB', 'A^2'")
    return tuple(sorted(powers))


def model_terms(model: str, k: int) -> tuple[tuple[int, ...], ...]:
    """Terms (without the intercept) of a named model in Design-Expert order:
    A, B, ..., then AB, AC, ..., BC, ..., then A^2, B^2, ..."""
    if model not in MODELS:
        raise InputError(f"unknown model {model!r}; valid models: {', '.join(MODELS)}")
    terms = [(i,) for i in range(k)]
    if model in ("2fi", "quadratic"):
        terms += [(i, j) for i in range(k) for j in range(i + 1, k)]
    if model == "quadratic":
        terms += [(i, i) for i in range(k)]
    return tuple(terms)


def term_columns(coded: np.ndarray, terms) -> np.ndarray:
    """(n, len(terms)) model-matrix columns: products of coded factor columns."""
    coded = np.atleast_2d(coded)
    out = np.ones((coded.shape[0], len(terms)))
    for j, powers in enumerate(terms):
        for i in powers:
            out[:, j] *= coded[:, i]
    return out


# --------------------------------------------------------------------------------------------
# Result containers

@dataclass(frozen=True)
class AnovaRow:
    """One row of the ANOVA table.

    Attributes
    ----------
    source : str
        ``Block``, ``Model``, a term name, ``Residual``, ``Lack of Fit``, ``Pure Error`` or
        ``Cor Total``.
    ss : float
        Sum of squares [response units^2] (Type III for terms, sequential for Block).
    df : int
        Degrees of freedom.
    ms : float or None
        Mean square ss/df [response units^2]; None for Cor Total.
    f : float or None
        F value (term or Model against Residual, Lack of Fit against Pure Error).
    p : float or None
        Upper-tail probability of ``f``.
    significance : str or None
        ``highly significant`` (p < 0.01), ``significant`` (p < 0.05), ``not significant``.
    """

    source: str
    ss: float
    df: int
    ms: float | None = None
    f: float | None = None
    p: float | None = None
    significance: str | None = None

    def to_dict(self) -> dict:
        return {"source": self.source, "ss": self.ss, "df": self.df, "ms": self.ms,
                "f": self.f, "p": self.p, "significance": self.significance}


@dataclass(frozen=True)
class FitStatistics:
    """Design-Expert's fit statistics.

    Attributes
    ----------
    std_dev : float
        sqrt(residual mean square) [response units].
    mean : float
        Mean of the observed response [response units].
    cv_pct : float
        Coefficient of variation 100 std_dev / mean [%].
    r2, adj_r2, pred_r2 : float
        R-squared = SS_model / (SS_model + SS_residual), adjusted for degrees of freedom, and
        predicted = 1 - PRESS / (SS_model + SS_residual); the block sum of squares is removed
        from the denominator, as Design-Expert does.
    press : float
        Predicted residual sum of squares, sum (e_i / (1 - h_ii))^2 [response units^2];
        NaN when a run has leverage 1 (its deletion residual is undefined).
    adeq_precision : float
        (max yhat - min yhat) / sqrt(p MSE / n) over the design points, p the number of fitted
        parameters (intercept and block coefficients included), n the number of runs [-].
    r2_incl_blocks, adj_r2_incl_blocks : float
        Ordinary regression R-squared and adjusted R-squared with the block term counted as
        part of the model (R's ``lm``/``rsm`` convention); equal to r2/adj_r2 without blocks.
    n_runs, n_parameters, df_residual : int
        Runs, fitted parameters (intercept, blocks, terms), residual degrees of freedom.
    """

    std_dev: float
    mean: float
    cv_pct: float
    r2: float
    adj_r2: float
    pred_r2: float
    press: float
    adeq_precision: float
    r2_incl_blocks: float
    adj_r2_incl_blocks: float
    n_runs: int
    n_parameters: int
    df_residual: int

    def to_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass(frozen=True, eq=False)
class ResponseSurface:
    """A fitted polynomial response surface with its ANOVA (see module docstring).

    Attributes
    ----------
    model : str
        ``linear``, ``2fi``, ``quadratic`` or ``custom``.
    response : str
        Name of the response.
    factors : tuple of str
        Factor names, in the order of the letters A, B, C, ...
    letters : tuple of str
        Factor letters used in term names.
    terms : tuple of str
        Model terms in coefficient order (the intercept excluded).
    coefficients : dict
        Coded coefficients, ``Intercept`` first, then ``terms`` [response units].
    std_errors : dict
        Standard errors of the coded coefficients [response units].
    ci95 : dict
        95 % confidence interval (low, high) of each coded coefficient [response units].
    block_effects : dict or None
        Block label -> effect (sum-to-zero coding, so the intercept is the average over blocks)
        [response units]; None without blocks.
    anova : tuple of AnovaRow
    fit : FitStatistics
    low, high : numpy.ndarray
        Actual levels coded -1 and +1 [factor units]; -1 and +1 when the data were coded.
    coefficients_actual : dict
        The same polynomial expanded in actual units, keyed like ``coefficients``.
    equation_coded, equation_actual : str
        The fitted equations as text.
    coded : numpy.ndarray
        (n, k) coded design [-].
    observed, fitted, residuals, leverage : numpy.ndarray
        Per run: observed response, fitted value (blocks included), residual, hat diagonal.
    blocks : tuple or None
        Block label per run.
    term_powers : tuple of tuple of int
        Factor indices of each term, e.g. (0, 1) for AB and (0, 0) for A^2.
    """

    model: str
    response: str
    factors: tuple[str, ...]
    letters: tuple[str, ...]
    terms: tuple[str, ...]
    coefficients: dict
    std_errors: dict
    ci95: dict
    block_effects: dict | None
    anova: tuple[AnovaRow, ...]
    fit: FitStatistics
    low: np.ndarray
    high: np.ndarray
    coefficients_actual: dict
    equation_coded: str
    equation_actual: str
    coded: np.ndarray
    observed: np.ndarray
    fitted: np.ndarray
    residuals: np.ndarray
    leverage: np.ndarray
    blocks: tuple | None = None
    term_powers: tuple = field(default=(), repr=False)

    # ---- prediction ----
    def predict(self, coded) -> np.ndarray | float:
        """Predicted response at coded point(s), (k,) or (m, k); blocks averaged out."""
        x = np.asarray(coded, dtype=float)
        single = x.ndim == 1
        x = np.atleast_2d(x)
        if x.shape[1] != len(self.factors):
            raise InputError(f"predict expects {len(self.factors)} coded factor values per point, "
                             f"got {x.shape[1]}")
        b = np.array([self.coefficients[t] for t in self.terms])
        y = self.coefficients["Intercept"] + term_columns(x, self.term_powers) @ b
        return float(y[0]) if single else y

    def predict_actual(self, actual) -> np.ndarray | float:
        """Predicted response at actual factor level(s), (k,) or (m, k)."""
        return self.predict(to_coded(actual, self.low, self.high))

    def to_actual(self, coded) -> np.ndarray:
        """Actual levels of coded point(s) under this fit's coding [factor units]."""
        return to_actual(coded, self.low, self.high)

    def anova_row(self, source: str) -> AnovaRow:
        """The ANOVA row named ``source`` (KeyError if absent)."""
        for row in self.anova:
            if row.source == source:
                return row
        raise KeyError(source)

    @property
    def significant(self) -> list[str]:
        """Model terms with p < 0.05, in model order."""
        terms = set(self.terms)
        return [r.source for r in self.anova if r.source in terms and r.p is not None
                and np.isfinite(r.p) and r.p < SIGNIFICANT]

    # ---- second-order form ----
    def second_order(self):
        """Coded model as b0 + x'b + x'Bx.

        Returns
        -------
        b0 : float
        b : numpy.ndarray, (k,)
            First-order coefficients.
        B : numpy.ndarray, (k, k)
            Symmetric: pure quadratic coefficients on the diagonal, half of each two-factor
            interaction coefficient off the diagonal.

        Raises
        ------
        AnalysisError
            If the model has terms of order above two.
        """
        k = len(self.factors)
        b, B = np.zeros(k), np.zeros((k, k))
        for name, powers in zip(self.terms, self.term_powers):
            c = self.coefficients[name]
            if len(powers) == 1:
                b[powers[0]] += c
            elif len(powers) == 2 and powers[0] == powers[1]:
                B[powers[0], powers[0]] += c
            elif len(powers) == 2:
                B[powers[0], powers[1]] += c / 2.0
                B[powers[1], powers[0]] += c / 2.0
            else:
                raise AnalysisError(f"term {name} is above second order; the model is not a "
                                    f"second-order surface")
        return self.coefficients["Intercept"], b, B

    def stationary_point(self) -> dict | None:
        """Stationary point x_s = -B^-1 b / 2 of a second-order model (Myers et al. 2009, 6.3).

        Returns a dict with ``coded``, ``actual`` and ``predicted``, or None when the model has
        no second-order terms or B is singular (no unique stationary point).
        """
        b0, b, B = self.second_order()
        if not np.any(B):
            return None
        try:
            xs = -0.5 * np.linalg.solve(B, b)
        except np.linalg.LinAlgError:
            return None
        if np.linalg.cond(B) > 1e12:
            return None
        return {"coded": dict(zip(self.letters, xs.tolist())),
                "actual": dict(zip(self.factors, self.to_actual(xs).tolist())),
                "predicted": float(self.predict(xs))}

    def to_dict(self) -> dict:
        """JSON-ready summary: coefficients, anova, fit, equations, significant terms,
        stationary point."""
        try:
            stationary = self.stationary_point()
        except AnalysisError:
            stationary = None
        return {
            "model": self.model,
            "response": self.response,
            "factors": dict(zip(self.letters, self.factors)),
            "low": dict(zip(self.factors, self.low.tolist())),
            "high": dict(zip(self.factors, self.high.tolist())),
            "coefficients": dict(self.coefficients),
            "std_errors": dict(self.std_errors),
            "ci95": {k: list(v) for k, v in self.ci95.items()},
            "block_effects": None if self.block_effects is None else dict(self.block_effects),
            "anova": [row.to_dict() for row in self.anova],
            "fit": self.fit.to_dict(),
            "equation_coded": self.equation_coded,
            "equation_actual": self.equation_actual,
            "coefficients_actual": dict(self.coefficients_actual),
            "significant": self.significant,
            "stationary_point": stationary,
        }


# --------------------------------------------------------------------------------------------
# Fitting

def _lstsq(X, y):
    beta, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ beta
    return beta, r, float(r @ r)


def _f_test(ms, ms_err, df1, df2):
    """F = ms / ms_err and its upper-tail p; an exact fit (ms_err = 0) gives F = inf, p = 0."""
    if df1 <= 0 or df2 <= 0 or not np.isfinite(ms_err):
        return None, None
    if ms_err <= 0:
        return (float("inf"), 0.0) if ms > 0 else (None, None)
    f = ms / ms_err
    return float(f), float(stats.f.sf(f, df1, df2))


def _block_columns(blocks):
    """Sum-to-zero contrast columns for the block labels and the ordered list of labels."""
    labels = list(dict.fromkeys(blocks))  # order of first appearance
    n, m = len(blocks), len(labels)
    cols = np.zeros((n, m - 1))
    index = {lab: i for i, lab in enumerate(labels)}
    for r, lab in enumerate(blocks):
        i = index[lab]
        if i == m - 1:
            cols[r, :] = -1.0
        else:
            cols[r, i] = 1.0
    return cols, labels


def _pure_error(coded, y, blocks, decimals=9):
    """Pure-error SS and df from runs replicated at the same design point within a block."""
    keys = [tuple(np.round(row, decimals)) + ((b,) if blocks is not None else ())
            for row, b in zip(coded, blocks if blocks is not None else [None] * len(y))]
    groups: dict = {}
    for key, v in zip(keys, y):
        groups.setdefault(key, []).append(v)
    ss = sum(float(np.sum((np.array(v) - np.mean(v)) ** 2)) for v in groups.values())
    df = sum(len(v) - 1 for v in groups.values())
    return ss, df


def _aliased_terms(X, names):
    from scipy.linalg import qr
    _, R, piv = qr(X, mode="economic", pivoting=True)
    d = np.abs(np.diag(R))
    rank = int(np.sum(d > d[0] * 1e-10)) if d.size else 0
    return [names[i] for i in piv[rank:]]


def _fmt(c: float) -> str:
    return f"{c:+.6g}"


def _equation(response, coef_items, names_for) -> str:
    parts = []
    for key, c in coef_items:
        parts.append(_fmt(c) if key == "Intercept" else f"{_fmt(c)} * {names_for(key)}")
    return f"{response} = " + " ".join(parts)


def _expand_actual(coefficients, powers_list, names, low, high, letters):
    """Expand the coded polynomial into actual units exactly.

    x_i = (X_i - c_i) / h_i = X_i / h_i - c_i / h_i; each term is a product of such binomials.
    Returns {term name in letters: coefficient} with monomials in actual units.
    """
    c = (low + high) / 2.0
    h = (high - low) / 2.0
    poly: dict = {(): coefficients["Intercept"]}
    for name, powers in zip(names, powers_list):
        term = {(): coefficients[name]}
        for i in powers:
            new: dict = {}
            for mono, v in term.items():
                up = tuple(sorted(mono + (i,)))
                new[up] = new.get(up, 0.0) + v / h[i]
                new[mono] = new.get(mono, 0.0) - v * c[i] / h[i]
            term = new
        for mono, v in term.items():
            poly[mono] = poly.get(mono, 0.0) + v
    order = [()] + list(powers_list)
    extra = sorted((m for m in poly if m not in order), key=lambda m: (len(m), m))
    return {term_name(m, letters): float(poly[m]) for m in order + extra}


def fit_response_surface(coded, response, model: str = "quadratic", *, terms=None,
                         factors=None, response_name: str = "y", blocks=None,
                         low=None, high=None) -> ResponseSurface:
    """Fit a polynomial model by least squares in coded units and build Design-Expert's ANOVA.

    Parameters
    ----------
    coded : array_like
        (n, k) coded factor levels [-].
    response : array_like
        (n,) observed response [response units].
    model : str
        ``linear`` (first order), ``2fi`` (two-factor interaction) or ``quadratic`` (full second
        order); ignored when ``terms`` is given.
    terms : sequence of str, optional
        Explicit model terms by name (``"A"``, ``"AB"``, ``"A^2"``), e.g. a reduced model.
    factors : sequence of str, optional
        Factor names (default: the letters A, B, ...).
    response_name : str
        Name of the response, used in the equations.
    blocks : sequence, optional
        Block label per run. The block term enters first (its sequential SS is shown on its
        own row and kept out of Model), block effects use sum-to-zero coding, and pure error is
        taken within blocks.
    low, high : array_like, optional
        (k,) actual levels coded -1 and +1 [factor units], for the actual equation and
        :meth:`ResponseSurface.to_actual`; default -1 and +1 (actual = coded).

    Returns
    -------
    ResponseSurface

    Raises
    ------
    InputError
        Shapes or values that do not fit together.
    AnalysisError
        The design cannot estimate the model (too few runs or aliased terms).
    """
    x = np.asarray(coded, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    y = np.asarray(response, dtype=float).ravel()
    n, k = x.shape
    if y.shape[0] != n:
        raise InputError(f"response has {y.shape[0]} values but the design has {n} runs")
    if not np.all(np.isfinite(x)):
        raise InputError("coded design contains non-finite values")
    if not np.all(np.isfinite(y)):
        i = int(np.flatnonzero(~np.isfinite(y))[0])
        raise InputError(f"response is not finite at run {i + 1}: {float(y[i])!r}")
    letters = factor_letters(k)
    factors = tuple(factors) if factors is not None else letters
    if len(factors) != k:
        raise InputError(f"{len(factors)} factor names given for {k} design columns")
    low = -np.ones(k) if low is None else np.asarray(low, dtype=float).ravel()
    high = np.ones(k) if high is None else np.asarray(high, dtype=float).ravel()
    if low.shape != (k,) or high.shape != (k,):
        raise InputError(f"low and high need {k} values each, got {low.size} and {high.size}")
    if np.any(~(high > low)):
        i = int(np.flatnonzero(~(high > low))[0])
        raise InputError(f"factor {factors[i]}: high level {float(high[i])!r} must exceed "
                         f"low level {float(low[i])!r}")

    if terms is not None:
        powers_list = tuple(dict.fromkeys(parse_term(t, letters) for t in terms))
        model = "custom"
    else:
        powers_list = model_terms(model, k)
    names = tuple(term_name(p, letters) for p in powers_list)

    if blocks is not None:
        blocks = tuple(blocks)
        if len(blocks) != n:
            raise InputError(f"{len(blocks)} block labels given for {n} runs")
        B, block_labels = _block_columns(blocks)
        if len(block_labels) < 2:
            blocks, B, block_labels = None, np.zeros((n, 0)), []
    else:
        B, block_labels = np.zeros((n, 0)), []
    nb = B.shape[1]

    T = term_columns(x, powers_list)
    X = np.hstack([np.ones((n, 1)), B, T])
    p = X.shape[1]
    col_names = ["Intercept"] + [f"Block[{b}]" for b in block_labels[:-1]] + list(names)
    rank = np.linalg.matrix_rank(X)
    if rank < p:
        aliased = _aliased_terms(X, col_names)
        raise AnalysisError(f"the design cannot estimate the {model} model: {p} parameters but "
                            f"rank {rank} ({n} runs); aliased or inestimable terms: "
                            f"{', '.join(aliased)}")

    beta, resid, sse = _lstsq(X, y)
    df_res = n - p
    mse = sse / df_res if df_res > 0 else float("nan")
    fitted = X @ beta

    ybar = float(np.mean(y))
    ss_total = float(np.sum((y - ybar) ** 2))
    # Blocks enter first: their sequential SS, then the model SS on top of blocks.
    if nb:
        _, _, sse_blocks = _lstsq(X[:, :1 + nb], y)
        ss_block = ss_total - sse_blocks
    else:
        sse_blocks, ss_block = ss_total, 0.0
    ss_model = sse_blocks - sse
    df_model = len(names)

    rows = []
    if nb:
        rows.append(AnovaRow("Block", ss_block, nb, ss_block / nb))
    f, pval = _f_test(ss_model / df_model, mse, df_model, df_res)
    rows.append(AnovaRow("Model", ss_model, df_model, ss_model / df_model, f, pval,
                         significance(pval)))
    for j, name in enumerate(names):
        keep = np.ones(p, dtype=bool)
        keep[1 + nb + j] = False
        _, _, sse_j = _lstsq(X[:, keep], y)
        ss_j = max(sse_j - sse, 0.0)
        f, pval = _f_test(ss_j, mse, 1, df_res)
        rows.append(AnovaRow(name, ss_j, 1, ss_j, f, pval, significance(pval)))
    rows.append(AnovaRow("Residual", sse, df_res, mse if df_res > 0 else None))
    ss_pe, df_pe = _pure_error(x, y, blocks)
    df_lof = df_res - df_pe
    if df_pe > 0 and df_lof > 0:
        ss_lof = max(sse - ss_pe, 0.0)
        ms_pe = ss_pe / df_pe
        f, pval = _f_test(ss_lof / df_lof, ms_pe, df_lof, df_pe)
        rows.append(AnovaRow("Lack of Fit", ss_lof, df_lof, ss_lof / df_lof, f, pval,
                             significance(pval)))
        rows.append(AnovaRow("Pure Error", ss_pe, df_pe, ms_pe))
    rows.append(AnovaRow("Cor Total", ss_total, n - 1))

    # Leverages from an orthonormal basis of the model matrix.
    Q, _ = np.linalg.qr(X)
    h = np.sum(Q ** 2, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        press = float(np.sum((resid / (1.0 - h)) ** 2)) if np.all(h < 1 - 1e-10) else float("nan")
    ss_within = ss_model + sse  # SS_total - SS_block
    sd = float(np.sqrt(mse)) if df_res > 0 else float("nan")
    with np.errstate(divide="ignore", invalid="ignore"):
        r2 = 1.0 - sse / ss_within if ss_within > 0 else float("nan")
        adj_r2 = (1.0 - mse / (ss_within / (df_model + df_res))
                  if ss_within > 0 and df_res > 0 else float("nan"))
        pred_r2 = 1.0 - press / ss_within if ss_within > 0 else float("nan")
        r2_all = 1.0 - sse / ss_total if ss_total > 0 else float("nan")
        adj_all = (1.0 - mse / (ss_total / (n - 1))
                   if ss_total > 0 and df_res > 0 else float("nan"))
        adeq = float(np.ptp(fitted) / np.sqrt(p * mse / n)) if df_res > 0 else float("nan")
        cv = 100.0 * sd / ybar if ybar != 0 else float("nan")
    fit = FitStatistics(std_dev=sd, mean=ybar, cv_pct=float(cv), r2=float(r2),
                        adj_r2=float(adj_r2), pred_r2=float(pred_r2), press=press,
                        adeq_precision=adeq, r2_incl_blocks=float(r2_all),
                        adj_r2_incl_blocks=float(adj_all), n_runs=n, n_parameters=p,
                        df_residual=df_res)

    # Coefficients, standard errors and 95 % intervals.
    if df_res > 0:
        XtX_inv = np.linalg.inv(X.T @ X)
        se = np.sqrt(np.maximum(np.diag(XtX_inv) * mse, 0.0))
        tq = stats.t.ppf(0.975, df_res)
    else:
        se, tq = np.full(p, np.nan), float("nan")
    idx = [0] + list(range(1 + nb, p))
    keys = ["Intercept"] + list(names)
    coefficients = {kname: float(beta[i]) for kname, i in zip(keys, idx)}
    std_errors = {kname: float(se[i]) for kname, i in zip(keys, idx)}
    ci95 = {kname: (float(beta[i] - tq * se[i]), float(beta[i] + tq * se[i]))
            for kname, i in zip(keys, idx)}
    block_effects = None
    if nb:
        eff = list(beta[1:1 + nb])
        eff.append(-float(np.sum(eff)))
        block_effects = {str(lab): float(e) for lab, e in zip(block_labels, eff)}

    actual = _expand_actual(coefficients, powers_list, names, low, high, letters)

    def product(key, labels):
        counts = Counter(parse_term(key, letters))
        return " * ".join(labels[i] + (f"^{c}" if c > 1 else "") for i, c in sorted(counts.items()))

    eq_coded = _equation(response_name, coefficients.items(), lambda key: product(key, letters))
    eq_actual = _equation(response_name, actual.items(), lambda key: product(key, factors))

    return ResponseSurface(
        model=model, response=response_name, factors=factors, letters=letters, terms=names,
        coefficients=coefficients, std_errors=std_errors, ci95=ci95, block_effects=block_effects,
        anova=tuple(rows), fit=fit, low=low, high=high, coefficients_actual=actual,
        equation_coded=eq_coded, equation_actual=eq_actual, coded=x, observed=y,
        fitted=fitted, residuals=resid, leverage=h,
        blocks=blocks, term_powers=powers_list)
