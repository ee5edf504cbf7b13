"""What the repose rigs share: how a heap run is carried out, and how a heap is measured.

A repose rig fills a container (the carton of the lifted plate, the lifting cylinder), waits
for the fill to settle, lifts a wall at the logged speed and lets the heap settle
(:func:`fill_lift_settle`); its heap is then seen from the side, as the lab's camera sees it,
and measured by the photo estimator of the lab's photos (:func:`side_view_angles`).

Profiles (``PROFILES``):

``paper``
    The source paper's timing: particles inserted at random during the first second in the
    upper part of the container (z from 0.4 to 0.96 of its height), the wall lifted at t = 4 s,
    10 s in all.
``quick``
    For calibration campaigns. The same container, fill, lift speed, time step and contact
    model; only the idle time is cut: the particles are inserted over 0.5 s into the whole
    height of the container (z from 0.1 to 0.96 of it), the wall is lifted as soon as the fill
    has settled (rms speed of the bodies below ``SETTLED_SPEED``) and stopped once its lower
    edge is a particle's width above the highest sphere, and the run ends when the heap has
    settled after that (or at 4 s). The heap forms while the wall rises, exactly as in the
    paper's timing, so the angles agree within the seed scatter.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from demcal.errors import InputError
from demcal.simulate.rigs import RunTally
from demcal.simulate.scenes import PAPER_DURATION

#: rms speed of the bodies below which a fill or a heap counts as settled [m/s].
SETTLED_SPEED = 0.005
#: Resolution of the rendered side view [px/m] (0.5 mm per pixel).
PX_PER_M = 2000.0
#: Spacing of the top profile [m].
PROFILE_STEP = 0.001
#: Simulated time between checks of a heap run [s].
CHUNK_S = 0.05


@dataclass(frozen=True)
class ReposeProfile:
    """How a repose run is carried out (see the module docstring).

    Attributes
    ----------
    name : str
    scale : float
        Linear scale of the container (fill count scaled by its cube) [-].
    fill_time : float
        Particles are inserted uniformly over [0, fill_time] [s].
    fill_bottom, fill_top : float
        Insertion region height, as fractions of the container height [-].
    lift_time : float or None
        Time the wall starts rising [s]; None: as soon as the fill has settled.
    duration : float
        Simulated time [s]; the largest one when ``early_end``.
    early_end : bool
        End once the heap has settled after the wall is clear; stop the wall then too.
    outside_length : float
        Floor kept in the simulation domain beyond the container, relative to its length (the
        carton) or diameter (the cylinder) [-].
    """

    name: str
    scale: float
    fill_time: float
    fill_bottom: float
    fill_top: float
    lift_time: float | None
    duration: float
    early_end: bool
    outside_length: float = 2.25

    def to_dict(self) -> dict:
        return asdict(self)


PROFILES = {
    "paper": ReposeProfile("paper", scale=1.0, fill_time=1.0, fill_bottom=0.4,
                           fill_top=0.96, lift_time=4.0, duration=PAPER_DURATION, early_end=False),
    "quick": ReposeProfile("quick", scale=1.0, fill_time=0.5, fill_bottom=0.1,
                           fill_top=0.96, lift_time=None, duration=4.0, early_end=True),
}


def repose_profile(profile) -> ReposeProfile:
    """A :class:`ReposeProfile`, or the one ``PROFILES`` names; an unknown name lists them."""
    if isinstance(profile, ReposeProfile):
        return profile
    if profile in PROFILES:
        return PROFILES[profile]
    raise InputError(f"unknown repose profile {profile!r}; valid: {', '.join(PROFILES)}")


# ----------------------------------------------------------------------------------------------
# a rig's dimensions in the workbook's meta


def meta_values(keys: dict, meta: dict, file=None, *, whole=(), required=(), rename=None) -> dict:
    """Field values from a workbook ``meta`` dict: ``keys`` maps each meta key to (field,
    factor to SI), ``rename`` some of those keys to the names the meta gives them. A missing or
    blank key is left out (the field keeps its default) unless it is ``required``; a value that
    is not a positive number (a whole number for the fields in ``whole``) raises
    ``WorkbookError`` naming the sheet, the key and the value."""
    from demcal.errors import WorkbookError

    rename = rename or {}
    values = {}
    for plain, (name, factor) in keys.items():
        key = rename.get(plain, plain)
        raw = meta.get(key) if meta else None

        def bad(why):
            return WorkbookError(f"meta {key}: {why}", file=file, sheet="meta", column="value", value=raw)

        if raw is None or (isinstance(raw, str) and not raw.strip()):
            if plain in required:
                raise bad(f"missing: the rig needs {', '.join(rename.get(k, k) for k in required)}")
            continue
        try:
            number = float(raw)
        except (TypeError, ValueError):
            raise bad("needs a number") from None
        if not (math.isfinite(number) and number > 0):
            raise bad("must be positive")
        if name in whole:
            if number != int(number):
                raise bad("needs a whole number")
            values[name] = int(number)
        else:
            values[name] = number * factor
    return values


def meta_rows(geometry, keys: dict, rename=None) -> list:
    """The workbook meta rows (key, value) of ``geometry``'s fields named in ``keys`` (as for
    :func:`meta_values`, keys renamed by ``rename``), in the workbook's units; a field that is
    None is left out."""
    rename = rename or {}
    rows = []
    for key, (name, factor) in keys.items():
        value = getattr(geometry, name)
        if value is not None:
            rows.append((rename.get(key, key), value if factor == 1 else round(value / factor, 6)))
    return rows


#: Most particles a repose rig may hold (the workbook's plausible range of ``fill_count``).
MAX_FILL = 1e6


class RigDimensions:
    """What every repose rig's dimensions (a frozen dataclass with ``META_KEYS``, ``meta key ->
    (field, factor to SI)``, and the keys the workbook must give, ``REQUIRED``) share: read from
    a workbook's meta, written back to it, and recorded."""

    REQUIRED: tuple = ()

    @classmethod
    def from_meta(cls, meta: dict, file=None, rename=None):
        """From a workbook ``meta`` dict; a missing required key or a bad value raises
        ``WorkbookError`` naming the sheet, the key and the value (and ``file``); an optional
        key left out keeps its default. ``rename`` maps keys to the names the meta gives them
        (a key several rigs of one workbook share: ``simulate.rigs.meta_names``)."""
        return cls(**meta_values(cls.META_KEYS, meta, file, whole=("fill_count",), required=cls.REQUIRED,
                                 rename=rename))

    def filled_for(self, shape):
        """The same dimensions with the fill count for ``shape`` (here: the one given)."""
        return self

    def check_fill(self, shape) -> None:
        """Refuse a fill (given, or sized from the rig's volume) of more than ``MAX_FILL``
        particles, before any memory is taken for it: dimensions that read as metres where
        millimetres were meant would otherwise ask for petabytes."""
        try:
            count = self.filled_for(shape).fill_count
        except (OverflowError, ValueError):           # a volume beyond any float
            count = math.inf
        if count is not None and count > MAX_FILL:
            raise InputError(f"a fill of {count:.4g} particles is more than {MAX_FILL:g}, more than any lab "
                             f"heap: check the repose rig's dimensions (in mm) and fill count ({self.describe()})")

    def to_dict(self) -> dict:
        return asdict(self)

    def meta_rows(self, rename=None) -> list:
        """The workbook meta rows (key, value) that describe these dimensions (keys renamed by
        ``rename``)."""
        return meta_rows(self, self.META_KEYS, rename)


