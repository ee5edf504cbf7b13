"""How many threads one DEM run uses.

A campaign keeps every core busy with separate runs, one process each; a single large run (a
user's ``demcal simulate``, a drum turning for seconds, a campaign with fewer runs than cores)
instead splits its steps over threads (``simulate.forces``). The choice is made here:

- ``threads_per_run()`` is the number of cores numba may use, unless limited by
  ``limit_threads_per_run`` (campaign worker processes and Dask tasks are limited to one; a
  Dask worker runs several tasks at once on threads of its own) or by the environment
  variable ``DEMCAL_THREADS``;
- a ``Simulation`` uses that many threads once it holds ``THREADS_MIN_SPHERES`` spheres
  (below that, starting the threads each step costs more than they save: one thread), unless
  it was made with ``threads=n``.

The number of threads never changes a run's result: from ``THREADS_MIN_SPHERES`` on, the
contacts are summed in fixed ranges whatever the number of threads
(``simulate.forces.contact_forces_ranged``), and the list rebuilds give the same lists on any
number. Those ranged sums differ from the plain loop's only in the order of the additions: a run
follows the plain one to roundoff and, like any DEM, drifts from it after that, the same heap in
distribution (``tests/simulate/test_threads.py``).
"""

from __future__ import annotations

import os
from contextlib import contextmanager

import numba

from demcal.errors import InputError

#: Spheres from which a run uses several threads by default.
THREADS_MIN_SPHERES = 8192

# The step launches a few parallel loops per time step: OpenMP starts them in microseconds, where
# TBB and numba's own queue take up to a few hundred (measured on 2 cores; each is used if the
# one before it is missing).
numba.config.THREADING_LAYER_PRIORITY = ["omp", "tbb", "workqueue"]

_limit: int | None = None


def threads_per_run() -> int:
    """Threads a large run may use in this process (at least 1)."""
    cores = numba.config.NUMBA_NUM_THREADS
    if _limit is not None:
        return max(1, min(_limit, cores))
    env = os.environ.get("DEMCAL_THREADS", "").strip()
    if env:
        if not env.isdigit() or int(env) < 1:
            raise InputError(f"DEMCAL_THREADS must be a whole number >= 1, got {env!r}")
        return min(int(env), cores)
    return cores


def limit_threads_per_run(n: int | None) -> None:
    """Limit the threads of every run in this process to ``n`` (None: no limit). A campaign's
    worker processes call it with 1 when they start."""
    global _limit
    _limit = None if n is None else int(n)


def run_processes(workers: int):
    """A pool of ``workers`` local processes for separate runs, each run's DEM on one thread (the
    cores are shared among the runs). Spawned: a worker must not inherit numba or threading
    state from its parent."""
    import concurrent.futures as cf
    import multiprocessing as mp

    return cf.ProcessPoolExecutor(workers, mp_context=mp.get_context("spawn"),
                                  initializer=limit_threads_per_run, initargs=(1,))


@contextmanager
def threads_limited_to(n: int | None):
    """``limit_threads_per_run(n)`` for the duration of a block (None leaves it as it is)."""
    global _limit
    before = _limit
    if n is not None:
        _limit = int(n)
    try:
        yield
    finally:
        _limit = before
