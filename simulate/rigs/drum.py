"""Rotating-drum rig: the twin of the dynamic angle of repose in a drum (GranuDrum-type).

The lab half fills a drum with a horizontal axis, turns it at a steady speed and photographs
its free surface end-on through a glass end plate (meta ``repose_rig: drum``). The twin builds
the same drum: a tube (``simulate.walls.Cylinder``) with its axis along y and two end plates
(``Rectangle``\\ s larger than the drum, which the particles never reach past the tube), filled
from a factory in the square inscribed in the drum, the bed let settle, then all three walls
spun about the axis at the logged speed (``spin``: the surface moves, the shape stays). After
``SPIN_UP_REVS`` revolutions (at least ``SPIN_UP_MIN_S``), ``FRAMES`` frames are taken over
the next ``SAMPLE_REVS`` revolutions (at least ``SAMPLE_MIN_S``): each is the end-on view of
the spheres (projected along y) drawn as a dark bed in the bright drum
(:func:`drum_photo`), and read by the lab's drum estimator
(``measure.repose.angle_from_drum``: the rim, the bed, a robust line through the central
chord of its free surface). The lab's photos and the twin's frames are measured the same way.

Fill. Without a ``fill_count`` the bed is ``fill_fraction`` of the drum's volume at the bulk
packing ``heap.BULK_PACKING``. Refused before any run: a drum under ``MIN_DIAMETER_LENGTHS``
particle lengths across or under ``MIN_WIDTH_LENGTHS`` wide, a bed under ``MIN_LAYERS``
particle widths deep, and a speed whose Froude number omega^2 R / g is ``MAX_FROUDE`` or more
(the bed would cataract or centrifuge: no free surface line; Mellmann 2001).

Observable keys: ``angle_deg`` (mean over the frames of the drum estimator's angle),
``angle_sd_deg`` (their sd: a bed of few particle diameters slumps and rocks by a few degrees
between frames), ``angle_profile_deg`` (mean over the same frames of a line through the
central chord of the bed's top profile, without the photo), ``frames_read`` and ``escaped``.

References
----------
Mellmann, J. (2001). The transverse motion of solids in rotating cylinders -- forms of motion
and transition behavior. Powder Technol. 118, 251-270.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from demcal.errors import DemcalError, InputError
from demcal.provenance import Provenance
from demcal.simulate.params import DEMParameters
from demcal.simulate.rigs import Rig, RigResult, heap, run_meta
from demcal.units import GRAVITY, MM

#: Drum fill when the workbook gives neither ``drum_fill_fraction`` nor ``fill_count`` [-].
DEFAULT_FILL_FRACTION = 0.4
#: Limits of the checks (module docstring).
MIN_DIAMETER_LENGTHS = 10.0
MIN_WIDTH_LENGTHS = 4.0
MIN_LAYERS = 4.0
MAX_FROUDE = 0.1
#: Revolutions (and least time [s]) before the first frame, and over which the frames are taken.
SPIN_UP_REVS, SPIN_UP_MIN_S = 0.5, 1.0
SAMPLE_REVS, SAMPLE_MIN_S = 0.25, 0.5
#: Frames read per run.
FRAMES = 5
#: Side of the rendered end-on frame [px]; the drum's radius is ``RIM_SHARE`` of it.
FRAME_PX = 600
RIM_SHARE = 0.45
#: Central share of the bed's free surface fitted by the profile method [-].
CHORD = 0.5
#: Facets of the drum's tube in LIGGGHTS.
FACETS = 64


def bed_depth(fill_fraction: float, diameter: float) -> float:
    """Depth [m] at the middle of a bed filling ``fill_fraction`` of a circle of ``diameter``:
    the circular segment of area f pi R^2, solved for its height by bisection."""
    r = diameter / 2.0
    target = fill_fraction * math.pi * r * r
    lo, hi = 0.0, 2.0 * r
    for _ in range(60):
        h = 0.5 * (lo + hi)
        area = r * r * math.acos((r - h) / r) - (r - h) * math.sqrt(max(2.0 * r * h - h * h, 0.0))
        lo, hi = (h, hi) if area < target else (lo, h)
    return 0.5 * (lo + hi)


@dataclass(frozen=True)
class DrumGeometry(heap.RigDimensions):
    """The rotating drum and its bed, as in the workbook's ``meta`` sheet.

    Attributes
    ----------
    diameter, width : float
        Inside diameter and width (axial length) of the drum [m].
    speed_rpm : float
        Rotation speed [1/min].
    fill_fraction : float or None
        Share of the drum's volume the bed fills (at the bulk packing) [-]; None:
        ``DEFAULT_FILL_FRACTION`` unless ``fill_count`` is given.
    fill_count : int or None
        Particles in the drum; None: from ``fill_fraction`` (``filled_for``).
    """

    diameter: float
    width: float
    speed_rpm: float
    fill_fraction: float | None = None
    fill_count: int | None = None

    #: meta key -> (field, factor to SI)
    META_KEYS = {"drum_diameter_mm": ("diameter", MM), "drum_width_mm": ("width", MM),
                 "drum_speed_rpm": ("speed_rpm", 1), "drum_fill_fraction": ("fill_fraction", 1),
                 "fill_count": ("fill_count", 1)}
    #: meta keys the workbook must give
    REQUIRED = ("drum_diameter_mm", "drum_width_mm", "drum_speed_rpm")

    def __post_init__(self):
        heap.check_dimensions(self, ("diameter", "width", "speed_rpm"), "drum")
        if self.fill_fraction is not None and not 0.05 <= self.fill_fraction <= 0.7:
            raise InputError(f"drum: fill_fraction must be between 0.05 and 0.7 of the drum's volume, "
                             f"got {self.fill_fraction!r} (meta drum_fill_fraction)")

    @property
    def omega(self) -> float:
        """Angular speed [rad/s]."""
        return 2.0 * math.pi * self.speed_rpm / 60.0

    @property
    def froude(self) -> float:
        """Froude number omega^2 R / g [-]."""
        return self.omega ** 2 * (self.diameter / 2.0) / GRAVITY

    def filled_for(self, shape) -> "DrumGeometry":
        """The same drum with its fill count: the workbook's, or its fill fraction of the drum's
        volume at the bulk packing (at least 10 particles)."""
        if self.fill_count is not None:
            return self
        share = DEFAULT_FILL_FRACTION if self.fill_fraction is None else self.fill_fraction
        volume = math.pi * self.diameter ** 2 / 4.0 * self.width
        return replace(self, fill_count=max(10, int(round(share * heap.BULK_PACKING * volume / shape.volume()))))

    def bed_fraction(self, shape) -> float:
        """The share of the drum's volume its fill takes at the bulk packing [-]."""
        geo = self.filled_for(shape)
        return geo.fill_count * shape.volume() / heap.BULK_PACKING / (math.pi * self.diameter ** 2 / 4.0 * self.width)

    def check_for(self, shape) -> None:
        """Refuse a drum whose free surface could not be read (module docstring), naming what
        to change."""
        length, width = float(shape.extent[0]), float(shape.extent[1])
        if self.diameter < MIN_DIAMETER_LENGTHS * length:
            raise InputError(f"drum: a drum of {self.diameter * 1e3:g} mm is under {MIN_DIAMETER_LENGTHS:g} particle "
                             f"lengths ({length * 1e3:.3g} mm) across, too few for a free surface; use a wider "
                             "drum (meta drum_diameter_mm)")
        if self.width < MIN_WIDTH_LENGTHS * length:
            raise InputError(f"drum: a drum {self.width * 1e3:g} mm wide is under {MIN_WIDTH_LENGTHS:g} particle "
                             f"lengths ({length * 1e3:.3g} mm); use a wider drum (meta drum_width_mm)")
        share = self.bed_fraction(shape)
        if share >= 0.9:
            raise InputError(f"drum: its {self.filled_for(shape).fill_count} particles fill {share:.0%} of the drum; "
                             "lower meta fill_count or drum_fill_fraction")
        depth = bed_depth(share, self.diameter)
        if depth < MIN_LAYERS * width:
            raise InputError(f"drum: a bed {depth * 1e3:.3g} mm deep is under {MIN_LAYERS:g} particle widths "
                             f"({width * 1e3:.3g} mm); raise meta drum_fill_fraction or fill_count")
        if self.froude >= MAX_FROUDE:
            raise InputError(f"drum: at {self.speed_rpm:g} rpm the Froude number omega^2 R / g is {self.froude:.3g}, "
                             f"at or above {MAX_FROUDE:g}: the bed would cataract, with no free surface line; "
                             "lower meta drum_speed_rpm")

    def describe(self, noun: str = "particles") -> str:
        """What the report says of the rig (``noun``: the particles' name, plural)."""
        fill = (f"{self.fill_count} {noun}" if self.fill_count else
                f"{noun} to {DEFAULT_FILL_FRACTION if self.fill_fraction is None else self.fill_fraction:.0%} "
                "of its volume")
        return (f"a drum of {self.diameter * 1e3:g} mm inside diameter and {self.width * 1e3:g} mm width, "
                f"filled with {fill} and turned at {self.speed_rpm:g} rpm")


