"""Coefficient of restitution from free-fall drop tests: rebound heights and camera tracks.

Three published ways to turn a drop log into a restitution coefficient e:

- :func:`from_rebound_heights`: energy of free flight, e = |v2| / |v1| = sqrt(h2 / h1), one
  value per drop (source paper, eqs. (2)-(4), after Dai et al. 2021).
- :func:`from_height_regression`: e = sqrt(B), B the slope of the first-rebound height
  against the release height over several release heights, which absorbs a constant offset
  of the height readings (the intercept), as in drop-test lab logs such as [2]_.
- :func:`from_camera_track`: velocities just before and after impact from the free-flight
  parabolas fitted to a high-speed-camera track, e = -v_after / v_before (Newton's definition
  of e as the ratio of normal separation to approach velocity [3]_).

References
----------
.. [1] Dai, N., Hou, Z., Qiu, Y., et al. (2021). Calibration and testing of discrete element
   simulation parameters for red clover seeds. Journal of Hebei Agricultural University
   44(06), 92-98 (as cited by the source paper for eq. (4)).
.. [2] giiulia/LabI-Dynamics-Thermodynamics, Coefficient_of_restitution report (Method 1:
   weighted linear fit h1 = B h0 + A of the per-height mean rebound heights, e = sqrt(B)).
.. [3] Goldsmith, W. (1960). Impact: The Theory and Physical Behaviour of Colliding Solids.
   Edward Arnold, London (coefficient of restitution as a velocity ratio).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace

import numpy as np

from demcal.errors import InputError, WorkbookError
from demcal.measure.estimate import summarise
from demcal.units import GRAVITY, MM



def from_rebound_heights(drop_height, rebound_height):
    """Restitution of each drop from its heights, e = sqrt(h2 / h1) (source paper eq. (4) [1]_).

    Parameters
    ----------
    drop_height : array_like
        Release height h1 above the impact point [m], > 0.
    rebound_height : array_like
        Apex height h2 of the first rebound [m], 0 <= h2 <= h1.

    Returns
    -------
    numpy.ndarray
        Restitution coefficient [1].
    """
    h1 = np.asarray(drop_height, dtype=float)
    h2 = np.asarray(rebound_height, dtype=float)
    if h1.shape != h2.shape:
        raise InputError("drop_height and rebound_height must have the same shape")
    if not np.all(h1 > 0):
        raise InputError("drop_height must be positive")
    if not np.all((h2 >= 0) & (h2 <= h1)):
        raise InputError("rebound_height must lie between 0 and drop_height")
    return np.sqrt(h2 / h1)


@dataclass(frozen=True)
class HeightRegression:
    """Straight line of rebound height on release height, h2 = A + B h1.

    Attributes
    ----------
    e : float
        Restitution sqrt(B) [1].
    e_se : float
        Standard error of e, delta method se(B) / (2 sqrt(B)) [1].
    slope, slope_se : float
        B and its standard error [1].
    intercept, intercept_se : float
        A and its standard error [m].
    n : int
        Number of drops.
    r2 : float
        Coefficient of determination (of the points fitted).
    weighting : str
        ``"ols"`` or ``"inverse_variance"``.
    chi2_dof : float
        Weighted residual sum of squares per degree of freedom (``inverse_variance`` only;
        well above 1 means the line does not fit within the scatter, e.g. air drag); NaN for OLS.
    """

    e: float
    e_se: float
    slope: float
    slope_se: float
    intercept: float
    intercept_se: float
    n: int
    r2: float
    weighting: str = "ols"
    chi2_dof: float = math.nan

    def to_dict(self) -> dict:
        return asdict(self)


def from_height_regression(drop_height, rebound_height, *, weighting="ols") -> HeightRegression:
    """Restitution from the slope of rebound height against release height, e = sqrt(B) [2]_.

    Parameters
    ----------
    drop_height : array_like
        Release heights h1 [m]; at least two distinct values.
    rebound_height : array_like
        First-rebound heights h2 [m].
    weighting : {"ols", "inverse_variance"}
        ``ols``: ordinary least squares over every drop (with the same number of drops per
        release height this equals the fit to the per-height means); standard errors from
        the residual scatter. ``inverse_variance``: the per-height mean rebound heights,
        weighted by n_i / s_i^2 (inverse variance of each mean, s_i the sample sd of the
        drops from that height), standard errors from (X' W X)^-1 without rescaling, as in
        the lab report [2]_; every release height needs at least 2 drops that differ.

    Returns
    -------
    HeightRegression
    """
    x = np.asarray(drop_height, dtype=float)
    y = np.asarray(rebound_height, dtype=float)
    if x.shape != y.shape or x.ndim != 1:
        raise InputError("drop_height and rebound_height must be 1-D arrays of equal length")
    if x.size < 3 or np.unique(x).size < 2:
        raise InputError("the height regression needs at least 3 drops from at least 2 release heights")
    if weighting == "ols":
        xf, yf, w = x, y, np.ones_like(x)
    elif weighting == "inverse_variance":
        heights = np.unique(x)
        if heights.size < 3:
            raise InputError("the weighted height regression needs at least 3 release heights")
        groups = [y[x == h] for h in heights]
        sds = np.array([g.std(ddof=1) if g.size > 1 else 0.0 for g in groups])
        if np.any(sds == 0):
            raise InputError("inverse-variance weighting needs at least 2 differing drops per release height")
        xf, yf = heights, np.array([g.mean() for g in groups])
        w = np.array([g.size for g in groups]) / sds**2
    else:
        raise InputError(f"unknown weighting {weighting!r}; valid: ols, inverse_variance")
    X = np.column_stack([np.ones_like(xf), xf])
    XtWX = X.T @ (w[:, None] * X)
    (intercept, slope) = np.linalg.solve(XtWX, X.T @ (w * yf))
    resid = yf - intercept - slope * xf
    dof = xf.size - 2
    wrss = float(np.sum(w * resid**2))
    if weighting == "ols":
        cov = wrss / dof * np.linalg.inv(XtWX)
        chi2_dof = math.nan
    else:
        cov = np.linalg.inv(XtWX)
        chi2_dof = wrss / dof
    ybar = np.sum(w * yf) / np.sum(w)
    syy = float(np.sum(w * (yf - ybar) ** 2))
    r2 = 1.0 - wrss / syy if syy > 0 else math.nan
    if slope <= 0:
        raise InputError(f"rebound height does not grow with drop height (slope {slope:.4g})")
    e = math.sqrt(slope)
    slope_se = math.sqrt(cov[1, 1])
    return HeightRegression(e=e, e_se=slope_se / (2.0 * e), slope=float(slope), slope_se=slope_se,
                            intercept=float(intercept), intercept_se=math.sqrt(cov[0, 0]),
                            n=int(x.size), r2=r2, weighting=weighting, chi2_dof=chi2_dof)


@dataclass(frozen=True)
class TrackFit:
    """Free-flight fit of a camera track around its first impact.

    Attributes
    ----------
    e : float
        Restitution -v_after / v_before [1].
    e_se : float
        Standard error of e from the fit covariances (delta method) [1].
    t_impact : float
        Impact time [s].
    v_before, v_after : float
        Vertical velocity just before (< 0) and after (> 0) impact [m/s].
    pre, post : tuple of int
        Sample index ranges [start, stop) of the two free-flight segments fitted.
    residual_sd : float
        Pooled residual standard deviation of the two fits [m].
    impact_time_method : str
        ``"intersection"`` of the two parabolas, or ``"lowest sample"`` when they do not meet
        inside the contact interval.
    contact_band : float
        Height above the lowest sample within which samples count as contact [m].
    """

    e: float
    e_se: float
    t_impact: float
    v_before: float
    v_after: float
    pre: tuple
    post: tuple
    residual_sd: float
    impact_time_method: str
    contact_band: float

    def to_dict(self) -> dict:
        return asdict(self)


def _runs(mask: np.ndarray, max_gap: int = 2) -> list[tuple[int, int]]:
    """Runs [start, stop) of True in ``mask``, merging runs separated by <= max_gap samples."""
    idx = np.flatnonzero(mask)
    if idx.size == 0:
        return []
    runs = []
    start = prev = int(idx[0])
    for i in idx[1:]:
        i = int(i)
        if i - prev > max_gap + 1:
            runs.append((start, prev + 1))
            start = i
        prev = i
    runs.append((start, prev + 1))
    return runs


def _flight_fit(t, y, g):
    """Least squares of y + g t^2 / 2 = a + b t; returns (a, b), covariance, residual sum, n."""
    z = y + 0.5 * g * t * t
    X = np.column_stack([np.ones_like(t), t])
    coef, *_ = np.linalg.lstsq(X, z, rcond=None)
    resid = z - X @ coef
    rss = float(resid @ resid)
    dof = t.size - 2
    s2 = rss / dof if dof > 0 else math.nan
    cov = s2 * np.linalg.inv(X.T @ X)
    return coef, cov, rss, t.size


def from_camera_track(t, y, *, g=GRAVITY, contact_band=None, min_points=4) -> TrackFit:
    """Restitution of the first impact of a high-speed-camera track [3]_.

    The track holds the height of the particle's tracked point from release, through the
    first impact, into the first rebound (later samples are allowed). Method:

    1. Contact samples are those within ``contact_band`` of the lowest sample; the first run
       of them (gaps of up to 2 samples merged) is the first impact, the next run (if any)
       the second.
    2. Free flight y = a + b t - g t^2 / 2 (known g, so each fit is linear in a and b) is
       fitted to the samples before the first contact run, and to the samples between the
       two contact runs. A still phase before release is left out: the first fit starts at
       the first sample more than ``contact_band`` below the highest one.
    3. The impact time is where the two parabolas meet, t* = (a2 - a1) / (b1 - b2), if that
       lies within one sample of the contact run; else the time of the lowest contact sample.
    4. v_before = b1 - g t*, v_after = b2 - g t*, e = -v_after / v_before; its standard error
       follows from the two fits' covariances by the delta method.

    Parameters
    ----------
    t : array_like
        Sample times [s], strictly increasing.
    y : array_like
        Height of the tracked point [m] (any origin, upward positive).
    g : float
        Gravitational acceleration [m/s^2].
    contact_band : float, optional
        Contact band [m]. Default: the larger of 5 noise sd (from second differences) and
        1 % of the track's height range.
    min_points : int
        Fewest samples in each free-flight segment.

    Returns
    -------
    TrackFit
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    if t.ndim != 1 or t.shape != y.shape:
        raise InputError("t and y must be 1-D arrays of equal length")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(y))):
        raise InputError("the track holds non-finite values")
    if t.size < 2 * min_points + 1:
        raise InputError(f"the track has {t.size} samples; at least {2 * min_points + 1} are needed")
    if not np.all(np.diff(t) > 0):
        raise InputError("track times must be strictly increasing")
    if not g > 0:
        raise InputError(f"g must be positive, got {g!r}")

    span = float(y.max() - y.min())
    if contact_band is None:
        d2 = np.diff(y, 2)
        noise = 1.4826 * float(np.median(np.abs(d2 - np.median(d2)))) / math.sqrt(6.0)
        contact_band = max(5.0 * noise, 0.01 * span)
    runs = _runs(y <= y.min() + contact_band)
    c0, c1 = runs[0]
    end = runs[1][0] if len(runs) > 1 else t.size
    start = 0
    if c0 > 0:
        # leave out a still phase before release: start where the fall has clearly begun
        top = int(np.argmax(y[:c0]))
        falling = np.flatnonzero(y[top:c0] < y[top] - contact_band)
        start = top + int(falling[0]) if falling.size else c0
    if c0 - start < min_points:
        raise InputError(f"only {c0 - start} free-fall samples before the first impact "
                         f"(need {min_points})")
    if end - c1 < min_points:
        raise InputError(f"only {end - c1} free-flight samples after the first impact "
                         f"(need {min_points}); no rebound found")

    t_ref = t[c0]  # centre the time axis on the impact for a well-conditioned fit
    tc = t - t_ref
    (a1, b1), cov1, rss1, n1 = _flight_fit(tc[start:c0], y[start:c0], g)
    (a2, b2), cov2, rss2, n2 = _flight_fit(tc[c1:end], y[c1:end], g)
    dof = n1 + n2 - 4
    residual_sd = math.sqrt((rss1 + rss2) / dof) if dof > 0 else math.nan

    D = b1 - b2
    ts = (a2 - a1) / D if D < 0 else math.nan
    lo = tc[c0 - 1] - (tc[c0] - tc[c0 - 1])
    hi = tc[c1] + (tc[c1] - tc[c1 - 1]) if c1 < t.size else tc[-1]
    if math.isfinite(ts) and lo <= ts <= hi:
        method = "intersection"
        # d t* / d(a1, b1, a2, b2)
        dts = np.array([-1.0 / D, -ts / D, 1.0 / D, ts / D])
    else:
        method = "lowest sample"
        ts = float(tc[c0 + int(np.argmin(y[c0:c1]))])
        dts = np.zeros(4)
    v1 = b1 - g * ts
    v2 = b2 - g * ts
    if not (v1 < 0 < v2):
        raise InputError(f"no rebound found: velocity before impact {v1:.4g} m/s, after {v2:.4g} m/s")
    e = -v2 / v1
    dv1 = np.array([0.0, 1.0, 0.0, 0.0]) - g * dts
    dv2 = np.array([0.0, 0.0, 0.0, 1.0]) - g * dts
    de = -(dv2 * v1 - v2 * dv1) / v1**2
    cov = np.zeros((4, 4))
    cov[:2, :2] = cov1
    cov[2:, 2:] = cov2
    var = float(de @ cov @ de)
    return TrackFit(e=float(e), e_se=math.sqrt(var) if var >= 0 else math.nan,
                    t_impact=float(ts + t_ref), v_before=float(v1), v_after=float(v2),
                    pre=(start, c0), post=(c1, end), residual_sd=residual_sd,
                    impact_time_method=method, contact_band=float(contact_band))


