"""Calibrating a noisy simulator: a surrogate that knows the noise, and the set of parameters
consistent with the lab.

One DEM heap's angle scatters by a few degrees from seed to seed, so no single run, and no
single optimum of a fitted surface, says where the parameters are. This module turns all the
runs of a campaign into a statement that holds up to the noise:

1. **Surrogate** (:class:`NoisySurrogate`): a Gaussian process of the *mean* response over the
   parameters (scikit-learn's ``GaussianProcessRegressor``, Matern 5/2 kernel with one length
   scale per parameter), with each design point's own noise variance, its replicate variance
   over its number of runs, on the diagonal: stochastic kriging [Ankenman2010]_. Its prediction
   sd is the uncertainty of the mean angle, not of one run.
2. **Prior** (:class:`Prior`): each parameter's measured mean and sd (the lab's spread of single
   measurements), a normal truncated to mean -+ ``PRIOR_WIDTH`` sd and the admissible range.
3. **Posterior and plausible set** (:func:`posterior`): prior samples weighted by the
   likelihood of the lab target, N(target; m(x), s_m(x)^2 + s_target^2 + s_disc^2), and the
   history-matching implausibility I(x) = |target - m(x)| / sqrt(same variance) [Craig1997]_,
   [Vernon2010]_; samples with I < 3 form the plausible (not ruled out yet) set. Per parameter:
   a 95 % interval and the ratio of posterior to prior sd (near 1: the heap does not identify
   it).
4. **Sequential runs** (:func:`next_points`): where it is least certain whether the mean angle
   equals the target, the smallest U(x) = |m(x) - target| / s(x) among prior samples
   [Echard2011]_, a batch at a time with the surrogate told that each chosen point's result is
   its own prediction (the "kriging believer"), so one batch spreads out. The campaign stops
   adding when every candidate has U >= 2 (the sign of m - target is then known with 97.7 %
   probability everywhere) or its budget is spent.
5. **Recommended point** (:func:`recommend`): the posterior mode, found from the best samples
   by bounded quasi-Newton steps; it lies in the plausible set by construction.

References
----------
.. [Ankenman2010] B. Ankenman, B. L. Nelson, J. Staum, "Stochastic kriging for simulation
   metamodeling", Operations Research 58(2), 371-382 (2010).
.. [Craig1997] P. S. Craig, M. Goldstein, A. H. Seheult, J. A. Smith, "Pressure matching for
   hydrocarbon reservoirs: a case study in the use of Bayes linear strategies for large
   computer experiments", in *Case Studies in Bayesian Statistics* III, Springer, 37-93 (1997).
.. [Vernon2010] I. Vernon, M. Goldstein, R. G. Bower, "Galaxy formation: a Bayesian
   uncertainty analysis", Bayesian Analysis 5(4), 619-669 (2010).
.. [Echard2011] B. Echard, N. Gayton, M. Lemaire, "AK-MCS: an active learning reliability
   method combining Kriging and Monte Carlo simulation", Structural Safety 33(2), 145-154 (2011).
.. [Rasmussen2006] C. E. Rasmussen, C. K. I. Williams, *Gaussian Processes for Machine
   Learning*, MIT Press (2006), sections 2.2 and 5.4.2 (leave-one-out).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize, stats

from demcal.errors import AnalysisError, InputError

#: The prior is truncated to mean -+ this many measured sd (and the admissible range).
PRIOR_WIDTH = 3.0
#: Implausibility cut-off of the plausible set (Pukelsheim's three-sigma rule).
IMPLAUSIBILITY_CUT = 3.0
#: Stop adding runs once every candidate's |m - target| / s is at least this.
U_STOP = 2.0
#: Posterior sd over prior sd below which a parameter counts as identified by the heap, and
#: above which as not identified (between: partly).
IDENTIFIED_BELOW, NOT_IDENTIFIED_ABOVE = 0.7, 0.9


# ----------------------------------------------------------------------------------------------
# prior

@dataclass(frozen=True)
class Prior:
    """Independent truncated normals, one per parameter.

    Attributes
    ----------
    names : tuple of str
        DEM parameter names (as ``--set`` takes them).
    mean, sd : numpy.ndarray
        Measured mean and sd of each parameter (before truncation).
    low, high : numpy.ndarray
        Truncation: mean -+ ``PRIOR_WIDTH`` sd, inside the admissible range.
    sources : tuple of str
        The measured quantity behind each parameter.
    """

    names: tuple
    mean: np.ndarray
    sd: np.ndarray
    low: np.ndarray
    high: np.ndarray
    sources: tuple = ()

    @classmethod
    def from_measured(cls, names, mean, sd, bounds, sources=(), width: float = PRIOR_WIDTH) -> "Prior":
        mean, sd = np.asarray(mean, dtype=float), np.asarray(sd, dtype=float)
        if np.any(~(sd > 0)):
            bad = [n for n, s in zip(names, sd) if not s > 0]
            raise InputError(f"the prior needs a measured spread (sd > 0) for {', '.join(bad)}")
        lo = np.maximum(mean - width * sd, [b[0] for b in bounds])
        hi = np.minimum(mean + width * sd, [b[1] for b in bounds])
        if np.any(hi <= lo):
            bad = [n for n, a, b in zip(names, lo, hi) if b <= a]
            raise InputError(f"the prior of {', '.join(bad)} is empty inside the admissible range")
        return cls(tuple(names), mean, sd, lo, hi, tuple(sources))

    def _args(self) -> tuple:
        """Shape and location arguments of ``scipy.stats.truncnorm``."""
        return (self.low - self.mean) / self.sd, (self.high - self.mean) / self.sd, self.mean, self.sd

    def _dist(self):
        return stats.truncnorm(*self._args())

    @property
    def dim(self) -> int:
        return len(self.names)

    def ppf(self, u) -> np.ndarray:
        """Parameters at the cumulative probabilities ``u`` (n, dim)."""
        return self._dist().ppf(np.clip(np.asarray(u, dtype=float), 1e-9, 1 - 1e-9))

    def sample(self, n: int, rng) -> np.ndarray:
        return self.ppf(rng.random((n, self.dim)))

    def logpdf(self, x) -> np.ndarray:
        # the distribution's own method, not a frozen one: freezing rebuilds scipy's distribution
        # object (docstrings included) on every call, and the posterior mode calls this thousands
        # of times
        return np.sum(stats.truncnorm.logpdf(np.atleast_2d(x), *self._args()), axis=1)

    def truncated_mean_sd(self) -> tuple[np.ndarray, np.ndarray]:
        d = self._dist()
        return d.mean(), d.std()

    def to_dict(self) -> dict:
        m, s = self.truncated_mean_sd()
        return {n: {"mean": float(a), "sd": float(b), "low": float(lo), "high": float(hi),
                    "truncated_mean": float(tm), "truncated_sd": float(ts),
                    "source": self.sources[i] if i < len(self.sources) else None}
                for i, (n, a, b, lo, hi, tm, ts) in enumerate(zip(self.names, self.mean, self.sd,
                                                                   self.low, self.high, m, s))}


def space_filling(prior: Prior, n: int, seed) -> np.ndarray:
    """``n`` points of a Latin hypercube (optimised for centred discrepancy) mapped through the
    prior's quantiles: spread over the whole prior box, denser where the prior is."""
    lhs = stats.qmc.LatinHypercube(d=prior.dim, optimization="random-cd", seed=np.random.default_rng(seed))
    return prior.ppf(lhs.random(n))


