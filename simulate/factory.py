"""Particle factories: clumps inserted at random, non-overlapping positions and orientations.

A ``ParticleFactory`` inserts ``n_total`` clumps of one template (or of several, each clump's
template drawn with the given weights: a size distribution) uniformly in time over
``[start_time, end_time]`` (EDEM's dynamic factory: e.g. 500 segments in the first second),
each at a uniformly random position and uniformly random orientation (Shoemake 1992) such
that every member sphere lies inside the box ``region_lo``-``region_hi``, overlaps no wall and
keeps a gap of the simulation's Verlet skin to every other sphere. A clump that cannot be
placed in ``max_attempts`` draws is retried at the next chunk (``failed_attempts`` counts the
rejected draws).

Clumps enter in batches, as LIGGGHTS' ``insert`` fixes do: the simulation stops for the
factory every ``batch_steps`` steps of the insertion window, and each clump enters at the first
batch at or after its due time (at most ``batch_steps`` steps late). A batch costs one return
to Python, and the gap of a skin lets the new spheres join the neighbour lists without a
rebuild (``simulate.neighbours.admit_spheres``): a fill no longer rebuilds the lists at every
clump.

Several templates. With ``template`` a sequence of template ids and ``weights`` (default
equal), the template of each clump is drawn (``Generator.choice``) before its position and
orientation, from the same generator, and kept until that clump is placed: a crowded region
delays a large clump but never swaps it for a small one, so the inserted sizes follow the
weights. With one template no draw is made, so a single-template factory gives the same clumps
for a given seed as before.

Randomness comes only from ``seed`` (an int or a ``numpy.random.Generator``).

Example (``sim`` and its segment template ``seg`` as in ``simulate.engine``)
-------
>>> factory = ParticleFactory(template=seg, n_total=500, region_lo=(0.01, 0.01, 0.10),
...                           region_hi=(0.19, 0.09, 0.24), start_time=0.0, end_time=1.0, seed=1)
>>> sim.add_factory(factory)

References
----------
Shoemake, K. (1992). Uniform random rotations. In Graphics Gems III, 124-132. Academic Press.
"""

from __future__ import annotations

import math

import numpy as np

from demcal.errors import InputError
from demcal.simulate.integrate import matrices_from_quats, quaternions_from_uniforms
from demcal.simulate.neighbours import bin_spheres, first_clear
from demcal.simulate.walls import wall_distances, walls_near

#: Draws made in a batch's first call into numpy, then twice as many each call (the clumps placed
#: do not depend on it).
DRAWS_AT_ONCE = 16


