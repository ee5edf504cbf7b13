"""The DEM engine: a ``Simulation`` of rigid sphere clumps, walls and particle factories.

Building and running a simulation
---------------------------------
>>> from simulate import Simulation, MaterialTable, DEMParameters
>>> from simulate.walls import Plane, Rectangle
>>> params = DEMParameters()
>>> sim = Simulation(MaterialTable.from_parameters(params), domain_lo=(-0.1, -0.1, -0.01),
...                  domain_hi=(0.1, 0.1, 0.6), dt=7.43678e-5)
>>> seg = sim.add_template(params.template())        # template id
>>> floor = sim.add_wall(Plane((0, 0, 0), (0, 0, 1), material="steel"))
>>> body = sim.add_clump(seg, position=(0, 0, 0.4), orientation=(1, 0, 0, 0),
...                      material="particle")                      # body id
>>> summary = sim.run(duration=0.5)

Walls are ``simulate.walls.Plane`` (infinite, one-sided), ``Rectangle`` (finite, two-sided,
edges included; ``box_rectangles`` gives the faces of a box) or ``Cylinder`` (an open tube,
two-sided, rims included); ``wall_index(name)`` finds one.
A wall translates at its ``velocity`` during ``[move_start, move_stop)``;
``set_wall_motion(k, velocity, start, stop)`` changes that between runs. Particle factories
(``simulate.factory.ParticleFactory``) are added with ``add_factory`` and insert clumps between
chunks of steps; ``reserve(n_bodies)`` pre-allocates for clumps added one by one, and
``add_clumps(templates, positions, orientations)`` adds many at once (a factory's batch). Gravity may
be changed between runs (``sim.gravity = (gx, gy, gz)``, e.g. to tilt a plate slowly).
``run(duration=...)`` or ``run(n_steps=...)`` returns a ``RunSummary``; ``progress(sim)`` is
called after every chunk.

Reading the state (copies, SI units, rows = bodies in the order they were added):
``positions()`` (centres of mass [m]), ``velocities()`` [m/s], ``orientations()`` (unit
quaternions (w, x, y, z) rotating the *template* frame into the world), ``rotation_matrices()``,
``angular_velocities()`` [rad/s], ``active()`` (False once a body has left the domain),
``sphere_positions()`` [m], ``sphere_radii()`` [m], ``sphere_body()`` (clump id of each sphere),
``kinetic_energy()`` [J], ``body_kinetic_energy()``, ``masses()``, ``angular_momenta()``,
``contact_forces()`` (contact force and torque on each body at the last step [N], [N m]),
``rolling_resistance()``, ``n_contacts()``, ``contact_history()`` (per touching contact:
tangential spring, first-touch impact speed, rolling spring torque), ``wall_origins()``,
``time`` [s], ``escaped``
(bodies that left the domain: id, time, position). ``evaluate_forces()`` recomputes the
contact forces of the current state without stepping. Frames go to ParaView with
``simulate.vtk.write_vtp(path, sim)``.

The step (``run`` pseudocode; the whole loop runs in numba, returning to Python every
``chunk_steps`` steps, or sooner when a factory has a clump due):

    for each step:
        for each active body: kick (forces, torques, rolling torque with its cap), drift
        move the walls that are in their motion window; t += dt
        sphere positions from the bodies; rebuild the sphere-sphere Verlet list if a sphere
            moved beyond its allowance since the last rebuild (at least skin/2: half its gap
            to the nearest sphere not listed with it), the sphere-wall list if a sphere and the
            walls moved beyond its wall allowance together (at least skin); contact history
            carried over; spheres added between steps are admitted without a rebuild when they
            have room (``simulate.neighbours``); the near pairs selected again if a sphere moved
            beyond its near allowance
        contact forces: the near sphere-sphere pairs (those of the list within a margin, the
            only ones that may touch), then sphere-wall pairs (Hertz-Mindlin, rolling)
    (kicks are half steps at the start and end of a chunk and whole steps in between: the
     velocity Verlet scheme of ``simulate.integrate``; Python always sees synchronous
     positions and velocities)
    every chunk: stop with SimulationError on non-finite state or runaway kinetic energy;
        deactivate and record bodies outside the domain; run the factories
    every ``sort_every`` steps (4,096 spheres or more): sort the bodies and spheres in memory
        along a Morton curve, lists and history renumbered (ids and readers keep their order)

Threads. From 8,192 spheres (``simulate.threads``) the kicks, the sphere positions and the
contact forces run on numba's threads, the contacts split into fixed ranges
(``simulate.forces.contact_forces_ranged``), and the list rebuilds' per-sphere passes too: a
run gives the same result on any number of threads. A campaign's worker processes run theirs
on one thread each; a single large run uses every core. The step loop is compiled twice
(``_advance_serial``, ``_advance_ranged``), each with only its own kernels, so a process that
runs small rigs only never compiles the threaded ones.

Engine hooks (off by default, switched by the material table, so that ``MaterialTable.
from_parameters`` carries them from ``DEMParameters``; ``simulate.extensions.ENGINE_HOOKS``):
a pair restitution that depends on the impact speed (``set_pair(restitution_exponent=n,
restitution_v_ref=v)``: the dashpots of a contact use e(v) at its first-touch approach speed,
kept in its history), the spring-dashpot rolling model (``MaterialTable(rolling_model=
"epsd")``, its spring torque kept in the history), and normal dashpots that damp the body's
effective mass at each contact (``MaterialTable(contact_effective_mass=True)``, from the
contacts of each step). The history rows are as wide as the hooks
need, and carried across list rebuilds whole; with every hook off a contact behaves as the
plain Hertz-Mindlin law with constant restitution and constant-torque rolling. Several clump templates per factory (a size distribution) are a
``ParticleFactory`` option.

Stability. ``run`` refuses a time step above ``max_dt_fraction`` (default 0.5) of the Rayleigh
time of the smallest sphere (``UnsafeTimeStepError`` stating T_R, the fraction and the limit)
unless the simulation was made with ``force=True``.
"""

from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass

import numba
import numpy as np

from demcal.errors import InputError, SimulationError
from demcal.simulate._jit import evaluator, kernel, loop_kernel, serial_or_threaded, threaded_kernel
from demcal.simulate.clump import ClumpTemplate
from demcal.simulate.contact.rolling import kick_mode, lever_index
from demcal.simulate.forces import (HIST_IMPACT_SPEED, HIST_ROLLING, PREFETCH_AHEAD, PREFETCH_MIN_SPHERES,
                                    contact_forces, contact_forces_ranged, history_width, odd_history_columns)
from demcal.simulate.integrate import (drift, half_kick, matrices_from_quats, quat_from_matrix,
                                       quat_multiply, refresh_rotation, row_norms)
from demcal.simulate.materials import MaterialTable
from demcal.simulate.neighbours import (admit_spheres, ascending_pairs, build_wall_list, grid_shape, morton_keys,
                                        padded_cell_count, rebuild_pair_list, renumber_pair_list,
                                        renumber_wall_list, select_near_pairs)
from demcal.simulate.threads import THREADS_MIN_SPHERES, threads_per_run
from demcal.simulate.timestep import DEFAULT_MAX_FRACTION, check_time_step, rayleigh_time
from demcal.simulate.walls import WALL_TYPES, pack_walls, wall_distance, wall_distances
from demcal.units import GRAVITY

# ----------------------------------------------------------------------------------------------
# kernels

@evaluator
def _place_sphere(s, b, soff, bx, bR, sx, sx0, sxw, sxn, sallow, swallow, snear, wmove):
    """World position of sphere ``s`` of body ``b``; whether it moved beyond its allowance since
    the last pair-list rebuild (``sx0``, ``sallow``), whether it plus the walls' largest move
    ``wmove`` went beyond its wall allowance (``sxw``, ``swallow``), and whether it moved beyond
    its near-pair allowance (``sxn``, ``snear``; ``simulate.neighbours``)."""
    ox = soff[s, 0]
    oy = soff[s, 1]
    oz = soff[s, 2]
    x = bx[b, 0] + bR[b, 0, 0] * ox + bR[b, 0, 1] * oy + bR[b, 0, 2] * oz
    y = bx[b, 1] + bR[b, 1, 0] * ox + bR[b, 1, 1] * oy + bR[b, 1, 2] * oz
    z = bx[b, 2] + bR[b, 2, 0] * ox + bR[b, 2, 1] * oy + bR[b, 2, 2] * oz
    sx[s, 0] = x
    sx[s, 1] = y
    sx[s, 2] = z
    dx = x - sx0[s, 0]
    dy = y - sx0[s, 1]
    dz = z - sx0[s, 2]
    d2 = dx * dx + dy * dy + dz * dz
    pair_stale = d2 > sallow[s] * sallow[s]
    dx = x - sxw[s, 0]
    dy = y - sxw[s, 1]
    dz = z - sxw[s, 2]
    d2 = dx * dx + dy * dy + dz * dz
    lim = swallow[s] - wmove
    wall_stale = (lim <= 0.0) | (d2 > lim * lim)
    dx = x - sxn[s, 0]
    dy = y - sxn[s, 1]
    dz = z - sxn[s, 2]
    d2 = dx * dx + dy * dy + dz * dz
    return pair_stale, wall_stale, d2 > snear[s] * snear[s]


