"""Fixed-funnel rig: the twin of the poured-cone repose test (ISO 4324; the fixed funnel of
Carr's method).

The lab fixes a conical funnel with its outlet at a set height above a floor, pours the sample
into it at a steady rate and photographs the cone that builds up on the floor from the side,
both flanks (meta ``repose_rig: funnel``). The twin builds the same funnel (a truncated cone,
``simulate.walls.Cylinder`` with a ``top_radius``, axis z, centred on x = y = 0) above the steel
floor z = 0, pours the particles into it from a factory above its rim, lets them run out of
the outlet onto the floor and the cone settle (``simulate.rigs.heap.fill_lift_settle``, nothing
lifted), and reads the cone of the spheres below the outlet as the lab's photos are read: seen
along y, the photo estimator on both flanks (``heap.side_view_angles``).

Pour. The factory pours at ``POUR_SHARE`` of the funnel's discharge rate by Beverloo's law
for the particle's volume-equivalent diameter d and an outlet D0 (Beverloo, Leniger & van de
Velde 1961):

    W = C rho_b sqrt(g) (D0 - k d)^(5/2),   C = 0.58, k = 1.5,

so the funnel never overflows and the stream through the outlet is the pour itself.

Fill. Without a ``fill_count`` in the workbook the sample is the cone of height
``HEAP_SHARE`` of the outlet's height at 30 deg, at the bulk packing ``heap.BULK_PACKING``. A
funnel is refused before any run when its outlet is under ``MIN_OUTLET_LENGTHS`` particle
lengths (the stream would arch; Beverloo's k d is 1.5 d), when the fill's cone at
``LOWEST_ANGLE_DEG`` is under ``MIN_LAYERS`` particle widths high (too few layers for its
flanks to be read), or when its cone at ``STEEPEST_ANGLE_DEG`` would reach the outlet (the
heap would choke the stream and join the funnel's contents in the photo).

Observable keys: those of a cone (``heap.cone_observables``: ``angle_deg`` (photo method, mean
of the flanks), ``angle_left_deg``, ``angle_right_deg``, ``angle_profile_deg``,
``angle_cone_deg`` [deg], ``crest_height_m``, ``base_diameter_m`` [m]), ``in_funnel`` (bodies
still above the outlet at the end) and ``escaped``.

References
----------
Beverloo, W. A., Leniger, H. A., van de Velde, J. (1961). The flow of granular solids through
orifices. Chem. Eng. Sci. 15, 260-269.
ISO 4324:1977. Surface active agents -- Powders and granules -- Measurement of the angle of
repose.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from demcal.errors import InputError
from demcal.provenance import Provenance
from demcal.simulate.params import DEMParameters
from demcal.simulate.rigs import Rig, RigResult, heap, run_meta
from demcal.units import GRAVITY, MM

#: Beverloo's discharge coefficient and empty-annulus factor (Beverloo et al. 1961).
BEVERLOO_C, BEVERLOO_K = 0.58, 1.5
#: Share of the funnel's discharge rate the factory pours at [-].
POUR_SHARE = 0.5
#: The default fill: a 30 deg cone of this share of the outlet's height [-].
HEAP_SHARE = 0.6
#: The outlet must be at least this many particle lengths across.
MIN_OUTLET_LENGTHS = 5.0
#: The cone must be at least this many particle widths high at ``LOWEST_ANGLE_DEG``.
MIN_LAYERS = 4.0
#: The flattest and the steepest cones the checks allow for [deg].
LOWEST_ANGLE_DEG = 20.0
STEEPEST_ANGLE_DEG = 45.0
#: Mesh facets of the funnel in LIGGGHTS.
FACETS = 64


def equivalent_diameter(shape) -> float:
    """Diameter [m] of the sphere of the particle's volume."""
    return (6.0 * shape.volume() / math.pi) ** (1.0 / 3.0)


