"""Ready-made scenes: the paper's repose-angle case (plate withdrawal from a carton).

``build_paper_repose_case(params, seed)`` builds, with the public ``Simulation`` API, the
"pumping plate" test of the source paper as the benchmark and the repose rig use it: a carton
of inside size 200 x 100 x 250 mm (x along its length; open top; the end plate at x = 200 mm),
standing on an infinite steel floor z = 0; 500 segments inserted at random orientations in the
region x 10-190, y 10-90, z 100-240 mm during the first second; the end plate lifted at
0.1 m/s from t = 4 s, so that the segments flow out under it onto the floor outside the carton
(the carton side walls stop at x = 200 mm). Carton, plate and floor are all the wall material
of ``params`` (steel). The run length (10 s in the paper) is the caller's ``sim.run(duration)``.

Particles are all ``params``' shape by default; with a size distribution (the
``size_distribution`` argument, or ``params.particle_sizes``) each particle is drawn from the
measured sizes: one template per distinct size (``simulate.extensions.particle_of_size``),
drawn with the size's count as weight.
"""

from __future__ import annotations

import functools
import math
from collections import Counter

import numpy as np

from demcal.simulate.engine import Simulation
from demcal.simulate.factory import ParticleFactory
from demcal.simulate.materials import MaterialTable
from demcal.simulate.params import DEMParameters
from demcal.simulate.timestep import material_time_step
from demcal.simulate.walls import Plane, Rectangle

#: The paper's total simulated time [s].
PAPER_DURATION = 10.0


def build_paper_repose_case(params: DEMParameters, seed, n_clumps: int = 500, *,
                            box_length: float = 0.200, box_width: float = 0.100,
                            box_height: float = 0.250, lift_speed: float = 0.1,
                            lift_time: float = 4.0, fill_time: float = 1.0,
                            fill_margin: float = 0.010, fill_bottom: float = 0.100,
                            fill_top: float = 0.240, dt: float | None = None,
                            outside_length: float = 0.45, outside_width: float = 0.25,
                            force: bool = False,
                            chunk_steps: int = 200, size_distribution=None) -> Simulation:
    """The paper's plate-withdrawal repose case, ready to ``run``.

    Parameters
    ----------
    params : DEMParameters
        Materials, contact parameters, segment shape, mass model and rolling lever.
    seed : int or numpy.random.Generator
        Seed of the particle factory (positions and orientations).
    n_clumps : int
        Segments to insert.
    box_length, box_width, box_height : float
        Carton inside [m] (x, y, z).
    lift_speed : float
        End-plate lifting speed [m/s].
    lift_time : float
        Time at which the plate starts to rise [s].
    fill_time : float
        Segments are inserted uniformly over [0, fill_time] [s].
    fill_margin, fill_bottom, fill_top : float
        Factory region: x and y inset by ``fill_margin`` from the carton walls, z from
        ``fill_bottom`` to ``fill_top`` [m].
    dt : float, optional
        Time step [s]; default ``params``' (``simulate.timestep.material_time_step``).
    outside_length, outside_width : float
        Floor kept inside the simulation domain beyond the plate (x) and on either side of the
        carton (y) [m]; a segment leaving it is recorded in ``sim.escaped``.
    force : bool
        Allow a time step above half the Rayleigh time.
    chunk_steps : int
        Steps between returns to Python.
    size_distribution : simulate.extensions.SizeDistribution, optional
        Draw each particle from these measured sizes; default
        ``params.particle_sizes`` if set, else every particle is ``params``' shape.

    Returns
    -------
    Simulation
        With the factory attached; walls named ``floor``, ``carton x-``, ``carton y-``,
        ``carton y+`` and ``end plate`` (``sim.wall_index(name)``).
    """
    materials = MaterialTable.from_parameters(params)
    dt = material_time_step(params) if dt is None else dt
    L, W, H = box_length, box_width, box_height
    sim = Simulation(materials,
                     domain_lo=(-0.05, -outside_width, -0.02),
                     domain_hi=(L + outside_length, W + outside_width, H + 0.05),
                     dt=dt, rolling_lever=params.rolling_lever, force=force, chunk_steps=chunk_steps)
    templates, weights = particle_templates(sim, params, size_distribution)
    sim.add_wall(Plane((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), material="steel", name="floor"))
    x_axis, y_axis, z_axis = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)
    sim.add_wall(Rectangle((0.0, W / 2, H / 2), y_axis, z_axis, W / 2, H / 2, "steel", name="carton x-"))
    sim.add_wall(Rectangle((L / 2, 0.0, H / 2), x_axis, z_axis, L / 2, H / 2, "steel", name="carton y-"))
    sim.add_wall(Rectangle((L / 2, W, H / 2), x_axis, z_axis, L / 2, H / 2, "steel", name="carton y+"))
    sim.add_wall(Rectangle((L, W / 2, H / 2), y_axis, z_axis, W / 2, H / 2, "steel",
                           velocity=(0.0, 0.0, lift_speed), move_start=lift_time, move_stop=math.inf,
                           name="end plate"))
    sim.add_factory(ParticleFactory(templates, n_clumps,
                                    (fill_margin, fill_margin, fill_bottom),
                                    (L - fill_margin, W - fill_margin, fill_top),
                                    seed=seed, start_time=0.0, end_time=fill_time,
                                    material="particle", weights=weights))
    return sim


