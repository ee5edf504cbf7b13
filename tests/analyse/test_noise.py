"""The noise measurement: pooled sd against a hand calculation, the constancy tests' false-alarm
rates and the seed correlation's interval checked by simulation (confidence bounds over many
repetitions), and the replicate rule."""

import math

import numpy as np
import pytest
from scipy import stats

from demcal.analyse.noise import pooled_noise, replicates_for, seed_correlation
from demcal.errors import InputError


def interval99(hits: int, reps: int) -> tuple[float, float]:
    """Clopper-Pearson 99 % interval of a rate."""
    lo = stats.beta.ppf(0.005, hits, reps - hits + 1) if hits else 0.0
    hi = stats.beta.ppf(0.995, hits + 1, reps - hits) if hits < reps else 1.0
    return lo, hi


def test_pooled_sd_by_hand():
    groups = [[30.0, 34.0], [36.0, 37.0, 41.0], [28.0]]
    res = pooled_noise(groups)
    ss = (2.0 ** 2 + 2.0 ** 2) + ((36 - 38) ** 2 + (37 - 38) ** 2 + (41 - 38) ** 2)
    assert res.df == 1 + 2 and res.points == 2            # the single run carries no noise
    assert res.sd == pytest.approx(math.sqrt(ss / 3))
    lo, hi = res.ci95
    assert lo == pytest.approx(res.sd * math.sqrt(3 / stats.chi2.ppf(0.975, 3)))
    assert lo < res.sd < hi
    with pytest.raises(InputError):
        pooled_noise([[1.0], [2.0]])


@pytest.mark.parametrize("k", [2, 3, 5])
def test_constancy_false_alarm_rate_at_the_nominal_level(k):
    # constant noise at 20 points: the test must reject at about its 5 % level, no more
    rng = np.random.default_rng(11)
    reps, hits = 1000, 0
    for _ in range(reps):
        res = pooled_noise(rng.normal(35.0, 3.0, (20, k)))
        assert res.constant_test == "bartlett"
        hits += not res.constant
    lo, _ = interval99(hits, reps)
    assert lo <= 0.05


@pytest.mark.parametrize("k, power", [(2, 0.5), (3, 0.8), (5, 0.8)])
def test_constancy_test_sees_a_noise_that_grows(k, power):
    # half of 40 points scatter 4x more: with three runs a point the test sees it in most
    # designs; with two (one df a point) in about two of three, which is what two runs can tell
    rng = np.random.default_rng(12)
    reps, hits = 300, 0
    sd = np.repeat([1.0, 4.0], 20)[:, None]
    for _ in range(reps):
        hits += not pooled_noise(35.0 + rng.normal(0.0, 1.0, (40, k)) * sd).constant
    lo, _ = interval99(hits, reps)
    assert lo > power


def test_seed_correlation_interval_covers():
    # Fisher's z interval of r holds the true correlation in about 95 % of samples
    rng = np.random.default_rng(13)
    for rho in (0.0, 0.6):
        reps, hits = 1000, 0
        cov = [[1.0, rho], [rho, 1.0]]
        for _ in range(reps):
            a, b = rng.multivariate_normal([0.0, 0.0], cov, 12).T
            lo, hi = seed_correlation(a, b).ci95
            hits += lo <= rho <= hi
        lo_rate, hi_rate = interval99(hits, reps)
        assert lo_rate <= 0.95 <= hi_rate
    res = seed_correlation([1.0, 2.0, 3.0, 4.0], [2.0, 4.0, 6.0, 8.5])
    assert res.r == pytest.approx(np.corrcoef([1, 2, 3, 4], [2, 4, 6, 8.5])[0, 1])
    assert res.variance_ratio == pytest.approx(1 - res.r)
    with pytest.raises(InputError):
        seed_correlation([1.0, 2.0, 3.0], [1.0, 2.0, 3.0])


def test_replicates_follow_the_noise():
    assert replicates_for(0.5, 1.0) == 2          # never fewer than two: every point measures noise
    assert replicates_for(3.0, 1.0) == 2          # 3 / sqrt(2) = 2.1 <= 3
    assert replicates_for(4.5, 1.0) == 3          # 4.5 / sqrt(2) = 3.2 > 3; / sqrt(3) = 2.6
    assert replicates_for(12.0, 1.0) == 4         # capped
    assert replicates_for(4.5, 2.0) == 2
    with pytest.raises(InputError):
        replicates_for(1.0, 0.0)