@loop_kernel
def _update_sphere_rows(s0, s1, sbody, soff, bx, bR, bactive, sx, sx0, sxw, sxn, sallow, swallow, snear, wmove):
    """World positions of spheres ``s0``..``s1 - 1``; returns whether the pair list, the wall
    list and the near pairs are stale (``_place_sphere``)."""
    pairs_stale = False
    walls_stale = False
    near_stale = False
    for s in range(s0, s1):
        b = sbody[s]
        if bactive[b]:
            p, w, n = _place_sphere(s, b, soff, bx, bR, sx, sx0, sxw, sxn, sallow, swallow, snear, wmove)
            pairs_stale |= p
            walls_stale |= w
            near_stale |= n
    return pairs_stale, walls_stale, near_stale


@loop_kernel
def _update_spheres(n_spheres, sbody, soff, bx, bR, bactive, sx, sx0, sxw, sxn, sallow, swallow, snear, wmove):
    """World positions of the spheres; returns whether the pair list, the wall list and the near
    pairs are stale."""
    return _update_sphere_rows(0, n_spheres, sbody, soff, bx, bR, bactive, sx, sx0, sxw, sxn, sallow, swallow,
                               snear, wmove)


#: Blocks of rows the threaded kicks and sphere updates are split into.
N_BLOCKS = 64


@threaded_kernel
def _update_spheres_threaded(n_spheres, sbody, soff, bx, bR, bactive, sx, sx0, sxw, sxn, sallow, swallow, snear,
                             wmove):
    """``_update_spheres`` over threads, a block of rows each."""
    n_pairs_stale = 0
    n_walls_stale = 0
    n_near_stale = 0
    for c in numba.prange(N_BLOCKS):
        p, w, n = _update_sphere_rows(n_spheres * c // N_BLOCKS, n_spheres * (c + 1) // N_BLOCKS, sbody, soff, bx,
                                      bR, bactive, sx, sx0, sxw, sxn, sallow, swallow, snear, wmove)
        n_pairs_stale += p
        n_walls_stale += w
        n_near_stale += n
    return n_pairs_stale > 0, n_walls_stale > 0, n_near_stale > 0


@loop_kernel
def _kick_drift_rows(b0, b1, tau, dt, gx, gy, gz, mode, bactive, bx, bv, bq, bL, bw, bR, bf, bt, brm, brv, brn,
                     binvm, binvi):
    """Kick active bodies ``b0``..``b1 - 1`` over ``tau``, then (``dt`` > 0) drift them over ``dt``."""
    for b in range(b0, b1):
        if bactive[b]:
            half_kick(b, tau, gx, gy, gz, bv, bL, bw, bR, bf, bt, brm, brv, brn, binvm, binvi, mode)
            if dt > 0.0:
                drift(b, dt, bx, bv, bq, bL, bw, bR, binvi)


@loop_kernel
def _kick_drift(n_bodies, tau, dt, gx, gy, gz, mode, bactive, bx, bv, bq, bL, bw, bR, bf, bt, brm, brv, brn,
                binvm, binvi):
    """Kick every active body over ``tau``, then (``dt`` > 0) drift it over ``dt``."""
    _kick_drift_rows(0, n_bodies, tau, dt, gx, gy, gz, mode, bactive, bx, bv, bq, bL, bw, bR, bf, bt, brm, brv, brn,
                     binvm, binvi)


@threaded_kernel
def _kick_drift_threaded(n_bodies, tau, dt, gx, gy, gz, mode, bactive, bx, bv, bq, bL, bw, bR, bf, bt, brm, brv,
                         brn, binvm, binvi):
    """``_kick_drift`` over threads, a block of bodies each."""
    for c in numba.prange(N_BLOCKS):
        _kick_drift_rows(n_bodies * c // N_BLOCKS, n_bodies * (c + 1) // N_BLOCKS, tau, dt, gx, gy, gz, mode,
                         bactive, bx, bv, bq, bL, bw, bR, bf, bt, brm, brv, brn, binvm, binvi)


@loop_kernel
def _wall_contact_velocities(ws, wk, sx, srad, wkind, worig, wnorm, wu, wv, whalf, wvel_now, wspin_now, wcv):
    """Velocity of the wall's surface at each sphere-wall contact into ``wcv``: the wall's
    translation, plus spin x (p - centre) for a spinning wall at the contact point p (the
    middle of the overlap, as the contact force takes it)."""
    for q in range(ws.shape[0]):
        k = wk[q]
        for c in range(3):
            wcv[q, c] = wvel_now[k, c]
        if wspin_now[k, 0] != 0.0 or wspin_now[k, 1] != 0.0 or wspin_now[k, 2] != 0.0:
            i = ws[q]
            d, nx, ny, nz = wall_distance(wkind, worig, wnorm, wu, wv, whalf, k, sx[i, 0], sx[i, 1], sx[i, 2])
            a = srad[i] - 0.5 * (srad[i] - d)
            rx = sx[i, 0] - nx * a - worig[k, 0]
            ry = sx[i, 1] - ny * a - worig[k, 1]
            rz = sx[i, 2] - nz * a - worig[k, 2]
            wcv[q, 0] += wspin_now[k, 1] * rz - wspin_now[k, 2] * ry
            wcv[q, 1] += wspin_now[k, 2] * rx - wspin_now[k, 0] * rz
            wcv[q, 2] += wspin_now[k, 0] * ry - wspin_now[k, 1] * rx


@loop_kernel
def _wall_velocities(t, wvel, wspin, wwin, wvel_now, wspin_now):
    """Velocity and spin of each wall during the step whose midpoint is ``t`` (zero outside its
    window)."""
    for k in range(wvel.shape[0]):
        moving = wwin[k, 0] <= t < wwin[k, 1]
        for a in range(3):
            wvel_now[k, a] = wvel[k, a] if moving else 0.0
            wspin_now[k, a] = wspin[k, a] if moving else 0.0


kick_drift = serial_or_threaded(_kick_drift, _kick_drift_threaded)
update_spheres = serial_or_threaded(_update_spheres, _update_spheres_threaded)
all_contact_forces = serial_or_threaded(contact_forces, contact_forces_ranged)


@kernel
def _aside_buffers(n):
    """Work arrays of ``contact_forces_ranged`` for ``n`` pairs: body, force, torque, rolling
    torque, rolling limit."""
    f = np.empty((n, 3))
    return np.empty(n, np.int64), f, np.empty_like(f), np.empty_like(f), np.empty(n)


@evaluator
def _move(ranged, step, t, dt, mode, settings, bodies, spheres, walls):
    """The first part of a step: kick and drift the bodies (``step`` >= 0; a half kick at step
    0, a whole one after), move the walls, place the spheres. Returns the new time and whether
    the pair list, the wall list and the near pairs are stale."""
    gx, gy, gz = settings[0], settings[1], settings[2]
    n_bodies, bx, bv, bq, bL, bw, bR, bf, bt, brm, brv, brn, binvm, binvi, bmat, bcount, bactive = bodies
    n_spheres, sbody, soff, srad, sx, sx0, sxw, sxn, sallow, swallow, snear = spheres
    wkind, worig, wnorm, wu, wv, whalf, wvel, wspin, wwin, wmat, wx0, wvel_now, wspin_now = walls
    h = 0.5 * dt
    n_walls = wkind.shape[0]
    if step >= 0:
        kick_drift(ranged, n_bodies, h if step == 0 else dt, dt, gx, gy, gz, mode, bactive, bx, bv, bq, bL, bw,
                   bR, bf, bt, brm, brv, brn, binvm, binvi)
        _wall_velocities(t + h, wvel, wspin, wwin, wvel_now, wspin_now)
        for k in range(n_walls):
            for a in range(3):
                worig[k, a] += wvel_now[k, a] * dt
        t += dt
    else:
        _wall_velocities(t + h, wvel, wspin, wwin, wvel_now, wspin_now)
    wmax2 = 0.0
    for k in range(n_walls):
        dw2 = 0.0
        for a in range(3):
            dw2 += (worig[k, a] - wx0[k, a]) ** 2
        wmax2 = max(wmax2, dw2)
    return (t, *update_spheres(ranged, n_spheres, sbody, soff, bx, bR, bactive, sx, sx0, sxw, sxn, sallow, swallow,
                               snear, math.sqrt(wmax2)))


