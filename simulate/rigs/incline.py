"""Incline rig: the twin of the inclinometer test (a particle on a plate tilted slowly).

The lab lays a particle on the test plane and rotates the plane slowly until it moves;
tan(angle) is then read as the static friction (a segment "placed along the length of the test
plane", so it can only slide) or as the rolling friction (across the slope, free to roll). A
round particle rolls before it slides whatever its friction, so labs measure its static
friction with a sled: a light plate carrying particles glued to its underside (``mode="sled"``:
a rigid body of ``SLED_ROWS`` x ``SLED_ROWS`` particles side by side, lying as on the plate,
which cannot roll; its onset is where the glued particles slide, tan(angle) = mu_s).

Tilting. The plate stays the plane z = 0 and gravity turns instead,

    g(theta) = |g| (sin theta, 0, -cos theta),   theta = start + rate t,

so +x is down the slope. For a rigid plate this is the same motion seen from the plate's
frame; the frame's rotation adds inertial accelerations of order omega^2 r and omega v, below
1e-5 g at 1 deg/s over 0.1 m, which are neglected. theta is held constant over chunks of
``CHUNK_DEG`` and raised between them.

Onsets, from the centre of mass and the orientation after each chunk:
- rolled arc = phi_y h, with phi_y the rotation about the across-slope axis (y) since the tilt
  began and h the height of the centre of mass above the plate (rolling without slip moves
  the centre by exactly this arc). phi_y is added up over pieces of the run short enough that
  each turns the particle by less than ``MAX_PIECE_TURN`` at its angular speed, so it keeps
  counting past half a turn, where the rotation vector of the whole turn would wrap;
- slip = displacement down the slope minus the rolled arc;
- ``slide_angle_deg``: tilt at which the slip first exceeds ``threshold`` (moving while not
  rolling) and then keeps growing, by ``CONFIRM_SLIP`` (or to the run's end) without a chunk in
  which it stands still (grows by less than ``REST_FRACTION`` of the threshold). A slip that
  stops is a knock, not a slide: a clump resting on one sphere whose centre is near its centre
  of mass (the kernel shape on its flat side) balances like a ball, rolls at tan(theta) = mu_r
  until its next sphere meets the plate, and that landing slips it by tens of micrometres
  whatever its friction. The slip is then counted afresh from where it stopped (the run's
  notes say so);
  ``roll_angle_deg``: tilt at which the rolled arc first exceeds ``threshold``, beyond the
  elastic windup the spring-dashpot rolling model allows (``_elastic_rolling_arc``).
The run stops at the onset asked for by ``mode`` (or when the segment has moved 50 mm, or at
``max_tilt_deg``). An onset not reached is NaN.

What the lab reads. ``static_friction_apparent`` = tan(slide angle) and
``rolling_friction_apparent`` = tan(roll angle), as the lab computes them. The first equals
mu_s; the second equals mu_r only when the rolling lever is the rolling radius: for a sphere,
or a segment with ``rolling_lever="edem_sphere"``. With ``"edem_com"`` (EDEM's definition for a
clump) the lever of each member contact is its distance from the clump's centre, so a segment
across the slope rolls at tan(theta) = mu_r mean(sqrt(a^2 + y_i^2)) / a (a the contact lever
of a sphere, y_i the member offsets along the axis): 1.32 mu_r for the paper's segment.

Tilt rate. The default 1 deg/s moves the onsets by less than 0.1 deg against 0.25 deg/s (the
detection lags the true onset by the time the motion needs to grow past ``threshold``).
"""

from __future__ import annotations

import math

import numpy as np

from demcal.errors import InputError
from demcal.provenance import Provenance
from demcal.simulate.clump import ClumpTemplate
from demcal.simulate.engine import Simulation
from demcal.simulate.integrate import axis_angle_quat, matrix_from_quat
from demcal.simulate.params import DEMParameters
from demcal.simulate.rigs import Rig, RigResult, RunTally, Trial, TrialGroup, check_seed, run_meta, used_rows
from demcal.simulate.rigs.surfaces import BUILT_IN_SURFACES, PARTICLE, Surface, make_surface, surface_options
from demcal.simulate.timestep import material_time_step
from demcal.simulate.walls import Plane
from demcal.units import GRAVITY