def drum_photo(centres, radii, diameter: float, *, size: int = FRAME_PX) -> np.ndarray:
    """The end-on view of a drum's spheres (projected along y) as a grey image: a dark bed in a
    bright drum inside a dark rim, the drum's radius ``RIM_SHARE`` of the frame, z up."""
    import cv2

    img = np.full((size, size), 235, np.uint8)
    c = size / 2.0
    r_px = RIM_SHARE * size
    scale = r_px / (diameter / 2.0)
    cv2.circle(img, (int(round(c)), int(round(c))), int(round(r_px + 6)), 30, thickness=12, lineType=cv2.LINE_AA)
    centres = np.asarray(centres, float).reshape(-1, 3)
    for (x, _, z), r in zip(centres, np.asarray(radii, float)):
        cv2.circle(img, (int(round(c + x * scale)), int(round(c - z * scale))), max(1, int(round(r * scale))), 40,
                   thickness=-1, lineType=cv2.LINE_AA)
    return img


def _with_noise(img, rng) -> np.ndarray:
    return np.clip(img.astype(float) + rng.normal(0.0, 4.0, img.shape), 0, 255).astype(np.uint8)


def analytic_photo(angle_deg: float, rng, fill_fraction: float = DEFAULT_FILL_FRACTION) -> np.ndarray:
    """A virtual lab's drum frame of a bed at ``angle_deg``: particles of 1.5 % of the drum's
    diameter at random in the part of the drum below a line at that angle, which holds
    ``fill_fraction`` of its area; grey noise as a camera's."""
    pts = rng.uniform(-1.0, 1.0, size=(40000, 2))
    pts = pts[np.hypot(*pts.T) < 0.985]
    height = pts[:, 1] - math.tan(math.radians(angle_deg)) * pts[:, 0]
    bed = pts[height < np.quantile(height, fill_fraction)]
    centres = np.column_stack([bed[:, 0], np.zeros(len(bed)), bed[:, 1]])
    return _with_noise(drum_photo(centres, np.full(len(bed), 0.015), 2.0), rng)