# ----------------------------------------------------------------------------------------------
# the run


@dataclass
class HeapRun:
    """What :func:`fill_lift_settle` did: its steps, kinetic energy, and when the wall moved.

    Attributes
    ----------
    tally : RunTally
    ke_t, ke : list of float
        Kinetic-energy history: time [s], energy [J].
    t_lift, t_clear : float
        Time the wall started rising and time its lower edge cleared the fill [s].
    notes : list of str
        What did not go as planned (a fill that did not fit, a run that ended early).
    """

    tally: RunTally = field(default_factory=RunTally)
    ke_t: list = field(default_factory=list)
    ke: list = field(default_factory=list)
    t_lift: float = math.nan
    t_clear: float = math.nan
    notes: list = field(default_factory=list)


def rms_speed(sim) -> float:
    """rms speed of the active bodies [m/s] (0 with none)."""
    act = sim.active()
    m = sim.masses()[act].sum()
    return math.sqrt(2.0 * sim.kinetic_energy() / m) if m > 0 else 0.0


def fill_lift_settle(sim, wall: int | None, lift_speed: float, prof: ReposeProfile, clearance: float,
                     fill_count: int, *, callback=None) -> HeapRun:
    """Fill ``sim`` from its factories, lift wall ``wall`` at ``lift_speed`` [m/s] and let the
    heap settle, as ``prof`` says (module docstring).

    The wall counts as clear once its lower edge is ``clearance`` [m] (a particle's width) above
    the highest sphere of the fill; ``fill_count`` is what the factories were asked to insert
    (a shortfall is noted). With ``wall`` None nothing is lifted (a heap poured through a fixed
    funnel): the heap forms while the factories fill, and settles after.
    ``callback(sim, t_end, final)`` as in ``simulate.rigs``.
    """
    run = HeapRun()
    dt = sim.dt

    def advance(seconds):
        n = int(round(seconds / dt))
        if n < 1:
            return False
        run.tally.add(sim.run(n_steps=n))
        run.ke_t.append(sim.time)
        run.ke.append(sim.kinetic_energy())
        if callback is not None:
            callback(sim, prof.duration, False)
        return True

    # fill, then (quick) wait for the fill to settle
    while advance(min(CHUNK_S, min(prof.fill_time, prof.duration) - sim.time)):
        pass
    if prof.lift_time is None:
        while sim.time < 0.5 * prof.duration and (rms_speed(sim) > SETTLED_SPEED or any(
                f.inserted < f.n_total for f in sim.factories)):
            advance(CHUNK_S)
        run.t_lift = sim.time
    else:
        run.t_lift = prof.lift_time
        while advance(min(CHUNK_S, min(prof.lift_time, prof.duration) - sim.time)):
            pass
    if wall is None:
        run.t_clear = run.t_lift
    else:
        z_top = float((sim.sphere_positions()[:, 2] + sim.sphere_radii()).max()) if sim.n_spheres else 0.0
        run.t_clear = run.t_lift + (z_top + clearance) / lift_speed
        stop = run.t_clear if prof.early_end else math.inf
        sim.set_wall_motion(wall, (0.0, 0.0, lift_speed), run.t_lift, stop)
    # flow and settle
    while advance(min(CHUNK_S, prof.duration - sim.time)):
        if prof.early_end and sim.time > run.t_clear + 0.2 and rms_speed(sim) < SETTLED_SPEED:
            break
    if callback is not None:
        callback(sim, prof.duration, True)
    inserted = sum(f.inserted for f in sim.factories)
    if inserted < fill_count:
        run.notes.append(f"only {inserted} of {fill_count} particles found room in the container")
    if sim.time < run.t_clear:
        run.notes.append(f"the run ended at {sim.time:.2f} s, before the wall was clear ({run.t_clear:.2f} s)")
    return run


