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
chunks of steps; ``reserve(n_bodies)`` pre-allocates for clumps added one by one. Gravity may
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
            have room (``simulate.neighbours``)
        contact forces: sphere-sphere pairs, then sphere-wall pairs (Hertz-Mindlin, rolling)
    (kicks are half steps at the start and end of a chunk and whole steps in between: the
     velocity Verlet scheme of ``simulate.integrate``; Python always sees synchronous
     positions and velocities)
    every chunk: stop with SimulationError on non-finite state or runaway kinetic energy;
        deactivate and record bodies outside the domain; run the factories

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

import numpy as np

from demcal.errors import InputError, SimulationError
from demcal.simulate._jit import kernel
from demcal.simulate.clump import ClumpTemplate
from demcal.simulate.contact.hertz_mindlin import impact_damping, normal_force, tangential_force
from demcal.simulate.contact.rolling import (EPSD, LIGGGHTS_REFF, constant_torque, epsd_torque,
                                             kick_mode, lever_index, rolling_lever)
from demcal.simulate.integrate import (damping_inverse_mass, drift, half_kick, matrix_from_quat,
                                       pair_rolling_scale, quat_from_matrix, quat_multiply,
                                       refresh_rotation)
from demcal.simulate.materials import MaterialTable
from demcal.simulate.neighbours import (admit_spheres, build_pair_list, build_wall_list, grid_shape,
                                        padded_cell_count)
from demcal.simulate.timestep import DEFAULT_MAX_FRACTION, check_time_step, rayleigh_time
from demcal.simulate.walls import WALL_TYPES, pack_walls, wall_distance, wall_distances
from demcal.units import GRAVITY

# ----------------------------------------------------------------------------------------------
# kernels

#: Columns of a contact's history row: the tangential spring displacement [m] (always), the
#: normal approach speed at first touch [m/s] (velocity-dependent restitution) and the rolling
#: spring torque [N m] (spring-dashpot rolling). The rows are only as wide as the hooks in use
#: need (``history_width``), so the default path carries 3 columns as before.
HIST_TANGENTIAL, HIST_IMPACT_SPEED, HIST_ROLLING = 0, 3, 4


def history_width(velocity_restitution: bool, rolling_model: int) -> int:
    """Columns of contact history the engine hooks in use need (3, 4 or 7)."""
    if rolling_model == EPSD:
        return HIST_ROLLING + 3
    return HIST_IMPACT_SPEED + 1 if velocity_restitution else HIST_IMPACT_SPEED


@kernel
def _update_spheres(n_spheres, sbody, soff, bx, bR, bactive, sx, sx0, sxw, sallow, swallow, wmove):
    """World positions of the spheres; returns whether the pair list and the wall list need a
    rebuild: a sphere moved beyond its allowance since the last one (``sx0``, ``sallow``), or a
    sphere plus the walls' largest move ``wmove`` beyond its wall allowance (``sxw``,
    ``swallow``; ``simulate.neighbours``)."""
    pairs_stale = False
    walls_stale = False
    for s in range(n_spheres):
        b = sbody[s]
        if not bactive[b]:
            continue
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
        pairs_stale |= d2 > sallow[s] * sallow[s]
        dx = x - sxw[s, 0]
        dy = y - sxw[s, 1]
        dz = z - sxw[s, 2]
        d2 = dx * dx + dy * dy + dz * dz
        lim = swallow[s] - wmove
        walls_stale |= (lim <= 0.0) | (d2 > lim * lim)
    return pairs_stale, walls_stale