@dataclass(frozen=True)
class FunnelGeometry(heap.RigDimensions):
    """The fixed funnel and its sample, as in the workbook's ``meta`` sheet.

    Attributes
    ----------
    outlet_diameter, top_diameter : float
        Inside diameters of the funnel's outlet and of its top rim [m].
    cone_height : float
        Height of the funnel's cone, outlet to rim [m].
    outlet_height : float
        Height of the outlet above the floor [m].
    fill_count : int or None
        Particles poured; None: the default fill (``filled_for``).
    """

    outlet_diameter: float
    top_diameter: float
    cone_height: float
    outlet_height: float
    fill_count: int | None = None

    #: meta key -> (field, factor to SI)
    META_KEYS = {"funnel_outlet_diameter_mm": ("outlet_diameter", MM), "funnel_top_diameter_mm": ("top_diameter", MM),
                 "funnel_height_mm": ("cone_height", MM), "funnel_outlet_height_mm": ("outlet_height", MM),
                 "fill_count": ("fill_count", 1)}
    #: meta keys the workbook must give
    REQUIRED = ("funnel_outlet_diameter_mm", "funnel_top_diameter_mm", "funnel_height_mm", "funnel_outlet_height_mm")

    def __post_init__(self):
        heap.check_dimensions(self, ("outlet_diameter", "top_diameter", "cone_height", "outlet_height"), "funnel")
        if not self.top_diameter > self.outlet_diameter:
            raise InputError(f"funnel: the top ({self.top_diameter * 1e3:g} mm) must be wider than the outlet "
                             f"({self.outlet_diameter * 1e3:g} mm); meta funnel_top_diameter_mm")

    @property
    def top_z(self) -> float:
        """Height of the funnel's rim above the floor [m]."""
        return self.outlet_height + self.cone_height

    def filled_for(self, shape) -> "FunnelGeometry":
        """The same funnel with its fill count: the workbook's, or a 30 deg cone of
        ``HEAP_SHARE`` of the outlet's height at ``heap.BULK_PACKING`` (at least 10 particles)."""
        if self.fill_count is not None:
            return self
        h = HEAP_SHARE * self.outlet_height
        volume = math.pi * h ** 3 / (3.0 * math.tan(math.radians(30.0)) ** 2)
        return replace(self, fill_count=max(10, int(round(heap.BULK_PACKING * volume / shape.volume()))))

    def check_for(self, shape) -> None:
        """Refuse a funnel whose stream would arch, or whose cone could not be read or would
        reach the outlet (module docstring), naming what to change."""
        geo = self.filled_for(shape)
        length, width = float(shape.extent[0]), float(shape.extent[1])
        if self.outlet_diameter < MIN_OUTLET_LENGTHS * length:
            raise InputError(f"funnel: an outlet of {self.outlet_diameter * 1e3:g} mm is under {MIN_OUTLET_LENGTHS:g} "
                             f"particle lengths ({length * 1e3:.3g} mm) across, so the stream would arch; use a "
                             "wider outlet (meta funnel_outlet_diameter_mm)")
        bulk = geo.fill_count * shape.volume() / heap.BULK_PACKING
        low = heap.cone_height(bulk, LOWEST_ANGLE_DEG)
        if low < MIN_LAYERS * width:
            raise InputError(f"funnel: {geo.fill_count} particles make a cone about {low * 1e3:.3g} mm high at "
                             f"{LOWEST_ANGLE_DEG:g} deg, under {MIN_LAYERS:g} particle widths ({width * 1e3:.3g} mm), "
                             "too few layers for its flanks to be read; raise meta fill_count")
        high = heap.cone_height(bulk, STEEPEST_ANGLE_DEG)
        if high > self.outlet_height - length:
            raise InputError(f"funnel: {geo.fill_count} particles make a cone up to {high * 1e3:.3g} mm high (at "
                             f"{STEEPEST_ANGLE_DEG:g} deg), which would reach the outlet {self.outlet_height * 1e3:g} mm "
                             "above the floor; lower meta fill_count or raise funnel_outlet_height_mm")

    def pour_time(self, shape) -> float:
        """Time [s] over which the fill is poured: at ``POUR_SHARE`` of Beverloo's discharge rate."""
        geo = self.filled_for(shape)
        d = equivalent_diameter(shape)
        per_s = (BEVERLOO_C * heap.BULK_PACKING * math.sqrt(GRAVITY)
                 * max(self.outlet_diameter - BEVERLOO_K * d, d) ** 2.5 / shape.volume())
        return geo.fill_count / (POUR_SHARE * per_s)

    def describe(self, noun: str = "particles") -> str:
        """What the report says of the rig (``noun``: the particles' name, plural)."""
        fill = f"{self.fill_count} {noun}" if self.fill_count else noun
        return (f"a funnel of {self.top_diameter * 1e3:g} mm top and {self.outlet_diameter * 1e3:g} mm outlet "
                f"diameter, {self.cone_height * 1e3:g} mm high, its outlet {self.outlet_height * 1e3:g} mm above "
                f"the floor, through which {fill} were poured")


