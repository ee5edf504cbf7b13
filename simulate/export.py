"""Calibrated parameters out to other DEM codes: LIGGGHTS-PUBLIC, Yade, EDEM and JSON.

``export_model(params, source)`` gathers what every target needs: the two materials (segment
and steel), the three interactions (particle-particle, particle-wall) and the segment's clump
template (sphere centres in the principal frame, radii, mass, principal moments), as demcal
simulates them. ``render(model, target)`` writes it in the target's terms:

``liggghts``
    An input fragment for LIGGGHTS-PUBLIC 3.8, to include after ``create_box`` with two atom
    types (1 = segment, 2 = steel): ``hard_particles``, the ``fix property/global`` blocks, the
    ``pair_style gran`` of demcal's contact and rolling model, and the multisphere template
    with the mass and inertia demcal uses.
``yade``
    A Python snippet for Yade: the two ``FrictMat`` materials, the Hertz-Mindlin engines with
    the restitutions and frictions of each material pair, and a clump factory with the same
    spheres, mass and inertia.
``edem``
    A CSV in EDEM's terms: materials, interactions (Hertz-Mindlin no slip, standard rolling
    friction) and the particle template's spheres.
``json``
    The whole parameter set with provenance.

Rolling friction. The constant-torque model T = mu_r F_n R_lever has the same mu_r only for the
same lever R_lever (``simulate.contact.rolling``). Each export states the lever of demcal's run
and of the target. Where they differ, mu_r is converted so that the torque is kept on average
over the contacts a segment can make (``rolling_conversion``): exact when the levers are in a
fixed ratio at every contact (e.g. a single sphere), an average otherwise (a clump under EDEM's
lever, the distance from the contact point to the centre of mass, which runs from the sphere
radius at the middle sphere to the half length at the tips), and the export says which.

Engine hooks of demcal that the target codes lack (velocity-dependent restitution, a size
distribution, the contact effective mass) are listed in every export as not carried over.
When the critique accepted such an extension and recalibrated with it
(``ExportModel.accepted``), the export keeps the set calibrated without it, which is what the
target can run (its values compensate for what the target cannot express), says so, and gives
the set calibrated with it beside it.

The material name comes from the workbook and the results file's name from the command line:
the JSON keeps them exact, the other formats write them as one line (``demcal.text.one_line``)
in a comment, without the characters LIGGGHTS acts on there, and as CSV cells no spreadsheet
runs as a formula.
"""

from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import dataclass, field

import numpy as np

from demcal.errors import InputError
from demcal.jsonio import to_jsonable
from demcal.simulate.clump import ClumpTemplate
from demcal.simulate.contact.rolling import ROLLING_LEVERS
from demcal.simulate.extensions import ENGINE_HOOKS, describe, engine_hooks
from demcal.simulate.materials import youngs_modulus
from demcal.simulate.params import DEMParameters
from demcal.text import no_formula, one_line

#: Formats ``demcal export --to`` writes, and the file each writes by default.
EXPORT_FILES = {"liggghts": "liggghts_materials.in", "yade": "yade_materials.py",
                "edem": "edem_materials.csv", "json": "parameters.json"}

#: Rolling lever of each target code's constant-torque model (``ROLLING_LEVERS`` names):
#: LIGGGHTS ``rolling_friction cdt`` takes R_eff, EDEM's standard rolling friction the
#: distance from the contact point to the centre of mass. Yade's Hertz-Mindlin law has none.
TARGET_LEVER = {"liggghts": "liggghts_reff", "edem": "edem_com", "yade": None, "json": None}

#: demcal engine hooks (``simulate.extensions.ENGINE_HOOKS``) each target expresses itself:
#: LIGGGHTS has the spring-dashpot rolling model (``rolling_friction epsd``); the JSON is demcal's own.
TARGET_HOOKS = {"liggghts": frozenset({"rolling_spring_dashpot"}), "yade": frozenset(), "edem": frozenset(),
                "json": frozenset(ENGINE_HOOKS)}

#: Names of the target codes in sentences.
TARGET_NAMES = {"liggghts": "LIGGGHTS", "yade": "Yade", "edem": "EDEM"}

