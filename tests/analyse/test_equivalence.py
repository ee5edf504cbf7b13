"""TOST equivalence of simulated and lab angles: hand calculations, error rates and power.

Rates are checked by exact (Clopper-Pearson) binomial bounds over many simulated experiments,
never by a point estimate.
"""

import json
import math

import numpy as np
import pytest
from scipy import stats
from statsmodels.stats.weightstats import ttost_ind, ttost_paired

from demcal.analyse.equivalence import (INTERIM_ALPHA, EquivalenceResult, SequentialResult, default_tolerance,
                                 equivalence_test, runs_for_power, sequential_equivalence,
                                 tost_power)
from demcal.errors import InputError

ALPHA = 0.05
LAB_MEAN = 32.0  # true lab angle [deg]
LAB_SD, LAB_N = 0.5, 3


def upper95(k: int, n: int) -> float:
    """One-sided 95 % Clopper-Pearson upper bound of a binomial rate."""
    return 1.0 if k == n else float(stats.beta.ppf(0.95, k + 1, n - k))


def lower95(k: int, n: int) -> float:
    """One-sided 95 % Clopper-Pearson lower bound of a binomial rate."""
    return 0.0 if k == 0 else float(stats.beta.ppf(0.05, k, n - k + 1))


def interval99(k: int, n: int) -> tuple[float, float]:
    """Two-sided 99 % Clopper-Pearson interval of a binomial rate."""
    lo = 0.0 if k == 0 else float(stats.beta.ppf(0.005, k, n - k + 1))
    hi = 1.0 if k == n else float(stats.beta.ppf(0.995, k + 1, n - k))
    return lo, hi


def lab_sample(rng):
    """Mean and sample sd of LAB_N photographed heaps."""
    heaps = rng.normal(LAB_MEAN, LAB_SD, LAB_N)
    return float(heaps.mean()), float(heaps.std(ddof=1))


RUNS = np.array([31.2, 33.5, 29.8, 32.1, 34.0, 30.6])
LAB = np.array([31.0, 31.8, 30.9])


def test_hand_calculation_with_lab_term():
    tol = 1.5
    res = equivalence_test(RUNS, LAB.mean(), LAB.std(ddof=1), LAB.size, tolerance=tol,
                           df_rule="welch")

    n, m = RUNS.size, LAB.size
    mean = sum(RUNS) / n
    s2 = sum((x - mean) ** 2 for x in RUNS) / (n - 1)
    lab_mean = sum(LAB) / m
    l2 = sum((x - lab_mean) ** 2 for x in LAB) / (m - 1)
    d = mean - lab_mean
    se = math.sqrt(s2 / n + l2 / m)
    df = (s2 / n + l2 / m) ** 2 / ((s2 / n) ** 2 / (n - 1) + (l2 / m) ** 2 / (m - 1))
    p_lower = stats.t.sf((d + tol) / se, df)
    p_upper = stats.t.cdf((d - tol) / se, df)
    t95 = stats.t.ppf(0.95, df)

    assert d == pytest.approx(0.63333333333, abs=1e-9)
    assert res.difference_deg == pytest.approx(d, abs=1e-12)
    assert res.se_deg == pytest.approx(se, rel=1e-12)
    assert res.df == pytest.approx(df, rel=1e-12)
    assert res.p_lower == pytest.approx(p_lower, rel=1e-9)
    assert res.p_upper == pytest.approx(p_upper, rel=1e-9)
    assert res.p_tost == pytest.approx(max(p_lower, p_upper), rel=1e-9)
    assert res.difference_ci90 == pytest.approx((d - t95 * se, d + t95 * se), rel=1e-9)
    half = stats.t.ppf(0.975, n - 1) * math.sqrt(s2 / n)
    assert res.ci95 == pytest.approx((mean - half, mean + half), rel=1e-12)
    detect = (stats.t.ppf(0.975, df) + stats.t.ppf(0.80, df)) * se
    assert res.detectable_bias_deg == pytest.approx(detect, rel=1e-9)
    # the interval reaches past +tol but not below -tol
    assert res.verdict == "undecided"
    assert res.lab_term and res.target_n == 3 and res.n_runs == 6

    # second implementation: Welch TOST on the raw lab heaps
    p_sm, lower_sm, upper_sm = ttost_ind(RUNS, LAB, -tol, tol, usevar="unequal")
    assert res.p_tost == pytest.approx(float(p_sm), rel=1e-9)
    assert res.df == pytest.approx(float(lower_sm[2]), rel=1e-9)

    # the default, conservative df: min(n - 1, n_lab - 1) (Hsu), same SE
    cons = equivalence_test(RUNS, LAB.mean(), LAB.std(ddof=1), LAB.size, tolerance=tol)
    assert cons.df == min(n - 1, m - 1) == 2
    assert cons.se_deg == pytest.approx(se, rel=1e-12)
    t95c = stats.t.ppf(0.95, 2)
    assert cons.difference_ci90 == pytest.approx((d - t95c * se, d + t95c * se), rel=1e-9)
    assert cons.p_tost == pytest.approx(max(stats.t.sf((d + tol) / se, 2),
                                            stats.t.cdf((d - tol) / se, 2)), rel=1e-9)