def run_photo(record: dict, rng) -> np.ndarray:
    """A virtual lab's drum frame of a run: its last frame's spheres end-on, with noise."""
    return _with_noise(drum_photo(record["sphere_positions"], record["sphere_radii"],
                                  record["geometry"]["diameter"]), rng)


def bed_profile_angle(centres, radii, diameter: float) -> float:
    """Angle [deg] of a line through the central ``CHORD`` of the bed's top profile, in the
    plane across the drum (x, z): the top of the spheres on a 1 mm grid, without a photo."""
    centres = np.asarray(centres, float).reshape(-1, 3)
    radii = np.asarray(radii, float)
    if centres.shape[0] < 10:
        return math.nan
    x = np.arange(-diameter / 2.0, diameter / 2.0, 0.001)
    top = np.full(x.shape, -np.inf)
    for (cx, _, cz), r in zip(centres, radii):
        near = np.abs(x - cx) < r
        top[near] = np.maximum(top[near], cz + np.sqrt(r * r - (x[near] - cx) ** 2))
    have = np.isfinite(top)
    xs, zs = x[have], top[have]
    mid = 0.5 * (xs.min() + xs.max())
    half = 0.5 * CHORD * (xs.max() - xs.min())
    keep = np.abs(xs - mid) <= half
    if keep.sum() < 5:
        return math.nan
    slope = np.polyfit(xs[keep], zs[keep], 1)[0]
    return float(math.degrees(math.atan(abs(slope))))


