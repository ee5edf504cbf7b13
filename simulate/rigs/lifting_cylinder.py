"""Lifting-cylinder rig: the twin of the most common repose test of seeds and grains.

The lab stands an open tube on a floor, fills it, lifts it at a steady speed and photographs
the cone left on the floor from the side, both flanks (meta ``repose_rig: lifting_cylinder``).
The twin builds the same tube (``simulate.walls.Cylinder``, axis z, standing on the steel floor
z = 0, centred on x = y = 0), fills it from a particle factory (the square inscribed in the
tube, z from ``fill_bottom`` to ``fill_top`` of its height, ``simulate.rigs.heap`` profiles),
waits for the fill to settle, lifts the tube at the logged speed until its rim is a particle's
width above the fill, and lets the cone settle. The cone is then seen along y, as the camera
sees it, and measured by the photo estimator on both flanks (``simulate.rigs.heap.
side_view_angles``): the lab's photos and the twin's view are measured the same way.

Fill. Without a ``fill_count`` in the workbook the tube is filled to ``FILL_SHARE`` of its
volume at the bulk packing ``BULK_PACKING`` (a loose random packing) of the particle's volume.
A fill too small for the photo estimator to read (a cone under ``MIN_LAYERS`` particle widths
high at ``LOWEST_ANGLE_DEG``) or a tube too narrow for the particles to flow out of (under
``MIN_DIAMETER_LENGTHS`` particle lengths) is refused before any run
(:meth:`CylinderGeometry.check_for`).

Observable keys: ``angle_deg`` (photo method, mean of the flanks), ``angle_left_deg``,
``angle_right_deg`` [deg], ``angle_profile_deg`` (profile fit, both flanks) [deg],
``angle_cone_deg`` (the height-and-diameter method, atan(2 h / D) of the top profile's height h
and the width D of the pile under it, stray particles apart [deg]; it reads a heap the flank
fits cannot, e.g. seeds that spread into a layer or two), ``crest_height_m``,
``base_diameter_m`` [m], ``escaped`` (bodies that left the simulation domain).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from demcal.errors import InputError
from demcal.provenance import Provenance
from demcal.simulate.params import DEMParameters
from demcal.simulate.rigs import Rig, RigResult, heap, run_meta
from demcal.simulate.rigs.heap import (BULK_PACKING, CONE_NOTES, CONE_OBSERVABLES, RigDimensions, check_dimensions,
                                       cone_height, cone_observables, fill_lift_settle, heap_task,
                                       inscribed_half, prepare_run, run_heap_task, run_options,
                                       side_view_angles)
from demcal.simulate.timestep import material_time_step
from demcal.units import MM

#: Share of the tube's volume filled when the workbook gives no fill count [-].
FILL_SHARE = 0.5
#: The cone must be at least this many particle widths high at ``LOWEST_ANGLE_DEG``.
MIN_LAYERS = 4.0
#: The flattest cone the check allows for [deg].
LOWEST_ANGLE_DEG = 20.0
#: The tube must be at least this many particle lengths across.
MIN_DIAMETER_LENGTHS = 4.0


@dataclass(frozen=True)
class CylinderGeometry(RigDimensions):
    """The lifting cylinder and its fill, as in the workbook's ``meta`` sheet.

    Attributes
    ----------
    diameter, height : float
        Inside diameter and height of the tube [m].
    lift_speed : float
        Speed at which the tube is lifted [m/s].
    fill_count : int or None
        Particles poured into the tube; None: ``FILL_SHARE`` of its volume (``filled_for``).
    """

    diameter: float
    height: float
    lift_speed: float
    fill_count: int | None = None

    #: meta key -> (field, factor to SI)
    META_KEYS = {"cylinder_diameter_mm": ("diameter", MM), "cylinder_height_mm": ("height", MM),
                 "lift_speed_mm_s": ("lift_speed", MM), "fill_count": ("fill_count", 1)}
    #: meta keys the workbook must give
    REQUIRED = ("cylinder_diameter_mm", "cylinder_height_mm", "lift_speed_mm_s")

    def __post_init__(self):
        check_dimensions(self, ("diameter", "height", "lift_speed"), "lifting cylinder")

    def filled_for(self, shape) -> "CylinderGeometry":
        """The same tube with its fill count: the workbook's, or ``FILL_SHARE`` of the tube's
        volume at ``BULK_PACKING`` of ``shape``'s volume (at least 10)."""
        if self.fill_count is not None:
            return self
        volume = math.pi * self.diameter ** 2 / 4.0 * self.height
        return replace(self, fill_count=max(10, int(round(FILL_SHARE * BULK_PACKING * volume / shape.volume()))))

    def check_for(self, shape) -> None:
        """Refuse a tube whose cone the photo estimator could not read, or that the particles
        could not flow out of (module docstring), naming what to change."""
        geo = self.filled_for(shape)
        length, width = float(shape.extent[0]), float(shape.extent[1])
        if self.diameter < MIN_DIAMETER_LENGTHS * length:
            raise InputError(f"lifting cylinder: a tube of {self.diameter * 1e3:g} mm is under {MIN_DIAMETER_LENGTHS:g} "
                             f"particle lengths ({length * 1e3:.3g} mm) across, so the fill would arch instead of "
                             "flowing out; use a wider tube (meta cylinder_diameter_mm)")
        h = cone_height(geo.fill_count * shape.volume() / BULK_PACKING, LOWEST_ANGLE_DEG)
        if h < MIN_LAYERS * width:
            raise InputError(f"lifting cylinder: {geo.fill_count} particles make a cone about {h * 1e3:.3g} mm high at "
                             f"{LOWEST_ANGLE_DEG:g} deg, under {MIN_LAYERS:g} particle widths ({width * 1e3:.3g} mm), "
                             "too few layers for its flanks to be read; raise meta fill_count or the tube's size")

    def describe(self, noun: str = "particles") -> str:
        """What the report says of the rig (``noun``: the particles' name, plural)."""
        fill = f"{self.fill_count} {noun}" if self.fill_count else f"{noun} to {FILL_SHARE:.0%} of its volume"
        return (f"a cylinder of {self.diameter * 1e3:g} mm inside diameter and {self.height * 1e3:g} mm height "
                f"standing on the floor, filled with {fill} and lifted at {self.lift_speed * 1e3:g} mm/s")