#: LIGGGHTS refuses a Young's modulus above this without ``hard_particles yes`` [Pa].
LIGGGHTS_SOFT_LIMIT_PA = 1e9
#: LIGGGHTS refuses a Young's modulus below this in SI units unless told ``soft_particles yes``
#: (src/global_properties.cpp): a seed of shear modulus 1 MPa is below it.
LIGGGHTS_HARD_LIMIT_PA = 5e6

#: Points per sphere of the surface sample that averages a clump's rolling lever.
LEVER_SAMPLE = 4000

#: Characters LIGGGHTS' input parser acts on: ``&`` at the end of a line joins the next line to
#: it (even to a comment), ``$`` substitutes a variable.
_LIGGGHTS_SPECIAL = str.maketrans({"&": " ", "$": " "})


def liggghts_seeds(seed: int) -> tuple:
    """Three distinct primes above 10000 derived from ``seed`` (LIGGGHTS wants its random seeds
    prime and larger than 10000); each seed has its own block of 30000 integers."""
    if isinstance(seed, bool) or int(seed) != seed or seed < 0:
        raise InputError(f"seed must be a non-negative integer, got {seed!r}")

    def is_prime(n):
        return n % 2 and all(n % k for k in range(3, math.isqrt(n) + 1, 2))

    primes = []
    for k in range(3):
        n = 100_003 + 30_000 * int(seed) + 10_000 * k
        while not is_prime(n):
            n += 1
        primes.append(n)
    return tuple(primes)


@dataclass(frozen=True)
class RollingConversion:
    """mu_r of one interaction carried from demcal's lever to a target's.

    Attributes
    ----------
    interaction : str
        ``particle-particle`` or ``particle-wall``.
    source_lever, target_lever : str
        ``ROLLING_LEVERS`` names (target None: the target has no constant-torque model).
    factor : float
        mu_r(target) = factor x mu_r(demcal): mean source lever over mean target lever.
    exact : bool
        The levers are in the same ratio at every contact, so the torque is kept at each.
    ratio_range : tuple of float
        Smallest and largest source / target lever over the contacts [-].
    """

    interaction: str
    source_lever: str
    target_lever: str | None
    factor: float
    exact: bool
    ratio_range: tuple

    def statement(self) -> str:
        if self.target_lever is None:
            return (f"{self.interaction}: the target has no constant-torque rolling friction; "
                    f"demcal's mu_r (lever {self.source_lever}) is not carried over")
        if self.source_lever == self.target_lever:
            return f"{self.interaction}: same lever ({self.source_lever}), mu_r unchanged (exact)"
        lo, hi = self.ratio_range
        how = ("exact: the levers are in a fixed ratio at every contact" if self.exact else
               f"not exact: the lever ratio runs from {lo:.3g} to {hi:.3g} over the segment's "
               "contacts, so the torque is kept on average only")
        text = (f"{self.interaction}: mu_r x {self.factor:.4g} from lever {self.source_lever} to "
                f"{self.target_lever} ({how})")
        if self.interaction == "particle-particle" and "liggghts_reff" in (self.source_lever, self.target_lever):
            # LIGGGHTS' pair torque opposes the relative rotation, EDEM's each body's own
            text += ("; the torque's direction differs too: w_i - w_j in LIGGGHTS, each body's "
                     "own w in EDEM")
        return text


def _surface_points(template: ClumpTemplate, rng) -> tuple:
    """Points spread evenly over the clump's outer surface (principal frame) and the radius of
    the sphere each lies on: where a contact can touch the segment."""
    points, radii = [], []
    for c, r in zip(template.offsets, template.radii):
        n = rng.normal(size=(LEVER_SAMPLE, 3))
        p = c + r * n / np.linalg.norm(n, axis=1, keepdims=True)
        inside = np.zeros(len(p), bool)
        for c2, r2 in zip(template.offsets, template.radii):
            if not np.array_equal(c2, c):
                inside |= np.linalg.norm(p - c2, axis=1) < r2 * (1.0 - 1e-12)
        points.append(p[~inside])
        radii.append(np.full((~inside).sum(), r))
    return np.concatenate(points), np.concatenate(radii)


