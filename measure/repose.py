"""Angle of repose: from a side photo of a heap, from a heap profile, from a rotating drum.

The lab photographs the heap left by the plate-withdrawal ("pumping plate") rig from the side
and measures the slope of its flank(s) relative to the floor, as the source paper does with
Matlab and Origin (binarise, extract the boundary curve, fit it). :func:`angle_from_photo`
does the whole chain on the photo, step by step:

1. *Grayscale*: luminance (ITU-R BT.601 weights).
2. *Illumination flattening*: a smooth field (a quadratic in x and y of the log intensity) is
   fitted to block medians of the background and divided out, removing light gradients and
   vignetting; repeated twice with the new classification.
3. *Otsu threshold* [Otsu1979]_ of the flattened image (lightly denoised). *Polarity*: the
   side of the threshold of the bottom centre of the frame (the floor in front of the heap)
   is the object, so the heap may be darker or lighter than the background. A three-class
   Otsu split [Liao2001]_ is tried first, so that a floor much lighter or darker than the heap
   does not pull the threshold between floor and heap: the threshold next to the background
   (the top of the frame) is used.
4. *Morphological clean-up* [Soille2003]_: an opening removes thin grid lines and speckle, a
   closing bridges the gaps between surface segments, holes are filled, and the largest
   connected object (heap and floor) is kept.
5. *Top boundary*: in every column, the top edge of the top-most object pixel, placed to
   a fraction of a pixel where the grey levels across it straddle the threshold.
6. *Floor line*: a Hough-type search [DudaHart1972]_ over near-horizontal lines for the one
   supported by most boundary points with (almost) none below it (the floor is the lower
   envelope of the boundary; a flat heap top is not), refined by the robust line of step 8
   through the locally flat boundary points near it. Its tilt is the camera roll; it is
   reported and removed: heights are measured perpendicular to the floor and distances
   along it.
7. *Flanks*: on the boundary smoothed by a running median and a Gaussian, the crest is the
   highest point and each toe is where the boundary falls to the floor (half the lower band
   height) walking out from the crest. A flank is fitted between the *outermost* point above
   ``band[1]`` of the crest height and the next point below ``band[0]`` (``FLANK_BAND``,
   15 % .. 95 % by default), which excludes the concave toe. The default band is the one
   whose angle scatters least from seed to seed on simulated heaps
   (``benchmarks/angle_methods.py``); lab photos and simulated heaps use the same one.
8. *Robust straight line* through the raw boundary points of the band: least squares
   without the spikes (narrow excursions beyond 3.5 robust standard deviations: specks, a
   stick standing up), started from the Theil-Sen line [Theil1950]_ [Sen1968]_. It is the
   mean (least-squares) slope of a rough flank: the wider waviness of the surface is kept.
   The band's ends are then moved to where the fitted line crosses the band heights and the
   line refitted (so that a bump at an end does not choose the range). The flank angle is the
   arctangent of the slope, and the angle of repose the mean of the measured flanks.

:func:`angle_from_profile` applies steps 7-8 to a height profile (e.g. the surface of a
simulated heap), and :func:`angle_from_drum` measures the dynamic angle of the free surface
in a rotating drum (e.g. a GranuDrum image) by a central-chord fit.

References
----------
.. [Otsu1979] N. Otsu, "A threshold selection method from gray-level histograms", IEEE Trans.
   Systems, Man, and Cybernetics 9(1), 62-66 (1979).
.. [Liao2001] P.-S. Liao, T.-S. Chen, P.-C. Chung, "A fast algorithm for multilevel
   thresholding", J. Inf. Sci. Eng. 17(5), 713-727 (2001).
.. [Soille2003] P. Soille, *Morphological Image Analysis*, 2nd ed., Springer (2003).
.. [DudaHart1972] R. O. Duda, P. E. Hart, "Use of the Hough transformation to detect lines and
   curves in pictures", Comm. ACM 15(1), 11-15 (1972).
.. [Theil1950] H. Theil, "A rank-invariant method of linear and polynomial regression analysis",
   Proc. Kon. Ned. Akad. v. Wetensch. A 53, 386-392 (1950).
.. [Sen1968] P. K. Sen, "Estimates of the regression coefficient based on Kendall's tau",
   J. Amer. Statist. Assoc. 63(324), 1379-1389 (1968).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from scipy import ndimage, stats

from demcal.errors import InputError
from demcal.measure.images import MAX_PHOTO_PIXELS, read_image

SIDES = ("left", "right", "both", "auto", "drum")
FLANKS = ("left", "right")
#: Heights between which a flank is fitted, as fractions of the crest height (step 7); one
#: default for lab photos and simulated heaps alike, so their angles compare.
FLANK_BAND = (0.15, 0.95)
PIXEL_SCALE = 0.25     # smallest robust sd of an image boundary about a line [px]


@dataclass(frozen=True)
class FlankFit:
    """Straight-line fit to one flank, in the floor frame (u along the floor, h above it).

    Attributes
    ----------
    side : str
        "left" (rising toward the crest) or "right" (falling from it).
    angle_deg : float
        Flank angle relative to the floor [deg].
    slope : float
        Fitted dh/du (robust line, step 8 of :func:`angle_from_photo`) [-].
    intercept : float
        Fitted h at u = 0 [px for photos, m for profiles].
    slope_ci : tuple of float
        95 % confidence interval of the slope from the fit [-]. It treats the boundary points
        as independent; the boundary of a granular heap is correlated over about a particle,
        so this understates the uncertainty (repeat photos measure it).
    u_range : tuple of float
        Along-floor range of the points used [px or m].
    h_range : tuple of float
        Height band used, ``band`` times the crest height [px or m].
    residual_sd : float
        Standard deviation of the residuals of the points fitted [px or m].
    n_points : int
        Number of boundary points fitted.
    n_rejected : int
        Points of the band set aside as outliers by the robust fit.
    """

    side: str
    angle_deg: float
    slope: float
    intercept: float
    slope_ci: tuple
    u_range: tuple
    h_range: tuple
    residual_sd: float
    n_points: int
    n_rejected: int = 0

    @property
    def angle_ci_deg(self) -> tuple:
        """95 % confidence interval of ``angle_deg`` from ``slope_ci`` [deg]."""
        a = sorted(abs(math.degrees(math.atan(s))) for s in self.slope_ci)
        return (a[0], a[1])

    def to_dict(self) -> dict:
        return {"side": self.side, "angle_deg": self.angle_deg, "angle_ci_deg": list(self.angle_ci_deg),
                "slope": self.slope, "intercept": self.intercept, "slope_ci": list(self.slope_ci),
                "u_range": list(self.u_range), "h_range": list(self.h_range),
                "residual_sd": self.residual_sd, "n_points": self.n_points,
                "n_rejected": self.n_rejected}


@dataclass(frozen=True)
class ReposeAngle:
    """Angle of repose of a heap.

    Attributes
    ----------
    angle_deg : float
        Mean of the measured flank angles [deg].
    flanks : dict
        ``{"left": deg or None, "right": deg or None}``: each flank's angle [deg], None if not
        measured.
    base_tilt_deg : float
        Tilt of the floor line in the image, counter-clockwise positive (the floor rises to the
        right) [deg]; the angles are measured relative to the floor. 0 for a profile.
    boundary : tuple of numpy.ndarray
        Top boundary ``(x, y)``: for a photo in image pixels (y down); for a profile the
        profile itself ``(x, z)`` [m].
    fits : dict
        ``{"left"/"right": FlankFit}`` for the measured flanks.
    annotated : str or None
        Path of the annotated image, if one was written.
    unit : str
        Length unit of ``boundary``, ``fits`` and ``crest_height``: "px" or "m".
    crest_height : float
        Height of the (smoothed) crest above the floor [px or m].
    scale_m_per_px : float or None
        Image scale when given [m/px]; converts pixel lengths to metres.
    """

    angle_deg: float
    flanks: dict
    base_tilt_deg: float
    boundary: tuple
    fits: dict
    annotated: str | None = None
    unit: str = "px"
    crest_height: float = float("nan")
    scale_m_per_px: float | None = None

    @property
    def crest_height_m(self) -> float | None:
        """Crest height [m], when the unit or the scale allows it."""
        if self.unit == "m":
            return self.crest_height
        return None if self.scale_m_per_px is None else self.crest_height * self.scale_m_per_px

    def to_dict(self) -> dict:
        return {"angle_deg": self.angle_deg, "flanks": dict(self.flanks),
                "base_tilt_deg": self.base_tilt_deg,
                "fits": {k: v.to_dict() for k, v in self.fits.items()},
                "annotated": self.annotated, "unit": self.unit,
                "crest_height": self.crest_height, "crest_height_m": self.crest_height_m,
                "scale_m_per_px": self.scale_m_per_px,
                "boundary": {"x": np.asarray(self.boundary[0]).tolist(),
                             "y": np.asarray(self.boundary[1]).tolist()}}


@dataclass(frozen=True)
class DrumAngle:
    """Dynamic angle of repose of the free surface in a rotating drum.

    Attributes
    ----------
    angle_deg : float
        Angle of the central chord of the free surface to the image rows [deg].
    centre_px : tuple of float
        Drum centre ``(x, y)`` in the image [px].
    radius_px : float
        Drum radius (inside of the rim) [px].
    boundary : tuple of numpy.ndarray
        Free-surface points ``(x, y)`` [px, y down].
    fit : FlankFit
        Robust line through the central chord (u = x, h = -y, in image pixels).
    annotated : str or None
        Path of the annotated image, if one was written.
    """

    angle_deg: float
    centre_px: tuple
    radius_px: float
    boundary: tuple
    fit: FlankFit
    annotated: str | None = None

    @property
    def flanks(self) -> dict:
        """A drum's free surface has no flanks (as a heap photo's result has)."""
        return {}

    @property
    def base_tilt_deg(self) -> None:
        """The drum is its own reference: no floor tilt is read."""
        return None

    def to_dict(self) -> dict:
        return {"angle_deg": self.angle_deg, "centre_px": list(self.centre_px),
                "radius_px": self.radius_px, "fit": self.fit.to_dict(), "annotated": self.annotated,
                "boundary": {"x": np.asarray(self.boundary[0]).tolist(),
                             "y": np.asarray(self.boundary[1]).tolist()}}


# ----------------------------------------------------------------------------------------
# Public functions

def angle_from_photo(image, side="both", annotate_to=None, scale_mm_per_px=None, *,
                     band=None, smooth=0.02, max_tilt_deg=10.0, min_points=20,
                     max_pixels=MAX_PHOTO_PIXELS):
    """Angle of repose from a side photo of a heap [deg], measured relative to the floor.

    Follows the steps in the module docstring: grayscale, illumination flattening, Otsu
    threshold with automatic polarity, morphological clean-up, top boundary, floor line and
    its tilt, crest and toes, robust line through the ``band`` of each flank.

    Parameters
    ----------
    image : str, pathlib.Path or numpy.ndarray
        Photo file, or an image array (grey ``(h, w)`` or BGR ``(h, w, 3)``, any numeric or
        boolean dtype). The floor must be visible and run into the bottom centre of the frame.
    side : {"both", "left", "right", "auto", "drum"}
        Flank(s) to measure: "left" rises toward the crest, "right" falls from it. A heap from
        the plate-withdrawal rig has one flank; a cone has two. "auto" measures every flank
        whose toe is inside the frame. "drum": the photo is a rotating drum seen end-on, and
        its free surface is read by :func:`angle_from_drum` (which returns a ``DrumAngle``).
    annotate_to : str or pathlib.Path, optional
        Write an annotated copy (boundary, floor line, fitted lines, angles) to this file.
    scale_mm_per_px : float, optional
        Image scale [mm/px]; only used to report lengths in metres (angles need none).
    band : (float, float), optional
        Lower and upper fraction of the crest height between which each flank is fitted [-];
        default ``FLANK_BAND``.
    smooth : float
        Width of the boundary smoothing used to find crest, toes and band, as a fraction of
        the boundary length [-] (the fit itself uses the raw boundary).
    max_tilt_deg : float
        Largest floor tilt searched for [deg].
    min_points : int
        Fewest boundary points a flank fit accepts.
    max_pixels : int
        Most pixels a photo file may have [px]; a larger one is refused before it is decoded.
        Default ``measure.images.MAX_PHOTO_PIXELS``.

    Returns
    -------
    ReposeAngle

    Raises
    ------
    InputError
        Unreadable or truncated image, a photo file with more than ``max_pixels`` pixels, no
        heap or no floor found, or a requested flank not measurable.
    """
    if side not in SIDES:
        raise InputError(f"side must be one of {SIDES}, got {side!r}")
    if side == "drum":
        return angle_from_drum(image, annotate_to=annotate_to, max_pixels=max_pixels)
    band = _check_band(band)
    _check_options(smooth, min_points)
    if not 0.0 < float(max_tilt_deg) <= 45.0:
        raise InputError(f"max_tilt_deg must be in (0, 45], got {max_tilt_deg!r}")
    scale = _check_scale(scale_mm_per_px)
    bgr, name = _read_image(image, max_pixels)
    h, w = bgr.shape[:2]
    gray = _grayscale(bgr)
    mask, flat, t, bright = _segment(gray, name)
    x, y = _top_boundary(mask, flat, t, bright)
    if x.size < 0.2 * w:
        raise InputError(f"{name}: no heap found (the object covers only {x.size} of {w} columns)")
    if np.mean(y < 0) > 0.5:
        raise InputError(f"{name}: no heap found (no background above the object: the image has "
                         f"no contrast, or the heap fills the frame)")
    tol = max(2.0, 0.003 * max(h, w))
    a, b, tilt = _floor_line(x, y, max_tilt_deg, tol, name)
    # Floor frame: u along the floor, h perpendicular to it, up (image y is down).
    norm = math.hypot(1.0, b)
    u = (x + b * (y - a)) / norm
    hgt = (b * x - (y - a)) / norm
    if not np.max(hgt) > 3.0:
        raise InputError(f"{name}: no heap found above the floor line")
    fits, crest, reasons = _flank_fits(u, hgt, band, smooth, min_points, min_scale=PIXEL_SCALE)
    fits = _select(fits, reasons, side, name)
    flanks = {s: (fits[s].angle_deg if s in fits else None) for s in FLANKS}
    angle = float(np.mean([f.angle_deg for f in fits.values()]))
    annotated = None
    if annotate_to is not None:
        annotated = _annotate_photo(bgr, x, y, a, b, fits, crest, angle, tilt, annotate_to)
    return ReposeAngle(angle_deg=angle, flanks=flanks, base_tilt_deg=tilt,
                       boundary=(x.astype(float), y.astype(float)), fits=fits,
                       annotated=annotated, unit="px", crest_height=crest, scale_m_per_px=scale)


def angle_from_profile(x, z, side="both", *, band=None, smooth=0.02, floor_z=0.0,
                       min_points=5):
    """Angle of repose of a heap height profile [deg], with the flank rule of the photos.

    Steps 7-8 of :func:`angle_from_photo` on a profile: crest = top of the smoothed profile,
    toes where it falls back to the floor, robust line through the ``band`` of each flank.

    Parameters
    ----------
    x, z : array_like
        Profile: horizontal position and surface height [m], e.g. the top of a simulated heap
        on a grid (need not be sorted; NaN heights are dropped).
    side : {"both", "left", "right", "auto"}
        Flank(s) to measure, as in :func:`angle_from_photo`.
    band : (float, float)
        Fractions of the crest height between which each flank is fitted [-].
    smooth : float
        Smoothing width as a fraction of the profile length [-].
    floor_z : float
        Height of the floor [m].
    min_points : int
        Fewest profile points a flank fit accepts.

    Returns
    -------
    ReposeAngle
        With ``unit="m"``, ``base_tilt_deg=0`` and ``boundary=(x, z)`` sorted by x.
    """
    if side not in SIDES or side == "drum":
        raise InputError(f"side must be one of {SIDES[:-1]}, got {side!r}")
    band = _check_band(band)
    _check_options(smooth, min_points)
    x = np.asarray(x, dtype=float).ravel()
    z = np.asarray(z, dtype=float).ravel()
    if x.shape != z.shape:
        raise InputError(f"angle_from_profile: x and z differ in length ({x.size} and {z.size})")
    ok = np.isfinite(x) & np.isfinite(z)
    if np.any(~np.isfinite(x)):
        raise InputError("angle_from_profile: x has non-finite values")
    x, z = x[ok], z[ok]
    if x.size < 2 * min_points or np.unique(x).size < 3:
        raise InputError(f"angle_from_profile: too few profile points ({x.size})")
    order = np.argsort(x, kind="stable")
    x, z = x[order], z[order]
    fits, crest, reasons = _flank_fits(x, z - float(floor_z), band, smooth, min_points)
    fits = _select(fits, reasons, side, "profile")
    flanks = {s: (fits[s].angle_deg if s in fits else None) for s in FLANKS}
    angle = float(np.mean([f.angle_deg for f in fits.values()]))
    return ReposeAngle(angle_deg=angle, flanks=flanks, base_tilt_deg=0.0, boundary=(x, z),
                       fits=fits, annotated=None, unit="m", crest_height=crest)


def angle_from_drum(image, *, chord=0.5, rim_margin=0.04, annotate_to=None,
                    max_pixels=MAX_PHOTO_PIXELS):
    """Dynamic angle of repose in a rotating drum from a side image of its free surface [deg].

    The drum rim is found as the strongest circle of the Hough gradient method
    [DudaHart1972]_ with a radius of 35-55 % of the frame. Inside the drum, less a
    ``rim_margin`` ring, the dark powder is thresholded (Otsu) and cleaned; the free surface
    is its top boundary in each column. A robust line (as for the heap flanks) is fitted to
    the central ``chord`` fraction of the free surface's horizontal extent; its angle to the
    image rows is the dynamic angle of repose.

    Parameters
    ----------
    image : str, pathlib.Path or numpy.ndarray
        Drum image: dark powder, bright air, drum seen end-on.
    chord : float
        Central fraction of the free surface fitted, in (0, 1] [-].
    rim_margin : float
        Ring inside the rim left out, as a fraction of the radius [-].
    annotate_to : str or pathlib.Path, optional
        Write an annotated copy to this file.
    max_pixels : int
        Most pixels an image file may have [px]; a larger one is refused before it is decoded.
        Default ``measure.images.MAX_PHOTO_PIXELS``.

    Returns
    -------
    DrumAngle
    """
    if not 0.0 < float(chord) <= 1.0:
        raise InputError(f"chord must be in (0, 1], got {chord!r}")
    if not 0.0 <= float(rim_margin) < 0.5:
        raise InputError(f"rim_margin must be in [0, 0.5), got {rim_margin!r}")
    bgr, name = _read_image(image, max_pixels)
    gray = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(np.float32)
    h, w = gray.shape
    dark = gray < _otsu(gray)
    # The drum rim: the strongest circle (Hough gradient method) of radius 35-55 % of the frame.
    side = min(h, w)
    circles = cv2.HoughCircles(cv2.GaussianBlur(gray, (0, 0), 1.5).astype(np.uint8),
                               cv2.HOUGH_GRADIENT, dp=1, minDist=side, param1=100, param2=30,
                               minRadius=int(0.35 * side), maxRadius=int(0.55 * side))
    if circles is None:
        raise InputError(f"{name}: no drum rim (circle) found")
    cx, cy, radius = (float(v) for v in circles[0][0])
    yy, xx = np.mgrid[0:h, 0:w]
    r = np.hypot(xx - cx, yy - cy)
    inner = r < radius * (1.0 - rim_margin)
    powder = dark & inner
    rad = max(1, int(round(0.01 * radius)))
    powder = _largest(cv2.morphologyEx(powder.astype(np.uint8), cv2.MORPH_OPEN, _disk(rad)) > 0)
    if powder.sum() < 0.05 * math.pi * radius ** 2:
        raise InputError(f"{name}: no powder bed found in the drum")
    # Free surface: top-most powder pixel of each column that has air above it.
    cols = np.nonzero(powder.any(axis=0))[0]
    top = powder[:, cols].argmax(axis=0)
    inner_top = inner[:, cols].argmax(axis=0)
    keep = (top > inner_top + 1) & (np.hypot(cols - cx, top - cy) < radius * (1.0 - 2 * rim_margin))
    bx, by = cols[keep].astype(float), top[keep].astype(float)
    if bx.size < 10:
        raise InputError(f"{name}: no free surface found in the drum")
    mid, span = 0.5 * (bx.min() + bx.max()), bx.max() - bx.min()
    sel = np.abs(bx - mid) <= 0.5 * chord * span
    slope, intercept, lo, hi, kept = _robust_line(bx[sel], -by[sel], min_scale=PIXEL_SCALE)
    res = (-by[sel] - (intercept + slope * bx[sel]))[kept]
    angle = abs(math.degrees(math.atan(slope)))
    fit = FlankFit(side="left" if slope > 0 else "right", angle_deg=angle, slope=slope,
                   intercept=intercept, slope_ci=(lo, hi),
                   u_range=(float(bx[sel].min()), float(bx[sel].max())),
                   h_range=(float(-by[sel].max()), float(-by[sel].min())),
                   residual_sd=float(np.std(res, ddof=2)), n_points=int(kept.sum()),
                   n_rejected=int((~kept).sum()))
    annotated = None
    if annotate_to is not None:
        img = bgr.copy()
        t = _thickness(img)
        cv2.circle(img, (int(round(cx)), int(round(cy))), int(round(radius)), (255, 255, 0), t,
                   cv2.LINE_AA)
        _polyline(img, bx, by, (0, 255, 255), t)
        x0, x1 = fit.u_range
        _line(img, (x0, -(intercept + slope * x0)), (x1, -(intercept + slope * x1)), (0, 0, 255), 2 * t)
        _label(img, f"drum angle {angle:.1f} deg", (10, 10 + 14 * t), t)
        annotated = _write(img, annotate_to)
    return DrumAngle(angle_deg=angle, centre_px=(float(cx), float(cy)), radius_px=radius,
                     boundary=(bx, by), fit=fit, annotated=annotated)


# ----------------------------------------------------------------------------------------
# Checks and image input

def _check_options(smooth, min_points):
    if not 0.0 < float(smooth) < 0.5:
        raise InputError(f"smooth must be a fraction in (0, 0.5), got {smooth!r}")
    if int(min_points) != min_points or min_points < 3:
        raise InputError(f"min_points must be an integer >= 3, got {min_points!r}")


def _check_band(band):
    if band is None:
        band = FLANK_BAND
    try:
        lo, hi = (float(v) for v in band)
    except (TypeError, ValueError):
        raise InputError(f"band must be (low, high) fractions of the crest height, got {band!r}") from None
    if not 0.0 < lo < hi < 1.0:
        raise InputError(f"band must satisfy 0 < low < high < 1, got {band!r}")
    return lo, hi


def _check_scale(scale_mm_per_px):
    if scale_mm_per_px is None:
        return None
    try:
        s = float(scale_mm_per_px)
    except (TypeError, ValueError):
        raise InputError(f"scale_mm_per_px must be a number, got {scale_mm_per_px!r}") from None
    if not (math.isfinite(s) and s > 0):
        raise InputError(f"scale_mm_per_px must be positive, got {scale_mm_per_px!r}")
    return s * 1e-3


def _read_image(image, max_pixels):
    """BGR uint8 image and a name for messages, from a path (at most ``max_pixels`` pixels,
    checked before decoding) or an array."""
    if isinstance(image, (str, Path)):
        path = Path(image)
        name = f"image {str(path)!r}"
        if not path.is_file():
            raise InputError(f"{name}: file not found")
        try:
            return read_image(path, max_pixels), name
        except ValueError as exc:
            raise InputError(f"{name}: {exc}") from None
    name = "image array"
    if not isinstance(image, np.ndarray):
        raise InputError(f"image must be a file path or a numpy array, got {type(image).__name__}")
    a = image
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.ndim == 3 and a.shape[2] == 4:
        a = a[..., :3]
    if not (a.ndim == 2 or (a.ndim == 3 and a.shape[2] == 3)):
        raise InputError(f"{name}: expected shape (h, w) or (h, w, 3), got {image.shape}")
    if min(a.shape[:2]) < 32:
        raise InputError(f"{name}: too small ({a.shape[0]} x {a.shape[1]} px)")
    if a.dtype == bool:
        a = a.astype(np.uint8) * 255
    elif a.dtype != np.uint8:
        a = a.astype(np.float64)
        if not np.all(np.isfinite(a)):
            raise InputError(f"{name}: has non-finite values")
        lo, hi = a.min(), a.max()
        a = np.zeros(a.shape, np.uint8) if hi <= lo else np.rint(255 * (a - lo) / (hi - lo)).astype(np.uint8)
    if a.ndim == 2:
        a = cv2.cvtColor(a, cv2.COLOR_GRAY2BGR)
    return np.ascontiguousarray(a), name


# ----------------------------------------------------------------------------------------
# Steps 1-5: grayscale, flattening, threshold, clean-up, boundary

def _otsu(values):
    """Otsu's threshold [Otsu1979]_ of an array of values."""
    from skimage.filters import threshold_otsu
    return float(threshold_otsu(np.asarray(values, dtype=np.float32)))