@evaluator
def _contacts(ranged, step, dt, settings, bodies, spheres, lists, walls, table, wcv, aside):
    """The second part of a step: the contact forces from the (fresh) lists."""
    lever_mode, rolling_model, eta_r, effective_mass = settings[4], settings[5], settings[6], settings[7]
    ahead = settings[12]
    n_bodies, bx, bv, bq, bL, bw, bR, bf, bt, brm, brv, brn, binvm, binvi, bmat, bcount, bactive = bodies
    n_spheres, sbody, soff, srad, sx, sx0, sxw, sxn, sallow, swallow, snear = spheres
    pstart, ppi, pj, ph, wstart, ws, wk, wh, near, near_start = lists
    wkind, worig, wnorm, wu, wv, whalf, wvel, wspin, wwin, wmat, wx0, wvel_now, wspin_now = walls
    e_star, g_star, damp, mu_s, mu_r, log_e, e_exp, log_v_ref, v_min = table
    aside_body, aside_f, aside_t, aside_rv, aside_rm = aside
    # the first evaluation of a fresh state must not advance the contact history
    hist_dt = dt if step >= 0 else 0.0
    _wall_contact_velocities(ws, wk, sx, srad, wkind, worig, wnorm, wu, wv, whalf, wvel_now, wspin_now, wcv)
    all_contact_forces(ranged, aside_body, aside_f, aside_t, aside_rm, aside_rv, near, near_start, wstart, hist_dt,
                       dt, lever_mode, rolling_model, eta_r, effective_mass, ahead, n_bodies, n_spheres, bx, bv, bw,
                       bR, bf, bt, brm, brv, brn, binvm, binvi, bmat, bcount, sbody, sx, srad, ppi, pj, ph, ws, wk,
                       wh, wkind, worig, wnorm, wu, wv, whalf, wcv, wmat, e_star, g_star, damp, mu_s, mu_r, log_e,
                       e_exp, log_v_ref, v_min)


@loop_kernel
def _copy_rows(src, dst, n):
    """``dst[:n] = src[:n]`` for rows of 3, as a loop: a slice assignment compiles numba's
    shape-mismatch error and its message formatting into the step loop."""
    for i in range(n):
        for a in range(3):
            dst[i, a] = src[i, a]


@evaluator
def _steps(ranged, step, n_steps, t, dt, mode, resume, rebuild, settings, bodies, spheres, lists, walls, table,
           wcv, aside):
    """Whole steps from ``step`` until ``n_steps``, or until a step finds a list stale (or
    ``rebuild``, the first): it returns then, after that step's first part, with the step, the
    new time and which lists are stale (pairs, walls, near pairs), for the caller to rebuild
    them and go on with ``resume`` (the first part of ``step`` is done and its lists are
    fresh)."""
    while step < n_steps:
        if not resume:
            t, pairs_stale, walls_stale, near_stale = _move(ranged, step, t, dt, mode, settings, bodies, spheres,
                                                            walls)
            if pairs_stale or walls_stale or near_stale or rebuild:
                return step, t, pairs_stale, walls_stale, near_stale
        resume = False
        _contacts(ranged, step, dt, settings, bodies, spheres, lists, walls, table, wcv, aside)
        step += 1
    return step, t, False, False, False


@loop_kernel
def _steps_serial(step, n_steps, t, dt, mode, resume, rebuild, settings, bodies, spheres, lists, walls, table, wcv,
                  aside):
    """``_steps`` on one thread, as a loop kernel: a step hands some sixty arrays to its kernels,
    and counting each of them in and out at every step was most of a step's cost in a rig of
    one particle."""
    return _steps(False, step, n_steps, t, dt, mode, resume, rebuild, settings, bodies, spheres, lists, walls,
                  table, wcv, aside)


@kernel
def _steps_ranged(step, n_steps, t, dt, mode, resume, rebuild, settings, bodies, spheres, lists, walls, table, wcv,
                  aside):
    """``_steps`` with the kicks, the sphere positions and the contact forces on threads."""
    return _steps(True, step, n_steps, t, dt, mode, resume, rebuild, settings, bodies, spheres, lists, walls,
                  table, wcv, aside)


steps_until_stale = serial_or_threaded(_steps_serial, _steps_ranged)


#: Steps a near-pair selection should last at least (under it the margin doubles) and at most
#: (over it the margin halves), and the smallest margin as a fraction of the skin.
NEAR_SHORT, NEAR_LONG, NEAR_MIN_MARGIN = 16, 128, 1.0 / 16.0


@evaluator
def _near_pairs(n_spheres, start, pi, pj, hist, sx, srad, margin, skin, sxn, snear):
    """The near pairs of the list ``start``, ``pi``, ``pj`` (``select_near_pairs``, into new
    arrays as long as the list's): a margin grown to the skin takes every pair."""
    near = np.empty(pi.shape[0], np.int64)
    near_start = np.empty(start.shape[0], np.int64)
    select_near_pairs(n_spheres, start, pi, pj, hist, sx, srad, margin if margin < skin else np.inf, near,
                      near_start, sxn, snear)
    return near, near_start


@kernel
def _advance(ranged, n_steps, t, dt, settings, bodies, spheres, lists, walls, table, grid):
    """Advance the state by ``n_steps`` steps (see the module docstring for the step).

    Between two steps the second half kick of one and the first of the next are one full kick
    (leapfrog); the chunk starts and ends with half kicks, so velocities are synchronous with
    positions whenever Python sees them. Returns the new time, the (possibly rebuilt) Verlet
    lists, the numbers of pair-list and wall-list rebuilds and the near-pair margin to start the
    next call with.

    The contact loops visit only the near pairs of the Verlet list, those whose gap is under a
    margin (``simulate.neighbours.select_near_pairs``), selected again whenever a sphere moved
    beyond its near allowance, the pair list was rebuilt, or a call starts (Python may have
    added, sorted or renumbered spheres between calls). The margin adapts: doubled when a
    selection lasted under ``NEAR_SHORT`` steps, up to the skin, where every listed pair is
    visited (a bed filling or flowing fast); halved when one lasted over ``NEAR_LONG``, down to
    ``NEAR_MIN_MARGIN`` of the skin. It changes only which pairs are visited, not the result.

    ``ranged`` (a constant: ``_advance_serial``, ``_advance_ranged``) runs the kicks, the sphere
    positions and the contact forces on numba's threads (``simulate.forces.contact_forces_ranged``;
    the same result on any number of them). The steps between two rebuilds run in
    ``steps_until_stale``. The other arguments are tuples, in the order ``Simulation._advance``
    packs them.
    """
    (gx, gy, gz, skin, lever_mode, rolling_model, eta_r, effective_mass, need_rebuild, need_forces, pool_size,
     margin, _) = settings
    n_bodies, bx, bv, bq, bL, bw, bR, bf, bt, brm, brv, brn, binvm, binvi, bmat, bcount, bactive = bodies
    n_spheres, sbody, soff, srad, sx, sx0, sxw, sxn, sallow, swallow, snear = spheres
    pstart, ppi, pj, ph, wstart, ws, wk, wh = lists
    wkind, worig, wnorm, wu, wv, whalf, wvel, wspin, wwin, wmat, wx0, wvel_now, wspin_now = walls
    lo, inv_cell, dims, cell_start = grid
    mode = kick_mode(lever_mode, rolling_model)
    wcv = np.empty((max(ws.shape[0], 1), 3))       # wall surface velocity at each wall contact
    # shares of a contact kept aside for a body of another range (ranged forces), a row per pair
    aside = _aside_buffers(ppi.shape[0] if ranged else 0)
    n_rebuilds = 0
    n_wall_rebuilds = 0
    step = -1 if need_forces else 0
    near, near_start = _near_pairs(n_spheres, pstart, ppi, pj, ph, sx, srad, margin, skin, sxn, snear)
    selected_at = step
    # the first part of ``step`` is done and its lists are fresh (a plain bool from the start: a
    # literal False would compile the steps a second time, for that type)
    resume = np.bool_(False)
    while step < n_steps:
        step, t, pairs_stale, walls_stale, near_stale = steps_until_stale(
            ranged, step, n_steps, t, dt, mode, resume, need_rebuild, settings, bodies, spheres,
            (pstart, ppi, pj, ph, wstart, ws, wk, wh, near, near_start), walls, table, wcv, aside)
        if step >= n_steps:
            break
        if need_rebuild or pairs_stale:
            pstart, ppi, pj, ph = rebuild_pair_list(ranged, n_spheres, sx, srad, sbody, bactive, skin, lo,
                                                    inv_cell, dims, cell_start, pstart, pj, ph, sallow,
                                                    pool_size if ranged else 1)
            _copy_rows(sx, sx0, n_spheres)
            n_rebuilds += 1
        if need_rebuild or pairs_stale or near_stale:
            lasted = step - selected_at
            if near_stale and lasted < NEAR_SHORT:
                margin = min(2.0 * margin, skin)
            elif lasted > NEAR_LONG:
                margin = max(0.5 * margin, NEAR_MIN_MARGIN * skin)
            near, near_start = _near_pairs(n_spheres, pstart, ppi, pj, ph, sx, srad, margin, skin, sxn, snear)
            selected_at = step
        if need_rebuild or walls_stale:
            wstart, ws, wk, wh = build_wall_list(n_spheres, sx, srad, sbody, bactive, skin, wkind,
                                                 worig, wnorm, wu, wv, whalf, wstart, wk, wh, swallow)
            _copy_rows(sx, sxw, n_spheres)
            _copy_rows(worig, wx0, worig.shape[0])
            n_wall_rebuilds += 1
        need_rebuild = False
        if wcv.shape[0] < ws.shape[0]:
            wcv = np.empty((2 * ws.shape[0], 3))
        if aside[0].shape[0] < (ppi.shape[0] if ranged else 0):
            aside = _aside_buffers(2 * ppi.shape[0])
        resume = True
    if n_steps > 0:
        kick_drift(ranged, n_bodies, 0.5 * dt, 0.0, gx, gy, gz, mode, bactive, bx, bv, bq, bL, bw, bR, bf, bt, brm,
                   brv, brn, binvm, binvi)
    if step - selected_at > NEAR_LONG:
        margin = max(0.5 * margin, NEAR_MIN_MARGIN * skin)
    return t, pstart, ppi, pj, ph, wstart, ws, wk, wh, n_rebuilds, n_wall_rebuilds, margin