MODES = ("slide", "roll", "sled")
#: Particles along each side of the sled's square of glued particles.
SLED_ROWS = 3
#: Gap between neighbouring glued particles, relative to the particle's extent [-].
SLED_GAP = 0.2
#: Tilt held constant over each chunk [deg].
CHUNK_DEG = 0.01
#: Movement after which the run ends [m].
STOP_DISTANCE = 0.05
#: The most a piece of a run may turn the particle at its angular speed at the piece's start
#: [rad]. The rolled arc adds up the pieces' rotation vectors, each unambiguous below half a
#: turn; a quarter leaves room for the speed to grow within the piece.
MAX_PIECE_TURN = 0.25 * math.pi
#: A chunk whose slip grows by less than this fraction of the threshold stands still (elastic
#: creep before an onset grows by a few 1e-4 of it per chunk, a slide just past its onset by
#: about half of it).
REST_FRACTION = 0.01
#: Slip beyond a slide's first threshold crossing that confirms it [m]. A slide past its onset
#: never stops and covers this in about half a degree of tilt at 1 deg/s; the knocks of the
#: kernel shape slip 0.01-0.05 mm from flat and up to 0.8 mm when laid on a steeper start.
CONFIRM_SLIP = 5.0e-3


def rotation_vector(R) -> np.ndarray:
    """Rotation vector (axis times angle [rad]) of a rotation matrix (the matrix logarithm)."""
    R = np.asarray(R, dtype=float)
    c = min(1.0, max(-1.0, (np.trace(R) - 1.0) / 2.0))
    angle = math.acos(c)
    skew = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if angle < 1e-8:
        return 0.5 * skew
    if math.pi - angle < 1e-6:
        # near a half turn: the axis is the column of R + I of largest norm
        m = R + np.eye(3)
        k = int(np.argmax(np.linalg.norm(m, axis=0)))
        return angle * m[:, k] / np.linalg.norm(m[:, k])
    return angle * skew / (2.0 * math.sin(angle))


def _run_adding_up_rotation(sim: Simulation, n_steps: int, R_last, tally: RunTally):
    """Runs ``sim`` ``n_steps`` steps in pieces that turn its one body by at most
    ``MAX_PIECE_TURN`` at the angular speed each starts with; returns the sum of the pieces'
    rotation vectors [rad] and the body's rotation matrix at the end."""
    turned = np.zeros(3)
    left = n_steps
    while left > 0:
        speed = float(np.linalg.norm(sim.angular_velocities()[0]))
        n = left if speed * left * sim.dt <= MAX_PIECE_TURN else max(1, int(MAX_PIECE_TURN / (speed * sim.dt)))
        tally.add(sim.run(n_steps=n))
        R = sim.rotation_matrices()[0]
        turned += rotation_vector(R @ R_last.T)
        R_last = R
        left -= n
    return turned, R_last


#: The steepest tilt a run reaches, unless told [deg].
MAX_TILT_DEG = 60.0