def read_frame(centres, radii, diameter: float, annotate_to=None) -> tuple[float, str]:
    """The drum estimator's angle [deg] of one end-on frame, or NaN and why."""
    from demcal.measure.repose import angle_from_drum

    try:
        return float(angle_from_drum(drum_photo(centres, radii, diameter), annotate_to=annotate_to).angle_deg), ""
    except DemcalError as exc:
        return math.nan, str(exc)


def build_drum(params: DEMParameters, seed, geo: DrumGeometry, prof, *, dt: float, force: bool = False):
    """The drum (tube ``drum``, end plates ``end_y0`` and ``end_y1``) with a factory filling it,
    ready to run."""
    from demcal.simulate.engine import Simulation
    from demcal.simulate.factory import ParticleFactory
    from demcal.simulate.materials import MaterialTable
    from demcal.simulate.scenes import particle_templates
    from demcal.simulate.walls import Cylinder, Rectangle

    R, W = geo.diameter / 2.0, geo.width
    margin = 0.02 + 0.1 * R
    sim = Simulation(MaterialTable.from_parameters(params), domain_lo=(-R - margin, -W / 2 - margin, -R - margin),
                     domain_hi=(R + margin, W / 2 + margin, R + margin), dt=dt,
                     rolling_lever=params.rolling_lever, force=force)
    templates, weights = particle_templates(sim, params, None)
    sim.add_wall(Cylinder((0.0, 0.0, 0.0), (0.0, 1.0, 0.0), R, W / 2, "steel", name="drum"))
    for name, y in (("end_y0", -W / 2), ("end_y1", W / 2)):
        sim.add_wall(Rectangle((0.0, y, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0), 1.2 * R, 1.2 * R, "steel", name=name))
    half = heap.inscribed_half(geo.diameter)
    inset = min(0.005, 0.1 * W)
    sim.add_factory(ParticleFactory(templates, geo.fill_count, (-half, -W / 2 + inset, -half),
                                    (half, W / 2 - inset, half), seed=seed, start_time=0.0,
                                    end_time=prof.fill_time, material="particle", weights=weights))
    return sim