# ----------------------------------------------------------------------------------------------
# surrogate

class NoisySurrogate:
    """Gaussian process of the mean response with per-point noise (stochastic kriging).

    Inputs are scaled to the prior box ([0, 1] per parameter); the response is centred on the
    noise-weighted mean of the points. ``alpha`` (the noise variance of each point's mean) goes
    on the kernel's diagonal in the response's own units: the process is fitted without
    scikit-learn's ``normalize_y``, which would rescale the noise.

    The kernel is c0 + s^2 Matern(5/2): the fixed, wide constant term c0 is a diffuse prior on
    the level of the mean, so that its uncertainty enters every prediction (ordinary kriging,
    [Rasmussen2006]_ 2.7). Without it, a surface the data cannot tell from flat (s^2 at its
    lower bound) would be predicted to a tenth of a degree from runs that scatter by ten.
    """

    #: c0 over the spread of the point means: wide enough to be diffuse.
    LEVEL_PRIOR = 100.0

    def __init__(self, low, high, seed: int = 0, restarts: int = 4):
        self.low, self.high = np.asarray(low, dtype=float), np.asarray(high, dtype=float)
        self.seed, self.restarts = int(seed), int(restarts)
        self.gp = None

    def _scale(self, x):
        return (np.atleast_2d(np.asarray(x, dtype=float)) - self.low) / (self.high - self.low)

    def fit(self, x, y, noise_var, kernel=None) -> "NoisySurrogate":
        """Fit to point means ``y`` (n,) at ``x`` (n, dim) whose noise variances are ``noise_var``
        (n,). ``kernel``: keep these hyperparameters (no optimisation), e.g. ``self.kernel``."""
        from sklearn.gaussian_process import GaussianProcessRegressor
        from sklearn.gaussian_process.kernels import ConstantKernel, Matern

        x, y = self._scale(x), np.asarray(y, dtype=float)
        noise_var = np.broadcast_to(np.asarray(noise_var, dtype=float), y.shape).copy()
        if x.shape[0] != y.size or y.size < 3:
            raise AnalysisError(f"the surrogate needs at least 3 design points, got {y.size}")
        w = 1.0 / np.maximum(noise_var, 1e-12)
        self.offset = float(np.sum(w * y) / np.sum(w))
        spread = max(float(np.var(y)), 1.0)
        if kernel is None:
            kernel = (ConstantKernel(self.LEVEL_PRIOR * spread, "fixed")
                      + ConstantKernel(spread, (1e-2, 1e2 * spread))
                      * Matern(length_scale=np.full(x.shape[1], 0.5), length_scale_bounds=(0.05, 50.0), nu=2.5))
            optimizer, restarts = "fmin_l_bfgs_b", self.restarts
        else:
            optimizer, restarts = None, 0
        gp = GaussianProcessRegressor(kernel=kernel, alpha=np.maximum(noise_var, 1e-10),
                                      optimizer=optimizer, n_restarts_optimizer=restarts,
                                      normalize_y=False, random_state=self.seed)
        with warnings.catch_warnings():
            # a length scale at its upper bound only says that parameter does not matter
            warnings.simplefilter("ignore")
            gp.fit(x, y - self.offset)
        self.gp, self.x, self.y, self.noise_var = gp, x, y, noise_var
        return self

    @property
    def kernel(self):
        return self.gp.kernel_

    def predict(self, x) -> tuple[np.ndarray, np.ndarray]:
        """Mean response and its sd (of the mean, without run noise) at ``x`` (n, dim)."""
        m, s = self.gp.predict(self._scale(x), return_std=True)
        return m + self.offset, s

    def length_scales(self) -> np.ndarray:
        """Fitted length scales, as fractions of each parameter's prior box."""
        return np.atleast_1d(self.gp.kernel_.k2.k2.length_scale).astype(float)

    def leave_one_out(self) -> dict:
        """Leave-one-out prediction of every point from the others, in closed form
        ([Rasmussen2006]_ 5.4.2): residuals and their standardised values (each residual over
        the sd of the prediction plus the point's own noise; about N(0, 1) when the surrogate
        and its noise model are right)."""
        k = self.gp.kernel_(self.x) + np.diag(self.noise_var)
        kinv = np.linalg.inv(k)
        r = self.y - self.offset
        d = np.diag(kinv)
        resid = (kinv @ r) / d                    # y_i - loo prediction of y_i
        z = resid * np.sqrt(d)                    # var of the loo residual is 1 / d
        return {"residual": resid.tolist(), "standardised": z.tolist(),
                "rmse": float(np.sqrt(np.mean(resid ** 2))),
                "share_within_2": float(np.mean(np.abs(z) < 2.0))}


