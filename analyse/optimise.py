"""Optimisation on fitted response surfaces: steepest ascent, the source paper's steepest climb,
optimisation to a target response, maximisation, canonical analysis and validation of repeats.

All functions are pure: they take fitted surfaces or measured responses and never run a
simulation (the campaign does that).

References
----------
.. [1] Myers, R. H., Montgomery, D. C. & Anderson-Cook, C. M. (2009). Response Surface
   Methodology, 3rd ed. Wiley. Section 5.2 (steepest ascent), 6.3-6.4 (stationary point,
   canonical analysis, ridge systems).
.. [2] Box, G. E. P. & Wilson, K. B. (1951). On the experimental attainment of optimum
   conditions. J. R. Stat. Soc. B 13(1), 1-45.
.. [3] Ma et al. (2020), as cited by the source paper: the steepest climb, significant factors
   stepped together with the relative error to the measured response as the criterion.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import optimize, stats

from demcal.analyse.designs import to_coded
from demcal.analyse.regression import ResponseSurface
from demcal.errors import AnalysisError, InputError


def _rng(seed):
    return seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)


def _surface(fit: ResponseSurface):
    """Fast yhat(x) and its gradient for a single coded point (second-order form)."""
    b0, b, B = fit.second_order()

    def value(x):
        return float(b0 + b @ x + x @ B @ x)

    def grad(x):
        return b + 2.0 * B @ x
    return value, grad


# --------------------------------------------------------------------------------------------
# Steepest ascent (Box & Wilson 1951)

@dataclass(frozen=True, eq=False)
class SteepestPath:
    """Path of steepest ascent (or descent) of a first-order model.

    Attributes
    ----------
    direction : numpy.ndarray
        (k,) unit vector b/|b| in coded units [-] (negated for descent).
    increment_actual : numpy.ndarray
        (k,) change of each factor per unit coded distance along the path [factor units].
    distances : numpy.ndarray
        (m,) coded distances from the design centre [-].
    coded, actual : numpy.ndarray
        (m, k) path points [-] and [factor units].
    predicted : numpy.ndarray
        (m,) fitted response along the path [response units].
    factors : tuple of str
    """

    direction: np.ndarray
    increment_actual: np.ndarray
    distances: np.ndarray
    coded: np.ndarray
    actual: np.ndarray
    predicted: np.ndarray
    factors: tuple[str, ...]

    def to_dict(self) -> dict:
        return {"factors": list(self.factors), "direction": self.direction.tolist(),
                "increment_actual": self.increment_actual.tolist(),
                "distances": self.distances.tolist(), "coded": self.coded.tolist(),
                "actual": self.actual.tolist(), "predicted": self.predicted.tolist()}


def steepest_ascent(fit: ResponseSurface, distances=(0.0, 0.5, 1.0), *,
                    descent: bool = False) -> SteepestPath:
    """Steepest-ascent path from the first-order coefficients of a fit (Box & Wilson 1951).

    The direction is the unit vector of the linear coefficients b (coded units); points lie at
    x = d b/|b| for each distance d. Higher-order terms, if any, only enter the predictions.
    """
    _, b, _ = fit.second_order()
    norm = float(np.linalg.norm(b))
    if norm == 0:
        raise AnalysisError("all first-order coefficients are zero: no direction of ascent")
    u = (-b if descent else b) / norm
    d = np.asarray(distances, dtype=float).ravel()
    coded = d[:, None] * u[None, :]
    return SteepestPath(direction=u, increment_actual=u * (fit.high - fit.low) / 2.0,
                        distances=d, coded=coded, actual=fit.to_actual(coded),
                        predicted=np.atleast_1d(fit.predict(coded)), factors=fit.factors)


# --------------------------------------------------------------------------------------------
# The source paper's steepest climb

@dataclass(frozen=True, eq=False)
class SteepestClimbPlan:
    """Levels of a steepest-climb series.

    Attributes
    ----------
    factors : tuple of str
        All factors, in column order of ``levels``.
    stepped : tuple of str
        The significant factors stepped together.
    directions : dict
        Stepped factor -> +1 (low to high) or -1 (high to low).
    levels : numpy.ndarray
        (n_levels, n_factors) actual settings of each level [factor units]; the factors not
        stepped stay at their fixed values.
    step : dict
        Stepped factor -> size of one step [factor units] (positive).
    """

    factors: tuple[str, ...]
    stepped: tuple[str, ...]
    directions: dict
    levels: np.ndarray
    step: dict

    def to_dict(self) -> dict:
        return {"factors": list(self.factors), "stepped": list(self.stepped),
                "directions": dict(self.directions), "step": dict(self.step),
                "levels": [dict(zip(self.factors, row)) for row in self.levels.tolist()]}


def steepest_climb_plan(low: dict, high: dict, effects: dict, significant, *, increase: bool,
                        n_levels: int = 6, fixed: dict | None = None) -> SteepestClimbPlan:
    """Plan the steepest climb: significant factors stepped together in equal steps across their
    range, each in the direction that moves the response toward the target, the other factors
    at fixed values (their measured means).

    Parameters
    ----------
    low, high : dict
        Factor -> lower and upper end of its range (the screening's -1/+1) [factor units].
    effects : dict
        Factor -> screening effect (only its sign is used) [response units]; a factor with a
        zero or missing effect is stepped as if its effect were positive.
    significant : iterable of str
        Factors to step.
    increase : bool
        True when the response must rise to reach the target (target above the current
        response, e.g. the screening mean), False when it must fall.
    n_levels : int
        Number of levels (>= 3), from one end of each range to the other.
    fixed : dict, optional
        Values of the factors not stepped; default the middle of their range.
    """
    factors = tuple(low)
    if set(high) != set(factors):
        raise InputError("low and high must name the same factors")
    stepped = tuple(significant)
    unknown = [f for f in stepped if f not in factors]
    if unknown:
        raise InputError(f"significant factors not in the level table: {', '.join(unknown)}")
    if not stepped:
        raise InputError("steepest climb needs at least one significant factor")
    if n_levels < 3:
        raise InputError(f"n_levels must be >= 3, got {n_levels}")
    fixed = dict(fixed or {})
    levels = np.empty((n_levels, len(factors)))
    directions, steps = {}, {}
    frac = np.linspace(0.0, 1.0, n_levels)
    for j, f in enumerate(factors):
        lo, hi = float(low[f]), float(high[f])
        if not hi > lo:
            raise InputError(f"factor {f}: high {hi!r} must exceed low {lo!r}")
        if f in stepped:
            e = float(effects[f]) if f in effects else 0.0
            # a factor without effect (carried only to fill the design) has no direction: up
            sign = (int(np.sign(e)) if e != 0.0 else 1) * (1 if increase else -1)
            directions[f] = sign
            steps[f] = (hi - lo) / (n_levels - 1)
            levels[:, j] = lo + frac * (hi - lo) if sign > 0 else hi - frac * (hi - lo)
        else:
            levels[:, j] = float(fixed.get(f, (lo + hi) / 2.0))
    return SteepestClimbPlan(factors, stepped, directions, levels, steps)


@dataclass(frozen=True, eq=False)
class SteepestClimbResult:
    """Outcome of a steepest climb.

    Attributes
    ----------
    responses : numpy.ndarray
        (n_levels,) response at each level [response units].
    relative_error_pct : numpy.ndarray
        (n_levels,) 100 |response - target| / |target| [%].
    target : float
    best_level : int
        1-based number of the level with the smallest relative error.
    centre, low, high : dict
        Stepped factor -> Box-Behnken centre (the best level) and its -1/+1 levels (the
        neighbouring levels, ordered so low < high) [factor units].
    at_edge : bool
        True when the best level is the first or last one: a longer climb may be warranted.
    note : str
    centre_level : int
        1-based number of the level at the Box-Behnken centre: the best level, or its inner
        neighbour when the best level is at an end and the window is kept inside the climb.
    smoothed : numpy.ndarray or None
        (n_levels,) the monotone (isotonic) fit of the responses the best level was chosen on,
        when the analysis was asked to smooth; None otherwise [response units].
    """

    responses: np.ndarray
    relative_error_pct: np.ndarray
    target: float
    best_level: int
    centre: dict
    low: dict
    high: dict
    at_edge: bool
    note: str
    centre_level: int = 0
    smoothed: np.ndarray | None = None

    def to_dict(self) -> dict:
        return {"responses": self.responses.tolist(),
                "smoothed": None if self.smoothed is None else self.smoothed.tolist(),
                "relative_error_pct": self.relative_error_pct.tolist(), "target": self.target,
                "best_level": self.best_level, "centre": dict(self.centre),
                "low": dict(self.low), "high": dict(self.high), "at_edge": self.at_edge,
                "note": self.note, "centre_level": self.centre_level or self.best_level}


def isotonic(y, increasing: bool = True) -> np.ndarray:
    """Least-squares monotone fit of the sequence ``y`` (pool adjacent violators)."""
    v = np.asarray(y, dtype=float).ravel()
    sign = 1.0 if increasing else -1.0
    blocks = []  # [mean, weight] of pooled runs, nondecreasing in sign * mean
    for value in sign * v:
        blocks.append([value, 1.0])
        while len(blocks) > 1 and blocks[-2][0] > blocks[-1][0]:
            m2, w2 = blocks.pop()
            m1, w1 = blocks.pop()
            blocks.append([(m1 * w1 + m2 * w2) / (w1 + w2), w1 + w2])
    return sign * np.concatenate([np.full(int(w), m) for m, w in blocks])


def steepest_climb_analysis(plan: SteepestClimbPlan, responses, target: float, *,
                            extrapolate: bool = True,
                            monotone: bool | None = None) -> SteepestClimbResult:
    """Relative error per level, the best level, and the Box-Behnken levels around it.

    The best level (smallest |response - target|) becomes the Box-Behnken centre and the levels
    on either side its -1 and +1, as in the source paper (level 4 the centre, levels 3 and 5
    the low and high levels). When the best level is the first or last one, its missing
    neighbour is extrapolated by one step (``extrapolate``, the paper's rule carried to the
    edge), or, with ``extrapolate=False``, the window moves one level inward so that every
    Box-Behnken level stays inside the climbed (measured) range.

    ``monotone`` (True: the response should rise along the climb, False: fall) chooses the best
    level on the isotonic fit of the responses instead of the raw ones, so that one noisy level
    cannot pull the window away from where the climb crosses the target; ties go to the earlier
    level. None (default) is the paper's rule on the raw responses.
    """
    y = np.asarray(responses, dtype=float).ravel()
    n = plan.levels.shape[0]
    if y.size != n:
        raise InputError(f"{y.size} responses given for {n} climb levels")
    if not np.all(np.isfinite(y)):
        raise InputError("climb responses must be finite")
    if target == 0:
        raise InputError("target must be non-zero for a relative error")
    rel = 100.0 * np.abs(y - target) / abs(target)
    smoothed = None if monotone is None else isotonic(y, increasing=monotone)
    best = int(np.argmin(rel if smoothed is None else np.abs(smoothed - target)))
    at_edge = best in (0, n - 1)
    mid = best if extrapolate or not at_edge else (1 if best == 0 else n - 2)
    centre, lo, hi = {}, {}, {}
    for f in plan.stepped:
        j = plan.factors.index(f)
        col = plan.levels[:, j]
        c = col[mid]
        step = col[1] - col[0]
        before = col[mid - 1] if mid > 0 else c - step
        after = col[mid + 1] if mid < n - 1 else c + step
        centre[f], lo[f], hi[f] = float(c), float(min(before, after)), float(max(before, after))
    note = f"level {best + 1} of {n} has the smallest relative error ({rel[best]:.3g} %)"
    if smoothed is not None:
        note = (f"level {best + 1} of {n} is closest to the target on the monotone fit of the "
                f"responses ({smoothed[best]:.4g}; raw {y[best]:.4g}, relative error {rel[best]:.3g} %)")
    if mid == best:
        note += "; it is the Box-Behnken centre and its neighbours are -1/+1"
    if at_edge and extrapolate:
        note += ("; the best level is at the end of the climb, so the missing neighbour was "
                 "extrapolated by one step: consider extending the climb")
    elif at_edge:
        note += (f"; it is at the end of the climb, so the Box-Behnken window is levels "
                 f"{min(mid, best)}-{max(mid, best) + 1} (centre level {mid + 1}) to stay inside "
                 f"the measured range: the target may lie beyond it")
    return SteepestClimbResult(y, rel, float(target), best + 1, centre, lo, hi, at_edge, note,
                               mid + 1, smoothed)


# --------------------------------------------------------------------------------------------
# Optimisation to a target and maximisation inside the coded cube

@dataclass(frozen=True, eq=False)
class TargetOptimum:
    """Solutions of yhat(x) = target inside the coded cube [-1, 1]^k.

    Attributes
    ----------
    target : float
        Target response [response units].
    reached : bool
        False when no point of the cube reaches the target; ``solutions`` then holds the
        closest approach.
    coded : numpy.ndarray
        (m, k) solutions in coded units, the preferred one first, the others by increasing
        distance to the reference [-].
    actual : numpy.ndarray
        (m, k) the same in actual units [factor units].
    predicted : numpy.ndarray
        (m,) fitted response at each solution [response units].
    distance : numpy.ndarray
        (m,) Euclidean distance to the reference in coded units [-].
    reference_coded, reference_actual : numpy.ndarray
        The reference point (e.g. the measured means) [-], [factor units].
    factors, letters : tuple of str
    note : str
        States that all points with yhat = target tie and which one is preferred.
    """

    target: float
    reached: bool
    coded: np.ndarray
    actual: np.ndarray
    predicted: np.ndarray
    distance: np.ndarray
    reference_coded: np.ndarray
    reference_actual: np.ndarray
    factors: tuple[str, ...]
    letters: tuple[str, ...]
    note: str

    @property
    def preferred(self) -> dict:
        """The preferred solution: coded, actual, predicted, distance."""
        return self._solution(0)

    def _solution(self, i):
        return {"coded": dict(zip(self.letters, self.coded[i].tolist())),
                "actual": dict(zip(self.factors, self.actual[i].tolist())),
                "predicted": float(self.predicted[i]), "distance": float(self.distance[i])}

    def to_dict(self) -> dict:
        return {"target": self.target, "reached": self.reached,
                "preferred": self.preferred,
                "solutions": [self._solution(i) for i in range(len(self.predicted))],
                "reference_coded": dict(zip(self.letters, self.reference_coded.tolist())),
                "reference_actual": dict(zip(self.factors, self.reference_actual.tolist())),
                "note": self.note}


def _closest_on_surface(value, grad, target, start, anchor, tol):
    """min |x - anchor|^2 subject to yhat(x) = target, -1 <= x <= 1 (SLSQP from ``start``)."""
    k = start.size
    res = optimize.minimize(
        lambda x: float(np.sum((x - anchor) ** 2)), start, jac=lambda x: 2.0 * (x - anchor),
        method="SLSQP", bounds=[(-1.0, 1.0)] * k,
        constraints=[{"type": "eq", "fun": lambda x: value(x) - target, "jac": grad}],
        options={"maxiter": 200, "ftol": 1e-12})
    x = np.clip(res.x, -1.0, 1.0)
    return x, abs(value(x) - target) <= tol


def optimise_to_target(fit: ResponseSurface, target: float, *, reference_actual=None,
                       reference_coded=None, n_starts: int = 48, seed=0,
                       tol: float | None = None, min_separation: float = 0.1,
                       max_solutions: int = 10) -> TargetOptimum:
    """Find settings inside the coded cube where the fitted response equals ``target``.

    Every point of the surface yhat = target inside the cube is an equally good answer, so
    several well-separated solutions are returned. Each one is the point of that surface
    closest to a start (the reference, then random starts from ``seed``), found by SLSQP; the
    preferred solution is the point of the surface closest to the reference (default the
    design centre; give the measured means), and the others follow by distance to it.

    Parameters
    ----------
    fit : ResponseSurface
    target : float
        Target response [response units].
    reference_actual, reference_coded : array_like, optional
        Reference point in actual [factor units] or coded [-] units (not both).
    n_starts : int
        Random starts used to collect alternative solutions.
    seed : int or numpy.random.Generator
    tol : float, optional
        Largest accepted |yhat - target| [response units]; default 1e-6 of the response scale.
    min_separation : float
        Alternative solutions closer than this (coded distance) to a kept one are dropped.
    max_solutions : int
        Most solutions returned (the preferred one included).
    """
    k = len(fit.factors)
    if reference_actual is not None and reference_coded is not None:
        raise InputError("give reference_actual or reference_coded, not both")
    if reference_actual is not None:
        ref = np.asarray(to_coded(reference_actual, fit.low, fit.high), dtype=float).ravel()
    elif reference_coded is not None:
        ref = np.asarray(reference_coded, dtype=float).ravel()
    else:
        ref = np.zeros(k)
    if ref.size != k:
        raise InputError(f"reference needs {k} values, got {ref.size}")
    scale = max(1.0, abs(float(target)), float(np.max(np.abs(fit.observed))))
    tol = 1e-6 * scale if tol is None else float(tol)
    value, grad = _surface(fit)
    # yhat is continuous on the connected cube: the target is reachable iff it lies between
    # the minimum and the maximum.
    rng = _rng(seed)
    lowest = optimise(fit, "minimise", n_starts=8, seed=rng)
    highest = optimise(fit, "maximise", n_starts=8, seed=rng)
    if not lowest.predicted - tol <= target <= highest.predicted + tol:
        end = highest if target > highest.predicted else lowest
        coded = end.coded[None, :]
        reached = False
        note = ("the target is not reached anywhere inside the coded cube; the listed point "
                f"(the {'maximum' if end is highest else 'minimum'}) comes closest")
    else:
        anchor = np.clip(ref, -1.0, 1.0)
        starts = [anchor, np.zeros(k)] + list(rng.uniform(-1.0, 1.0, size=(n_starts, k)))
        found = [x for x, ok in (_closest_on_surface(value, grad, target, s, s, tol)
                                 for s in starts) if ok]
        if not found:
            raise AnalysisError(f"no point with predicted response {target} was found although "
                                f"the target lies between the minimum and maximum")
        # The preferred point: closest to the reference, polished from several starts.
        best = min(found, key=lambda x: np.linalg.norm(x - ref))
        for s in [anchor] + found[:8]:
            x, ok = _closest_on_surface(value, grad, target, s, ref, tol)
            if ok and np.linalg.norm(x - ref) < np.linalg.norm(best - ref):
                best = x
        kept = [best]
        for x in sorted(found, key=lambda x: np.linalg.norm(x - ref)):
            if len(kept) >= max_solutions:
                break
            if all(np.linalg.norm(x - y) >= min_separation for y in kept):
                kept.append(x)
        coded = np.array(kept)
        reached = True
        note = ("every point with predicted response equal to the target ties; "
                f"{len(kept)} separated solutions are listed and the first, the one closest to "
                "the reference point (in coded units), is preferred")
    pred = np.atleast_1d(fit.predict(coded))
    return TargetOptimum(target=float(target), reached=reached, coded=coded,
                         actual=fit.to_actual(coded), predicted=pred,
                         distance=np.linalg.norm(coded - ref, axis=1), reference_coded=ref,
                         reference_actual=fit.to_actual(ref), factors=fit.factors,
                         letters=fit.letters, note=note)


@dataclass(frozen=True, eq=False)
class Optimum:
    """Best point of a fitted surface inside the coded cube.

    Attributes
    ----------
    goal : str
        ``maximise`` or ``minimise``.
    coded, actual : numpy.ndarray
        (k,) location [-], [factor units].
    predicted : float
        Fitted response there [response units].
    on_boundary : bool
        True when a coordinate sits at -1 or +1 (the optimum may lie outside the region).
    factors, letters : tuple of str
    """

    goal: str
    coded: np.ndarray
    actual: np.ndarray
    predicted: float
    on_boundary: bool
    factors: tuple[str, ...]
    letters: tuple[str, ...]

    def to_dict(self) -> dict:
        return {"goal": self.goal, "coded": dict(zip(self.letters, self.coded.tolist())),
                "actual": dict(zip(self.factors, self.actual.tolist())),
                "predicted": self.predicted, "on_boundary": self.on_boundary}


def optimise(fit: ResponseSurface, goal: str = "maximise", *, n_starts: int = 32,
             seed=0) -> Optimum:
    """Maximise or minimise the fitted response inside the coded cube (multi-start L-BFGS-B)."""
    goals = ("maximise", "minimise")
    if goal not in goals:
        raise InputError(f"unknown goal {goal!r}; valid goals: {', '.join(goals)}")
    k = len(fit.factors)
    sign = -1.0 if goal == "maximise" else 1.0
    value, grad = _surface(fit)
    starts = [np.zeros(k)] + list(_rng(seed).uniform(-1.0, 1.0, size=(n_starts, k)))
    best = None
    for s in starts:
        r = optimize.minimize(lambda x: sign * value(x), s, jac=lambda x: sign * grad(x),
                              method="L-BFGS-B", bounds=[(-1.0, 1.0)] * k)
        if best is None or r.fun < best.fun:
            best = r
    x = np.clip(best.x, -1.0, 1.0)
    return Optimum(goal, x, fit.to_actual(x), float(fit.predict(x)),
                   bool(np.any(np.abs(x) > 1 - 1e-6)), fit.factors, fit.letters)


# --------------------------------------------------------------------------------------------
# Canonical analysis

@dataclass(frozen=True, eq=False)
class CanonicalAnalysis:
    """Canonical analysis of a second-order surface yhat = b0 + x'b + x'Bx.

    Attributes
    ----------
    eigenvalues : numpy.ndarray
        (k,) eigenvalues of B, largest first [response units].
    eigenvectors : numpy.ndarray
        (k, k) matching unit eigenvectors as columns (coded axes) [-].
    stationary_coded, stationary_actual : numpy.ndarray or None
        Stationary point x_s = -B^-1 b / 2 [-], [factor units]; None if B is singular.
    predicted : float or None
        Fitted response at the stationary point [response units].
    inside_region : bool
        Whether the stationary point lies in the coded cube [-1, 1]^k.
    verdict : str
        ``maximum`` (all eigenvalues negative), ``minimum`` (all positive) or ``saddle``
        (mixed signs).
    ridge : str or None
        ``stationary ridge`` / ``rising ridge`` when an eigenvalue is near zero
        (|lambda| < ridge_ratio max|lambda|) and the stationary point lies inside / outside
        the coded cube (Myers et al. 2009, 6.4); None otherwise.
    near_zero : tuple of int
        Indices of the near-zero eigenvalues.
    factors, letters : tuple of str
    """

    eigenvalues: np.ndarray
    eigenvectors: np.ndarray
    stationary_coded: np.ndarray | None
    stationary_actual: np.ndarray | None
    predicted: float | None
    inside_region: bool
    verdict: str
    ridge: str | None
    near_zero: tuple[int, ...]
    factors: tuple[str, ...]
    letters: tuple[str, ...]

    def to_dict(self) -> dict:
        sc, sa = self.stationary_coded, self.stationary_actual
        return {"eigenvalues": self.eigenvalues.tolist(),
                "eigenvectors": self.eigenvectors.tolist(),
                "stationary_coded": None if sc is None else dict(zip(self.letters, sc.tolist())),
                "stationary_actual": None if sa is None else dict(zip(self.factors, sa.tolist())),
                "predicted": self.predicted, "inside_region": self.inside_region,
                "verdict": self.verdict, "ridge": self.ridge, "near_zero": list(self.near_zero)}


def canonical_analysis(fit: ResponseSurface, ridge_ratio: float = 0.05) -> CanonicalAnalysis:
    """Stationary point, eigenvalues of B and the nature of the stationary point.

    Parameters
    ----------
    fit : ResponseSurface
        A fit with second-order terms.
    ridge_ratio : float
        Eigenvalues smaller in magnitude than ``ridge_ratio`` times the largest are treated as
        zero (a ridge). Myers et al. give no fixed threshold; 0.05 is a stated default.
    """
    _, b, B = fit.second_order()
    if not np.any(B):
        raise AnalysisError("the model has no second-order terms; canonical analysis needs a "
                            "second-order fit")
    lam, vec = np.linalg.eigh(B)
    order = np.argsort(-lam)
    lam, vec = lam[order], vec[:, order]
    big = float(np.max(np.abs(lam)))
    near = tuple(int(i) for i in np.flatnonzero(np.abs(lam) < ridge_ratio * big))
    xs = None
    if np.linalg.cond(B) < 1e12:
        xs = -0.5 * np.linalg.solve(B, b)
    inside = bool(xs is not None and np.all(np.abs(xs) <= 1.0))
    verdict = "maximum" if np.all(lam < 0) else "minimum" if np.all(lam > 0) else "saddle"
    ridge = None
    if near:
        ridge = "stationary ridge" if inside else "rising ridge"
    return CanonicalAnalysis(
        eigenvalues=lam, eigenvectors=vec, stationary_coded=xs,
        stationary_actual=None if xs is None else fit.to_actual(xs),
        predicted=None if xs is None else float(fit.predict(xs)), inside_region=inside,
        verdict=verdict, ridge=ridge, near_zero=near, factors=fit.factors, letters=fit.letters)


# --------------------------------------------------------------------------------------------
# Validation

@dataclass(frozen=True, eq=False)
class ValidationResult:
    """Repeated runs at the optimum against the target.

    Attributes
    ----------
    values : numpy.ndarray
        The repeats [response units].
    n : int
    mean, std : float
        Mean and sample standard deviation (ddof 1; NaN for one repeat) [response units].
    target : float
    relative_error_pct : float
        100 |mean - target| / |target| [%].
    ci95 : tuple of float
        95 % confidence interval of the mean, t-based, from ``noise_sd`` when given (the DEM's
        seed-to-seed noise measured with more runs) else from ``std`` [response units].
    target_in_ci : bool
        Whether the target lies inside ``ci95``: the runs cannot tell the mean from the target.
    """

    values: np.ndarray
    n: int
    mean: float
    std: float
    target: float
    relative_error_pct: float
    ci95: tuple = (float("nan"), float("nan"))
    target_in_ci: bool = False

    def to_dict(self) -> dict:
        return {"values": self.values.tolist(), "n": self.n, "mean": self.mean, "std": self.std,
                "target": self.target, "relative_error_pct": self.relative_error_pct,
                "ci95": list(self.ci95), "target_in_ci": self.target_in_ci}


def validate_repeats(values, target: float, *, noise_sd: float | None = None,
                     noise_df: int | None = None) -> ValidationResult:
    """Mean of repeated runs and its relative error to the target (the source paper's check),
    with a 95 % confidence interval of the mean.

    ``noise_sd`` (with its degrees of freedom ``noise_df``) is the seed-to-seed sd of one run
    measured elsewhere with more runs; without it the repeats' own sd is used (n - 1 df).
    """
    v = np.asarray(values, dtype=float).ravel()
    if v.size == 0 or not np.all(np.isfinite(v)):
        raise InputError("validation needs at least one finite repeat")
    if target == 0:
        raise InputError("target must be non-zero for a relative error")
    mean = float(v.mean())
    std = float(v.std(ddof=1)) if v.size > 1 else float("nan")
    sd, df = (noise_sd, noise_df) if noise_sd is not None else (std, v.size - 1)
    ci = (float("nan"), float("nan"))
    if df and df > 0 and math.isfinite(sd):
        half = float(stats.t.ppf(0.975, df)) * sd / math.sqrt(v.size)
        ci = (mean - half, mean + half)
    return ValidationResult(v, int(v.size), mean, std, float(target),
                            100.0 * abs(mean - target) / abs(target), ci,
                            bool(ci[0] <= target <= ci[1]))


def confirmation_interval(fit, coded_point, n_runs: int, alpha: float = 0.05) -> dict:
    """Design-Expert's confirmation check: the 100 (1 - alpha) % prediction interval of the mean
    of ``n_runs`` new runs at ``coded_point``,

        yhat(x0) -+ t_{1 - alpha/2, df_res} sqrt(MSE (1/n + x0' (X'X)^-1 x0)),

    the model's own variance at the point included (Montgomery, *Design and Analysis of
    Experiments*, 8th ed., Wiley 2013, section 10.6). Blocks are averaged out.

    Returns ``{"predicted", "pi95": [lo, hi], "se", "df", "leverage"}``.
    """
    from demcal.analyse.regression import term_columns

    if n_runs < 1:
        raise InputError(f"n_runs must be >= 1, got {n_runs}")
    x = term_columns(np.asarray(fit.coded, dtype=float), ((),) + tuple(fit.term_powers))
    x0 = term_columns(np.atleast_2d(np.asarray(coded_point, dtype=float)), ((),) + tuple(fit.term_powers))[0]
    lev = float(x0 @ np.linalg.pinv(x.T @ x) @ x0)
    df = int(fit.fit.df_residual)
    mse = float(fit.fit.std_dev) ** 2
    pred = float(fit.predict(np.asarray(coded_point, dtype=float)))
    if df < 1 or not math.isfinite(mse):
        return {"predicted": pred, "pi95": [math.nan, math.nan], "se": math.nan, "df": df, "leverage": lev}
    se = math.sqrt(mse * (1.0 / n_runs + lev))
    half = float(stats.t.ppf(1 - alpha / 2, df)) * se
    return {"predicted": pred, "pi95": [pred - half, pred + half], "se": se, "df": df, "leverage": lev}