def run_incline(params: DEMParameters, seed: int = 0, *, mode: str = "slide", surface: str = "steel",
                surface_material: dict | None = None, surface_contact: dict | None = None,
                tilt_rate_deg_s: float = 1.0, start_deg: float = 0.0, max_tilt_deg: float = MAX_TILT_DEG,
                threshold: float = 1.0e-5, settle_time: float = 0.05,
                template: ClumpTemplate | None = None, dt: float | None = None,
                callback=None) -> RigResult:
    """Tilt a plate under one segment and find the angles at which it slides and rolls.

    Parameters
    ----------
    params : DEMParameters
        Particle, wall and contact parameters, segment shape, mass model, rolling lever.
    seed : int
        Recorded only: the rig is deterministic.
    mode : {"slide", "roll", "sled"}
        "slide": long axis down the slope (it can only slide); "roll": long axis across the
        slope, free to roll; "sled": a sled of glued particles (:func:`sled_template`).
    surface : str
        ``steel``, ``particle`` or another material (``simulate.rigs.surfaces``).
    surface_material, surface_contact : dict, optional
        Properties of another plate material and its contact with the particle.
    tilt_rate_deg_s : float
        Rotation rate of the plate [deg/s].
    start_deg : float
        Tilt at which the segment is laid on the plate and the rotation starts [deg]; the lab
        starts at 0.
    max_tilt_deg : float
        Largest tilt [deg].
    threshold : float
        Movement that marks an onset [m] (elastic creep before the onset is below 1e-6 m).
    settle_time : float
        Time the segment rests on the plate at ``start_deg`` before the rotation [s].
    template : ClumpTemplate, optional
        Body; default the template of ``params``' shape.
    dt : float, optional
        Time step [s]; default ``params``' (``simulate.timestep.material_time_step``).
    callback : callable, optional
        ``callback(sim, t_end, final)`` after each chunk (see ``simulate.rigs``).

    Returns
    -------
    RigResult
        ``observable``: ``slide_angle_deg``, ``roll_angle_deg`` [deg] (NaN if not reached),
        ``static_friction_apparent``, ``rolling_friction_apparent`` (their tangents) [-],
        ``mode``. ``record``: per chunk ``t`` [s], ``tilt_deg``, ``displacement`` (down the
        slope) [m], ``rolled_arc`` [m], ``slip`` [m], ``com`` [m], ``angular_velocity``
        [rad/s]; ``rolling_height`` [m].
    """
    seed = check_seed(seed)
    if not isinstance(params, DEMParameters):
        raise InputError(f"params must be a DEMParameters, got {type(params).__name__}")
    if mode not in MODES:
        raise InputError(f"unknown incline mode {mode!r}; valid: {', '.join(MODES)}")
    checks = {"tilt_rate_deg_s": (tilt_rate_deg_s, 1e-3, 30.0), "start_deg": (start_deg, 0.0, 89.0),
              "max_tilt_deg": (max_tilt_deg, 0.0, 89.9), "threshold": (threshold, 1e-8, 0.01),
              "settle_time": (settle_time, 0.0, 10.0)}
    for name, (value, lo, hi) in checks.items():
        if not (isinstance(value, (int, float)) and lo <= value <= hi):
            raise InputError(f"{name} must be a number in [{lo:g}, {hi:g}], got {value!r}")
    if not max_tilt_deg > start_deg:
        raise InputError(f"max_tilt_deg ({max_tilt_deg!r}) must exceed start_deg ({start_deg!r})")
    surf = make_surface(params, surface, surface_material=surface_material,
                        surface_contact=surface_contact)
    tpl = template if template is not None else params.template()
    if mode == "sled":
        tpl = sled_template(tpl)
    if not isinstance(tpl, ClumpTemplate):
        raise InputError(f"template must be a ClumpTemplate, got {type(tpl).__name__}")
    dt = material_time_step(params) if dt is None else float(dt)

    # long axis (template x) down the slope (x) to slide, across it (y) to roll
    q = np.array([1.0, 0.0, 0.0, 0.0]) if mode != "roll" else axis_angle_quat((0.0, 0.0, 1.0), math.pi / 2)
    rel = (tpl.centres - tpl.centre_of_mass) @ matrix_from_quat(q).T
    z0 = -float((rel[:, 2] - tpl.radii).min())          # lowest point on the plate
    reach = tpl.bounding_radius
    sim = Simulation(surf.materials, domain_lo=(-0.05, -0.05 - reach, -0.02),
                     domain_hi=(STOP_DISTANCE + 0.05 + reach, 0.05 + reach, 2.0 * reach + 0.05),
                     dt=dt, gravity=_gravity(start_deg), rolling_lever=params.rolling_lever)
    tid = sim.add_template(tpl)
    sim.add_wall(Plane((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), material=surf.plate_material, name="plate"))
    sim.add_clump(tid, position=(0.0, 0.0, z0), orientation=q, material=PARTICLE)

    tally = RunTally()
    chunk_s = CHUNK_DEG / tilt_rate_deg_s
    n_chunk = max(1, int(round(chunk_s / dt)))
    t_end = settle_time + (max_tilt_deg - start_deg) / tilt_rate_deg_s
    tally.add(sim.run(duration=settle_time))
    x0 = sim.positions()[0]
    R_last = sim.rotation_matrices()[0]
    phi = np.zeros(3)           # rotation since the tilt began [rad], added up piece by piece
    height = float(x0[2])
    windup = _elastic_rolling_arc(sim, surf, height)
    t0 = sim.time
    rows = []
    onset = {"slide": math.nan, "roll": math.nan}
    slip_from, candidate, knocks = 0.0, None, []     # candidate: (tilt, slip) of a slide to confirm
    tilt = start_deg
    while tilt < max_tilt_deg:
        # tilt at the middle of the coming chunk
        tilt = start_deg + tilt_rate_deg_s * (sim.time - t0 + 0.5 * n_chunk * dt)
        sim.gravity = _gravity(tilt)
        turned, R_last = _run_adding_up_rotation(sim, n_chunk, R_last, tally)
        x = sim.positions()[0]
        phi += turned
        moved = float(x[0] - x0[0])
        arc = float(phi[1]) * height
        slip = moved - arc
        rows.append((sim.time, tilt, moved, arc, slip, *x, *sim.angular_velocities()[0]))
        if callback is not None:
            callback(sim, t_end, False)
        if math.isnan(onset["slide"]):
            if candidate is None and slip - slip_from > threshold:
                candidate = (tilt, slip)
            elif candidate is not None and slip - candidate[1] > CONFIRM_SLIP:
                onset["slide"] = candidate[0]
            elif candidate is not None and abs(slip - rows[-2][4]) < REST_FRACTION * threshold:
                knocks.append((candidate[0], slip - slip_from))
                slip_from, candidate = slip, None
        if math.isnan(onset["roll"]) and arc > threshold + windup:
            onset["roll"] = tilt
        if not math.isnan(onset[ONSET[mode]]) or abs(moved) > STOP_DISTANCE or not sim.active()[0]:
            break
    if callback is not None:
        callback(sim, t_end, True)
    if candidate is not None and math.isnan(onset["slide"]):
        onset["slide"] = candidate[0]           # still slipping when the run ended

    data = np.array(rows).reshape(-1, 11)
    observable = {
        "slide_angle_deg": float(onset["slide"]),
        "roll_angle_deg": float(onset["roll"]),
        "static_friction_apparent": math.tan(math.radians(onset["slide"])),
        "rolling_friction_apparent": math.tan(math.radians(onset["roll"])),
        "mode": mode,
    }
    rec = {"t": data[:, 0], "tilt_deg": data[:, 1], "displacement": data[:, 2], "rolled_arc": data[:, 3],
           "slip": data[:, 4], "com": data[:, 5:8], "angular_velocity": data[:, 8:11],
           "rolling_height": height, "elastic_rolling_arc": windup}
    options = {"mode": mode, "surface": surface, "surface_material": surface_material,
               "surface_contact": surface_contact, "tilt_rate_deg_s": tilt_rate_deg_s,
               "start_deg": start_deg, "max_tilt_deg": max_tilt_deg, "threshold": threshold,
               "settle_time": settle_time, "template": tpl.name if template is not None else None,
               "dt": dt}
    notes = [f"slipped {1e3 * d:.3f} mm at {a:.2f} deg and stopped: not read as a slide" for a, d in knocks]
    if math.isnan(onset[ONSET[mode]]):
        notes.append(f"no {mode} onset up to {tilt:.2f} deg" + (" (the particle moved otherwise first)"
                                                              if rows and abs(rows[-1][2]) > STOP_DISTANCE else ""))
    meta = run_meta(seed, dt, tally, sim.n_spheres, sim.time, notes=notes, surface=surf.to_dict(),
                    template=tpl.to_dict())
    return RigResult("incline", observable, rec, meta, params.to_dict(), Provenance(seed=seed, options=options))