def _levers(convention: str, interaction: str, points, radii) -> np.ndarray:
    """Lever [m] of ``convention`` at contacts on the given surface points (no overlap): R_eff
    between two equal segments' spheres (R/2) or R against a wall (``liggghts_reff``), the
    sphere radius (``edem_sphere``), the distance to the centre of mass (``edem_com``)."""
    if convention == "liggghts_reff":
        return radii / 2.0 if interaction == "particle-particle" else radii.copy()
    if convention == "edem_sphere":
        return radii.copy()
    if convention == "edem_com":
        return np.linalg.norm(points, axis=1)
    raise InputError(f"unknown rolling_lever {convention!r}; valid: {', '.join(ROLLING_LEVERS)}")


def rolling_conversion(params: DEMParameters, template: ClumpTemplate, target: str) -> tuple:
    """``RollingConversion`` of each interaction from ``params.rolling_lever`` to ``target``'s.

    The lever is averaged over points spread evenly on the segment's outer surface (a fixed
    sample, so the export is reproducible); the conversion is exact when source / target lever
    is the same at every point.
    """
    points, radii = _surface_points(template, np.random.default_rng(0))
    out = []
    for interaction in ("particle-particle", "particle-wall"):
        target_lever = TARGET_LEVER[target]
        if target_lever is None:
            out.append(RollingConversion(interaction, params.rolling_lever, None, math.nan, False,
                                         (math.nan, math.nan)))
            continue
        src = _levers(params.rolling_lever, interaction, points, radii)
        tgt = _levers(target_lever, interaction, points, radii)
        ratio = src / tgt
        out.append(RollingConversion(interaction, params.rolling_lever, target_lever,
                                     float(src.mean() / tgt.mean()),
                                     bool(np.ptp(ratio) <= 1e-9 * ratio.mean()),
                                     (float(ratio.min()), float(ratio.max()))))
    return tuple(out)


@dataclass(frozen=True)
class ExportModel:
    """A calibrated parameter set as every export needs it.

    Attributes
    ----------
    params : DEMParameters
    template : ClumpTemplate
        The segment's clump (spheres in the principal frame: ``template.offsets``).
    material : str
        Name of the bulk material, from the workbook: the JSON keeps it exact, the other
        formats write it as one line safe in their syntax.
    source : dict
        Provenance: the results file and its SHA-256, the code version.
    intervals : dict
        Parameter -> 95 % plausible interval of the calibration (empty when it has none).
    accepted : tuple of CalibratedWith
        Extensions the critique accepted and recalibrated with; ``params`` is the set
        calibrated without them.
    """

    params: DEMParameters
    template: ClumpTemplate
    material: str = "segment"
    source: dict = field(default_factory=dict)
    intervals: dict = field(default_factory=dict)
    accepted: tuple = ()

    @property
    def youngs_moduli(self) -> tuple:
        """(segment, steel) Young's moduli [Pa]."""
        p = self.params
        return (youngs_modulus(p.shear_modulus_pa, p.poisson_ratio),
                youngs_modulus(p.wall_shear_modulus_pa, p.wall_poisson_ratio))

    def untransferred_hooks(self, target: str) -> list:
        """demcal engine hooks in use that ``target`` has no equivalent of (LIGGGHTS has the
        spring-dashpot rolling model, ``rolling_friction epsd``)."""
        return [h["extension"] for h in engine_hooks(self.params) if not expresses(target, h["extension"])]

    def spheres(self) -> np.ndarray:
        """(x, y, z, r) of each sphere in the principal frame [m], rounding noise removed."""
        xyz = np.where(np.abs(self.template.offsets) < 1e-12, 0.0, self.template.offsets)
        return np.column_stack([xyz, self.template.radii])


def expresses(target: str, extension: str) -> bool:
    """Whether ``target`` can run demcal's model ``extension``: an engine hook it has an
    equivalent of, or an extension that only sets parameter values (any code takes those)."""
    return extension not in ENGINE_HOOKS or extension in TARGET_HOOKS.get(target, frozenset())


