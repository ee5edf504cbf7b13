"""Rigs: the twins of the lab tests, each measuring its observable the way the lab does.

========  ==========================================  ============================================
rig       lab test                                    observable
========  ==========================================  ============================================
repose    plate withdrawal ("pumping plate") heap     ``angle_deg`` (photo method), profile and
          (``simulate.rigs.repose``)                  outside-heap angles, escapes
drop      free fall onto a plate, rebound filmed      ``apparent_restitution`` = sqrt(h_rebound /
          (``simulate.rigs.drop``)                    h_drop) of the centre of mass
incline   inclinometer, plate tilted slowly           ``slide_angle_deg``, ``roll_angle_deg``
          (``simulate.rigs.incline``)
========  ==========================================  ============================================

Every rig returns a :class:`RigResult`; :func:`run_rig` runs one by name. Each rig module
also has ``task(params, ...)``, the inputs of one run as a plain dict naming its rig (what a run
store keys, ``analyse.runs.run_key``), and ``run_task(inputs)``, which runs it;
:func:`run_task` runs any task on the rig it names, so the stages above never dispatch on a
rig's name.

>>> from simulate.params import DEMParameters
>>> result = run_rig("drop", DEMParameters(), seed=1, height=0.4, orientation_deg=0.0)
>>> result.observable["apparent_restitution"]                      # doctest: +SKIP

Progress and frames. Every rig accepts ``callback(sim, t_end, final)``, called after each
chunk of steps it runs (``t_end``: the planned, or for runs that may end early the largest,
simulated time [s]; ``final``: True on the last call, with the final state).
"""

from __future__ import annotations

import importlib
import operator
from dataclasses import dataclass

from demcal.errors import InputError
from demcal.provenance import Provenance

#: Rig name -> "module:function".
RIGS = {"repose": "demcal.simulate.rigs.repose:run_repose",
        "drop": "demcal.simulate.rigs.drop:run_drop",
        "incline": "demcal.simulate.rigs.incline:run_incline"}


@dataclass(frozen=True)
class RigResult:
    """What one run of a rig produced.

    Attributes
    ----------
    rig : str
        ``"repose"``, ``"drop"`` or ``"incline"``.
    observable : dict
        The measured quantities, named as in the lab (e.g. ``angle_deg``,
        ``apparent_restitution``, ``slide_angle_deg``); NaN when the run could not measure one.
    record : dict
        The full record: heap profile, sphere positions and radii, trajectories, time series
        (numpy arrays, SI units).
    meta : dict
        ``seed``, ``dt`` [s], ``steps``, ``wall_s`` (real time of the simulation) [s],
        ``spheres`` (spheres simulated at the end), ``sphere_steps_per_s`` [1/s], ``profile``
        (repose profile, None for the other rigs), ``simulated_s`` [s] and rig-specific notes.
    params : dict
        The ``DEMParameters`` used, as a dict.
    provenance : demcal.provenance.Provenance
        Code version, seed and the rig options.
    """

    rig: str
    observable: dict
    record: dict
    meta: dict
    params: dict
    provenance: Provenance

    def to_dict(self) -> dict:
        return {"rig": self.rig, "observable": dict(self.observable), "record": dict(self.record),
                "meta": dict(self.meta), "params": dict(self.params),
                "provenance": self.provenance.to_dict()}


def rig_function(name: str):
    """The run function of rig ``name``; an unknown name lists the valid ones."""
    if name not in RIGS:
        raise InputError(f"unknown rig {name!r}; valid rigs: {', '.join(RIGS)}")
    module, func = RIGS[name].split(":")
    return getattr(importlib.import_module(module), func)


def run_rig(name: str, params, seed: int = 0, **opts) -> RigResult:
    """Run rig ``name`` (``repose``, ``drop``, ``incline``) with ``params`` and ``seed``.

    ``opts`` are the rig's keyword options (see ``run_repose``, ``run_drop``, ``run_incline``).
    """
    return rig_function(name)(params, seed, **opts)


def run_task(inputs: dict) -> dict:
    """Run one task (a rig module's ``task(...)``) on the rig it names; a task naming no rig is
    a repose run, as the first campaigns stored them (top level, so worker processes run it)."""
    name = inputs.get("rig", "repose")
    if name not in RIGS:
        raise InputError(f"unknown rig {name!r} in a run's task; valid rigs: {', '.join(RIGS)}")
    module = importlib.import_module(RIGS[name].split(":")[0])
    return module.run_task(inputs)


def run_meta(seed, dt, tally, spheres, simulated_s, profile=None, **extra) -> dict:
    """The ``meta`` dict of a :class:`RigResult` from a :class:`RunTally` of its runs."""
    wall = tally.wall_s
    return {"seed": seed, "dt": float(dt), "steps": int(tally.steps), "wall_s": float(wall),
            "spheres": int(spheres),
            "sphere_steps_per_s": float(tally.sphere_steps / wall) if wall > 0 else 0.0,
            "profile": profile, "simulated_s": float(simulated_s), **extra}


class RunTally:
    """Totals over successive ``Simulation.run`` calls: steps, wall time, sphere-steps."""

    def __init__(self):
        self.steps = 0
        self.wall_s = 0.0
        self.sphere_steps = 0.0

    def add(self, summary) -> None:
        """Add one ``RunSummary``."""
        self.steps += summary.steps
        self.wall_s += summary.wall_time
        self.sphere_steps += summary.sphere_steps_per_second * summary.wall_time


def check_seed(seed) -> int:
    """A run seed: a non-negative integer (Python or numpy)."""
    try:
        value = operator.index(seed)
    except TypeError:
        value = None
    if value is None or isinstance(seed, bool) or value < 0:
        raise InputError(f"seed must be a non-negative integer, got {seed!r}")
    return value


__all__ = ["RIGS", "RigResult", "RunTally", "check_seed", "rig_function", "run_meta", "run_rig", "run_task"]