def run_options(prof: ReposeProfile, geometry, force: bool, params) -> dict:
    """The provenance options of a heap run: profile, the rig's dimensions as given, the flank
    band of the photo estimator and the engine hooks in use."""
    from demcal.measure.repose import FLANK_BAND
    from demcal.simulate.extensions import engine_hooks

    options = {"profile": prof.name, "geometry": geometry.to_dict(), "force": force,
               "flank_band": list(FLANK_BAND)}
    hooks = engine_hooks(params)
    if hooks:
        options["extensions"] = hooks
    return options


def heap_task(rig: str, params, seed: int, *, profile: str, geometry) -> dict:
    """The inputs of one run of the repose rig ``rig`` (``analyse.runs.run_key`` keys its
    record); ``geometry`` the rig's dimensions or their ``to_dict()``."""
    if not isinstance(geometry, dict):
        geometry = geometry.to_dict()
    return {"rig": rig, "profile": profile, "params": params.to_dict(), "geometry": geometry, "seed": int(seed)}


def run_heap_task(run, geometry_class, inputs: dict) -> dict:
    """One run from its :func:`heap_task` by the rig's ``run``: the whole ``RigResult`` as a
    dict."""
    from demcal.simulate.params import DEMParameters

    params = DEMParameters.from_names(inputs["params"])
    return run(params, inputs["seed"], profile=inputs["profile"],
               geometry=geometry_class(**inputs["geometry"])).to_dict()