#: The onset each mode reads.
ONSET = {"slide": "slide", "roll": "roll", "sled": "slide"}


def sled_template(particle: ClumpTemplate) -> ClumpTemplate:
    """A sled: ``SLED_ROWS`` x ``SLED_ROWS`` copies of ``particle`` in its principal frame (its
    longest axis x, its thinnest z, as it lies on a plate), side by side in x and y with gaps of
    ``SLED_GAP`` of its extent, glued into one rigid body of their summed mass and inertia."""
    from demcal.simulate.clump import MassProperties, principal_frame

    offsets, radii = particle.offsets, particle.radii
    extent = (offsets + radii[:, None]).max(axis=0) - (offsets - radii[:, None]).min(axis=0)
    step = extent * (1.0 + SLED_GAP)
    k = np.arange(SLED_ROWS) - (SLED_ROWS - 1) / 2.0
    shifts = np.array([(i * step[0], j * step[1], 0.0) for i in k for j in k])
    centres = np.concatenate([offsets + s for s in shifts])
    one = np.diag(particle.principal_moments)
    inertia = sum(one + particle.mass * ((s @ s) * np.eye(3) - np.outer(s, s)) for s in shifts)
    props = MassProperties(particle.mass * len(shifts), np.zeros(3), inertia)
    moments, axes = principal_frame(props.inertia)
    return ClumpTemplate(f"sled of {len(shifts)} {particle.name}", centres, np.tile(radii, len(shifts)),
                         props.mass, props.centre_of_mass, moments, axes, particle.mass_model)


