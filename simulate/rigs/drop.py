"""Drop rig: the twin of the free-fall restitution test (high-speed camera, rebound height).

One segment is released at rest above a horizontal plate (``simulate.rigs.surfaces``) and
falls onto it; the rig follows its centre of mass as the lab's camera track does and reports

    apparent_restitution = sqrt(h_rebound / h_drop)                   (paper, eq. 2-4)

with
- ``h_drop``: the fall of the centre of mass from release to its height at the first contact;
- ``h_rebound``: the rise of the centre of mass from that same contact height to its first
  apex in free flight after the impact (0 if that apex lies lower). A tilted segment strikes
  with one end, turns and strikes with the other, its centre of mass still descending between
  the impacts (Stoianovici & Hurmuzlu 1996): the rebound is the whole impact sequence, up to
  the first time the body, clear of the plate, stops rising, as a camera track reads it.

Release height. ``height`` is the gap between the plate and the lowest point of the segment at
release (what a release stand sets). Released at rest, the body does not rotate in free fall,
so its centre of mass falls by exactly ``height`` before the first contact (``h_drop`` =
``height``, up to the time step). That free fall (no air drag in the model) is done
analytically: the simulation starts ``START_GAP`` above the plate with the free-fall velocity,
and the record starts with the release point at t = 0.

Orientation. ``orientation_deg`` is the angle of the segment's long axis (template x axis) to
the horizontal: 0 = lying flat, 90 = end on. ``None`` draws the axis uniformly on the sphere
of directions (and the spin about it uniformly) from ``seed``.

For a single sphere the apparent restitution equals the contact's coefficient of restitution.
For an elongated body hitting with one end, part of the energy goes into rotation and the
apparent restitution falls below the contact value: the rig also reports the first-impact
velocity ratio (-v_z after the first contact period / v_z before it; negative when the centre
of mass is still descending as the first contact ends, e.g. one end struck and the body pivots)
and the rotational share of the kinetic energy after it.

Multi-sphere contacts. Each member sphere makes its own contact, with the mass of the whole
body in m* (docs/design.md, as EDEM). A segment landing flat touches with all n spheres at once:
the body then sees n springs and n dashpots whose damping is set for one, so its damping
ratio is sqrt(n) times the contact's and the rebound far lower than ``e`` (0.04 instead of
0.35 for 5 spheres; Kodam et al. 2010). A segment landing end on (one contact through the
centre of mass) rebounds with the contact's ``e``. One striking with an end sphere is
overdamped too, its contact moving only the body's effective mass there. The
``contact_effective_mass`` hook (``simulate.extensions``) damps that mass at each contact
instead; ``simulate.rigid_impact`` gives the rigid body's rebound to compare with.

Time step. Contacts must be resolved: by default dt = t_c / 100, t_c the elastic Hertz contact
duration (Johnson 1985, sec. 11.4) of one member sphere carrying 1/n of the body's mass at the
impact speed sqrt(2 g h), capped at 0.4 of the Rayleigh time (and at the parameter set's own
``dt`` when that is finer). Far from the plate the rig runs
in long chunks that cannot reach the plate, shrinking to single steps as it approaches (so the
first contact is found to the step). While the body touches the plate it runs chunks of steps
(from t_c / 10, doubling while nothing happens; ``CONTACT_CHUNK_FRACTION``) and records their
ends. The state before each such chunk is kept, and a chunk in which an event may lie (no
sphere touched the plate at both ends, so the body may have left it; the centre of mass
turned from rising to falling; the rebound may have ended) is run again from there in halves,
down to single steps around the event. The events, and so the observables, are those of a
record at every step, for a small fraction of the calls: the engine's trajectory does not
depend on how its steps are chunked (its half kicks at the ends of a chunk add up to the full
kick), up to rounding and to the rolling torque's stop, a constraint over each kick that a
chunk's end splits in two (about 1e-8 m in a sequence of end impacts).

References
----------
Johnson, K. L. (1985). Contact Mechanics. Cambridge University Press.
Kodam, M., Bharadwaj, R., Curtis, J., Hancock, B., Wassgren, C. (2010). Force model
considerations for glued-sphere discrete element method simulations. Chem. Eng. Sci. 65,
5852-5861.
Stoianovici, D., Hurmuzlu, Y. (1996). A critical study of the applicability of rigid-body
collision theory. J. Appl. Mech. 63, 307-316.
"""