def restitution_estimates(workbook, *, outliers="none", g=GRAVITY) -> dict:
    """``restitution.<pair>`` for every pair of the ``drop`` sheet.

    Each drop gives one e: from its camera track when the row has a ``track_file``
    (:func:`from_camera_track`), otherwise from its heights (:func:`from_rebound_heights`).
    The estimate is the mean over drops. When at least 3 height-based drops used come from at
    least 2 release heights, ``extra["height_regression"]`` gives e = sqrt(slope) too.
    """
    sheet = workbook.sheet("drop")
    if sheet is None or not sheet.rows:
        return {}
    f = sheet.frame
    out = {}
    pair_of, trial_id = sheet.column("pair"), sheet.column("trial_id")
    drop_mm, rebound_mm = sheet.column("drop_height_mm"), sheet.column("rebound_height_mm")
    for pair in sorted(set(f["pair"])):
        rows = [r for r in sheet.rows if pair_of[r] == pair]
        values, records = [], []
        for r in rows:
            h1 = drop_mm[r] * MM
            h2 = rebound_mm[r] * MM
            rec = {"id": trial_id[r], "pair": pair,
                   "drop_height_m": None if math.isnan(h1) else h1,
                   "rebound_height_m": None if math.isnan(h2) else h2}
            e_heights = (float(from_rebound_heights(h1, h2))
                         if not (math.isnan(h1) or math.isnan(h2)) else None)
            track = sheet.column("track_file")[r] if "track_file" in f else None
            if track is not None:
                table = workbook.attachment(track)
                try:
                    fit = from_camera_track(table["t_s"].to_numpy(), table["y_mm"].to_numpy() * MM, g=g)
                except InputError as exc:
                    raise WorkbookError(f"track {workbook.resolve(track)}: {exc}", file=str(sheet.file),
                                        sheet=sheet.name, row=r, column="track_file", value=track) from None
                rec.update(method="track", track_file=track, e_heights=e_heights, track=fit.to_dict())
                values.append(fit.e)
            else:
                rec.update(method="heights")
                values.append(e_heights)
            rec["covariates"] = sheet.covariates_of(r)
            records.append(rec)
        n_track = sum(rec["method"] == "track" for rec in records)
        extra = {"n_from_track": n_track, "n_from_heights": len(records) - n_track,
                 "note": ("rows with a track_file use the camera track (velocities), "
                          "not their heights") if n_track else None}
        est = summarise(f"restitution.{pair}", values, rows, unit="1", source=sheet.source(),
                        method=("per-drop e = sqrt(h2/h1) (source paper eq. 4; Dai et al. 2021)"
                                + ("; e = -v_after/v_before from free-flight fits of camera tracks"
                                   if n_track else "")),
                        outliers=outliers, extra=extra, per_row=records)
        used = [rec for rec in est.per_row if rec["used"] and rec["method"] == "heights"]
        h1 = [rec["drop_height_m"] for rec in used]
        if len(used) >= 3 and len(set(h1)) >= 2:
            rows_used = [rec["row"] for rec in used]
            try:
                reg = from_height_regression(h1, [rec["rebound_height_m"] for rec in used])
                regression = dict(reg.to_dict(), rows=rows_used,
                                  method="e = sqrt(slope of h2 on h1), ordinary least squares")
            except InputError as exc:
                # a cross-check beside the per-drop values, never a reason to refuse them
                regression = {"rows": rows_used, "unavailable": str(exc)}
            est = replace(est, extra=dict(est.extra, height_regression=regression))
        out[est.name] = est
    return out