def _elastic_rolling_arc(sim: Simulation, surf: Surface, height: float) -> float:
    """The largest arc [m] the spring-dashpot rolling model lets a body resting on the plate
    roll elastically (0 under the constant torque). Its spring holds a contact at a rolling angle
    up to M_m / k_r = d_n / (2.25 mu_r R_r) (``simulate.contact.rolling``: M_m = mu_r F_n R_r,
    k_r = 2.25 k_n mu_r^2 R_r^2, F_n = k_n d_n), with d_n the overlap and R_r the sphere's
    radius against a plane; the body's rolled arc is that angle times ``height``. For a soft
    seed this windup exceeds ``threshold`` far below the tilt at which the body rolls (a soybean
    at mu_r 0.05 winds up 37 um), so a roll is counted beyond it."""
    if surf.materials.rolling_model != "epsd":
        return 0.0
    mu_r = surf.materials.pair(PARTICLE, surf.plate_material).rolling_friction
    if not mu_r > 0.0:
        return 0.0
    z, r = sim.sphere_positions()[:, 2], sim.sphere_radii()
    touching = z < r
    if not touching.any():
        return 0.0
    return float(height * np.max((r - z)[touching] / (2.25 * mu_r * r[touching])))


def _gravity(tilt_deg: float) -> tuple:
    """Gravity [m/s2] for a plate tilted by ``tilt_deg``, +x down the slope."""
    a = math.radians(tilt_deg)
    return (GRAVITY * math.sin(a), 0.0, -GRAVITY * math.cos(a))


# ----------------------------------------------------------------------------------------------
# a run as a task: what a run store keys and a worker runs


