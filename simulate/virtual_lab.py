"""The virtual lab: complete lab workbooks made from a known truth, with optional planted effects.

A :class:`Truth` holds what the real material and the real rigs would be (contact parameters,
segment sizes, moisture, the spread from trial to trial, the reading noise of each instrument,
the operators and days of the campaign). :func:`write_virtual_workbook` runs a virtual
campaign of the lab tests of docs/workbook.md and writes every sheet, with realistic
covariates (operator, date, trial order, specimen, moisture, orientation, several drop
heights), plus the files the sheets point to: heap photos, camera tracks and compression
curves. It is how demcal's tests hide an effect in data and require the critique loop to find
it, and how a user can plan an experiment (how many drops, which heights) before making it.

The physics of each test, without planted effects:

drop
    Each drop's apparent restitution sqrt(h2/h1) is the drop twin's (``simulate.rigs.drop``)
    at the drop's orientation: the contact restitution e of the pair times the twin's ratio
    R(orientation) = apparent / contact, precomputed with the drop rig on a 10-degree grid of
    orientations covering the design and interpolated (:func:`drop_twin_ratio`, cached), plus
    a drop-to-drop scatter ``e_sd``. Rebound heights are read to ``height_noise_mm``. By
    default the segments are released end on (orientation 80-90 degrees, a release jig),
    where the twin's apparent restitution is the contact restitution within 1 %.
incline
    tan(angle at onset) is the static friction (slide) or the rolling friction (roll), with a
    specimen-to-specimen scatter ``mu_sd``; the inclinometer is read to ``angle_noise_deg``
    and 0.1 degree.
repose
    Two-flank heaps of angle ``repose_angle_deg`` (heap-to-heap scatter ``repose_sd_deg``),
    rendered by ``simulate.render.heap_photo`` from an analytic heap profile
    (``photos="analytic"``, fast) or from the heap of a repose-rig run (``photos="dem"``),
    with a random, small camera roll that the photo estimator corrects.
specimens, density, compression
    Calliper sizes, masses from the envelope density, displaced volumes read to 0.1 ml,
    Poisson's ratio and force curves of modulus E = 2 G (1 + nu).

Planted effects (:class:`PlantedEffect`, kinds = the critique catalogue):

========================================  =====================================================
kind (default size)                       what changes
========================================  =====================================================
``velocity_dependent_restitution``        contact e of the drop pair(s) changes by ``size``
(-2e-4 per mm)                            per mm of drop height (0.38 at 200 mm to 0.30 at
                                          600 mm around 0.34)
``orientation_rotation`` (0 deg)          segments dropped by hand at random orientations
                                          from ``size`` to 90 deg on every pair, so part of the
                                          energy goes into rotation as in the drop twin
``size_dependence`` (0.02 per mm)         contact e tracks the specimen's length
``block_effect`` (2 deg)                  one operator reads incline angles ``size`` higher
                                          (levels of the covariate offset evenly over ``size``;
                                          by ``date``, the sheet's trials span the days)
``trial_order_drift`` (0.004 per trial)   static friction rises with trial order
``moisture_dependence`` (0.01 per %)      static friction rises with moisture content
``camera_tilt`` (2 deg)                   an uncorrected camera roll: the left flank reads
                                          ``size`` steeper and the right one ``size``
                                          shallower (``quantity="floor"``: the camera is
                                          rolled by ``size`` and the floor shows it)
========================================  =====================================================

The workbook's folder also gets ``truth.json``: the truth, the effects and, for each planted
effect, the true size of what the diagnosis estimates (``VirtualWorkbook.expected``).
"""

from __future__ import annotations

import math
import os
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from demcal.errors import DemcalError, InputError, SimulationError
from demcal.jsonio import read_json, write_json
from demcal.provenance import Provenance, run_key
from demcal.simulate.materials import youngs_modulus
from demcal.simulate.params import DEMParameters
from demcal.simulate.rigs import meta_names, rig as rig_named, rig_of_geometry
from demcal.units import GRAVITY

#: Effect kinds, the identifiers of the critique catalogue that a workbook can carry.
EFFECT_KINDS = ("velocity_dependent_restitution", "orientation_rotation", "size_dependence",
                "block_effect", "trial_order_drift", "moisture_dependence", "camera_tilt")

#: Per kind: default size, sheet, quantity (prefix), covariate and the unit of ``size``.
EFFECT_DEFAULTS = {
    "velocity_dependent_restitution": dict(size=-2.0e-4, sheet="drop", quantity="restitution",
                                           covariate="drop_height_mm", unit="1/mm"),
    "orientation_rotation": dict(size=0.0, sheet="drop", quantity="restitution",
                                 covariate="orientation_deg", unit="deg (lowest release angle)"),
    "size_dependence": dict(size=0.02, sheet="drop", quantity="restitution", covariate="length_mm",
                            unit="1/mm"),
    "block_effect": dict(size=2.0, sheet="incline", quantity="", covariate="operator",
                         unit="deg (incline), 1 (drop e) or deg (repose) between extreme levels"),
    "trial_order_drift": dict(size=0.004, sheet="incline", quantity="static_friction",
                              covariate="trial_order", unit="quantity per trial"),
    "moisture_dependence": dict(size=0.01, sheet="incline", quantity="static_friction",
                                covariate="moisture_pct", unit="quantity per %"),
    "camera_tilt": dict(size=2.0, sheet="repose", quantity="flanks", covariate="side",
                        unit="deg"),
}

#: Sheets each kind may be planted in.
EFFECT_SHEETS = {"velocity_dependent_restitution": ("drop",), "orientation_rotation": ("drop",),
                 "size_dependence": ("drop", "incline"), "block_effect": ("drop", "incline", "repose"),
                 "trial_order_drift": ("drop", "incline"), "moisture_dependence": ("drop", "incline"),
                 "camera_tilt": ("repose",)}

#: Orientation grid spacing of the drop-twin table [deg].
ORIENTATION_STEP_DEG = 10.0

PHOTO_MODES = ("analytic", "dem", "none")