class ParticleFactory:
    """Inserts clumps into a ``Simulation`` during ``run`` (see the module docstring).

    Parameters
    ----------
    template : int or sequence of int
        Template id in the simulation, or several ids to draw each clump's template from.
    n_total : int
        Clumps to insert.
    region_lo, region_hi : 3-sequence
        Insertion box [m].
    start_time, end_time : float
        Insertion window [s]; clump k (0-based) is due at start + (k + 1) (end - start) / n_total.
    seed : int or numpy.random.Generator
    material : str
    velocity : 3-sequence
        Initial velocity [m/s].
    max_attempts : int
        Random draws per clump per insertion attempt.
    weights : sequence of float, optional
        Relative frequency of each template (several templates only); default equal.
    batch_steps : int
        Steps between insertion batches (default 50).

    Attributes
    ----------
    templates : tuple of int
        The template ids; ``template`` is the first.
    probabilities : numpy.ndarray
        Normalised ``weights``.
    bodies : list of int
        Body ids inserted so far.
    body_templates : list of int
        Template id of each inserted body.
    failed_attempts : int
        Rejected draws (overlap or outside the region).
    """

    def __init__(self, template, n_total: int, region_lo, region_hi, *, seed,
                 start_time: float = 0.0, end_time: float = 1.0, material: str = "particle",
                 velocity=(0.0, 0.0, 0.0), max_attempts: int = 200, weights=None, batch_steps: int = 50):
        ids = np.atleast_1d(np.asarray(template))
        if ids.ndim != 1 or ids.size == 0 or not np.issubdtype(ids.dtype, np.integer) or np.any(ids < 0):
            raise InputError(f"template must be a template id or a non-empty sequence of ids, got {template!r}")
        self.templates = tuple(int(k) for k in ids)
        self.template = self.templates[0]
        if weights is None:
            w = np.ones(len(self.templates))
        else:
            w = np.asarray(weights, dtype=float).reshape(-1)
            if w.size != len(self.templates) or not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
                raise InputError(f"weights must be {len(self.templates)} finite numbers >= 0, not all "
                                 f"zero (one per template), got {weights!r}")
        self.probabilities = w / w.sum()
        if int(n_total) != n_total or n_total < 0:
            raise InputError(f"n_total must be a non-negative integer, got {n_total!r}")
        self.n_total = int(n_total)
        self.region_lo = np.asarray(region_lo, dtype=float).reshape(3)
        self.region_hi = np.asarray(region_hi, dtype=float).reshape(3)
        if not np.all(self.region_hi > self.region_lo):
            raise InputError(f"factory region_hi {self.region_hi.tolist()} must exceed region_lo "
                             f"{self.region_lo.tolist()}")
        if not (end_time >= start_time >= 0):
            raise InputError(f"factory needs 0 <= start_time <= end_time, got {start_time!r}, {end_time!r}")
        self.start_time = float(start_time)
        self.end_time = float(end_time)
        if isinstance(seed, np.random.Generator):
            self.rng = seed
        elif isinstance(seed, (int, np.integer)):
            self.rng = np.random.default_rng(int(seed))
        else:
            raise InputError(f"seed must be an int or numpy.random.Generator, got {seed!r}")
        self.material = material
        self.velocity = np.asarray(velocity, dtype=float).reshape(3)
        self.max_attempts = int(max_attempts)
        if int(batch_steps) != batch_steps or batch_steps < 1:
            raise InputError(f"batch_steps must be a positive integer, got {batch_steps!r}")
        self.batch_steps = int(batch_steps)
        self.bodies: list[int] = []
        self.body_templates: list[int] = []
        self.failed_attempts = 0
        self._pending = None  # template drawn for the next clump, kept until it is placed

    @property
    def inserted(self) -> int:
        return len(self.bodies)

    def n_due(self, t: float) -> int:
        """Clumps that should have been inserted by time ``t`` [s]."""
        if self.n_total == 0 or t < self.start_time:
            return 0
        if t >= self.end_time or self.end_time == self.start_time:
            return self.n_total
        # a tiny tolerance so that a clump due exactly at a step boundary enters there
        frac = (t - self.start_time) / (self.end_time - self.start_time)
        return min(self.n_total, int(math.floor(frac * self.n_total + 1e-9)))

    def steps_until_next(self, sim) -> int:
        """Steps until the next clump is due (a large number when none is left)."""
        if self.inserted >= self.n_total:
            return 1 << 60
        if self.inserted < self.n_due(sim.time):
            return sim.chunk_steps  # behind schedule (region full): retry after a chunk
        k = self.inserted + 1
        t_next = self.start_time + k * (self.end_time - self.start_time) / self.n_total
        # the first batch at or after it: batches every batch_steps steps from start_time
        period = self.batch_steps * sim.dt
        t_batch = self.start_time + math.ceil((t_next - self.start_time) / period - 1e-9) * period
        return max(1, int(math.ceil((t_batch - sim.time) / sim.dt - 1e-9)))

    def insert_due(self, sim) -> int:
        """Insert the clumps due at ``sim.time``; returns how many were placed."""
        if self.inserted == 0 and self.n_total and not self.bodies:
            sim.reserve(sim.n_bodies + self.n_total)
        if self.inserted >= self.n_due(sim.time):
            return 0
        # the spheres that can touch the region, once per batch (the batch's clumps are added)
        x, r = sim.sphere_positions(), sim.sphere_radii()
        keep = sim.active()[sim.sphere_body()] if sim.n_spheres else np.zeros(0, bool)
        gap = sim.skin   # room to join the neighbour lists without a rebuild
        reach = max(sim.templates[k].bounding_radius for k in self.templates) + gap
        margin = reach + (float(r[keep].max()) if keep.any() else 0.0)
        keep &= np.all((x > self.region_lo - margin) & (x < self.region_hi + margin), axis=1)
        room = int(keep.sum()) + (self.n_due(sim.time) - self.inserted) * max(
            sim.templates[k].n_spheres for k in self.templates)
        nearby = _Nearby(x[keep], r[keep], room, self.region_lo - margin, self.region_hi + margin, margin)
        draws = None
        due = self.n_due(sim.time) - self.inserted
        templates, positions, orientations = [], [], []   # the batch's clumps, added at once
        try:
            while len(templates) < due:
                if draws is not None and len(self.templates) > 1:
                    draws.release()     # the next template is drawn from the generator
                    draws = None
                template = self._next_template()
                if draws is None:
                    draws = _Draws(self.rng, sim.templates[template], self.region_lo, self.region_hi)
                m = self._place_one(sim, nearby, gap, template, draws)
                if m < 0:
                    break
                templates.append(template)
                positions.append(draws.pos[m])
                orientations.append(draws.q[m])
        finally:
            if draws is not None:
                draws.release()
            bodies = sim.add_clumps(templates, positions, orientations, velocities=self.velocity,
                                    material=self.material)
            self.bodies.extend(bodies.tolist())
            self.body_templates.extend(templates)
        return len(templates)

    def _next_template(self) -> int:
        """Template of the next clump: drawn once per clump, and only if there are several."""
        if len(self.templates) == 1:
            return self.template
        if self._pending is None:
            self._pending = self.templates[int(self.rng.choice(len(self.templates), p=self.probabilities))]
        return self._pending

    def _place_one(self, sim, nearby: "_Nearby", gap: float, template: int, draws: "_Draws") -> int:
        """The first of the next clump's ``draws`` (of ``template``) at least ``gap`` [m] clear of
        the spheres ``nearby`` and of the walls, within ``max_attempts`` draws; -1 if none. The
        clump's spheres are added to those ``nearby``."""
        tpl = sim.templates[template]
        first = draws.taken
        limit = first + self.max_attempts
        m = first
        while m < limit:
            end = draws.made_at_least(m + 1, limit)
            m = nearby.first_clear(m, draws.pos[:end], tpl.bounding_radius, draws.centres[:end], tpl.radii, gap,
                                   draws.inside[:end])
            if m < 0:
                m = end
            elif _touches_a_wall(sim._w, draws.pos[m], tpl.bounding_radius, draws.centres[m], draws.radii):
                m += 1
            else:
                self.failed_attempts += m - first
                draws.taken = m + 1
                nearby.add(draws.centres[m], tpl.radii)
                self._pending = None
                return m
        self.failed_attempts += limit - first
        draws.taken = limit
        return -1

    def to_dict(self) -> dict:
        return {"template": self.template, "templates": list(self.templates),
                "weights": self.probabilities.tolist(), "n_total": self.n_total,
                "region_lo": self.region_lo.tolist(), "region_hi": self.region_hi.tolist(),
                "start_time": self.start_time, "end_time": self.end_time, "material": self.material,
                "velocity": self.velocity.tolist(), "batch_steps": self.batch_steps, "inserted": self.inserted,
                "failed_attempts": self.failed_attempts}


