"""The simulator's seed-to-seed noise, measured: its size, whether it is constant over the
design, whether runs sharing a seed are correlated, and how many replicates a design point needs.

A DEM heap is chaotic: a relative change of 1e-6 in one parameter redraws it, so every run is an
independent draw of a noisy response. The calibration (``analyse.campaign``) therefore

- runs two nearby points with the same seeds and measures the correlation of the paired
  responses (:func:`seed_correlation`): common random numbers help only if it is high;
- pools the replicate variance of every design point (:func:`pooled_noise`) and tests whether
  it is constant across points by Bartlett's test. Levene's and Brown-Forsythe's tests, robust
  to heavy tails, fail with the two to four runs a design point has: with two runs the
  deviations from the centre are equal by construction, with an odd count the median is one of
  the runs (a structural zero that takes the power), and the mean-centred version rejects far
  too often (about half of constant-noise designs with three runs per point). Bartlett's test
  is sensitive to heavy tails instead; a heap that jams now and then makes it reject, and the
  surrogate then uses each point's own variance (shrunk toward the pooled one), which is the
  safe side;
- runs each design point ``k`` times, ``k`` from the measured noise (:func:`replicates_for`).

References
----------
.. [Bartlett1937] M. S. Bartlett, "Properties of sufficiency and statistical tests", Proc. R.
   Soc. Lond. A 160(901), 268-282 (1937).
.. [Fisher1921] R. A. Fisher, "On the probable error of a coefficient of correlation deduced
   from a small sample", Metron 1, 3-32 (1921).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy import stats

from demcal.errors import InputError

#: Largest number of replicates per design point: beyond it, more design points inform a
#: surrogate more than more replicates do.
MAX_REPLICATES = 4


@dataclass(frozen=True)
class NoiseSummary:
    """Pooled seed-to-seed noise over design points with replicates.

    Attributes
    ----------
    sd : float
        Pooled within-point sd of one run [response units].
    df : int
        Its degrees of freedom (runs minus points).
    ci95 : (float, float)
        95 % interval of ``sd`` (chi-square).
    points : int
        Design points with at least two replicates.
    point_sd : list of float
        Each point's replicate sd.
    constant_p : float
        p-value of the test that the variance is the same at every point (NaN with fewer than
        two points).
    constant_test : str
        The test used (``bartlett``).
    constant : bool
        Whether constancy is kept at the 5 % level.
    """

    sd: float
    df: int
    ci95: tuple
    points: int
    point_sd: list
    constant_p: float
    constant: bool
    constant_test: str = ""

    def to_dict(self) -> dict:
        return asdict(self)


def pooled_noise(groups) -> NoiseSummary:
    """Pool the replicate variance of design points.

    Parameters
    ----------
    groups : sequence of sequences of float
        The runs of each design point (points with one run carry no noise information and are
        skipped).

    Returns
    -------
    NoiseSummary
    """
    groups = [np.asarray(g, dtype=float) for g in groups]
    groups = [g for g in groups if g.size >= 2]
    if not groups:
        raise InputError("the noise needs at least one design point with two or more runs")
    df = sum(g.size - 1 for g in groups)
    ss = sum(float(np.sum((g - g.mean()) ** 2)) for g in groups)
    sd = math.sqrt(ss / df)
    lo = sd * math.sqrt(df / stats.chi2.ppf(0.975, df))
    hi = sd * math.sqrt(df / stats.chi2.ppf(0.025, df))
    p, test = math.nan, ""
    if len(groups) >= 2 and all(np.ptp(g) > 0 for g in groups):
        p, test = float(stats.bartlett(*groups).pvalue), "bartlett"
    return NoiseSummary(sd=sd, df=int(df), ci95=(lo, hi), points=len(groups),
                        point_sd=[float(np.std(g, ddof=1)) for g in groups], constant_p=p,
                        constant=bool(not (p < 0.05)), constant_test=test)


@dataclass(frozen=True)
class SeedCorrelation:
    """Correlation of paired runs at two nearby points that share their seeds.

    Attributes
    ----------
    r : float
        Pearson correlation of the pairs.
    ci95 : (float, float)
        95 % interval (Fisher's z).
    n : int
        Pairs.
    variance_ratio : float
        Variance of a same-seed difference over that of independent runs (1 - r): below about
        0.5 common random numbers would pay off.
    """

    r: float
    ci95: tuple
    n: int
    variance_ratio: float

    def to_dict(self) -> dict:
        return asdict(self)


def seed_correlation(a, b) -> SeedCorrelation:
    """Correlation of runs ``a[i]`` and ``b[i]`` made with the same seed at two points."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if a.shape != b.shape or a.size < 4:
        raise InputError("the seed correlation needs at least four pairs of runs of equal count")
    if np.ptp(a) == 0 or np.ptp(b) == 0:
        return SeedCorrelation(math.nan, (math.nan, math.nan), int(a.size), math.nan)
    r = float(np.corrcoef(a, b)[0, 1])
    z, se = math.atanh(max(min(r, 0.999999), -0.999999)), 1.0 / math.sqrt(a.size - 3)
    lo, hi = math.tanh(z - 1.96 * se), math.tanh(z + 1.96 * se)
    return SeedCorrelation(r, (lo, hi), int(a.size), 1.0 - r)


def replicates_for(run_sd: float, tolerance: float, max_replicates: int = MAX_REPLICATES) -> int:
    """Runs per design point: the fewest ``k >= 2`` whose mean has an sd no larger than three
    tolerances (the surrogate pools neighbouring points for the rest, and more points inform it
    more than more replicates do), at most ``max_replicates``. Two at the least, so every point
    also measures the noise."""
    if not (run_sd >= 0 and tolerance > 0):
        raise InputError(f"replicates_for needs run_sd >= 0 and tolerance > 0, got {run_sd}, {tolerance}")
    k = math.ceil((run_sd / (3.0 * tolerance)) ** 2)
    return int(min(max(k, 2), max_replicates))