from __future__ import annotations

import copy
import functools
import math

import numpy as np

from demcal.errors import InputError
from demcal.provenance import Provenance
from demcal.simulate.clump import ClumpTemplate
from demcal.simulate.contact.hertz_mindlin import contact_duration_elastic, effective_modulus
from demcal.simulate.engine import Simulation
from demcal.simulate.integrate import axis_angle_quat, matrix_from_quat, quat_multiply
from demcal.simulate.params import DEMParameters
from demcal.simulate.rigs import Rig, RigResult, RunTally, Trial, TrialGroup, check_seed, run_meta, used_rows
from demcal.simulate.rigs.surfaces import PARTICLE, make_surface, surface_from_pair, surface_options
from demcal.simulate.walls import Plane
from demcal.units import GRAVITY

#: The paper's drop height [m] ("fixed at 400 mm").
PAPER_DROP_HEIGHT = 0.400
#: Time steps per (shortest) contact for the automatic time step (the apparent restitution of
#: a single sphere is then within about 1 % of the contact value).
STEPS_PER_CONTACT = 100
#: Gap between the lowest point and the plate at which the simulation starts [m].
START_GAP = 0.002
#: Largest time step as a fraction of the Rayleigh time.
MAX_RAYLEIGH_FRACTION = 0.4
#: Longest chunk of steps run without a record [steps].
MAX_CHUNK = 2000
#: First chunk of steps run while the body touches the plate, as a fraction of the shortest
#: contact time t_c (one member sphere with 1/n of the mass, ``shortest_contact_time``).
#: Chunks double while nothing happens in them, up to CONTACT_CHUNK_ACTIVE t_c (less than the
#: half period of the fastest contact oscillation, so a chunk holds at most one turning point),
#: or up to CONTACT_CHUNK_QUIET t_c once the contact is quiet: no point of the body changed its
#: velocity by more than QUIET_ACCELERATION g over the last chunk (a body rocking or resting on
#: the plate, not an impact).
CONTACT_CHUNK_FRACTION = 0.1
CONTACT_CHUNK_ACTIVE = 0.5
CONTACT_CHUNK_QUIET = 8.0
QUIET_ACCELERATION = 10.0


def release_orientation(orientation_deg, rng: np.random.Generator):
    """Quaternion (w, x, y, z) of the template frame at release and the axis angle [deg].

    A given ``orientation_deg`` tilts the template x axis by that angle above the horizontal
    (a rotation about y); ``None`` draws the x axis uniformly on the unit sphere (normalised
    Gaussian vector, Muller 1959) and a uniform spin about it.
    """
    if orientation_deg is None:
        u = rng.standard_normal(3)
        u /= np.linalg.norm(u)
        spin = rng.uniform(0.0, 2.0 * math.pi)
        x = np.array([1.0, 0.0, 0.0])
        axis = np.cross(x, u)
        s = np.linalg.norm(axis)
        angle = math.atan2(s, float(x @ u))
        align = axis_angle_quat(axis / s, angle) if s > 1e-12 else (
            np.array([1.0, 0.0, 0.0, 0.0]) if u[0] > 0 else axis_angle_quat((0.0, 0.0, 1.0), math.pi))
        q = quat_multiply(axis_angle_quat(u, spin), align)
        return q, math.degrees(math.asin(min(1.0, abs(float(u[2])))))
    try:
        a = float(orientation_deg)
    except (TypeError, ValueError):
        raise InputError(f"orientation_deg must be a number in [0, 90] or None, got {orientation_deg!r}") from None
    if not 0.0 <= a <= 90.0:
        raise InputError(f"orientation_deg must be in [0, 90] (angle of the long axis to the "
                         f"horizontal), got {orientation_deg!r}")
    return axis_angle_quat((0.0, 1.0, 0.0), -math.radians(a)), a


