"""The surrogate and the posterior: leave-one-out in closed form against refits without each
point (a second implementation), predictions against a known function, the prior against
scipy's truncated normal, and the importance-sampled posterior against the conjugate normal
answer."""

import math

import numpy as np
import pytest
from scipy import stats

from demcal.analyse.surrogate import (NoisySurrogate, Prior, next_points, posterior, recommend, recommend_among,
                                      space_filling)


def prior_2d():
    return Prior.from_measured(["a", "b"], [0.5, 0.3], [0.1, 0.05], [(0.0, 1.0), (0.0, 1.0)], ["qa", "qb"])


def truth(x):
    x = np.atleast_2d(x)
    return 30.0 + 40.0 * (x[:, 0] - 0.5) + 10.0 * np.sin(20.0 * (x[:, 1] - 0.3))


def fitted(seed=0, n=25, noise_sd=0.5):
    prior = prior_2d()
    rng = np.random.default_rng(seed)
    x = space_filling(prior, n, seed)
    y = truth(x) + rng.normal(0, noise_sd, n)
    return prior, NoisySurrogate(prior.low, prior.high, seed=0).fit(x, y, np.full(n, noise_sd ** 2)), x, y


def test_prior_is_scipys_truncated_normal():
    prior = prior_2d()
    assert prior.low == pytest.approx([0.2, 0.15]) and prior.high == pytest.approx([0.8, 0.45])
    m, s = prior.truncated_mean_sd()
    ref = stats.truncnorm(-3, 3, loc=0.5, scale=0.1)
    assert m[0] == pytest.approx(ref.mean()) and s[0] == pytest.approx(ref.std())
    x = prior.sample(20000, np.random.default_rng(1))
    assert x[:, 0].std() == pytest.approx(ref.std(), rel=0.03)
    assert np.all((x >= prior.low) & (x <= prior.high))


def test_leave_one_out_equals_refits_without_each_point():
    prior, model, x, y = fitted()
    loo = model.leave_one_out()
    for i in (0, 7, 19):
        keep = np.arange(len(y)) != i
        other = NoisySurrogate(prior.low, prior.high).fit(x[keep], y[keep], model.noise_var[keep],
                                                         kernel=model.kernel)
        # the refit centres y on its own weighted mean, which shifts only the constant
        other.offset = model.offset
        other.gp.fit(other.x, y[keep] - model.offset)
        m, _ = other.predict(x[i])
        assert loo["residual"][i] == pytest.approx(y[i] - m[0], rel=1e-6, abs=1e-8)


def test_predictions_hold_the_known_function():
    prior, model, _, _ = fitted(n=40)
    x = prior.sample(500, np.random.default_rng(5))
    m, s = model.predict(x)
    z = (m - truth(x)) / s
    assert np.mean(np.abs(z) < 3) > 0.9
    assert np.sqrt(np.mean((m - truth(x)) ** 2)) < 1.5


class LinearModel:
    """A surrogate that is exact: m(x) = 30 + 40 (a - 0.5), no uncertainty."""

    low, high = np.array([0.2, 0.15]), np.array([0.8, 0.45])

    def predict(self, x):
        x = np.atleast_2d(x)
        return 30.0 + 40.0 * (x[:, 0] - 0.5), np.zeros(len(x))


def test_posterior_matches_the_conjugate_normal():
    prior = Prior.from_measured(["a", "b"], [0.5, 0.3], [0.1, 0.05], [(0.0, 1.0), (0.0, 1.0)], width=6.0)
    target, v = 32.0, 1.0
    post = posterior(LinearModel(), prior, target, v, n=200000, seed=3)
    # a ~ N(0.5, 0.1^2); target | a ~ N(30 + 40 (a - 0.5), 1): conjugate normal posterior
    prec = 1 / 0.1 ** 2 + 40.0 ** 2 / v
    mean = (0.5 / 0.1 ** 2 + 40.0 * (target - 30.0 + 40 * 0.5) / v) / prec
    s = post.summary()
    assert s["a"]["mean"] == pytest.approx(mean, abs=0.002)
    assert s["a"]["sd"] == pytest.approx(1 / math.sqrt(prec), rel=0.05)
    assert s["a"]["ci95"][0] == pytest.approx(mean - 1.96 / math.sqrt(prec), abs=0.004)
    # b does not enter the angle: its posterior is its prior
    assert s["b"]["sd_ratio"] == pytest.approx(1.0, abs=0.02)
    assert s["b"]["identifiability"] == "not identified" and s["a"]["identifiability"] == "identified"
    rec = recommend(post, LinearModel())
    assert rec["values"]["a"] == pytest.approx(mean, abs=1e-3)   # the mode of a normal is its mean
    assert rec["values"]["b"] == pytest.approx(0.3, abs=1e-3)
    # among given points: the normal posterior density by hand (b at its prior mean throughout)
    pts = np.array([[mean - 0.02, 0.3], [mean + 0.005, 0.3], [mean + 0.03, 0.3]])
    among = recommend_among(post, LinearModel(), pts)
    assert among["index"] == 1 and among["values"]["a"] == pytest.approx(mean + 0.005)
    hand = -0.5 * prec * (pts[:, 0] - mean) ** 2
    lp = [recommend_among(post, LinearModel(), p[None, :])["log_posterior"] for p in pts]
    assert np.diff(lp) == pytest.approx(np.diff(hand), rel=1e-6)


def test_next_points_go_where_the_sign_is_uncertain():
    prior, model, _, _ = fitted(n=12)
    pts, u_min = next_points(model, prior, 30.0, 4, noise_var=0.25, seed=2)
    assert pts.shape == (4, 2)
    m, s = model.predict(pts[:1])
    assert abs(m[0] - 30.0) / s[0] == pytest.approx(u_min)
    # the batch spreads out: no two chosen points coincide
    d = np.linalg.norm((pts[:, None] - pts[None]) / (prior.high - prior.low), axis=-1)
    assert d[np.triu_indices(4, 1)].min() > 1e-3


def test_a_flat_surface_is_predicted_with_the_uncertainty_of_its_level():
    # pure noise around a constant: the data cannot tell the surface from flat, and the
    # prediction must still carry the uncertainty of the level (about the SE of the mean of
    # all runs), not shrink to the kernel's lower bound. Coverage over repetitions, asserted by
    # its Clopper-Pearson bounds.
    prior = prior_2d()
    reps, n, noise_var, covered, ratio = 300, 12, 9.0 / 2, 0, []
    for rep in range(reps):
        rng = np.random.default_rng(1000 + rep)
        x = prior.sample(n, rng)
        y = 40.0 + rng.normal(0.0, math.sqrt(noise_var), n)
        model = NoisySurrogate(prior.low, prior.high, seed=rep, restarts=0).fit(x, y, np.full(n, noise_var))
        m, s = model.predict(prior.sample(1, rng))
        covered += abs(m[0] - 40.0) <= 1.96 * s[0]
        ratio.append(s[0] / math.sqrt(noise_var / n))
    lo = stats.beta.ppf(0.005, covered, reps - covered + 1)
    hi = stats.beta.ppf(0.995, covered + 1, reps - covered)
    assert lo > 0.85 and hi > 0.95, (covered, reps)
    # near the SE of the mean of every run, never a tenth of it
    assert 0.8 < np.median(ratio) < 2.0