# ----------------------------------------------------------------------------------------------
# posterior, plausible set, identifiability

@dataclass(frozen=True)
class HeapDatum:
    """A further lab reading the posterior is conditioned on (another repose rig's angle, or an
    extra target such as a crest height): the surrogate of the twin's mean reading, the lab's
    mean and the variance of that mean.

    ``discrepancy_var`` None takes the posterior's (an angle's, deg^2); an extra target in
    another unit gives its own. A reading taken from the same photos as another (``given``: a
    crest height and its rig's angle) has lab means that covary by ``lab_cov``: its likelihood is
    then conditional on the other's residual, so that the two together are a bivariate normal."""

    surrogate: NoisySurrogate
    target: float
    target_var: float
    discrepancy_var: float | None = None
    given: "HeapDatum | None" = None
    lab_cov: float = 0.0

    def _moments(self, x, discrepancy_var: float) -> tuple[np.ndarray, np.ndarray]:
        m, s = self.surrogate.predict(x)
        extra = discrepancy_var if self.discrepancy_var is None else self.discrepancy_var
        return m, s ** 2 + self.target_var + extra

    def terms(self, x, discrepancy_var: float) -> tuple[np.ndarray, np.ndarray]:
        """Log-likelihood (conditional on ``given``'s reading when they covary) and marginal
        implausibility of the reading at the points ``x`` (n, dim)."""
        m, var = self._moments(x, discrepancy_var)
        implausibility = np.abs(self.target - m) / np.sqrt(var)
        if self.given is not None and self.lab_cov != 0.0:
            mg, vg = self.given._moments(x, discrepancy_var)
            k = self.lab_cov / vg
            m, var = m + k * (self.given.target - mg), var - k * self.lab_cov
        return -0.5 * (self.target - m) ** 2 / var - 0.5 * np.log(var), implausibility