def build_funnel(params: DEMParameters, seed, geo: FunnelGeometry, prof, *, dt: float, force: bool = False):
    """The funnel above its floor with a factory pouring into it, ready to run; the funnel's
    wall is named ``funnel`` (``sim.wall_index``)."""
    from demcal.simulate.engine import Simulation
    from demcal.simulate.factory import ParticleFactory
    from demcal.simulate.materials import MaterialTable
    from demcal.simulate.scenes import particle_templates
    from demcal.simulate.walls import Cylinder, Plane

    length = float(params.shape.extent[0])
    bulk = geo.fill_count * params.shape.volume() / heap.BULK_PACKING
    reach = max(1.5 * heap.cone_height(bulk, 15.0) / math.tan(math.radians(15.0)), geo.top_diameter) + 0.05
    column = max(3.0 * length, 0.3 * geo.cone_height)     # the factory's column above the rim
    sim = Simulation(MaterialTable.from_parameters(params), domain_lo=(-reach, -reach, -0.02),
                     domain_hi=(reach, reach, geo.top_z + column + 0.05), dt=dt,
                     rolling_lever=params.rolling_lever, force=force)
    templates, weights = particle_templates(sim, params, None)
    sim.add_wall(Plane((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), material="steel", name="floor"))
    sim.add_wall(Cylinder((0.0, 0.0, geo.outlet_height + geo.cone_height / 2), (0.0, 0.0, 1.0),
                          geo.outlet_diameter / 2, geo.cone_height / 2, "steel", name="funnel",
                          top_radius=geo.top_diameter / 2))
    half = heap.inscribed_half(geo.top_diameter)      # the stream falls inside the funnel
    sim.add_factory(ParticleFactory(templates, geo.fill_count, (-half, -half, geo.top_z),
                                    (half, half, geo.top_z + column), seed=seed, start_time=0.0,
                                    end_time=prof.fill_time, material="particle", weights=weights))
    return sim


def run_funnel(params: DEMParameters, seed: int = 0, *, geometry: FunnelGeometry, profile: str = "quick",
               annotate_to=None, force: bool = False, callback=None, size_distribution=None) -> RigResult:
    """Run the fixed-funnel repose test and measure the cone (module docstring).

    The arguments are every repose rig's (``heap.RUN_ARGUMENTS``); ``geometry`` is a
    :class:`FunnelGeometry`, and the pour lasts at least its :meth:`FunnelGeometry.pour_time`.

    Returns
    -------
    RigResult
        ``observable`` as the module docstring lists. ``record``: ``profile_x``, ``profile_z``
        [m], ``sphere_positions``, ``sphere_radii``, ``sphere_body``, ``body_positions`` [m]
        (the cone's), ``geometry``, ``t_poured``, ``t_end`` [s], ``ke_t`` [s], ``ke`` [J].
    """
    from demcal.simulate.timestep import material_time_step

    seed, params, prof, geo = heap.prepare_run(params, seed, geometry, FunnelGeometry, profile, size_distribution)
    pour = max(prof.fill_time, geo.pour_time(params.shape))
    fall = math.sqrt(2.0 * geo.top_z / GRAVITY)
    prof = replace(prof, fill_time=pour, duration=max(prof.duration, pour + fall + 2.0))
    dt = material_time_step(params)
    sim = build_funnel(params, seed, geo, prof, dt=dt, force=force)
    width = max(float(shape.extent[1]) for shape in params.sized_shapes())
    run = heap.fill_lift_settle(sim, None, 0.0, prof, width, geo.fill_count, callback=callback)
    act = sim.active()
    below = sim.positions()[:, 2] < geo.outlet_height
    keep_body = act & below
    keep = keep_body[sim.sphere_body()]
    pos, rad = sim.sphere_positions()[keep], sim.sphere_radii()[keep]
    view = heap.side_view_angles(pos, rad, "both", annotate_to=annotate_to)
    in_funnel = int((act & ~below).sum())
    notes = list(view.notes) + run.notes
    if in_funnel:
        notes.append(f"{in_funnel} particles were still above the outlet at the end (left out of the cone)")
    observable = {**heap.cone_observables(view), "in_funnel": in_funnel, "escaped": len(sim.escaped)}
    rec = {"profile_x": view.profile_x, "profile_z": view.profile_z, "crest_height": view.crest_height,
           "sphere_positions": pos, "sphere_radii": rad, "sphere_body": sim.sphere_body()[keep],
           "body_positions": sim.positions()[keep_body], "geometry": geo.to_dict(), "t_poured": run.t_lift,
           "t_end": sim.time, "ke_t": np.array(run.ke_t), "ke": np.array(run.ke),
           "escapes": [e.to_dict() for e in sim.escaped]}
    meta = run_meta(seed, dt, run.tally, sim.n_spheres, sim.time, profile=prof.name, notes=notes,
                    profile_settings=prof.to_dict(), bodies=sim.n_bodies,
                    inserted=sum(f.inserted for f in sim.factories))
    return RigResult("funnel", observable, rec, meta, params.to_dict(),
                     Provenance(seed=seed, options=heap.run_options(prof, geometry, force, params)))