# ----------------------------------------------------------------------------------------------
# measuring a heap


def top_profile(centres, radii, x_min: float, x_max: float, step: float = PROFILE_STEP):
    """Upper envelope over y of the spheres seen from the side: z(x) = max over spheres of
    z_i + sqrt(r_i^2 - (x - x_i)^2), 0 (the floor) where no sphere covers x.

    Parameters
    ----------
    centres : array (n, 3)
        Sphere centres [m].
    radii : array (n,)
        Sphere radii [m].
    x_min, x_max : float
        Range of the profile [m].
    step : float
        Spacing [m].

    Returns
    -------
    x, z : numpy.ndarray
    """
    c = np.asarray(centres, dtype=float).reshape(-1, 3)
    r = np.broadcast_to(np.asarray(radii, dtype=float), (c.shape[0],))
    x = np.arange(x_min, x_max + 0.5 * step, step)
    z = np.zeros_like(x)
    if c.shape[0] == 0:
        return x, z
    lo = np.searchsorted(x, c[:, 0] - r)
    hi = np.searchsorted(x, c[:, 0] + r, side="right")
    for i in range(c.shape[0]):
        if hi[i] <= lo[i]:
            continue
        xs = x[lo[i]:hi[i]]
        top = c[i, 2] + np.sqrt(np.clip(r[i] ** 2 - (xs - c[i, 0]) ** 2, 0.0, None))
        np.maximum(z[lo[i]:hi[i]], top, out=z[lo[i]:hi[i]])
    return x, z


@dataclass(frozen=True)
class SideView:
    """A heap seen from the side and measured like the lab's photos.

    Attributes
    ----------
    angle_deg : float
        Photo method on the rendered side view, mean of the flanks measured [deg] (NaN if not
        measurable or not rendered).
    flanks_deg : dict
        ``{"left"/"right": deg}`` of the photo method's flanks.
    angle_profile_deg : float
        Profile fit of the same flanks [deg] (NaN if not measurable).
    crest_height : float
        Crest height of the profile fit [m].
    profile_x, profile_z : numpy.ndarray
        Top profile [m].
    notes : tuple of str
        Why an angle is NaN.
    """

    angle_deg: float
    flanks_deg: dict
    angle_profile_deg: float
    crest_height: float
    profile_x: np.ndarray
    profile_z: np.ndarray
    notes: tuple = ()