#: A twin run that reads a sliding onset starts tilted at this fraction of atan(mu_s), below
#: Coulomb's onset: nothing moves in the tilt it skips, and the onset it reads is the same
#: within about ``CHUNK_DEG`` (the spring's elastic preload at the start is not counted as
#: movement: 0.013 deg at most in the cases measured, a segment at G = 1 MPa) at a third to a
#: fifth of the steps. Rolling onsets are not started tilted: under the spring-dashpot rolling
#: model a sphere's elastic windup from flat reads an onset far below atan(mu_r).
START_FRACTION = 0.8
#: A run that reads an onset, or ends, within this tilt of a tilted start [deg] is run again
#: from flat: its particle moved (or crept) at once, and a slow tilt from 0 might have seen it
#: move lower. A true sliding onset lies 0.2 atan(mu_s) above the start.
RESTART_WITHIN_DEG = 0.1


def start_angle(params: DEMParameters, mode: str, surface: str) -> float:
    """The tilt a twin run starts at [deg]: ``START_FRACTION`` of atan(mu_s) of the particle's
    contact with the surface for the sliding modes on a surface ``params`` define, 0 otherwise
    (rolling runs start flat, see ``START_FRACTION``)."""
    if ONSET.get(mode) != "slide" or surface not in BUILT_IN_SURFACES:
        return 0.0
    surf = make_surface(params, surface)
    mu = surf.materials.pair(PARTICLE, surf.plate_material).static_friction
    start = round(START_FRACTION * math.degrees(math.atan(mu)), 2)
    # a friction whose slide lies beyond the tilt a run reaches: flat, as it reads no onset anyway
    return start if start < MAX_TILT_DEG - RESTART_WITHIN_DEG else 0.0


def task(params: DEMParameters, mode: str, surface: str, seed: int = 0) -> dict:
    """The inputs of one incline run (``analyse.runs.run_key`` keys its record)."""
    return {"rig": "incline", "params": params.to_dict(), "mode": mode, "surface": surface,
            "start_deg": start_angle(params, mode, surface), "seed": int(seed)}


def run_task(inputs: dict) -> dict:
    """One incline run from its :func:`task`: the observable and the run's tally. A run that
    moved at once started too steep (a particle that rolls, a friction the slide does not
    follow) and is run again from 0, as the lab tilts; its tally counts both."""
    params = DEMParameters.from_names(inputs["params"])
    options = {"mode": inputs["mode"], "surface": inputs["surface"]}
    start = float(inputs.get("start_deg", 0.0))
    res = run_incline(params, int(inputs["seed"]), start_deg=start, **options)
    steps, wall_s = res.meta["steps"], res.meta["wall_s"]
    restarted = []
    if start > 0.0 and _moved_at_once(res, start):
        res = run_incline(params, int(inputs["seed"]), start_deg=0.0, **options)
        steps, wall_s = steps + res.meta["steps"], wall_s + res.meta["wall_s"]
        restarted = [f"moved at once when started tilted at {start:.2f} deg: run again from 0 deg"]
    return {"rig": "incline", "observable": res.observable, "notes": restarted + res.meta.get("notes", []),
            "dt": res.meta["dt"], "steps": steps, "wall_s": wall_s}


def _moved_at_once(res: RigResult, start: float) -> bool:
    """Whether a run started at ``start`` [deg] read an onset, or ended, within
    ``RESTART_WITHIN_DEG`` of it."""
    near = start + RESTART_WITHIN_DEG
    onsets = (res.observable["slide_angle_deg"], res.observable["roll_angle_deg"])
    return float(res.record["tilt_deg"][-1]) <= near or any(a <= near for a in onsets if math.isfinite(a))


# ----------------------------------------------------------------------------------------------
# the lab's tilts as twin runs

#: Points of the joint calibration's grid, over the lab's mean -+ ``LIKELIHOOD_SDS`` sd.
LIKELIHOOD_POINTS = 7
LIKELIHOOD_SDS = 4.0
#: The twin's mode for a measured friction, and the preferred one first: a sled's reading
#: (the rows' ``carrier``) before a single particle's.
FAMILY_MODES = {"static_friction": ("sled", "slide"), "rolling_friction": ("roll",)}