@kernel
def _contact_forces(hist_dt, dt, lever_mode, rolling_model, eta_r, effective_mass, n_bodies, bx, bv, bw, bR,
                    bf, bt, brm, brv, brn, binvm, binvi, bmat, bcount, sbody, sx, srad, ppi, pj, ph,
                    ws, wk, wh, wkind, worig, wnorm, wu, wv, whalf, wcv, wmat,
                    e_star, g_star, damp, mu_s, mu_r, log_e, e_exp, log_v_ref, v_min):
    """Contact forces, torques and rolling torques on every body from the Verlet lists.

    ``hist_dt`` is the time step used to accumulate tangential displacement (0 for a force
    evaluation that must not advance the contact history). A pair with ``e_exp`` != 0 takes
    its dashpots from e(v) at its first-touch approach speed (history column
    ``HIST_IMPACT_SPEED``); ``rolling_model`` ``EPSD`` replaces the constant torque by the
    spring-dashpot torque (history columns ``HIST_ROLLING``..+2, damping ratio ``eta_r``),
    summed into ``brv`` with its limits mu_r F_n R_r in ``brm``. With the constant torque and
    the LIGGGHTS lever a particle pair's rolling torque goes into ``bt`` as an equal and
    opposite pair, capped over the step ``dt`` for both bodies alike; wall contacts sum theirs
    into ``brv``, ``brm`` and ``brn`` (normals weighted by magnitude) for the kick's static stop.

    ``effective_mass`` (the ``contact_effective_mass`` extension) gives the normal dashpot of
    each contact the smaller of the body's mass over its number of touching contacts this step
    (counted into ``bcount``) and the rigid-body effective mass at the contact
    (``damping_inverse_mass``): n simultaneous contacts of one body then damp like one contact
    of n times the stiffness, and one off-centre contact damps the mass it actually moves,
    instead of each damping with the whole mass (Kodam et al. 2010; Stronge 2000, ch. 3).
    """
    pw = ph.shape[1]
    ww = wh.shape[1]
    store = hist_dt > 0.0
    if effective_mass:
        _count_contacts(n_bodies, bcount, sbody, sx, srad, ppi, pj, ws, wk, wkind, worig, wnorm,
                        wu, wv, whalf)
    for b in range(n_bodies):
        bf[b, 0] = 0.0
        bf[b, 1] = 0.0
        bf[b, 2] = 0.0
        bt[b, 0] = 0.0
        bt[b, 1] = 0.0
        bt[b, 2] = 0.0
        brm[b] = 0.0
        brv[b, 0] = 0.0
        brv[b, 1] = 0.0
        brv[b, 2] = 0.0
        brn[b, 0] = 0.0
        brn[b, 1] = 0.0
        brn[b, 2] = 0.0
    # ---- sphere-sphere
    for k in range(ppi.shape[0]):
        i = ppi[k]
        j = pj[k]
        xi = sx[i, 0]
        yi = sx[i, 1]
        zi = sx[i, 2]
        dx = sx[j, 0] - xi
        dy = sx[j, 1] - yi
        dz = sx[j, 2] - zi
        ri = srad[i]
        rj = srad[j]
        rsum = ri + rj
        d2 = dx * dx + dy * dy + dz * dz
        if d2 >= rsum * rsum:
            ph[k, 0] = 0.0
            ph[k, 1] = 0.0
            ph[k, 2] = 0.0
            for c in range(3, pw):
                ph[k, c] = 0.0
            continue
        d = math.sqrt(d2)
        inv = 1.0 / d
        nx = dx * inv
        ny = dy * inv
        nz = dz * inv
        overlap = rsum - d
        a = ri - 0.5 * overlap  # contact point: middle of the overlap, along n from i
        px = xi + nx * a
        py = yi + ny * a
        pz = zi + nz * a
        bi = sbody[i]
        bj = sbody[j]
        aix = px - bx[bi, 0]
        aiy = py - bx[bi, 1]
        aiz = pz - bx[bi, 2]
        ajx = px - bx[bj, 0]
        ajy = py - bx[bj, 1]
        ajz = pz - bx[bj, 2]
        wxi = bw[bi, 0]
        wyi = bw[bi, 1]
        wzi = bw[bi, 2]
        wxj = bw[bj, 0]
        wyj = bw[bj, 1]
        wzj = bw[bj, 2]
        # velocity of i relative to j at the contact point
        vrx = bv[bi, 0] + wyi * aiz - wzi * aiy - (bv[bj, 0] + wyj * ajz - wzj * ajy)
        vry = bv[bi, 1] + wzi * aix - wxi * aiz - (bv[bj, 1] + wzj * ajx - wxj * ajz)
        vrz = bv[bi, 2] + wxi * aiy - wyi * aix - (bv[bj, 2] + wxj * ajy - wyj * ajx)
        vn = vrx * nx + vry * ny + vrz * nz
        vtx = vrx - vn * nx
        vty = vry - vn * ny
        vtz = vrz - vn * nz
        mi = bmat[bi]
        mj = bmat[bj]
        r_star = ri * rj / rsum
        m_star = 1.0 / (binvm[bi] + binvm[bj])
        m_damp = m_star
        if effective_mass:
            m_damp = 1.0 / (damping_inverse_mass(bR, binvi, binvm, bcount, bi, aix, aiy, aiz, nx, ny, nz)
                            + damping_inverse_mass(bR, binvi, binvm, bcount, bj, ajx, ajy, ajz, nx, ny, nz))
        cd = damp[mi, mj]
        if e_exp[mi, mj] != 0.0:
            cd = impact_damping(ph, k, HIST_IMPACT_SPEED, vn, log_e[mi, mj], e_exp[mi, mj],
                                log_v_ref[mi, mj], v_min[mi, mj], store)
        f_n, f_el, sqrt_rd = normal_force(e_star[mi, mj], r_star, m_damp, cd, overlap, vn)
        ftx, fty, ftz = tangential_force(ph, k, nx, ny, nz, vtx, vty, vtz, g_star[mi, mj],
                                         m_star, cd, mu_s[mi, mj], sqrt_rd, f_n, hist_dt)
        fx = ftx - f_n * nx
        fy = fty - f_n * ny
        fz = ftz - f_n * nz
        bf[bi, 0] += fx
        bf[bi, 1] += fy
        bf[bi, 2] += fz
        bf[bj, 0] -= fx
        bf[bj, 1] -= fy
        bf[bj, 2] -= fz
        bt[bi, 0] += aiy * fz - aiz * fy
        bt[bi, 1] += aiz * fx - aix * fz
        bt[bi, 2] += aix * fy - aiy * fx
        bt[bj, 0] -= ajy * fz - ajz * fy
        bt[bj, 1] -= ajz * fx - ajx * fz
        bt[bj, 2] -= ajx * fy - ajy * fx
        mr = mu_r[mi, mj]
        if mr > 0.0:
            wrx = wxi - wxj
            wry = wyi - wyj
            wrz = wzi - wzj
            if rolling_model == EPSD:
                tx, ty, tz, m_max = epsd_torque(mr, f_el, e_star[mi, mj], sqrt_rd, r_star, ri, rj,
                                                binvm[bi], binvm[bj], eta_r, ph, k, HIST_ROLLING,
                                                wrx, wry, wrz, nx, ny, nz, hist_dt)
                brv[bi, 0] += tx
                brv[bi, 1] += ty
                brv[bi, 2] += tz
                brv[bj, 0] -= tx
                brv[bj, 1] -= ty
                brv[bj, 2] -= tz
                brm[bi] += m_max
                brm[bj] += m_max
            elif lever_mode == LIGGGHTS_REFF:
                # resists only the rolling relative to the neighbour (a body turning with its
                # neighbours keeps turning): an ordinary pair torque, capped alike for both
                tx, ty, tz, m = constant_torque(mr, f_el, r_star, wrx, wry, wrz, nx, ny, nz)
                s = pair_rolling_scale(bR, binvi, bi, bj, tx, ty, tz, m, wrx, wry, wrz, dt)
                bt[bi, 0] += s * tx
                bt[bi, 1] += s * ty
                bt[bi, 2] += s * tz
                bt[bj, 0] -= s * tx
                bt[bj, 1] -= s * ty
                bt[bj, 2] -= s * tz
            else:
                brm[bi] += mr * f_el * rolling_lever(lever_mode, aix, aiy, aiz, a, r_star)
                brm[bj] += mr * f_el * rolling_lever(lever_mode, ajx, ajy, ajz, rj - 0.5 * overlap, r_star)
    # ---- sphere-wall
    for q in range(ws.shape[0]):
        i = ws[q]
        k = wk[q]
        xi = sx[i, 0]
        yi = sx[i, 1]
        zi = sx[i, 2]
        ri = srad[i]
        d, nx, ny, nz = wall_distance(wkind, worig, wnorm, wu, wv, whalf, k, xi, yi, zi)
        overlap = ri - d
        if overlap <= 0.0:
            wh[q, 0] = 0.0
            wh[q, 1] = 0.0
            wh[q, 2] = 0.0
            for c in range(3, ww):
                wh[q, c] = 0.0
            continue
        a = ri - 0.5 * overlap
        bi = sbody[i]
        aix = xi - nx * a - bx[bi, 0]
        aiy = yi - ny * a - bx[bi, 1]
        aiz = zi - nz * a - bx[bi, 2]
        wxi = bw[bi, 0]
        wyi = bw[bi, 1]
        wzi = bw[bi, 2]
        # velocity of the sphere relative to the wall's surface at the contact point (``wcv``:
        # the wall's translation, and a spinning wall's spin x (p - centre))
        vrx = bv[bi, 0] + wyi * aiz - wzi * aiy - wcv[q, 0]
        vry = bv[bi, 1] + wzi * aix - wxi * aiz - wcv[q, 1]
        vrz = bv[bi, 2] + wxi * aiy - wyi * aix - wcv[q, 2]
        vn = vrx * nx + vry * ny + vrz * nz
        vtx = vrx - vn * nx
        vty = vry - vn * ny
        vtz = vrz - vn * nz
        mi = bmat[bi]
        mk = wmat[k]
        m_star = 1.0 / binvm[bi]
        m_damp = m_star
        if effective_mass:
            m_damp = 1.0 / damping_inverse_mass(bR, binvi, binvm, bcount, bi, aix, aiy, aiz, nx, ny, nz)
        cd = damp[mi, mk]
        if e_exp[mi, mk] != 0.0:
            cd = impact_damping(wh, q, HIST_IMPACT_SPEED, -vn, log_e[mi, mk], e_exp[mi, mk],
                                log_v_ref[mi, mk], v_min[mi, mk], store)
        f_n, f_el, sqrt_rd = normal_force(e_star[mi, mk], ri, m_damp, cd, overlap, -vn)
        ftx, fty, ftz = tangential_force(wh, q, nx, ny, nz, vtx, vty, vtz, g_star[mi, mk],
                                         m_star, cd, mu_s[mi, mk], sqrt_rd, f_n, hist_dt)
        fx = ftx + f_n * nx
        fy = fty + f_n * ny
        fz = ftz + f_n * nz
        bf[bi, 0] += fx
        bf[bi, 1] += fy
        bf[bi, 2] += fz
        bt[bi, 0] += aiy * fz - aiz * fy
        bt[bi, 1] += aiz * fx - aix * fz
        bt[bi, 2] += aix * fy - aiy * fx
        mr = mu_r[mi, mk]
        if mr > 0.0:
            # a wall neither turns nor moves under the torque: R_r and I_r are the sphere's
            if rolling_model == EPSD:
                tx, ty, tz, m = epsd_torque(mr, f_el, e_star[mi, mk], sqrt_rd, ri, ri, ri, binvm[bi],
                                            0.0, eta_r, wh, q, HIST_ROLLING, wxi, wyi, wzi, nx, ny, nz,
                                            hist_dt)
            elif lever_mode == LIGGGHTS_REFF:
                tx, ty, tz, m = constant_torque(mr, f_el, ri, wxi, wyi, wzi, nx, ny, nz)
            else:
                tx = ty = tz = 0.0
                m = mr * f_el * rolling_lever(lever_mode, aix, aiy, aiz, a, ri)
            brv[bi, 0] += tx
            brv[bi, 1] += ty
            brv[bi, 2] += tz
            brm[bi] += m
            brn[bi, 0] += m * nx
            brn[bi, 1] += m * ny
            brn[bi, 2] += m * nz


