"""Neighbour lists: a cell list feeding a Verlet list with a skin, rebuilt on displacement.

Sphere pairs (i < j, different clumps, both active) closer than R_i + R_j + skin, and
sphere-wall pairs closer than R + skin, are listed at a rebuild; the contact loops then visit
only those. The lists stay valid while no sphere has moved more than skin/2 and no sphere plus
wall has moved more than skin together (Verlet 1967; Allen & Tildesley 2017, sec. 5.3), which
the engine checks every step.

Cells are boxes of side at least 2 R_max + skin over the simulation domain; spheres outside it
are counted in the nearest boundary cell, so the lists stay correct (only slower) for strays.
Pairs are found over the 13 forward neighbour cells plus the own cell, then ordered by their
first sphere (compressed rows: ``start[i]:start[i+1]`` holds the partners of sphere i).
Sphere-wall pairs are listed in rows by sphere the same way.

Contact history (the tangential displacement of each contact, and the slots of the optional
engine hooks: impact speed, rolling spring torque; ``simulate.engine``) lives in a row per
listed pair, as many columns as the old list has, and is carried across rebuilds by looking
each new pair up in the old rows.

References
----------
Verlet, L. (1967). Computer "experiments" on classical fluids. Phys. Rev. 159, 98-103.
Allen, M. P., Tildesley, D. J. (2017). Computer Simulation of Liquids, 2nd ed. Oxford.
"""

from __future__ import annotations

import numpy as np

from demcal.simulate._jit import kernel
from demcal.simulate.walls import CYLINDER, PLANE, wall_distance


def grid_shape(lo, hi, cell_min: float, max_cells: int = 4_000_000):
    """Cell sides [m] (each >= ``cell_min``) and cell counts per axis tiling ``lo``-``hi`` [m]."""
    span = np.asarray(hi, float) - np.asarray(lo, float)
    cell = float(cell_min)
    while True:
        dims = np.maximum(1, np.floor(span / cell).astype(np.int64))
        if int(np.prod(dims + 2)) <= max_cells:
            break
        cell *= 1.25
    return span / dims, dims


def padded_cell_count(dims) -> int:
    """Cells of the grid with one layer of empty cells around it (what the kernels index)."""
    return int(np.prod(np.asarray(dims) + 2))