@dataclass(frozen=True)
class CalibratedWith:
    """A model extension the critique accepted and the calibration with it
    (``analyse.critique.heap_gain.HeapGain``).

    Attributes
    ----------
    extension, mechanism : str
    settings : dict
        The ``DEMParameters`` fields that switch it on.
    campaign : str
        Folder of the recalibration, relative to the campaign.
    parameters : dict
        Calibrated parameter -> (value with the extension, its 95 % interval or None).
    """

    extension: str
    mechanism: str
    settings: dict
    campaign: str
    parameters: dict

    def __post_init__(self):
        describe(self.extension)                    # a known extension, else refused by name
        unknown = sorted(set(self.parameters) - set(DEMParameters.names()))
        if unknown:
            raise InputError(f"extension {self.extension}: unknown DEM parameter(s) {', '.join(unknown)}")

    def statements(self, target: str, params: DEMParameters) -> list:
        """Lines for ``target``'s export: whether it can run the extension, and the parameters
        calibrated without it (the export's values) and with it, one per line."""
        name = TARGET_NAMES.get(target, target)
        head = (f"The critique accepted model extension {self.extension} "
                f"({_text(self.mechanism, target)}); {name} "
                + ("expresses it." if expresses(target, self.extension) else
                   f"cannot express it: the values below are calibrated without it and compensate for "
                   f"it, which is what {name} needs."))
        lines = [head, f"  parameter: calibrated without it (exported) -> with it, for demcal "
                       f"({_text(self.campaign, target)})"]
        for n, (v, ci) in self.parameters.items():
            lines.append(f"  {n}: {_g(getattr(params, n))} -> {_g(v)}"
                         + ("" if ci is None else f" [{_g(ci[0])}, {_g(ci[1])}]"))
        return lines

    def to_dict(self) -> dict:
        return {"extension": self.extension, "mechanism": self.mechanism, "settings": dict(self.settings),
                "campaign": self.campaign,
                "calibrated_with": {n: {"value": v, "ci95": None if ci is None else list(ci)}
                                    for n, (v, ci) in self.parameters.items()},
                "expressed_by": {t: expresses(t, self.extension) for t in TARGET_NAMES}}


def export_model(params: DEMParameters, *, material: str = "segment", source: dict | None = None,
                 intervals: dict | None = None, accepted=()) -> ExportModel:
    """The ``ExportModel`` of a parameter set (the segment template built as demcal builds it);
    ``accepted``: the ``CalibratedWith`` of each extension the critique accepted."""
    if not isinstance(params, DEMParameters):
        raise InputError(f"params must be a DEMParameters, got {type(params).__name__}")
    # the template of the mean segment; a size distribution is listed as not carried over
    template = params.template()
    return ExportModel(params, template, material, dict(source or {}), dict(intervals or {}), tuple(accepted))


# ---------------------------------------------------------------------------------------------
# the formats

def _g(x: float) -> str:
    return f"{x:.9g}"


def _text(text, target: str) -> str:
    """Untrusted text (the material name, a file name) as it may stand in a comment of
    ``target``'s file: one line, and for LIGGGHTS without ``&`` and ``$``."""
    if target == "liggghts":
        text = str(text).translate(_LIGGGHTS_SPECIAL)
    return one_line(text)


def _header(model: ExportModel, target: str, title: str, comment: str) -> list:
    """Lines every export opens with: what it is, where it came from, the rolling convention
    and what does not carry over."""
    src = model.source
    lines = [f"demcal export of the calibrated {_text(model.material, target)} parameters for {title}",
             f"source: {_text(src.get('file', 'parameters given directly'), target)}"
             + (f" (sha256 {src['sha256']})" if src.get("sha256") else ""),
             f"code: demcal {src.get('code', {}).get('demcal', '?')}, git {src.get('code', {}).get('git_sha')}",
             "units: SI (m, kg, s, Pa)",
             f"rolling friction: demcal's lever is {model.params.rolling_lever} "
             f"(model {model.params.rolling_model})"]
    lines += ["  " + c.statement() for c in rolling_conversion(model.params, model.template, target)]
    for hook in model.untransferred_hooks(target):
        lines.append(f"NOT carried over: demcal engine hook {hook} (the target has no equivalent)")
    for accepted in model.accepted:
        lines += accepted.statements(target, model.params)
    return [f"{comment} {line}".rstrip() for line in lines]


