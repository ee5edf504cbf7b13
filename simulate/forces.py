"""Contact forces of the DEM step: the sphere-sphere and sphere-wall loops over the Verlet lists,
on one core (``contact_forces``) or split into fixed ranges run on threads
(``contact_forces_ranged``).

The ranged driver gives each range a block of bodies and the contacts whose first sphere is
theirs; a range writes its own bodies only and keeps aside what it owes the others, added after
in a fixed order. The result is that of the serial loop with the additions in another order,
and the same whatever the number of threads. The lists are in memory order
(``simulate.neighbours``), so a range's contacts lie in a compact region of the bed and few
shares are kept aside.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from demcal.simulate._jit import loop_kernel, prefetch, threaded_kernel
from demcal.simulate.contact.hertz_mindlin import impact_damping, normal_force, tangential_force
from demcal.simulate.contact.rolling import (EPSD, LIGGGHTS_REFF, constant_torque, epsd_torque,
                                             rolling_lever)
from demcal.simulate.integrate import damping_inverse_mass, pair_rolling_scale
from demcal.simulate.walls import wall_distance

#: Columns of a contact's history row: the tangential spring displacement [m] (always), the
#: normal approach speed at first touch [m/s] (velocity-dependent restitution) and the rolling
#: spring torque [N m] (spring-dashpot rolling). The rows are only as wide as the hooks in use
#: need (``history_width``), so the default path carries 3 columns as before.
HIST_TANGENTIAL, HIST_IMPACT_SPEED, HIST_ROLLING = 0, 3, 4


def odd_history_columns(width: int) -> list[int]:
    """History columns that change sign when a pair's two spheres swap roles (the tangential
    spring and the rolling spring torque, both kept for the first sphere)."""
    return [c for c in (*range(HIST_TANGENTIAL, HIST_TANGENTIAL + 3), *range(HIST_ROLLING, HIST_ROLLING + 3))
            if c < width]


def history_width(velocity_restitution: bool, rolling_model: int) -> int:
    """Columns of contact history the engine hooks in use need (3, 4 or 7)."""
    if rolling_model == EPSD:
        return HIST_ROLLING + 3
    return HIST_IMPACT_SPEED + 1 if velocity_restitution else HIST_IMPACT_SPEED


@loop_kernel
def contact_forces(fbody, ff, ft, frm, frv, near, near_start, wstart, hist_dt, dt, lever_mode, rolling_model,
                   eta_r, effective_mass, ahead, n_bodies, n_spheres, bx, bv, bw, bR, bf, bt, brm, brv, brn, binvm,
                   binvi, bmat, bcount, sbody, sx, srad, ppi, pj, ph, ws, wk, wh, wkind, worig, wnorm, wu, wv, whalf,
                   wcv, wmat, e_star, g_star, damp, mu_s, mu_r, log_e, e_exp, log_v_ref, v_min):
    """Contact forces, torques and rolling torques on every body from the Verlet lists (the
    arguments of ``contact_forces_ranged``; its row pointers unused here, and nothing put aside
    in its work arrays, since every body is in the one range).

    The sphere-sphere loop visits the listed pairs ``near`` (``near_start``: their row pointers,
    the last one their number; ``simulate.neighbours.select_near_pairs``), the only ones that
    may touch: the rest of the list ``ppi``, ``pj``, ``ph`` is not read.

    ``ahead``: pairs ahead whose second sphere the sphere-sphere loop asks for (``pair_forces``;
    0: none).

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
    if effective_mass:
        _count_contacts(n_bodies, bcount, sbody, sx, srad, ppi, pj, ws, wk, wkind, worig, wnorm,
                        wu, wv, whalf)
    _zero(0, n_bodies, bf, bt, brm, brv, brn)
    pair_forces(0, near_start[near_start.shape[0] - 1], hist_dt, dt, lever_mode, rolling_model, eta_r,
                effective_mass, ahead, bx, bv, bw, bR, binvm, binvi, bmat, bcount, sbody, sx, srad, near, ppi, pj, ph,
                e_star, g_star, damp, mu_s, mu_r, log_e, e_exp, log_v_ref, v_min, bf, bt, brm, brv, 0, n_bodies,
                fbody, ff, ft, frm, frv)
    wall_forces(0, ws.shape[0], hist_dt, lever_mode, rolling_model, eta_r, effective_mass, bx, bv, bw, bR,
                binvm, binvi, bmat, bcount, sbody, sx, srad, ws, wk, wh, wkind, worig, wnorm, wu, wv, whalf, wcv,
                wmat, e_star, g_star, damp, mu_s, mu_r, log_e, e_exp, log_v_ref, v_min, bf, bt, brm, brv, brn)


#: Ranges the lists are split into by ``contact_forces_ranged``, whatever the number of threads.
N_RANGES = 32