def _grayscale(bgr):
    """Step 1: luminance (ITU-R BT.601 weights, as OpenCV's BGR2GRAY)."""
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(np.float32)


def _disk(radius):
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))


def _object_class(img):
    """Step 3: threshold; the object is on the side of the bottom centre of the frame.
    Returns the object mask, the threshold and whether the object is the bright side.

    Three-class Otsu thresholds [Otsu1979]_ [Liao2001]_ split background, heap and floor when
    the floor is much lighter or darker than the heap; the threshold next to the class of the
    top of the frame (the background) is used. If the background is the middle class, the
    two-class Otsu threshold is used instead.
    """
    from skimage.filters import threshold_multiotsu
    h, w = img.shape
    bottom = float(np.median(img[int(0.93 * h):, int(0.3 * w):int(0.7 * w) + 1]))
    top = float(np.median(img[:max(2, h // 20)]))
    try:
        t1, t2 = threshold_multiotsu(img, classes=3)
    except ValueError:                  # too few grey levels for three classes
        t1 = t2 = None
    if t1 is not None and top < t1 < bottom:
        return img > t1, float(t1), True
    if t1 is not None and bottom < t2 < top:
        return img < t2, float(t2), False
    t = _otsu(img)
    return (img > t, t, True) if bottom > t else (img <= t, t, False)


def _illumination(img, background):
    """Step 2: smooth multiplicative light field fitted to block medians of the background.

    log(field) is a quadratic in normalised x, y, fitted by least squares to the log of the
    median of each block that is mostly background. None if too few such blocks.
    """
    h, w = img.shape
    b = max(8, min(h, w) // 20)
    nr, nc = h // b, w // b
    # Views (block row, block column, row, column in the block): only the blocks used are copied.
    blocks = img[:nr * b, :nc * b].reshape(nr, b, nc, b).transpose(0, 2, 1, 3)
    bg = background[:nr * b, :nc * b].reshape(nr, b, nc, b).transpose(0, 2, 1, 3)
    use = bg.mean(axis=(2, 3)) >= 0.6
    if use.sum() < 12:
        return None
    # Median of each block's background pixels (NaN elsewhere; NaN sorts last).
    in_bg = bg[use].reshape(-1, b * b)
    vals = blocks[use].reshape(-1, b * b)
    vals[~in_bg] = np.nan
    vals.sort(axis=1)
    count = in_bg.sum(axis=1)
    med = vals[np.arange(vals.shape[0]), (count - 1) // 2]
    rows, cols = np.nonzero(use)
    ok = med > 0
    if ok.sum() < 12:
        return None
    ys, xs, vs = (rows[ok] + 0.5) * b, (cols[ok] + 0.5) * b, np.log(med[ok])

    def design(xv, yv):
        xn, yn = 2 * xv / w - 1, 2 * yv / h - 1
        return [np.ones_like(xn * yn), xn, yn, xn * xn, xn * yn, yn * yn]

    coef, *_ = np.linalg.lstsq(np.stack(design(xs, ys), axis=-1), vs, rcond=None)
    # No extrapolation downward: below the lowest background block (the floor, the bench) each
    # column keeps the light level of that row; and stay within the observed range.
    xg = np.arange(w, dtype=np.float32)[None, :]
    yg = np.minimum(np.arange(h, dtype=np.float32), ys.max())[:, None]
    field = np.empty((h, w), np.float32)
    # In bands of rows: the double-precision terms of the whole frame would take several
    # times the memory of the photo.
    for i in range(0, h, 256):
        log_field = sum(c * t for c, t in zip(coef.astype(np.float32), design(xg, yg[i:i + 256])))
        field[i:i + 256] = np.exp(np.clip(log_field, vs.min() - 0.1, vs.max() + 0.1))
    return field


def _fill_holes(mask):
    """Fill the holes of a binary mask: background not connected to the frame border."""
    m = np.pad(mask.astype(np.uint8), 1)
    outside = m.copy()
    cv2.floodFill(outside, None, (0, 0), 1)          # the padded border is connected
    return (m | (outside == 0))[1:-1, 1:-1].astype(bool)


def _largest(mask):
    n, lab, st, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    if n <= 1:
        return np.zeros(mask.shape, bool)
    return lab == 1 + int(np.argmax(st[1:, cv2.CC_STAT_AREA]))


def _segment(gray, name):
    """Steps 2-4: cleaned mask of the heap and floor, with the flattened image, its threshold
    and the object's side of it (for the sub-pixel boundary)."""
    h, w = gray.shape
    diag = math.hypot(h, w)
    r_open = max(1, int(round(0.003 * diag)))
    r_close = max(2, int(round(0.008 * diag)))

    def clean(obj):
        m = cv2.morphologyEx(obj.astype(np.uint8), cv2.MORPH_OPEN, _disk(r_open))
        m = cv2.morphologyEx(m, cv2.MORPH_CLOSE, _disk(r_close))
        return _largest(_fill_holes(m > 0))

    img = cv2.GaussianBlur(gray, (0, 0), max(1.0, diag / 1000.0))
    flat = img
    obj, t, bright = _object_class(flat)
    mask = clean(obj)
    for _ in range(2):
        # Background well away from the object (its light level is what is fitted).
        background = cv2.erode((~mask).astype(np.uint8), _disk(r_close)) > 0
        field = _illumination(img, background)
        if field is None:
            break
        flat = img / field
        obj, t, bright = _object_class(flat)
        mask = clean(obj)
    if mask.sum() < 0.01 * h * w:
        raise InputError(f"{name}: no heap found (no object large enough after thresholding)")
    return mask, flat, t, bright


def _top_boundary(mask, flat=None, t=None, bright=True):
    """Step 5: the top edge of the object in each column [px, pixel centres at integers].

    The edge lies between the top-most object pixel (row y0) and the pixel above it. Where
    their grey levels in ``flat`` straddle the threshold ``t``, it is placed where the linear
    interpolation between the two crosses ``t`` (sub-pixel); elsewhere (e.g. a notch filled by
    the closing) half-way, at y0 - 0.5.
    """
    cols = np.nonzero(mask.any(axis=0))[0]
    y0 = mask[:, cols].argmax(axis=0)
    y = y0 - 0.5
    if flat is not None:
        ok = y0 >= 1
        c, r = cols[ok], y0[ok]
        v_in, v_out = flat[r, c].astype(float), flat[r - 1, c].astype(float)
        if not bright:
            v_in, v_out, t = -v_in, -v_out, -t
        straddle = (v_out <= t) & (v_in > t)
        frac = np.where(straddle, (t - v_out) / np.where(straddle, v_in - v_out, 1.0), 0.5)
        y[ok] = r - 1 + frac
    return cols.astype(float), y.astype(float)


# ----------------------------------------------------------------------------------------
# Step 6: floor line

def _floor_line(x, y, max_tilt_deg, tol, name):
    """Lower-envelope line y = a + b x of the boundary (image y down); tilt in degrees.

    For each candidate tilt (0.05 deg steps) every boundary point proposes the line through
    it; a line's support is the number of points within ``tol`` of it, and it is admissible
    if at most 3 % of the points lie more than ``tol`` below it. The best admissible line is
    refined by a robust fit to the locally flat points within 2 ``tol`` of it.
    """
    n = x.size
    allowed = max(2, int(0.03 * n))
    need = max(30, int(0.05 * n))
    xc = x - x.mean()
    best = (-1, 0.0, 0.0)
    for tilt in np.arange(-max_tilt_deg, max_tilt_deg + 1e-9, 0.05):
        b = -math.tan(math.radians(tilt))
        # Intercepts of the points; candidate bands [c_k, c_k + 2 tol] in image rows.
        c = np.sort(y - b * xc)
        end = np.searchsorted(c, c + 2 * tol, side="right")
        support = end - np.searchsorted(c, c, side="left")
        ok = (n - end) <= allowed                       # few points below the band
        if not ok.any():
            continue
        k = int(np.argmax(np.where(ok, support, -1)))
        if support[k] > best[0]:
            best = (int(support[k]), b, float(c[k]) + tol)
    if best[0] < need:
        raise InputError(f"{name}: no floor line found (need a straight floor edge visible over "
                         f"at least {need} columns, within +-{max_tilt_deg} deg of horizontal)")
    _, b, c0 = best
    a = c0 - b * x.mean()
    # Refine on the floor points near the line: locally flat boundary only (not the edges of
    # a stray segment or the toe), robust line, three times.
    # Points within a few tolerances of a steep part are left out: the fillets that the
    # morphological closing leaves where a segment meets the floor.
    dy = np.gradient(ndimage.uniform_filter1d(y, 5), x)
    steep = np.abs(dy) > math.tan(math.radians(max_tilt_deg)) + 0.05
    flat = ~(ndimage.maximum_filter1d(steep.astype(np.uint8), 2 * int(4 * tol) + 1) > 0)
    for _ in range(3):
        near = flat & (np.abs(y - (a + b * x)) <= 2 * tol)
        if near.sum() < need // 2:
            break
        b, a = _robust_line(x[near], y[near], min_scale=PIXEL_SCALE)[:2]
    return float(a), float(b), float(-math.degrees(math.atan(b)))


# ----------------------------------------------------------------------------------------
# Steps 7-8: crest, toes, band, robust line

def _robust_line(u, h, clip=3.5, max_width=0.05, min_scale=0.0, max_iter=10):
    """Straight line h = intercept + slope u: least squares without the spikes.

    Started from the Theil-Sen line [Theil1950]_ [Sen1968]_, which no outlier can pull far.
    A spike is an excursion from the line (a run of consecutive points, in u order, on one
    side of it by more than one robust standard deviation, 1.4826 x the median absolute
    deviation) that is narrower than ``max_width`` times the u-span fitted and reaches more
    than ``clip`` robust standard deviations: a speck, a stick standing up, a remnant of the
    background. Spikes are set aside and the line refitted by least squares until the set is
    stable. Wider excursions are the roughness of the surface and are kept, so the result is
    the mean (least-squares) slope of a rough flank.

    ``min_scale`` is a floor for the robust standard deviation (a quarter pixel for image
    boundaries: below it, the median absolute deviation of a nearly exact edge only measures
    the pixel grid).

    Returns slope, intercept, the 95 % interval of the slope (t distribution) and the mask
    of the points kept (in the order given).
    """
    u = np.asarray(u, dtype=float)
    h = np.asarray(h, dtype=float)
    order = np.argsort(u, kind="stable")
    us, hs = u[order], h[order]
    step = max(1, us.size // 2000)               # Theil-Sen's pairwise slopes grow as n^2
    slope, intercept = stats.theilslopes(hs[::step], us[::step])[:2]
    width = max_width * (us[-1] - us[0])
    tiny = 1e-9 * max(float(np.ptp(hs)), 1e-300)     # scale floor for an exact line
    keep = np.ones(us.size, bool)
    for it in range(max_iter):
        res = hs - (intercept + slope * us)
        scale = max(1.4826 * float(np.median(np.abs(res[keep] - np.median(res[keep])))), tiny,
                    min_scale)
        spike = np.zeros(us.size, bool)
        for sign in (1.0, -1.0):
            runs, _ = ndimage.label(sign * res > scale)
            for sl in ndimage.find_objects(runs):
                run = sl[0]
                if (us[run.stop - 1] - us[run.start] <= width
                        and np.max(sign * res[run]) > clip * scale):
                    spike[run] = True
        new = ~spike
        # (the first pass always refits: the start is Theil-Sen, the answer least squares)
        if new.sum() < 3 or (it > 0 and np.array_equal(new, keep)):
            break
        keep = new
        slope, intercept = np.polyfit(us[keep], hs[keep], 1)
    n = int(keep.sum())
    res = hs[keep] - (intercept + slope * us[keep])
    if n > 2:
        se = math.sqrt(np.sum(res ** 2) / (n - 2) / np.sum((us[keep] - us[keep].mean()) ** 2))
        half = float(stats.t.ppf(0.975, n - 2)) * se
    else:
        half = float("nan")
    kept = np.empty(u.size, bool)
    kept[order] = keep
    return float(slope), float(intercept), float(slope - half), float(slope + half), kept


def _flank_fits(u, h, band, smooth, min_points, min_scale=0.0):
    """Fit each flank of the profile h(u) (u sorted or not). Returns (fits, crest height,
    reasons a flank could not be measured)."""
    order = np.argsort(u, kind="stable")
    u, h = u[order], h[order]
    span = u[-1] - u[0]
    steps = np.diff(u)
    if not (span > 0 and np.any(steps > 0)):
        raise InputError("the boundary/profile has no horizontal extent")
    du = np.median(steps[steps > 0])
    grid = np.arange(u[0], u[-1] + 0.5 * du, du)
    hg = np.interp(grid, u, h)
    win = max(3, int(round(smooth * span / du)) | 1)
    hs = ndimage.median_filter(hg, size=win, mode="nearest")
    hs = ndimage.gaussian_filter1d(hs, win / 4.0, mode="nearest")
    ic = int(np.argmax(hs))
    crest = float(hs[ic])
    lo, hi = band
    if not crest > 0:
        raise InputError("no heap above the floor")
    fits, reasons = {}, {}
    for side in FLANKS:
        walk = np.arange(ic, -1, -1) if side == "left" else np.arange(ic, grid.size)
        down = np.nonzero(hs[walk] <= 0.5 * lo * crest)[0]
        if down.size == 0:
            reasons[side] = "does not reach the floor inside the image (no toe)"
            continue
        walk = walk[:down[0] + 1]                       # crest .. toe
        k_hi = np.nonzero(hs[walk] >= hi * crest)[0][-1]
        k_lo = k_hi + np.nonzero(hs[walk[k_hi:]] <= lo * crest)[0][0]
        ua, ub = sorted((grid[walk[k_hi]], grid[walk[k_lo]]))
        if ub - ua < 2 * win * du:
            # The band is no wider than the smoothing: a vertical face (the wall of the box
            # the heap came from, the frame edge), not a flank.
            reasons[side] = (f"is too steep or too short to fit (its band spans "
                             f"{ub - ua:.3g}, less than twice the smoothing width)")
            continue
        sel = (u >= ua) & (u <= ub)
        if sel.sum() < min_points:
            reasons[side] = f"too few boundary points in the fitting band ({int(sel.sum())} < {min_points})"
            continue
        slope, intercept, s_lo, s_hi, kept = _robust_line(u[sel], h[sel], min_scale=min_scale)
        # The band's ends where the fitted line, not the rough boundary, crosses the band
        # heights: a bump or dip at an end would otherwise choose the range and bias the slope.
        # They stay between crest and toe: a shallow first line (a low tail) crosses the band
        # heights far out, and refitting there would take in the floor and the other flank.
        flank = sorted((grid[walk[0]], grid[walk[-1]]))
        for _ in range(3):
            if slope == 0 or not (math.degrees(math.atan(abs(slope))) > 0):
                break
            ends = np.clip(sorted(((lo * crest - intercept) / slope, (hi * crest - intercept) / slope)), *flank)
            new_sel = (u >= ends[0]) & (u <= ends[1])
            if new_sel.sum() < min_points or np.array_equal(new_sel, sel):
                break
            sel, (ua, ub) = new_sel, ends
            slope, intercept, s_lo, s_hi, kept = _robust_line(u[sel], h[sel], min_scale=min_scale)
        angle = math.degrees(math.atan(slope if side == "left" else -slope))
        if angle <= 0:
            reasons[side] = f"is not a slope down to the floor (fitted angle {angle:.1f} deg)"
            continue
        res = (h[sel] - (intercept + slope * u[sel]))[kept]
        fits[side] = FlankFit(side=side, angle_deg=angle, slope=slope, intercept=intercept,
                              slope_ci=(s_lo, s_hi), u_range=(float(ua), float(ub)),
                              h_range=(lo * crest, hi * crest),
                              residual_sd=float(np.std(res, ddof=2)) if res.size > 2 else 0.0,
                              n_points=int(kept.sum()), n_rejected=int((~kept).sum()))
    return fits, crest, reasons


def _select(fits, reasons, side, name):
    """Keep the requested flanks; a requested flank that could not be measured is an error."""
    wanted = FLANKS if side in ("both", "auto") else (side,)
    if side != "auto":
        missing = [s for s in wanted if s not in fits]
        if missing:
            why = "; ".join(f"{s} flank {reasons[s]}" for s in missing)
            hint = " (try side='auto' or the other side)" if side == "both" or len(fits) else ""
            raise InputError(f"{name}: {why}{hint}")
        return {s: fits[s] for s in wanted}
    if not fits:
        why = "; ".join(f"{s} flank {reasons[s]}" for s in FLANKS)
        raise InputError(f"{name}: no heap flank found ({why})")
    return dict(fits)


# ----------------------------------------------------------------------------------------
# Annotation

def _thickness(img):
    return max(1, int(round(max(img.shape[:2]) / 700)))


def _polyline(img, x, y, colour, t):
    pts = np.round(np.c_[x, y] * 16).astype(np.int32)
    cv2.polylines(img, [pts], False, colour, t, cv2.LINE_AA, 4)


def _line(img, p, q, colour, t):
    cv2.line(img, (int(round(p[0] * 16)), int(round(p[1] * 16))),
             (int(round(q[0] * 16)), int(round(q[1] * 16))), colour, t, cv2.LINE_AA, 4)


def _label(img, text, org, t, colour=(255, 255, 255), scale=None):
    """Text with a black outline (the same text shifted around it) for any background."""
    scale = 0.5 * t + 0.2 if scale is None else scale
    x0, y0 = int(org[0]), int(org[1])
    for dx in (-t, 0, t):
        for dy in (-t, 0, t):
            if dx or dy:
                cv2.putText(img, text, (x0 + dx, y0 + dy), cv2.FONT_HERSHEY_SIMPLEX, scale,
                            (0, 0, 0), t, cv2.LINE_AA)
    cv2.putText(img, text, (x0, y0), cv2.FONT_HERSHEY_SIMPLEX, scale, colour, t, cv2.LINE_AA)


def _write(img, path):
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        ok, buf = cv2.imencode(path.suffix or ".png", img)
    except cv2.error:
        ok = False
    if not ok:
        raise InputError(f"annotate_to: cannot encode an image as {path.suffix!r} ({path})")
    buf.tofile(str(path))
    return str(path)


def _annotate_photo(bgr, x, y, a, b, fits, crest, angle, tilt, path):
    img = bgr.copy()
    t = _thickness(img)
    w = img.shape[1]
    norm = math.hypot(1.0, b)

    def to_image(u, hh):                    # floor frame -> image
        return (u + b * hh) / norm, a + (b * u - hh) / norm

    _polyline(img, x, y, (0, 255, 255), t)
    _line(img, (0, a), (w - 1, a + b * (w - 1)), (255, 255, 0), t)
    for side, f in fits.items():
        # The fitted line from the floor to the crest height, thick over the band used.
        u_floor = -f.intercept / f.slope
        u_top = (crest - f.intercept) / f.slope
        _line(img, to_image(u_floor, 0.0), to_image(u_top, crest), (0, 0, 255), t)
        ua, ub = f.u_range
        _line(img, to_image(ua, f.intercept + f.slope * ua), to_image(ub, f.intercept + f.slope * ub),
              (255, 0, 255), 3 * t)
        um = 0.5 * (ua + ub)
        px, py = to_image(um, f.intercept + f.slope * um + 0.12 * crest)
        text = f"{side} {f.angle_deg:.1f} deg"
        tw = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, 0.5 * t + 0.2, t)[0][0]
        px = px - tw - 10 * t if side == "left" else px + 10 * t
        _label(img, text, (min(max(px, 5), w - tw - 5), max(py, 20 * t)), t)
    _label(img, f"angle of repose {angle:.1f} deg   floor tilt {tilt:+.2f} deg", (10, 10 + 14 * t), t)
    _label(img, "yellow: top boundary   cyan: floor line   magenta: fitted band   red: fitted line",
           (10, img.shape[0] - 8 * t), 1, scale=0.25 * t + 0.2)
    return _write(img, path)
