"""Simulate stage: a numba DEM of multi-sphere clumps and the twins of the lab rigs.

Public API (details in each module's docstring):

- ``Simulation`` (``simulate.engine``): state, walls, factories, ``run``, state readers.
- ``DEMParameters`` (``simulate.params``): the parameter set with the paper's defaults.
- ``MaterialTable`` (``simulate.materials``): materials and per-pair contact parameters.
- ``ClumpTemplate``, ``segment_template``, ``make_template`` (``simulate.clump``): clumps and
  their mass properties; ``DEMParameters.template()`` builds the clump of its shape
  (``simulate.shapes``).
- ``Plane``, ``Rectangle``, ``Cylinder``, ``box_rectangles`` (``simulate.walls``).
- ``ParticleFactory`` (``simulate.factory``).
- ``rayleigh_time`` (``simulate.timestep``).
- ``build_paper_repose_case`` (``simulate.scenes``): the paper's repose-angle case.
- ``write_vtp`` (``simulate.vtk``): frames for ParaView.
"""

from demcal.simulate.clump import ClumpTemplate, make_template, segment_template
from demcal.simulate.engine import Escape, RunSummary, Simulation
from demcal.simulate.factory import ParticleFactory
from demcal.simulate.materials import MaterialTable
from demcal.simulate.params import DEMParameters
from demcal.simulate.scenes import build_paper_repose_case
from demcal.simulate.timestep import rayleigh_time
from demcal.simulate.vtk import write_vtp
from demcal.simulate.walls import Cylinder, Plane, Rectangle, box_rectangles

__all__ = ["ClumpTemplate", "Cylinder", "DEMParameters", "Escape", "MaterialTable", "ParticleFactory", "Plane",
           "Rectangle", "RunSummary", "Simulation", "box_rectangles", "build_paper_repose_case",
           "make_template", "rayleigh_time", "segment_template",
           "write_vtp"]
