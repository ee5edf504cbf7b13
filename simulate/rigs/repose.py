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

Profiles: ``paper`` and ``quick`` (``simulate.rigs.heap``). With the paper's carton the quick
profile simulates about 2.4 s instead of 10, and its heaps agree with the paper profile's within
the seed scatter.

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
from dataclasses import dataclass, replace

import numpy as np

from demcal.errors import InputError
from demcal.provenance import Provenance
from demcal.simulate.params import DEMParameters
from demcal.simulate.rigs import Rig, RigResult, check_seed, heap, run_meta
from demcal.simulate.rigs.heap import (PX_PER_M, RigDimensions, fill_lift_settle, heap_task,
                                       repose_profile, run_heap_task, run_options,
                                       side_view_angles)
from demcal.simulate.scenes import build_paper_repose_case
from demcal.simulate.timestep import material_time_step
from demcal.units import MM

#: The particle the default carton and fill were made for: segments of 25 x 11 mm [m].
REFERENCE_LENGTH, REFERENCE_WIDTH = 0.025, 0.011


@dataclass(frozen=True)
class ReposeGeometry(RigDimensions):
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

    def check_for(self, shape) -> None:
        """The carton's heap is read on its slope from the crest, inside the carton too, so any
        fill that flows out under the plate leaves a slope to read: nothing to refuse."""

    def describe(self, noun: str = "particles") -> str:
        """What the report says of the rig (``noun``: the particles' name, plural)."""
        return (f"a carton of {self.box_length * 1e3:g} × {self.box_width * 1e3:g} × {self.box_height * 1e3:g} mm "
                f"inside, filled with {self.fill_count} {noun}, its end plate lifted at "
                f"{self.lift_speed * 1e3:g} mm/s")


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
    from demcal.measure.repose import angle_from_profile

    view = side_view_angles(centres, radii, "right", x_min=0.0, px_per_m=px_per_m,
                            annotate_to=annotate_to, band=band, photo=photo)
    notes = list(view.notes)
    outside = view.profile_x > box_length
    try:
        angle_outside = angle_from_profile(view.profile_x[outside], view.profile_z[outside], side="right",
                                           band=band).angle_deg
    except InputError as exc:
        notes.append(f"outside heap: {exc}")
        angle_outside = math.nan
    return HeapAngles(view.angle_deg, view.angle_profile_deg, float(angle_outside), view.profile_x,
                      view.profile_z, view.crest_height, tuple(notes))


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
    from demcal.simulate.extensions import with_size_distribution  # scipy: only when running

    seed = check_seed(seed)
    if not isinstance(params, DEMParameters):
        raise InputError(f"params must be a DEMParameters, got {type(params).__name__}")
    if size_distribution is not None:
        params = with_size_distribution(params, size_distribution)
    prof = repose_profile(profile)
    base = geometry if geometry is not None else ReposeGeometry()
    if not isinstance(base, ReposeGeometry):
        raise InputError(f"geometry must be a ReposeGeometry, got {type(base).__name__}")
    base.check_fill(params.shape)
    geo = base.scaled(prof.scale) if prof.scale != 1.0 else base
    L, W, H = geo.box_length, geo.box_width, geo.box_height
    fill_margin = min(0.010, 0.1 * W)
    dt = material_time_step(params)
    sim = build_paper_repose_case(
        params, seed, n_clumps=geo.fill_count, box_length=L, box_width=W, box_height=H,
        lift_speed=geo.lift_speed, lift_time=prof.lift_time if prof.lift_time is not None else math.inf,
        fill_time=prof.fill_time, fill_margin=fill_margin, fill_bottom=prof.fill_bottom * H,
        fill_top=prof.fill_top * H, dt=dt, outside_length=prof.outside_length * L, force=force)
    # the plate is clear once its lower edge is a particle's width above the highest sphere
    width = max(float(shape.extent[1]) for shape in params.sized_shapes())
    run = fill_lift_settle(sim, sim.wall_index("end plate"), geo.lift_speed, prof, width, geo.fill_count,
                           callback=callback)
    act = sim.active()
    keep = act[sim.sphere_body()]
    pos, rad = sim.sphere_positions()[keep], sim.sphere_radii()[keep]
    body = sim.positions()
    heap = heap_angles(pos, rad, L, annotate_to=annotate_to)
    notes = list(heap.notes) + run.notes
    inserted = sum(f.inserted for f in sim.factories)
    n_act = int(act.sum())
    observable = {
        "angle_deg": heap.angle_deg,
        "angle_profile_deg": heap.angle_profile_deg,
        "angle_outside_deg": heap.angle_outside_deg,
        "escaped": len(sim.escaped),
        "outside_fraction": float(np.mean(body[act, 0] > L)) if n_act else math.nan,
        "crest_height_m": heap.crest_height,
    }
    rec = {"profile_x": heap.profile_x, "profile_z": heap.profile_z, "crest_height": heap.crest_height,
           "sphere_positions": pos, "sphere_radii": rad, "sphere_body": sim.sphere_body()[keep],
           "body_positions": body[act], "geometry": geo.to_dict(), "t_lift": run.t_lift,
           "t_clear": run.t_clear, "t_end": sim.time, "ke_t": np.array(run.ke_t), "ke": np.array(run.ke),
           "escapes": [e.to_dict() for e in sim.escaped]}
    options = run_options(prof, base, force, params)
    meta = run_meta(seed, dt, run.tally, sim.n_spheres, sim.time, profile=prof.name, notes=notes,
                    profile_settings=prof.to_dict(), bodies=sim.n_bodies,
                    inserted=inserted)
    return RigResult("repose", observable, rec, meta, params.to_dict(), Provenance(seed=seed, options=options))