def side_view_angles(centres, radii, side: str, *, x_min: float | None = None,
                     px_per_m: float = PX_PER_M, annotate_to=None, band=None,
                     photo: bool = True) -> SideView:
    """Measure a heap from its spheres as the lab measures its photos.

    The spheres are projected along y onto the x-z plane; the top profile is fitted
    (``measure.repose.angle_from_profile``) and, with ``photo``, the rendered side view
    (``simulate.render.silhouette``, floor visible on both sides) is measured by the photo
    estimator (``measure.repose.angle_from_photo``), on the flank(s) ``side`` names.

    Parameters
    ----------
    centres : array (n, 3)
        Sphere centres [m], floor z = 0.
    radii : array (n,)
        Sphere radii [m].
    side : {"right", "left", "both"}
        Flank(s) to measure (a carton's heap has one, a cone two).
    x_min : float, optional
        Left end of the view before its margin [m] (default: the leftmost sphere).
    px_per_m : float
        Scale of the rendered side view [px/m].
    annotate_to : path, optional
        Write the annotated side view there.
    band : (float, float), optional
        Fitting band of the flank (default ``measure.repose.FLANK_BAND``).
    photo : bool
        Render the side view and run the photo method (else ``angle_deg`` is NaN).
    """
    from demcal.measure.repose import angle_from_photo, angle_from_profile
    from demcal.simulate.render import silhouette

    c = np.asarray(centres, dtype=float).reshape(-1, 3)
    r = np.broadcast_to(np.asarray(radii, dtype=float), (c.shape[0],))
    if c.shape[0] < 3:
        raise InputError(f"too few spheres ({c.shape[0]}) to make a heap")
    notes = []
    r_max = float(r.max())
    x_lo = float((c[:, 0] - r).min()) if x_min is None else min(x_min, float((c[:, 0] - r).min()))
    x_hi = float((c[:, 0] + r).max())
    margin = max(0.15 * (x_hi - x_lo), 0.02)      # floor visible on both sides
    x_lo, x_hi = x_lo - margin, x_hi + margin
    x, z = top_profile(c, r, x_lo, x_hi)
    try:
        fit = angle_from_profile(x, z, side=side, band=band)
        angle_profile, crest = fit.angle_deg, fit.crest_height
    except InputError as exc:
        notes.append(f"profile: {exc}")
        angle_profile, crest = math.nan, math.nan
    angle_photo, flanks = math.nan, {}
    if photo:
        # the floor fills the bottom 15 % of the image, a margin above the crest
        top = float(z.max())
        z_lo = -0.15 / 0.85 * (top + 2.0 * r_max)
        img = silhouette(c[:, [0, 2]], r, px_per_m=px_per_m, extent=(x_lo, x_hi, z_lo, top + 2.0 * r_max),
                         floor_z_m=0.0)
        try:
            res = angle_from_photo(img, side=side, annotate_to=annotate_to, band=band,
                                   scale_mm_per_px=1e3 / px_per_m)
            angle_photo = res.angle_deg
            flanks = {k: float(v) for k, v in res.flanks.items() if v is not None}
        except InputError as exc:
            notes.append(f"photo method: {exc}")
    return SideView(float(angle_photo), flanks, float(angle_profile), float(crest), x, z, tuple(notes))


__all__ = ["CHUNK_S", "HeapRun", "PROFILES", "PROFILE_STEP", "PX_PER_M", "ReposeProfile", "SETTLED_SPEED",
           "SideView", "fill_lift_settle", "heap_task", "meta_rows", "meta_values", "repose_profile", "rms_speed",
           "run_heap_task", "run_options", "side_view_angles", "top_profile"]


#: Bulk packing fraction of a loose random heap [-], for sizing fills and cones.
BULK_PACKING = 0.6
#: Observables of a cone read on both flanks (``cone_observables``) and their units.
CONE_OBSERVABLES = {"angle_deg": "deg", "angle_left_deg": "deg", "angle_right_deg": "deg",
                    "angle_profile_deg": "deg", "angle_cone_deg": "deg", "crest_height_m": "m",
                    "base_diameter_m": "m"}
#: The lab's crest height of a heap photographed from the side (``measure.pipeline``, with the
#: photos' scale) and the twin's, read the same way (``Rig.targets``).
CREST_TARGET = {"crest_height_mm": ("crest_height_m", 1e3)}
#: What a cone's observables measure (``Rig.observable_notes``), and ``escaped``, every heap's.
CONE_NOTES = {"angle_cone_deg": "atan of twice the crest height over the base diameter",
              "crest_height_m": "the top of the cone's profile", "base_diameter_m": "the cone's base, flank to flank",
              "escaped": "particles that left the simulated domain"}


def cone_height(bulk_volume: float, angle_deg: float) -> float:
    """Height [m] of a cone of ``bulk_volume`` [m^3] whose flanks rise at ``angle_deg``:
    V = pi h^3 / (3 tan^2 a)."""
    t = math.tan(math.radians(angle_deg))
    return (3.0 * bulk_volume * t * t / math.pi) ** (1.0 / 3.0)


def inscribed_half(diameter: float) -> float:
    """Half side [m] of the square inscribed in a circle of ``diameter``, less a margin of
    5 mm (at most 5 % of the diameter): a sphere placed in it is inside the circle's wall."""
    return (diameter / 2 - min(0.005, 0.05 * diameter)) / math.sqrt(2.0)