@dataclass(frozen=True)
class Truth:
    """What the virtual material and rigs really are.

    Attributes
    ----------
    params : DEMParameters
        Contact parameters (the truth of e, mu_s, mu_r per pair), particle density, Poisson's
        ratio, shear modulus and the mean segment size.
    e_sd : float
        Drop-to-drop scatter of the apparent restitution [-].
    mu_sd : float
        Specimen-to-specimen scatter of static and rolling friction [-].
    length_sd_m, diameter_sd_m : float
        Spread of segment length and diameter [m].
    size_sd_rel : float
        Relative spread of each size of any other shape [-].
    envelope_ratio : float
        Envelope density / particle density of the segments [-].
    density_sd : float
        Scatter of the displacement density of a sample [kg/m^3].
    moisture_pct, moisture_sd_pct : float
        Mean and spread of the moisture content [%].
    repose_angle_deg, repose_sd_deg : float
        Flank angle of the heaps and its heap-to-heap spread [deg].
    poisson_sd : float
        Specimen scatter of Poisson's ratio [-].
    modulus_sd_rel : float
        Relative specimen scatter of the elastic modulus [-].
    height_noise_mm : float
        Reading noise of a rebound height [mm].
    angle_noise_deg : float
        Reading noise of the inclinometer [deg].
    camera_roll_sd_deg : float
        Spread of the camera roll from photo to photo [deg] (corrected by the estimator).
    operators, batches, days : tuple of str
        Who measures, the segment batches, and the days of the campaign.
    icc : float
        Intraclass correlation of repeated trials on one specimen: the share of the trial
        scatter (``e_sd``, ``mu_sd``) that belongs to the specimen (a random effect per specimen
        and quantity) [-]; 0: trials independent.
    """

    params: DEMParameters = field(default_factory=DEMParameters)
    e_sd: float = 0.03
    mu_sd: float = 0.02
    length_sd_m: float = 1.6e-3
    diameter_sd_m: float = 0.9e-3
    size_sd_rel: float = 0.06
    envelope_ratio: float = 0.965
    density_sd: float = 15.0
    moisture_pct: float = 48.0
    moisture_sd_pct: float = 3.0
    repose_angle_deg: float = 35.8
    repose_sd_deg: float = 0.8
    poisson_sd: float = 0.02
    modulus_sd_rel: float = 0.05
    height_noise_mm: float = 1.0
    angle_noise_deg: float = 0.3
    camera_roll_sd_deg: float = 0.5
    operators: tuple = ("op1", "op2")
    batches: tuple = ("B1", "B2", "B3")
    days: tuple = ("2024-03-04", "2024-03-05", "2024-03-06")
    icc: float = 0.0

    def __post_init__(self):
        if not isinstance(self.params, DEMParameters):
            raise InputError(f"Truth.params must be a DEMParameters, got {type(self.params).__name__}")
        for name in ("e_sd", "mu_sd", "length_sd_m", "diameter_sd_m", "size_sd_rel", "density_sd", "moisture_sd_pct",
                     "repose_sd_deg", "poisson_sd", "modulus_sd_rel", "height_noise_mm",
                     "angle_noise_deg", "camera_roll_sd_deg"):
            if not getattr(self, name) >= 0:
                raise InputError(f"Truth.{name} must be >= 0, got {getattr(self, name)!r}")
        if not 0 <= self.icc < 1:
            raise InputError(f"Truth.icc must be in [0, 1), got {self.icc!r}")
        if not 0 < self.repose_angle_deg < 80:
            raise InputError(f"Truth.repose_angle_deg must be in (0, 80), got {self.repose_angle_deg!r}")
        for name in ("operators", "batches", "days"):
            if not getattr(self, name):
                raise InputError(f"Truth.{name} must name at least one level")

    def restitution(self, pair: str) -> float:
        """Contact restitution of a drop pair [-] (``particle-steel`` or ``particle-particle``)."""
        if pair == "particle-steel":
            return self.params.e_pw
        if pair == "particle-particle":
            return self.params.e_pp
        raise InputError(f"the virtual lab drops on particle-steel or particle-particle, got {pair!r}")

    def friction(self, surface: str, mode: str) -> float:
        """Static (``slide``) or rolling (``roll``) friction on ``steel`` or ``particle`` [-]."""
        p = self.params
        table = {("steel", "slide"): p.mu_s_pw, ("steel", "roll"): p.mu_r_pw,
                 ("particle", "slide"): p.mu_s_pp, ("particle", "roll"): p.mu_r_pp}
        try:
            return table[(surface, mode)]
        except KeyError:
            raise InputError(f"the virtual lab tilts on steel or particle plates, slide or roll; "
                             f"got {surface!r}, {mode!r}") from None

    def to_dict(self) -> dict:
        d = asdict(self)
        d["params"] = self.params.to_dict()
        return d


@dataclass(frozen=True)
class PlantedEffect:
    """An effect hidden in a virtual workbook (see the module docstring for the kinds).

    Attributes
    ----------
    kind : str
        One of ``EFFECT_KINDS``.
    size : float, optional
        Size in the unit of the kind (``EFFECT_DEFAULTS``); default the kind's.
    sheet : str, optional
        Sheet it is planted in; default the kind's.
    quantity : str, optional
        Quantity name or family prefix it acts on (e.g. ``restitution``,
        ``restitution.particle-steel``, ``static_friction``; ``""`` = every quantity of the
        sheet); for ``camera_tilt``, ``flanks`` or ``floor``. Default: the kind's in its
        default sheet, every quantity in another sheet.
    covariate : str, optional
        For ``block_effect``: ``operator``, ``date`` or ``batch``.
    """

    kind: str
    size: float | None = None
    sheet: str | None = None
    quantity: str | None = None
    covariate: str | None = None

    def __post_init__(self):
        if self.kind not in EFFECT_KINDS:
            extra = (" (ill_conditioned_parameter is a property of a calibration campaign, not "
                     "of a workbook)") if self.kind == "ill_conditioned_parameter" else ""
            raise InputError(f"unknown planted effect {self.kind!r}{extra}; valid: {', '.join(EFFECT_KINDS)}")
        d = EFFECT_DEFAULTS[self.kind]
        if self.quantity is None and self.sheet not in (None, d["sheet"]):
            object.__setattr__(self, "quantity", "")   # another sheet: every quantity of it
        for name in ("size", "sheet", "quantity", "covariate"):
            if getattr(self, name) is None:
                object.__setattr__(self, name, d[name])
        if not math.isfinite(float(self.size)):
            raise InputError(f"planted effect {self.kind}: size must be a finite number, got {self.size!r}")
        if self.sheet not in EFFECT_SHEETS[self.kind]:
            raise InputError(f"planted effect {self.kind}: sheet must be one of "
                             f"{', '.join(EFFECT_SHEETS[self.kind])}, got {self.sheet!r}")
        if self.kind == "block_effect" and self.covariate not in ("operator", "date", "batch"):
            raise InputError(f"block_effect: covariate must be operator, date or batch, got {self.covariate!r}")
        if self.kind == "camera_tilt" and self.quantity not in ("flanks", "floor"):
            raise InputError(f"camera_tilt: quantity must be 'flanks' or 'floor', got {self.quantity!r}")
        if self.kind == "orientation_rotation" and not 0 <= self.size < 90:
            raise InputError(f"orientation_rotation: size (lowest release angle) must be in [0, 90) deg, "
                             f"got {self.size!r}")

    def acts_on(self, quantity: str) -> bool:
        """Whether the effect changes quantity ``quantity`` of its sheet."""
        q = self.quantity
        return not q or quantity == q or quantity.startswith(q + ".")

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class VirtualWorkbook:
    """A workbook written by :func:`write_virtual_workbook`.

    Attributes
    ----------
    path : Path
        What ``measure.workbook.read_workbook`` takes (the ``.xlsx`` or the CSV folder).
    truth : Truth
    effects : tuple of PlantedEffect
    expected : tuple of dict
        For each planted effect and quantity it acts on: ``kind``, ``sheet``, ``quantity``,
        ``covariate``, ``true_effect`` (the size of what the diagnosis estimates, computed on
        the noise-free rows: the least-squares slope on the covariate, the range of the level
        means for a block, the mean for a flank difference or floor tilt) and ``unit``.
    seed : int or None
        Seed of the generator when an int was given.
    provenance : Provenance
    """

    path: Path
    truth: Truth
    effects: tuple
    expected: tuple
    seed: int | None
    provenance: Provenance

    def to_dict(self) -> dict:
        return {"path": str(self.path), "truth": self.truth.to_dict(),
                "effects": [e.to_dict() for e in self.effects], "expected": [dict(x) for x in self.expected],
                "seed": self.seed, "provenance": self.provenance.to_dict()}


# ----------------------------------------------------------------------------------------------
# the drop twin table


_DROP_CACHE: dict = {}