def test_hand_calculation_exact_target():
    target, tol = 31.5, 1.0
    for sd, n_lab in [(None, None), (0.5, None), (0.5, 1)]:
        res = equivalence_test(RUNS, target, sd, n_lab, tolerance=tol)
        n = RUNS.size
        se = RUNS.std(ddof=1) / math.sqrt(n)
        d = RUNS.mean() - target
        p = max(stats.t.sf((d + tol) / se, n - 1), stats.t.cdf((d - tol) / se, n - 1))
        assert not res.lab_term
        assert "exact" in res.note
        assert res.df == n - 1
        assert res.se_deg == pytest.approx(se, rel=1e-12)
        assert res.p_tost == pytest.approx(p, rel=1e-9)
        # one-sample TOST is the paired TOST against a constant
        p_sm = ttost_paired(RUNS, np.full(n, target), -tol, tol)[0]
        assert res.p_tost == pytest.approx(float(p_sm), rel=1e-9)


def test_verdicts_follow_the_interval():
    x = np.array([-1.0, 1.0] * 50) + 32.0  # s = 1.005, n = 100: half-width ~0.17
    assert equivalence_test(x, 32.0, tolerance=1.0).verdict == "equivalent"
    assert equivalence_test(x + 2.0, 32.0, tolerance=1.0).verdict == "different"
    assert equivalence_test(x - 2.0, 32.0, tolerance=1.0).verdict == "different"
    assert equivalence_test(x + 1.0, 32.0, tolerance=1.0).verdict == "undecided"
    res = equivalence_test(x, 32.0, tolerance=1.0)
    assert res.p_tost < ALPHA
    json.dumps(res.to_dict())


def test_default_tolerance():
    assert default_tolerance(0.4) == 1.0
    assert default_tolerance(1.7) == 1.7
    assert default_tolerance(None) == 1.0
    assert default_tolerance(float("nan"), floor_deg=2.0) == 2.0
    with pytest.raises(InputError):
        default_tolerance(-0.1)


def test_false_equivalence_rate_at_the_margin():
    # the true simulated mean sits exactly at +tol above the true lab mean
    rng = np.random.default_rng(20240611)
    # a tolerance at which the 2-df lab term still lets "equivalent" happen often at bias 0
    tol, run_sd, n, reps = 2.0, 2.0, 20, 4000
    assert tost_power(0.0, run_sd, n, tol, LAB_SD, LAB_N, ALPHA) > 0.5
    hits = 0
    for _ in range(reps):
        target, target_sd = lab_sample(rng)
        runs = rng.normal(LAB_MEAN + tol, run_sd, n)
        hits += equivalence_test(runs, target, target_sd, LAB_N, tol, ALPHA).verdict == "equivalent"
    assert upper95(hits, reps) <= ALPHA


def test_sequential_false_equivalence_rate_at_the_margin():
    rng = np.random.default_rng(77)
    tol, run_sd, reps = 2.0, 2.0, 2000
    assert tost_power(0.0, run_sd, 40, tol, LAB_SD, LAB_N, ALPHA) > 0.5
    hits = 0
    for _ in range(reps):
        target, target_sd = lab_sample(rng)
        res = sequential_equivalence(lambda k: rng.normal(LAB_MEAN + tol, run_sd, k),
                                     target, target_sd, LAB_N, tol, first=10, step=10, cap=40,
                                     alpha=ALPHA)
        hits += res.verdict == "equivalent"
    assert upper95(hits, reps) <= ALPHA


def simulated_equivalence_rate(rng, bias, run_sd, n, tol, lab, reps):
    hits = 0
    for _ in range(reps):
        target, target_sd = lab_sample(rng) if lab else (LAB_MEAN, None)
        runs = rng.normal(LAB_MEAN + bias, run_sd, n)
        res = equivalence_test(runs, target, target_sd, LAB_N if lab else None, tol, ALPHA)
        hits += res.verdict == "equivalent"
    return hits


@pytest.mark.parametrize("bias, run_sd, n, tol, lab", [
    (0.0, 1.0, 40, 1.0, False),
    (0.5, 1.5, 12, 1.0, False),  # power near 0.24: a point where the calculation matters
    (0.3, 2.0, 20, 2.0, True),   # the lab term with its 2 df
])
def test_power_agrees_with_simulation(bias, run_sd, n, tol, lab):
    rng = np.random.default_rng(5)
    reps = 2000
    hits = simulated_equivalence_rate(rng, bias, run_sd, n, tol, lab, reps)
    power = tost_power(bias, run_sd, n, tol, LAB_SD if lab else None, LAB_N if lab else None,
                       ALPHA)
    lo, hi = interval99(hits, reps)
    assert lo <= power <= hi