def build_lifting_cylinder(params: DEMParameters, seed, geo: CylinderGeometry, prof, *, dt: float,
                           force: bool = False, size_distribution=None):
    """The tube on its floor with a factory filling it, ready to run; the tube's wall is named
    ``cylinder`` (``sim.wall_index``)."""
    from demcal.simulate.engine import Simulation
    from demcal.simulate.factory import ParticleFactory
    from demcal.simulate.materials import MaterialTable
    from demcal.simulate.scenes import particle_templates
    from demcal.simulate.walls import Cylinder, Plane

    D, H = geo.diameter, geo.height
    # floor for the flattest cone of the fill, and at least the tube's own width
    bulk = geo.fill_count * params.shape.volume() / BULK_PACKING
    h = cone_height(bulk, 15.0)
    reach = max(1.5 * h / math.tan(math.radians(15.0)), D) + 0.05
    sim = Simulation(MaterialTable.from_parameters(params), domain_lo=(-reach, -reach, -0.02),
                     domain_hi=(reach, reach, H + 0.05), dt=dt, rolling_lever=params.rolling_lever, force=force)
    templates, weights = particle_templates(sim, params, size_distribution)
    sim.add_wall(Plane((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), material="steel", name="floor"))
    sim.add_wall(Cylinder((0.0, 0.0, H / 2), (0.0, 0.0, 1.0), D / 2, H / 2, "steel", name="cylinder"))
    half = inscribed_half(D)
    sim.add_factory(ParticleFactory(templates, geo.fill_count, (-half, -half, prof.fill_bottom * H),
                                    (half, half, prof.fill_top * H), seed=seed, start_time=0.0,
                                    end_time=prof.fill_time, material="particle", weights=weights))
    return sim