def measure_heap(centres, radii, geometry) -> dict:
    """The observables of a settled cone of spheres under the funnel (e.g. LIGGGHTS' final
    positions): the spheres below the outlet, seen along y and measured on both flanks."""
    outlet = geometry["outlet_height"] if isinstance(geometry, dict) else geometry.outlet_height
    below = np.asarray(centres)[:, 2] < outlet
    view = heap.side_view_angles(np.asarray(centres)[below], np.asarray(radii)[below], "both")
    return {**heap.cone_observables(view), "notes": list(view.notes)}


def task(params: DEMParameters, seed: int, *, profile: str, geometry) -> dict:
    """The inputs of one funnel run (``heap.heap_task``)."""
    return heap.heap_task("funnel", params, seed, profile=profile, geometry=geometry)


def run_task(inputs: dict) -> dict:
    """One funnel run from its :func:`task`: the whole :class:`RigResult` as a dict."""
    return heap.run_heap_task(run_funnel, FunnelGeometry, inputs)


def liggghts_case(params: DEMParameters, geometry: FunnelGeometry, lift_time: float):
    """The funnel in LIGGGHTS: a ``FACETS``-gon cone mesh above the floor, poured into from a
    column above its rim at the twin's rate, nothing lifted (``lift_time`` unused: the heap
    settles once the pour ends)."""
    from demcal.simulate.liggghts.deck import ReposeCase, _rectangle

    class FunnelCase(ReposeCase):
        walls_comment = "fixed funnel: the cone (mesh), infinite steel floor z = 0"
        title = "Angle of repose, fixed funnel, LIGGGHTS-PUBLIC 3.8"
        lifted_mesh = None

        def meshes(self) -> dict:
            c = self.box_length / 2
            phi = np.linspace(0.0, 2.0 * np.pi, FACETS + 1)
            ring = np.stack([np.cos(phi), np.sin(phi)], axis=1)
            lo = c + geo.outlet_diameter / 2 * ring
            hi = c + geo.top_diameter / 2 * ring
            z0, z1 = geo.outlet_height, geo.top_z
            return {"funnel": np.concatenate([_rectangle((*lo[k], z0), (*hi[k], z1), (*hi[k + 1], z1), (*lo[k + 1], z0))
                                              for k in range(FACETS)])}

        @property
        def domain(self) -> tuple:
            c, reach = self.box_length / 2, 3.0 * self.box_length
            return (c - reach, c + reach, c - reach, c + reach, -0.01, self.box_height + 0.02)

        def settling_from(self) -> float:
            return self.fill_time

        def phase_steps(self, duration: float) -> tuple:
            return (("pour_and_settle", self.steps(duration)),)

        def to_dict(self) -> dict:          # what measure_heap reads of LIGGGHTS' final spheres
            return {**super().to_dict(), **geo.to_dict()}

    geo = geometry.filled_for(params.shape)
    base = ReposeCase.for_params(params)
    D, column = geo.top_diameter, max(3.0 * float(params.shape.extent[0]), 0.3 * geo.cone_height)
    half = heap.inscribed_half(D)
    fields = {f: getattr(base, f) for f in ReposeCase.__dataclass_fields__}
    fields["plate_lift_start"] = fields["fill_time"] = max(1.0, geo.pour_time(params.shape))
    fields.update(box_length=D, box_width=D, box_height=geo.top_z + column, n_segments=geo.fill_count,
                  fill_region=(D / 2 - half, D / 2 + half, D / 2 - half, D / 2 + half, geo.top_z, geo.top_z + column))
    return FunnelCase(**fields)


RIG = Rig("funnel", sheet="repose", run=run_funnel, task=task, run_task=run_task,
          compared="angle_deg", fallbacks=("angle_profile_deg", "angle_cone_deg"),
          observables={**heap.CONE_OBSERVABLES, "in_funnel": "-", "escaped": "-"},
          observable_notes={**heap.CONE_NOTES, "in_funnel": "particles left above the outlet"},
          targets=heap.CREST_TARGET,
          geometry=FunnelGeometry, workbook_name="funnel", flanks="both",
          lab_test="fixed funnel cone (ISO 4324), side photograph of both flanks", measure=measure_heap,
          liggghts_case=liggghts_case, cli_arguments=heap.cli_arguments, cli_options=heap.cli_options)