def test_runs_for_power():
    # the lab mean of 3 heaps (sd 0.5) with 2 df alone keeps the power below 0.8 at tol 1
    assert runs_for_power(0.0, 2.0, 1.0, 0.8, target_sd=LAB_SD, target_n=LAB_N) is None
    assert tost_power(0.0, 2.0, 400, 1.0, LAB_SD, LAB_N) < 0.8
    # beyond the margin no number of runs helps
    assert runs_for_power(1.2, 2.0, 1.0, 0.8) is None

    for sd, n_lab, tol in [(None, None, 1.0), (LAB_SD, LAB_N, 1.5)]:
        n = runs_for_power(0.0, 2.0, tol, 0.8, target_sd=sd, target_n=n_lab)
        assert n is not None and 2 < n <= 400
        assert tost_power(0.0, 2.0, n, tol, sd, n_lab) >= 0.8
        assert tost_power(0.0, 2.0, n - 1, tol, sd, n_lab) < 0.8


def test_clear_difference():
    rng = np.random.default_rng(3)
    reps, hits = 500, 0
    for i in range(reps):
        target, target_sd = lab_sample(rng)
        bias = 3.0 if i % 2 else -3.0
        runs = rng.normal(LAB_MEAN + bias, 2.0, 40)
        hits += equivalence_test(runs, target, target_sd, LAB_N, 1.0, ALPHA).verdict == "different"
    assert lower95(hits, reps) >= 0.9


def test_too_few_runs():
    for runs in ([], [31.0]):
        with pytest.raises(InputError, match="at least 2 runs"):
            equivalence_test(runs, 31.0, 0.5, 3, 1.0)
    with pytest.raises(InputError):
        equivalence_test([31.0, float("nan")], 31.0)
    with pytest.raises(InputError):
        sequential_equivalence(lambda k: [31.0] * k, 31.0, 0.5, 3, 1.0, first=1)


def test_sequential_looks_stop_and_replay():
    def run(seed, bias, lab=True):
        rng = np.random.default_rng(seed)
        return sequential_equivalence(lambda k: rng.normal(LAB_MEAN + bias, 2.0, k),
                                      LAB_MEAN, LAB_SD if lab else None, LAB_N if lab else None,
                                      1.0, first=10, step=10, cap=40)

    # an exact target: a bias of 4 deg is clear at the first look even at its strict level (with
    # the 3-heap lab term, whose t quantile has 2 df, no interim look can decide)
    clear = run(1, 4.0, lab=False)
    assert isinstance(clear, SequentialResult) and isinstance(clear, EquivalenceResult)
    assert clear.verdict == "different" and clear.stopped_because == "decided"
    assert [look.n_runs for look in clear.looks] == [10] and clear.n_runs == 10
    assert clear.planned_looks == (10, 20, 30, 40)
    # Haybittle-Peto: a strict level at the interim looks, the rest at the last; they sum to alpha
    assert clear.alpha_per_look == pytest.approx((INTERIM_ALPHA,)) and clear.alpha == ALPHA
    assert "Haybittle-Peto" in clear.note

    capped = run(2, 1.0)  # at the margin with this seed no look decides
    assert capped.stopped_because == "cap"
    assert [look.n_runs for look in capped.looks] == [10, 20, 30, 40]
    assert capped.n_runs == 40 and capped.verdict == "undecided"
    assert sum(capped.alpha_per_look) == pytest.approx(ALPHA)
    assert capped.alpha_per_look[-1] == pytest.approx(ALPHA - 3 * INTERIM_ALPHA)

    # draw holds all the randomness: the same seed replays the same validation
    assert run(2, 1.0).to_dict() == capped.to_dict()
    out = json.loads(json.dumps(capped.to_dict()))
    assert out["looks"][0]["n_runs"] == 10 and len(out["looks"][0]["difference_ci90"]) == 2

    # a cap off the step grid is still a look
    res = sequential_equivalence(lambda k: [32.0, 33.0] * (k // 2) + [32.0] * (k % 2),
                                 32.5, None, None, 1.0, first=4, step=4, cap=10)
    assert res.planned_looks[-1] == 10

    with pytest.raises(InputError, match="returned"):
        sequential_equivalence(lambda k: [32.0], 32.0, LAB_SD, LAB_N, 1.0)


def test_lab_heaps_for_power():
    from demcal.analyse.equivalence import lab_heaps_for_power

    m = lab_heaps_for_power(1.0, 40, 1.0, 0.5)
    assert m is not None and m > 3
    assert tost_power(0.0, 1.0, 40, 1.0, 0.5, m) >= 0.8 > tost_power(0.0, 1.0, 40, 1.0, 0.5, m - 1)
    # the runs alone put it out of reach: 40 runs of sd 4 have a half-width above 1 deg
    assert lab_heaps_for_power(4.0, 40, 1.0, 0.5) is None
