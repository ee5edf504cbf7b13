"""Designs of experiments in coded units: Plackett-Burman screening, Box-Behnken response surface,
and the coding between actual and coded levels.

Coded levels are -1 (low), 0 (centre) and +1 (high); ``to_coded`` / ``to_actual`` convert with
the centre ``(low + high) / 2`` and half-range ``(high - low) / 2`` of each factor, as
Design-Expert does.

References
----------
.. [1] Plackett, R. L. & Burman, J. P. (1946). The design of optimum multifactorial experiments.
   Biometrika 33(4), 305-325.
.. [2] Box, G. E. P. & Behnken, D. W. (1960). Some new three level designs for the study of
   quantitative variables. Technometrics 2(4), 455-475.
.. [3] Box, G. E. P., Hunter, J. S. & Hunter, W. G. (2005). Statistics for Experimenters,
   2nd ed. Wiley (the 12-run Plackett-Burman matrix as printed there).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from demcal.errors import InputError

#: Plackett & Burman's (1946) generators: the first column of the N-run design; the other
#: N - 2 columns are its cyclic shifts and a row of minuses closes the design. Every one is
#: checked by X'X = N I in the tests.
PB_GENERATORS = {
    8: (+1, +1, +1, -1, +1, -1, -1),
    12: (+1, +1, -1, +1, +1, +1, -1, -1, -1, +1, -1),
    16: (+1, +1, +1, +1, -1, +1, -1, +1, +1, -1, -1, +1, -1, -1, -1),
    20: (+1, +1, -1, -1, +1, +1, +1, +1, -1, +1, -1, +1, -1, -1, -1, -1, +1, +1, -1),
    24: (+1, +1, +1, +1, +1, -1, +1, -1, +1, +1, -1, -1, +1, +1, -1, -1, +1, -1, +1, -1,
         -1, -1, -1),
}

#: Factor letters: A, B, C, ... with I left out so it is not read as the intercept.
FACTOR_LETTERS = tuple(c for c in "ABCDEFGHJKLMNOPQRSTUVWXYZ")


def factor_letters(n: int) -> tuple[str, ...]:
    """The first ``n`` factor letters (A, B, C, ...; I is skipped)."""
    if not 0 < n <= len(FACTOR_LETTERS):
        raise InputError(f"number of factors must be 1..{len(FACTOR_LETTERS)}, got {n}")
    return FACTOR_LETTERS[:n]


@dataclass(frozen=True, eq=False)
class Design:
    """A design in coded units, rows in standard order.

    Attributes
    ----------
    kind : str
        ``"plackett-burman"`` or ``"box-behnken"``.
    coded : numpy.ndarray
        (n_runs, n_columns) coded levels [-]; the first ``n_factors`` columns are the factors,
        any further columns are dummy factors (unassigned Plackett-Burman columns, used to
        estimate error).
    columns : tuple of str
        Column labels: factor letters, then ``dummy_1``, ``dummy_2``, ...
    n_factors : int
        Number of real factors.
    centre_points : int
        Number of centre runs at the end of the design.
    """

    kind: str
    coded: np.ndarray
    columns: tuple[str, ...]
    n_factors: int
    centre_points: int = 0

    @property
    def factors(self) -> np.ndarray:
        """(n_runs, n_factors) coded levels of the real factors [-]."""
        return self.coded[:, :self.n_factors]

    @property
    def n_runs(self) -> int:
        return int(self.coded.shape[0])

    def to_dict(self) -> dict:
        return {"kind": self.kind, "columns": list(self.columns), "n_factors": self.n_factors,
                "centre_points": self.centre_points, "coded": self.coded.tolist()}


def plackett_burman(n_factors: int, runs: int = 12) -> Design:
    """Plackett-Burman two-level screening design (Plackett & Burman 1946).

    Column ``j`` of the first ``runs - 1`` rows is the generator shifted cyclically down by
    ``j`` rows; the last row is all minus. For 12 runs this is exactly the matrix printed in
    Box, Hunter & Hunter (2005) (BsMD ``PB12Des``). Factors take the first ``n_factors``
    columns; the remaining ``runs - 1 - n_factors`` columns are dummy factors whose effects
    estimate the error.

    Parameters
    ----------
    n_factors : int
        Number of real factors, 1 <= n_factors <= runs - 1.
    runs : int
        Number of runs; one of 8, 12, 16, 20, 24.

    Returns
    -------
    Design
        ``coded`` has shape (runs, runs - 1), all entries -1 or +1.
    """
    if runs not in PB_GENERATORS:
        raise InputError(f"Plackett-Burman runs must be one of {sorted(PB_GENERATORS)}, got {runs}")
    if not 1 <= n_factors <= runs - 1:
        raise InputError(f"a {runs}-run Plackett-Burman design takes 1..{runs - 1} factors, "
                         f"got n_factors={n_factors}")
    g = np.array(PB_GENERATORS[runs], dtype=float)
    m = runs - 1
    rows = np.arange(m)[:, None]
    cols = np.arange(m)[None, :]
    matrix = np.vstack([g[(rows - cols) % m], -np.ones((1, m))])
    letters = factor_letters(n_factors)
    columns = letters + tuple(f"dummy_{i + 1}" for i in range(m - n_factors))
    return Design("plackett-burman", matrix, columns, n_factors)


def box_behnken(n_factors: int = 3, centre_points: int = 5) -> Design:
    """Box-Behnken three-level response-surface design (Box & Behnken 1960), standard order.

    For every pair of factors (AB, AC, ..., BC, ...) the four runs (-1,-1), (+1,-1), (-1,+1),
    (+1,+1) with the other factors at 0, then ``centre_points`` runs at the centre. For three
    factors this is Design-Expert's standard order: 12 edge runs then the centres (17 runs
    with 5 centre points). The pairwise construction is Box & Behnken's design for 3, 4 and 5
    factors; 6 or more factors use other incomplete-block constructions and are refused.

    Parameters
    ----------
    n_factors : int
        3, 4 or 5.
    centre_points : int
        Number of centre runs (>= 0; at least 1 is needed for a full quadratic, and replicated
        centres give the pure error).
    """
    if n_factors not in (3, 4, 5):
        raise InputError(f"box_behnken supports 3, 4 or 5 factors, got n_factors={n_factors}")
    if centre_points < 0:
        raise InputError(f"centre_points must be >= 0, got {centre_points}")
    rows = []
    for i, j in itertools.combinations(range(n_factors), 2):
        for b, a in ((-1, -1), (-1, +1), (+1, -1), (+1, +1)):
            x = [0.0] * n_factors
            x[i], x[j] = float(a), float(b)
            rows.append(x)
    rows += [[0.0] * n_factors for _ in range(centre_points)]
    return Design("box-behnken", np.array(rows), factor_letters(n_factors), n_factors,
                  centre_points)


def _check_range(low, high):
    low = np.asarray(low, dtype=float)
    high = np.asarray(high, dtype=float)
    if low.shape != high.shape:
        raise InputError(f"low and high must have the same shape, got {low.shape} and {high.shape}")
    bad = ~(high > low)
    if np.any(bad):
        i = int(np.flatnonzero(np.atleast_1d(bad))[0])
        lo, hi = float(np.atleast_1d(low)[i]), float(np.atleast_1d(high)[i])
        raise InputError(f"each high level must exceed its low level; factor {i}: "
                         f"low={lo!r}, high={hi!r}")
    return low, high


def to_coded(actual, low, high) -> np.ndarray:
    """Code actual levels: x = (actual - (low + high)/2) / ((high - low)/2).

    Parameters
    ----------
    actual : array_like
        Actual levels, (..., k) [factor units].
    low, high : array_like
        (k,) actual levels coded -1 and +1 [factor units].

    Returns
    -------
    numpy.ndarray
        Coded levels [-], same shape as ``actual``.
    """
    low, high = _check_range(low, high)
    return (np.asarray(actual, dtype=float) - (low + high) / 2.0) / ((high - low) / 2.0)


def to_actual(coded, low, high) -> np.ndarray:
    """Inverse of :func:`to_coded`: actual = (low + high)/2 + x (high - low)/2 [factor units]."""
    low, high = _check_range(low, high)
    return (low + high) / 2.0 + np.asarray(coded, dtype=float) * (high - low) / 2.0


def run_order(n_runs: int, seed) -> np.ndarray:
    """A randomised run order (a permutation of 0..n_runs-1) from an explicit seed or Generator."""
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    return rng.permutation(int(n_runs))