#: Pairs ahead whose second sphere's rows the sphere-sphere loop asks for (``pair_forces``), and
#: the spheres from which the engine has it do so. A list runs by first sphere, so the first
#: sphere's rows come in order, but the second's may lie far off in memory: in a settled bed of
#: 100,000 spheres (about 39 MB of state) three pairs in ten had their spheres 200 or more rows
#: apart, and each cost 1.5 to 2.7 times as much as the others (two runs). Asked for 32 pairs
#: ahead, the loop over that bed took 11.4 ms instead of 13.1 (0.87); over beds of 20,000 and
#: 2,500 spheres, whose state the caches hold, 1.03 and 1.01 times as long
#: (``benchmarks/settled_step.py``, medians of 9 rounds in turn; AMD EPYC, 2 MB of L2 a core,
#: 32 MB of L3, 2026-11-30). Asking for the second body's rows as well made the loop slower.
PREFETCH_AHEAD, PREFETCH_MIN_SPHERES = 32, 50_000


@threaded_kernel
def contact_forces_ranged(fbody, ff, ft, frm, frv, near, near_start, wstart, hist_dt, dt, lever_mode, rolling_model,
                          eta_r, effective_mass, ahead, n_bodies, n_spheres, bx, bv, bw, bR, bf, bt, brm, brv,
                          brn, binvm, binvi, bmat, bcount, sbody, sx, srad, ppi, pj, ph, ws, wk, wh, wkind, worig,
                          wnorm, wu, wv, whalf, wcv, wmat, e_star, g_star, damp, mu_s, mu_r, log_e, e_exp,
                          log_v_ref, v_min):
    """``contact_forces`` on threads: the bodies split into ``N_RANGES`` runs of about equal
    numbers of listed pairs, each run computing the near pairs of its bodies' spheres (the first
    sphere of each pair; the lists are in rows by sphere, ``near_start`` and ``wstart``) and
    summing into its own bodies directly. A pair's share for a body of another run is kept aside in
    ``fbody``, ``ff``, ``ft``, ``frm``, ``frv`` (work arrays, >= the pairs) and added after, run
    by run. No two threads write the same memory, and the order of every sum is fixed by the
    lists alone: the result is the same on any number of threads.
    """
    if effective_mass:
        _count_contacts(n_bodies, bcount, sbody, sx, srad, ppi, pj, ws, wk, wkind, worig, wnorm,
                        wu, wv, whalf)
    # the runs are split by the whole list, so they do not change with the near pairs (nor the
    # order of the sums)
    n_pairs = ppi.shape[0]
    first = np.empty(N_RANGES + 1, np.int64)     # first body of each run
    first[0] = 0
    first[N_RANGES] = n_bodies
    for c in range(1, N_RANGES):
        b = sbody[ppi[n_pairs * c // N_RANGES]] if n_pairs > 0 else n_bodies * c // N_RANGES
        first[c] = min(max(b, first[c - 1]), n_bodies)
    # spheres are stored body after body, so a run's spheres are one block of rows
    rows = np.searchsorted(sbody[:n_spheres], first)
    k = np.empty(N_RANGES + 1, np.int64)
    q = np.empty(N_RANGES + 1, np.int64)
    for c in range(N_RANGES + 1):
        k[c] = near_start[min(rows[c], near_start.shape[0] - 1)]   # spheres added since have no pairs
        q[c] = wstart[min(rows[c], wstart.shape[0] - 1)]
    aside = np.zeros(N_RANGES, np.int64)
    for c in numba.prange(N_RANGES):
        _zero(first[c], first[c + 1], bf, bt, brm, brv, brn)
        aside[c] = pair_forces(k[c], k[c + 1], hist_dt, dt, lever_mode, rolling_model, eta_r, effective_mass,
                               ahead, bx, bv, bw, bR, binvm, binvi, bmat, bcount, sbody, sx, srad, near, ppi, pj, ph,
                               e_star, g_star, damp, mu_s, mu_r, log_e, e_exp, log_v_ref, v_min, bf, bt, brm, brv,
                               first[c], first[c + 1], fbody, ff, ft, frm, frv)
        wall_forces(q[c], q[c + 1], hist_dt, lever_mode, rolling_model, eta_r, effective_mass, bx, bv, bw, bR,
                    binvm, binvi, bmat, bcount, sbody, sx, srad, ws, wk, wh, wkind, worig, wnorm, wu, wv, whalf,
                    wcv, wmat, e_star, g_star, damp, mu_s, mu_r, log_e, e_exp, log_v_ref, v_min, bf, bt, brm, brv,
                    brn)
    for c in range(N_RANGES):
        for e in range(k[c], k[c] + aside[c]):
            b = fbody[e]
            for a in range(3):
                bf[b, a] += ff[e, a]
                bt[b, a] += ft[e, a]
                brv[b, a] += frv[e, a]
            brm[b] += frm[e]


@loop_kernel
def _zero(b0, b1, bf, bt, brm, brv, brn):
    for b in range(b0, b1):
        for a in range(3):
            bf[b, a] = 0.0
            bt[b, a] = 0.0
            brv[b, a] = 0.0
            brn[b, a] = 0.0
        brm[b] = 0.0


@loop_kernel
def pair_forces(k0, k1, hist_dt, dt, lever_mode, rolling_model, eta_r, effective_mass, ahead, bx, bv, bw, bR,
                binvm, binvi, bmat, bcount, sbody, sx, srad, near, ppi, pj, ph, e_star, g_star, damp, mu_s, mu_r,
                log_e, e_exp, log_v_ref, v_min, bf, bt, brm, brv, b_lo, b_hi, fbody, ff, ft, frm, frv):
    """Sphere-sphere contacts ``near[k0]``..``near[k1 - 1]`` of the list, added to the body sums.

    With ``ahead`` > 0 the rows of the second sphere of the pair that many pairs on are asked
    for ahead (``prefetch``; see ``PREFETCH_AHEAD``).

    The second body of a pair outside ``b_lo``..``b_hi - 1`` gets its share in the next row of
    ``fbody``, ``ff``, ``ft``, ``frm``, ``frv`` from row ``k0`` on instead (added later by the
    caller); returns how many such rows were written."""
    pw = ph.shape[1]
    store = hist_dt > 0.0
    n_aside = 0
    for e in range(k0, k1):
        if ahead > 0 and e + ahead < k1:
            later = pj[near[e + ahead]]
            prefetch(sx, later)
            prefetch(srad, later)
            prefetch(sbody, later)
        k = near[e]
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
        # j's share goes to its body, or aside if that is another range's (written out at
        # each site: an array chosen at run time would slow the plain loop by a tenth)
        own_j = b_lo <= bj < b_hi
        aside = k0 + n_aside
        if not own_j:
            n_aside += 1
            fbody[aside] = bj
            for c in range(3):
                ff[aside, c] = 0.0
                ft[aside, c] = 0.0
                frv[aside, c] = 0.0
            frm[aside] = 0.0
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
        if own_j:
            bf[bj, 0] -= fx
            bf[bj, 1] -= fy
            bf[bj, 2] -= fz
        else:
            ff[aside, 0] -= fx
            ff[aside, 1] -= fy
            ff[aside, 2] -= fz
        bt[bi, 0] += aiy * fz - aiz * fy
        bt[bi, 1] += aiz * fx - aix * fz
        bt[bi, 2] += aix * fy - aiy * fx
        if own_j:
            bt[bj, 0] -= ajy * fz - ajz * fy
            bt[bj, 1] -= ajz * fx - ajx * fz
            bt[bj, 2] -= ajx * fy - ajy * fx
        else:
            ft[aside, 0] -= ajy * fz - ajz * fy
            ft[aside, 1] -= ajz * fx - ajx * fz
            ft[aside, 2] -= ajx * fy - ajy * fx
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
                brm[bi] += m_max
                if own_j:
                    brv[bj, 0] -= tx
                    brv[bj, 1] -= ty
                    brv[bj, 2] -= tz
                    brm[bj] += m_max
                else:
                    frv[aside, 0] -= tx
                    frv[aside, 1] -= ty
                    frv[aside, 2] -= tz
                    frm[aside] += m_max
            elif lever_mode == LIGGGHTS_REFF:
                # resists only the rolling relative to the neighbour (a body turning with its
                # neighbours keeps turning): an ordinary pair torque, capped alike for both
                tx, ty, tz, m = constant_torque(mr, f_el, r_star, wrx, wry, wrz, nx, ny, nz)
                s = pair_rolling_scale(bR, binvi, bi, bj, tx, ty, tz, m, wrx, wry, wrz, dt)
                bt[bi, 0] += s * tx
                bt[bi, 1] += s * ty
                bt[bi, 2] += s * tz
                if own_j:
                    bt[bj, 0] -= s * tx
                    bt[bj, 1] -= s * ty
                    bt[bj, 2] -= s * tz
                else:
                    ft[aside, 0] -= s * tx
                    ft[aside, 1] -= s * ty
                    ft[aside, 2] -= s * tz
            else:
                brm[bi] += mr * f_el * rolling_lever(lever_mode, aix, aiy, aiz, a, r_star)
                if own_j:
                    brm[bj] += mr * f_el * rolling_lever(lever_mode, ajx, ajy, ajz, rj - 0.5 * overlap, r_star)
                else:
                    frm[aside] += mr * f_el * rolling_lever(lever_mode, ajx, ajy, ajz, rj - 0.5 * overlap, r_star)
    return n_aside


@loop_kernel
def wall_forces(q0, q1, hist_dt, lever_mode, rolling_model, eta_r, effective_mass, bx, bv, bw, bR, binvm,
                binvi, bmat, bcount, sbody, sx, srad, ws, wk, wh, wkind, worig, wnorm, wu, wv, whalf, wcv,
                wmat, e_star, g_star, damp, mu_s, mu_r, log_e, e_exp, log_v_ref, v_min, bf, bt, brm, brv, brn):
    """Sphere-wall contacts ``q0``..``q1 - 1`` of the list, added to the body sums."""
    ww = wh.shape[1]
    store = hist_dt > 0.0
    for q in range(q0, q1):
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



@loop_kernel
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