def check_dimensions(geometry, names, rig: str) -> None:
    """Refuse a rig's dimensions (dataclass fields ``names``) that are not positive numbers,
    and a ``fill_count`` that is not a positive integer (stored as an int)."""
    for name in names:
        value = getattr(geometry, name)
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise InputError(f"{rig}: {name} must be a positive number, got {value!r}")
    if geometry.fill_count is not None:
        if int(geometry.fill_count) != geometry.fill_count or geometry.fill_count < 1:
            raise InputError(f"{rig}: fill_count must be a positive integer, got {geometry.fill_count!r}")
        object.__setattr__(geometry, "fill_count", int(geometry.fill_count))


#: The arguments of every repose rig's ``run(params, seed, *, geometry, profile, annotate_to,
#: force, callback, size_distribution)``, for their docstrings.
RUN_ARGUMENTS = """
params : DEMParameters
    Materials, contact parameters, shape, mass model, rolling lever.
seed : int
    Seed of the particle factory.
geometry
    The rig's dimensions (its ``Rig.geometry`` class).
profile : {"paper", "quick"} or ReposeProfile
    How the run is carried out (``PROFILES``).
annotate_to : path, optional
    Write the annotated view of the heap there.
force : bool
    Allow a time step above half the Rayleigh time.
callback : callable, optional
    ``callback(sim, t_end, final)`` after each chunk (see ``simulate.rigs``).
size_distribution : simulate.extensions.SizeDistribution, optional
    Draw each particle from these measured sizes.
"""


def prepare_run(params, seed, geometry, geometry_class, profile, size_distribution):
    """The checked inputs of a repose rig's run: the seed, the parameters (with the size
    distribution), the profile, and the rig's dimensions with their fill for the shape (a heap
    the rig could not read refused here, before anything runs)."""
    from demcal.simulate.extensions import with_size_distribution  # scipy: only when running
    from demcal.simulate.params import DEMParameters
    from demcal.simulate.rigs import check_seed

    seed = check_seed(seed)
    if not isinstance(params, DEMParameters):
        raise InputError(f"params must be a DEMParameters, got {type(params).__name__}")
    if not isinstance(geometry, geometry_class):
        raise InputError(f"geometry must be a {geometry_class.__name__}, got {type(geometry).__name__}")
    if size_distribution is not None:
        params = with_size_distribution(params, size_distribution)
    geometry.check_fill(params.shape)
    geometry.check_for(params.shape)
    return seed, params, repose_profile(profile), geometry.filled_for(params.shape)


def pile_height_and_diameter(x, z) -> tuple:
    """Height [m] of a top profile ``z(x)`` and the width [m] of the pile under its highest
    point: the run of ``x`` around it where the profile stands above the floor, so that stray
    particles beyond a gap do not count."""
    x, z = np.asarray(x, float), np.asarray(z, float)
    if x.size == 0 or not np.any(z > 0):
        return 0.0, 0.0
    top = int(np.argmax(z))
    covered = z > 0
    lo = top
    while lo > 0 and covered[lo - 1]:
        lo -= 1
    hi = top
    while hi < x.size - 1 and covered[hi + 1]:
        hi += 1
    return float(z[top]), float(x[hi] - x[lo])


def cone_observables(view) -> dict:
    """The observables of a cone seen from the side (``heap.SideView``)."""
    h, d = pile_height_and_diameter(view.profile_x, view.profile_z)
    return {"angle_deg": view.angle_deg, "angle_left_deg": view.flanks_deg.get("left", math.nan),
            "angle_right_deg": view.flanks_deg.get("right", math.nan),
            "angle_profile_deg": view.angle_profile_deg,
            "angle_cone_deg": math.degrees(math.atan2(2.0 * h, d)) if d > 0 else math.nan,
            "crest_height_m": view.crest_height, "base_diameter_m": d}


def cli_arguments(group) -> None:
    """``demcal simulate repose``'s options (every repose rig's)."""
    group.add_argument("--profile", choices=tuple(PROFILES), default="quick",
                       help="paper: the source paper's schedule (10 s simulated); quick: the same rig and "
                            "fill with the idle time cut, for calibration campaigns (default)")
    group.add_argument("--annotate", metavar="PNG", help="write the annotated side view of the heap")


def cli_options(args) -> dict:
    """A repose run's options from ``demcal simulate repose``'s arguments."""
    return {"profile": args.profile, "annotate_to": args.annotate}
