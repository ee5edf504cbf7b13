"""Neighbour lists: a cell list feeding a Verlet list with a skin, rebuilt on displacement.

Sphere pairs (i < j, different clumps, both active) closer than R_i + R_j + skin, and
sphere-wall pairs closer than R + skin, are listed at a rebuild; the contact loops then visit
only those. The lists stay valid while no sphere has moved more than skin/2 and no sphere plus
wall has moved more than skin together (Verlet 1967; Allen & Tildesley 2017, sec. 5.3), which
the engine checks every step.

Each sphere has its own allowance, at least that much. A rebuild records the gap g_i from
sphere i to the nearest sphere *not* listed with it (its own clump aside; beyond the 27 cells
around it, the distance to their faces bounds it), and the list stays valid while each sphere
has moved less than g_i / 2: a pair not listed closes by at most g_i / 2 + g_j / 2 <= g_ij. A
sphere falling through empty space, far from everything, may so fall a cell or more between
rebuilds instead of skin / 2. Its wall allowance is likewise the gap to the nearest wall not
listed with it (sphere move plus wall move below it). A sphere added between rebuilds is
admitted into the lists without a rebuild (``admit_spheres``) when its allowances, measured
from the other spheres' reference positions less their own allowances, are at least skin / 2.

Near pairs. In a bed most listed pairs are apart (in the paper's carton at rest about one in seven
of them touches). The contact loops visit only the pairs whose gap was under a margin, smaller than
the skin, when they were selected (``select_near_pairs``), and the selection is made again
once a sphere has moved just under half the gap of its nearest pair left out: the same
displacement bound as the list's, one level down. The forces are those of a loop over the
whole list to the bit.

Cells are boxes of side at least 2 R_max + skin over the simulation domain; spheres outside it
are counted in the nearest boundary cell, so the lists stay correct (only slower) for strays.
Pairs are found over the 13 forward neighbour cells plus the own cell, then ordered by their
first sphere (compressed rows: ``start[i]:start[i+1]`` holds the partners of sphere i).
Sphere-wall pairs are listed in rows by sphere the same way.

Contact history (the tangential displacement of each contact, and the slots of the optional
engine hooks: impact speed, rolling spring torque; ``simulate.engine``) lives in a row per
listed pair, as many columns as the old list has, and is carried across rebuilds by looking
each new pair up in the old rows.

Memory order. The engine stores spheres clump by clump, clumps periodically sorted along a
Morton (Z-order) curve of the grid cells (``morton_keys``), so that spheres near in space are
near in memory and the contact loops keep hitting the cache as a bed grows to 10^5 spheres
(the ``atom_modify sort`` of LAMMPS; Morton 1966). ``renumber_pair_list`` and
``renumber_wall_list`` carry the lists and their history across such a renumbering.

References
----------
Verlet, L. (1967). Computer "experiments" on classical fluids. Phys. Rev. 159, 98-103.
Morton, G. M. (1966). A computer oriented geodetic data base and a new technique in file
sequencing. IBM Technical Report, Ottawa.
Allen, M. P., Tildesley, D. J. (2017). Computer Simulation of Liquids, 2nd ed. Oxford.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from demcal.simulate._jit import evaluator, kernel, loop_kernel, serial_or_threaded, serial_twin, threaded_kernel
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


@threaded_kernel
def build_pair_list(n_spheres, sx, srad, sbody, bactive, skin, lo, inv_cell, dims, cell_start,
                    old_start, old_j, old_hist, allow, pool_size):
    """Sphere-sphere Verlet list with history carried from the previous list, and each
    sphere's displacement allowance into ``allow`` (half its gap to the nearest sphere not
    listed with it; see the module docstring).

    The grid is padded by one empty cell on every side, so the stencil needs no bounds checks;
    cells are numbered x fastest, so the three cells of a stencil row are one contiguous run of
    the cell-sorted spheres (five runs cover the own cell and the 13 forward neighbours).

    The per-sphere passes run on numba's threads; each sphere's pairs go to slots of their own
    and are then joined into rows by blocks of spheres, each block's pairs placed after those of
    the blocks before it, as one pass in order would place them; the gaps are minima (exact in
    any order). So the lists and allowances are the same on any number of threads.

    Parameters
    ----------
    cell_start : int64 (padded cells + 1,)
        Work array (overwritten).
    old_start, old_j, old_hist
        The previous list (rows, partners, tangential history).
    allow : float64 (>= n_spheres,)
        Filled with each active sphere's allowance [m] (at least skin / 2).
    pool_size : int
        Threads in numba's pool (``numba.config.NUMBA_NUM_THREADS``): a bound on thread ids, and
        the blocks of the joining (at most ``JOIN_BLOCKS_MAX``).

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
    # the largest radius of the spheres present, for the bound beyond a sphere's 27 cells
    rmax = 0.0
    for s in range(n_spheres):
        if bactive[sbody[s]]:
            rmax = max(rmax, srad[s])
    # each active sphere's cell and its gap bound from the faces of its 27 cells (any sphere
    # beyond them is at least that far), skin for a stray
    far = np.empty(n_spheres)   # the same bound from the faces of the 125 cells around it
    for s in numba.prange(n_spheres):
        if bactive[sbody[s]]:
            face = np.inf
            face5 = np.inf
            stray = False
            c = 0
            for a in range(2, -1, -1):
                u = (sx[s, a] - lo[a]) * inv_cell[a]
                k = int(u)
                if u < 0.0 or k > dims[a] - 1:
                    stray = True    # strays go to the nearest boundary cell
                k = min(max(k, 0), dims[a] - 1)
                face = min(face, (u - (k - 1)) / inv_cell[a], (k + 2 - u) / inv_cell[a])
                face5 = min(face5, (u - (k - 2)) / inv_cell[a], (k + 3 - u) / inv_cell[a])
                c = c * (dims[a] + 2) + k + 1
            allow[s] = skin if stray else face - srad[s] - rmax
            far[s] = skin if stray else face5 - srad[s] - rmax
            scell[s] = c
        else:
            scell[s] = -1
    # counting sort into cells
    cell_start[:] = 0
    for s in range(n_spheres):
        if scell[s] >= 0:
            cell_start[scell[s] + 1] += 1
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
    gap = np.empty(m)   # gap to the nearest sphere not listed, less skin (cell order)
    for p in numba.prange(m):
        s = order[p]
        xs[p] = sx[s, 0]
        ys[p] = sx[s, 1]
        zs[p] = sx[s, 2]
        rs[p] = srad[s] + 0.5 * skin
        bs[p] = sbody[s]
        cs[p] = scell[s]
        gap[p] = allow[s] - skin
    # a sphere with no other sphere in the shell of cells just beyond its 27 has the bound of
    # the 125 (a sphere falling through empty space); counted by rows of contiguous cells, once
    # per occupied cell (at its first sphere), unless the shell may hold the sphere's own clump
    shell = np.empty(m, np.int8)
    for p in numba.prange(m):
        if p == cell_start[cs[p]]:
            shell[p] = _shell_of_cell(cs[p], cell_start, nx, ny, nz)
    for p in numba.prange(m):
        held = shell[cell_start[cs[p]]]
        if held == SHELL_CLEAR or (held == SHELL_OWN_CLUMP_ONLY
                                   and _shell_holds_own_clump_only(p, cs, bs, cell_start, nx, ny, nz)):
            gap[p] = far[order[p]] - skin
    row = np.empty(5, np.int64)  # first cell of each forward stencil row, relative to the own cell
    row[0] = 0
    row[1] = nx - 1
    row[2] = (ny - 1) * nx - 1
    row[3] = ny * nx - 1
    row[4] = (ny + 1) * nx - 1

    # each sphere's candidates are at most the spheres in its stencil runs: a slot of that size
    # each keeps the buffer fixed in the loop below (a buffer reallocated there slows it 4x)
    slot = np.empty(m + 1, np.int64)
    slot[0] = 0
    for p in range(m):
        c = cs[p]
        n_c = cell_start[c + 2] - p - 1
        for o in range(1, 5):
            n_c += cell_start[c + row[o] + 3] - cell_start[c + row[o]]
        slot[p + 1] = slot[p] + n_c
    tb = np.empty(slot[m] + 1, np.int64)
    found = np.empty(m, np.int64)
    # each thread lowers the gaps in a copy of its own, joined by their minimum
    gaps = np.empty((pool_size, m))
    for p in numba.prange(m):   # not a slice assignment: its shape check compiles a formatted message
        for t in range(gaps.shape[0]):
            gaps[t, p] = gap[p]
    for p in numba.prange(m):
        g = gaps[numba.get_thread_id()]
        xi = xs[p]
        yi = ys[p]
        zi = zs[p]
        ri = rs[p]
        bi = bs[p]
        c = cs[p]
        n = slot[p]
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
                d2 = dx * dx + dy * dy + dz * dz
                other = bs[k] != bi
                near = (d2 < cut * cut) & other
                tb[n] = k   # written always, kept only if near (no branch)
                n += near
                if other and not near:
                    # a root only where it may lower either sphere's gap
                    reach = cut + max(g[p], g[k])
                    if d2 < reach * reach:
                        d = math.sqrt(d2) - cut
                        g[p] = min(g[p], d)
                        g[k] = min(g[k], d)
        found[p] = n - slot[p]
    for p in numba.prange(m):
        least = gaps[0, p]
        for t in range(1, gaps.shape[0]):
            least = min(least, gaps[t, p])
        allow[order[p]] = max(0.5 * skin, 0.5 * (least + skin))

    # back to sphere ids, ordered by first sphere (counting sort) into compressed rows; each
    # block of cell-ordered spheres counts and places its pairs apart, blocks in order, so a
    # row holds its pairs in the order of a single pass on any number of threads
    n_blocks = min(pool_size, JOIN_BLOCKS_MAX, max(m, 1))
    place = np.zeros((n_blocks, n_spheres), np.int64)
    for blk in numba.prange(n_blocks):
        _count_rows(blk * m // n_blocks, (blk + 1) * m // n_blocks, order, slot, found, tb, place[blk])
    start = np.empty(n_spheres + 1, np.int64)
    n_pairs = 0
    for s in range(n_spheres):
        start[s] = n_pairs
        for blk in range(n_blocks):
            k = place[blk, s]
            place[blk, s] = n_pairs     # the block's first place in row s
            n_pairs += k
    start[n_spheres] = n_pairs
    pi = np.empty(n_pairs, np.int64)
    pj = np.empty(n_pairs, np.int64)
    for blk in numba.prange(n_blocks):
        _place_rows(blk * m // n_blocks, (blk + 1) * m // n_blocks, order, slot, found, tb, place[blk], pi, pj)

    width = old_hist.shape[1]
    hist = np.zeros((n_pairs, width))
    n_old_rows = old_start.shape[0] - 1
    for k in numba.prange(n_pairs):
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


#: Most blocks the joining of a rebuild's pairs is split into (each holds a row count per sphere).
JOIN_BLOCKS_MAX = 8

#: ``build_pair_list`` compiled for one thread (pass a pool of 1), and the two as one kernel
#: ``rebuild_pair_list(use_threads, ...)`` for the step loop (``_jit.serial_or_threaded``).
build_pair_list_serial = serial_twin(build_pair_list)
rebuild_pair_list = serial_or_threaded(build_pair_list_serial, build_pair_list)


@loop_kernel
def _count_rows(p0, p1, order, slot, found, tb, count):
    """Pairs found from cell-ordered spheres ``p0``..``p1 - 1`` (``build_pair_list``), counted
    into ``count`` by row (their first sphere)."""
    for p in range(p0, p1):
        a = order[p]
        for q in range(slot[p], slot[p] + found[p]):
            count[min(a, order[tb[q]])] += 1


@loop_kernel
def _place_rows(p0, p1, order, slot, found, tb, place, pi, pj):
    """Those pairs into ``pi``, ``pj`` at ``place`` (by row, the next free place of this block)."""
    for p in range(p0, p1):
        a = order[p]
        for q in range(slot[p], slot[p] + found[p]):
            b = order[tb[q]]
            row = min(a, b)
            k = place[row]
            pi[k] = row
            pj[k] = max(a, b)
            place[row] = k + 1


@evaluator
def _cell_coordinates(c, nx, ny):
    """Coordinates (x, y, z) of cell ``c`` of a grid ``nx`` by ``ny`` by any, numbered x fastest."""
    return c % nx, (c // nx) % ny, c // (nx * ny)


#: What the shell of cells just beyond the 27 around a cell holds (``_shell_of_cell``).
SHELL_CLEAR, SHELL_OCCUPIED, SHELL_OWN_CLUMP_ONLY = 1, 0, -1


@loop_kernel
def _shell_of_cell(c, cell_start, nx, ny, nz):
    """What the shell of cells just beyond the 27 around cell ``c`` holds: no sphere
    (``SHELL_CLEAR``); else, with more than 64 spheres in the 125 cells, ``SHELL_OCCUPIED``; else
    ``SHELL_OWN_CLUMP_ONLY`` (they may all be of the clump of a sphere in ``c``: one sphere at a
    time, ``_shell_holds_own_clump_only``)."""
    cx, cy, cz = _cell_coordinates(c, nx, ny)
    inner = 0
    outer = 0
    for z in range(cz - 2, cz + 3):
        for y in range(cy - 2, cy + 3):
            if 0 <= z < nz and 0 <= y < ny:
                base = (z * ny + y) * nx
                x0 = max(cx - 2, 0)
                x1 = min(cx + 3, nx)
                outer += cell_start[base + x1] - cell_start[base + x0]
                if abs(z - cz) <= 1 and abs(y - cy) <= 1:
                    inner += cell_start[base + cx + 2] - cell_start[base + cx - 1]
    if outer == inner:
        return SHELL_CLEAR
    if outer > 64:
        return SHELL_OCCUPIED
    return SHELL_OWN_CLUMP_ONLY


@loop_kernel
def _shell_holds_own_clump_only(p, cs, bs, cell_start, nx, ny, nz):
    """Whether every sphere in the shell of cells just beyond the 27 around sphere ``p`` (cell
    order) is of its own clump."""
    cx, cy, cz = _cell_coordinates(cs[p], nx, ny)
    for z in range(max(cz - 2, 0), min(cz + 3, nz)):
        for y in range(max(cy - 2, 0), min(cy + 3, ny)):
            base = (z * ny + y) * nx
            for k in range(cell_start[base + max(cx - 2, 0)], cell_start[base + min(cx + 3, nx)]):
                kx, ky, kz = _cell_coordinates(cs[k], nx, ny)
                ring = max(abs(kz - cz), abs(ky - cy), abs(kx - cx))
                if ring >= 2 and bs[k] != bs[p]:
                    return False
    return True


#: Fraction of a near pair's gap each of its spheres may move before the near list is stale:
#: just under a half, so that rounding never lets a pair left out touch.
NEAR_ALLOWANCE = 0.4999


@loop_kernel
def select_near_pairs(n_spheres, start, pi, pj, hist, sx, srad, margin, near, near_start, sxn, near_allow):
    """The listed pairs whose gap is under ``margin`` into ``near`` (their indices in the Verlet
    list, ascending) with row pointers ``near_start`` (as ``start``); returns how many.

    The contact loops visit only these. A pair left out has a gap g >= ``margin`` > 0 now, so it
    is not touching and its history row is zeroed, as a contact loop would zero it; each of its
    spheres may move ``NEAR_ALLOWANCE`` g (into ``near_allow``, the smallest over its pairs; from
    ``sxn``, set to the positions now) before it could touch. Until a sphere moves that far the
    loops over the near pairs give the forces of a loop over the whole list to the bit: the same
    touching pairs in the same order. An infinite ``margin`` takes every pair without a distance.
    """
    for s in range(n_spheres):
        near_allow[s] = np.inf
    n_rows = start.shape[0] - 1
    if margin == np.inf:
        # a bed filling or flowing: after every rebuild, so a pass with no arithmetic (and no
        # reference positions: nothing is left out)
        for k in range(start[n_rows]):
            near[k] = k
        for r in range(n_rows + 1):
            near_start[r] = start[r]
        return start[n_rows]
    for s in range(n_spheres):
        for a in range(3):
            sxn[s, a] = sx[s, a]
    width = hist.shape[1]
    n = 0
    for r in range(n_rows):
        near_start[r] = n
        for k in range(start[r], start[r + 1]):
            i = pi[k]
            j = pj[k]
            dx = sx[j, 0] - sx[i, 0]
            dy = sx[j, 1] - sx[i, 1]
            dz = sx[j, 2] - sx[i, 2]
            d2 = dx * dx + dy * dy + dz * dz
            rsum = srad[i] + srad[j]
            reach = rsum + margin
            if d2 < reach * reach:
                near[n] = k
                n += 1
            else:
                g = NEAR_ALLOWANCE * (math.sqrt(d2) - rsum)
                near_allow[i] = min(near_allow[i], g)
                near_allow[j] = min(near_allow[j], g)
                for c in range(width):
                    hist[k, c] = 0.0
    near_start[n_rows] = n
    return n


@kernel
def build_wall_list(n_spheres, sx, srad, sbody, bactive, skin, kind, origin, normal, axis_u, axis_v,
                    half, old_start, old_wall, old_hist, allow):
    """Sphere-wall Verlet list (rows by sphere) with history carried over, and each active
    sphere's gap [m] to the nearest wall not listed with it into ``allow`` (at least skin;
    infinite without walls).

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
            free = np.inf
            for k in range(n_walls):
                # distance to a plane or rectangle's plane bounds the distance to the wall
                # from below (a cylinder has no such plane)
                if kind[k] != CYLINDER:
                    h = ((x - origin[k, 0]) * normal[k, 0] + (y - origin[k, 1]) * normal[k, 1]
                         + (z - origin[k, 2]) * normal[k, 2])
                    if kind[k] != PLANE:
                        h = abs(h)
                    if h >= reach:
                        free = min(free, h - srad[s])
                        continue
                d, ux, uy, uz = wall_distance(kind, origin, normal, axis_u, axis_v, half, k, x, y, z)
                if d < reach:
                    ts[n] = s
                    tk[n] = k
                    n += 1
                else:
                    free = min(free, d - srad[s])
            allow[s] = max(free, skin)
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


@kernel
def admit_spheres(first, n_spheres, sx, srad, sbody, bactive, skin, sx0, allow, sxw, wall_allow,
                  kind, origin, normal, axis_u, axis_v, half, wall_ref, lo, inv_cell, dims):
    """Admit spheres ``first``..``n_spheres - 1``, added since the last rebuild, into valid
    Verlet lists without rebuilding them; returns False if a rebuild is needed instead (the
    allowances may then have been narrowed: the rebuild sets them all anew).

    A new sphere s is listed with nothing. Against each earlier sphere j (reference position
    ``sx0[j]``, allowance ``allow[j]``) the pair stays apart while s moves less than
    |x_s - sx0_j| - R_s - R_j - allow_j, and against the walls while s plus a wall move less
    than its gap to them less the walls' moves since their reference ``wall_ref``; the smallest
    of each is its allowance (``allow``, ``wall_allow``), from its position now (``sx0``,
    ``sxw``). A sphere allowance below skin / 2 is raised to it by narrowing the allowances of
    the neighbours in the way, if they have not yet moved as far; else, and for a wall allowance
    below skin / 2, the lists are rebuilt instead.

    The earlier spheres are put in the cells of the grid ``lo``, ``inv_cell``, ``dims`` by
    their reference positions (each new sphere joins as it is admitted), and a new sphere
    looks at rings of cells around its own until no sphere beyond can come closer than the
    nearest found: the same smallest allowance as over every sphere, in time independent of
    the number of spheres.
    """
    wmax = 0.0
    for k in range(kind.shape[0]):
        d2 = 0.0
        for a in range(3):
            d2 += (origin[k, a] - wall_ref[k, a]) ** 2
        wmax = max(wmax, math.sqrt(d2))
    least = 0.5 * skin
    head = np.full(dims[0] * dims[1] * dims[2], -1, np.int64)   # a linked list of spheres per cell
    nxt = np.empty(n_spheres, np.int64)
    reach = 0.0    # the largest radius plus allowance in the cells: bounds how far a sphere matters
    for j in range(first):
        if bactive[sbody[j]]:
            reach = _into_cell(j, sx0, srad, allow, lo, inv_cell, dims, head, nxt, reach)
    edge = min(1.0 / inv_cell[0], 1.0 / inv_cell[1], 1.0 / inv_cell[2])
    ring = np.empty(24 * max(dims[0], dims[1], dims[2]) ** 2 + 2, np.int64)
    for s in range(first, n_spheres):
        if not bactive[sbody[s]]:
            continue
        w_s = np.inf
        for k in range(kind.shape[0]):
            d, ux, uy, uz = wall_distance(kind, origin, normal, axis_u, axis_v, half, k,
                                          sx[s, 0], sx[s, 1], sx[s, 2])
            w_s = min(w_s, d - srad[s] - wmax)
        if w_s < least:
            return False
        a_s = _admit_rings(s, np.inf, sx, sx0, srad, sbody, allow, lo, inv_cell, dims, head, nxt, reach, edge, ring)
        if a_s < least:
            # give s skin / 2 by narrowing the neighbours that leave it less: valid while
            # each has not yet moved that far from its reference
            if _admit_rings(s, least, sx, sx0, srad, sbody, allow, lo, inv_cell, dims, head, nxt, reach, edge,
                            ring) < 0.0:
                return False
            a_s = least
        allow[s] = a_s
        wall_allow[s] = w_s
        for a in range(3):
            sx0[s, a] = sx[s, a]
            sxw[s, a] = sx[s, a]
        reach = _into_cell(s, sx0, srad, allow, lo, inv_cell, dims, head, nxt, reach)
    return True


@kernel
def _into_cell(j, sx0, srad, allow, lo, inv_cell, dims, head, nxt, reach):
    """Put sphere j in the cell of its reference position (``bin_spheres``); returns ``reach``
    raised to its radius plus allowance."""
    bin_spheres(sx0, j, j + 1, lo, inv_cell, dims, head, nxt)
    return max(reach, srad[j] + allow[j])


@kernel
def _admit_rings(s, need, sx, sx0, srad, sbody, allow, lo, inv_cell, dims, head, nxt, reach, edge, ring):
    """The smallest room |x_s - sx0_j| - R_s - R_j - allow_j over the spheres j in cells (other
    clumps than s's), searched ring of cells by ring around s while a sphere beyond could have
    less than that smallest (``need`` infinite); every ring when s lies outside the grid.

    With a finite ``need``, each j with room below it instead has its allowance narrowed to
    leave s ``need``, ring by ring while a sphere beyond could have less (``admit_spheres``);
    returns -1 if one has already moved that far."""
    # a flag passed as a constant would compile this twice (numba types True and False apart)
    narrow = need < np.inf
    cell = np.empty(3, np.int64)
    inside = True
    for a in range(3):
        u = (sx[s, a] - lo[a]) * inv_cell[a]
        inside &= 0.0 <= u < dims[a]
        cell[a] = min(max(int(u), 0), dims[a] - 1)
    best = np.inf
    for r in range(max(dims[0], dims[1], dims[2])):
        for q in range(_cells_in_ring(cell, r, dims, ring)):
            j = head[ring[q]]
            while j >= 0:
                if sbody[j] != sbody[s] and not narrow:
                    best = min(best, _room(s, j, sx, sx0, srad) - allow[j])
                elif sbody[j] != sbody[s]:
                    narrowed = _room(s, j, sx, sx0, srad) - need
                    if narrowed < allow[j]:
                        moved2 = 0.0
                        for a in range(3):
                            moved2 += (sx[j, a] - sx0[j, a]) ** 2
                        if narrowed <= 0.0 or moved2 >= narrowed * narrowed:
                            return -1.0
                        allow[j] = narrowed
                j = nxt[j]
        # a sphere beyond ring r is at least r cell edges from s (a margin of a billionth of
        # an edge over the rounding)
        if inside and r * edge - srad[s] - reach > min(best, need) + 1e-9 * edge:
            break
    return best


@kernel
def _cells_in_ring(cell, r, dims, out):
    """The cells at Chebyshev distance ``r`` from ``cell`` within the grid, into ``out``;
    returns how many."""
    n = 0
    for z in range(max(cell[2] - r, 0), min(cell[2] + r, dims[2] - 1) + 1):
        for y in range(max(cell[1] - r, 0), min(cell[1] + r, dims[1] - 1) + 1):
            row = (z * dims[1] + y) * dims[0]
            if abs(z - cell[2]) == r or abs(y - cell[1]) == r:
                for x in range(max(cell[0] - r, 0), min(cell[0] + r, dims[0] - 1) + 1):
                    out[n] = row + x
                    n += 1
            else:   # r > 0 here: the ring's two ends of this row
                for x in (cell[0] - r, cell[0] + r):
                    if 0 <= x < dims[0]:
                        out[n] = row + x
                        n += 1
    return n


@kernel
def _room(s, j, sx, sx0, srad):
    """Gap [m] between sphere s where it is and sphere j at its reference position."""
    d2 = 0.0
    for a in range(3):
        d2 += (sx[s, a] - sx0[j, a]) ** 2
    return math.sqrt(d2) - srad[s] - srad[j]


def morton_keys(points, lo, cell) -> np.ndarray:
    """Morton (Z-order) key of the grid cell holding each point: the bits of the cell's x, y
    and z indices interleaved (21 bits each; points outside the grid clipped to its edge)."""
    k = np.clip(np.floor((np.asarray(points, float) - np.asarray(lo, float)) / np.asarray(cell, float)),
                0, (1 << 21) - 1).astype(np.int64)
    key = np.zeros(k.shape[0], np.int64)
    for bit in range(21):
        for a in range(3):
            key |= ((k[:, a] >> bit) & 1) << (3 * bit + a)
    return key


def ascending_pairs(a, b, hist, odd_columns):
    """Pairs (a, b) as (min, max), with the history columns that are odd under exchange of the
    two spheres (``odd_columns``: the tangential spring, the rolling spring torque, both
    written for the first sphere) negated where a pair was turned round."""
    turned = a > b
    hist = hist.copy()
    if turned.any() and len(odd_columns):
        rows = np.flatnonzero(turned)
        hist[np.ix_(rows, odd_columns)] *= -1.0
    return np.where(turned, b, a), np.where(turned, a, b), hist


def _rows(first, n_rows):
    """Row pointers of a list ordered by ``first``."""
    start = np.zeros(n_rows + 1, np.int64)
    np.cumsum(np.bincount(first, minlength=n_rows), out=start[1:])
    return start


def renumber_pair_list(new_index, start, pi, pj, hist, odd_columns):
    """The sphere-sphere list after sphere s became sphere ``new_index[s]``: pairs turned so
    that i < j (``ascending_pairs``), reordered into rows by first sphere, history alongside."""
    a, b, hist = ascending_pairs(new_index[pi], new_index[pj], hist, odd_columns)
    order = np.lexsort((b, a))
    return _rows(a, new_index.shape[0]), a[order], b[order], hist[order]


def renumber_wall_list(new_index, start, ws, wk, hist):
    """The sphere-wall list after sphere s became sphere ``new_index[s]``, in rows by sphere."""
    s = new_index[ws]
    order = np.lexsort((wk, s))
    return _rows(s, new_index.shape[0]), s[order], wk[order].copy(), hist[order].copy()


@kernel
def bin_spheres(x, first, n, lo, inv_cell, dims, head, nxt):
    """Spheres ``first``..``n - 1`` of ``x`` into the cells of a grid (``lo``, ``inv_cell``,
    ``dims``; outside it, the nearest boundary cell): a linked list per cell, ``head[cell]``
    and ``nxt[sphere]`` (-1 ends)."""
    for j in range(first, n):
        c = 0
        for a in range(2, -1, -1):
            c = c * dims[a] + min(max(int((x[j, a] - lo[a]) * inv_cell[a]), 0), dims[a] - 1)
        nxt[j] = head[c]
        head[c] = j


@kernel
def first_clear(start, x, r, rmax, lo, inv_cell, dims, head, nxt, centres_of_mass, reach, cx, cr, gap,
                inside) -> int:
    """The first candidate clump ``m >= start`` with ``inside[m]`` whose spheres ``cx[m]``, ``cr``
    keep ``gap`` [m] from every sphere ``x``, ``r`` in the cells (``bin_spheres``; ``rmax`` their
    largest radius; the clump lies within ``reach`` of its centre ``centres_of_mass[m]``); -1 if
    none."""
    box = reach + rmax + gap
    for m in range(start, cx.shape[0]):
        if inside[m] and not _near_any(x, r, lo, inv_cell, dims, head, nxt, centres_of_mass[m], box, cx[m], cr,
                                       gap):
            return m
    return -1


@kernel
def _near_any(x, r, lo, inv_cell, dims, head, nxt, centre, box, cx, cr, gap) -> bool:
    """Whether a sphere in the cells within ``box`` of ``centre`` (one cell more each way, over
    the rounding) comes closer than ``gap`` to a sphere ``cx``, ``cr``."""
    k0 = np.empty(3, np.int64)
    k1 = np.empty(3, np.int64)
    for a in range(3):
        k0[a] = min(max(int((centre[a] - box - lo[a]) * inv_cell[a]) - 1, 0), dims[a] - 1)
        k1[a] = min(max(int((centre[a] + box - lo[a]) * inv_cell[a]) + 1, 0), dims[a] - 1)
    for z in range(k0[2], k1[2] + 1):
        for y in range(k0[1], k1[1] + 1):
            for c in range((z * dims[1] + y) * dims[0] + k0[0], (z * dims[1] + y) * dims[0] + k1[0] + 1):
                j = head[c]
                while j >= 0:
                    if (abs(x[j, 0] - centre[0]) < box and abs(x[j, 1] - centre[1]) < box
                            and abs(x[j, 2] - centre[2]) < box):
                        for i in range(cx.shape[0]):
                            dx = x[j, 0] - cx[i, 0]
                            dy = x[j, 1] - cx[i, 1]
                            dz = x[j, 2] - cx[i, 2]
                            if math.sqrt(dx * dx + dy * dy + dz * dz) < cr[i] + r[j] + gap:
                                return True
                    j = nxt[j]
    return False