def _interactions(model: ExportModel, target: str) -> dict:
    """(restitution, static friction, rolling friction in the target's convention) per
    interaction."""
    p = model.params
    conv = {c.interaction: c for c in rolling_conversion(p, model.template, target)}

    def rolling(inter, mu):
        c = conv[inter]
        return mu if c.target_lever is None else mu * c.factor

    return {"particle-particle": (p.e_pp, p.mu_s_pp, rolling("particle-particle", p.mu_r_pp)),
            "particle-wall": (p.e_pw, p.mu_s_pw, rolling("particle-wall", p.mu_r_pw))}


def liggghts_fragment(model: ExportModel, seed: int = 0) -> str:
    """LIGGGHTS-PUBLIC 3.8 input lines for the materials, contact model and segment template.

    Include after ``create_box 2 ...`` (type 1 = the particle, type 2 = steel). The template is
    ``fix pts``, its distribution ``fix pdd`` (for ``fix insert/...``), and ``fix ms`` the
    multisphere integrator; a one-sphere particle gets LIGGGHTS' sphere template at the density
    that gives demcal's mass, and ``fix integr`` (``nve/sphere``). Walls use the same model string: ``fix ID all wall/gran
    ${demcal_model} primitive type 2 zplane 0.0`` or ``... mesh n_meshes 1 meshes M``.
    """
    p = model.params
    e_p, e_s = model.youngs_moduli
    inter = _interactions(model, "liggghts")
    rolling = "epsd" if p.rolling_model == "epsd" else "cdt"
    p_template, p_distribution, _ = liggghts_seeds(seed)

    def pair(k):  # 2 x 2 type-pair matrix: the steel-steel entry is unused
        pp, pw = inter["particle-particle"][k], inter["particle-wall"][k]
        return f"{_g(pp)} {_g(pw)} {_g(pw)} {_g(pw)}"

    i1, i2, i3 = model.template.principal_moments
    spheres = " ".join(" ".join(_g(v) for v in row) for row in model.spheres())
    out = _header(model, "liggghts", "LIGGGHTS-PUBLIC 3.8", "#")
    out += [""]
    if max(e_p, e_s) > LIGGGHTS_SOFT_LIMIT_PA:
        out.append(f"hard_particles yes  # E up to {_g(max(e_p, e_s))} Pa exceeds LIGGGHTS' default limit of 1e9 Pa")
    if min(e_p, e_s) < LIGGGHTS_HARD_LIMIT_PA:
        out.append(f"soft_particles yes  # E down to {_g(min(e_p, e_s))} Pa is below LIGGGHTS' default limit of 5e6 Pa")
    out += [
        f"fix m1 all property/global youngsModulus peratomtype {_g(e_p)} {_g(e_s)}",
        f"fix m2 all property/global poissonsRatio peratomtype {_g(p.poisson_ratio)} {_g(p.wall_poisson_ratio)}",
        f"fix m3 all property/global coefficientRestitution peratomtypepair 2 {pair(0)}",
        f"fix m4 all property/global coefficientFriction peratomtypepair 2 {pair(1)}",
        f"fix m5 all property/global coefficientRollingFriction peratomtypepair 2 {pair(2)}",
    ]
    if rolling == "epsd":
        eta = _g(p.rolling_damping_ratio)
        out.append(f"fix m6 all property/global coefficientRollingViscousDamping peratomtypepair 2 "
                   f"{eta} {eta} {eta} {eta}")
    out += [
        "",
        f"variable demcal_model string \"model hertz tangential history rolling_friction {rolling}\"",
        "pair_style      gran ${demcal_model}",
        "pair_coeff      * *",
        "",
    ]
    if model.template.n_spheres == 1:
        # one sphere: LIGGGHTS' own sphere template, at the density that gives demcal's mass
        r = float(model.template.radii[0])
        out += [f"# the particle: {_shape_words(model)}, with demcal's mass ({model.template.mass_model})",
                f"fix pts all particletemplate/sphere {p_template} atom_type 1 density constant "
                f"{_g(model.template.mass / (4.0 / 3.0 * math.pi * r ** 3))} radius constant {_g(r)}",
                f"fix pdd all particledistribution/discrete {p_distribution} 1 pts 1.0",
                "fix integr all nve/sphere", ""]
        return "\n".join(out)
    out += [
        f"# the particle: {_shape_words(model)}; {len(model.template.radii)} spheres in its principal frame, "
        f"with demcal's mass ({model.template.mass_model}) and principal moments",
        f"fix pts all particletemplate/multisphere {p_template} atom_type 1 density constant "
        f"{_g(p.particle_density_kg_m3)} nspheres {len(model.template.radii)} ntry 1000000 spheres {spheres} "
        f"type 1 mass {_g(model.template.mass)} inertia_tensor {_g(i1)} 0 0 {_g(i2)} 0 {_g(i3)} use_volume",
        f"fix pdd all particledistribution/discrete {p_distribution} 1 pts 1.0",
        "fix ms all multisphere",
        "",
    ]
    return "\n".join(out)