@kernel
def _advance_serial(n_steps, t, dt, settings, bodies, spheres, lists, walls, table, grid):
    """``_advance`` on one thread (only the serial kernels compiled in)."""
    return _advance(False, n_steps, t, dt, settings, bodies, spheres, lists, walls, table, grid)


@kernel
def _advance_ranged(n_steps, t, dt, settings, bodies, spheres, lists, walls, table, grid):
    """``_advance`` with the kicks, sphere positions and contact forces on threads."""
    return _advance(True, n_steps, t, dt, settings, bodies, spheres, lists, walls, table, grid)


# ----------------------------------------------------------------------------------------------
# Python side


@dataclass(frozen=True)
class Escape:
    """A body that left the simulation domain.

    Attributes
    ----------
    body : int
        Body id.
    time : float
        Time at which it was found outside [s].
    position : tuple
        Its centre of mass then [m].
    """

    body: int
    time: float
    position: tuple

    def to_dict(self) -> dict:
        return {"body": self.body, "time": self.time, "position": list(self.position)}


@dataclass(frozen=True)
class RunSummary:
    """What one ``Simulation.run`` call did.

    Attributes
    ----------
    steps : int
        Steps taken.
    start_time, end_time : float
        Simulated time before and after [s].
    wall_time : float
        Elapsed real time of the run [s].
    sphere_steps_per_second : float
        Sum over steps of the active spheres, divided by the wall time [1/s].
    n_rebuilds : int
        Verlet-list rebuilds.
    n_bodies, n_spheres : int
        Active bodies and spheres at the end.
    kinetic_energy : float
        At the end [J].
    escaped : int
        Bodies that left the domain during the run.
    """

    steps: int
    start_time: float
    end_time: float
    wall_time: float
    sphere_steps_per_second: float
    n_rebuilds: int
    n_bodies: int
    n_spheres: int
    kinetic_energy: float
    escaped: int

    def to_dict(self) -> dict:
        return dict(self.__dict__)


_BODY_FIELDS = {  # name: (trailing shape, dtype)
    "bx": ((3,), np.float64), "bv": ((3,), np.float64), "bq": ((4,), np.float64),
    "bL": ((3,), np.float64), "bw": ((3,), np.float64), "bR": ((3, 3), np.float64),
    "bf": ((3,), np.float64), "bt": ((3,), np.float64), "brm": ((), np.float64),
    "brv": ((3,), np.float64), "brn": ((3,), np.float64), "binvm": ((), np.float64), "binvi": ((3,), np.float64),
    "bmat": ((), np.int64), "bcount": ((), np.int64), "bactive": ((), np.bool_), "btemplate": ((), np.int64),
    "bmass": ((), np.float64), "bI": ((3,), np.float64), "bid": ((), np.int64),
}
_SPHERE_FIELDS = {
    "sbody": ((), np.int64), "soff": ((3,), np.float64), "srad": ((), np.float64),
    "sx": ((3,), np.float64), "sx0": ((3,), np.float64), "sxw": ((3,), np.float64),
    "sallow": ((), np.float64), "swallow": ((), np.float64), "sid": ((), np.int64),
    "sxn": ((3,), np.float64), "snear": ((), np.float64),
}