@dataclass
class Posterior:
    """Prior samples weighted by the likelihood of the lab target (and of the ``others`` heaps).

    Attributes
    ----------
    samples : numpy.ndarray (n, dim)
    weights : numpy.ndarray (n,)
        Normalised importance weights.
    predicted, predicted_sd : numpy.ndarray (n,)
        Surrogate mean and sd at each sample (of the first heap).
    implausibility : numpy.ndarray (n,)
        The largest over the heaps (history matching's maximum implausibility).
    ess : float
        Effective sample size of the weights.
    others : tuple of HeapDatum
        The further heaps.
    """

    prior: Prior
    samples: np.ndarray
    weights: np.ndarray
    predicted: np.ndarray
    predicted_sd: np.ndarray
    implausibility: np.ndarray
    ess: float
    target: float
    target_var: float
    discrepancy_var: float
    parameters: dict = field(default_factory=dict)
    others: tuple = ()

    @property
    def plausible(self) -> np.ndarray:
        return self.implausibility < IMPLAUSIBILITY_CUT

    def summary(self) -> dict:
        """Per parameter: posterior mean, sd, 95 % interval, prior mean and sd, their ratio and
        what the heap says about it; plus the plausible share of the prior."""
        w = self.weights
        prior_mean, prior_sd = self.prior.truncated_mean_sd()
        out = {}
        for j, name in enumerate(self.prior.names):
            v = self.samples[:, j]
            mean = float(np.sum(w * v))
            sd = float(math.sqrt(max(np.sum(w * (v - mean) ** 2), 0.0)))
            lo, hi = weighted_quantiles(v, w, (0.025, 0.975))
            ratio = sd / float(prior_sd[j])
            if ratio < IDENTIFIED_BELOW:
                verdict = "identified"
            elif ratio > NOT_IDENTIFIED_ABOVE:
                verdict = "not identified"
            else:
                verdict = "partly identified"
            out[name] = {"mean": mean, "sd": sd, "ci95": [float(lo), float(hi)],
                         "prior_mean": float(self.prior.mean[j]), "prior_sd": float(self.prior.sd[j]),
                         "prior_truncated_sd": float(prior_sd[j]), "sd_ratio": ratio,
                         "identifiability": verdict, "source": self.prior.sources[j]
                         if j < len(self.prior.sources) else None}
        return out

    def plausible_box(self) -> dict:
        """Range of every parameter over the plausible samples."""
        keep = self.plausible
        if not keep.any():
            return {}
        return {n: [float(self.samples[keep, j].min()), float(self.samples[keep, j].max())]
                for j, n in enumerate(self.prior.names)}