def _drop_point(params: DEMParameters, pair: str, height_m: float, orientation_deg: float,
                cache_dir) -> float:
    """Apparent restitution of the drop twin at one orientation (cached in memory and on disk)."""
    inputs = {"params": params.to_dict(), "pair": pair, "height": round(float(height_m), 6),
              "orientation_deg": round(float(orientation_deg), 6)}
    key = run_key(inputs)
    if key in _DROP_CACHE:
        return _DROP_CACHE[key]
    path = Path(cache_dir) / f"drop-{key}.json" if cache_dir else None
    if path is not None and path.is_file():
        value = float(read_json(path)["apparent_restitution"])
    else:
        from demcal.simulate.rigs import run_rig
        result = run_rig("drop", params, 0, height=float(height_m), orientation_deg=float(orientation_deg),
                         pair=pair)
        value = float(result.observable["apparent_restitution"])
        if path is not None:
            write_json(path, {"inputs": inputs, "apparent_restitution": value})
    _DROP_CACHE[key] = value
    return value


def drop_twin_ratio(params: DEMParameters, pair: str, height_m: float, orientation_deg, *,
                    cache_dir=None) -> np.ndarray:
    """Ratio apparent / contact restitution of the drop twin at the given orientations.

    The drop rig is run at the points of a ``ORIENTATION_STEP_DEG`` grid that cover the
    orientations asked for (each point once per parameter set, pair and height; cached in
    memory and, with ``cache_dir`` or the environment variable ``DEMCAL_CACHE``, on disk) and
    the ratio is interpolated linearly between them.

    Parameters
    ----------
    params : DEMParameters
        Contact parameters of the twin (its restitution of ``pair`` is the contact one).
    pair : str
        ``particle-steel`` or ``particle-particle``.
    height_m : float
        Drop height [m].
    orientation_deg : array_like
        Angles of the long axis to the horizontal at release [deg], in [0, 90].

    Returns
    -------
    numpy.ndarray
        R [-], one per orientation.
    """
    from demcal.simulate.extensions import restitution_parameter

    o = np.atleast_1d(np.asarray(orientation_deg, dtype=float))
    if np.any((o < 0) | (o > 90)):
        raise InputError("orientation_deg must lie in [0, 90] deg")
    cache_dir = cache_dir or os.environ.get("DEMCAL_CACHE") or None
    step = ORIENTATION_STEP_DEG
    lo = step * math.floor(o.min() / step)
    hi = step * math.ceil(o.max() / step)
    grid = np.arange(lo, hi + 0.5 * step, step) if hi > lo else np.array([lo])
    e = getattr(params, restitution_parameter(pair))
    ratio = np.array([_drop_point(params, pair, height_m, g, cache_dir) for g in grid]) / e
    return np.interp(o, grid, ratio) if grid.size > 1 else np.full(o.shape, ratio[0])


# ----------------------------------------------------------------------------------------------
# helpers


def _slope(x, y) -> float:
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    xc = x - x.mean()
    sxx = float(xc @ xc)
    return float(xc @ (y - y.mean()) / sxx) if sxx > 0 else math.nan


def _block_range(levels, y) -> float:
    frame = pd.DataFrame({"g": list(levels), "y": np.asarray(y, dtype=float)})
    means = frame.groupby("g")["y"].mean()
    return float(means.max() - means.min())


def _level_offset(levels: tuple, value, size: float) -> float:
    """Offset of one level: levels spread evenly from 0 to ``size`` in their given order."""
    if len(levels) < 2:
        return 0.0
    return size * levels.index(value) / (len(levels) - 1)


def camera_track(rng: np.random.Generator, drop_height_m: float, e: float, *, fps: float = 1000.0,
                 g: float = GRAVITY, pixel_mm: float = 0.4, noise_mm: float = 0.15) -> pd.DataFrame:
    """High-speed-camera track of a drop: free fall from rest at ``drop_height_m``, impact,
    rebound at ``e`` times the impact speed; positions with Gaussian noise [mm], quantised to
    the pixel size. Columns ``t_s``, ``y_mm``."""
    v_in = math.sqrt(2.0 * g * drop_height_m)
    t_impact = v_in / g
    t = np.arange(0.2 * t_impact, t_impact + 1.8 * e * v_in / g, 1.0 / fps)
    y = np.where(t < t_impact, drop_height_m - 0.5 * g * t ** 2,
                 e * v_in * (t - t_impact) - 0.5 * g * (t - t_impact) ** 2)
    y_mm = 1000.0 * y + rng.normal(0.0, noise_mm, t.size)
    y_mm = np.round(y_mm / pixel_mm) * pixel_mm
    return pd.DataFrame({"t_s": t.round(5), "y_mm": y_mm.round(3)})


def force_curve(rng: np.random.Generator, stiffness_n_per_m: float, max_disp_mm: float, *,
                rate_mm_s: float = 5.0, hz: float = 500.0, noise_n: float = 0.3) -> pd.DataFrame:
    """Texture-analyser loading curve: linear (``stiffness``) over the first 20 % of the travel,
    then softening as the tissue yields; load-cell noise ``noise_n``, at most 0.2 % of the
    linear part's force (a lab fits the load cell to the specimen: a seed of 1 MPa shear
    modulus loads a few newtons). Columns ``displacement_mm``, ``force_N``."""
    d = np.arange(0.0, max_disp_mm, rate_mm_s / hz)
    d_lin = 0.2 * max_disp_mm
    k = stiffness_n_per_m * 1e-3
    f = np.where(d <= d_lin, k * d, k * d_lin + 0.45 * k * (d - d_lin) - 0.02 * k * (d - d_lin) ** 2 / d_lin)
    f = f + rng.normal(0.0, min(noise_n, 0.002 * k * d_lin), d.size)
    return pd.DataFrame({"displacement_mm": d.round(4), "force_N": f.round(3)})


# ----------------------------------------------------------------------------------------------
# sheets


def _specimens(truth: Truth, rng, n: int) -> pd.DataFrame:
    """The specimens sheet: each specimen's calliper readings of the truth's shape (a segment's
    length and diameter with their own spreads; any other shape's sizes with the relative
    spread ``size_sd_rel``, a kernel's axes kept in order), its mass from the envelope density
    and the volume of its shape's body, moisture and batch."""
    from demcal.simulate.shapes.segment import Segment

    p = truth.params
    shape = p.shape
    if isinstance(shape, Segment):
        length = np.clip(rng.normal(shape.length_m, truth.length_sd_m, n), 0.6 * shape.length_m, 1.4 * shape.length_m)
        dia = np.clip(rng.normal(shape.diameter_m, truth.diameter_sd_m, n), 0.6 * shape.diameter_m,
                      np.minimum(1.4 * shape.diameter_m, length))
        sizes = {"length_m": length, "diameter_m": dia}
    else:
        sizes = {}
        for name in shape.sizes:
            mean = getattr(shape, name)
            x = np.clip(rng.normal(mean, truth.size_sd_rel * mean, n), 0.6 * mean, 1.4 * mean)
            for bigger in sizes.values():          # a kernel's axes: length >= width >= thickness
                x = np.minimum(x, bigger)
            sizes[name] = x
    volume = np.array([replace(shape, **{k: float(v[i]) for k, v in sizes.items()}).volume() for i in range(n)])
    env = truth.envelope_ratio * p.particle_density_kg_m3 * (1.0 + 0.02 * rng.standard_normal(n))
    mass = env * volume          # kg
    columns = {column: (sizes[name] * 1e3).round(2) for name, column in zip(shape.sizes, size_columns(shape))}
    return pd.DataFrame({
        "specimen_id": [f"S{i + 1:02d}" for i in range(n)], **columns,
        "mass_g": (mass * 1e3).round(3),
        "moisture_pct": rng.normal(truth.moisture_pct, truth.moisture_sd_pct, n).round(1),
        "batch": rng.choice(list(truth.batches), n)})


