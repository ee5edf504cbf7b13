"""Neighbour lists: a cell list feeding a Verlet list with a skin, rebuilt on displacement.

Sphere pairs (i < j, different clumps, both active) closer than R_i + R_j + skin, and
sphere-wall pairs closer than R + skin, are listed at a rebuild; the contact loops then visit
only those. The lists stay valid while no sphere has moved more than skin/2 and no sphere plus
wall has moved more than skin together (Verlet 1967; Allen & Tildesley 2017, sec. 5.3), which
the engine checks every step.

Cells are cubes of side at least 2 R_max + skin over the simulation domain; spheres outside it
are counted in the nearest boundary cell, so the lists stay correct (only slower) for strays.
Pairs are found over the 13 forward neighbour cells plus the own cell, then ordered by their
first sphere (compressed rows: ``start[i]:start[i+1]`` holds the partners of sphere i).

Contact history (the tangential displacement of each contact) lives in a row per listed pair and
is carried across rebuilds by looking each new pair up in the old rows.

References
----------
Verlet, L. (1967). Computer "experiments" on classical fluids. Phys. Rev. 159, 98-103.
Allen, M. P., Tildesley, D. J. (2017). Computer Simulation of Liquids, 2nd ed. Oxford.
"""

from __future__ import annotations

import numpy as np

from simulate._jit import kernel
from simulate.walls import wall_distance


def grid_shape(lo, hi, cell_min: float, max_cells: int = 4_000_000):
    """Cell side [m] (>= ``cell_min``) and cell counts per axis covering ``lo``-``hi`` [m]."""
    span = np.asarray(hi, float) - np.asarray(lo, float)
    cell = float(cell_min)
    while True:
        dims = np.maximum(1, np.floor(span / cell).astype(np.int64))
        if int(np.prod(dims)) <= max_cells:
            break
        cell *= 1.25
    # stretch the cells so that they tile the domain exactly
    cell_xyz = span / dims
    return float(cell_xyz.min()), cell_xyz, dims


@kernel
def _cell_of(x, lo, inv_cell, dims, axis):
    c = int((x - lo[axis]) * inv_cell[axis])
    if c < 0:
        return 0
    if c >= dims[axis]:
        return dims[axis] - 1
    return c


@kernel
def _grow_int(a, n):
    b = np.empty(2 * a.shape[0] + 16, a.dtype)
    b[:n] = a[:n]
    return b


