"""Side-view images of granular heaps: realistic lab photos and DEM silhouettes.

Three functions, one per use:

- :func:`heap_profile` makes a heap surface with known flank angles (the ground truth of the
  photo tests);
- :func:`heap_photo` renders a photograph of a heap whose top surface follows a given
  profile: root segments on a floor, in front of grid paper, with uneven light, camera roll,
  blur, sensor noise and JPEG compression;
- :func:`silhouette` projects the spheres of a DEM heap onto the x-z plane, so that the
  simulated heap is measured by the same photo estimator
  (:func:`measure.repose.angle_from_photo`) as the lab's photos.

Conventions: lengths in metres, x horizontal (to the right in the image), z up, the floor at
z = 0. Images are ``uint8``; photos are BGR (OpenCV's channel order).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from scipy import ndimage

from demcal.errors import InputError

#: Size of one cut root segment of the source paper: 11 mm x 25 mm [m].
SEGMENT_LENGTH_M = 0.025
SEGMENT_DIAMETER_M = 0.011

HEAP_TONES = ("dark", "light")

_SHIFT = 4                 # OpenCV sub-pixel drawing: coordinates in 1/16 px
_ONE = 1 << _SHIFT


@dataclass(frozen=True)
class Lighting:
    """Uneven illumination of a heap photo.

    Attributes
    ----------
    gradient : float
        Relative change of the scene illumination across the frame along ``direction_deg``
        [-]; 0.3 means from 85 % to 115 % of the mean.
    direction_deg : float
        Direction, in the image, toward which the light increases, counter-clockwise from the
        +x axis [deg]. 135 is light from the upper left.
    vignetting : float
        Relative darkening of the frame corners by the lens [-]; 0.3 means 70 % at the corners.
    exposure : float
        Overall gain [-].
    shadow : float
        Darkening of the backdrop in the heap's soft cast shadow [-].
    """

    gradient: float = 0.25
    direction_deg: float = 135.0
    vignetting: float = 0.25
    exposure: float = 1.0
    shadow: float = 0.12

    def to_dict(self) -> dict:
        return {"gradient": self.gradient, "direction_deg": self.direction_deg,
                "vignetting": self.vignetting, "exposure": self.exposure, "shadow": self.shadow}


# Colours (BGR, 0..255). The segments are light brownish-yellow cut roots with a pale cut face
# and a thin brown bark; what is seen between them is their shadow.
_SEGMENT_BGR = np.array([122.0, 180.0, 212.0])
_BROWNER = np.array([-14.0, -8.0, 4.0])      # direction of colour variation: redder, darker
_CUT_FACE_BGR = np.array([168.0, 214.0, 234.0])
_BARK_BGR = np.array([70.0, 112.0, 150.0])
_GAP_BGR = np.array([38.0, 62.0, 84.0])
# Backdrops: white graph paper with green lines (the heap looks darker), or a dark green
# cutting mat with pale lines (the heap looks lighter). The floor is on the heap's side of the
# backdrop: a steel plate in front of the paper, a white board in front of the mat.
_SCENES = {
    "dark": {"backdrop": (232.0, 240.0, 243.0), "minor": (196.0, 222.0, 190.0),
             "major": (150.0, 196.0, 140.0), "floor": (142.0, 140.0, 136.0),
             "floor_front": (105.0, 104.0, 102.0), "bench": (78.0, 88.0, 98.0),
             "segment_gain": 0.85},
    "light": {"backdrop": (52.0, 72.0, 32.0), "minor": (92.0, 118.0, 78.0),
              "major": (150.0, 178.0, 150.0), "floor": (206.0, 210.0, 212.0),
              "floor_front": (176.0, 182.0, 186.0), "bench": (160.0, 184.0, 204.0),
              "segment_gain": 1.12},
}


def heap_profile(angle_left_deg, angle_right_deg, *, height_m=0.10, crest_width_m=0.0,
                 plateau_m=0.30, floor_m=0.08, roughness_m=0.0,
                 correlation_m=SEGMENT_LENGTH_M, trend_free_band=(0.15, 0.85), rng=None,
                 step_m=0.001):
    """Surface of a heap with known flank angles: a triangle, trapezoid or single slope.

    A two-flank heap (both angles given) is a cone section: the left flank rises at
    ``angle_left_deg`` to a crest of width ``crest_width_m`` at ``height_m``, the right flank
    falls at ``angle_right_deg``. A single-flank heap (one angle ``None``) is the heap left by
    the plate-withdrawal rig: a plateau of length ``plateau_m`` at ``height_m`` (the material
    held back by the box), then one slope down to the floor. ``floor_m`` of flat floor (z = 0)
    is added beyond each toe.

    Optional roughness, of the order of a segment, is a Gaussian random field of correlation
    length ``correlation_m``, tapered to zero at the toes and at the crest height (the floor
    stays flat and the crest keeps its height), then made free of any least-squares linear
    trend over each whole flank and over the part of each flank between the heights
    ``trend_free_band`` (fractions of ``height_m``), and scaled to a root-mean-square of
    ``roughness_m`` over the flanks. A least-squares line through either part of a rough flank
    thus has exactly the requested angle: the ground truth stays defined.

    Parameters
    ----------
    angle_left_deg, angle_right_deg : float or None
        Flank angles above the horizontal [deg], in (0, 90); ``None`` for no flank on that
        side (at most one).
    height_m : float
        Crest height above the floor [m].
    crest_width_m : float
        Width of the flat top of a two-flank heap [m].
    plateau_m : float
        Length of the plateau of a single-flank heap [m].
    floor_m : float
        Length of floor kept beyond each toe [m].
    roughness_m : float
        Root-mean-square roughness over the flanks [m]; 0 for a smooth profile.
    correlation_m : float
        Correlation length of the roughness, the distance at which its autocorrelation falls
        to 1/e [m].
    trend_free_band : (float, float)
        Heights, as fractions of ``height_m``, between which the roughness of each flank has
        no linear trend (besides the whole flank) [-].
    rng : numpy.random.Generator or int, optional
        Random source, required when ``roughness_m > 0``.
    step_m : float
        Spacing of the profile points [m].

    Returns
    -------
    x, z : numpy.ndarray
        Profile abscissae, increasing, and heights above the floor [m].
    """
    angles = {"angle_left_deg": angle_left_deg, "angle_right_deg": angle_right_deg}
    if angle_left_deg is None and angle_right_deg is None:
        raise InputError("heap_profile: give at least one of angle_left_deg, angle_right_deg")
    for name, value in angles.items():
        if value is not None and not (0.0 < float(value) < 90.0):
            raise InputError(f"heap_profile: {name} must be in (0, 90) deg, got {value!r}")
    for name, value in {"height_m": height_m, "step_m": step_m, "correlation_m": correlation_m}.items():
        if not float(value) > 0.0:
            raise InputError(f"heap_profile: {name} must be positive, got {value!r}")
    for name, value in {"crest_width_m": crest_width_m, "plateau_m": plateau_m,
                        "floor_m": floor_m, "roughness_m": roughness_m}.items():
        if not float(value) >= 0.0:
            raise InputError(f"heap_profile: {name} must be >= 0, got {value!r}")

    # Corner points of the smooth profile, left to right.
    h = float(height_m)
    if angle_left_deg is None:
        run_r = h / math.tan(math.radians(angle_right_deg))
        corners = [(-plateau_m, h), (0.0, h), (run_r, 0.0), (run_r + floor_m, 0.0)]
        flanks = [(0.0, run_r)]
    elif angle_right_deg is None:
        run_l = h / math.tan(math.radians(angle_left_deg))
        corners = [(-run_l - floor_m, 0.0), (-run_l, 0.0), (0.0, h), (plateau_m, h)]
        flanks = [(-run_l, 0.0)]
    else:
        run_l = h / math.tan(math.radians(angle_left_deg))
        run_r = h / math.tan(math.radians(angle_right_deg))
        half = 0.5 * crest_width_m
        corners = [(-half - run_l - floor_m, 0.0), (-half - run_l, 0.0), (-half, h),
                   (half, h), (half + run_r, 0.0), (half + run_r + floor_m, 0.0)]
        flanks = [(-half - run_l, -half), (half, half + run_r)]
    cx, cz = np.array(corners).T
    n = int(round((cx[-1] - cx[0]) / step_m)) + 1
    x = np.linspace(cx[0], cx[-1], n)
    # Keep the corners exactly (the flanks must be exact straight lines between them).
    far = np.min(np.abs(x[:, None] - cx[None, :]), axis=1) > 1e-3 * step_m
    x = np.union1d(x[far], cx)
    z = np.interp(x, cx, cz)

    if roughness_m > 0.0:
        if rng is None:
            raise InputError("heap_profile: roughness_m > 0 needs an explicit rng (seed or Generator)")
        rng = np.random.default_rng(rng)
        sigma = 0.5 * correlation_m / step_m     # kernel sd: correlation falls to 1/e at 2 sigma
        pad = int(4 * sigma) + 1
        white = rng.standard_normal(x.size + 2 * pad)
        r = ndimage.gaussian_filter1d(white, sigma)[pad:pad + x.size]
        r *= roughness_m / r.std()
        # Taper to zero at the floor and at the crest height, so that the toes stay on the
        # floor and the crest keeps its height.
        taper = np.clip(z / (3.0 * roughness_m), 0.0, 1.0) * np.clip((h - z) / (3.0 * roughness_m), 0.0, 1.0)
        rough = r * taper
        on_flanks = np.zeros(x.size, bool)
        for a, b in flanks:
            rough = _trend_free(x, z, rough, a, b, h, trend_free_band)
            on_flanks |= (x >= a) & (x <= b)
        # Removing the trends takes out the long waves: rescale to the requested deviation.
        rough *= roughness_m / np.sqrt(np.mean(rough[on_flanks] ** 2))
        z = np.maximum(z + rough, 0.0)
    return x, z


def _trend_free(x, z, rough, a, b, height, band):
    """Remove from ``rough`` the linear trends over the flank [a, b] and over its part whose
    smooth height is within ``band``: subtract two lines, each weighted by a bump vanishing at
    the ends of its range (the profile stays continuous), solved so that
    sum(rough_new * [1, x]) = 0 over both ranges."""
    flank = (x >= a) & (x <= b)
    part = flank & (z >= band[0] * height) & (z <= band[1] * height)
    xm = x - 0.5 * (a + b)
    cols, rows = [], []
    for on in (flank, part):
        xs = x[on]
        if xs.size < 3:
            continue
        bump = np.zeros_like(x)
        bump[on] = np.sin(np.pi * (xs - xs[0]) / (xs[-1] - xs[0]))
        cols += [bump, bump * xm]
        rows += [on, on]
    # Constraint k: sum over range_k of (rough - sum_j c_j col_j) * basis_k = 0.
    basis = [np.ones_like(x), xm] * (len(rows) // 2)
    m = np.array([[np.sum((col * bk)[rk]) for col in cols] for bk, rk in zip(basis, rows)])
    rhs = np.array([np.sum((rough * bk)[rk]) for bk, rk in zip(basis, rows)])
    coef = np.linalg.solve(m, rhs)
    return rough - sum(c * col for c, col in zip(coef, cols))


#: A heap photo's default height and width [px] and scale [px/m].
PHOTO_SIZE = (900, 1200)
PHOTO_PX_PER_M = 2500.0


def heap_photo(profile_x_m, profile_z_m, *, rng, px_per_m=PHOTO_PX_PER_M, camera_roll_deg=0.0,
               light=None, noise_sd=3.0, blur_px=1.0, jpeg_quality=None, grid=True,
               texture=True, heap_tone="dark", size=PHOTO_SIZE, floor_row=0.78,
               centre_x_m=None, strays=4, particle_m=(SEGMENT_LENGTH_M, SEGMENT_DIAMETER_M),
               spheres=None):
    """Photograph of a heap of particles (cut root segments by default) seen from the side.

    The scene, in the plane of the profile: a backdrop (grid paper), a floor plate whose far
    edge is the line z = 0, and the heap, the region between the floor and the piecewise
    linear profile, filled with capsules of the particle's size (light brownish-yellow, with
    bark, cut faces on elongated ones and shadowed gaps) and lined along its surface with
    particles lying on the slope; a few have rolled past the toes. The camera then
    adds, in order: illumination gradient, camera roll, vignetting, defocus blur, sensor noise
    and JPEG compression.

    Parameters
    ----------
    profile_x_m, profile_z_m : array_like
        Heap surface, x increasing, z >= 0 above the floor [m] (e.g. from
        :func:`heap_profile`). Beyond its ends there is floor only.
    rng : numpy.random.Generator or int
        Random source (segment layout, textures, noise).
    px_per_m : float
        Image scale [px/m].
    camera_roll_deg : float
        Roll of the camera about its optical axis [deg]. The scene, and the floor, appear
        rotated counter-clockwise by this angle: a positive roll makes the floor rise to the
        right of the image.
    light : Lighting, optional
        Illumination; ``Lighting()`` by default.
    noise_sd : float
        Standard deviation of the additive sensor noise [grey levels].
    blur_px : float
        Standard deviation of the Gaussian defocus blur [px]; 0 for none.
    jpeg_quality : int, optional
        JPEG quality (1..100) of a compression round trip; ``None`` for none.
    grid : bool
        Draw the grid lines of the backdrop.
    texture : bool
        Draw the heap as individual segments; if False it is a flat, shaded region.
    heap_tone : {"dark", "light"}
        "dark": the heap is darker than the backdrop (white graph paper, steel floor);
        "light": lighter (dark green cutting mat, white floor board).
    size : (int, int)
        Image height and width [px].
    floor_row : float
        Row of the floor line at the image centre, as a fraction of the height [-].
    centre_x_m : float, optional
        Profile abscissa shown at the image centre [m]; the middle of the profile by default.
    strays : int
        Number of particles lying on the floor beyond the toes.
    particle_m : (float, float)
        Length and width of one particle as the photo shows it lying down [m]
        (``Shape.outline_m``); a root segment of the source paper by default. Equal values
        draw round particles.
    spheres : (centres, radii), optional
        The heap's own spheres, centres ``(n, 3)`` [m] (x along the profile, y along the line
        of sight, z up) and radii ``(n,)`` [m]: a simulated heap photographed as it lies, each
        sphere a shaded disc, nearest the camera (smallest y) in front, instead of a heap
        drawn under the profile (``texture``, ``strays`` and ``particle_m`` are then unused).
        The outline is the spheres' own, as the twin's side view shows them
        (``simulate.render.silhouette``).

    Returns
    -------
    numpy.ndarray
        ``uint8`` BGR image of shape ``(h, w, 3)``.
    """
    if rng is None:
        raise InputError("heap_photo: rng must be a seed or numpy.random.Generator, got None")
    rng = np.random.default_rng(rng)
    x = np.asarray(profile_x_m, dtype=float)
    z = np.asarray(profile_z_m, dtype=float)
    if x.ndim != 1 or x.shape != z.shape or x.size < 2:
        raise InputError(f"heap_photo: profile_x_m and profile_z_m must be 1-D of equal length "
                         f">= 2, got shapes {x.shape} and {z.shape}")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(z))):
        raise InputError("heap_photo: the profile has non-finite values")
    if np.any(np.diff(x) <= 0):
        raise InputError("heap_photo: profile_x_m must be strictly increasing")
    if np.any(z < 0):
        raise InputError(f"heap_photo: profile_z_m must be >= 0 (floor at 0), min is {z.min()!r}")
    if heap_tone not in HEAP_TONES:
        raise InputError(f"heap_photo: heap_tone must be one of {HEAP_TONES}, got {heap_tone!r}")
    if not px_per_m > 0:
        raise InputError(f"heap_photo: px_per_m must be positive, got {px_per_m!r}")
    if not abs(camera_roll_deg) <= 20.0:
        raise InputError(f"heap_photo: camera_roll_deg must be within +-20, got {camera_roll_deg!r}")
    if jpeg_quality is not None and not 1 <= int(jpeg_quality) <= 100:
        raise InputError(f"heap_photo: jpeg_quality must be in 1..100, got {jpeg_quality!r}")
    try:
        h, w = (int(v) for v in size)
    except (TypeError, ValueError):
        raise InputError(f"heap_photo: size must be (height, width), got {size!r}") from None
    if h < 64 or w < 64:
        raise InputError(f"heap_photo: size must be at least 64 x 64 px, got {size!r}")
    if noise_sd < 0 or blur_px < 0:
        raise InputError(f"heap_photo: noise_sd and blur_px must be >= 0, got {noise_sd!r}, {blur_px!r}")
    light = Lighting() if light is None else light
    scene = _SCENES[heap_tone]

    # Canvas large enough that the rotated h x w frame stays inside it.
    th = math.radians(camera_roll_deg)
    cw = int(math.ceil(w * abs(math.cos(th)) + h * abs(math.sin(th)))) + 8
    ch = int(math.ceil(w * abs(math.sin(th)) + h * abs(math.cos(th)))) + 8
    ox, oy = 0.5 * (cw - w), 0.5 * (ch - h)
    s = float(px_per_m)
    xc = 0.5 * (x[0] + x[-1]) if centre_x_m is None else float(centre_x_m)
    col0 = ox + 0.5 * w - xc * s                 # canvas column of x = 0
    row0 = oy + floor_row * h                    # canvas row of z = 0 (the floor line)
    try:
        length_m, width_m = (float(v) for v in particle_m)
    except (TypeError, ValueError):
        raise InputError(f"heap_photo: particle_m must be (length, width) [m], got {particle_m!r}") from None
    if not (0 < width_m <= length_m < math.inf):
        raise InputError(f"heap_photo: particle_m must be 0 < width <= length [m], got {particle_m!r}")
    seg_len, seg_dia = length_m * s, width_m * s

    img = _backdrop(ch, cw, scene, grid, s, col0, row0, rng)
    img = cv2.GaussianBlur(img, (0, 0), 0.8)     # the backdrop is behind the focal plane
    px = col0 + x * s
    pz = row0 - z * s
    _shadow(img, px, pz, row0, seg_dia, light)
    if spheres is not None:
        centres, radii = _sphere_rows(spheres)
        _discs(img, col0 + centres[:, 0] * s, row0 - centres[:, 2] * s, centres[:, 1], radii * s, scene, rng)
    else:
        _heap(img, px, pz, row0, seg_len, seg_dia, scene, texture, rng)
    if strays and texture and spheres is None:
        _strays(img, px, pz, row0, seg_len, seg_dia, scene, int(strays), rng)
    # The floor plate is in front of the heap's base: drawn last, it hides whatever of the
    # segments at the toes reaches below its far edge.
    _floor(img, scene, row0, s, rng)

    # Scene illumination (a gradient across the frame), then the camera.
    xx = np.arange(cw, dtype=np.float32)[None, :] - 0.5 * cw
    yy = np.arange(ch, dtype=np.float32)[:, None] - 0.5 * ch
    d = math.radians(light.direction_deg)
    proj = (xx * math.cos(d) - yy * math.sin(d)) / max(cw, ch)
    img *= (light.exposure * (1.0 + light.gradient * proj))[..., None]
    rot = cv2.getRotationMatrix2D((0.5 * cw, 0.5 * ch), camera_roll_deg, 1.0)
    img = cv2.warpAffine(img, rot, (cw, ch), flags=cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_REFLECT)
    r0, c0 = int(round(oy)), int(round(ox))
    img = img[r0:r0 + h, c0:c0 + w]
    xx = np.arange(w, dtype=np.float32)[None, :] - 0.5 * w
    yy = np.arange(h, dtype=np.float32)[:, None] - 0.5 * h
    r2 = (xx ** 2 + yy ** 2) / (0.25 * (w * w + h * h))
    img *= (1.0 - light.vignetting * r2)[..., None]
    if blur_px > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur_px)
    if noise_sd > 0:
        # Luminance noise plus a weaker independent noise per channel.
        lum = rng.standard_normal((h, w, 1)).astype(np.float32)
        chroma = rng.standard_normal((h, w, 3)).astype(np.float32)
        img += noise_sd * (0.8 * lum + 0.6 * chroma)
    out = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    if jpeg_quality is not None:
        ok, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)])
        out = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    return out


def silhouette(centres_xz_m, radii_m, *, px_per_m, extent, floor_z_m=0.0):
    """Side view of a DEM heap: the spheres projected onto the x-z plane.

    Each sphere projects to a disc; the floor (z <= ``floor_z_m``) is drawn as part of the
    object so that :func:`measure.repose.angle_from_photo` finds the floor line as it does in a
    photo. Edges are anti-aliased: a pixel's grey level is its covered fraction, from the
    distance of its centre to the circle (exact area to a fraction of a pixel per disc).

    Parameters
    ----------
    centres_xz_m : array_like, shape (n, 2)
        Sphere centres, x and z [m] (the y coordinate, along the line of sight, is dropped).
    radii_m : float or array_like, shape (n,)
        Sphere radii [m].
    px_per_m : float
        Image scale [px/m].
    extent : (float, float, float, float)
        Window ``(x_min, x_max, z_min, z_max)`` shown [m].
    floor_z_m : float or None
        Height of the floor [m]; ``None`` draws no floor.

    Returns
    -------
    numpy.ndarray
        ``uint8`` grey image, object (spheres and floor) 0, background 255; row 0 is z_max.
    """
    c = np.asarray(centres_xz_m, dtype=float).reshape(-1, 2)
    r = np.broadcast_to(np.asarray(radii_m, dtype=float), (c.shape[0],))
    if not px_per_m > 0:
        raise InputError(f"silhouette: px_per_m must be positive, got {px_per_m!r}")
    try:
        x0, x1, z0, z1 = (float(v) for v in extent)
    except (TypeError, ValueError):
        raise InputError(f"silhouette: extent must be (x_min, x_max, z_min, z_max), got {extent!r}") from None
    if not (x1 > x0 and z1 > z0):
        raise InputError(f"silhouette: extent must have x_max > x_min and z_max > z_min, got {extent!r}")
    if np.any(~np.isfinite(c)) or np.any(~np.isfinite(r)) or np.any(r <= 0):
        raise InputError("silhouette: centres must be finite and radii positive")
    s = float(px_per_m)
    w, h = int(round((x1 - x0) * s)), int(round((z1 - z0) * s))
    if w < 8 or h < 8 or w * h > 64e6:
        raise InputError(f"silhouette: image of {h} x {w} px from extent {extent!r} and "
                         f"px_per_m {px_per_m!r} is out of range")
    # Coverage of each pixel (0..1); pixel (i, j) is the square [j, j+1) x [i, i+1).
    cover = np.zeros((h, w), np.float32)
    if floor_z_m is not None:
        fr = (z1 - float(floor_z_m)) * s              # floor line, in rows from the top
        rows = np.arange(h, dtype=np.float32)
        cover[:] = np.clip(rows + 1.0 - fr, 0.0, 1.0)[:, None]
    cols = (c[:, 0] - x0) * s
    rows = (z1 - c[:, 1]) * s
    rad = r * s
    keep = (cols + rad > 0) & (cols - rad < w) & (rows + rad > 0) & (rows - rad < h)
    for cc, rr, ra in zip(cols[keep], rows[keep], rad[keep]):
        # Anti-aliased disc: coverage from the distance of the pixel centre to the circle.
        i0, i1 = max(int(rr - ra) - 1, 0), min(int(rr + ra) + 2, h)
        j0, j1 = max(int(cc - ra) - 1, 0), min(int(cc + ra) + 2, w)
        dist = np.hypot(np.arange(j0, j1, dtype=np.float32)[None, :] + 0.5 - cc,
                        np.arange(i0, i1, dtype=np.float32)[:, None] + 0.5 - rr)
        np.maximum(cover[i0:i1, j0:j1], np.clip(ra - dist + 0.5, 0.0, 1.0), out=cover[i0:i1, j0:j1])
    return np.rint(255.0 * (1.0 - cover)).astype(np.uint8)


# ----------------------------------------------------------------------------------------
# Scene parts (canvas drawing; float32 BGR images, modified in place)

def _pt(x, y):
    return int(round(x * _ONE)), int(round(y * _ONE))


def _backdrop(ch, cw, scene, grid, s, col0, row0, rng):
    """Backdrop with mottled light, paper grain and grid lines every 5 mm (stronger every
    10 mm, thicker every 50 mm), aligned with the floor."""
    base = np.array(scene["backdrop"], np.float32)
    img = np.empty((ch, cw, 3), np.float32)
    img[:] = base
    mottle = ndimage.gaussian_filter(rng.standard_normal((ch // 8 + 1, cw // 8 + 1)), 6)
    mottle = cv2.resize((mottle / (mottle.std() + 1e-12)).astype(np.float32), (cw, ch))
    grain = ndimage.gaussian_filter(rng.standard_normal((ch, cw)), 0.7).astype(np.float32)
    img *= (1.0 + 0.015 * mottle + 0.012 * grain)[..., None]
    if grid:
        pitch = 0.005 * s
        k0 = int(math.floor(-col0 / pitch)) - 1
        k1 = int(math.ceil((cw - col0) / pitch)) + 1
        for k in range(k0, k1):
            c = col0 + k * pitch
            colour = scene["major"] if k % 2 == 0 else scene["minor"]
            thick = 2 if (k % 10 == 0 and pitch > 8) else 1
            cv2.line(img, _pt(c, 0), _pt(c, row0), colour, thick, cv2.LINE_AA, _SHIFT)
        for k in range(1, int(row0 / pitch) + 2):
            r = row0 - k * pitch
            colour = scene["major"] if k % 2 == 0 else scene["minor"]
            thick = 2 if (k % 10 == 0 and pitch > 8) else 1
            cv2.line(img, _pt(0, r), _pt(cw, r), colour, thick, cv2.LINE_AA, _SHIFT)
    return img


def _floor(img, scene, row0, s, rng):
    """Floor plate below z = 0: top face seen at a grazing angle, front edge, then the bench."""
    ch, cw = img.shape[:2]
    r0 = int(math.ceil(row0))
    above = img[r0 - 1].copy() if r0 > 0 else None
    top = max(int(0.035 * s), 6)                # visible depth of the top face [px]
    edge = max(int(0.004 * s), 2)               # plate thickness [px]
    rows = np.arange(r0, ch, dtype=np.float32)
    colour = np.empty((rows.size, 3), np.float32)
    t = np.clip((rows - r0) / top, 0, 1)[:, None]
    colour[:] = np.array(scene["floor"]) * (0.93 + 0.1 * t)     # brighter toward the viewer
    front = (rows >= r0 + top) & (rows < r0 + top + edge)
    colour[front] = scene["floor_front"]
    colour[rows >= r0 + top + edge] = scene["bench"]
    img[r0:] = colour[:, None, :]
    # Brushed / grained texture: horizontal streaks.
    streak = ndimage.gaussian_filter(rng.standard_normal((ch - r0, cw)), (0.6, 25.0))
    img[r0:] *= (1.0 + 0.025 * streak / (streak.std() + 1e-12))[..., None].astype(np.float32)
    if above is not None:
        # The row cut by the floor line: blend backdrop and floor by the covered fraction.
        f = r0 - row0
        img[r0 - 1] = (1.0 - f) * above + f * img[r0]


def _shadow(img, px, pz, row0, seg_dia, light):
    """Soft shadow of the heap, cast away from the light onto the backdrop behind it (the
    floor seen in front of the heap is lit)."""
    ch, cw = img.shape[:2]
    d = math.radians(light.direction_deg)
    off = 1.2 * seg_dia
    poly = np.concatenate([np.c_[px - off * math.cos(d), pz + off * math.sin(d)],
                           [[px[-1], row0 + seg_dia], [px[0], row0 + seg_dia]]])
    # Drawn and blurred at a quarter of the resolution: the shadow is soft anyway.
    q = 4
    small = np.zeros((ch // q + 1, cw // q + 1), np.float32)
    cv2.fillPoly(small, [np.round(poly / q * _ONE).astype(np.int32)], 1.0, cv2.LINE_AA, _SHIFT)
    small = cv2.GaussianBlur(small, (0, 0), 1.5 * seg_dia / q)
    mask = cv2.resize(small, (cw, ch), interpolation=cv2.INTER_LINEAR)
    mask[int(math.ceil(row0)):] = 0.0
    img *= (1.0 - light.shadow * mask)[..., None]


def _segment_colour(scene, rng):
    gain = scene["segment_gain"] * math.exp(rng.normal(0.0, 0.08))
    brown = abs(rng.normal(0.0, 1.0))
    return _bgr(_SEGMENT_BGR * gain + brown * _BROWNER + rng.normal(0.0, 2.0, 3))


def _bgr(c, gain=1.0, add=0.0):
    """Colour tuple for OpenCV: gain * c + add, clipped to 0..255."""
    return tuple(min(255.0, max(0.0, gain * float(v) + add)) for v in c)


#: Shading of a round body seen from the side: nested strokes (width as a fraction of the
#: diameter, brightness gain, shift toward the light), from the dark limb to the lit middle.
_SHADING = ((1.0, 0.68, 0.0), (0.82, 0.85, 0.04), (0.6, 0.96, 0.08), (0.34, 1.06, 0.14), (0.14, 1.12, 0.2))


def _draw_segment(img, cx, cy, phi, seg_len, seg_dia, tilt, colour, rng, floor_row=None):
    """One root segment: a shaded capsule with bark wrinkles and, when tilted toward the
    camera by ``tilt`` [rad], an elliptical cut face at one end; seen end-on it is a disc.
    With ``floor_row`` it rests on the floor (its lowest point on that row)."""
    dia = seg_dia * rng.uniform(0.85, 1.15)
    proj = max(seg_len * rng.uniform(0.85, 1.15) * math.cos(tilt), dia)
    u = np.array([math.cos(phi), -math.sin(phi)])          # axis, image coordinates
    v = np.array([math.sin(phi), math.cos(phi)])           # across the axis
    half = 0.5 * (proj - dia)
    if floor_row is not None:
        cy = floor_row - half * abs(u[1]) - 0.5 * dia  # resting on the floor
    p1 = (cx - half * u[0], cy - half * u[1])
    p2 = (cx + half * u[0], cy + half * u[1])
    # Cylinder shading: nested strokes from the dark limb to the lit middle, shifted toward
    # the light (upper left).
    side = -1.0 if v[1] > 0 else 1.0
    for width, gain, shift in _SHADING:
        o = side * shift * dia
        cv2.line(img, _pt(p1[0] + o * v[0], p1[1] + o * v[1]),
                 _pt(p2[0] + o * v[0], p2[1] + o * v[1]), _bgr(colour, gain, (gain - 1) * 30),
                 max(int(round(width * dia)), 1), cv2.LINE_AA, _SHIFT)
    # Longitudinal bark wrinkles.
    for _ in range(rng.integers(1, 5)):
        o = rng.uniform(-0.33, 0.33) * dia
        a, b = sorted(rng.uniform(-1.1, 1.1, 2))
        q1 = (cx + a * half * u[0] + o * v[0], cy + a * half * u[1] + o * v[1])
        q2 = (cx + b * half * u[0] + o * v[0], cy + b * half * u[1] + o * v[1])
        cv2.line(img, _pt(*q1), _pt(*q2), _bgr(colour, rng.uniform(0.7, 0.85)), 1,
                 cv2.LINE_AA, _SHIFT)
    if tilt > math.radians(25) and seg_len > 1.5 * seg_dia:
        # Cut face at the end nearer the camera: cream wood, brown bark ring, dark pith.
        end = p2 if rng.random() < 0.5 else p1
        minor = 0.5 * dia * math.sin(tilt)
        ang = -math.degrees(phi) + 90.0
        face = _bgr(_CUT_FACE_BGR, sum(colour) / _SEGMENT_BGR.sum() * rng.uniform(0.85, 1.0))
        cv2.ellipse(img, _pt(*end), _pt(0.5 * dia, minor), ang, 0, 360, _bgr(_BARK_BGR),
                    -1, cv2.LINE_AA, _SHIFT)
        cv2.ellipse(img, _pt(*end), _pt(0.4 * dia, 0.8 * minor), ang, 0, 360, _bgr(face),
                    -1, cv2.LINE_AA, _SHIFT)
        cv2.ellipse(img, _pt(*end), _pt(0.22 * dia, 0.44 * minor), ang, 0, 360,
                    _bgr(face, 0.88), 1, cv2.LINE_AA, _SHIFT)
        if minor > 2:
            cv2.ellipse(img, _pt(*end), _pt(0.05 * dia, 0.1 * minor), ang, 0, 360,
                        _bgr(_BARK_BGR, 0.8), -1, cv2.LINE_AA, _SHIFT)


def _heap(img, px, pz, row0, seg_len, seg_dia, scene, texture, rng):
    """The heap between the floor line and the profile (px, pz in canvas pixels)."""
    ch, cw = img.shape[:2]
    up = np.nonzero(pz < row0)[0]
    if up.size == 0:
        return
    # Only the part of the profile above the floor (its flat ends are floor, not heap).
    i0, i1 = max(up[0] - 1, 0), min(up[-1] + 1, px.size - 1)
    poly = np.concatenate([np.c_[px[i0:i1 + 1], pz[i0:i1 + 1]], [[px[i1], row0], [px[i0], row0]]])
    mask = np.zeros((ch, cw), np.uint8)
    cv2.fillPoly(mask, [np.round(poly * _ONE).astype(np.int32)], 255, cv2.LINE_AA, _SHIFT)
    mask[int(math.ceil(row0)):] = 0
    inside = mask > 127
    if not inside.any():
        return
    # Depth below the surface (the floor counts as inside), for ambient occlusion.
    solid = mask.copy()
    solid[int(row0):] = 255
    depth = cv2.distanceTransform((solid > 127).astype(np.uint8), cv2.DIST_L2, 5)
    shade = 0.75 + 0.25 * np.exp(-depth / (1.5 * seg_dia))
    layer = np.empty_like(img)
    if texture:
        layer[:] = _GAP_BGR
        rows, cols = np.nonzero(inside)
        n = int(4.0 * rows.size / (seg_len * seg_dia)) + 1
        pick = rng.integers(0, rows.size, n)
        for i in pick:
            tilt = min(abs(rng.normal(0.0, 0.5)), 1.45)
            _draw_segment(layer, cols[i] + rng.uniform(-0.5, 0.5), rows[i] + rng.uniform(-0.5, 0.5),
                          rng.uniform(-math.pi / 2, math.pi / 2), seg_len, seg_dia, tilt,
                          _segment_colour(scene, rng), rng)
    else:
        layer[:] = _SEGMENT_BGR * scene["segment_gain"]
    layer *= shade[..., None]
    alpha = (mask.astype(np.float32) / 255.0)[..., None]
    img[:] = img * (1.0 - alpha) + layer * alpha
    if not texture:
        return
    # Segments lying on the surface, roughly along the local slope.
    seg = np.hypot(np.diff(px), np.diff(pz))
    arc = np.r_[0.0, np.cumsum(seg)]
    on_heap = pz < row0 - 0.3 * seg_dia
    # Two passes: a deeper, disordered layer, then the outermost segments, which make the
    # silhouette and lie roughly along the slope (they came to rest sliding down it).
    for depth_range, step, spread in (((0.9, 1.5), 0.6, 35.0), ((0.35, 0.65), 0.35, 12.0)):
        for a in np.arange(rng.uniform(0, 0.5) * seg_len, arc[-1], step * seg_len):
            i = min(np.searchsorted(arc, a, side="right") - 1, px.size - 2)
            f = (a - arc[i]) / max(seg[i], 1e-9)
            x = px[i] + f * (px[i + 1] - px[i])
            y = pz[i] + f * (pz[i + 1] - pz[i])
            if not (on_heap[i] or on_heap[i + 1]) or not (0 <= x < cw):
                continue
            # Local direction of the surface over about one segment length.
            j0 = max(np.searchsorted(arc, a - 0.5 * seg_len) - 1, 0)
            j1 = min(np.searchsorted(arc, a + 0.5 * seg_len), px.size - 1)
            tx, ty = px[j1] - px[j0], pz[j1] - pz[j0]
            norm = max(math.hypot(tx, ty), 1e-9)
            tx, ty = tx / norm, ty / norm
            nx, ny = -ty, tx                               # inward normal (into the heap)
            if ny < 0:
                nx, ny = -nx, -ny
            depth_in = rng.uniform(*depth_range) * seg_dia
            phi = math.atan2(-ty, tx) + rng.normal(0.0, math.radians(spread))
            tilt = min(abs(rng.normal(0.0, 0.4)), 1.3)
            _draw_segment(img, x + nx * depth_in, y + ny * depth_in, phi, seg_len, seg_dia,
                          tilt, _segment_colour(scene, rng), rng)


def _sphere_rows(spheres):
    try:
        centres, radii = spheres
        centres = np.asarray(centres, dtype=float).reshape(-1, 3)
        radii = np.broadcast_to(np.asarray(radii, dtype=float), (centres.shape[0],))
    except (TypeError, ValueError):
        raise InputError("heap_photo: spheres must be (centres (n, 3), radii (n,)) [m]") from None
    if not (np.all(np.isfinite(centres)) and np.all(np.isfinite(radii)) and np.all(radii > 0)):
        raise InputError("heap_photo: spheres must have finite centres and positive radii")
    return centres, radii


def _discs(img, cx, cy, depth, r, scene, rng):
    """Spheres seen from the side (canvas pixels): the farthest first, each a disc shaded from
    its dark limb to a highlight toward the light (upper left)."""
    for i in np.argsort(-depth, kind="stable"):
        colour = _segment_colour(scene, rng)
        for width, gain, shift in _SHADING:
            o = shift * r[i]
            cv2.circle(img, _pt(cx[i] - o, cy[i] - o), max(int(round(width * r[i] * _ONE)), 1),
                       _bgr(colour, gain, (gain - 1) * 30), -1, cv2.LINE_AA, _SHIFT)


def _strays(img, px, pz, row0, seg_len, seg_dia, scene, n, rng):
    """Segments that rolled past the toes, lying on the floor."""
    on = np.nonzero(pz < row0 - 1.0)[0]
    if on.size == 0:
        return
    toes = [px[on[0]], px[on[-1]]]
    for k in range(n):
        side = k % 2
        dist = seg_len * rng.uniform(0.5, 6.0)
        x = toes[side] + (dist if side else -dist)
        if not (0 <= x < img.shape[1]) or (side == 0 and on[0] == 0) or (side == 1 and on[-1] == px.size - 1):
            continue
        phi = rng.normal(0.0, math.radians(8))
        tilt = min(abs(rng.normal(0.0, 0.5)), 1.3)
        _draw_segment(img, x, row0, phi, seg_len, seg_dia, tilt, _segment_colour(scene, rng), rng,
                      floor_row=row0 + 0.03 * seg_dia)