def _clump(shape) -> pd.DataFrame:
    """The clump sheet of a clump-table shape: its reference spheres [mm]."""
    t = np.asarray(shape.table, float) * 1e3
    return pd.DataFrame({"sphere_id": [f"s{i + 1}" for i in range(len(t))], "x_mm": t[:, 0].round(6),
                         "y_mm": t[:, 1].round(6), "z_mm": t[:, 2].round(6), "radius_mm": t[:, 3].round(6)})


def _density(truth: Truth, rng, n: int) -> pd.DataFrame:
    rho = rng.normal(truth.params.particle_density_kg_m3, truth.density_sd, n)
    mass = rng.uniform(18.0, 26.0, n)
    displaced = np.round(mass / (rho / 1000.0), 1)           # read to 0.1 ml
    return pd.DataFrame({"sample_id": [f"D{i + 1}" for i in range(n)], "mass_g": mass.round(3),
                         "volume_before_ml": np.full(n, 100.0), "volume_after_ml": 100.0 + displaced})


def _session(rng, n: int, truth: Truth, day: str, specimens: pd.DataFrame, *, spread_days=False,
             trials_per_specimen=None) -> dict:
    """Covariates of ``n`` trials in random order: trial order, alternating operators, a day
    (or, with ``spread_days``, a random day of the campaign each), a specimen each (random,
    or ``n / trials_per_specimen`` specimens tested that many times each)."""
    ops = list(truth.operators)
    days = list(rng.choice(list(truth.days), n)) if spread_days else [day] * n
    ids = specimens["specimen_id"].to_numpy()
    if trials_per_specimen:
        chosen = rng.choice(ids, math.ceil(n / trials_per_specimen), replace=False)
        spec = rng.permutation(np.repeat(chosen, trials_per_specimen)[:n])
    else:
        spec = rng.choice(ids, n)
    return {"trial_order": np.arange(1, n + 1),
            "operator": [ops[k % len(ops)] for k in range(n)],
            "date": days,
            "specimen_id": spec}


def _specimen_scatter(rng, truth: Truth, sd: float, specimen_ids) -> np.ndarray:
    """Trial scatter of sd ``sd`` split into a specimen random effect (variance share
    ``truth.icc``) and the trial's own."""
    ids = np.asarray(specimen_ids)
    names, index = np.unique(ids, return_inverse=True)
    shared = rng.normal(0.0, sd * math.sqrt(truth.icc), names.size)[index]
    return shared + rng.normal(0.0, sd * math.sqrt(1.0 - truth.icc), ids.size)


def _by_day(effects, sheet: str) -> bool:
    """Whether a block effect by date is planted in ``sheet`` (its trials then span the days)."""
    return any(e.kind == "block_effect" and e.sheet == sheet and e.covariate == "date" for e in effects)


def size_column(params: DEMParameters) -> str:
    """The specimens column of the particle's first size (``length_mm``, a sphere's
    ``diameter_mm``): the covariate a planted size dependence follows."""
    return size_columns(params.shape)[0]


def size_columns(shape) -> list:
    """The specimens columns [mm] of a shape's sizes, in the order of ``shape.sizes``."""
    return [name.removesuffix("_m") + "_mm" for name in shape.sizes]


def _join_specimens(frame: pd.DataFrame, specimens: pd.DataFrame, size: str) -> pd.DataFrame:
    return frame.merge(specimens[["specimen_id", size, "moisture_pct", "batch"]],
                       on="specimen_id", how="left", suffixes=("", "_spec"))


def _contributions(effects, sheet: str, quantity: str, rows: pd.DataFrame, truth: Truth,
                   specimens_mean: dict, height_ref_mm: float = 0.0, order_centre=None) -> dict:
    """Per-row additive contribution of each effect (index in ``effects``) to a quantity, in its
    own unit (e for drops, mu for inclines; block offsets of inclines are in degrees and are
    returned separately by the caller). A drift is centred on ``order_centre`` (default the
    middle of these rows' trials)."""
    out = {}
    n = len(rows)
    for k, eff in enumerate(effects):
        if eff.sheet != sheet or not eff.acts_on(quantity):
            continue
        if eff.kind == "velocity_dependent_restitution":
            h = rows["drop_height_mm"].to_numpy(float)
            out[k] = eff.size * (h - height_ref_mm)
        elif eff.kind == "size_dependence":
            size = size_column(truth.params)
            out[k] = eff.size * (rows[size].to_numpy(float) - specimens_mean[size])
        elif eff.kind == "trial_order_drift":
            t = rows["trial_order"].to_numpy(float)
            out[k] = eff.size * (t - (0.5 * (n + 1) if order_centre is None else order_centre))
        elif eff.kind == "moisture_dependence":
            out[k] = eff.size * (rows["moisture_pct"].to_numpy(float) - truth.moisture_pct)
        elif eff.kind == "block_effect":
            levels = {"operator": truth.operators, "date": truth.days, "batch": truth.batches}[eff.covariate]
            out[k] = np.array([_level_offset(tuple(levels), v, eff.size) for v in rows[eff.covariate]])
    return out


def _expected(effects, k: int, sheet: str, quantity: str, rows: pd.DataFrame, delta, size: str) -> dict:
    eff = effects[k]
    cov = (eff.covariate if eff.kind == "block_effect" else size if eff.kind == "size_dependence" else
           EFFECT_DEFAULTS[eff.kind]["covariate"])
    if eff.kind == "block_effect":
        size = _block_range(rows[cov], delta)
        unit = "quantity (range of level means)"
    else:
        size = _slope(rows[cov].to_numpy(float), delta)
        unit = f"quantity per {cov}"
    return {"kind": eff.kind, "sheet": sheet, "quantity": quantity, "covariate": cov,
            "true_effect": size, "unit": unit}