def _shape_words(model: ExportModel) -> str:
    """The DEM particle in words, as one comment-safe line."""
    return one_line(model.params.shape.describe())


def yade_snippet(model: ExportModel) -> str:
    """A Python snippet for Yade: materials, Hertz-Mindlin engines and a clump factory."""
    p = model.params
    e_p, e_s = model.youngs_moduli
    inter = _interactions(model, "yade")
    (e_pp, mu_pp, _), (e_pw, mu_pw, _) = inter["particle-particle"], inter["particle-wall"]
    spheres = ",\n    ".join(f"(({_g(x)}, {_g(y)}, {_g(z)}), {_g(r)})" for x, y, z, r in model.spheres())
    i1, i2, i3 = model.template.principal_moments
    # declared first, so that no text of the header can declare another encoding (PEP 263)
    out = ["# -*- coding: utf-8 -*-", *_header(model, "yade", "Yade", "#")]
    out += [
        "# Hertz-Mindlin: Ip2_FrictMat_FrictMat_MindlinPhys with the restitution en of each",
        "# material pair and Law2_ScGeom_MindlinPhys_Mindlin; the friction angle of each pair is",
        "# atan(mu_s). Yade's Mindlin law has no constant-torque rolling friction (see above).",
        "import math",
        "from yade import *",
        "",
        f"particle = O.materials.append(FrictMat(young={_g(e_p)}, poisson={_g(p.poisson_ratio)}, "
        f"density={_g(p.particle_density_kg_m3)}, frictionAngle=math.atan({_g(mu_pp)}), label='particle'))",
        f"steel = O.materials.append(FrictMat(young={_g(e_s)}, poisson={_g(p.wall_poisson_ratio)}, "
        f"density={_g(p.wall_density_kg_m3)}, frictionAngle=math.atan({_g(mu_pw)}), label='steel'))",
        "",
        "O.engines = [",
        "    ForceResetter(),",
        "    InsertionSortCollider([Bo1_Sphere_Aabb(), Bo1_Facet_Aabb(), Bo1_Box_Aabb()]),",
        "    InteractionLoop(",
        "        [Ig2_Sphere_Sphere_ScGeom(), Ig2_Facet_Sphere_ScGeom(), Ig2_Box_Sphere_ScGeom()],",
        "        [Ip2_FrictMat_FrictMat_MindlinPhys(",
        f"            en=MatchMaker(matches=((particle, particle, {_g(e_pp)}), (particle, steel, {_g(e_pw)}))),",
        f"            es=MatchMaker(matches=((particle, particle, {_g(e_pp)}), (particle, steel, {_g(e_pw)}))),",
        "            frictAngle=MatchMaker(matches=((particle, particle, math.atan("
        f"{_g(mu_pp)})), (particle, steel, math.atan({_g(mu_pw)})))))],",
        "        [Law2_ScGeom_MindlinPhys_Mindlin()]),",
        "    NewtonIntegrator(gravity=(0, 0, -9.81), damping=0.0),",
        "]",
        "",
        "# the particle: spheres (centre, radius) in its principal frame [m]",
        f"PARTICLE_SPHERES = [\n    {spheres},\n]",
        f"PARTICLE_MASS = {_g(model.template.mass)}  # kg, demcal's ({model.template.mass_model})",
        f"PARTICLE_INERTIA = ({_g(i1)}, {_g(i2)}, {_g(i3)})  # kg m2, principal",
        "",
        "",
        "def add_particle(position, orientation=Quaternion((1, 0, 0), 0)):",
        "    \"\"\"Append one particle clump at ``position`` with demcal's mass and inertia.\"\"\"",
        "    members = [sphere(position + orientation * Vector3(*c), r, material=particle)",
        "               for c, r in PARTICLE_SPHERES]",
        "    clump_id, member_ids = O.bodies.appendClumped(members)",
        "    state = O.bodies[clump_id].state",
        "    state.mass, state.inertia = PARTICLE_MASS, Vector3(*PARTICLE_INERTIA)",
        "    # Yade's Hertz-Mindlin dashpot takes the touching member's mass; demcal's (and",
        "    # LIGGGHTS') the whole particle's. The clump moves with its own mass and inertia.",
        "    for i in member_ids:",
        "        O.bodies[i].state.mass = PARTICLE_MASS",
        "    return clump_id",
        "",
    ]
    return "\n".join(out)