# ----------------------------------------------------------------------------------------------
# a run as a task: what a run store keys and a worker runs


def task(params: DEMParameters, seed: int, *, profile: str, geometry) -> dict:
    """The inputs of one repose run (``heap.heap_task``); ``geometry`` a :class:`ReposeGeometry` or its
    ``to_dict()``."""
    return heap_task("repose", params, seed, profile=profile, geometry=geometry)


def run_task(inputs: dict) -> dict:
    """One repose run from its :func:`task`: the whole :class:`RigResult` as a dict."""
    return run_heap_task(run_repose, ReposeGeometry, inputs)


def measure_heap(centres, radii, geometry) -> dict:
    """The angle observables of a settled heap of spheres in the carton ``geometry`` (a
    :class:`ReposeGeometry` or its dict), e.g. LIGGGHTS' final positions."""
    box_length = geometry["box_length"] if isinstance(geometry, dict) else geometry.box_length
    heap = heap_angles(centres, radii, box_length)
    return {"angle_deg": heap.angle_deg, "angle_profile_deg": heap.angle_profile_deg,
            "angle_outside_deg": heap.angle_outside_deg, "notes": list(heap.notes)}


def liggghts_case(params: DEMParameters, geometry: ReposeGeometry, lift_time: float):
    """The carton in LIGGGHTS (``simulate.liggghts.deck.ReposeCase``), the plate lifted at
    ``lift_time`` [s]."""
    from demcal.simulate.liggghts.deck import ReposeCase

    return replace(ReposeCase.for_params(params, geometry), plate_lift_start=float(lift_time))


RIG = Rig("repose", sheet="repose", run=run_repose, task=task, run_task=run_task, compared="angle_deg",
          # a frictionless floor can spread the heap flat: the direct profile fit of the full
          # slope, then the heap beyond the carton
          fallbacks=("angle_profile_deg", "angle_outside_deg"),
          observables={"angle_deg": "deg", "angle_profile_deg": "deg", "angle_outside_deg": "deg",
                       "escaped": "-", "outside_fraction": "-", "crest_height_m": "m"},
          targets=heap.CREST_TARGET, recorded_as={"crest_height_m": "crest_height"},
          observable_notes={"outside_fraction": "share of the particles whose centre ends beyond the end plate",
                            "angle_outside_deg": "the pile beyond the carton",
                            "crest_height_m": "the top of the heap's profile",
                            "escaped": heap.CONE_NOTES["escaped"]},
          geometry=ReposeGeometry, workbook_name="lifted_plate", flanks="right",
          lab_test="plate withdrawal (pumping plate) heap, side photograph of its flank", measure=measure_heap,
          liggghts_case=liggghts_case, cli_arguments=heap.cli_arguments, cli_options=heap.cli_options)