def _drops(truth: Truth, rng, effects, specimens, *, pairs, heights_mm, n_drop, orientation_range,
           n_tracks, root: Path, cache_dir, trials_per_specimen=None, interleaved=False):
    """The drop sheet, its tracks, and the expected sizes of the effects planted in it."""
    frames, expected = [], []
    n_pair = n_drop * len(heights_mm)
    orders = rng.permutation(np.arange(1, n_pair * len(pairs) + 1)) if interleaved else None
    orient = [e for e in effects if e.kind == "orientation_rotation"]
    size = size_column(truth.params)
    spec_mean = {size: float(specimens[size].mean())}
    trial = 0
    for pair in pairs:
        e_pair = truth.restitution(pair)
        n = n_drop * len(heights_mm)
        rows = pd.DataFrame(_session(rng, n, truth, truth.days[0], specimens,
                                     spread_days=_by_day(effects, "drop"),
                                     trials_per_specimen=trials_per_specimen))
        rows["pair"] = pair
        if interleaved:
            k = len(frames)
            rows["trial_order"] = orders[k * n:(k + 1) * n]
        rows["drop_height_mm"] = rng.permutation(np.repeat(np.asarray(heights_mm, float), n_drop))
        hand = [e for e in orient if e.acts_on(f"restitution.{pair}")]
        lo = min([e.size for e in hand]) if hand else orientation_range[0]
        hi = 90.0 if hand else orientation_range[1]
        rows["orientation_deg"] = rng.uniform(lo, hi, n).round(1)
        rows = _join_specimens(rows, specimens, size)
        contrib = _contributions(effects, "drop", f"restitution.{pair}", rows, truth, spec_mean,
                                 height_ref_mm=float(np.mean(heights_mm)),
                                 order_centre=0.5 * (n_pair * len(pairs) + 1) if interleaved else None)
        contact = e_pair + sum(contrib.values(), np.zeros(n))
        # without a planted orientation effect the rebound is the contact restitution at every
        # orientation; with one, segments turn part of their energy into rotation as a rigid
        # segment does: the drop twin without the glued-sphere damping of flat landings
        ratio = np.ones(n)
        for h in np.unique(rows["drop_height_mm"]) if hand else ():
            sel = rows["drop_height_mm"].to_numpy() == h
            ratio[sel] = drop_twin_ratio(truth.params.with_(contact_effective_mass=True), pair, h * 1e-3,
                                         rows.loc[sel, "orientation_deg"], cache_dir=cache_dir)
        apparent = contact * ratio
        # expected sizes, on the noise-free apparent restitution
        for k, c in contrib.items():
            expected.append(_expected(effects, k, "drop", f"restitution.{pair}", rows, c * ratio, size))
        for eff in hand:
            expected.append({"kind": eff.kind, "sheet": "drop", "quantity": f"restitution.{pair}",
                             "covariate": "orientation_deg",
                             "true_effect": _slope(rows["orientation_deg"], apparent - contact),
                             "unit": "quantity per orientation_deg"})
        e_obs = np.clip(apparent + _specimen_scatter(rng, truth, truth.e_sd, rows["specimen_id"]), 0.01, 0.99)
        h1 = rows["drop_height_mm"].to_numpy(float)
        h2 = np.clip(e_obs ** 2 * h1 + rng.normal(0.0, truth.height_noise_mm, n), 0.0, h1).round(1)
        rows["rebound_height_mm"] = h2
        rows["trial_id"] = [f"T{trial + i + 1:03d}" for i in range(n)]
        trial += n
        rows["track_file"] = ""
        if pair == "particle-steel" and n_tracks:
            (root / "tracks").mkdir(parents=True, exist_ok=True)
            # film the first drops that rebound clearly (a track needs a rebound to fit)
            for i in [i for i in range(n) if e_obs[i] >= 0.15][:n_tracks]:
                name = f"tracks/{rows.at[i, 'trial_id']}.csv"
                camera_track(rng, h1[i] * 1e-3, float(e_obs[i])).to_csv(root / name, index=False)
                rows.at[i, "track_file"] = name
        frames.append(rows)
    drop = pd.concat(frames, ignore_index=True)
    cols = ["trial_id", "pair", "drop_height_mm", "rebound_height_mm", "specimen_id", "operator",
            "date", "orientation_deg", "trial_order", "track_file"]
    return drop[cols], expected


def _inclines(truth: Truth, rng, effects, specimens, *, surfaces, n_incline, trials_per_specimen=None):
    frames, expected = [], []
    size = size_column(truth.params)
    spec_mean = {size: float(specimens[size].mean())}
    trial = 0
    day = truth.days[min(1, len(truth.days) - 1)]
    for surface in surfaces:
        for mode in ("slide", "roll"):
            quantity = f"{'static' if mode == 'slide' else 'rolling'}_friction.{surface}"
            rows = pd.DataFrame(_session(rng, n_incline, truth, day, specimens,
                                         spread_days=_by_day(effects, "incline"),
                                         trials_per_specimen=trials_per_specimen))
            rows["surface"], rows["mode"] = surface, mode
            # a round particle rolls first: its lab slides a sled of glued particles
            rows["carrier"] = "sled" if mode == "slide" and truth.params.shape.rolls_first else "particle"
            rows = _join_specimens(rows, specimens, size)
            contrib = _contributions(effects, "incline", quantity, rows, truth, spec_mean)
            block = {k: c for k, c in contrib.items() if effects[k].kind == "block_effect"}
            shifts = {k: c for k, c in contrib.items() if k not in block}
            mu = truth.friction(surface, mode) + _specimen_scatter(rng, truth, truth.mu_sd, rows["specimen_id"])

            def reading(keep):
                m = mu + sum((c for k, c in shifts.items() if k in keep), np.zeros(n_incline))
                off = sum((c for k, c in block.items() if k in keep), np.zeros(n_incline))
                return np.degrees(np.arctan(np.clip(m, 1e-3, None))) + off

            everything = set(contrib)
            for k in contrib:
                delta = np.tan(np.radians(reading(everything))) - np.tan(np.radians(reading(everything - {k})))
                expected.append(_expected(effects, k, "incline", quantity, rows, delta, size))
            angle = reading(everything) + rng.normal(0.0, truth.angle_noise_deg, n_incline)
            rows["angle_deg"] = np.clip(angle, 0.1, 89.0).round(1)
            rows["trial_id"] = [f"I{trial + i + 1:03d}" for i in range(n_incline)]
            trial += n_incline
            frames.append(rows)
    inc = pd.concat(frames, ignore_index=True)
    return inc[["trial_id", "surface", "mode", "carrier", "angle_deg", "specimen_id", "operator", "date",
                "trial_order"]], expected


def _compression(truth: Truth, rng, specimens, n: int, root: Path) -> pd.DataFrame:
    p = truth.params
    (root / "curves").mkdir(parents=True, exist_ok=True)
    rows = []
    for i in range(min(n, len(specimens))):
        spec = specimens.iloc[i]
        nu = float(np.clip(rng.normal(p.poisson_ratio, truth.poisson_sd), 0.05, 0.45))
        E = youngs_modulus(p.shear_modulus_pa, p.poisson_ratio) * (1.0 + truth.modulus_sd_rel * rng.standard_normal())
        # radial loading across the thickness (a segment's diameter), the width across; a
        # clump's from its table's extents at the specimen's length
        extent = p.shape.extent / p.shape.extent[0] * float(spec.get("length_mm", spec.get("diameter_mm")))
        t0 = float(spec.get("thickness_mm", spec.get("diameter_mm", extent[2]))) * (1.0 + 0.01 * rng.standard_normal())
        w0 = float(spec.get("width_mm", spec.get("diameter_mm", extent[1]))) * (1.0 + 0.01 * rng.standard_normal())
        eps_t = 0.30 * (0.55 + 0.1 * rng.random())
        length = float(spec.get("length_mm", spec.get("diameter_mm")))
        k = E * (w0 * 1e-3) * (length * 1e-3) / (t0 * 1e-3)
        # a curve (and so an elastic modulus) only where measure's strip contact applies
        name = f"curves/C{i + 1:02d}.csv" if p.shape.strip_contact else None
        if name is not None:
            force_curve(rng, k, 0.30 * t0).to_csv(root / name, index=False)
        rows.append({"specimen_id": spec["specimen_id"], "axis": "radial",
                     "width_before_mm": round(w0, 3), "width_after_mm": round(w0 * (1.0 + nu * eps_t), 3),
                     "thickness_before_mm": round(t0, 3), "thickness_after_mm": round(t0 * (1.0 - eps_t), 3),
                     "curve_file": name})
    return pd.DataFrame(rows)