class _Draws:
    """Candidate placements of one template, drawn ahead from a factory's generator and handed
    out in order (``taken`` of them so far).

    Each draw takes six numbers from the generator: three for the orientation, three for the
    position. Draws are made in blocks (``DRAWS_AT_ONCE``, doubling), a block a call into numpy;
    ``release`` sets the generator back to just after the last draw taken, so the clumps placed,
    and the numbers left for the next use of the generator, are those of one draw at a time."""

    def __init__(self, rng, tpl, lo, hi):
        self.rng, self.lo, self.hi = rng, lo, hi
        self.offsets = tpl.centres - tpl.centre_of_mass
        self.radii = tpl.radii[:, None]
        self.state = rng.bit_generator.state
        self.taken = 0
        self.q = np.empty((0, 4))
        self.pos = np.empty((0, 3))
        self.centres = np.empty((0,) + self.offsets.shape)
        self.inside = np.empty(0, bool)

    def made_at_least(self, n: int, limit: int) -> int:
        """Make draws until there are ``n`` (a block at a time, never beyond ``limit``); returns
        how many there are, at most ``limit``."""
        while len(self.q) < n:
            block = min(max(DRAWS_AT_ONCE, len(self.q)), limit - len(self.q))
            u = self.rng.random((block, 6))
            q = quaternions_from_uniforms(u[:, :3])
            pos = self.lo + u[:, 3:] * (self.hi - self.lo)
            centres = pos[:, None, :] + self.offsets @ matrices_from_quats(q).transpose(0, 2, 1)
            inside = ~(np.any(centres - self.radii < self.lo, axis=(1, 2))
                       | np.any(centres + self.radii > self.hi, axis=(1, 2)))
            self.q = np.concatenate([self.q, q])
            self.pos = np.concatenate([self.pos, pos])
            self.centres = np.concatenate([self.centres, centres])
            self.inside = np.concatenate([self.inside, inside])
        return min(len(self.q), limit)

    def release(self) -> None:
        """Set the generator back to just after the last draw taken."""
        if self.taken < len(self.q):
            self.rng.bit_generator.state = self.state
            self.rng.random((self.taken, 6))


