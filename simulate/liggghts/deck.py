"""LIGGGHTS-PUBLIC 3.8 input deck for the source paper's angle-of-repose test.

The case is the "pumping plate" test of the paper (seed/000, "Determination of angle of
repose" and Fig. 11): a carton of 200 x 100 x 250 mm (inside) on a steel floor is filled with
500 segments of *Astragalus membranaceus* in the first second; at t = 4 s the end plate is
pulled up at 0.1 m/s and the segments run out into a heap; the run ends at 10 s. Each segment
is a rigid clump of 5 spheres of radius 5.5 mm on a line (end centres at +-7 mm, so the clump
is 25 mm long and 11 mm thick) with the mass and inertia of an 11 x 25 mm cylinder.

Axes: x along the carton (back wall at x = 0, end plate at x = L), y across (side walls at
y = 0 and y = W), z up (floor z = 0). Everything is SI; the deck uses LIGGGHTS ``units si``.

LIGGGHTS styles used (names as in the LIGGGHTS-PUBLIC 3.8 documentation [1]):
``atom_style granular``, ``pair_style gran model hertz tangential history rolling_friction
cdt``, ``fix wall/gran`` (``primitive zplane`` floor, ``mesh`` carton walls),
``fix mesh/surface``, ``fix move/mesh ... linear``, ``fix particletemplate/multisphere``
(``mass``, ``inertia_tensor``, ``use_volume``), ``fix particledistribution/discrete``,
``fix insert/rate/region``, ``fix multisphere``, ``fix gravity``,
``compute ke/multisphere``, ``compute erotate/multisphere``, ``write_dump``.

Contact law as LIGGGHTS implements it (hertz/history [1], cdt [2]): Hertz normal force with
1/E* = (1-nu_i^2)/E_i + (1-nu_j^2)/E_j and 1/R* = 1/R_i + 1/R_j, Mindlin no-slip tangential
spring with Coulomb cap, damping from the restitution coefficient with the *body* mass of a
clump in m*. Rolling friction ``cdt`` applies the torque mu_r F_n,el R_roll w/|w| (tangential
part only) with w the relative angular velocity (pairs) or the sphere's angular velocity
(walls), and lever arm R_roll = R_i R_j / (R_i + R_j) between spheres (2.75 mm here, half the
radius) and R_roll = R_i - delta_n / 2 (about the sphere radius) against walls. EDEM takes the
distance from the contact point to the centre of mass instead, which for a clump is longer.

References
----------
.. [1] LIGGGHTS-PUBLIC 3.8 documentation: pair_gran, gran_model_hertz,
       fix_particletemplate_multisphere, fix_multisphere, fix_insert_rate_region,
       fix_move_mesh, fix_wall_gran. DCS Computing GmbH, 2017.
.. [2] J. Ai, J.-F. Chen, J. M. Rotter, J. Y. Ooi, "Assessment of rolling resistance models
       in discrete element simulations", Powder Technology 206 (2011) 269-282 (model A,
       constant directional torque).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from demcal.errors import InputError
from demcal.simulate.export import liggghts_seeds
from demcal.simulate.materials import youngs_modulus
from demcal.units import GRAVITY

#: File names inside a run folder.
SCRIPT_NAME = "in.repose"
LOG_NAME = "log.liggghts"
POSITIONS_NAME = "final_positions.txt"
MESH_NAMES = ("back", "side_y0", "side_y1", "plate")

#: Columns of the final positions file (``write_dump ... custom``) and their format: the
#: LIGGGHTS default of 6 significant digits would round positions to 1e-6 m.
POSITION_COLUMNS = ("id", "mol", "x", "y", "z", "radius")
#: The same for single spheres: ``mol`` exists with fix multisphere only; a sphere is its own body.
SPHERE_POSITION_COLUMNS = ("id", "id", "x", "y", "z", "radius")
POSITION_FORMAT = '"%d %d %.10g %.10g %.10g %.10g"'


def cylinder_mass_inertia(diameter: float, length: float, density: float):
    """Mass and principal moments of inertia of a solid circular cylinder.

    m = rho pi d^2 L / 4, I_axial = m d^2 / 8, I_transverse = m (3 d^2 / 4 + L^2) / 12
    (about the centre of mass; any mechanics handbook, e.g. Meriam & Kraige, Engineering
    Mechanics: Dynamics, table D/4).

    Parameters
    ----------
    diameter, length : float
        Cylinder diameter and length [m].
    density : float
        Density [kg/m3].

    Returns
    -------
    tuple of float
        (mass [kg], axial moment [kg m2], transverse moment [kg m2]).
    """
    r = 0.5 * diameter
    mass = density * math.pi * r * r * length
    return mass, 0.5 * mass * r * r, mass * (3.0 * r * r + length * length) / 12.0


@dataclass(frozen=True)
class ReposeCase:
    """The paper's repose case, with every number the deck uses (SI units).

    Attributes
    ----------
    box_length, box_width, box_height : float
        Carton inside dimensions [m]: x from the back wall to the end plate, y between the
        side walls, z of the walls and of the end plate.
    plate_lift_speed : float
        Speed at which the end plate is pulled up [m/s].
    plate_lift_start : float
        Time at which the plate starts to move [s].
    plate_clearance : float
        The plate stops once its lower edge is this far above the carton top [m]; no segment
        can reach it after that, so stopping changes nothing but keeps the mesh in the box.
    n_segments : int
        Number of clumps poured into the carton.
    sphere_radius : float
        Radius of each sphere of a clump [m].
    sphere_offsets : tuple of float
        Positions of the sphere centres along the clump axis [m].
    segment_diameter, segment_length : float
        Cylinder whose mass and inertia the clump is given [m].
    particle_density : float
        Density of the segments [kg/m3].
    particle_shear_modulus, particle_poisson : float
        Segment shear modulus [Pa] and Poisson's ratio [-].
    steel_shear_modulus, steel_poisson : float
        Steel (floor and carton) shear modulus [Pa] and Poisson's ratio [-].
    restitution_pp, restitution_ps : float
        Coefficient of restitution particle-particle and particle-steel [-].
    friction_pp, friction_ps : float
        Static (sliding) friction particle-particle and particle-steel [-].
    rolling_pp, rolling_ps : float
        Rolling friction (cdt) particle-particle and particle-steel [-].
    time_step : float
        DEM time step [s].
    fill_time : float
        Time over which the segments are generated [s].
    fill_region : tuple of float
        (xlo, xhi, ylo, yhi, zlo, zhi) of the generation region [m]; whole clumps are
        placed inside it (LIGGGHTS ``all_in yes``).
    insert_interval : float
        Time between two insertion batches [s].
    skin : float
        Neighbour-list skin [m].
    gravity : float
        Gravitational acceleration, along -z [m/s2].
    thermo_interval : float
        Time between two thermo lines in the log [s].
    ntry : int
        Monte Carlo samples LIGGGHTS uses for the clump volume and centre of mass.
    particle : simulate.export.ExportModel, optional
        Any other material (:meth:`for_params`): its materials, contact model and particle
        template are demcal's own LIGGGHTS export (``simulate.export.liggghts_fragment``),
        and the segment and contact fields above only describe it; None: the paper's segment.
    """

    box_length: float = 0.200
    box_width: float = 0.100
    box_height: float = 0.250
    plate_lift_speed: float = 0.1
    plate_lift_start: float = 4.0
    plate_clearance: float = 0.010
    n_segments: int = 500
    sphere_radius: float = 5.5e-3
    sphere_offsets: tuple = (-7.0e-3, -3.5e-3, 0.0, 3.5e-3, 7.0e-3)
    segment_diameter: float = 0.011
    segment_length: float = 0.025
    particle_density: float = 912.0
    particle_shear_modulus: float = 1.0e7
    particle_poisson: float = 0.25
    steel_shear_modulus: float = 8.0e10
    steel_poisson: float = 0.3
    restitution_pp: float = 0.32
    restitution_ps: float = 0.36
    friction_pp: float = 0.65
    friction_ps: float = 0.22
    rolling_pp: float = 0.53
    rolling_ps: float = 0.15
    time_step: float = 7.43678e-5
    fill_time: float = 1.0
    fill_region: tuple = (0.010, 0.190, 0.010, 0.090, 0.100, 0.240)
    insert_interval: float = 0.05
    skin: float = 2.75e-3
    gravity: float = GRAVITY
    thermo_interval: float = 0.1
    ntry: int = 1_000_000
    particle: object = field(default=None, compare=False, repr=False)

    @classmethod
    def for_params(cls, params, geometry=None) -> "ReposeCase":
        """The repose case of any parameter set (``DEMParameters``, any shape): the carton of
        ``geometry`` (``simulate.rigs.repose.ReposeGeometry``; default the paper's carton in
        proportion to the particle, ``ReposeGeometry.for_particle``), filled over the paper's
        share of it (x 5-95 %, y 10-90 %, z 40-96 %), the neighbour skin half the largest
        sphere radius, the parameters' time step, and the particle as demcal exports it."""
        from demcal.simulate.export import export_model
        from demcal.simulate.rigs.repose import ReposeGeometry
        from demcal.simulate.timestep import material_time_step

        g = ReposeGeometry.for_particle(params.shape) if geometry is None else geometry
        model = export_model(params, material=params.shape.name)
        radius = float(np.max(model.template.radii))
        L, W, H = g.box_length, g.box_width, g.box_height
        return cls(box_length=L, box_width=W, box_height=H, plate_lift_speed=g.lift_speed,
                   n_segments=g.fill_count, sphere_radius=radius,
                   sphere_offsets=tuple(float(np.linalg.norm(o)) for o in model.template.offsets),
                   segment_diameter=2.0 * radius, segment_length=2.0 * model.template.bounding_radius,
                   particle_density=params.particle_density_kg_m3, particle_shear_modulus=params.shear_modulus_pa,
                   particle_poisson=params.poisson_ratio, steel_shear_modulus=params.wall_shear_modulus_pa,
                   steel_poisson=params.wall_poisson_ratio, restitution_pp=params.e_pp, restitution_ps=params.e_pw,
                   friction_pp=params.mu_s_pp, friction_ps=params.mu_s_pw, rolling_pp=params.mu_r_pp,
                   rolling_ps=params.mu_r_pw, time_step=material_time_step(params),
                   fill_region=(0.05 * L, 0.95 * L, 0.1 * W, 0.9 * W, 0.4 * H, 0.96 * H),
                   skin=radius / 2.0, particle=model)

    @property
    def spheres_per_particle(self) -> int:
        return len(self.sphere_offsets)

    #: The mesh that is lifted, and a line saying what the walls are.
    lifted_mesh = "plate"
    walls_comment = "carton: back wall, two side walls, end plate (meshes), infinite steel floor z = 0"
    title = "Angle of repose, plate withdrawal (source paper, Fig. 11), LIGGGHTS-PUBLIC 3.8"

    def meshes(self) -> dict:
        """Mesh name -> triangles (n, 3, 3) [m] of the walls (:func:`carton_meshes`)."""
        return carton_meshes(self)

    def __post_init__(self):
        positive = ("box_length", "box_width", "box_height", "plate_lift_speed",
                    "sphere_radius", "segment_diameter", "segment_length", "particle_density",
                    "particle_shear_modulus", "steel_shear_modulus", "time_step", "fill_time",
                    "insert_interval", "skin", "gravity", "thermo_interval")
        for name in positive:
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise InputError(f"ReposeCase.{name} must be a positive number [SI], got {value!r}")
        for name in ("restitution_pp", "restitution_ps"):
            value = getattr(self, name)
            if not 0.0 < value <= 1.0:
                raise InputError(f"ReposeCase.{name} must be in (0, 1], got {value!r}")
        for name in ("friction_pp", "friction_ps", "rolling_pp", "rolling_ps",
                     "plate_lift_start", "plate_clearance"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise InputError(f"ReposeCase.{name} must be >= 0, got {value!r}")
        for name in ("particle_poisson", "steel_poisson"):
            value = getattr(self, name)
            if not -1.0 < value < 0.5:
                raise InputError(f"ReposeCase.{name} must be in (-1, 0.5), got {value!r}")
        if int(self.n_segments) != self.n_segments or self.n_segments < 1:
            raise InputError(f"ReposeCase.n_segments must be a positive integer, got {self.n_segments!r}")
        if len(self.sphere_offsets) < 1:
            raise InputError("ReposeCase.sphere_offsets must list at least one sphere centre")
        xlo, xhi, ylo, yhi, zlo, zhi = self.fill_region
        half = self.clump_half_length
        if not (0.0 <= xlo and xhi <= self.box_length and 0.0 <= ylo and yhi <= self.box_width
                and 0.0 <= zlo and zhi <= self.box_height):
            raise InputError(f"ReposeCase.fill_region must lie inside the carton, got {self.fill_region!r}")
        if min(xhi - xlo, yhi - ylo, zhi - zlo) <= 2.0 * half:
            raise InputError(f"ReposeCase.fill_region {self.fill_region!r} is too small for a whole "
                             f"clump of bounding radius {half:.4g} m")

    # ---- derived quantities -------------------------------------------------------------
    @property
    def particle_youngs_modulus(self) -> float:
        """Segment Young's modulus from G and nu [Pa]."""
        return youngs_modulus(self.particle_shear_modulus, self.particle_poisson)

    @property
    def steel_youngs_modulus(self) -> float:
        """Steel Young's modulus from G and nu [Pa]."""
        return youngs_modulus(self.steel_shear_modulus, self.steel_poisson)

    @property
    def segment_mass(self) -> float:
        """Clump mass: the cylinder's [kg]."""
        return cylinder_mass_inertia(self.segment_diameter, self.segment_length, self.particle_density)[0]

    @property
    def segment_inertia(self) -> tuple:
        """Principal moments (axial, transverse, transverse) of the cylinder [kg m2]."""
        _, axial, transverse = cylinder_mass_inertia(self.segment_diameter, self.segment_length,
                                                     self.particle_density)
        return axial, transverse, transverse

    @property
    def clump_half_length(self) -> float:
        """Distance from the clump centre to its farthest surface point [m]."""
        if self.particle is not None:
            return float(self.particle.template.bounding_radius)
        return max(abs(o) for o in self.sphere_offsets) + self.sphere_radius

    @property
    def domain(self) -> tuple:
        """(xlo, xhi, ylo, yhi, zlo, zhi) of the LIGGGHTS box [m].

        Room for the heap beyond the open end, and for the raised plate above the carton;
        an atom leaving it is lost, which the runner reports.
        """
        L, W, H = self.box_length, self.box_width, self.box_height
        return (-0.02, L + 2.0 * L, -1.5 * W, 2.5 * W, -0.01, 2.0 * H + self.plate_clearance + 0.02)

    def steps(self, seconds: float) -> int:
        """Number of time steps covering ``seconds`` (nearest integer)."""
        return int(round(seconds / self.time_step))

    def settling_from(self) -> float:
        """Time [s] after which only the heap's settling remains: the lifted wall's lower edge
        past its top."""
        return self.plate_lift_start + self.box_height / self.plate_lift_speed

    def motion(self, label: str) -> tuple:
        """LIGGGHTS commands issued before and after the phase ``label``: the lifted wall's
        ``move/mesh`` during ``plate_lift``."""
        if label != "plate_lift":
            return (), ()
        return ((f"fix lift all move/mesh mesh {self.lifted_mesh} linear 0.0 0.0 {_g(self.plate_lift_speed)}",),
                ("unfix lift",))

    def phase_steps(self, duration: float) -> tuple:
        """The run split into (label, steps) phases: before, during and after the plate lift.

        ``fix move/mesh`` is issued when the plate starts to move and removed once its lower
        edge is ``plate_clearance`` above the carton; phases of zero length are left out.
        """
        total = self.steps(duration)
        start = min(self.steps(self.plate_lift_start), total)
        lift_time = (self.box_height + self.plate_clearance) / self.plate_lift_speed
        lift = min(self.steps(lift_time), total - start)
        phases = (("fill_and_settle", start), ("plate_lift", lift), ("heap_settle", total - start - lift))
        return tuple((label, n) for label, n in phases if n > 0)

    def to_dict(self) -> dict:
        d = asdict(replace(self, particle=None))
        if self.particle is not None:   # its contact fields are the export's inputs
            d["particle"] = {"shape": self.particle.params.shape.to_dict(),
                             "spheres": self.particle.spheres().tolist(), "mass": self.particle.template.mass,
                             "mass_model": self.particle.template.mass_model,
                             "rolling_lever": self.particle.params.rolling_lever}
        d.update(particle_youngs_modulus=self.particle_youngs_modulus,
                 steel_youngs_modulus=self.steel_youngs_modulus, domain=self.domain)
        if self.particle is None:   # the hand-written segment's cylinder
            d.update(segment_mass=self.segment_mass, segment_inertia=self.segment_inertia)
        return d


# ---- geometry ---------------------------------------------------------------------------
def _rectangle(a, b, c, d) -> np.ndarray:
    """Two triangles (a, b, c) and (a, c, d) of the planar quadrilateral a-b-c-d."""
    a, b, c, d = (np.asarray(p, dtype=float) for p in (a, b, c, d))
    return np.array([[a, b, c], [a, c, d]])


def carton_meshes(case: ReposeCase) -> dict:
    """Triangles of the carton walls, each a rectangle of two triangles [m].

    Returns
    -------
    dict
        ``back`` (x = 0), ``side_y0`` (y = 0), ``side_y1`` (y = W), ``plate`` (x = L, the end
        plate that is lifted); each an array of shape (2, 3, 3): triangle, vertex, xyz.
        The floor is the LIGGGHTS primitive plane z = 0, not a mesh.
    """
    L, W, H = case.box_length, case.box_width, case.box_height
    return {
        "back": _rectangle((0, 0, 0), (0, W, 0), (0, W, H), (0, 0, H)),
        "side_y0": _rectangle((0, 0, 0), (0, 0, H), (L, 0, H), (L, 0, 0)),
        "side_y1": _rectangle((0, W, 0), (L, W, 0), (L, W, H), (0, W, H)),
        "plate": _rectangle((L, 0, 0), (L, 0, H), (L, W, H), (L, W, 0)),
    }


@dataclass(frozen=True)
class CylinderCase(ReposeCase):
    """The lifting-cylinder repose test (``simulate.rigs.lifting_cylinder``): a tube of inside
    diameter ``box_length`` (= ``box_width``) and height ``box_height``, its axis at
    x = y = D/2, standing on the steel floor, filled, then lifted at ``plate_lift_speed`` from
    ``plate_lift_start`` until its rim is ``plate_clearance`` above its own height. The tube is
    a mesh of ``facets`` flat strips, inscribed in the circle (a 64-gon's radius at its flats is
    0.12 % short of the circle's)."""

    facets: int = 64

    lifted_mesh = "tube"
    walls_comment = "lifting cylinder: the tube (mesh), infinite steel floor z = 0"
    title = "Angle of repose, lifting cylinder, LIGGGHTS-PUBLIC 3.8"

    @classmethod
    def for_cylinder(cls, params, geometry, *, lift_start: float) -> "CylinderCase":
        """The case of any parameter set in the tube ``geometry``
        (``simulate.rigs.lifting_cylinder.CylinderGeometry``), filled as demcal fills it (the
        square inscribed in the tube, z 40-96 % of its height, over the first second), lifted
        from ``lift_start``."""
        from demcal.simulate.rigs.lifting_cylinder import CylinderGeometry

        if not isinstance(geometry, CylinderGeometry):
            raise InputError(f"geometry must be a CylinderGeometry, got {type(geometry).__name__}")
        g = geometry.filled_for(params.shape)
        base = ReposeCase.for_params(params)
        D, H = g.diameter, g.height
        half = (D / 2 - min(0.005, 0.05 * D)) / math.sqrt(2.0)
        fields = {f: getattr(base, f) for f in ReposeCase.__dataclass_fields__}
        fields.update(box_length=D, box_width=D, box_height=H, plate_lift_speed=g.lift_speed,
                      plate_lift_start=lift_start, n_segments=g.fill_count,
                      fill_region=(D / 2 - half, D / 2 + half, D / 2 - half, D / 2 + half, 0.4 * H, 0.96 * H))
        return cls(**fields)

    def meshes(self) -> dict:
        """The tube as ``facets`` strips of two triangles each, normals pointing inwards."""
        D, H = self.box_length, self.box_height
        phi = np.linspace(0.0, 2.0 * np.pi, self.facets + 1)
        x, y = D / 2 * (1 + np.cos(phi)), D / 2 * (1 + np.sin(phi))
        strips = [_rectangle((x[k], y[k], 0), (x[k], y[k], H), (x[k + 1], y[k + 1], H), (x[k + 1], y[k + 1], 0))
                  for k in range(self.facets)]
        return {"tube": np.concatenate(strips)}

    @property
    def domain(self) -> tuple:
        """Room for the cone on the floor around the tube and for the raised tube above."""
        D, H = self.box_length, self.box_height
        reach = 3.0 * D
        return (D / 2 - reach, D / 2 + reach, D / 2 - reach, D / 2 + reach, -0.01,
                2.0 * H + self.plate_clearance + 0.02)


def write_ascii_stl(path, triangles, name: str) -> Path:
    """Write triangles (n, 3, 3) [m] as an ASCII STL file; normals from the vertex order."""
    path = Path(path)
    tri = np.asarray(triangles, dtype=float)
    lines = [f"solid {name}"]
    for t in tri:
        n = np.cross(t[1] - t[0], t[2] - t[0])
        n = n / np.linalg.norm(n)
        lines.append(f"  facet normal {n[0]:.9g} {n[1]:.9g} {n[2]:.9g}")
        lines.append("    outer loop")
        lines.extend(f"      vertex {v[0]:.9g} {v[1]:.9g} {v[2]:.9g}" for v in t)
        lines.append("    endloop")
        lines.append("  endfacet")
    lines.append(f"endsolid {name}")
    path.write_text("\n".join(lines) + "\n")
    return path


def read_ascii_stl(path) -> np.ndarray:
    """Triangles (n, 3, 3) of an ASCII STL file."""
    vertices = [[float(v) for v in line.split()[1:4]]
                for line in Path(path).read_text().splitlines() if line.strip().startswith("vertex")]
    if not vertices or len(vertices) % 3:
        raise InputError(f"{path}: not an ASCII STL file with whole triangles")
    return np.array(vertices).reshape(-1, 3, 3)


# ---- the input script -------------------------------------------------------------------
def _g(x: float) -> str:
    return f"{x:.9g}"


def _segment_lines(case: ReposeCase, p_template: int, p_distribution: int) -> list:
    """Materials, contact model and template of the paper's segment, written by hand: a
    5-sphere clump with the mass and inertia of an 11 x 25 mm cylinder."""
    E_p, E_s = case.particle_youngs_modulus, case.steel_youngs_modulus
    i_ax, i_tr, _ = case.segment_inertia
    spheres = " ".join(f"{_g(o)} 0 0 {_g(case.sphere_radius)}" for o in case.sphere_offsets)

    def pair(pp, ps):  # 2 x 2 type-pair matrix; type 1 = segment, type 2 = steel
        return f"{_g(pp)} {_g(ps)} {_g(ps)} {_g(ps)}"

    return [
        "hard_particles  yes  # steel E = 2.08e11 Pa exceeds the SI default cap of 1e9 Pa",
        "",
        "# materials: type 1 = segment, type 2 = steel (floor and carton)",
        f"fix m1 all property/global youngsModulus peratomtype {_g(E_p)} {_g(E_s)}",
        f"fix m2 all property/global poissonsRatio peratomtype {_g(case.particle_poisson)} {_g(case.steel_poisson)}",
        f"fix m3 all property/global coefficientRestitution peratomtypepair 2 {pair(case.restitution_pp, case.restitution_ps)}",
        f"fix m4 all property/global coefficientFriction peratomtypepair 2 {pair(case.friction_pp, case.friction_ps)}",
        f"fix m5 all property/global coefficientRollingFriction peratomtypepair 2 {pair(case.rolling_pp, case.rolling_ps)}",
        "",
        'variable demcal_model string "model hertz tangential history rolling_friction cdt"',
        "pair_style      gran model hertz tangential history rolling_friction cdt",
        "pair_coeff      * *",
        "",
        "# segment: 5-sphere clump with the mass and inertia of an 11 x 25 mm cylinder",
        f"fix pts all particletemplate/multisphere {p_template} atom_type 1 "
        f"density constant {_g(case.particle_density)} nspheres {len(case.sphere_offsets)} "
        f"ntry {case.ntry} spheres {spheres} type 1 mass {_g(case.segment_mass)} "
        f"inertia_tensor {_g(i_ax)} 0 0 {_g(i_tr)} 0 {_g(i_tr)} use_volume",
        f"fix pdd all particledistribution/discrete {p_distribution} 1 pts 1.0",
        "fix ms all multisphere",
        "",
    ]


def render_script(case: ReposeCase, seed: int, duration: float = 10.0,
                  positions_file: str = POSITIONS_NAME, dump_interval: float | None = None) -> str:
    """The LIGGGHTS input script for ``case`` (meshes are read from the run folder).

    Parameters
    ----------
    case : ReposeCase
        Geometry, material and run parameters.
    seed : int
        Run seed; mapped to LIGGGHTS prime seeds by :func:`liggghts_seeds`.
    duration : float
        Simulated time [s].
    positions_file : str
        Where ``write_dump`` puts the final sphere positions (columns ``POSITION_COLUMNS``).
    dump_interval : float, optional
        If given, also dump all spheres every this many seconds to ``post/dump.*`` (for
        pictures; off for timing runs).
    """
    if not (math.isfinite(duration) and duration > 0):
        raise InputError(f"duration must be a positive number of seconds, got {duration!r}")
    p_template, p_distribution, p_insert = liggghts_seeds(seed)
    xlo, xhi, ylo, yhi, zlo, zhi = case.domain
    fx0, fx1, fy0, fy1, fz0, fz1 = case.fill_region
    every = max(case.steps(case.insert_interval), 1)
    thermo = max(case.steps(case.thermo_interval), 1)
    clump = case.spheres_per_particle > 1
    columns = POSITION_COLUMNS if clump else SPHERE_POSITION_COLUMNS

    names = tuple(case.meshes())
    out = [
        f"# {case.title}",
        f"# seed {seed}: LIGGGHTS seeds {p_template} {p_distribution} {p_insert}; duration {_g(duration)} s",
        "units           si",
        "atom_style      granular",
        "atom_modify     map array",
        "boundary        f f f",
        "newton          off",
        "communicate     single vel yes",
        f"region          domain block {_g(xlo)} {_g(xhi)} {_g(ylo)} {_g(yhi)} {_g(zlo)} {_g(zhi)} units box",
        "create_box      2 domain",
        f"neighbor        {_g(case.skin)} bin",
        "neigh_modify    delay 0",
    ]
    if case.particle is None:
        out += _segment_lines(case, p_template, p_distribution)
    else:   # demcal's own export of the material: the side-by-side tests the export too
        from demcal.simulate.export import liggghts_fragment
        out += ["", "# materials, contact model and particle: demcal's LIGGGHTS export",
                liggghts_fragment(case.particle, seed)]
    out += [
        f"timestep        {_g(case.time_step)}",
        f"fix gravi all gravity {_g(case.gravity)} vector 0.0 0.0 -1.0",
        "",
        f"# {case.walls_comment}",
    ]
    out += [f"fix {name} all mesh/surface file {name}.stl type 2" for name in names]
    out += [
        f"fix carton all wall/gran ${{demcal_model}} mesh n_meshes {len(names)} meshes {' '.join(names)}",
        "fix floor all wall/gran ${demcal_model} primitive type 2 zplane 0.0",
        "",
        f"region fill block {_g(fx0)} {_g(fx1)} {_g(fy0)} {_g(fy1)} {_g(fz0)} {_g(fz1)} units box",
        f"fix ins all insert/rate/region seed {p_insert} distributiontemplate pdd "
        f"nparticles {case.n_segments} particlerate {_g(case.n_segments / case.fill_time)} "
        f"insert_every {every} overlapcheck yes all_in yes orientation random "
        "vel constant 0.0 0.0 0.0 region fill",
        "",
        "compute tke all ke/multisphere" if clump else "compute tke all ke",
        "compute rke all erotate/multisphere" if clump else "compute rke all erotate/sphere",
        "thermo_style    custom step atoms c_tke c_rke cpu",
        f"thermo          {thermo}",
        "thermo_modify   lost ignore norm no",
    ]
    if dump_interval:
        out.append(f"dump snap all custom {max(case.steps(dump_interval), 1)} post/dump.* "
                   f"{' '.join(columns)}")
        out.append(f"dump_modify snap format {POSITION_FORMAT}")
    for label, n in case.phase_steps(duration):
        before, after = case.motion(label)
        out.append("")
        out += list(before)
        out.append(f"# phase {label}")
        out.append(f"run             {n}")
        out += list(after)
    out += ["", f"write_dump all custom {positions_file} {' '.join(columns)} "
                f"modify format {POSITION_FORMAT}", ""]
    return "\n".join(out)


@dataclass(frozen=True)
class Deck:
    """A written run folder.

    Attributes
    ----------
    workdir : Path
        The run folder; LIGGGHTS runs with it as working directory.
    script : Path
        The input script.
    meshes : dict
        Mesh name -> STL path.
    positions_file, log_file : Path
        Where LIGGGHTS writes the final positions and its log.
    seed : int
        The run seed; ``liggghts_seeds`` the primes it maps to.
    liggghts_seeds : tuple of int
    duration : float
        Simulated time [s].
    n_steps : int
        Total time steps.
    phases : tuple
        (label, steps) of each ``run`` command, in order.
    case : ReposeCase
    """

    workdir: Path
    script: Path
    meshes: dict
    positions_file: Path
    log_file: Path
    seed: int
    liggghts_seeds: tuple
    duration: float
    n_steps: int
    phases: tuple
    case: ReposeCase = field(repr=False)

    def to_dict(self) -> dict:
        return {"workdir": str(self.workdir), "script": str(self.script),
                "meshes": {k: str(v) for k, v in self.meshes.items()},
                "positions_file": str(self.positions_file), "log_file": str(self.log_file),
                "seed": self.seed, "liggghts_seeds": list(self.liggghts_seeds),
                "duration": self.duration, "n_steps": self.n_steps,
                "phases": [list(p) for p in self.phases], "case": self.case.to_dict()}


def write_deck(workdir, seed: int, duration: float = 10.0, case: ReposeCase | None = None,
               dump_interval: float | None = None) -> Deck:
    """Write the input script and the carton meshes into ``workdir``.

    Parameters
    ----------
    workdir : path-like
        Run folder (created if missing).
    seed : int
        Run seed (non-negative integer).
    duration : float
        Simulated time [s]; 10 s in the paper.
    case : ReposeCase, optional
        Defaults to the paper's case with its calibrated parameters.
    dump_interval : float, optional
        Periodic dumps every this many seconds into ``workdir/post`` (off by default).

    Returns
    -------
    Deck
    """
    case = ReposeCase() if case is None else case
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    if dump_interval:
        (workdir / "post").mkdir(exist_ok=True)
    meshes = {name: write_ascii_stl(workdir / f"{name}.stl", tri, name)
              for name, tri in case.meshes().items()}
    script = workdir / SCRIPT_NAME
    script.write_text(render_script(case, seed, duration, POSITIONS_NAME, dump_interval))
    phases = case.phase_steps(duration)
    return Deck(workdir=workdir, script=script, meshes=meshes,
                positions_file=workdir / POSITIONS_NAME, log_file=workdir / LOG_NAME,
                seed=int(seed), liggghts_seeds=liggghts_seeds(seed), duration=float(duration),
                n_steps=sum(n for _, n in phases), phases=phases, case=case)