def _photos(truth: Truth, rng, effects, n: int, root: Path, mode: str, seed_base: int, geometry=None,
            size=None, prefix="", workers: int = 1):
    import cv2

    from demcal.simulate.render import PHOTO_PX_PER_M, PHOTO_SIZE, Lighting, heap_photo, heap_profile

    rig = rig_of_geometry(geometry) if geometry is not None else rig_named("repose")
    if size is not None and (mode != "analytic" or rig.analytic_photo is not None):
        # never dropped silently: only the drawn heap profile can be rendered at any size
        raise InputError(f"photo_size sets the size of the analytic photos of a heap profile; the "
                         f"{'DEM' if mode == 'dem' else rig.name} photos are framed by what they show")
    size = PHOTO_SIZE if size is None else size

    tilt = [e for e in effects if e.kind == "camera_tilt"]
    block = [e for e in effects if e.kind == "block_effect" and e.sheet == "repose"]
    flank = sum(e.size for e in tilt if e.quantity == "flanks")
    floor = sum(e.size for e in tilt if e.quantity == "floor")
    if mode == "dem" and flank:
        raise InputError("camera_tilt on the flanks needs photos='analytic' (a repose-rig heap has one flank)")
    (root / "photos").mkdir(parents=True, exist_ok=True)
    rows, expected = [], []
    ops = list(truth.operators)
    day = truth.days[-1]
    for e in block:
        if e.covariate not in ("operator", "date"):
            raise InputError(f"block_effect in the repose sheet: covariate must be operator or date, "
                             f"got {e.covariate!r}")
    spread = _by_day(effects, "repose")
    seeds = iter(range(seed_base, seed_base + 100 * n))
    discarded: list = []
    with _Pours(truth.params, geometry, range(seed_base, seed_base + n) if mode == "dem" else (), workers) as pours:
        for i in range(n):
            row = {"photo_id": f"{prefix}P{i + 1}", "operator": ops[i % len(ops)],
                   "date": str(rng.choice(list(truth.days))) if spread else day}
            offset = sum(_level_offset(tuple({"operator": truth.operators, "date": truth.days,
                                              "batch": truth.batches}[e.covariate]),
                                       row.get(e.covariate, truth.batches[0]), e.size) for e in block)
            angle = truth.repose_angle_deg + truth.repose_sd_deg * rng.standard_normal() + offset
            roll = truth.camera_roll_sd_deg * rng.standard_normal() + floor
            light = Lighting(gradient=float(rng.uniform(0.1, 0.35)), direction_deg=float(rng.uniform(0, 360)))
            if mode == "analytic" and rig.analytic_photo is not None:
                img, side = rig.analytic_photo(angle, rng), rig.flanks
            elif mode == "analytic":
                x, z = heap_profile(angle + flank, angle - flank, height_m=0.10, floor_m=0.04,
                                    roughness_m=0.002, rng=rng)
                side = "both"
                # the same field of view at any resolution: the heap spans the same share of the frame
                img = heap_photo(x, z, rng=rng, camera_roll_deg=float(np.clip(roll, -15, 15)), light=light,
                                 noise_sd=4.0, blur_px=1.0, jpeg_quality=int(rng.integers(75, 93)),
                                 size=size, px_per_m=PHOTO_PX_PER_M * size[1] / PHOTO_SIZE[1],
                                 particle_m=truth.params.shape.outline_m)
            else:
                img, side, px_per_m = _dem_heap_photo(rng, roll, light, seeds, discarded, geometry, pours)
            name = f"photos/{prefix}heap_{i + 1}.jpg"
            cv2.imwrite(str(root / name), img, [cv2.IMWRITE_JPEG_QUALITY, 95])
            rows.append({"photo_id": row["photo_id"], "file": name, "side": side, "operator": row["operator"],
                         "date": row["date"]})
            if mode == "dem" and rig.run_photo is None:
                # a twin's heap seen from the side at the photo's scale: its crest height is the truth's
                rows[-1]["scale_mm_per_px"] = 1e3 / px_per_m
    frame = pd.DataFrame(rows)
    for e in tilt:
        q = "flank_difference_deg" if e.quantity == "flanks" else "base_tilt_deg"
        expected.append({"kind": e.kind, "sheet": "repose", "quantity": q,
                         "covariate": "side" if e.quantity == "flanks" else "floor",
                         "true_effect": 2.0 * e.size if e.quantity == "flanks" else e.size,
                         "unit": "deg"})
    for e in block:
        levels = {"operator": truth.operators, "date": truth.days, "batch": truth.batches}[e.covariate]
        offs = [_level_offset(tuple(levels), v, e.size) for v in frame[e.covariate]]
        expected.append({"kind": e.kind, "sheet": "repose", "quantity": "repose_angle_deg",
                         "covariate": e.covariate, "true_effect": _block_range(frame[e.covariate], offs),
                         "unit": "deg (range of level means)"})
    return frame, expected, discarded


#: Pours of the repose twin per photo before the virtual lab gives up on a geometry.
MAX_POURS = 5


def _pour(params, geometry, seed: int):
    """One repose-twin heap of the photos (top level: worker processes pickle it)."""
    return rig_of_geometry(geometry).run(params, seed, profile="quick", geometry=geometry)


class _Pours:
    """The repose-twin heaps of the photos by seed, as a context manager. The heaps of
    ``seeds`` (one per photo, as when no heap is discarded) are poured on ``workers`` local
    processes while the photos of the first are drawn here; any other seed is poured here when
    asked for. A heap depends on its seed only, so the photos are the same whatever
    ``workers``."""

    def __init__(self, params, geometry, seeds, workers: int):
        self.params, self.geometry = params, geometry
        self._pool, self._heaps = None, iter(())
        self._seeds = list(seeds)
        if workers > 1 and len(self._seeds) > 1:
            from demcal.simulate.scenes import compile_kernels
            from demcal.simulate.threads import run_processes

            compile_kernels()                     # the workers load the kernels, none compiles them
            n = len(self._seeds)
            self._pool = run_processes(min(workers, n))
            self._heaps = self._pool.map(_pour, [params] * n, [geometry] * n, self._seeds)
        else:
            self._seeds = []

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
        return False

    def __call__(self, seed: int):
        # the pool's heaps come in seed order; a seed past them (after a discarded heap) or
        # before them is poured here
        while self._seeds and self._seeds[0] < seed:
            self._seeds.pop(0)
            next(self._heaps)
        if self._seeds and self._seeds[0] == seed:
            self._seeds.pop(0)
            return next(self._heaps)
        return _pour(self.params, self.geometry, seed)