def trial_groups(quantities: dict, wall: str) -> list:
    """One group per measured friction and mode (``static_friction.<surface>``: ``sled`` rows,
    those whose ``carrier`` is a sled, then ``slide``; ``rolling_friction.<surface>``:
    ``roll``). The twin is deterministic, so one run serves every trial of a group."""
    groups = []
    for name, est in quantities.items():
        family, _, surface = name.partition(".")
        if family not in FAMILY_MODES:
            continue
        rig_surface = "steel" if surface == wall else surface if surface == "particle" else None
        by_mode = {}
        for rec in used_rows(est):
            mode = "sled" if family == "static_friction" and rec.get("carrier") == "sled" else FAMILY_MODES[family][-1]
            by_mode.setdefault(mode, []).append(Trial(int(rec["row"]), float(rec["value"]), {}, rec))
        for mode in FAMILY_MODES[family]:
            if mode in by_mode:
                groups.append(TrialGroup("incline", name, None if rig_surface is None else
                                         {"mode": mode, "surface": rig_surface}, tuple(by_mode[mode]),
                                         "" if rig_surface else f"no DEM parameters for surface {surface}"))
    return groups


def group_tasks(params: DEMParameters, group) -> list:
    """The group's one twin run (the rig is deterministic)."""
    return [task(params, group.setting["mode"], group.setting["surface"], 0)]


def observed(inputs: dict) -> str:
    """The observable a task reads: tan of the onset its mode reads."""
    return "rolling_friction_apparent" if ONSET[inputs["mode"]] == "roll" else "static_friction_apparent"


def describe_twin(group, params: DEMParameters, results: list) -> str:
    """What the group's run read, and why it read nothing (the particle rolled before it slid,
    or slid before it rolled)."""
    mode, surface = group.setting["mode"], group.setting["surface"]
    ob = results[0]["observable"]
    note = f"tan(onset angle) of the {mode} twin on {surface}"
    value = ob.get(observed(group.setting))
    if value is None or not math.isfinite(value):
        rolls = ONSET[mode] == "roll"
        other = ob.get("slide_angle_deg" if rolls else "roll_angle_deg")
        note += f"; no {mode} onset" + (f" (it {'slid' if rolls else 'rolled'} first, at {other:.3g} deg)"
                                        if other is not None and math.isfinite(other) else "")
    return note


def likelihood_grid(value: float, sd: float, bounds: tuple) -> np.ndarray:
    """The frictions the joint calibration runs the twin at: the lab's mean -+ 4 sd, inside
    the parameter's bounds."""
    lo = max(bounds[0], value - LIKELIHOOD_SDS * sd)
    hi = min(bounds[1], value + LIKELIHOOD_SDS * sd)
    return np.linspace(lo, hi, LIKELIHOOD_POINTS)


def cli_arguments(group) -> None:
    """``demcal simulate incline``'s options."""
    group.add_argument("--surface", default="steel",
                       help="incline: plate surface, steel (default), particle or another material "
                            "(needs --surface-material)")
    group.add_argument("--mode", choices=MODES, default="slide",
                       help="incline: slide (the particle along the slope), roll (across it) or sled (a sled of "
                            "glued particles, for round particles that roll first)")
    group.add_argument("--tilt-rate", type=float, default=1.0, metavar="DEG_S",
                       help="incline: tilt rate [deg/s] (default 1)")


def cli_options(args) -> dict:
    """The incline's options from ``demcal simulate incline``'s arguments."""
    return {"mode": args.mode, "surface": args.surface, "tilt_rate_deg_s": args.tilt_rate,
            **surface_options(args.surface_values)}


RIG = Rig("incline", sheet="incline", run=run_incline, task=task, run_task=run_task, compared="slide_angle_deg",
          observables={"slide_angle_deg": "deg", "roll_angle_deg": "deg", "static_friction_apparent": "-",
                       "rolling_friction_apparent": "-"},
          lab_test="inclinometer, plate tilted slowly",
          trial_groups=trial_groups, group_tasks=group_tasks, observed=observed, grid=likelihood_grid,
          describe_twin=describe_twin, cli_arguments=cli_arguments, cli_options=cli_options)