@kernel
def _count_contacts(n_bodies, bcount, sbody, sx, srad, ppi, pj, ws, wk, wkind, worig, wnorm, wu, wv,
                    whalf):
    """Number of touching sphere-sphere and sphere-wall contacts of each body, into ``bcount``."""
    for b in range(n_bodies):
        bcount[b] = 0
    for k in range(ppi.shape[0]):
        i = ppi[k]
        j = pj[k]
        rsum = srad[i] + srad[j]
        d2 = 0.0
        for a in range(3):
            d2 += (sx[j, a] - sx[i, a]) ** 2
        if d2 < rsum * rsum:
            bcount[sbody[i]] += 1
            bcount[sbody[j]] += 1
    for q in range(ws.shape[0]):
        i = ws[q]
        d, nx, ny, nz = wall_distance(wkind, worig, wnorm, wu, wv, whalf, wk[q], sx[i, 0], sx[i, 1], sx[i, 2])
        if srad[i] - d > 0.0:
            bcount[sbody[i]] += 1


@kernel
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


@kernel
def _wall_velocities(t, wvel, wspin, wwin, wvel_now, wspin_now):
    """Velocity and spin of each wall during the step whose midpoint is ``t`` (zero outside its
    window)."""
    for k in range(wvel.shape[0]):
        moving = wwin[k, 0] <= t < wwin[k, 1]
        for a in range(3):
            wvel_now[k, a] = wvel[k, a] if moving else 0.0
            wspin_now[k, a] = wspin[k, a] if moving else 0.0