def _dem_heap_photo(rng, roll, light, seeds, discarded: list, geometry, pours: _Pours):
    """The side photo of a repose-twin heap, poured again (next seed) when the photo method
    cannot read it, as a lab pours again a heap it cannot measure; the seeds of the discarded
    heaps are appended to ``discarded``. Returns the image, the flank measured and the photo's
    scale [px/m] (None for a rig's own photo).

    The camera sees the heap's own spheres, framed as the twin's side view frames them (the
    width of its profile fills the frame), so that photo and twin differ by the camera only.
    Drawn from the profile at one scale for every carton, a heap a few particles high read
    1-3 deg lower than its twin."""
    import cv2

    from demcal.measure.repose import angle_from_photo
    from demcal.simulate.render import PHOTO_SIZE, heap_photo

    rig = rig_of_geometry(geometry)
    for _ in range(MAX_POURS):
        seed = next(seeds)
        res = pours(seed)
        px_per_m = None
        if rig.run_photo is not None:
            img = rig.run_photo(res.record, rng)
        else:
            x = np.asarray(res.record["profile_x"], float)
            z = np.asarray(res.record["profile_z"], float)
            px_per_m = PHOTO_SIZE[1] / (x[-1] - x[0])
            img = heap_photo(x, z, rng=rng, camera_roll_deg=float(np.clip(roll, -15, 15)), light=light,
                             noise_sd=4.0, blur_px=1.0, jpeg_quality=int(rng.integers(75, 93)),
                             px_per_m=px_per_m, spheres=(res.record["sphere_positions"], res.record["sphere_radii"]))
        # read it back as the workbook will hold it (the JPEG written by _photos)
        stored = cv2.imdecode(cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 95])[1], cv2.IMREAD_COLOR)
        try:
            angle_from_photo(stored, side=rig.flanks)
        except DemcalError as exc:
            discarded.append({"seed": seed, "reason": str(exc)})
            continue
        return img, rig.flanks, px_per_m
    raise SimulationError(f"{MAX_POURS} repose-twin heaps in a row could not be read from their photos "
                          f"(last: {discarded[-1]['reason']}); the rig's dimensions or the truth give no "
                          "measurable flank")


def repose_geometries(meta: dict) -> list:
    """The dimensions of each repose rig meta rows name (``repose_rig``, one rig or several
    separated by commas, and each rig's keys), as objects of the rigs' geometry classes; a bad
    row refused naming its key."""
    from demcal.simulate.rigs import repose_setups

    if not isinstance(meta, dict):
        raise InputError(f"repose_rig must be a mapping of workbook meta keys, got {meta!r}")
    try:
        setups = repose_setups(meta)
    except DemcalError as exc:
        raise InputError(f"repose_rig: {exc}") from None
    return [s.dimensions() for s in setups]


def repose_geometry(meta: dict):
    """The first repose rig's dimensions of meta rows (:func:`repose_geometries`)."""
    return repose_geometries(meta)[0]


def _meta(truth: Truth, effects, geometries=()) -> pd.DataFrame:
    from demcal.simulate.rigs.repose import ReposeGeometry

    p = truth.params
    geometries = list(geometries) or [ReposeGeometry()]
    rigs = [rig_of_geometry(g) for g in geometries]
    names = meta_names(rigs)
    material = "root segments" if p.shape.name == "segment" else f"{p.shape.name} particles"
    rows = [("material", f"Virtual {material} (demcal virtual lab)"), ("contact_material", "steel"),
            ("contact_density_kg_m3", p.wall_density_kg_m3), ("contact_poisson", p.wall_poisson_ratio),
            ("contact_shear_modulus_pa", p.wall_shear_modulus_pa),
            ("particle_shear_modulus_pa", p.shear_modulus_pa),
            ("repose_rig", ", ".join(r.workbook_name for r in rigs)),
            *(row for g, r in zip(geometries, rigs) for row in g.meta_rows(names[r.workbook_name])),
            ("shape", p.shape.name)] + ([("time_step_s", p.dt)] if p.dt is not None else []) + (
            [("spheres_per_particle", p.shape.n_spheres)] if hasattr(p.shape, "n_spheres") else []) + [
            ("virtual_lab", "made by simulate.virtual_lab from a known truth (truth.json); planted: "
             + (", ".join(e.kind for e in effects) or "none"))]
    return pd.DataFrame(rows, columns=["key", "value"])


def check_design(effects, *, photos, n_specimens, n_density, n_drop, n_incline, n_compression, n_photos,
                 n_tracks, trials_per_specimen, orientation_range_deg, drop_heights_mm, repose_rig=None,
                 **_) -> None:
    """Refuse a design (the options of ``write_virtual_workbook``) it cannot write, before
    anything is written; the options not checked here (``pairs``, ``surfaces``...) are ignored."""
    effects = tuple(e if isinstance(e, PlantedEffect) else PlantedEffect(str(e)) for e in effects)
    if photos not in PHOTO_MODES:
        raise InputError(f"photos must be one of {', '.join(PHOTO_MODES)}, got {photos!r}")
    for name, value, least in (("n_specimens", n_specimens, 3), ("n_density", n_density, 2),
                               ("n_drop", n_drop, 1), ("n_incline", n_incline, 2),
                               ("n_compression", n_compression, 0), ("n_photos", n_photos, 0),
                               ("n_tracks", n_tracks, 0)):
        if int(value) != value or value < least:
            raise InputError(f"{name} must be an integer >= {least}, got {value!r}")
    if trials_per_specimen is not None:
        if int(trials_per_specimen) != trials_per_specimen or trials_per_specimen < 1:
            raise InputError(f"trials_per_specimen must be a positive integer, got {trials_per_specimen!r}")
        need = max(n_drop * len(drop_heights_mm), n_incline)
        if math.ceil(need / trials_per_specimen) > n_specimens:
            raise InputError(f"trials_per_specimen {trials_per_specimen}: {need} trials need "
                             f"{math.ceil(need / trials_per_specimen)} specimens, the workbook has {n_specimens}")
    lo, hi = (float(v) for v in orientation_range_deg)
    if not 0 <= lo <= hi <= 90:
        raise InputError(f"orientation_range_deg must satisfy 0 <= low <= high <= 90, got {orientation_range_deg!r}")
    if not drop_heights_mm or any(not h > 0 for h in drop_heights_mm):
        raise InputError(f"drop_heights_mm must be positive heights, got {drop_heights_mm!r}")
    for e in effects:
        if e.sheet == "repose" and repose_rig is not None and len(repose_geometries(repose_rig)) > 1:
            raise InputError(f"planted effect {e.kind} is in the repose sheet: plant it with one repose rig")
        if e.sheet == "repose" and (photos == "none" or n_photos < 2):
            raise InputError(f"planted effect {e.kind} is in the repose sheet: needs photos and n_photos >= 2")