def run_lifting_cylinder(params: DEMParameters, seed: int = 0, *, geometry: CylinderGeometry,
                         profile: str = "quick", annotate_to=None, force: bool = False, callback=None,
                         size_distribution=None) -> RigResult:
    """Run the lifting-cylinder repose test and measure the cone (module docstring).

    The arguments are every repose rig's (``heap.RUN_ARGUMENTS``); ``geometry`` is a
    :class:`CylinderGeometry`.

    Returns
    -------
    RigResult
        ``observable`` as the module docstring lists. ``record``: ``profile_x``, ``profile_z``
        [m], ``sphere_positions``, ``sphere_radii``, ``sphere_body``, ``body_positions`` [m],
        ``geometry`` (the tube and the fill simulated), ``t_lift``, ``t_clear``, ``t_end`` [s],
        ``ke_t`` [s], ``ke`` [J].
    """

    seed, params, prof, geo = prepare_run(params, seed, geometry, CylinderGeometry, profile, size_distribution)
    width = max(float(shape.extent[1]) for shape in params.sized_shapes())
    if prof.early_end:
        # time enough to lift the tube clear of a full fill and to settle after it
        prof = replace(prof, duration=max(prof.duration, prof.fill_time + 2.0 + (geo.height + width) / geo.lift_speed))
    dt = material_time_step(params)
    sim = build_lifting_cylinder(params, seed, geo, prof, dt=dt, force=force)
    run = fill_lift_settle(sim, sim.wall_index("cylinder"), geo.lift_speed, prof, width, geo.fill_count,
                           callback=callback)
    act = sim.active()
    keep = act[sim.sphere_body()]
    pos, rad = sim.sphere_positions()[keep], sim.sphere_radii()[keep]
    view = side_view_angles(pos, rad, "both", annotate_to=annotate_to)
    observable = {**cone_observables(view), "escaped": len(sim.escaped)}
    rec = {"profile_x": view.profile_x, "profile_z": view.profile_z, "crest_height": view.crest_height,
           "sphere_positions": pos, "sphere_radii": rad, "sphere_body": sim.sphere_body()[keep],
           "body_positions": sim.positions()[act], "geometry": geo.to_dict(), "t_lift": run.t_lift,
           "t_clear": run.t_clear, "t_end": sim.time, "ke_t": np.array(run.ke_t), "ke": np.array(run.ke),
           "escapes": [e.to_dict() for e in sim.escaped]}
    options = run_options(prof, geometry, force, params)
    meta = run_meta(seed, dt, run.tally, sim.n_spheres, sim.time, profile=prof.name,
                    notes=list(view.notes) + run.notes, profile_settings=prof.to_dict(), bodies=sim.n_bodies,
                    inserted=sum(f.inserted for f in sim.factories))
    return RigResult("lifting_cylinder", observable, rec, meta, params.to_dict(),
                     Provenance(seed=seed, options=options))


def measure_heap(centres, radii, geometry=None) -> dict:
    """The observables of a settled cone of spheres (e.g. LIGGGHTS' final positions), seen
    along y and measured on both flanks; the tube's position does not matter."""
    view = side_view_angles(centres, radii, "both")
    return {**cone_observables(view), "notes": list(view.notes)}


def task(params: DEMParameters, seed: int, *, profile: str, geometry) -> dict:
    """The inputs of one lifting-cylinder run (``heap.heap_task``); ``geometry`` a :class:`CylinderGeometry` or its
    ``to_dict()``."""
    return heap_task("lifting_cylinder", params, seed, profile=profile, geometry=geometry)


def run_task(inputs: dict) -> dict:
    """One lifting-cylinder run from its :func:`task`: the whole :class:`RigResult` as a dict."""
    return run_heap_task(run_lifting_cylinder, CylinderGeometry, inputs)


def liggghts_case(params: DEMParameters, geometry: CylinderGeometry, lift_time: float):
    """The tube in LIGGGHTS (``simulate.liggghts.deck.CylinderCase``: a 64-gon mesh), lifted at
    ``lift_time`` [s]."""
    from demcal.simulate.liggghts.deck import CylinderCase

    return CylinderCase.for_cylinder(params, geometry, lift_start=float(lift_time))


RIG = Rig("lifting_cylinder", sheet="repose", run=run_lifting_cylinder, task=task, run_task=run_task,
          compared="angle_deg", fallbacks=("angle_profile_deg", "angle_cone_deg"),
          observables={**CONE_OBSERVABLES, "escaped": "-"}, observable_notes=CONE_NOTES,
          targets=heap.CREST_TARGET,
          geometry=CylinderGeometry, workbook_name="lifting_cylinder", flanks="both",
          lab_test="lifting cylinder cone, side photograph of both flanks", measure=measure_heap,
          liggghts_case=liggghts_case, cli_arguments=heap.cli_arguments, cli_options=heap.cli_options)
