"""Estimates of measured quantities: value, spread, confidence interval, and the rows behind them.

Every estimator of the measure stage returns an :class:`Estimate`. Its uncertainty is the
classical one for repeated measurements: the sample mean, the sample standard deviation
(n - 1 in the denominator) and the Student-t 95 % confidence interval of the mean [1]_.
Rows are screened for outliers by a rule chosen by the caller (:func:`screen_outliers`);
every screened row is listed in ``rows_rejected`` with its reason, never dropped silently.

References
----------
.. [1] Student (1908). The probable error of a mean. Biometrika 6(1), 1-25.
.. [2] Iglewicz, B. & Hoaglin, D. C. (1993). How to Detect and Handle Outliers. ASQC Basic
   References in Quality Control, vol. 16 (modified z-score, cut-off 3.5).
.. [3] Grubbs, F. E. (1969). Procedures for detecting outlying observations in samples.
   Technometrics 11(1), 1-21; NIST/SEMATECH e-Handbook of Statistical Methods, 1.3.5.17.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from demcal.errors import InputError

#: Outlier rules known to :func:`screen_outliers`, with their default limit.
OUTLIER_RULES = {"none": None, "mad": 3.5, "grubbs": 0.05}

#: Smallest sample each rule screens.
MIN_SCREENED = {"mad": 5, "grubbs": 3}

#: Scale factor that makes the median absolute deviation a consistent estimator of the
#: standard deviation of normal data (1 / Phi^-1(3/4)).
MAD_TO_SD = 1.4826


@dataclass(frozen=True)
class Estimate:
    """One measured quantity.

    Attributes
    ----------
    name : str
        Quantity name of docs/workbook.md, e.g. ``"restitution.particle-steel"``.
    value : float
        The estimate (mean of the rows used) [unit].
    sd : float
        Sample standard deviation of the rows used (n - 1) [unit]; NaN when n < 2.
    n : int
        Number of rows used.
    ci95 : tuple of float
        Student-t 95 % confidence interval of the mean (lo, hi) [unit]; NaN when n < 2.
    unit : str
        Unit of ``value``, ``sd`` and ``ci95`` (``"1"`` for dimensionless numbers).
    rows_used : list of int
        Data rows (1 = first row under the header) that entered the estimate.
    rows_rejected : list of dict
        ``{"row": int, "reason": str}`` for every row of the quantity that was left out.
    source : dict
        ``{"file", "sheet", "sha256"}`` of the sheet the rows come from.
    method : str
        Short citation of the method.
    extra : dict
        Method-specific additions (alternative formulas, sub-estimates, settings).
    per_row : list of dict
        Per-row values: ``{"row", "value", "used", ...inputs..., "covariates": {...}}``.
    """

    name: str
    value: float
    sd: float
    n: int
    ci95: tuple
    unit: str
    rows_used: list
    rows_rejected: list
    source: dict
    method: str
    extra: dict = field(default_factory=dict)
    per_row: list = field(default_factory=list)

    def to_dict(self, *, per_row: bool = False) -> dict:
        """JSON-ready dict of the quantity (``per_row`` records only when asked)."""
        out = {"name": self.name, "value": self.value, "sd": self.sd, "n": self.n,
               "ci95": [self.ci95[0], self.ci95[1]], "unit": self.unit,
               "rows_used": list(self.rows_used),
               "rows_rejected": [dict(r) for r in self.rows_rejected],
               "source": dict(self.source), "method": self.method, "extra": dict(self.extra)}
        if per_row:
            out["per_row"] = [dict(r) for r in self.per_row]
        return out

    @classmethod
    def from_dict(cls, d: dict, per_row=None) -> "Estimate":
        """Rebuild an estimate from :meth:`to_dict` output (JSON nulls become NaN)."""
        def num(x):
            return math.nan if x is None else float(x)
        lo, hi = d["ci95"]
        return cls(name=d["name"], value=num(d["value"]), sd=num(d["sd"]), n=int(d["n"]),
                   ci95=(num(lo), num(hi)), unit=d["unit"], rows_used=list(d["rows_used"]),
                   rows_rejected=list(d["rows_rejected"]), source=dict(d["source"]),
                   method=d.get("method", ""), extra=dict(d.get("extra", {})),
                   per_row=list(per_row if per_row is not None else d.get("per_row", [])))


def parse_outlier_rule(rule) -> tuple[str, float | None]:
    """Parse an outlier rule ``"none"``, ``"mad"``, ``"mad:3.0"``, ``"grubbs"`` or ``"grubbs:0.01"``.

    For ``mad`` the limit is the largest modified z-score kept [2]_; for ``grubbs`` it is the
    significance level of the two-sided test [3]_. A tuple ``(name, limit)`` is accepted too.
    """
    if isinstance(rule, tuple):
        name, limit = rule
    else:
        text = str(rule).strip().lower()
        name, _, limit_text = text.partition(":")
        limit = None
        if limit_text:
            try:
                limit = float(limit_text)
            except ValueError:
                raise InputError(f"outlier rule {rule!r}: limit {limit_text!r} is not a number") from None
    if name not in OUTLIER_RULES:
        raise InputError(f"unknown outlier rule {rule!r}; valid: {', '.join(OUTLIER_RULES)} "
                         "(optionally with a limit, e.g. 'mad:3.5', 'grubbs:0.05')")
    if limit is None:
        limit = OUTLIER_RULES[name]
    if name == "mad" and not limit > 0:
        raise InputError(f"outlier rule {rule!r}: the MAD limit must be positive")
    if name == "grubbs" and not 0 < limit < 1:
        raise InputError(f"outlier rule {rule!r}: the Grubbs significance level must be in (0, 1)")
    return name, limit


def screen_outliers(values, rule="mad") -> list[str | None]:
    """Screen a sample for outliers.

    Parameters
    ----------
    values : array_like of float
        The sample.
    rule : str or tuple
        ``"none"``; ``"mad"`` (modified z-score |x - median| / (1.4826 MAD) above the limit,
        default 3.5, Iglewicz & Hoaglin [2]_; when MAD is 0 the mean absolute deviation
        times 1.2533 is used instead, and nothing is rejected if that is 0 too); or
        ``"grubbs"`` (two-sided Grubbs test repeated while it rejects, default alpha 0.05 [3]_).
        Samples smaller than 5 values (``mad``: the median absolute deviation of fewer
        values flags any asymmetric sample) or 3 values (``grubbs``) are never screened.

    Returns
    -------
    list of (str or None)
        For each value, None if kept, else the reason it was rejected.
    """
    name, limit = parse_outlier_rule(rule)
    x = np.asarray(values, dtype=float)
    reasons: list[str | None] = [None] * x.size
    if name == "none" or x.size < MIN_SCREENED[name]:
        return reasons
    if name == "mad":
        med = float(np.median(x))
        dev = np.abs(x - med)
        scale = MAD_TO_SD * float(np.median(dev))
        label = "1.4826 MAD"
        if scale == 0.0:
            scale = 1.2533 * float(np.mean(dev))  # MAD is 0 when over half the values tie
            label = "1.2533 mean absolute deviation"
        if scale == 0.0:
            return reasons
        for i in np.flatnonzero(dev / scale > limit):
            reasons[i] = (f"outlier: |x - median| = {dev[i]:.4g} > {limit:g} x {label} "
                          f"({scale:.4g}); median {med:.4g}")
        return reasons
    keep = np.ones(x.size, dtype=bool)
    while keep.sum() >= 3:
        idx = np.flatnonzero(keep)
        sample = x[idx]
        sd = sample.std(ddof=1)
        if sd == 0.0:
            break
        g = np.abs(sample - sample.mean()) / sd
        j = int(np.argmax(g))
        n = sample.size
        g_crit = grubbs_critical(n, limit)
        if g[j] <= g_crit:
            break
        keep[idx[j]] = False
        reasons[idx[j]] = f"outlier: Grubbs G = {g[j]:.3f} > {g_crit:.3f} (alpha {limit:g}, n {n})"
    return reasons


def grubbs_critical(n: int, alpha: float = 0.05) -> float:
    """Critical value of the two-sided Grubbs test for n values at significance alpha [3]_.

    G_crit = (n - 1) / sqrt(n) * sqrt(t^2 / (n - 2 + t^2)), t the upper alpha / (2 n)
    quantile of Student's t with n - 2 degrees of freedom.
    """
    if n < 3:
        raise InputError(f"the Grubbs test needs at least 3 values, got {n}")
    t = stats.t.ppf(1.0 - alpha / (2.0 * n), n - 2)
    return (n - 1) / math.sqrt(n) * math.sqrt(t * t / (n - 2 + t * t))


def mean_sd_ci95(values) -> tuple[float, float, tuple[float, float]]:
    """Sample mean, standard deviation (n - 1) and Student-t 95 % interval of the mean [1]_.

    The sd and interval are NaN for fewer than 2 values; the mean is NaN for none.
    """
    x = np.asarray(values, dtype=float)
    n = x.size
    if n == 0:
        return math.nan, math.nan, (math.nan, math.nan)
    mean = float(x.mean())
    if n < 2:
        return mean, math.nan, (math.nan, math.nan)
    sd = float(x.std(ddof=1))
    half = float(stats.t.ppf(0.975, n - 1)) * sd / math.sqrt(n)
    return mean, sd, (mean - half, mean + half)


def summarise(name: str, values, rows, *, unit: str, source: dict, method: str,
              outliers="none", rejected=None, extra=None, per_row=None) -> Estimate:
    """Screen per-row values for outliers and summarise them as an :class:`Estimate`.

    Parameters
    ----------
    name : str
        Quantity name.
    values : array_like of float
        One value per row [unit].
    rows : sequence of int
        The data-row number of each value.
    unit, source, method : str, dict, str
        Copied into the estimate.
    outliers : str or tuple
        Outlier rule, see :func:`screen_outliers`.
    rejected : list of dict, optional
        Rows already left out by the caller (``{"row", "reason"}``); reported with the rest.
    extra : dict, optional
        Copied into ``Estimate.extra`` (the outlier rule is added).
    per_row : list of dict, optional
        One record per value (same order), completed with ``row``, ``value``, ``used`` and,
        for rejected rows, ``reason``.
    """
    x = np.asarray(values, dtype=float)
    rows = [int(r) for r in rows]
    if x.ndim != 1 or x.size != len(rows):
        raise InputError(f"{name}: values and rows must be one-dimensional and of equal length")
    reasons = screen_outliers(x, outliers) if x.size else []
    keep = np.array([r is None for r in reasons], dtype=bool)
    mean, sd, ci = mean_sd_ci95(x[keep])
    rows_rejected = [dict(r) for r in (rejected or [])]
    rows_rejected += [{"row": row, "reason": why} for row, why in zip(rows, reasons) if why is not None]
    rows_rejected.sort(key=lambda r: r["row"])
    records = []
    for i, row in enumerate(rows):
        rec = dict(per_row[i]) if per_row is not None else {}
        rec.update(row=row, value=float(x[i]), used=bool(keep[i]))
        if reasons[i] is not None:
            rec["reason"] = reasons[i]
        records.append(rec)
    info = dict(extra or {})
    rule_name, limit = parse_outlier_rule(outliers)
    info.setdefault("outlier_rule", rule_name if limit is None else f"{rule_name}:{limit:g}")
    return Estimate(name=name, value=mean, sd=sd, n=int(keep.sum()), ci95=ci, unit=unit,
                    rows_used=[r for r, k in zip(rows, keep) if k], rows_rejected=rows_rejected,
                    source=dict(source), method=method, extra=info, per_row=records)