def weighted_quantiles(values, weights, qs) -> list[float]:
    order = np.argsort(values)
    v, w = np.asarray(values)[order], np.asarray(weights)[order]
    c = np.cumsum(w) - 0.5 * w
    c /= c[-1] + 0.5 * w[-1]
    return [float(np.interp(q, c, v)) for q in qs]


def posterior(surrogate: NoisySurrogate, prior: Prior, target: float, target_var: float, *,
              discrepancy_var: float = 0.0, n: int = 20000, seed=0, log_likelihood=None,
              others=()) -> Posterior:
    """Importance-sample the posterior of the parameters given the lab target.

    Parameters
    ----------
    surrogate : NoisySurrogate
    prior : Prior
    target : float
        Lab target (mean of the photographed heaps).
    target_var : float
        Variance of that mean (the lab's heap-to-heap sd squared over the number of heaps).
    discrepancy_var : float
        Variance allowed for what the model cannot represent (0: none).
    n : int
        Prior samples.
    seed : int or numpy.random.SeedSequence
    log_likelihood : callable, optional
        ``f(samples) -> (n,)`` log-likelihood of other lab tests (the joint calibration's drop
        and incline twins), added to the heap's.
    others : sequence of HeapDatum
        Further heaps (other repose rigs of the workbook), each with its own surrogate: their
        log-likelihoods are added, and the implausibility is the largest of all heaps'.
    """
    rng = np.random.default_rng(seed)
    x = prior.sample(n, rng)
    m, s = surrogate.predict(x)
    var = s ** 2 + target_var + discrepancy_var
    logw = -0.5 * (target - m) ** 2 / var - 0.5 * np.log(var)
    implausibility = np.abs(target - m) / np.sqrt(var)
    for other in others:
        ll, imp = other.terms(x, discrepancy_var)
        logw = logw + ll
        implausibility = np.maximum(implausibility, imp)
    if log_likelihood is not None:
        logw = logw + np.asarray(log_likelihood(x), dtype=float)
    logw -= logw.max()
    w = np.exp(logw)
    w /= w.sum()
    ess = float(1.0 / np.sum(w ** 2))
    return Posterior(prior, x, w, m, s, implausibility, ess, float(target),
                     float(target_var), float(discrepancy_var), others=tuple(others))


def log_posterior(post: Posterior, surrogate: NoisySurrogate, x, log_likelihood=None) -> np.ndarray:
    """Log prior + log likelihood of the lab target (and of the posterior's other heaps) at the
    points ``x`` (n, dim), the surrogate's own variance added to the target's and the
    discrepancy's (unnormalised)."""
    x = np.atleast_2d(np.asarray(x, dtype=float))
    m, s = surrogate.predict(x)
    var = s ** 2 + post.target_var + post.discrepancy_var
    val = post.prior.logpdf(x) - 0.5 * (post.target - m) ** 2 / var - 0.5 * np.log(var)
    for other in post.others:
        val = val + other.terms(x, post.discrepancy_var)[0]
    if log_likelihood is not None:
        val = val + np.asarray(log_likelihood(x), dtype=float)
    return val