def run_drum(params: DEMParameters, seed: int = 0, *, geometry: DrumGeometry, profile: str = "quick",
             annotate_to=None, force: bool = False, callback=None, size_distribution=None) -> RigResult:
    """Run the rotating drum and read its free surface (module docstring).

    The arguments are every repose rig's (``heap.RUN_ARGUMENTS``); ``geometry`` is a
    :class:`DrumGeometry`, ``profile`` says how the drum is filled (the rotation follows) and
    ``annotate_to`` gets the last frame.

    Returns
    -------
    RigResult
        ``observable`` as the module docstring lists. ``record``: ``frame_angles``,
        ``frame_profile_angles`` [deg], ``frame_times`` [s], ``sphere_positions``,
        ``sphere_radii`` [m] (the last frame),
        ``geometry``, ``t_spin``, ``t_end`` [s].
    """
    from demcal.simulate.timestep import material_time_step

    seed, params, prof, geo = heap.prepare_run(params, seed, geometry, DrumGeometry, profile, size_distribution)
    period = 2.0 * math.pi / geo.omega
    spin_up = max(SPIN_UP_REVS * period, SPIN_UP_MIN_S)
    sample = max(SAMPLE_REVS * period, SAMPLE_MIN_S)
    dt = material_time_step(params)
    sim = build_drum(params, seed, geo, prof, dt=dt, force=force)
    fill = replace(prof, duration=max(prof.duration, prof.fill_time + 1.0), early_end=True)
    run = heap.fill_lift_settle(sim, None, 0.0, fill, 0.0, geo.fill_count, callback=None)
    t_spin = sim.time
    for name in ("drum", "end_y0", "end_y1"):
        sim.set_wall_motion(sim.wall_index(name), (0.0, 0.0, 0.0), t_spin, math.inf, spin=(0.0, geo.omega, 0.0))
    t_end = t_spin + spin_up + sample
    tally = run.tally
    tally.add(sim.run(duration=spin_up))
    if callback is not None:
        callback(sim, t_end, False)
    angles, profiles, times, notes = [], [], [], list(run.notes)
    for k in range(FRAMES):
        tally.add(sim.run(duration=sample / FRAMES))
        act = sim.active()
        keep = act[sim.sphere_body()]
        pos, rad = sim.sphere_positions()[keep], sim.sphere_radii()[keep]
        last = k == FRAMES - 1
        angle, why = read_frame(pos, rad, geo.diameter, annotate_to=annotate_to if last else None)
        angles.append(angle)
        profiles.append(bed_profile_angle(pos, rad, geo.diameter))
        times.append(sim.time)
        if why:
            notes.append(f"frame at {sim.time:.2f} s: {why}")
        if callback is not None:
            callback(sim, t_end, last)
    read = np.isfinite(angles)
    observable = {"angle_deg": float(np.mean(np.asarray(angles)[read])) if read.any() else math.nan,
                  "angle_sd_deg": float(np.std(np.asarray(angles)[read], ddof=1)) if read.sum() > 1 else math.nan,
                  "angle_profile_deg": float(np.nanmean(profiles)) if np.isfinite(profiles).any() else math.nan,
                  "frames_read": int(read.sum()), "escaped": len(sim.escaped)}
    rec = {"frame_angles": np.asarray(angles), "frame_profile_angles": np.asarray(profiles),
           "frame_times": np.asarray(times), "sphere_positions": pos,
           "sphere_radii": rad, "geometry": geo.to_dict(), "t_spin": t_spin, "t_end": sim.time,
           "escapes": [e.to_dict() for e in sim.escaped]}
    meta = run_meta(seed, dt, tally, sim.n_spheres, sim.time, profile=prof.name, notes=notes,
                    profile_settings=prof.to_dict(), bodies=sim.n_bodies,
                    inserted=sum(f.inserted for f in sim.factories))
    return RigResult("drum", observable, rec, meta, params.to_dict(),
                     Provenance(seed=seed, options=heap.run_options(prof, geometry, force, params)))


def measure_heap(centres, radii, geometry) -> dict:
    """The drum observables of one frame of spheres (another code's): the estimator's angle of
    the end-on view and the profile fit. ``geometry``: a :class:`DrumGeometry` or a dict with
    ``diameter`` [m] and, for a drum not centred on the origin, its ``centre`` [m]."""
    if isinstance(geometry, dict):
        diameter, centre = geometry["diameter"], np.asarray(geometry.get("centre", (0.0, 0.0, 0.0)), float)
    else:
        diameter, centre = geometry.diameter, np.zeros(3)
    centres = np.asarray(centres, float).reshape(-1, 3) - centre
    angle, why = read_frame(centres, radii, diameter)
    return {"angle_deg": angle, "angle_profile_deg": bed_profile_angle(centres, radii, diameter),
            "notes": [why] if why else []}


def task(params: DEMParameters, seed: int, *, profile: str, geometry) -> dict:
    """The inputs of one drum run (``heap.heap_task``)."""
    return heap.heap_task("drum", params, seed, profile=profile, geometry=geometry)


def run_task(inputs: dict) -> dict:
    """One drum run from its :func:`task`: the whole :class:`RigResult` as a dict."""
    return heap.run_heap_task(run_drum, DrumGeometry, inputs)