@kernel
def build_pair_list(n_spheres, sx, srad, sbody, bactive, skin, lo, inv_cell, dims, cell_start,
                    old_start, old_j, old_hist):
    """Sphere-sphere Verlet list with history carried from the previous list.

    The grid is padded by one empty cell on every side, so the stencil needs no bounds checks;
    cells are numbered x fastest, so the three cells of a stencil row are one contiguous run of
    the cell-sorted spheres (five runs cover the own cell and the 13 forward neighbours).

    Parameters
    ----------
    cell_start : int64 (padded cells + 1,)
        Work array (overwritten).
    old_start, old_j, old_hist
        The previous list (rows, partners, tangential history).

    Returns
    -------
    start : int64 (n_spheres + 1,)
        Row pointers.
    pi, pj : int64 (n_pairs,)
        First and second sphere of each pair (pi ascending, pi < pj).
    hist : float64 (n_pairs, w)
        Contact history carried over (zero for new pairs), as wide as ``old_hist``.
    """
    nx = dims[0] + 2
    ny = dims[1] + 2
    nz = dims[2] + 2
    n_cells = nx * ny * nz
    scell = np.empty(n_spheres, np.int64)
    # counting sort of the active spheres into cells
    cell_start[:] = 0
    for s in range(n_spheres):
        if bactive[sbody[s]]:
            cx = int((sx[s, 0] - lo[0]) * inv_cell[0])
            cy = int((sx[s, 1] - lo[1]) * inv_cell[1])
            cz = int((sx[s, 2] - lo[2]) * inv_cell[2])
            # strays outside the domain go to the nearest boundary cell
            cx = min(max(cx, 0), dims[0] - 1) + 1
            cy = min(max(cy, 0), dims[1] - 1) + 1
            cz = min(max(cz, 0), dims[2] - 1) + 1
            c = (cz * ny + cy) * nx + cx
            scell[s] = c
            cell_start[c + 1] += 1
        else:
            scell[s] = -1
    for c in range(n_cells):
        cell_start[c + 1] += cell_start[c]
    m = cell_start[n_cells]
    order = np.empty(m, np.int64)
    for s in range(n_spheres):
        c = scell[s]
        if c >= 0:
            order[cell_start[c]] = s
            cell_start[c] += 1  # used as a fill pointer, shifted back below
    for c in range(n_cells, 0, -1):
        cell_start[c] = cell_start[c - 1]
    cell_start[0] = 0
    # cell-ordered copies: the search below reads them contiguously
    xs = np.empty(m)
    ys = np.empty(m)
    zs = np.empty(m)
    rs = np.empty(m)
    bs = np.empty(m, np.int64)
    cs = np.empty(m, np.int64)
    for p in range(m):
        s = order[p]
        xs[p] = sx[s, 0]
        ys[p] = sx[s, 1]
        zs[p] = sx[s, 2]
        rs[p] = srad[s] + 0.5 * skin
        bs[p] = sbody[s]
        cs[p] = scell[s]
    row = np.empty(5, np.int64)  # first cell of each forward stencil row, relative to the own cell
    row[0] = 0
    row[1] = nx - 1
    row[2] = (ny - 1) * nx - 1
    row[3] = ny * nx - 1
    row[4] = (ny + 1) * nx - 1

    # candidates are at most the spheres in the stencil runs; sizing the buffers by that bound
    # keeps them fixed in the loop below (a buffer that may be reallocated there slows it 4x)
    cap = 0
    for p in range(m):
        c = cs[p]
        cap += cell_start[c + 2] - p - 1
        for o in range(1, 5):
            cap += cell_start[c + row[o] + 3] - cell_start[c + row[o]]
    ta = np.empty(cap + 1, np.int64)
    tb = np.empty(cap + 1, np.int64)
    n = 0
    for p in range(m):
        xi = xs[p]
        yi = ys[p]
        zi = zs[p]
        ri = rs[p]
        bi = bs[p]
        c = cs[p]
        for o in range(5):
            if o == 0:
                b0 = p + 1              # rest of the own cell and the cell at +x
                b1 = cell_start[c + 2]
            else:
                q = c + row[o]
                b0 = cell_start[q]
                b1 = cell_start[q + 3]
            for k in range(b0, b1):
                dx = xs[k] - xi
                dy = ys[k] - yi
                dz = zs[k] - zi
                cut = ri + rs[k]
                near = (dx * dx + dy * dy + dz * dz < cut * cut) & (bs[k] != bi)
                ta[n] = p   # written always, kept only if near (no branch)
                tb[n] = k
                n += near

    # back to sphere ids, ordered by first sphere (counting sort) into compressed rows
    start = np.zeros(n_spheres + 1, np.int64)
    for k in range(n):
        a = order[ta[k]]
        b = order[tb[k]]
        if a > b:
            a, b = b, a
        ta[k] = a
        tb[k] = b
        start[a + 1] += 1
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

    width = old_hist.shape[1]
    hist = np.zeros((n, width))
    n_old_rows = old_start.shape[0] - 1
    for k in range(n):
        a = pi[k]
        if a >= n_old_rows:
            continue
        b = pj[k]
        for q in range(old_start[a], old_start[a + 1]):
            if old_j[q] == b:
                for c in range(width):
                    hist[k, c] = old_hist[q, c]
                break
    return start, pi, pj, hist


@kernel
def build_wall_list(n_spheres, sx, srad, sbody, bactive, skin, kind, origin, normal, axis_u, axis_v,
                    half, old_start, old_wall, old_hist):
    """Sphere-wall Verlet list (rows by sphere) with history carried over.

    Returns ``start`` (n_spheres + 1,), ``ws`` (sphere of each pair), ``wk`` (wall), ``hist``
    (as wide as ``old_hist``).
    """
    n_walls = kind.shape[0]
    start = np.zeros(n_spheres + 1, np.int64)
    ts = np.empty(n_spheres * n_walls, np.int64)  # the bound keeps the buffers fixed in the loop
    tk = np.empty(n_spheres * n_walls, np.int64)
    n = 0
    for s in range(n_spheres):
        if bactive[sbody[s]]:
            x = sx[s, 0]
            y = sx[s, 1]
            z = sx[s, 2]
            reach = srad[s] + skin
            for k in range(n_walls):
                # distance to a plane or rectangle's plane bounds the distance to the wall
                # from below (a cylinder has no such plane)
                if kind[k] != CYLINDER:
                    h = ((x - origin[k, 0]) * normal[k, 0] + (y - origin[k, 1]) * normal[k, 1]
                         + (z - origin[k, 2]) * normal[k, 2])
                    if kind[k] != PLANE:
                        h = abs(h)
                    if h >= reach:
                        continue
                d, ux, uy, uz = wall_distance(kind, origin, normal, axis_u, axis_v, half, k, x, y, z)
                if d < reach:
                    ts[n] = s
                    tk[n] = k
                    n += 1
        start[s + 1] = n
    ws = ts[:n].copy()
    wk = tk[:n].copy()
    width = old_hist.shape[1]
    hist = np.zeros((n, width))
    n_old_rows = old_start.shape[0] - 1
    for m in range(n):
        s = ws[m]
        if s >= n_old_rows:
            continue
        for q in range(old_start[s], old_start[s + 1]):
            if old_wall[q] == wk[m]:
                for c in range(width):
                    hist[m, c] = old_hist[q, c]
                break
    return start, ws, wk, hist