def shortest_contact_time(template: ClumpTemplate, surface, height: float, gravity: float = GRAVITY) -> float:
    """t_c [s]: the elastic Hertz contact duration of the smallest member sphere against the
    plate, with 1/n of the body mass (n member spheres), at the impact speed sqrt(2 g height)."""
    table = surface.materials
    p = table.material(PARTICLE)
    w = table.material(surface.plate_material)
    e_star = effective_modulus(p.youngs_modulus, p.poisson_ratio, w.youngs_modulus, w.poisson_ratio)
    speed = math.sqrt(2.0 * gravity * height)
    return contact_duration_elastic(template.mass / template.n_spheres, float(template.radii.min()),
                                    e_star, speed)


def automatic_time_step(template: ClumpTemplate, surface, height: float, gravity: float = GRAVITY) -> float:
    """dt [s]: t_c / STEPS_PER_CONTACT, capped at MAX_RAYLEIGH_FRACTION of the Rayleigh time.

    t_c is :func:`shortest_contact_time`.
    """
    from demcal.simulate.timestep import rayleigh_time
    p = surface.materials.material(PARTICLE)
    t_c = shortest_contact_time(template, surface, height, gravity)
    t_r = rayleigh_time(float(template.radii.min()), p.density, p.shear_modulus, p.poisson_ratio)
    return min(t_c / STEPS_PER_CONTACT, MAX_RAYLEIGH_FRACTION * t_r)


