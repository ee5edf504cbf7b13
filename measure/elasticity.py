"""Elastic constants from the compression test: Poisson's ratio, elastic and shear modulus.

The source paper compresses each segment with a texture analyser (5 mm/s, to 30 %
deformation, in the thickness direction) and takes Poisson's ratio from the width and
thickness measured before and after loading, its equation (1):
nu = (L1 - L2) / (H2 - H1), absolute changes. docs/workbook.md normalises each change by its
original size, nu = (|w_after - w_before| / w_before) / (|t_before - t_after| / t_before),
which is the ratio of transverse to axial strain; that is the value used, and eq. (1) is
reported beside it.

The elastic modulus comes from the initial linear part of the force-displacement curve:
E = (dF/dd) t0 / A, nominal stress F / A over nominal strain d / t0 (t0 the thickness before
loading). Contact area A: for ``axial`` loading (along the segment's axis) the circular
cross-section pi w0^2 / 4, w0 = width before; for ``radial`` loading (across a diameter) the
projected area w0 L, L the segment length. Between flat platens a radially loaded cylinder
touches along a line, so the radial value is an apparent (nominal) modulus, as usual for
convex agricultural specimens [1]_. G = E / (2 (1 + nu)) for an isotropic solid.

References
----------
.. [1] Mohsenin, N. N. (1986). Physical Properties of Plant and Animal Materials, 2nd ed.
   Gordon and Breach, New York, ch. 4-6 (compression of intact specimens, apparent modulus).
.. [2] Timoshenko, S. P. & Goodier, J. N. (1970). Theory of Elasticity, 3rd ed. McGraw-Hill
   (G = E / (2 (1 + nu))).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace

import numpy as np

from demcal.errors import InputError, WorkbookError
from demcal.measure.estimate import mean_sd_ci95, summarise
from demcal.units import MM

POISSON_METHOD = ("nu = (|dw| / w0) / (|dt| / t0), normalised strains (docs/workbook.md); "
                  "source paper eq. (1) |dw| / |dt| in extra")
MODULUS_METHOD = ("E = (dF/dd) t0 / A over the initial window up to the yield point (line then "
                  "parabola, BIC), R^2 >= {r2:g} (nominal stress F/A, strain d/t0; Mohsenin 1986)")


def poisson_ratio(width_before, width_after, thickness_before, thickness_after):
    """Poisson's ratio from normalised strains, (|w1 - w0| / w0) / (|t0 - t1| / t0) (docs/workbook.md).

    Parameters
    ----------
    width_before, width_after : array_like
        Width across the load before and after loading [m].
    thickness_before, thickness_after : array_like
        Thickness along the load before and after loading [m].

    Returns
    -------
    numpy.ndarray
        Poisson's ratio [1].
    """
    w0, w1, t0, t1 = (np.asarray(a, dtype=float) for a in
                      (width_before, width_after, thickness_before, thickness_after))
    if not (np.all(w0 > 0) and np.all(t0 > 0)):
        raise InputError("width_before and thickness_before must be positive")
    if np.any(t1 == t0):
        raise InputError("thickness_after equals thickness_before: no axial strain")
    return (np.abs(w1 - w0) / w0) / (np.abs(t0 - t1) / t0)


def poisson_ratio_eq1(width_before, width_after, thickness_before, thickness_after):
    """Poisson's ratio as the source paper's equation (1), |L1 - L2| / |H2 - H1| (absolute changes).

    Parameters are those of :func:`poisson_ratio` [m]; returns [1]. Equal to the normalised
    ratio only when width and thickness are equal before loading.
    """
    w0, w1, t0, t1 = (np.asarray(a, dtype=float) for a in
                      (width_before, width_after, thickness_before, thickness_after))
    if np.any(t1 == t0):
        raise InputError("thickness_after equals thickness_before: no axial strain")
    return np.abs(w0 - w1) / np.abs(t1 - t0)


@dataclass(frozen=True)
class LinearRegion:
    """Straight line through the initial part of a loading curve.

    Attributes
    ----------
    slope, slope_se : float
        Stiffness dF/dd and its standard error [N/m].
    intercept : float
        Force at zero displacement of the line [N].
    r2 : float
        Coefficient of determination of the window.
    start, stop : int
        Sample index range [start, stop) of the window.
    """

    slope: float
    slope_se: float
    intercept: float
    r2: float
    start: int
    stop: int

    def to_dict(self) -> dict:
        return asdict(self)


def _line_sums(x, y):
    """Cumulative least-squares sums of the windows x[:m], y[:m], m = 1 .. n."""
    m = np.arange(1, x.size + 1, dtype=float)
    sx, sy = np.cumsum(x), np.cumsum(y)
    sxx = np.cumsum(x * x) - sx * sx / m
    syy = np.cumsum(y * y) - sy * sy / m
    sxy = np.cumsum(x * y) - sx * sy / m
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = np.where(sxx > 0, sxy / sxx, 0.0)
    rss = np.maximum(syy - slope * sxy, 0.0)
    return m, sx, sy, sxx, syy, sxy, slope, rss


def _suffix_parabolas(x, y):
    """Residual sum of squares and starting slope of the least-squares parabola through each
    suffix x[i:], y[i:] (NaN where fewer than 6 samples remain)."""
    u = (x - x[0]) / (x[-1] - x[0])             # scaled for the normal equations
    pw = np.stack([u ** k for k in range(5)])
    su = np.cumsum(pw[:, ::-1], axis=1)[:, ::-1]            # suffix sums of u^0 .. u^4
    suy = np.cumsum((pw[:3] * y)[:, ::-1], axis=1)[:, ::-1]
    syy = np.cumsum((y * y)[::-1])[::-1]
    A = np.stack([su[i: i + 3] for i in range(3)]).transpose(2, 0, 1)
    b = suy.T
    n = x.size
    ok = np.arange(n) <= n - 6
    coef = np.full((n, 3), np.nan)
    coef[ok] = np.linalg.solve(A[ok], b[ok][..., None])[..., 0]
    rss = np.maximum(syy - np.einsum("ij,ij->i", coef, b), 0.0)
    slope = (coef[:, 1] + 2 * coef[:, 2] * u) / (x[-1] - x[0])
    return np.where(ok, rss, np.nan), slope


def initial_linear_region(displacement, force, *, r2_min=0.995, min_points=5,
                          trigger=0.01) -> LinearRegion:
    """The straight initial part of a loading curve, ending where the specimen starts to yield.

    Only the loading branch (from the trigger force to the peak force) is used; the window
    starts at the first sample whose force reaches ``trigger`` times the peak force, as a
    texture analyser's trigger force ignores the approach. The yield point is the breakpoint
    of a piecewise least-squares fit of the branch, a line before it and a parabola after it
    (the yielding tissue softens gradually): the split that minimises the summed residuals,
    among splits after which the curve starts softer. The split is kept only if the Bayesian
    information criterion prefers the two pieces (6 parameters, the breakpoint counted) to one
    line over the whole branch; otherwise the whole branch is the window.

    A longest-window rule (extend while R^2 >= r2_min) reads a curve that softens after its
    linear part low: the large range of a long window tolerates the bend, and the window runs
    past the yield point. Here ``r2_min`` only guards against a window that is not straight.

    Parameters
    ----------
    displacement : array_like
        Platen displacement [m].
    force : array_like
        Force [N].
    r2_min : float
        Least coefficient of determination accepted for the window.
    min_points : int
        Fewest samples in the window (the parabola after a breakpoint takes at least 6).
    trigger : float
        Start threshold as a fraction of the peak force.

    Returns
    -------
    LinearRegion

    References
    ----------
    Schwarz, G. (1978). Estimating the dimension of a model. Ann. Stat. 6, 461-464 (BIC).
    """
    x = np.asarray(displacement, dtype=float)
    F = np.asarray(force, dtype=float)
    if x.ndim != 1 or x.shape != F.shape:
        raise InputError("displacement and force must be 1-D arrays of equal length")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(F))):
        raise InputError("the curve holds non-finite values")
    if not 0 < r2_min < 1:
        raise InputError(f"r2_min must lie in (0, 1), got {r2_min!r}")
    peak = int(np.argmax(F))
    if not F[peak] > 0:
        raise InputError("the curve has no positive force")
    start = int(np.argmax(F[: peak + 1] >= trigger * F[peak]))
    xs, ys = x[start: peak + 1], F[start: peak + 1]
    n_all = xs.size
    if n_all < min_points:
        raise InputError(f"only {n_all} samples between the trigger force and the peak "
                         f"(need {min_points})")
    m, sx, sy, sxx, syy, sxy, slope, rss = _line_sums(xs, ys)
    n = n_all
    if n_all >= min_points + 6:
        # split after sample j: a line through [0, j], a parabola through [j + 1, end]
        j = np.arange(min_points - 1, n_all - 6)
        q_rss, q_slope = _suffix_parabolas(xs, ys)
        after = j + 1
        softer = q_slope[after] < slope[j]
        if np.any(softer):
            split_rss = rss[j] + q_rss[after]
            best = int(j[softer][int(np.argmin(split_rss[softer]))])
            floor = 1e-12 * max(syy[-1], 1e-300)    # an exact line would make log(0)
            bic_one = n_all * math.log(max(rss[-1], floor) / n_all) + 2 * math.log(n_all)
            bic_two = (n_all * math.log(max(rss[best] + q_rss[best + 1], floor) / n_all)
                       + 6 * math.log(n_all))
            if bic_two < bic_one:
                n = best + 1
    k = n - 1
    r2 = sxy[k] * sxy[k] / (sxx[k] * syy[k]) if sxx[k] > 0 and syy[k] > 0 else 0.0
    if not (r2 >= r2_min and sxy[k] > 0):
        raise InputError(f"the initial window of {n} samples is not linear: R^2 = {r2:.4f} "
                         f"< {r2_min:g}")
    intercept = (sy[k] - slope[k] * sx[k]) / n
    se = math.sqrt(rss[k] / (n - 2) / sxx[k]) if n > 2 else math.nan
    return LinearRegion(slope=float(slope[k]), slope_se=se, intercept=float(intercept),
                        r2=float(r2), start=start, stop=start + n)


def contact_area(axis: str, width, length=None):
    """Nominal loaded area of a cylindrical segment [m^2].

    ``axial``: pi w^2 / 4 (circular cross-section); ``radial``: w L (projected area).

    Parameters
    ----------
    axis : {"axial", "radial"}
        Loading direction relative to the segment's axis.
    width : float
        Width (diameter) before loading [m].
    length : float, optional
        Segment length [m]; needed for ``radial``.
    """
    if axis == "axial":
        return math.pi * width * width / 4.0
    if axis == "radial":
        if length is None or not length > 0:
            raise InputError("radial loading needs the segment length")
        return width * length
    raise InputError(f"unknown axis {axis!r}; valid: radial, axial")


def elastic_modulus(stiffness, thickness, area):
    """Elastic modulus from the initial stiffness, E = k t0 / A [1]_.

    Parameters
    ----------
    stiffness : array_like
        Initial slope dF/dd of the loading curve [N/m].
    thickness : array_like
        Specimen thickness along the load before loading [m].
    area : array_like
        Nominal loaded area [m^2].

    Returns
    -------
    numpy.ndarray
        Elastic modulus [Pa].
    """
    return np.asarray(stiffness, dtype=float) * np.asarray(thickness, dtype=float) / np.asarray(area, dtype=float)


def shear_modulus(E, nu):
    """Shear modulus of an isotropic solid, G = E / (2 (1 + nu)) [2]_.

    Parameters
    ----------
    E : array_like
        Elastic modulus [Pa].
    nu : array_like
        Poisson's ratio [1], > -1.

    Returns
    -------
    numpy.ndarray
        Shear modulus [Pa].
    """
    nu = np.asarray(nu, dtype=float)
    if np.any(nu <= -1):
        raise InputError("Poisson's ratio must exceed -1")
    return np.asarray(E, dtype=float) / (2.0 * (1.0 + nu))


def _segment_length(workbook, sheet, row) -> float:
    """Length [m] of the compressed segment: the compression row's ``length_mm``, else its specimen's."""
    f = sheet.frame
    if "length_mm" in f and not math.isnan(f.at[row, "length_mm"]):
        return f.at[row, "length_mm"] * MM
    specimen = f.at[row, "specimen_id"]
    specimens = workbook.sheet("specimens")
    matches = [] if specimens is None else [
        r for r, name in specimens.column("specimen_id").items() if name == specimen]
    if len(matches) != 1 or "length_mm" not in specimens.frame:
        found = ("no length_mm in the specimens sheet" if matches and len(matches) == 1 else
                 f"{'no' if not matches else len(matches)} specimens rows with this specimen_id")
        raise sheet.error(f"radial loading needs the segment length: add length_mm to this row "
                          f"({found})", row=row, column="specimen_id", value=specimen)
    return specimens.frame.at[matches[0], "length_mm"] * MM


def compression_estimates(workbook, *, outliers="none", r2_min=0.995, min_points=5,
                          trigger=0.01) -> dict:
    """``poisson_ratio``, ``elastic_modulus_pa`` and ``shear_modulus_pa`` from the ``compression`` sheet.

    Every row gives a Poisson's ratio; rows with a ``curve_file`` give an elastic modulus. The
    shear modulus of each such row is E / (2 (1 + nu)) with nu the ``poisson_ratio`` estimate
    (the per-specimen ratio is too noisy to pair with each curve).
    """
    sheet = workbook.sheet("compression")
    if sheet is None or not sheet.rows:
        return {}
    f = sheet.frame
    rows = sheet.rows
    w0, w1, t0, t1 = (f[c].to_numpy(float) * MM for c in
                      ("width_before_mm", "width_after_mm", "thickness_before_mm", "thickness_after_mm"))
    nu = poisson_ratio(w0, w1, t0, t1)
    nu1 = poisson_ratio_eq1(w0, w1, t0, t1)
    records = [{"id": f.at[r, "specimen_id"], "axis": f.at[r, "axis"], "poisson_eq1": float(nu1[i]),
                "covariates": sheet.covariates_of(r)} for i, r in enumerate(rows)]
    est = summarise("poisson_ratio", nu, rows, unit="1", source=sheet.source(), method=POISSON_METHOD,
                    outliers=outliers, per_row=records)
    used = [i for i, r in enumerate(rows) if r in set(est.rows_used)]
    m1, sd1, ci1 = mean_sd_ci95(nu1[used])
    est = replace(est, extra=dict(est.extra, used="normalised strains (docs/workbook.md)",
                                  eq1={"value": m1, "sd": sd1, "ci95": list(ci1), "n": len(used),
                                       "formula": "|w_before - w_after| / |t_after - t_before| "
                                                  "(source paper eq. 1)"}))
    out = {"poisson_ratio": est}

    curve_rows = [r for r in rows if "curve_file" in f and f.at[r, "curve_file"] is not None]
    if not curve_rows:
        return out
    values, records = [], []
    for r in curve_rows:
        rel = f.at[r, "curve_file"]
        table = workbook.attachment(rel)
        axis = f.at[r, "axis"]
        width = f.at[r, "width_before_mm"] * MM
        thickness = f.at[r, "thickness_before_mm"] * MM
        length = _segment_length(workbook, sheet, r) if axis == "radial" else None
        area = contact_area(axis, width, length)
        try:
            region = initial_linear_region(table["displacement_mm"].to_numpy() * MM,
                                           table["force_N"].to_numpy(), r2_min=r2_min,
                                           min_points=min_points, trigger=trigger)
        except InputError as exc:
            raise WorkbookError(f"curve {workbook.resolve(rel)}: {exc}", file=str(sheet.file),
                                sheet=sheet.name, row=r, column="curve_file", value=rel) from None
        E = float(elastic_modulus(region.slope, thickness, area))
        values.append(E)
        records.append({"id": f.at[r, "specimen_id"], "axis": axis, "curve_file": rel,
                        "area_m2": area, "thickness_m": thickness, "length_m": length,
                        "E_se_pa": region.slope_se * thickness / area, "linear_region": region.to_dict(),
                        "covariates": sheet.covariates_of(r)})
    extra = {"area": "axial: pi w0^2 / 4; radial: w0 L (L from the row's length_mm, else its specimen)",
             "strain": "displacement / thickness_before", "r2_min": r2_min, "trigger": trigger,
             "axes": sorted({rec["axis"] for rec in records})}
    E_est = summarise("elastic_modulus_pa", values, curve_rows, unit="Pa", source=sheet.source(),
                      method=MODULUS_METHOD.format(r2=r2_min), outliers=outliers, extra=extra,
                      per_row=records)
    out["elastic_modulus_pa"] = E_est
    if E_est.n and math.isfinite(est.value) and est.value > -1:
        used_E = [rec for rec in E_est.per_row if rec["used"]]
        G = shear_modulus([rec["value"] for rec in used_E], est.value)
        g_records = [{"id": rec["id"], "axis": rec["axis"], "elastic_modulus_pa": rec["value"],
                      "covariates": rec["covariates"]} for rec in used_E]
        out["shear_modulus_pa"] = summarise(
            "shear_modulus_pa", G, [rec["row"] for rec in used_E], unit="Pa", source=sheet.source(),
            method="G = E / (2 (1 + nu)), isotropic elasticity, nu = poisson_ratio estimate",
            outliers="none", extra={"poisson_ratio": est.value}, rejected=E_est.rows_rejected,
            per_row=g_records)
    return out
