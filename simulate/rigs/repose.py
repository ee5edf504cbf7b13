"""Repose rig: the twin of the plate-withdrawal ("pumping plate") angle-of-repose test.

The lab fills a carton with segments, pulls its end plate up, lets the segments flow out and
come to rest, and photographs the heap from the side (docs/design.md, "Rigs"). The twin builds the
same carton (``simulate.scenes.build_paper_repose_case``: carton of inside ``box_length`` x
``box_width`` x ``box_height``, x along its length, back wall x = 0, end plate x = L, open top,
steel floor z = 0), fills it with segments from a particle factory, lifts the plate and lets
the heap settle. The heap is then measured in three ways:

``angle_deg`` (compared with the lab's photos)
    The side view of the spheres is rendered to an image (``simulate.render.silhouette``, all
    spheres projected along y onto the x-z plane, floor included) and measured by the photo
    estimator ``measure.repose.angle_from_photo`` on its right flank, the slope falling from
    the crest: simulation and lab are measured the same way.
``angle_profile_deg``
    ``measure.repose.angle_from_profile`` on the heap's top profile, the upper envelope over y
    of the spheres' x-z discs on a 1 mm grid (what the silhouette shows), right flank: the full
    slope from the crest (inside the carton too) down to the toe.
``angle_outside_deg``
    The same fit restricted to the profile beyond the end plate (x > L), from its own top at
    the plate line to its toe. With the paper's carton only about 10 % of the segments leave
    it, so this heap is a few segments high and its angle noisy (docs/design.md); it is reported,
    not compared.

Profiles (``PROFILES``):

``paper``
    The source paper's case: the workbook's carton and fill count (default 500 segments in
    200 x 100 x 250 mm), segments inserted at random during the first second in the upper part
    of the carton (z from 0.4 to 0.96 of its height), the end plate lifted at t = 4 s at the
    logged speed, 10 s in all, at the parameter set's time step (the paper's 7.43678e-5 s).
``quick``
    For calibration campaigns (about 45 runs within 15 minutes on 2 cores). The same carton,
    fill count, lift speed, time step and contact model as the paper case; only the idle
    time is cut: the segments are inserted over 0.5 s into the whole height of the carton
    (z from 0.1 to 0.96 of it), the plate is lifted as soon as the fill has settled (rms speed
    of the bodies below ``SETTLED_SPEED``, about 0.4 s later) and stopped once its lower edge
    is a segment diameter above the highest sphere, and the run ends when the heap has
    settled after that (or at 4 s): about 2.4 s simulated instead of 10. The heap forms while
    the plate rises, exactly as in the paper case, so the angles agree within the seed
    scatter and respond to the contact parameters in the same directions.

Size distribution. With ``size_distribution`` (or ``params.particle_sizes``) each particle is
drawn from the measured sizes (``simulate.extensions``, engine hook
``size_distribution``); the engine hooks in use are named in the provenance options
(``extensions``).

Observable keys: ``angle_deg``, ``angle_profile_deg``, ``angle_outside_deg`` [deg],
``escaped`` (bodies that left the simulation domain), ``outside_fraction`` (share of the
bodies whose centre is beyond the end plate) [-].
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace

import numpy as np

from demcal.errors import InputError, WorkbookError
from demcal.provenance import Provenance
from demcal.simulate.params import DEMParameters
from demcal.simulate.rigs import RigResult, RunTally, check_seed, run_meta
from demcal.simulate.scenes import PAPER_DURATION, build_paper_repose_case
from demcal.simulate.timestep import material_time_step
from demcal.units import MM

#: rms speed of the bodies below which a fill or a heap counts as settled [m/s].
SETTLED_SPEED = 0.005
#: Resolution of the rendered side view [px/m] (0.5 mm per pixel).
PX_PER_M = 2000.0
#: Spacing of the top profile [m].
PROFILE_STEP = 0.001


#: The particle the default carton and fill were made for: segments of 25 x 11 mm [m].
REFERENCE_LENGTH, REFERENCE_WIDTH = 0.025, 0.011


@dataclass(frozen=True)
class ReposeGeometry:
    """The repose rig's carton and fill, as in the workbook's ``meta`` sheet.

    Attributes
    ----------
    box_length, box_width, box_height : float
        Inside of the carton [m]; the end plate closes the length.
    lift_speed : float
        Speed at which the end plate is pulled up [m/s].
    fill_count : int
        Segments poured into the carton.
    """

    box_length: float = 0.200
    box_width: float = 0.100
    box_height: float = 0.250
    lift_speed: float = 0.100
    fill_count: int = 500

    #: meta key -> (field, factor to SI)
    META_KEYS = {"box_length_mm": ("box_length", MM), "box_width_mm": ("box_width", MM),
                 "box_height_mm": ("box_height", MM), "plate_lift_speed_mm_s": ("lift_speed", MM),
                 "fill_count": ("fill_count", 1)}

    def __post_init__(self):
        for name in ("box_length", "box_width", "box_height", "lift_speed"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise InputError(f"repose geometry: {name} must be a positive number, got {value!r}")
        if int(self.fill_count) != self.fill_count or self.fill_count < 1:
            raise InputError(f"repose geometry: fill_count must be a positive integer, got {self.fill_count!r}")
        object.__setattr__(self, "fill_count", int(self.fill_count))

    @classmethod
    def from_meta(cls, meta: dict, file=None) -> "ReposeGeometry":
        """From a workbook ``meta`` dict (keys ``box_length_mm``, ``box_width_mm``,
        ``box_height_mm``, ``plate_lift_speed_mm_s``, ``fill_count``; docs/workbook.md); a
        missing or empty key keeps the default (200, 100, 250 mm, 100 mm/s, 500). A bad value
        raises ``WorkbookError`` naming the sheet, the key and the value (and ``file``), and so
        does a heap of another rig (``repose_rig``, or that rig's dimensions): the twin would
        simulate the carton while the lab photographed another heap."""
        _refuse_other_rigs(meta or {}, file)
        values = {}
        for key, (name, factor) in cls.META_KEYS.items():
            raw = meta.get(key) if meta else None
            if raw is None or (isinstance(raw, str) and not raw.strip()):
                continue

            def bad(why):
                return WorkbookError(f"meta {key}: {why}", file=file, sheet="meta", column="value", value=raw)

            try:
                number = float(raw)
            except (TypeError, ValueError):
                raise bad("needs a number") from None
            if not (math.isfinite(number) and number > 0):
                raise bad("must be positive")
            if name == "fill_count":
                if number != int(number):
                    raise bad("needs a whole number")
                values[name] = int(number)
            else:
                values[name] = number * factor
        return cls(**values)

    @classmethod
    def for_particle(cls, shape) -> "ReposeGeometry":
        """The default carton in proportion to a particle (``simulate.shapes``): scaled by the
        particle's width over ``REFERENCE_WIDTH``, the width it was made for, and filled with as
        many particles as make the same bulk volume (at least 10)."""
        from demcal.simulate.shapes.segment import Segment

        default = cls()
        factor = float(shape.extent[1]) / REFERENCE_WIDTH
        reference = Segment(REFERENCE_LENGTH, REFERENCE_WIDTH).volume() * factor ** 3
        return replace(default.scaled(factor),
                       fill_count=max(10, int(round(default.fill_count * reference / shape.volume()))))

    def scaled(self, factor: float) -> "ReposeGeometry":
        """The carton scaled by ``factor`` in every dimension, the fill count by its cube (at
        least 10), the lift speed kept."""
        return replace(self, box_length=self.box_length * factor, box_width=self.box_width * factor,
                       box_height=self.box_height * factor,
                       fill_count=max(10, int(round(self.fill_count * factor ** 3))))

    def to_dict(self) -> dict:
        return asdict(self)


#: The repose rig this twin is (meta ``repose_rig``, the default when it is not given).
REPOSE_RIG = "lifted_plate"
#: Repose rigs labs use that the twin does not simulate, with the prefix of their meta keys.
OTHER_REPOSE_RIGS = {"lifting_cylinder": "cylinder_", "funnel": "funnel_", "drum": "drum_"}


def _refuse_other_rigs(meta: dict, file) -> None:
    """Refuse a workbook whose heap is not the lifted plate's, by its ``repose_rig`` or a
    dimension of another rig, naming the key."""
    rig = meta.get("repose_rig")
    if rig is not None and str(rig).strip() and str(rig).strip().lower() != REPOSE_RIG:
        raise WorkbookError(f"meta repose_rig: the repose twin simulates the carton with a lifted end plate "
                            f"({REPOSE_RIG}) only, so a heap of another rig cannot be calibrated against "
                            f"(its photos still measure with demcal measure); rigs labs use: "
                            f"{', '.join((REPOSE_RIG, *OTHER_REPOSE_RIGS))}",
                            file=file, sheet="meta", column="value", value=rig)
    for key, value in meta.items():
        if value is None or (isinstance(value, str) and not value.strip()):
            continue                              # a blank row of a template says nothing
        other = next((r for r, prefix in OTHER_REPOSE_RIGS.items() if str(key).startswith(prefix)), None)
        if other is not None:
            raise WorkbookError(f"meta {key}: a dimension of the {other} rig, which the repose twin does not "
                                f"simulate (it simulates the lifted plate: {', '.join(ReposeGeometry.META_KEYS)})",
                                file=file, sheet="meta", column="key", value=key)


@dataclass(frozen=True)
class ReposeProfile:
    """How a repose run is carried out (see the module docstring).

    Attributes
    ----------
    name : str
    scale : float
        Linear scale of the carton (fill count scaled by its cube) [-].
    fill_time : float
        Segments are inserted uniformly over [0, fill_time] [s].
    fill_bottom, fill_top : float
        Insertion region height, as fractions of the carton height [-].
    lift_time : float or None
        Time the plate starts rising [s]; None: as soon as the fill has settled.
    duration : float
        Simulated time [s]; the largest one when ``early_end``.
    early_end : bool
        End once the heap has settled after the plate is clear; stop the plate then too.
    outside_length : float
        Floor beyond the carton kept in the simulation domain, relative to the carton length [-].
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


# ----------------------------------------------------------------------------------------------
# measuring a heap


@dataclass(frozen=True)
class HeapAngles:
    """Angles of a heap left by the plate-withdrawal rig (see the module docstring).

    Attributes
    ----------
    angle_deg : float
        Photo method on the rendered side view [deg] (NaN if not measurable).
    angle_profile_deg : float
        Profile fit of the full slope [deg].
    angle_outside_deg : float
        Profile fit of the heap beyond the carton [deg] (NaN if too small to fit).
    profile_x, profile_z : numpy.ndarray
        Top profile [m].
    crest_height : float
        Crest height of the profile fit [m].
    notes : tuple of str
        Why an angle is NaN.
    """

    angle_deg: float
    angle_profile_deg: float
    angle_outside_deg: float
    profile_x: np.ndarray
    profile_z: np.ndarray
    crest_height: float
    notes: tuple = ()

    def to_dict(self) -> dict:
        return {"angle_deg": self.angle_deg, "angle_profile_deg": self.angle_profile_deg,
                "angle_outside_deg": self.angle_outside_deg, "profile_x": self.profile_x,
                "profile_z": self.profile_z, "crest_height": self.crest_height, "notes": list(self.notes)}


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


def heap_angles(centres, radii, box_length: float, *, px_per_m: float = PX_PER_M,
                annotate_to=None, band=None, photo: bool = True) -> HeapAngles:
    """Measure the heap of a plate-withdrawal run from its spheres (demcal's or another code's).

    Parameters
    ----------
    centres : array (n, 3)
        Sphere centres [m] (x along the carton, back wall x = 0, end plate x = ``box_length``,
        floor z = 0).
    radii : array (n,)
        Sphere radii [m].
    box_length : float
        Carton length [m].
    px_per_m : float
        Scale of the rendered side view [px/m].
    annotate_to : path, optional
        Write the annotated side view (photo method) there.
    band : (float, float), optional
        Fitting band of the flank for every method (default ``measure.repose.FLANK_BAND``, as
        for the lab's photos).
    photo : bool
        Also render the side view and run the photo method (else ``angle_deg`` is NaN).

    Returns
    -------
    HeapAngles
    """
    from demcal.measure.repose import angle_from_photo, angle_from_profile
    from demcal.simulate.render import silhouette

    c = np.asarray(centres, dtype=float).reshape(-1, 3)
    r = np.broadcast_to(np.asarray(radii, dtype=float), (c.shape[0],))
    if c.shape[0] < 3:
        raise InputError(f"heap_angles: too few spheres ({c.shape[0]}) to make a heap")
    notes = []
    r_max = float(r.max())
    # floor visible on both sides (the photo method finds the floor line there)
    x_lo = min(0.0, float((c[:, 0] - r).min()))
    x_hi = float((c[:, 0] + r).max())
    margin = max(0.15 * (x_hi - x_lo), 0.02)
    x_lo, x_hi = x_lo - margin, x_hi + margin
    x, z = top_profile(c, r, x_lo, x_hi)

    def fit(xs, zs, label):
        try:
            res = angle_from_profile(xs, zs, side="right", band=band)
        except InputError as exc:
            notes.append(f"{label}: {exc}")
            return math.nan, math.nan
        return res.angle_deg, res.crest_height

    angle_profile, crest = fit(x, z, "profile")
    outside = x > box_length
    angle_outside, _ = fit(x[outside], z[outside], "outside heap")

    if not photo:
        return HeapAngles(math.nan, float(angle_profile), float(angle_outside), x, z, float(crest),
                          tuple(notes))
    # side view: the floor fills the bottom 15 % of the image, a margin above the crest
    top = float(z.max())
    z_lo = -0.15 / 0.85 * (top + 2.0 * r_max)
    img = silhouette(c[:, [0, 2]], r, px_per_m=px_per_m, extent=(x_lo, x_hi, z_lo, top + 2.0 * r_max),
                     floor_z_m=0.0)
    try:
        angle_photo = angle_from_photo(img, side="right", annotate_to=annotate_to, band=band,
                                       scale_mm_per_px=1e3 / px_per_m).angle_deg
    except InputError as exc:
        notes.append(f"photo method: {exc}")
        angle_photo = math.nan
    return HeapAngles(float(angle_photo), float(angle_profile), float(angle_outside), x, z,
                      float(crest), tuple(notes))


# ----------------------------------------------------------------------------------------------
# the run


def run_repose(params: DEMParameters, seed: int = 0, *, profile: str = "quick",
               geometry: ReposeGeometry | None = None, annotate_to=None, force: bool = False,
               callback=None, size_distribution=None) -> RigResult:
    """Run the plate-withdrawal repose test and measure the heap.

    Parameters
    ----------
    params : DEMParameters
        Materials, contact parameters, segment shape, mass model, rolling lever.
    seed : int
        Seed of the particle factory.
    profile : {"paper", "quick"} or ReposeProfile
        How the run is carried out (``PROFILES``).
    geometry : ReposeGeometry, optional
        Carton, lift speed and fill count; default the paper's (workbook defaults).
    annotate_to : path, optional
        Write the annotated side view of the heap there.
    force : bool
        Allow a time step above half the Rayleigh time.
    callback : callable, optional
        ``callback(sim, t_end, final)`` after each chunk (see ``simulate.rigs``).
    size_distribution : simulate.extensions.SizeDistribution, optional
        Draw each particle from these measured sizes; they are set as
        ``params.particle_sizes``, so the result's ``params`` record them. Default: as
        ``params`` says (one particle size unless ``particle_sizes`` is set).

    Returns
    -------
    RigResult
        ``observable``: ``angle_deg``, ``angle_profile_deg``, ``angle_outside_deg`` [deg],
        ``escaped``, ``outside_fraction``. ``record``: ``profile_x``, ``profile_z`` [m],
        ``sphere_positions`` [m], ``sphere_radii`` [m], ``sphere_body``, ``body_positions``
        [m], ``geometry`` (the carton simulated), ``t_lift``, ``t_clear``, ``t_end`` [s], and
        the kinetic-energy history ``ke_t`` [s], ``ke`` [J].
    """
    from demcal.simulate.extensions import engine_hooks, with_size_distribution  # scipy: only when running

    seed = check_seed(seed)
    if not isinstance(params, DEMParameters):
        raise InputError(f"params must be a DEMParameters, got {type(params).__name__}")
    if size_distribution is not None:
        params = with_size_distribution(params, size_distribution)
    if isinstance(profile, ReposeProfile):
        prof = profile
    elif profile in PROFILES:
        prof = PROFILES[profile]
    else:
        raise InputError(f"unknown repose profile {profile!r}; valid: {', '.join(PROFILES)}")
    base = geometry if geometry is not None else ReposeGeometry()
    if not isinstance(base, ReposeGeometry):
        raise InputError(f"geometry must be a ReposeGeometry, got {type(base).__name__}")
    geo = base.scaled(prof.scale) if prof.scale != 1.0 else base
    L, W, H = geo.box_length, geo.box_width, geo.box_height
    fill_margin = min(0.010, 0.1 * W)
    dt = material_time_step(params)
    sim = build_paper_repose_case(
        params, seed, n_clumps=geo.fill_count, box_length=L, box_width=W, box_height=H,
        lift_speed=geo.lift_speed, lift_time=prof.lift_time if prof.lift_time is not None else math.inf,
        fill_time=prof.fill_time, fill_margin=fill_margin, fill_bottom=prof.fill_bottom * H,
        fill_top=prof.fill_top * H, dt=dt, outside_length=prof.outside_length * L, force=force)
    plate = sim.wall_index("end plate")
    tally = RunTally()
    ke_t, ke = [], []
    chunk = 0.05                      # simulated seconds between checks [s]

    def advance(seconds):
        n = int(round(seconds / dt))
        if n < 1:
            return False
        tally.add(sim.run(n_steps=n))
        ke_t.append(sim.time)
        ke.append(sim.kinetic_energy())
        if callback is not None:
            callback(sim, prof.duration, False)
        return True

    def advance_to(t_target):
        while advance(min(chunk, t_target - sim.time)):
            pass

    def rms_speed():
        act = sim.active()
        m = sim.masses()[act].sum()
        return math.sqrt(2.0 * sim.kinetic_energy() / m) if m > 0 else 0.0

    # fill, then (quick) wait for the fill to settle and lift the plate
    advance_to(min(prof.fill_time, prof.duration))
    t_lift = prof.lift_time
    if t_lift is None:
        while sim.time < 0.5 * prof.duration and (rms_speed() > SETTLED_SPEED or any(
                f.inserted < f.n_total for f in sim.factories)):
            advance(chunk)
        t_lift = sim.time
    else:
        advance_to(min(t_lift, prof.duration))
    # the plate is clear once its lower edge is a particle's width above the highest sphere
    z_top = float((sim.sphere_positions()[:, 2] + sim.sphere_radii()).max()) if sim.n_spheres else 0.0
    width = max(float(shape.extent[1]) for shape in params.sized_shapes())
    t_clear = t_lift + (z_top + width) / geo.lift_speed
    if prof.early_end:
        sim.set_wall_motion(plate, (0.0, 0.0, geo.lift_speed), t_lift, t_clear)
    else:
        sim.set_wall_motion(plate, (0.0, 0.0, geo.lift_speed), t_lift)
    # flow and settle
    while advance(min(chunk, prof.duration - sim.time)):
        if prof.early_end and sim.time > t_clear + 0.2 and rms_speed() < SETTLED_SPEED:
            break
    if callback is not None:
        callback(sim, prof.duration, True)

    act = sim.active()
    keep = act[sim.sphere_body()]
    pos, rad = sim.sphere_positions()[keep], sim.sphere_radii()[keep]
    body = sim.positions()
    heap = heap_angles(pos, rad, L, annotate_to=annotate_to)
    notes = list(heap.notes)
    inserted = sum(f.inserted for f in sim.factories)
    if inserted < geo.fill_count:
        notes.append(f"only {inserted} of {geo.fill_count} segments found room in the carton")
    if sim.time < t_clear:
        notes.append(f"the run ended at {sim.time:.2f} s, before the plate was clear ({t_clear:.2f} s)")
    n_act = int(act.sum())
    observable = {
        "angle_deg": heap.angle_deg,
        "angle_profile_deg": heap.angle_profile_deg,
        "angle_outside_deg": heap.angle_outside_deg,
        "escaped": len(sim.escaped),
        "outside_fraction": float(np.mean(body[act, 0] > L)) if n_act else math.nan,
    }
    rec = {"profile_x": heap.profile_x, "profile_z": heap.profile_z, "crest_height": heap.crest_height,
           "sphere_positions": pos, "sphere_radii": rad, "sphere_body": sim.sphere_body()[keep],
           "body_positions": body[act], "geometry": geo.to_dict(), "t_lift": t_lift, "t_clear": t_clear,
           "t_end": sim.time, "ke_t": np.array(ke_t), "ke": np.array(ke),
           "escapes": [e.to_dict() for e in sim.escaped]}
    from demcal.measure.repose import FLANK_BAND
    options = {"profile": prof.name, "geometry": base.to_dict(), "force": force,
               "flank_band": list(FLANK_BAND)}
    hooks = engine_hooks(params)
    if hooks:
        options["extensions"] = hooks
    meta = run_meta(seed, dt, tally, sim.n_spheres, sim.time, profile=prof.name, notes=notes,
                    profile_settings=prof.to_dict(), bodies=sim.n_bodies,
                    inserted=inserted)
    return RigResult("repose", observable, rec, meta, params.to_dict(), Provenance(seed=seed, options=options))


# ----------------------------------------------------------------------------------------------
# a run as a task: what a run store keys and a worker runs


def task(params: DEMParameters, seed: int, *, profile: str, geometry) -> dict:
    """The inputs of one repose run (``analyse.runs.run_key`` keys its record); ``geometry`` a
    :class:`ReposeGeometry` or its ``to_dict()``."""
    if isinstance(geometry, ReposeGeometry):
        geometry = geometry.to_dict()
    return {"rig": "repose", "profile": profile, "params": params.to_dict(), "geometry": geometry,
            "seed": int(seed)}


def run_task(inputs: dict) -> dict:
    """One repose run from its :func:`task`: the whole :class:`RigResult` as a dict."""
    params = DEMParameters.from_names(inputs["params"])
    return run_repose(params, inputs["seed"], profile=inputs["profile"],
                      geometry=ReposeGeometry(**inputs["geometry"])).to_dict()