def _touches_a_wall(packed: dict, centre_of_mass, reach: float, centres, radii) -> bool:
    """Whether a sphere ``centres``, ``radii`` of a clump within ``reach`` of its centre of mass
    overlaps a wall (``wall_distances``, over the walls near enough to matter)."""
    near = walls_near(packed["kind"], packed["origin"], packed["normal"], packed["axis_u"], packed["axis_v"],
                      packed["half"], *centre_of_mass, reach)
    if near.size == 0:
        return False
    return bool(np.any(wall_distances({k: v[near] for k, v in packed.items()}, centres) < radii))


class _Nearby:
    """The spheres a batch's clumps keep clear of: those near the insertion region, then the
    batch's own as they are placed, in cells of side ``cell`` [m] (at least the reach of a
    test) over ``lo``-``hi``, so a test looks at a few cells instead of every sphere."""

    MAX_CELLS = 1 << 20

    def __init__(self, x, r, room: int, lo, hi, cell: float):
        self.x = np.empty((room, 3))
        self.r = np.empty(room)
        self.n = len(r)
        self.x[:self.n] = x
        self.r[:self.n] = r
        self.rmax = float(r.max()) if self.n else 0.0
        cell = max(cell, 1e-12)
        while True:
            self.dims = np.maximum(np.ceil((hi - lo) / cell), 1).astype(np.int64)
            if self.dims.prod() <= self.MAX_CELLS:
                break
            cell *= 2.0
        self.lo = np.asarray(lo, dtype=float)
        self.inv_cell = np.full(3, 1.0 / cell)
        self.head = np.full(int(self.dims.prod()), -1, np.int64)
        self.nxt = np.empty(room, np.int64)
        bin_spheres(self.x, 0, self.n, self.lo, self.inv_cell, self.dims, self.head, self.nxt)

    def add(self, centres, radii) -> None:
        n = self.n
        self.x[n:n + len(radii)] = centres
        self.r[n:n + len(radii)] = radii
        self.n = n + len(radii)
        self.rmax = max(self.rmax, float(radii.max()))
        bin_spheres(self.x, n, self.n, self.lo, self.inv_cell, self.dims, self.head, self.nxt)

    def first_clear(self, start: int, centres_of_mass, reach: float, centres, radii, gap: float, inside) -> int:
        """The first candidate from ``start`` inside the region and ``gap`` clear of these
        spheres (``simulate.neighbours.first_clear``); -1 if none."""
        return first_clear(start, self.x, self.r, self.rmax, self.lo, self.inv_cell, self.dims, self.head, self.nxt,
                           centres_of_mass, reach, centres, radii, gap, inside)