class Simulation:
    """A DEM simulation of rigid sphere clumps (see the module docstring for the API).

    Parameters
    ----------
    materials : MaterialTable
        Materials and pair contact parameters.
    domain_lo, domain_hi : 3-sequence
        Corners of the simulation domain [m]: the neighbour grid covers it and a body whose
        centre of mass leaves it is deactivated and recorded in ``escaped``.
    dt : float
        Time step [s].
    gravity : 3-sequence
        [m/s2]; may be changed between runs (``sim.gravity = ...``, e.g. to tilt a plate).
    rolling_lever : str
        ``"liggghts_reff"`` (default), ``"edem_com"`` or ``"edem_sphere"``
        (``simulate.contact.rolling``), the lever of the constant torque rolling model. The
        rolling model itself (``"constant_torque"`` or ``"epsd"``) and the velocity dependence
        of the restitution come with ``materials`` (``MaterialTable(rolling_model=...)``,
        ``set_pair(..., restitution_exponent=...)``, or ``MaterialTable.from_parameters``).
    skin : float or None
        Verlet skin [m]; default 0.4 of the smallest sphere radius.
    max_dt_fraction : float
        Largest allowed dt / T_R (Rayleigh time), default 0.5.
    force : bool
        Run even if dt exceeds ``max_dt_fraction`` T_R.
    max_speed : float
        A body whose kinetic energy exceeds 1/2 m max_speed^2 [m/s] stops the run with
        ``SimulationError`` (runaway energy). Default 50 m/s, far above anything in the rigs.
    chunk_steps : int
        Steps per return to Python (checks, factories, progress).
    sort_every, sort_min_spheres : int
        Every ``sort_every`` steps (0: never) a simulation of at least ``sort_min_spheres``
        spheres sorts its clumps in memory along a Morton curve (``simulate.neighbours``).
        Below some 4,000 spheres the whole state (about 500 bytes a sphere with its contacts)
        stays in a core's cache and sorting would change only the order of roundoff.
        Body and sphere ids, and every reader, keep the order of addition.
    prefetch_min_spheres : int
        From this many spheres the sphere-sphere loop asks for each pair's second sphere some
        pairs ahead (``simulate.forces.PREFETCH_AHEAD``): faster once the state outgrows the
        caches, no gain while they hold it. The result is the same to the bit either way.
    threads : int or None
        Threads of the step loop. None (default): once the simulation holds
        ``THREADS_MIN_SPHERES`` spheres, its contacts are split into fixed ranges run on
        ``simulate.threads.threads_per_run()`` threads, with the same result on any number of
        them (``simulate.forces``); below, one thread and the plain loop. A number: the ranges
        on that many threads whatever the size.
    """

    def __init__(self, materials: MaterialTable, *, domain_lo, domain_hi, dt: float,
                 gravity=(0.0, 0.0, -GRAVITY), rolling_lever: str = "liggghts_reff", skin: float | None = None,
                 max_dt_fraction: float = DEFAULT_MAX_FRACTION, force: bool = False,
                 max_speed: float = 50.0, chunk_steps: int = 200, sort_every: int = 1000,
                 sort_min_spheres: int = 4096, prefetch_min_spheres: int = PREFETCH_MIN_SPHERES,
                 threads: int | None = None):
        if not isinstance(materials, MaterialTable):
            raise InputError(f"materials must be a MaterialTable, got {type(materials).__name__}")
        self.materials = materials
        self.domain_lo = np.asarray(domain_lo, dtype=float).reshape(3)
        self.domain_hi = np.asarray(domain_hi, dtype=float).reshape(3)
        if not np.all(self.domain_hi > self.domain_lo):
            raise InputError(f"domain_hi {self.domain_hi.tolist()} must exceed domain_lo "
                             f"{self.domain_lo.tolist()} on every axis")
        if not (dt > 0 and math.isfinite(dt)):
            raise InputError(f"time step dt must be a positive number [s], got {dt!r}")
        self.dt = float(dt)
        self.gravity = gravity
        self.rolling_lever = rolling_lever
        self._lever = lever_index(rolling_lever)
        if skin is not None and not skin > 0:
            raise InputError(f"skin must be > 0 [m], got {skin!r}")
        self._skin_option = skin
        self.max_dt_fraction = float(max_dt_fraction)
        self.force = bool(force)
        if not max_speed > 0:
            raise InputError(f"max_speed must be > 0 [m/s], got {max_speed!r}")
        self.max_speed = float(max_speed)
        if int(chunk_steps) < 1:
            raise InputError(f"chunk_steps must be >= 1, got {chunk_steps!r}")
        self.chunk_steps = int(chunk_steps)
        if int(sort_every) < 0 or int(sort_min_spheres) < 0 or int(prefetch_min_spheres) < 0:
            raise InputError(f"sort_every, sort_min_spheres and prefetch_min_spheres must be >= 0, got "
                             f"{sort_every!r}, {sort_min_spheres!r}, {prefetch_min_spheres!r}")
        self.sort_every = int(sort_every)
        self.sort_min_spheres = int(sort_min_spheres)
        self.prefetch_min_spheres = int(prefetch_min_spheres)
        self._steps_since_sort = 0
        self.total_sorts = 0
        if threads is not None and int(threads) < 1:
            raise InputError(f"threads must be >= 1 (or None: chosen by size), got {threads!r}")
        self.threads = None if threads is None else int(threads)

        self.time = 0.0
        self.templates: list[ClumpTemplate] = []
        self._template_quat: list[np.ndarray] = []
        self.walls: list = []
        self.factories: list = []
        self.escaped: list[Escape] = []
        self.n_bodies = 0
        self.n_spheres = 0
        self._materials_checked: set[int] = set()    # body materials whose pairs are all defined
        self._b = {k: np.zeros((0,) + s, d) for k, (s, d) in _BODY_FIELDS.items()}
        self._s = {k: np.zeros((0,) + s, d) for k, (s, d) in _SPHERE_FIELDS.items()}
        # row of each body id and sphere id in the arrays above (the rows move when sorted)
        self._body_row = np.zeros(0, np.int64)
        self._sphere_row = np.zeros(0, np.int64)
        self._pairs = (np.zeros(1, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64),
                       np.zeros((0, 3)))
        self._wpairs = (np.zeros(1, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64),
                        np.zeros((0, 3)))
        self._w = pack_walls([], materials.index)
        self._wx0 = np.zeros((0, 3))
        self._wvel_now = np.zeros((0, 3))
        self._wspin_now = np.zeros((0, 3))
        self._grid = None
        self._need_rebuild = True
        self._need_forces = True
        self._admit_from = 0          # spheres from here on were added since the lists were made
        self._near_fraction = 0.25    # the contact loops' near-pair margin over the skin (see _advance)
        self.total_rebuilds = 0
        self.total_wall_rebuilds = 0

    # ---------------------------------------------------------------- configuration
    @property
    def gravity(self) -> np.ndarray:
        return self._gravity.copy()

    @gravity.setter
    def gravity(self, value):
        g = np.asarray(value, dtype=float).reshape(3)
        if not np.all(np.isfinite(g)):
            raise InputError(f"gravity must be a finite 3-vector [m/s2], got {value!r}")
        self._gravity = g

    @property
    def skin(self) -> float:
        if self._skin_option is not None:
            return float(self._skin_option)
        if self.n_spheres:
            return 0.4 * float(self._s["srad"][:self.n_spheres].min())
        return 0.4 * min((float(t.radii.min()) for t in self.templates), default=0.005)

    @property
    def rolling_model(self) -> str:
        """Rolling resistance model of the contacts (from the material table)."""
        return self.materials.rolling_model

    def add_template(self, template: ClumpTemplate) -> int:
        """Register a clump template; returns its id."""
        if not isinstance(template, ClumpTemplate):
            raise InputError(f"add_template needs a ClumpTemplate, got {type(template).__name__}")
        self.templates.append(template)
        self._template_quat.append(quat_from_matrix(template.principal_axes))
        self._grid = None
        return len(self.templates) - 1

    def add_wall(self, wall) -> int:
        """Add a ``Plane``, ``Rectangle`` or ``Cylinder``; returns its index."""
        if not isinstance(wall, WALL_TYPES):
            raise InputError(f"add_wall needs a Plane, Rectangle or Cylinder, got {type(wall).__name__}")
        self.materials.index(wall.material)
        self.walls.append(wall)
        self._repack_walls()
        return len(self.walls) - 1

    def wall_index(self, name: str) -> int:
        """Index of the wall called ``name``; an unknown name lists the defined ones."""
        for k, w in enumerate(self.walls):
            if w.name == name:
                return k
        raise InputError(f"no wall named {name!r}; walls: {', '.join(w.name for w in self.walls)}")

    def add_walls(self, walls) -> list[int]:
        return [self.add_wall(w) for w in walls]

    def set_wall_motion(self, k: int, velocity, move_start: float = None, move_stop: float = math.inf, *,
                        spin=None):
        """Translate wall ``k`` at ``velocity`` [m/s] (and spin it at ``spin`` [rad/s] about its
        centre, ``simulate.walls``) during [move_start, move_stop) [s] (default: from now on)."""
        if not 0 <= k < len(self.walls):
            raise InputError(f"no wall {k!r}; there are {len(self.walls)}")
        start = self.time if move_start is None else float(move_start)
        if not move_stop >= start:
            raise InputError(f"move_stop ({move_stop!r}) is before move_start ({start!r})")
        self._w["velocity"][k] = np.asarray(velocity, dtype=float).reshape(3)
        if spin is not None:
            self._w["spin"][k] = np.asarray(spin, dtype=float).reshape(3)
        self._w["window"][k] = (start, move_stop)

    def add_factory(self, factory) -> None:
        """Add a ``simulate.factory.ParticleFactory`` (it inserts clumps during ``run``)."""
        self.factories.append(factory)

    def _repack_walls(self):
        old = self._w
        n_old = old["kind"].shape[0]
        self._w = pack_walls(self.walls, self.materials.index)
        # keep the current place and motion of the walls that already existed
        for key in ("origin", "velocity", "spin", "window"):
            self._w[key][:n_old] = old[key][:n_old]
        wx0 = np.zeros((len(self.walls), 3))
        wx0[:n_old] = self._wx0[:n_old]
        wx0[n_old:] = self._w["origin"][n_old:]
        self._wx0 = wx0
        self._wvel_now = np.zeros((len(self.walls), 3))
        self._wspin_now = np.zeros((len(self.walls), 3))
        self._need_rebuild = True
        self._check_pairs_defined()

    def _check_pairs_defined(self):
        mats = self.materials.names
        body_mats = {mats[m] for m in np.unique(self._b["bmat"][:self.n_bodies])}
        wall_mats = {w.material for w in self.walls}
        for a in body_mats:
            for b in body_mats | wall_mats:
                if not self.materials.has_pair(a, b):
                    raise InputError(f"no contact parameters for material pair {a}-{b}; "
                                     f"use MaterialTable.set_pair")

    def _reserve(self, n_bodies: int, n_spheres: int):
        """Grow the body and sphere arrays to hold at least the given counts."""
        for store, rows, need in ((self._b, "_body_row", n_bodies), (self._s, "_sphere_row", n_spheres)):
            have = next(iter(store.values())).shape[0]
            if need > have:
                cap = max(need, 2 * have, 16)
                for k, a in store.items():
                    new = np.zeros((cap,) + a.shape[1:], a.dtype)
                    new[:have] = a
                    store[k] = new
                grown = np.zeros(cap, np.int64)
                grown[:have] = getattr(self, rows)
                setattr(self, rows, grown)

    def reserve(self, n_bodies: int, n_spheres: int | None = None) -> None:
        """Pre-allocate room for ``n_bodies`` clumps (and spheres; default from the templates)."""
        if n_spheres is None:
            per = max((t.n_spheres for t in self.templates), default=1)
            n_spheres = n_bodies * per
        self._reserve(int(n_bodies), int(n_spheres))

    def add_clump(self, template: int, position, orientation=(1.0, 0.0, 0.0, 0.0), *,
                  velocity=(0.0, 0.0, 0.0), angular_velocity=(0.0, 0.0, 0.0),
                  material: str = "particle") -> int:
        """Add a clump of template id ``template``; returns its body id.

        ``position`` is its centre of mass [m]; ``orientation`` a quaternion (w, x, y, z)
        rotating the template frame into the world; ``angular_velocity`` [rad/s] world frame.
        """
        return int(self.add_clumps([template], [position], [orientation], velocities=[velocity],
                                   angular_velocities=[angular_velocity], material=material)[0])

    def add_clumps(self, templates, positions, orientations, *, velocities=(0.0, 0.0, 0.0),
                   angular_velocities=(0.0, 0.0, 0.0), material: str = "particle") -> np.ndarray:
        """Add clumps at once, row by row as ``add_clump`` would add them one at a time (the same
        body ids, sphere rows and bits); returns their body ids.

        ``templates`` (n,), ``positions`` (n, 3), ``orientations`` (n, 4); ``velocities`` and
        ``angular_velocities`` one 3-vector for all or (n, 3). A factory's batch of clumps costs
        one pass of numpy operations instead of one per clump.
        """
        ids = np.asarray(templates).reshape(-1)
        n = ids.size
        if n == 0:
            return np.zeros(0, np.int64)
        if not np.issubdtype(ids.dtype, np.integer):
            raise InputError(f"template ids must be integers, got {ids.tolist()!r}")
        unknown = ids[(ids < 0) | (ids >= len(self.templates))]
        if unknown.size:
            raise InputError(f"unknown template id {int(unknown[0])!r}; {len(self.templates)} defined")
        mat = self.materials.index(material)
        fields = {}
        for name, value, width in (("orientation", orientations, 4), ("position", positions, 3),
                                   ("velocity", velocities, 3), ("angular_velocity", angular_velocities, 3)):
            a = np.asarray(value, dtype=float)
            try:
                a = np.broadcast_to(a, (n, width)) if a.ndim == 1 else a.reshape(n, width)
            except ValueError:
                raise InputError(f"{name} must be {width} numbers per clump ({n} clumps), got shape "
                                 f"{a.shape}") from None
            fields[name] = a
        q_user, pos, vel, omega = (fields[k] for k in ("orientation", "position", "velocity", "angular_velocity"))
        norm = row_norms(q_user)     # to the bits of numpy.linalg.norm of one row
        bad = ~(np.isfinite(norm) & (norm > 0))
        if bad.any():
            raise InputError(f"orientation must be a non-zero quaternion (w, x, y, z), got "
                             f"{q_user[np.argmax(bad)].tolist()}")
        for name in ("position", "velocity", "angular_velocity"):
            finite = np.all(np.isfinite(fields[name]), axis=1)
            if not finite.all():
                raise InputError(f"{name} must be finite, got {fields[name][np.argmin(finite)].tolist()}")
        q_body = quat_multiply((q_user / norm[:, None]).T, np.array([self._template_quat[t] for t in ids]).T).T
        R = matrices_from_quats(q_body)
        spheres = np.array([self.templates[t].n_spheres for t in ids], dtype=np.int64)
        b0, s0 = self.n_bodies, self.n_spheres
        first = s0 + np.concatenate([[0], np.cumsum(spheres)])    # each clump's first sphere row
        s1 = int(first[-1])
        self._reserve(b0 + n, s1)
        B, S = self._b, self._s
        new_bodies, new_spheres = slice(b0, b0 + n), slice(s0, s1)   # they take the last rows
        bodies = np.arange(b0, b0 + n)
        for key, value in (("bx", pos), ("bv", vel), ("bq", q_body), ("bR", R), ("bw", omega), ("bf", 0.0),
                           ("bt", 0.0), ("brv", 0.0), ("brm", 0.0), ("bmat", mat), ("bactive", True),
                           ("btemplate", ids), ("bid", bodies)):
            B[key][new_bodies] = value
        self._body_row[new_bodies] = bodies
        S["sid"][new_spheres] = self._sphere_row[new_spheres] = np.arange(s0, s1)
        S["sbody"][new_spheres] = np.repeat(bodies, spheres)
        for t in np.unique(ids):
            tpl = self.templates[t]
            of = np.flatnonzero(ids == t)
            B["bmass"][b0 + of] = tpl.mass
            B["binvm"][b0 + of] = 1.0 / tpl.mass
            B["bI"][b0 + of] = tpl.principal_moments
            B["binvi"][b0 + of] = 1.0 / tpl.principal_moments
            R_t = R[of]
            inertia_world = R_t @ np.diag(tpl.principal_moments) @ R_t.transpose(0, 2, 1)
            B["bL"][b0 + of] = (inertia_world @ omega[of][:, :, None])[:, :, 0]
            rows = (first[of][:, None] + np.arange(tpl.n_spheres)).reshape(-1)
            S["soff"][rows] = np.tile(tpl.offsets, (of.size, 1))
            S["srad"][rows] = np.tile(tpl.radii, of.size)
            S["sx"][rows] = (pos[of][:, None, :] + tpl.offsets @ R_t.transpose(0, 2, 1)).reshape(-1, 3)
        S["sx0"][new_spheres] = S["sx"][new_spheres]
        S["sxw"][new_spheres] = S["sx"][new_spheres]
        self.n_bodies = b0 + n
        self.n_spheres = s1
        # no rebuild: the next step admits the new spheres into the lists (``_advance``)
        if mat not in self._materials_checked:   # the pairs only grow: a material checked stays so
            self._check_pairs_defined()
            self._materials_checked.add(mat)
        return bodies

    # ---------------------------------------------------------------- stability
    def rayleigh_time(self) -> float:
        """Rayleigh time [s] of the most critical sphere: the smallest T_R over the spheres of
        the clumps present and of the templates the factories will insert (inf if none)."""
        mats = self.materials.names
        t_r = self._template_rayleigh_time()
        srad = self._s["srad"][:self.n_spheres]
        smat = self._b["bmat"][self._s["sbody"][:self.n_spheres]]
        for m in np.unique(smat):
            mat = self.materials.material(mats[m])
            r = float(srad[smat == m].min())
            t_r = min(t_r, rayleigh_time(r, mat.density, mat.shear_modulus, mat.poisson_ratio))
        return t_r

    def _template_rayleigh_time(self) -> float:
        """T_R from every template the factories may insert (before any particle exists)."""
        t_r = math.inf
        for f in self.factories:
            mat = self.materials.material(f.material)
            r = min(float(self.templates[k].radii.min()) for k in f.templates)
            t_r = min(t_r, rayleigh_time(r, mat.density, mat.shear_modulus, mat.poisson_ratio))
        return t_r

    def check_time_step(self) -> float:
        """dt / T_R; raises ``UnsafeTimeStepError`` above ``max_dt_fraction`` unless ``force``."""
        t_r = self.rayleigh_time()
        if not math.isfinite(t_r):
            return 0.0
        return check_time_step(self.dt, t_r, self.max_dt_fraction, self.force)

    # ---------------------------------------------------------------- running
    def _ensure_grid(self):
        rmax = max((float(t.radii.max()) for t in self.templates), default=0.0)
        key = (rmax, self.skin)
        if self._grid is not None and self._grid[0] == key:
            return
        cell_xyz, dims = grid_shape(self.domain_lo, self.domain_hi, 2.0 * rmax + self.skin)
        self._grid = (key, 1.0 / cell_xyz, dims.astype(np.int64),
                      np.zeros(padded_cell_count(dims) + 1, np.int64))
        self._need_rebuild = True

    def run(self, duration: float | None = None, *, n_steps: int | None = None, progress=None) -> RunSummary:
        """Advance by ``duration`` [s] (rounded to whole steps) or by ``n_steps``.

        ``progress(sim)``, if given, is called after every chunk. Raises ``SimulationError`` on
        a non-finite state or runaway kinetic energy, ``UnsafeTimeStepError`` on a time step
        above the allowed fraction of the Rayleigh time.
        """
        if (duration is None) == (n_steps is None):
            raise InputError("give exactly one of duration [s] or n_steps")
        if duration is not None:
            if not (duration >= 0 and math.isfinite(duration)):
                raise InputError(f"duration must be >= 0 [s], got {duration!r}")
            n_steps = int(round(duration / self.dt))
        n_steps = int(n_steps)
        if n_steps < 0:
            raise InputError(f"n_steps must be >= 0, got {n_steps!r}")
        self.check_time_step()
        start_time = self.time
        t0 = _time.perf_counter()
        rebuilds = 0
        sphere_steps = 0.0
        n_escaped0 = len(self.escaped)
        done = 0
        for f in self.factories:
            f.insert_due(self)
        while done < n_steps:
            chunk = min(self.chunk_steps, n_steps - done)
            for f in self.factories:
                chunk = min(chunk, max(1, f.steps_until_next(self)))
            active_spheres = self._active_spheres()
            rebuilds += self._advance(chunk)
            sphere_steps += active_spheres * chunk
            done += chunk
            self._check_state()
            for f in self.factories:
                f.insert_due(self)
            if progress is not None:
                progress(self)
        wall = _time.perf_counter() - t0
        self.total_rebuilds += rebuilds
        return RunSummary(steps=n_steps, start_time=start_time, end_time=self.time, wall_time=wall,
                          sphere_steps_per_second=sphere_steps / wall if wall > 0 else 0.0,
                          n_rebuilds=rebuilds, n_bodies=int(self._b["bactive"][:self.n_bodies].sum()),
                          n_spheres=self._active_spheres(),
                          kinetic_energy=self.kinetic_energy(),
                          escaped=len(self.escaped) - n_escaped0)

    def _active_spheres(self) -> int:
        return int(self._b["bactive"][self._s["sbody"][:self.n_spheres]].sum())

    def evaluate_forces(self) -> None:
        """Recompute the contact forces at the current state without advancing time or the
        contact history (e.g. after editing the state, or to read ``contact_forces()``)."""
        self._need_forces = True
        self._advance(0)

    def _advance(self, n_steps: int) -> int:
        """Run the numba step loop for ``n_steps``; returns the number of pair-list rebuilds."""
        self._ensure_grid()
        _, inv_cell, dims, cell_start = self._grid
        B, S, W = self._b, self._s, self._w
        if self._need_forces:
            refresh_rotation(self.n_bodies, B["bq"], B["bL"], B["bw"], B["bR"], B["binvi"])
        if self._admit_from < self.n_spheres and not self._need_rebuild:
            self._need_rebuild = not admit_spheres(
                self._admit_from, self.n_spheres, S["sx"], S["srad"], S["sbody"], B["bactive"], self.skin,
                S["sx0"], S["sallow"], S["sxw"], S["swallow"], W["kind"], W["origin"], W["normal"],
                W["axis_u"], W["axis_v"], W["half"], self._wx0, self.domain_lo, inv_cell, dims)
        self._admit_from = self.n_spheres
        pt = self.materials.compile()
        width = history_width(pt.velocity_restitution, pt.rolling_model)
        self._ensure_history_width(width)
        if (self.sort_every and self._steps_since_sort >= self.sort_every
                and self.n_spheres >= self.sort_min_spheres):
            self.sort_in_memory()
        self._steps_since_sort += n_steps
        g = self._gravity
        skin = self.skin
        ranged = self.threads is not None or self.n_spheres >= THREADS_MIN_SPHERES
        numba.set_num_threads(self.threads_in_use())   # the list rebuilds too (one thread below the size)
        out = (_advance_ranged if ranged else _advance_serial)(
            n_steps, self.time, self.dt,
            (g[0], g[1], g[2], skin, self._lever, pt.rolling_model, pt.rolling_damping_ratio,
             pt.contact_effective_mass, self._need_rebuild, self._need_forces, numba.config.NUMBA_NUM_THREADS,
             self._near_fraction * skin, PREFETCH_AHEAD if self.n_spheres >= self.prefetch_min_spheres else 0),
            (self.n_bodies, B["bx"], B["bv"], B["bq"], B["bL"], B["bw"], B["bR"], B["bf"], B["bt"], B["brm"],
             B["brv"], B["brn"], B["binvm"], B["binvi"], B["bmat"], B["bcount"], B["bactive"]),
            (self.n_spheres, S["sbody"], S["soff"], S["srad"], S["sx"], S["sx0"], S["sxw"], S["sxn"], S["sallow"],
             S["swallow"], S["snear"]),
            (*self._pairs, *self._wpairs),
            (W["kind"], W["origin"], W["normal"], W["axis_u"], W["axis_v"], W["half"], W["velocity"], W["spin"],
             W["window"], W["material"], self._wx0, self._wvel_now, self._wspin_now),
            (pt.e_star, pt.g_star, pt.damping, pt.mu_s, pt.mu_r, pt.log_e, pt.e_exponent, pt.log_v_ref, pt.v_min),
            (self.domain_lo, inv_cell, dims, cell_start))
        self.time = out[0]
        self._pairs = out[1:5]
        self._wpairs = out[5:9]
        self.total_wall_rebuilds += int(out[10])
        self._near_fraction = float(out[11]) / skin
        self._need_rebuild = False
        self._need_forces = False
        return int(out[9])

    def threads_in_use(self) -> int:
        """Threads the next steps run on (``threads``, or chosen by size: ``simulate.threads``)."""
        # the numba pool has NUMBA_NUM_THREADS threads at most
        if self.threads is not None:
            return min(self.threads, numba.config.NUMBA_NUM_THREADS)
        return threads_per_run() if self.n_spheres >= THREADS_MIN_SPHERES else 1

    def sort_in_memory(self) -> None:
        """Reorder the bodies along a Morton curve of their cells (the left ones last), each
        body's spheres after it, and carry the Verlet lists and their history across; ids and
        physics are unchanged (``simulate.neighbours``)."""
        self._ensure_grid()
        nb, ns = self.n_bodies, self.n_spheres
        B, S = self._b, self._s
        key = morton_keys(B["bx"][:nb], self.domain_lo, 1.0 / self._grid[1])
        key[~B["bactive"][:nb]] = np.iinfo(np.int64).max
        body_order = np.argsort(key, kind="stable")
        new_body = np.empty(nb, np.int64)
        new_body[body_order] = np.arange(nb)
        sphere_order = np.argsort(new_body[S["sbody"][:ns]], kind="stable")
        new_sphere = np.empty(ns, np.int64)
        new_sphere[sphere_order] = np.arange(ns)
        for a in B.values():
            a[:nb] = a[:nb][body_order]
        for a in S.values():
            a[:ns] = a[:ns][sphere_order]
        S["sbody"][:ns] = new_body[S["sbody"][:ns]]
        self._body_row[B["bid"][:nb]] = np.arange(nb)
        self._sphere_row[S["sid"][:ns]] = np.arange(ns)
        hist = self._pairs[3]
        self._pairs = renumber_pair_list(new_sphere, *self._pairs, odd_history_columns(hist.shape[1]))
        self._wpairs = renumber_wall_list(new_sphere, *self._wpairs)
        self._steps_since_sort = 0
        self.total_sorts += 1

    def _ensure_history_width(self, width: int) -> None:
        """Widen the contact history rows (zero-filled) if the hooks in use need more columns;
        a hook switched on mid-run starts from empty slots, which the kernels fill."""
        for name in ("_pairs", "_wpairs"):
            start, a, b, hist = getattr(self, name)
            if hist.shape[1] < width:
                wide = np.zeros((hist.shape[0], width))
                wide[:, :hist.shape[1]] = hist
                setattr(self, name, (start, a, b, wide))

    def _check_state(self):
        n = self.n_bodies
        B = self._b
        act = B["bactive"][:n]
        for key, label in (("bx", "position"), ("bv", "velocity"), ("bL", "angular momentum")):
            bad = ~np.isfinite(B[key][:n]).all(axis=1) & act
            if bad.any():
                b = int(B["bid"][np.flatnonzero(bad)].min())
                raise SimulationError(f"non-finite {label} of body {b} at t = {self.time:.6g} s "
                                      f"(dt = {self.dt:.6g} s); the time step or the contact "
                                      f"stiffness is probably unstable")
        e = self._kinetic_energy_by_row()
        limit = 0.5 * B["bmass"][:n] * self.max_speed ** 2
        bad = (e > limit) & act
        if bad.any():
            rows = np.flatnonzero(bad)
            r = rows[np.argmin(B["bid"][rows])]
            raise SimulationError(f"runaway kinetic energy: body {B['bid'][r]} has {e[r]:.4g} J at t = "
                                  f"{self.time:.6g} s, above 1/2 m v^2 for max_speed = "
                                  f"{self.max_speed:g} m/s")
        x = B["bx"][:n]
        out = act & ((x < self.domain_lo) | (x > self.domain_hi)).any(axis=1)
        rows = np.flatnonzero(out)
        for b in rows[np.argsort(B["bid"][rows])]:
            self.escaped.append(Escape(int(B["bid"][b]), float(self.time), tuple(float(v) for v in x[b])))
            B["bactive"][b] = False
            for key in ("bv", "bL", "bw", "bf", "bt", "brv"):
                B[key][b] = 0.0
            B["brm"][b] = 0.0
            self._need_rebuild = True

    # ---------------------------------------------------------------- reading
    def _by_body(self, key: str) -> np.ndarray:
        """A body field in body-id order (a copy)."""
        return self._b[key][self._body_row[:self.n_bodies]]

    def _by_sphere(self, key: str) -> np.ndarray:
        """A sphere field in sphere-id order (a copy)."""
        return self._s[key][self._sphere_row[:self.n_spheres]]

    def positions(self) -> np.ndarray:
        """Centres of mass [m], (n_bodies, 3)."""
        return self._by_body("bx")

    def velocities(self) -> np.ndarray:
        """Velocities of the centres of mass [m/s], (n_bodies, 3)."""
        return self._by_body("bv")

    def angular_velocities(self) -> np.ndarray:
        """World-frame angular velocities [rad/s], (n_bodies, 3)."""
        return self._by_body("bw")

    def angular_momenta(self) -> np.ndarray:
        """World-frame spin angular momenta about each centre of mass [kg m2/s]."""
        return self._by_body("bL")

    def orientations(self) -> np.ndarray:
        """Unit quaternions (w, x, y, z) rotating each body's template frame into the world."""
        out = np.empty((self.n_bodies, 4))
        conj = np.array([1.0, -1.0, -1.0, -1.0])
        for b, (q, t) in enumerate(zip(self._by_body("bq"), self._by_body("btemplate"))):
            out[b] = quat_multiply(q, self._template_quat[int(t)] * conj)
        return out

    def rotation_matrices(self) -> np.ndarray:
        """Rotation matrices template frame -> world, (n_bodies, 3, 3)."""
        out = np.empty((self.n_bodies, 3, 3))
        for b, (R, t) in enumerate(zip(self._by_body("bR"), self._by_body("btemplate"))):
            out[b] = R @ self.templates[int(t)].principal_axes.T
        return out

    def masses(self) -> np.ndarray:
        """Body masses [kg]."""
        return self._by_body("bmass")

    def active(self) -> np.ndarray:
        """False for bodies that left the domain."""
        return self._by_body("bactive")

    def sphere_positions(self) -> np.ndarray:
        """World centres of every member sphere [m], (n_spheres, 3)."""
        return self._by_sphere("sx")

    def sphere_radii(self) -> np.ndarray:
        return self._by_sphere("srad")

    def sphere_body(self) -> np.ndarray:
        """Body (clump) id of every sphere."""
        return self._b["bid"][self._by_sphere("sbody")]

    def body_kinetic_energy(self) -> np.ndarray:
        """Translational plus rotational kinetic energy of each body [J]."""
        return self._kinetic_energy_by_row()[self._body_row[:self.n_bodies]]

    def _kinetic_energy_by_row(self) -> np.ndarray:
        B = self._b
        n = self.n_bodies
        v = B["bv"][:n]
        return 0.5 * B["bmass"][:n] * np.einsum("ij,ij->i", v, v) + \
            0.5 * np.einsum("ij,ij->i", B["bw"][:n], B["bL"][:n])

    def kinetic_energy(self) -> float:
        """Total kinetic energy of the active bodies [J]."""
        return float(self._kinetic_energy_by_row()[self._b["bactive"][:self.n_bodies]].sum())

    def contact_forces(self) -> tuple[np.ndarray, np.ndarray]:
        """Contact force [N] and torque about the centre of mass [N m] on each body at the last
        step. The torque includes the particle-pair rolling torques of the constant torque model
        with the ``liggghts_reff`` lever (ordinary pair torques, capped per contact); the other
        rolling torques are applied in the integration (see ``rolling_resistance``)."""
        return self._by_body("bf"), self._by_body("bt")

    def rolling_resistance(self) -> tuple[np.ndarray, np.ndarray]:
        """Rolling-friction terms of each body at the last force evaluation.

        Constant torque model: the summed torque magnitude sum(mu_r F_n R_lever) [N m] over the
        contacts that can hold it still (all contacts with the EDEM levers, wall contacts only
        with ``liggghts_reff``), and (``liggghts_reff`` only) the summed wall torque vector
        [N m], both before the cap (particle pairs: see ``contact_forces``). Spring-dashpot model (``epsd``): the summed limit torques
        sum(mu_r F_n R_r) [N m] over all the body's contacts, and the summed spring-dashpot
        torque applied to it [N m] (``simulate.contact.rolling``)."""
        return self._by_body("brm"), self._by_body("brv")

    def wall_origins(self) -> np.ndarray:
        """Current point (plane) or centre (rectangle) of each wall [m]."""
        return self._w["origin"].copy()

    def contact_history(self) -> dict:
        """History of the contacts touching now (copies; rows in Verlet-list order, sphere ids).

        Returns
        -------
        dict
            ``"pairs"``: ``i``, ``j`` (sphere ids, i < j); ``"walls"``: ``sphere``, ``wall``;
            each with ``tangential`` (n, 3) the tangential spring displacement [m],
            ``impact_speed`` (n,) the normal approach speed at first touch [m/s] (NaN unless
            some pair has a velocity-dependent restitution; 0 for a contact not yet advanced
            by a step) and ``rolling_torque`` (n, 3) the spring-dashpot rolling spring torque
            on sphere i [N m] (zeros unless ``rolling_model`` is ``epsd``).
        """
        sx, r = self._s["sx"], self._s["srad"]
        recorded = self.materials.compile().velocity_restitution

        def columns(hist, touching):
            h = hist[touching]
            n = h.shape[0]
            return {"tangential": h[:, 0:3].copy(),
                    "impact_speed": (h[:, HIST_IMPACT_SPEED].copy()
                                     if recorded and h.shape[1] > HIST_IMPACT_SPEED else np.full(n, np.nan)),
                    "rolling_torque": (h[:, HIST_ROLLING:HIST_ROLLING + 3].copy()
                                       if h.shape[1] > HIST_ROLLING else np.zeros((n, 3)))}

        _, pi, pj, ph = self._pairs
        touch = np.zeros(pi.size, bool)
        if pi.size:
            touch = np.linalg.norm(sx[pj] - sx[pi], axis=1) < r[pi] + r[pj]
        sid = self._s["sid"]
        i, j, ph = ascending_pairs(sid[pi[touch]], sid[pj[touch]], ph[touch], odd_history_columns(ph.shape[1]))
        pairs = {"i": i, "j": j, **columns(ph, np.ones(i.size, bool))}
        _, ws, wk, wh = self._wpairs
        wtouch = np.zeros(ws.size, bool)
        if ws.size:
            dist = wall_distances(self._w, sx[ws])
            wtouch = dist[np.arange(ws.size), wk] < r[ws]
        walls = {"sphere": sid[ws[wtouch]], "wall": wk[wtouch].copy(), **columns(wh, wtouch)}
        return {"pairs": pairs, "walls": walls}

    def n_contacts(self) -> tuple[int, int]:
        """Numbers of touching sphere-sphere and sphere-wall pairs now."""
        start, pi, pj, _ = self._pairs
        sx, r = self._s["sx"], self._s["srad"]
        d = np.linalg.norm(sx[pj] - sx[pi], axis=1) if pi.size else np.zeros(0)
        n_pp = int((d < r[pi] + r[pj]).sum()) if pi.size else 0
        _, ws, wk, _ = self._wpairs
        n_pw = 0
        if ws.size:
            dist = wall_distances(self._w, sx[ws])
            n_pw = int((dist[np.arange(ws.size), wk] < r[ws]).sum())
        return n_pp, n_pw