@kernel
def _advance(n_steps, t, dt, gx, gy, gz, skin, lever_mode, rolling_model, eta_r, effective_mass,
             need_rebuild, need_forces,
             n_bodies, bx, bv, bq, bL, bw, bR, bf, bt, brm, brv, brn, binvm, binvi, bmat, bcount, bactive,
             n_spheres, sbody, soff, srad, sx, sx0, sxw, sallow, swallow,
             pstart, ppi, pj, ph, wstart, ws, wk, wh,
             wkind, worig, wnorm, wu, wv, whalf, wvel, wspin, wwin, wmat, wx0, wvel_now, wspin_now,
             e_star, g_star, damp, mu_s, mu_r, log_e, e_exp, log_v_ref, v_min,
             lo, inv_cell, dims, cell_start):
    """Advance the state by ``n_steps`` steps (see the module docstring for the step).

    Between two steps the second half kick of one and the first of the next are one full kick
    (leapfrog); the chunk starts and ends with half kicks, so velocities are synchronous with
    positions whenever Python sees them. Returns the new time, the (possibly rebuilt) Verlet
    lists and the numbers of pair-list and wall-list rebuilds.
    """
    h = 0.5 * dt
    mode = kick_mode(lever_mode, rolling_model)
    n_walls = wkind.shape[0]
    wcv = np.empty((max(ws.shape[0], 1), 3))       # wall surface velocity at each wall contact
    n_rebuilds = 0
    n_wall_rebuilds = 0
    for step in range(-1 if need_forces else 0, n_steps):
        if step >= 0:
            tau = h if step == 0 else dt
            for b in range(n_bodies):
                if bactive[b]:
                    half_kick(b, tau, gx, gy, gz, bv, bL, bw, bR, bf, bt, brm, brv, brn, binvm, binvi,
                              mode)
                    drift(b, dt, bx, bv, bq, bL, bw, bR, binvi)
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
        pairs_stale, walls_stale = _update_spheres(n_spheres, sbody, soff, bx, bR, bactive, sx, sx0, sxw,
                                                   sallow, swallow, math.sqrt(wmax2))
        if need_rebuild or pairs_stale:
            pstart, ppi, pj, ph = build_pair_list(n_spheres, sx, srad, sbody, bactive, skin, lo,
                                                  inv_cell, dims, cell_start, pstart, pj, ph, sallow)
            sx0[:n_spheres] = sx[:n_spheres]
            n_rebuilds += 1
        if need_rebuild or walls_stale:
            wstart, ws, wk, wh = build_wall_list(n_spheres, sx, srad, sbody, bactive, skin, wkind,
                                                 worig, wnorm, wu, wv, whalf, wstart, wk, wh, swallow)
            sxw[:n_spheres] = sx[:n_spheres]
            wx0[:] = worig
            n_wall_rebuilds += 1
        need_rebuild = False
        # the first evaluation of a fresh state must not advance the contact history
        hist_dt = dt if step >= 0 else 0.0
        if wcv.shape[0] < ws.shape[0]:
            wcv = np.empty((2 * ws.shape[0], 3))
        _wall_contact_velocities(ws, wk, sx, srad, wkind, worig, wnorm, wu, wv, whalf, wvel_now, wspin_now, wcv)
        _contact_forces(hist_dt, dt, lever_mode, rolling_model, eta_r, effective_mass, n_bodies, bx, bv, bw,
                        bR, bf, bt, brm, brv, brn, binvm, binvi, bmat, bcount, sbody, sx, srad, ppi, pj,
                        ph, ws, wk, wh, wkind, worig, wnorm, wu, wv, whalf, wcv, wmat,
                        e_star, g_star, damp, mu_s, mu_r, log_e, e_exp, log_v_ref, v_min)
    if n_steps > 0:
        for b in range(n_bodies):
            if bactive[b]:
                half_kick(b, h, gx, gy, gz, bv, bL, bw, bR, bf, bt, brm, brv, brn, binvm, binvi, mode)
    return t, pstart, ppi, pj, ph, wstart, ws, wk, wh, n_rebuilds, n_wall_rebuilds


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
    "bmass": ((), np.float64), "bI": ((3,), np.float64),
}
_SPHERE_FIELDS = {
    "sbody": ((), np.int64), "soff": ((3,), np.float64), "srad": ((), np.float64),
    "sx": ((3,), np.float64), "sx0": ((3,), np.float64), "sxw": ((3,), np.float64),
    "sallow": ((), np.float64), "swallow": ((), np.float64),
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
    """

    def __init__(self, materials: MaterialTable, *, domain_lo, domain_hi, dt: float,
                 gravity=(0.0, 0.0, -GRAVITY), rolling_lever: str = "liggghts_reff", skin: float | None = None,
                 max_dt_fraction: float = DEFAULT_MAX_FRACTION, force: bool = False,
                 max_speed: float = 50.0, chunk_steps: int = 200):
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

        self.time = 0.0
        self.templates: list[ClumpTemplate] = []
        self._template_quat: list[np.ndarray] = []
        self.walls: list = []
        self.factories: list = []
        self.escaped: list[Escape] = []
        self.n_bodies = 0
        self.n_spheres = 0
        self._b = {k: np.zeros((0,) + s, d) for k, (s, d) in _BODY_FIELDS.items()}
        self._s = {k: np.zeros((0,) + s, d) for k, (s, d) in _SPHERE_FIELDS.items()}
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
        for store, need in ((self._b, n_bodies), (self._s, n_spheres)):
            have = next(iter(store.values())).shape[0]
            if need > have:
                cap = max(need, 2 * have, 16)
                for k, a in store.items():
                    new = np.zeros((cap,) + a.shape[1:], a.dtype)
                    new[:have] = a
                    store[k] = new

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
        if not 0 <= int(template) < len(self.templates):
            raise InputError(f"unknown template id {template!r}; {len(self.templates)} defined")
        tpl = self.templates[int(template)]
        mat = self.materials.index(material)
        q_user = np.asarray(orientation, dtype=float).reshape(4)
        norm = np.linalg.norm(q_user)
        if not (np.isfinite(norm) and norm > 0):
            raise InputError(f"orientation must be a non-zero quaternion (w, x, y, z), got {orientation!r}")
        pos = np.asarray(position, dtype=float).reshape(3)
        vel = np.asarray(velocity, dtype=float).reshape(3)
        omega = np.asarray(angular_velocity, dtype=float).reshape(3)
        for name, v in (("position", pos), ("velocity", vel), ("angular_velocity", omega)):
            if not np.all(np.isfinite(v)):
                raise InputError(f"{name} must be finite, got {v.tolist()}")
        q_body = quat_multiply(q_user / norm, self._template_quat[int(template)])
        R = matrix_from_quat(q_body)
        b = self.n_bodies
        s0 = self.n_spheres
        ns = tpl.n_spheres
        self._reserve(b + 1, s0 + ns)
        B, S = self._b, self._s
        B["bx"][b] = pos
        B["bv"][b] = vel
        B["bq"][b] = q_body
        B["bR"][b] = R
        inertia_world = R @ np.diag(tpl.principal_moments) @ R.T
        B["bL"][b] = inertia_world @ omega
        B["bw"][b] = omega
        for key in ("bf", "bt", "brv"):
            B[key][b] = 0.0
        B["brm"][b] = 0.0
        B["bmass"][b] = tpl.mass
        B["binvm"][b] = 1.0 / tpl.mass
        B["bI"][b] = tpl.principal_moments
        B["binvi"][b] = 1.0 / tpl.principal_moments
        B["bmat"][b] = mat
        B["bactive"][b] = True
        B["btemplate"][b] = int(template)
        S["sbody"][s0:s0 + ns] = b
        S["soff"][s0:s0 + ns] = tpl.offsets
        S["srad"][s0:s0 + ns] = tpl.radii
        S["sx"][s0:s0 + ns] = pos + tpl.offsets @ R.T
        S["sx0"][s0:s0 + ns] = S["sx"][s0:s0 + ns]
        S["sxw"][s0:s0 + ns] = S["sx"][s0:s0 + ns]
        self.n_bodies = b + 1
        self.n_spheres = s0 + ns
        # no rebuild: the next step admits the new spheres into the lists (``_advance``)
        self._check_pairs_defined()
        return b

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
                W["axis_u"], W["axis_v"], W["half"], self._wx0)
        self._admit_from = self.n_spheres
        pt = self.materials.compile()
        width = history_width(pt.velocity_restitution, pt.rolling_model)
        self._ensure_history_width(width)
        g = self._gravity
        out = _advance(
            n_steps, self.time, self.dt, g[0], g[1], g[2], self.skin, self._lever,
            pt.rolling_model, pt.rolling_damping_ratio, pt.contact_effective_mass, self._need_rebuild,
            self._need_forces,
            self.n_bodies, B["bx"], B["bv"], B["bq"], B["bL"], B["bw"], B["bR"], B["bf"], B["bt"],
            B["brm"], B["brv"], B["brn"], B["binvm"], B["binvi"], B["bmat"], B["bcount"], B["bactive"],
            self.n_spheres, S["sbody"], S["soff"], S["srad"], S["sx"], S["sx0"], S["sxw"], S["sallow"],
            S["swallow"], *self._pairs, *self._wpairs,
            W["kind"], W["origin"], W["normal"], W["axis_u"], W["axis_v"], W["half"], W["velocity"],
            W["spin"], W["window"], W["material"], self._wx0, self._wvel_now, self._wspin_now,
            pt.e_star, pt.g_star, pt.damping, pt.mu_s, pt.mu_r, pt.log_e, pt.e_exponent, pt.log_v_ref,
            pt.v_min, self.domain_lo, inv_cell, dims, cell_start)
        self.time = out[0]
        self._pairs = out[1:5]
        self._wpairs = out[5:9]
        self.total_wall_rebuilds += int(out[10])
        self._need_rebuild = False
        self._need_forces = False
        return int(out[9])

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
                b = int(np.flatnonzero(bad)[0])
                raise SimulationError(f"non-finite {label} of body {b} at t = {self.time:.6g} s "
                                      f"(dt = {self.dt:.6g} s); the time step or the contact "
                                      f"stiffness is probably unstable")
        e = self.body_kinetic_energy()
        limit = 0.5 * B["bmass"][:n] * self.max_speed ** 2
        bad = (e > limit) & act
        if bad.any():
            b = int(np.flatnonzero(bad)[0])
            raise SimulationError(f"runaway kinetic energy: body {b} has {e[b]:.4g} J at t = "
                                  f"{self.time:.6g} s, above 1/2 m v^2 for max_speed = "
                                  f"{self.max_speed:g} m/s")
        x = B["bx"][:n]
        out = act & ((x < self.domain_lo) | (x > self.domain_hi)).any(axis=1)
        for b in np.flatnonzero(out):
            self.escaped.append(Escape(int(b), float(self.time), tuple(float(v) for v in x[b])))
            B["bactive"][b] = False
            for key in ("bv", "bL", "bw", "bf", "bt", "brv"):
                B[key][b] = 0.0
            B["brm"][b] = 0.0
            self._need_rebuild = True

    # ---------------------------------------------------------------- reading
    def positions(self) -> np.ndarray:
        """Centres of mass [m], (n_bodies, 3)."""
        return self._b["bx"][:self.n_bodies].copy()

    def velocities(self) -> np.ndarray:
        """Velocities of the centres of mass [m/s], (n_bodies, 3)."""
        return self._b["bv"][:self.n_bodies].copy()

    def angular_velocities(self) -> np.ndarray:
        """World-frame angular velocities [rad/s], (n_bodies, 3)."""
        return self._b["bw"][:self.n_bodies].copy()

    def angular_momenta(self) -> np.ndarray:
        """World-frame spin angular momenta about each centre of mass [kg m2/s]."""
        return self._b["bL"][:self.n_bodies].copy()

    def orientations(self) -> np.ndarray:
        """Unit quaternions (w, x, y, z) rotating each body's template frame into the world."""
        out = np.empty((self.n_bodies, 4))
        for b in range(self.n_bodies):
            qt = self._template_quat[int(self._b["btemplate"][b])]
            conj = qt * np.array([1.0, -1.0, -1.0, -1.0])
            out[b] = quat_multiply(self._b["bq"][b], conj)
        return out

    def rotation_matrices(self) -> np.ndarray:
        """Rotation matrices template frame -> world, (n_bodies, 3, 3)."""
        out = np.empty((self.n_bodies, 3, 3))
        for b in range(self.n_bodies):
            V = self.templates[int(self._b["btemplate"][b])].principal_axes
            out[b] = self._b["bR"][b] @ V.T
        return out

    def masses(self) -> np.ndarray:
        """Body masses [kg]."""
        return self._b["bmass"][:self.n_bodies].copy()

    def active(self) -> np.ndarray:
        """False for bodies that left the domain."""
        return self._b["bactive"][:self.n_bodies].copy()

    def sphere_positions(self) -> np.ndarray:
        """World centres of every member sphere [m], (n_spheres, 3)."""
        return self._s["sx"][:self.n_spheres].copy()

    def sphere_radii(self) -> np.ndarray:
        return self._s["srad"][:self.n_spheres].copy()

    def sphere_body(self) -> np.ndarray:
        """Body (clump) id of every sphere."""
        return self._s["sbody"][:self.n_spheres].copy()

    def body_kinetic_energy(self) -> np.ndarray:
        """Translational plus rotational kinetic energy of each body [J]."""
        B = self._b
        n = self.n_bodies
        v = B["bv"][:n]
        return 0.5 * B["bmass"][:n] * np.einsum("ij,ij->i", v, v) + \
            0.5 * np.einsum("ij,ij->i", B["bw"][:n], B["bL"][:n])

    def kinetic_energy(self) -> float:
        """Total kinetic energy of the active bodies [J]."""
        return float(self.body_kinetic_energy()[self._b["bactive"][:self.n_bodies]].sum())

    def contact_forces(self) -> tuple[np.ndarray, np.ndarray]:
        """Contact force [N] and torque about the centre of mass [N m] on each body at the last
        step. The torque includes the particle-pair rolling torques of the constant torque model
        with the ``liggghts_reff`` lever (ordinary pair torques, capped per contact); the other
        rolling torques are applied in the integration (see ``rolling_resistance``)."""
        return self._b["bf"][:self.n_bodies].copy(), self._b["bt"][:self.n_bodies].copy()

    def rolling_resistance(self) -> tuple[np.ndarray, np.ndarray]:
        """Rolling-friction terms of each body at the last force evaluation.

        Constant torque model: the summed torque magnitude sum(mu_r F_n R_lever) [N m] over the
        contacts that can hold it still (all contacts with the EDEM levers, wall contacts only
        with ``liggghts_reff``), and (``liggghts_reff`` only) the summed wall torque vector
        [N m], both before the cap (particle pairs: see ``contact_forces``). Spring-dashpot model (``epsd``): the summed limit torques
        sum(mu_r F_n R_r) [N m] over all the body's contacts, and the summed spring-dashpot
        torque applied to it [N m] (``simulate.contact.rolling``)."""
        return self._b["brm"][:self.n_bodies].copy(), self._b["brv"][:self.n_bodies].copy()

    def wall_origins(self) -> np.ndarray:
        """Current point (plane) or centre (rectangle) of each wall [m]."""
        return self._w["origin"].copy()

    def contact_history(self) -> dict:
        """History of the contacts touching now (copies; rows in Verlet-list order).

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
        pairs = {"i": pi[touch].copy(), "j": pj[touch].copy(), **columns(ph, touch)}
        _, ws, wk, wh = self._wpairs
        wtouch = np.zeros(ws.size, bool)
        if ws.size:
            dist = wall_distances(self._w, sx[ws])
            wtouch = dist[np.arange(ws.size), wk] < r[ws]
        walls = {"sphere": ws[wtouch].copy(), "wall": wk[wtouch].copy(), **columns(wh, wtouch)}
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
