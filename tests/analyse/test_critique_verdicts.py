"""Verdicts that mean what they say: ``ruled_out`` only where the data exclude a relevant
effect, ``inconclusive`` (with the rows that would decide it) where they neither find nor
exclude one.

Rates are asserted by exact Clopper-Pearson bounds over simulated series (table level: no
workbook, no DEM)."""

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy import stats

from demcal.analyse.critique import diagnosis
from demcal.analyse.critique.diagnosis import Series
from demcal.analyse.critique.mechanisms import judge


def _upper(k, n, level=0.95):
    return 1.0 if k == n else float(stats.beta.ppf(level, k + 1, n - k))


def _lower(k, n, level=0.95):
    return 0.0 if k == 0 else float(stats.beta.ppf(1.0 - level, k, n - k + 1))


def _drift(rng, n: int, per_trial: float, sd: float = 0.03, mean: float = 0.35, name="static_friction.steel",
           sheet="incline", family="static_friction") -> Series:
    order = np.arange(1, n + 1, dtype=float)
    y = mean + per_trial * (order - order.mean()) + rng.normal(0.0, sd, n)
    return Series(name, sheet, "measured", family, "1", tuple(range(1, n + 1)), tuple(y),
                  {"trial_order": tuple(order)})


def _noise(rng, n: int, k: int) -> list:
    """``k`` clean series of ``n`` rows (other quantities, their own covariates): the tests a
    relevant effect shares its correction with."""
    return [Series(f"rolling_friction.s{j}", "incline", "measured", "rolling_friction", "1",
                   tuple(range(1, n + 1)), tuple(0.15 + rng.normal(0.0, 0.02, n)),
                   {"moisture_pct": tuple(rng.uniform(40, 55, n))}) for j in range(k)]


def _verdict(series, alpha=0.01):
    tests, untestable = diagnosis.run_tests(series, alpha=alpha)
    return {f.mechanism: f for f in judge(tests, untestable)}, tests


def test_a_relevant_interval_that_misses_the_corrected_level_is_inconclusive_never_ruled_out():
    """A drift whose whole 95 % interval lies beyond the practical threshold but whose adjusted
    p-value misses the level (too many other tests share the correction) is inconclusive, with
    the rows that would decide it; over 200 such labs it is never ruled out."""
    rng = np.random.default_rng(11)
    n, seen, beyond = 200, {"found": 0, "inconclusive": 0, "ruled_out": 0}, 0
    for _ in range(n):
        f, tests = _verdict([_drift(rng, 20, 0.004, sd=0.02)] + _noise(rng, 20, 60), alpha=1e-4)
        v = f["trial_order_drift"]
        seen[v.verdict] += 1
        t = next(t for t in tests if t.covariate == "trial_order")
        if v.verdict == "inconclusive":
            assert v.rows_to_decide is not None and v.rows_to_decide > 0
            assert "not excluded" in v.reason
            beyond += min(abs(c) for c in t.ci95) * t.span > t.threshold
    assert seen["ruled_out"] == 0, seen
    assert seen["inconclusive"] > 20 and beyond > 0, (seen, beyond)


def test_a_mechanism_is_ruled_out_only_when_every_interval_lies_within_the_threshold():
    """No effect, many rows: the drift's interval lies within the threshold, ruled out, with the
    largest admitted size in the reason; few rows: the same truth is only inconclusive."""
    rng = np.random.default_rng(3)
    f, tests = _verdict([_drift(rng, 400, 0.0, sd=0.01)])
    v = f["trial_order_drift"]
    assert sorted(t.method for t in tests) == ["line", "trend"]
    assert all(t.largest_admitted() < t.threshold for t in tests)
    assert v.verdict == "ruled_out" and "within the practical threshold" in v.reason
    f, tests = _verdict([_drift(rng, 8, 0.0, sd=0.03)])
    assert all(t.largest_admitted() > t.threshold for t in tests)
    assert f["trial_order_drift"].verdict == "inconclusive"


def test_a_directed_mechanism_is_excluded_in_its_own_direction():
    """Restitution rising with drop height (against the falling signature) far beyond the
    threshold does not keep velocity_dependent_restitution open: in its direction the interval
    admits nothing."""
    rng = np.random.default_rng(5)
    h = np.repeat([200.0, 400.0, 600.0], 20)
    y = 0.35 + 2e-4 * (h - 400.0) + rng.normal(0, 0.01, h.size)
    s = Series("restitution.particle-steel", "drop", "measured", "restitution", "1", tuple(range(1, 61)),
               tuple(y), {"drop_height_mm": tuple(h)})
    f, tests = _verdict([s])
    assert len(tests) == 2
    assert all(t.largest_admitted(-1) == 0.0 and t.largest_admitted() > t.threshold for t in tests)
    assert f["velocity_dependent_restitution"].verdict == "ruled_out"


@pytest.mark.parametrize("n,noise", [(12, 0), (30, 40)])
def test_rows_to_decide_give_the_planned_power(n, noise):
    """Rows from ``rows_to_decide`` find an effect of the threshold's size at the test's level
    with 80 % power: over 400 simulated designs of that many rows, tested as the critique tests
    them (the straight line's t-test, the primary test of a trend covariate), the rate's
    two-sided 99 % Clopper-Pearson interval holds 0.8.
    The plan is checked at the true standard error (a plan from data carries the error of its
    estimate too)."""
    rng = np.random.default_rng(21 + n)
    tests, _ = diagnosis.run_tests([_drift(rng, n, 0.0, sd=0.03)] + _noise(rng, n, noise))
    (t,) = [t for t in tests if t.covariate == "trial_order" and t.method == "line"]
    assert t.tier == "primary"
    order = np.arange(1, n + 1, dtype=float)
    t = replace(t, se=0.03 / math.sqrt(float(((order - order.mean()) ** 2).sum())))
    rows = t.rows_to_decide()
    slope = t.threshold / t.span
    assert rows > n
    hits, reps = 0, 400
    for _ in range(reps):
        # more rows of this design (its trial orders repeated): se falls as 1/sqrt(rows)
        order = np.resize(np.arange(1.0, n + 1), rows)
        y = 0.35 + slope * (order - order.mean()) + rng.normal(0.0, 0.03, rows)
        hits += diagnosis.trend_test(order, y)["p_line"] < t.alpha_test
    assert _lower(hits, reps, 0.995) <= 0.8 <= _upper(hits, reps, 0.995), (rows, hits)