def edem_table(model: ExportModel) -> str:
    """A CSV in EDEM's terms: one section each for materials, interactions and the template."""
    p = model.params
    inter = _interactions(model, "edem")
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    for line in _header(model, "edem", "EDEM (Hertz-Mindlin no slip, standard rolling friction)", "#"):
        w.writerow([line])       # one cell: a comma or quote in the text cannot add a field
    name = one_line(model.material)
    w.writerow(["section", "name", "Poisson's ratio", "Shear Modulus (Pa)", "Density (kg/m3)"])
    w.writerow(["material", no_formula(name), _g(p.poisson_ratio), _g(p.shear_modulus_pa),
                _g(p.particle_density_kg_m3)])
    w.writerow(["material", "steel", _g(p.wall_poisson_ratio), _g(p.wall_shear_modulus_pa),
                _g(p.wall_density_kg_m3)])
    w.writerow(["section", "interaction", "Coefficient of Restitution", "Coefficient of Static Friction",
                "Coefficient of Rolling Friction"])
    names = {"particle-particle": no_formula(f"{name}-{name}"), "particle-wall": no_formula(f"{name}-steel")}
    for key, (e, mu_s, mu_r) in inter.items():
        w.writerow(["interaction", names[key], _g(e), _g(mu_s), _g(mu_r)])
    w.writerow(["section", "sphere", "X (m)", "Y (m)", "Z (m)", "Radius (m)"])
    for k, row in enumerate(model.spheres()):
        w.writerow(["template", k + 1, *(_g(v) for v in row)])
    i1, i2, i3 = model.template.principal_moments
    w.writerow(["section", "property", "value"])
    w.writerow(["template", "Mass (kg)", _g(model.template.mass)])
    w.writerow(["template", "Moment of inertia Ixx Iyy Izz (kg m2)", f"{_g(i1)} {_g(i2)} {_g(i3)}"])
    return buf.getvalue()


def json_document(model: ExportModel) -> dict:
    """The whole parameter set with provenance, the template and the rolling conventions."""
    e_p, e_s = model.youngs_moduli
    return {"material": model.material, "parameters": model.params.to_dict(),
            "intervals_95": model.intervals,
            "youngs_modulus_pa": {"particle": e_p, "wall": e_s},
            "template": {"spheres_xyzr_m": model.spheres().tolist(), "mass_kg": model.template.mass,
                         "principal_moments_kg_m2": list(map(float, model.template.principal_moments)),
                         "mass_model": model.template.mass_model, "frame": "principal axes, origin at the centre of mass"},
            "rolling": {"lever": model.params.rolling_lever, "model": model.params.rolling_model,
                        "for_targets": {t: [c.statement() for c in rolling_conversion(model.params, model.template, t)]
                                        for t in ("liggghts", "edem", "yade")}},
            "engine_hooks": engine_hooks(model.params),
            "accepted_extensions": [a.to_dict() for a in model.accepted],
            "source": model.source}


def render(model: ExportModel, target: str) -> str:
    """The export of ``model`` for ``target`` (a key of ``EXPORT_FILES``) as text."""
    if target == "liggghts":
        return liggghts_fragment(model)
    if target == "yade":
        return yade_snippet(model)
    if target == "edem":
        return edem_table(model)
    if target == "json":
        return json.dumps(to_jsonable(json_document(model)), indent=2) + "\n"
    raise InputError(f"unknown export format {target!r}; valid: {', '.join(EXPORT_FILES)}")