@kernel
def build_pair_list(n_spheres, sx, srad, sbody, bactive, skin, lo, inv_cell, dims, cell_start,
                    cell_items, sphere_cell, old_start, old_j, old_hist):
    """Sphere-sphere Verlet list with history carried from the previous list.

    Returns
    -------
    start : int64 (n_spheres + 1,)
        Row pointers.
    pi, pj : int64 (n_pairs,)
        First and second sphere of each pair (pi ascending, pi < pj).
    hist : float64 (n_pairs, 3)
        Tangential displacement carried over (zero for new pairs).
    """
    nx, ny, nz = dims[0], dims[1], dims[2]
    n_cells = nx * ny * nz
    # counting sort of active spheres into cells
    for c in range(n_cells + 1):
        cell_start[c] = 0
    for s in range(n_spheres):
        if bactive[sbody[s]]:
            cx = _cell_of(sx[s, 0], lo, inv_cell, dims, 0)
            cy = _cell_of(sx[s, 1], lo, inv_cell, dims, 1)
            cz = _cell_of(sx[s, 2], lo, inv_cell, dims, 2)
            c = (cz * ny + cy) * nx + cx
            sphere_cell[s] = c
            cell_start[c + 1] += 1
        else:
            sphere_cell[s] = -1
    for c in range(n_cells):
        cell_start[c + 1] += cell_start[c]
    fill = np.empty(n_cells, np.int64)
    fill[:] = cell_start[:n_cells]
    for s in range(n_spheres):
        c = sphere_cell[s]
        if c >= 0:
            cell_items[fill[c]] = s
            fill[c] += 1

    cap = max(2 * old_j.shape[0], 8 * n_spheres + 64)
    ta = np.empty(cap, np.int64)
    tb = np.empty(cap, np.int64)
    n = 0
    for i in range(n_spheres):
        c = sphere_cell[i]
        if c < 0:
            continue
        cx = c % nx
        cy = (c // nx) % ny
        cz = c // (nx * ny)
        bi = sbody[i]
        xi = sx[i, 0]
        yi = sx[i, 1]
        zi = sx[i, 2]
        ri = srad[i]
        # own cell (j > i) and the 13 forward neighbours (all j): each pair once
        for o in range(14):
            if o == 0:
                ox, oy, oz = 0, 0, 0
            else:
                m = o + 13  # offsets 14..26 of the 3x3x3 stencil are the forward half
                ox = m % 3 - 1
                oy = (m // 3) % 3 - 1
                oz = m // 9 - 1
            qx = cx + ox
            qy = cy + oy
            qz = cz + oz
            if qx < 0 or qx >= nx or qy < 0 or qy >= ny or qz < 0 or qz >= nz:
                continue
            q = (qz * ny + qy) * nx + qx
            for p in range(cell_start[q], cell_start[q + 1]):
                j = cell_items[p]
                if o == 0 and j <= i:
                    continue
                if sbody[j] == bi:
                    continue
                dx = sx[j, 0] - xi
                dy = sx[j, 1] - yi
                dz = sx[j, 2] - zi
                cut = ri + srad[j] + skin
                if dx * dx + dy * dy + dz * dz < cut * cut:
                    if n == ta.shape[0]:
                        ta = _grow_int(ta, n)
                        tb = _grow_int(tb, n)
                    if i < j:
                        ta[n] = i
                        tb[n] = j
                    else:
                        ta[n] = j
                        tb[n] = i
                    n += 1

    # order by first sphere (counting sort) into compressed rows
    start = np.zeros(n_spheres + 1, np.int64)
    for k in range(n):
        start[ta[k] + 1] += 1
    for s in range(n_spheres):
        start[s + 1] += start[s]
    pos = start[:n_spheres].copy()
    pi = np.empty(n, np.int64)
    pj = np.empty(n, np.int64)
    for k in range(n):
        a = ta[k]
        pi[pos[a]] = a
        pj[pos[a]] = tb[k]
        pos[a] += 1

    hist = np.zeros((n, 3))
    n_old_rows = old_start.shape[0] - 1
    for k in range(n):
        a = pi[k]
        if a >= n_old_rows:
            continue
        b = pj[k]
        for m in range(old_start[a], old_start[a + 1]):
            if old_j[m] == b:
                hist[k, 0] = old_hist[m, 0]
                hist[k, 1] = old_hist[m, 1]
                hist[k, 2] = old_hist[m, 2]
                break
    return start, pi, pj, hist


@kernel
def build_wall_list(n_spheres, sx, srad, sbody, bactive, skin, kind, origin, normal, axis_u, axis_v,
                    half, old_start, old_wall, old_hist):
    """Sphere-wall Verlet list (rows by sphere) with history carried over.

    Returns ``start`` (n_spheres + 1,), ``ws`` (sphere of each pair), ``wk`` (wall), ``hist``.
    """
    n_walls = kind.shape[0]
    start = np.zeros(n_spheres + 1, np.int64)
    cap = 2 * old_wall.shape[0] + n_spheres + 16
    ts = np.empty(cap, np.int64)
    tk = np.empty(cap, np.int64)
    n = 0
    for s in range(n_spheres):
        if bactive[sbody[s]]:
            for k in range(n_walls):
                d, ux, uy, uz = wall_distance(kind, origin, normal, axis_u, axis_v, half, k,
                                              sx[s, 0], sx[s, 1], sx[s, 2])
                if d < srad[s] + skin:
                    if n == ts.shape[0]:
                        ts = _grow_int(ts, n)
                        tk = _grow_int(tk, n)
                    ts[n] = s
                    tk[n] = k
                    n += 1
        start[s + 1] = n
    ws = ts[:n].copy()
    wk = tk[:n].copy()
    hist = np.zeros((n, 3))
    n_old_rows = old_start.shape[0] - 1
    for m in range(n):
        s = ws[m]
        if s >= n_old_rows:
            continue
        for q in range(old_start[s], old_start[s + 1]):
            if old_wall[q] == wk[m]:
                hist[m, 0] = old_hist[q, 0]
                hist[m, 1] = old_hist[q, 1]
                hist[m, 2] = old_hist[q, 2]
                break
    return start, ws, wk, hist
