"""Static and rolling friction from inclined-plane tests.

Tilting plane (the source paper's CNY-1 inclinometer, after Zhang et al. 2018): a particle on
a plate of the tested surface is tilted slowly; at the angle theta where it starts to slide,
the weight's components balance the largest friction force, so mu_s = tan(theta). The same
reading at the onset of rolling gives the rolling friction coefficient mu_r = tan(theta)
used by the source paper. A tilt board read by height instead of angle gives
sin(theta) = h / L (:func:`from_tilt_height`).

Roll-out (:func:`rolling_from_rollout`): the particle is released at height H on a slope of
angle theta, rolls down it and on along a flat plate of the same surface until it stops after
a run-out S. With a constant rolling resistance mu_r N, the energy balance
m g H = mu_r m g cos(theta) H / sin(theta) + mu_r m g S gives
mu_r = H sin(theta) / (H cos(theta) + S sin(theta)).

References
----------
.. [1] Zhang, T., Liu, F., Zhao, M., et al. (2018). Determination of physical parameters of
   corn stover contact and calibration by discrete element simulation. Journal of China
   Agricultural University 23(4), 120-127 (as cited by the source paper).
.. [2] Mohsenin, N. N. (1986). Physical Properties of Plant and Animal Materials, 2nd ed.
   Gordon and Breach, New York (friction on an inclined plane, mu = tan(theta)).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from demcal.errors import InputError
from demcal.measure.estimate import summarise
from demcal.units import MM

TILT_METHOD = "tilting plane, mu = tan(angle at onset) (source paper; Zhang et al. 2018)"
ROLLOUT_METHOD = "roll-out energy balance, mu_r = H sin(theta) / (H cos(theta) + S sin(theta))"


def _angles(angle, name):
    a = np.asarray(angle, dtype=float)
    if not np.all((a > 0) & (a < math.pi / 2)):
        raise InputError(f"{name} must lie strictly between 0 and pi/2 rad")
    return a


def from_tilt_angle(angle):
    """Friction coefficient from the tilt angle at onset of sliding or rolling, mu = tan(theta) [1]_ [2]_.

    Parameters
    ----------
    angle : array_like
        Plate angle at onset [rad], in (0, pi/2).

    Returns
    -------
    numpy.ndarray
        Friction coefficient [1].
    """
    return np.tan(_angles(angle, "angle"))


def from_tilt_height(height, board_length):
    """Friction coefficient from a tilt board read by height: sin(theta) = h / L, mu = tan(theta).

    Note that mu = h / L (the sine, not the tangent) understates mu, more so the steeper the
    board: 14 / 29.5 gives sin 0.474 but tan 0.539.

    Parameters
    ----------
    height : array_like
        Height of the raised end at onset [m].
    board_length : array_like
        Board length from hinge to the raised end [m].

    Returns
    -------
    numpy.ndarray
        Friction coefficient [1].
    """
    h = np.asarray(height, dtype=float)
    L = np.asarray(board_length, dtype=float)
    if not np.all((h > 0) & (h < L)):
        raise InputError("height must be positive and below board_length")
    return h / np.sqrt(L * L - h * h)


def rolling_from_rollout(slope_angle, release_height, runout):
    """Rolling friction from a roll-out test, mu_r = H sin(theta) / (H cos(theta) + S sin(theta)).

    Parameters
    ----------
    slope_angle : array_like
        Slope angle theta [rad], in (0, pi/2).
    release_height : array_like
        Release height H above the flat plate [m], > 0.
    runout : array_like
        Distance S rolled on the flat plate before stopping [m], >= 0.

    Returns
    -------
    numpy.ndarray
        Rolling friction coefficient [1].
    """
    theta = _angles(slope_angle, "slope_angle")
    H = np.asarray(release_height, dtype=float)
    S = np.asarray(runout, dtype=float)
    if not np.all(H > 0):
        raise InputError("release_height must be positive")
    if not np.all(S >= 0):
        raise InputError("runout must not be negative")
    s, c = np.sin(theta), np.cos(theta)
    return H * s / (H * c + S * s)


def friction_estimates(workbook, *, outliers="none") -> dict:
    """``static_friction.<surface>`` and ``rolling_friction.<surface>`` from the ``incline`` sheet.

    Slide rows give static friction, roll rows rolling friction; a surface's tilt-angle and
    roll-out rows are pooled, and ``extra["by_method"]`` gives each method's own mean and n.
    """
    sheet = workbook.sheet("incline")
    if sheet is None or not sheet.rows:
        return {}
    f = sheet.frame
    out = {}
    mode_of, surface_of = sheet.column("mode"), sheet.column("surface")
    cell = {c: sheet.column(c) for c in ("angle_deg", "trial_id", "carrier", "slope_deg",
                                         "release_height_mm", "runout_mm") if c in f}
    groups = sorted({(mode_of[r], surface_of[r]) for r in sheet.rows})
    for mode, surface in groups:
        rows = [r for r in sheet.rows if mode_of[r] == mode and surface_of[r] == surface]
        values, records = [], []
        for r in rows:
            angle = cell["angle_deg"][r] if "angle_deg" in f else math.nan
            rec = {"id": cell["trial_id"][r], "surface": surface, "mode": mode,
                   "carrier": cell["carrier"][r] if "carrier" in f else "particle"}
            if not math.isnan(angle):
                values.append(float(from_tilt_angle(math.radians(angle))))
                rec.update(method="tilt", angle_rad=math.radians(angle))
            else:
                theta = math.radians(cell["slope_deg"][r])
                H = cell["release_height_mm"][r] * MM
                S = cell["runout_mm"][r] * MM
                values.append(float(rolling_from_rollout(theta, H, S)))
                rec.update(method="rollout", slope_angle_rad=theta, release_height_m=H, runout_m=S)
            rec["covariates"] = sheet.covariates_of(r)
            records.append(rec)
        kinds = sorted({rec["method"] for rec in records})
        method = " + ".join(TILT_METHOD if k == "tilt" else ROLLOUT_METHOD for k in kinds)
        name = f"{'static' if mode == 'slide' else 'rolling'}_friction.{surface}"
        est = summarise(name, values, rows, unit="1", source=sheet.source(), method=method,
                        outliers=outliers, per_row=records)
        if len(kinds) > 1:
            by_method = {}
            for k in kinds:
                x = [rec["value"] for rec in est.per_row if rec["used"] and rec["method"] == k]
                by_method[k] = {"value": float(np.mean(x)) if x else None, "n": len(x)}
            est = replace(est, extra=dict(est.extra, by_method=by_method))
        out[name] = est
    return out