def liggghts_case(params: DEMParameters, geometry: DrumGeometry, lift_time: float):
    """The drum in LIGGGHTS: its tube a ``FACETS``-gon mesh along y and its end plates two
    square meshes, its axis through ``(R, ., R + 10 mm)`` (inside the deck's box, above its floor
    plane), filled over the first second and turned about its axis (``move/mesh rotate``) from
    ``lift_time`` [s]; the last frame is read by :func:`measure_heap` (the case's dict holds the
    ``diameter`` and the ``centre``)."""
    from demcal.simulate.liggghts.deck import ReposeCase, _g, _rectangle

    geo = geometry.filled_for(params.shape)
    R, W = geo.diameter / 2.0, geo.width
    cx, cy, cz = R, W / 2.0, R + 0.01
    period = 2.0 * math.pi / geo.omega
    spin_up = max(SPIN_UP_REVS * period, SPIN_UP_MIN_S)

    class DrumCase(ReposeCase):
        walls_comment = "rotating drum: the tube and two end plates (meshes), turned about its axis along y"
        title = "Dynamic angle of repose, rotating drum, LIGGGHTS-PUBLIC 3.8"
        lifted_mesh = None

        def meshes(self) -> dict:
            phi = np.linspace(0.0, 2.0 * np.pi, FACETS + 1)
            x, z = cx + R * np.cos(phi), cz + R * np.sin(phi)
            tube = np.concatenate([_rectangle((x[k], 0.0, z[k]), (x[k + 1], 0.0, z[k + 1]),
                                              (x[k + 1], W, z[k + 1]), (x[k], W, z[k])) for k in range(FACETS)])
            h = 1.2 * R
            plates = {name: _rectangle((cx - h, y, cz - h), (cx + h, y, cz - h), (cx + h, y, cz + h), (cx - h, y, cz + h))
                      for name, y in (("end_y0", 0.0), ("end_y1", W))}
            return {"drum": tube, **plates}

        @property
        def domain(self) -> tuple:
            m = 0.02 + 0.2 * R
            return (cx - R - m, cx + R + m, -m, W + m, -0.01, cz + R + m)

        def settling_from(self) -> float:
            return self.plate_lift_start + spin_up

        def phase_steps(self, duration: float) -> tuple:
            total = self.steps(duration)
            start = min(self.steps(self.plate_lift_start), total)
            return tuple((label, n) for label, n in (("fill_and_settle", start), ("rotate", total - start)) if n > 0)

        def motion(self, label: str) -> tuple:
            if label != "rotate":
                return (), ()
            return tuple(f"fix spin_{name} all move/mesh mesh {name} rotate origin {_g(cx)} {_g(cy)} {_g(cz)} "
                         f"axis 0.0 1.0 0.0 period {_g(period)}" for name in self.meshes()), ()

        def to_dict(self) -> dict:
            return {**super().to_dict(), "diameter": geo.diameter, "width": W, "centre": [cx, cy, cz],
                    "period_s": period}

    base = ReposeCase.for_params(params)
    half, inset = heap.inscribed_half(geo.diameter), min(0.005, 0.1 * W)
    fields = {f: getattr(base, f) for f in ReposeCase.__dataclass_fields__}
    fields.update(box_length=geo.diameter, box_width=W, box_height=cz + R, n_segments=geo.fill_count,
                  plate_lift_start=float(lift_time),
                  fill_region=(cx - half, cx + half, inset, W - inset, cz - half, cz + half))
    return DrumCase(**fields)


RIG = Rig("drum", sheet="repose", run=run_drum, task=task, run_task=run_task,
          compared="angle_deg", fallbacks=("angle_profile_deg",),
          observables={"angle_deg": "deg", "angle_sd_deg": "deg", "angle_profile_deg": "deg", "frames_read": "-",
                       "escaped": "-"},
          observable_notes={"angle_sd_deg": "sd of the angle over the frames", "frames_read": "frames whose free "
                            "surface was found", "escaped": heap.CONE_NOTES["escaped"]},
          geometry=DrumGeometry, workbook_name="drum", flanks="drum",
          lab_test="rotating drum, end-on photographs of the free surface in steady rotation", measure=measure_heap,
          analytic_photo=analytic_photo, run_photo=run_photo, liggghts_case=liggghts_case,
          cli_arguments=heap.cli_arguments, cli_options=heap.cli_options)