def _at(post: Posterior, surrogate: NoisySurrogate, x, log_post: float) -> dict:
    x = np.asarray(x, dtype=float)
    m, s = surrogate.predict(x[None, :])
    imp = abs(post.target - m[0]) / math.sqrt(s[0] ** 2 + post.target_var + post.discrepancy_var)
    for other in post.others:
        imp = max(imp, float(other.terms(x[None, :], post.discrepancy_var)[1][0]))
    return {"values": {n: float(v) for n, v in zip(post.prior.names, x)}, "predicted": float(m[0]),
            "predicted_sd": float(s[0]), "implausibility": float(imp), "log_posterior": float(log_post)}


def recommend(post: Posterior, surrogate: NoisySurrogate, log_likelihood=None, starts: int = 5) -> dict:
    """The posterior mode: bounded quasi-Newton steps on log prior + log likelihood from the
    ``starts`` best-weighted samples.

    Returns ``{"values": {name: value}, "predicted", "predicted_sd", "implausibility",
    "log_posterior"}``."""
    prior = post.prior

    def neg_log_post(x):
        val = log_posterior(post, surrogate, x[None, :], log_likelihood)[0]
        return -val if np.isfinite(val) else 1e30

    # the prior's logpdf is -inf on its boundary: stay a hair inside
    pad = 1e-9 * (prior.high - prior.low)
    bounds = list(zip(prior.low + pad, prior.high - pad))
    best = None
    for i in np.argsort(-post.weights)[:starts]:
        res = optimize.minimize(neg_log_post, post.samples[i], method="L-BFGS-B", bounds=bounds)
        if best is None or res.fun < best.fun:
            best = res
    return _at(post, surrogate, best.x, -best.fun)


def recommend_among(post: Posterior, surrogate: NoisySurrogate, points, log_likelihood=None) -> dict:
    """Of ``points`` (n, dim), e.g. the points whose mean angle was measured by replicates, the
    one with the highest posterior density; same keys as ``recommend`` plus ``index``."""
    points = np.atleast_2d(np.asarray(points, dtype=float))
    lp = log_posterior(post, surrogate, points, log_likelihood)
    i = int(np.argmax(lp))
    return {**_at(post, surrogate, points[i], lp[i]), "index": i}


# ----------------------------------------------------------------------------------------------
# sequential design

def next_points(surrogate: NoisySurrogate, prior: Prior, target: float, batch: int, *,
                noise_var: float, candidates: int = 4000, seed=0) -> tuple[np.ndarray, float]:
    """Where to run next: the ``batch`` prior samples with the smallest
    U = |m - target| / s, chosen one at a time, the surrogate updated after each choice as if
    the run had returned its prediction (with noise ``noise_var``, hyperparameters kept).

    Returns the points (batch, dim) and the smallest U before the first choice (the stopping
    statistic: at least ``U_STOP`` means the sign of m - target is settled everywhere)."""
    rng = np.random.default_rng(seed)
    cand = prior.sample(candidates, rng)
    model = surrogate
    chosen, u_min = [], math.inf
    x_known = surrogate.low + surrogate.x * (surrogate.high - surrogate.low)
    y_known, nv_known = surrogate.y.copy(), surrogate.noise_var.copy()
    for b in range(batch):
        m, s = model.predict(cand)
        u = np.abs(m - target) / np.maximum(s, 1e-12)
        i = int(np.argmin(u))
        if b == 0:
            u_min = float(u[i])
        chosen.append(cand[i])
        x_known = np.vstack([x_known, cand[i]])
        y_known = np.append(y_known, m[i])
        nv_known = np.append(nv_known, noise_var)
        cand = np.delete(cand, i, axis=0)
        model = NoisySurrogate(surrogate.low, surrogate.high, surrogate.seed).fit(
            x_known, y_known, nv_known, kernel=surrogate.kernel)
    return np.array(chosen), u_min
