"""Small scenes shared by the simulate tests."""

from __future__ import annotations

import numpy as np

from demcal.simulate import DEMParameters, MaterialTable, Plane, Simulation
from demcal.simulate.clump import make_template

#: Radius of the paper's spheres [m].
R = 0.0055


def sphere_mass(radius=R, density=912.0):
    return density * 4.0 / 3.0 * np.pi * radius ** 3


def simulation(params=None, *, dt=1e-6, gravity=(0.0, 0.0, 0.0), lo=(-0.2, -0.2, -0.05),
               hi=(0.2, 0.2, 0.5), rolling_lever=None, **kwargs):
    """A Simulation with the particle/steel materials of ``params`` and a huge domain."""
    params = params or DEMParameters()
    lever = rolling_lever or params.rolling_lever
    return Simulation(MaterialTable.from_parameters(params), domain_lo=lo, domain_hi=hi, dt=dt,
                      gravity=gravity, rolling_lever=lever, **kwargs)


def sphere_template(sim, radius=R, density=912.0):
    return sim.add_template(make_template([[0.0, 0.0, 0.0]], radius, density, name="sphere"))


def floor(sim, z=0.0):
    return sim.add_wall(Plane((0.0, 0.0, z), (0.0, 0.0, 1.0), material="steel", name="floor"))