def write_virtual_workbook(truth: Truth, path, effects=(), rng=None, *, photos: str = "analytic",
                           n_specimens: int = 30, n_density: int = 5,
                           pairs=("particle-particle", "particle-steel"),
                           drop_heights_mm=(200.0, 400.0, 600.0), n_drop: int = 10,
                           orientation_range_deg=(80.0, 90.0), n_tracks: int = 2,
                           surfaces=("particle", "steel"), n_incline: int = 30,
                           n_compression: int = 10, n_photos: int = 4,
                           cache_dir=None, geometry=None, trials_per_specimen: int | None = None,
                           interleaved: bool = False, photo_size=None,
                           repose_rig: dict | None = None, workers: int = 1) -> VirtualWorkbook:
    """Write a complete lab workbook from ``truth``, with ``effects`` planted.

    Parameters
    ----------
    truth : Truth
    path : str or Path
        ``*.xlsx`` for a workbook file (photos, tracks and curves beside it), else a folder
        that receives one CSV per sheet and the files.
    effects : sequence of PlantedEffect or str
        Effects to plant (a kind name plants the kind's default).
    rng : numpy.random.Generator or int
        Random source; an int is a seed. Required.
    photos : {"analytic", "dem", "none"}
        Heap photos from analytic heap profiles (fast), from repose-rig heaps (slow), or none
        (no repose sheet).
    n_specimens, n_density : int
        Specimens measured with callipers; density samples.
    pairs : sequence of str
        Drop pairs (``particle-steel``, ``particle-particle``).
    drop_heights_mm : sequence of float
        Drop heights [mm]; ``n_drop`` drops of each pair from each height, in random order.
    orientation_range_deg : (float, float)
        Release orientations without a planted ``orientation_rotation`` [deg].
    n_tracks : int
        Particle-steel drops filmed (a camera track each).
    surfaces : sequence of str
        Incline surfaces (``particle``, ``steel``); ``n_incline`` slide and ``n_incline`` roll
        trials on each.
    n_compression, n_photos : int
        Compression tests (with curves); heap photos.
    cache_dir : path, optional
        Disk cache of the drop-twin table (default ``$DEMCAL_CACHE``, else memory only).
    geometry : ReposeGeometry or CylinderGeometry, optional
        The repose rig's dimensions (``simulate.rigs.repose.ReposeGeometry`` for the lifted
        plate, ``simulate.rigs.lifting_cylinder.CylinderGeometry``), written to the meta sheet
        with the rig's name (``repose_rig``) and used for the heaps of ``photos="dem"``; default
        the carton in proportion to the truth's particle (``ReposeGeometry.for_particle``: for
        the paper's segments, its 200 x 100 x 250 mm carton of 500).
    repose_rig : dict, optional
        The same as workbook meta rows instead (``repose_rig`` and the rig's dimensions, e.g.
        ``{"repose_rig": "lifting_cylinder", "cylinder_diameter_mm": 60, ...}``); not with
        ``geometry``. Several rigs (``"repose_rig": "lifted_plate, drum"`` and each one's
        dimensions) photograph ``n_photos`` heaps each, the repose sheet's ``rig`` column naming
        the rig of each photo.
    trials_per_specimen : int, optional
        Drop and incline trials per specimen: each sheet's trials go to that many trials on
        each of a random subset of the specimens (with ``Truth.icc`` a clustered design);
        default a random specimen per trial.
    interleaved : bool
        Drops of every pair in one random order (``trial_order`` runs over the whole sheet, and
        a planted drift with it); default each pair's drops in a session of its own.
    photo_size : (int, int), optional
        Height and width of the analytic heap photos [px], the same field of view at any size
        (default ``simulate.render.PHOTO_SIZE``, 900 x 1200 at 2.5 px/mm). Refused for photos
        that are framed by what they show (``photos="dem"``, a drum's analytic frames).
    workers : int
        Local processes pouring the heaps of ``photos="dem"`` at once; the workbook is the
        same whatever their number.

    Returns
    -------
    VirtualWorkbook
    """
    from demcal.measure.workbook import write_workbook

    if not isinstance(truth, Truth):
        raise InputError(f"truth must be a Truth, got {type(truth).__name__}")
    if rng is None:
        raise InputError("write_virtual_workbook needs rng (a seed or numpy.random.Generator)")
    seed = int(rng) if isinstance(rng, (int, np.integer)) else None
    rng = np.random.default_rng(rng)
    effects = tuple(e if isinstance(e, PlantedEffect) else PlantedEffect(str(e)) for e in effects)
    check_design(effects, photos=photos, n_specimens=n_specimens, n_density=n_density, n_drop=n_drop,
                 n_incline=n_incline, n_compression=n_compression, n_photos=n_photos, n_tracks=n_tracks,
                 trials_per_specimen=trials_per_specimen, orientation_range_deg=orientation_range_deg,
                 drop_heights_mm=drop_heights_mm, repose_rig=repose_rig)
    if photo_size is not None and (len(photo_size) != 2 or min(photo_size) < 120
                                   or not all(isinstance(v, (int, np.integer)) for v in photo_size)):
        raise InputError(f"photo_size must be (height, width) in whole pixels, each >= 120, got {photo_size!r}")
    lo, hi = (float(v) for v in orientation_range_deg)

    geometries = [geometry] if geometry is not None else []
    if repose_rig is not None:
        if geometry is not None:
            raise InputError("give the repose rig as geometry or as repose_rig meta rows, not both")
        geometries = repose_geometries(repose_rig)
    stated = list(geometries)
    if not geometries:
        from demcal.simulate.rigs.repose import ReposeGeometry
        geometries = [ReposeGeometry.for_particle(truth.params.shape)]
    for g in geometries:
        rig_of_geometry(g)                        # a repose rig's dimensions, or refused
        g.check_for(truth.params.shape)

    path = Path(path)
    xlsx = path.suffix.lower() == ".xlsx"
    root = path.parent if xlsx else path
    root.mkdir(parents=True, exist_ok=True)
    specimens = _specimens(truth, rng, n_specimens)
    sheets = {"meta": _meta(truth, effects, geometries), "specimens": specimens,
              "density": _density(truth, rng, n_density)}
    if truth.params.shape.name == "clump":
        sheets["clump"] = _clump(truth.params.shape)
    expected = []
    if pairs:
        sheets["drop"], exp = _drops(truth, rng, effects, specimens, pairs=tuple(pairs),
                                     heights_mm=tuple(float(h) for h in drop_heights_mm), n_drop=n_drop,
                                     orientation_range=(lo, hi), n_tracks=n_tracks, root=root,
                                     cache_dir=cache_dir, trials_per_specimen=trials_per_specimen,
                                     interleaved=interleaved)
        expected += exp
    if surfaces:
        sheets["incline"], exp = _inclines(truth, rng, effects, specimens, surfaces=tuple(surfaces),
                                           n_incline=n_incline, trials_per_specimen=trials_per_specimen)
        expected += exp
    if n_compression:
        sheets["compression"] = _compression(truth, rng, specimens, n_compression, root)
    discarded_heaps: list = []
    if photos != "none" and n_photos:
        frames = []
        for i, g in enumerate(geometries):
            # every rig photographs n_photos heaps; the first rig's come as a single-rig lab's
            frame, exp, discarded = _photos(truth, rng, effects, n_photos, root, photos,
                                            seed_base=int(rng.integers(0, 2**31)), geometry=g,
                                            size=photo_size, workers=workers,
                                            prefix="" if i == 0 else rig_of_geometry(g).workbook_name + "_")
            if len(geometries) > 1:
                frame.insert(2, "rig", rig_of_geometry(g).workbook_name)
            frames.append(frame)
            expected += exp
            discarded_heaps += discarded
        sheets["repose"] = pd.concat(frames, ignore_index=True)
    for e in effects:
        if e.sheet not in sheets or not any(x["kind"] == e.kind for x in expected):
            raise InputError(f"planted effect {e.kind} acts on nothing in this design "
                             f"(sheet {e.sheet!r}, quantity {e.quantity!r})")
    write_workbook(sheets, path)
    options = {"photos": photos, "n_specimens": n_specimens, "n_density": n_density, "pairs": list(pairs),
               "drop_heights_mm": list(drop_heights_mm), "n_drop": n_drop,
               "orientation_range_deg": [lo, hi], "n_tracks": n_tracks, "surfaces": list(surfaces),
               "n_incline": n_incline, "n_compression": n_compression, "n_photos": n_photos,
               "trials_per_specimen": trials_per_specimen,
               "discarded_heaps": discarded_heaps,
               "geometry": stated[0].to_dict() if len(stated) == 1 else None}
    if len(stated) > 1:
        options["geometries"] = [g.to_dict() for g in stated]
    result = VirtualWorkbook(path=path, truth=truth, effects=effects, expected=tuple(expected), seed=seed,
                             provenance=Provenance(seed=seed, options=options))
    write_json(root / "truth.json", result.to_dict())
    return result