def run_drop(params: DEMParameters, seed: int = 0, *, height: float = PAPER_DROP_HEIGHT,
             orientation_deg: float | None = None, pair: str = "particle-steel",
             surface_material: dict | None = None, surface_contact: dict | None = None,
             template: ClumpTemplate | None = None, dt: float | None = None,
             callback=None) -> RigResult:
    """Drop one segment onto a plate and measure its apparent restitution.

    Parameters
    ----------
    params : DEMParameters
        Particle, wall and contact parameters, segment shape and mass model.
    seed : int
        Seed of the random orientation (unused when ``orientation_deg`` is given).
    height : float
        Gap between the plate and the lowest point of the segment at release [m].
    orientation_deg : float or None
        Angle of the long axis to the horizontal at release [deg], 0..90; None = random.
    pair : str
        ``particle-steel``, ``particle-particle`` or ``particle-<material>``
        (``simulate.rigs.surfaces``).
    surface_material, surface_contact : dict, optional
        Properties of another plate material and its contact with the particle.
    template : ClumpTemplate, optional
        Body shape; default the segment of ``params``.
    dt : float, optional
        Time step [s]; default :func:`automatic_time_step`.
    callback : callable, optional
        ``callback(sim, t_end, final)`` after each chunk (see ``simulate.rigs``).

    Returns
    -------
    RigResult
        ``observable``: ``apparent_restitution`` [-], ``velocity_ratio`` [-],
        ``rotational_energy_share`` [-], ``orientation_deg`` [deg], ``drop_height_m`` and
        ``rebound_height_m`` (of the centre of mass) [m]. ``record``: ``t`` [s], ``com`` [m],
        ``velocity`` [m/s], ``angular_velocity`` [rad/s], ``gap`` (lowest point above the
        plate) [m], ``contact`` (bool) per record, and the event times ``t_contact``,
        ``t_separation``, ``t_apex`` [s] and ``z_contact``, ``z_apex`` [m].
    """
    seed = check_seed(seed)
    if not isinstance(params, DEMParameters):
        raise InputError(f"params must be a DEMParameters, got {type(params).__name__}")
    try:
        height = float(height)
    except (TypeError, ValueError):
        raise InputError(f"drop height must be a number [m], got {height!r}") from None
    if not 0.0 < height <= 5.0:
        raise InputError(f"drop height must be in (0, 5] m, got {height!r}")
    surface_name = surface_from_pair(pair)
    surface = make_surface(params, surface_name, surface_material=surface_material,
                           surface_contact=surface_contact)
    tpl = template if template is not None else _template(params)
    if not isinstance(tpl, ClumpTemplate):
        raise InputError(f"template must be a ClumpTemplate, got {type(tpl).__name__}")
    rng = np.random.default_rng(seed)
    q, angle = release_orientation(orientation_deg, rng)
    g = GRAVITY
    if dt is None:   # a finer step the parameter set states is honoured, a coarser one not
        dt = min(automatic_time_step(tpl, surface, height, g), params.dt or math.inf)

    # release with the lowest point `height` above the plate z = 0; fall analytically to
    # START_GAP above it
    rel = (tpl.centres - tpl.centre_of_mass) @ matrix_from_quat(q).T
    lowest = float((rel[:, 2] - tpl.radii).min())
    z0 = height - lowest
    fall = max(height - START_GAP, 0.0)
    t_pre = math.sqrt(2.0 * fall / g)
    reach = tpl.bounding_radius
    t_fall = math.sqrt(2.0 * height / g)
    rise_max = height + 2.0 * reach     # an elastic rebound, plus what a turn can add
    sim = Simulation(surface.materials, domain_lo=(-0.3, -0.3, -0.05),
                     domain_hi=(0.3, 0.3, max(z0, rise_max) + reach + 0.05),
                     dt=dt, gravity=(0.0, 0.0, -g), rolling_lever=params.rolling_lever)
    tid = sim.add_template(tpl)
    sim.add_wall(Plane((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), material=surface.plate_material, name="plate"))
    sim.add_clump(tid, position=(0.0, 0.0, z0 - fall), orientation=q, velocity=(0.0, 0.0, -g * t_pre),
                  material=PARTICLE)
    radii = sim.sphere_radii()
    t_end = 3.0 * t_fall + 0.2 - t_pre    # an elastic rebound is back at the contact height at 2 t_fall

    rows = [(0.0, 0.0, 0.0, z0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, height)]   # the release

    def record():
        x = sim.positions()[0]
        sphere_gaps = sim.sphere_positions()[:, 2] - radii
        gap = float(sphere_gaps.min())
        rows.append((t_pre + sim.time, *x, *sim.velocities()[0], *sim.angular_velocities()[0], gap))
        return x[2], gap, sphere_gaps < 0.0

    tally = RunTally()
    _, _, touching = record()
    phase = "fall"
    ev = {"t_contact": math.nan, "z_contact": math.nan, "vz_in": math.nan, "t_separation": math.nan,
          "vz_out": math.nan, "rot_share": math.nan, "t_apex": math.nan, "z_apex": math.nan}
    t_c = shortest_contact_time(tpl, surface, height, g)
    first_chunk = max(1, int(CONTACT_CHUNK_FRACTION * t_c / dt))
    active_chunk = max(first_chunk, int(CONTACT_CHUNK_ACTIVE * t_c / dt))
    quiet_chunk = max(active_chunk, min(int(CONTACT_CHUNK_QUIET * t_c / dt), MAX_CHUNK))
    limit, hold_until = first_chunk, 0   # contact chunk [steps]; not grown before step hold_until
    step = 0
    while sim.time < t_end and sim.n_bodies and sim.active()[0]:
        gap, vz = rows[-1][10], rows[-1][6]
        saved = None
        in_contact = gap < 0.0 and phase != "fall"
        if in_contact:
            n = limit
            if n > 1:
                # keep the state to go back to; materials, templates, walls: shared, runs keep them
                fixed = {id(o): o for o in (sim.materials, *sim.templates, *sim.walls)}
                saved = (copy.deepcopy(sim, fixed), len(rows), touching)
        else:
            n = _safe_steps(gap, vz, float(np.linalg.norm(rows[-1][7:10])), reach, g, dt)
            if phase == "flight" and gap > 0.0 and vz > 0.0:
                n = min(n, max(1, int(math.ceil(vz / (g * dt)))))   # land on the apex
            limit = first_chunk     # a new impact starts fast
        tally.add(sim.run(n_steps=n))   # replayed steps count too: they cost their time
        z, gap, touching = record()
        prev = rows[-2]
        if saved is not None and _event_within(prev, rows[-1], saved[2], touching):
            # back to the chunk's start; run it in halves
            sim, del_from, touching = saved
            del rows[del_from:]
            limit, hold_until = max(1, n // 2), step + n
            continue
        step += n
        if in_contact and step >= hold_until:
            dv = math.dist(prev[4:7], rows[-1][4:7]) + reach * math.dist(prev[7:10], rows[-1][7:10])
            quiet = dv <= QUIET_ACCELERATION * g * n * dt
            limit = min(2 * limit, quiet_chunk if quiet else active_chunk)
        if callback is not None:
            callback(sim, t_end, False)
        if phase == "fall" and gap < 0.0:
            # first contact between the two records: interpolate the crossing of the plate
            f = prev[-1] / (prev[-1] - gap)
            ev["t_contact"] = prev[0] + f * (rows[-1][0] - prev[0])
            ev["z_contact"] = prev[3] + f * (z - prev[3])
            ev["vz_in"] = prev[6] + f * (rows[-1][6] - prev[6])
            phase = "impact"
        elif phase == "impact" and gap >= 0.0:
            if math.isnan(ev["t_separation"]):      # the end of the first contact
                v = sim.velocities()[0]
                e_rot = 0.5 * float(sim.angular_velocities()[0] @ sim.angular_momenta()[0])
                e_tr = 0.5 * float(sim.masses()[0]) * float(v @ v)
                ev["t_separation"] = t_pre + sim.time
                ev["vz_out"] = float(v[2])
                ev["rot_share"] = e_rot / (e_rot + e_tr) if e_rot + e_tr > 0 else math.nan
            phase, flight_top = "flight", (z, t_pre + sim.time)
        elif phase == "flight" and gap < 0.0:
            phase = "impact"        # the next impact of the sequence (the other end, a tilted body)
        if phase == "flight":
            if z > flight_top[0]:
                flight_top = (z, t_pre + sim.time)
            if prev[6] > 0.0 >= rows[-1][6]:
                # the first apex in free flight ends the rebound
                ev["z_apex"], ev["t_apex"] = flight_top
                break
    if callback is not None:
        callback(sim, t_end, True)

    data = np.array(rows)
    h_drop = z0 - ev["z_contact"]
    notes = []
    if math.isfinite(ev["z_apex"]):
        rise = max(ev["z_apex"] - ev["z_contact"], 0.0)
        apparent = math.sqrt(rise / h_drop)
    elif phase in ("impact", "flight"):
        notes.append("the body did not rise clear of the plate to an apex within the run (it stayed on "
                     "the plate)")
        rise, apparent = 0.0, 0.0
    else:
        notes.append("the body never reached the plate")
        rise, apparent = math.nan, math.nan
    observable = {k: float(v) for k, v in {
        "apparent_restitution": apparent,
        "velocity_ratio": -ev["vz_out"] / ev["vz_in"] if ev["vz_in"] < 0 else math.nan,
        "rotational_energy_share": ev["rot_share"],
        "orientation_deg": angle,
        "drop_height_m": h_drop,
        "rebound_height_m": rise,
    }.items()}
    rec = {"t": data[:, 0], "com": data[:, 1:4], "velocity": data[:, 4:7],
           "angular_velocity": data[:, 7:10], "gap": data[:, 10], "contact": data[:, 10] < 0.0,
           "t_contact": ev["t_contact"], "t_separation": ev["t_separation"], "t_apex": ev["t_apex"],
           "z_contact": ev["z_contact"], "z_apex": ev["z_apex"], "z_release": z0}
    options = {"height": height, "orientation_deg": orientation_deg, "pair": pair,
               "surface_material": surface_material, "surface_contact": surface_contact,
               "template": tpl.name if template is not None else None, "dt": dt}
    meta = run_meta(seed, dt, tally, sim.n_spheres, t_pre + sim.time, notes=notes,
                    surface=surface.to_dict(), template=tpl.to_dict())
    return RigResult("drop", observable, rec, meta, params.to_dict(),
                     Provenance(seed=seed, options=options))


@functools.lru_cache(maxsize=8)
def _template(params: DEMParameters) -> ClumpTemplate:
    """``params.template()``, built once per parameter set: the union's mass properties take
    about 0.1 s, longer than most drops (the critique runs hundreds of drops with one
    parameter set)."""
    return params.template()


def _event_within(prev, row, touching0, touching1) -> bool:
    """Whether a chunk run in contact, from record ``prev`` to ``row`` (rows of ``run_drop``),
    may hold an event that a record at every step would have caught: no sphere touched the
    plate at both ends (the body may have left it), or the centre of mass turned from rising
    to falling (an apex inside)."""
    return not (touching0 & touching1).any() or prev[6] > 0.0 >= row[6]


def _safe_steps(gap: float, vz: float, w: float, reach: float, g: float, dt: float) -> int:
    """Steps that cannot bring any point of the body onto the plate: half the time in which a
    point approaching at |min(vz, 0)| + w reach [m/s] and accelerating at g closes ``gap``."""
    if gap <= 0.0:
        return 1
    a = max(-vz, 0.0) + w * reach
    t = (-a + math.sqrt(a * a + 2.0 * g * gap)) / g
    return int(min(max(1, math.floor(0.5 * t / dt)), MAX_CHUNK))


# ----------------------------------------------------------------------------------------------
# a run as a task: what a run store keys and a worker runs


def task(params: DEMParameters, pair: str, height: float, orientation_deg, seed: int, *, template=None,
         extension: dict | None = None) -> dict:
    """The inputs of one drop run (``analyse.runs.run_key`` keys its record): ``template`` the
    specimen's sizes [m] (``Shape.size_values``) for a particle of its own size, ``extension``
    the provenance of the model extension it evaluates."""
    return {"rig": "drop", "params": params.to_dict(), "pair": pair, "height": round(float(height), 9),
            "orientation_deg": orientation_deg, "seed": int(seed),
            "template": None if template is None else [float(v) for v in template],
            "extension": extension}


def run_task(inputs: dict) -> dict:
    """One drop run from its :func:`task`: the observable and the run's tally."""
    from demcal.simulate.extensions import particle_of_size

    params = DEMParameters.from_names(inputs["params"])
    opts = {}
    if inputs.get("template"):
        opts["template"] = particle_of_size(params, inputs["template"])
    res = run_drop(params, int(inputs["seed"]), height=float(inputs["height"]),
                   orientation_deg=inputs.get("orientation_deg"), pair=inputs["pair"], **opts)
    return {"rig": "drop", "observable": res.observable, "notes": res.meta.get("notes", []),
            "dt": res.meta["dt"], "steps": res.meta["steps"], "wall_s": res.meta["wall_s"]}


# ----------------------------------------------------------------------------------------------
# the lab's drops as twin runs

#: Contact restitutions the joint calibration runs the twin at: the whole admissible range,
#: since the apparent value can lie far below the contact one.
LIKELIHOOD_GRID = (0.05, 0.95, 9)


def twin_pair(pair: str, wall: str) -> str | None:
    """The rig's pair for a lab pair (the workbook's plate is the DEM's wall material), or None
    when the DEM has no parameters for it (e.g. ``particle-rubber``)."""
    if pair == "particle-particle":
        return "particle-particle"
    if pair == f"particle-{wall}":
        return "particle-steel"
    return None


def trial_groups(quantities: dict, wall: str) -> list:
    """One group per drop pair (``restitution.<pair>``): each used row at its drop height (the
    track's impact speed when the sheet gives none) and its logged orientation (random from the
    row's seed when the sheet logs none)."""
    groups = []
    for name, est in quantities.items():
        family, _, pair = name.partition(".")
        if family != "restitution":
            continue
        trials = []
        for rec in used_rows(est):
            h = rec.get("drop_height_m")
            if h is None and rec.get("track"):
                h = rec["track"]["v_before"] ** 2 / (2.0 * GRAVITY)
            o = (rec.get("covariates") or {}).get("orientation_deg")
            o = float(o) if isinstance(o, (int, float)) and 0.0 <= float(o) <= 90.0 else None
            trials.append(Trial(int(rec["row"]), float(rec["value"]), {"height": float(h), "orientation_deg": o},
                                rec))
        rig_pair = twin_pair(pair, wall)
        groups.append(TrialGroup("drop", name, None if rig_pair is None else {"pair": rig_pair}, tuple(trials),
                                 "" if rig_pair else f"no DEM contact parameters for {pair} (the DEM knows "
                                                     f"particle-particle and particle-{wall})"))
    return groups


def group_tasks(params: DEMParameters, group, *, sizes=None, extension=None) -> list:
    """One drop per trial, at its height and orientation, seeded by its row; ``sizes`` maps a
    row to its specimen's sizes [m] for a particle of its own size."""
    return [task(params, group.setting["pair"], t.settings["height"], t.settings["orientation_deg"], t.row,
                 template=None if sizes is None else sizes.get(t.row), extension=extension)
            for t in group.trials]


def describe_twin(group, params: DEMParameters, results: list) -> str:
    """How the group's drops were released."""
    logged = sum(t.settings["orientation_deg"] is not None for t in group.trials)
    n = len(group.trials)
    return f"each drop at its height and {'logged' if logged == n else f'logged ({logged}) or random'} orientation"


def likelihood_grid(value: float, sd: float, bounds: tuple) -> np.ndarray:
    """The contact restitutions the joint calibration runs the twin at (``LIKELIHOOD_GRID``)."""
    return np.linspace(*LIKELIHOOD_GRID)


def cli_arguments(group) -> None:
    """``demcal simulate drop``'s options."""
    group.add_argument("--height", type=float, default=PAPER_DROP_HEIGHT * 1e3, metavar="MM",
                       help="drop: gap between the plate and the particle's lowest point at release [mm] "
                            "(default 400, the paper's)")
    group.add_argument("--orientation", default="random", metavar="DEG|random",
                       help="drop: angle of the long axis to the horizontal at release [deg], or "
                            "'random' (uniform on the sphere, from --seed; default)")
    group.add_argument("--pair", default="particle-steel",
                       help="drop: material pair, particle-steel (default), particle-particle or "
                            "particle-<material> (needs --surface-material)")


def cli_options(args) -> dict:
    """The drop's options from ``demcal simulate drop``'s arguments (lengths in mm there)."""
    if not (math.isfinite(args.height) and args.height > 0):
        raise InputError(f"--height must be a positive drop height [mm], got {args.height!r}")
    text = str(args.orientation).strip().lower()
    if text == "random":
        orientation = None
    else:
        try:
            orientation = float(text)
        except ValueError:
            raise InputError(f"--orientation must be an angle in [0, 90] deg or 'random', "
                             f"got {args.orientation!r}") from None
    return {"height": args.height * 1e-3, "orientation_deg": orientation, "pair": args.pair,
            **surface_options(args.surface_values)}


RIG = Rig("drop", sheet="drop", run=run_drop, task=task, run_task=run_task, compared="apparent_restitution",
          observables={"apparent_restitution": "-", "velocity_ratio": "-", "rotational_energy_share": "-",
                       "orientation_deg": "deg", "drop_height_m": "m", "rebound_height_m": "m"},
          lab_test="free-fall drop onto a plate, rebound filmed",
          trial_groups=trial_groups, group_tasks=group_tasks, grid=likelihood_grid, per_trial=True,
          reading_label="apparent sqrt(h2/h1)", describe_twin=describe_twin,
          cli_arguments=cli_arguments, cli_options=cli_options)