def particle_templates(sim: Simulation, params: DEMParameters, size_distribution):
    """Add the particle template(s) to ``sim``; returns their ids and weights (None for one)."""
    sizes = size_distribution.sizes if size_distribution is not None else params.particle_sizes
    if sizes is None:
        return sim.add_template(params.template()), None
    from demcal.simulate.extensions import particle_of_size   # scipy only when a distribution is used

    counts = Counter(tuple(float(v) for v in entry) for entry in sizes)
    ids = [sim.add_template(particle_of_size(params, entry)) for entry in counts]
    return ids, np.array(list(counts.values()), dtype=float)


@functools.cache
def compile_kernels(threaded: bool = False) -> None:
    """Load the engine's compiled kernels into this process, compiling them first if this
    installation has none yet (about a minute, once: they are cached on disk), by a step of a
    two-segment paper case, a clump added and a step more (the factory, the admission and the
    serial step loop), and with ``threaded`` the step loop on threads
    too (runs from ``THREADS_MIN_SPHERES`` spheres, or with ``threads`` set). A second call does
    nothing. Called before local worker processes start, so that they load the kernels instead
    of each compiling them at the same time, and by ``demcal compile`` at installation.

    With ``threaded`` a child process readies the threaded step loop while this one readies the
    serial one: on two cores a first compilation then takes about two thirds of the time of one
    after the other (62 and 67 s side by side against 99 s in one process, 2026-11-28)."""
    child = None
    if threaded:
        import subprocess
        import sys
        # the child compiles in silence: this process says so once for both
        child = subprocess.Popen([sys.executable, "-c",
                                  "from demcal.simulate._jit import compile_notice; compile_notice.said = True; "
                                  "from demcal.simulate.scenes import step_cases; step_cases(threads=2)"])
    try:
        step_cases(threads=None)
    finally:
        if child is not None:
            child.wait()       # never left running, whatever happened here
    if threaded:
        if child.returncode != 0:
            raise RuntimeError(f"compiling the threaded step loop failed in a child process "
                               f"(exit {child.returncode})")
        step_cases(threads=2)       # loaded from the cache the child filled


def step_cases(threads=None) -> None:
    """A step of a two-segment paper case, a clump added and a step more, on ``threads``
    threads (None: the serial step loop): what compiles (or loads) the engine's kernels."""
    sim = build_paper_repose_case(DEMParameters(), seed=0, n_clumps=2, fill_time=0.0)
    sim.threads = threads
    sim.run(n_steps=1)
    sim.add_clump(0, (0.1, 0.05, 0.05))     # a clump added between steps: the admission too
    sim.run(n_steps=1)
