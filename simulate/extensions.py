"""Model extensions: switchable changes of the DEM model that the critique loop proposes.

Each extension answers a mechanism of the critique catalogue (``analyse.critique.mechanisms``)
and is recorded, by name and settings, in the provenance of every run that uses it
(:func:`describe`). Four of them are engine hooks switched by ``DEMParameters`` fields
(``ENGINE_HOOKS``), so they are recorded with the parameters of every run as well;
:func:`engine_hooks` names those a parameter set switches on, :func:`with_velocity_restitution`,
:func:`with_spring_dashpot_rolling`, :func:`with_size_distribution` and
:func:`with_contact_effective_mass` switch them on.
``EXTENSIONS`` lists them all:

``velocity_dependent_restitution``
    e falls with impact speed. :func:`fit_velocity_restitution` fits the power law
    e(v) = e_ref (v / v_ref)^(-n) to drops from several heights (Johnson 1985, sec. 11.5:
    n = 1/4 for fully plastic impacts). Engine hook (``e_pp_exponent``, ``e_pp_v_ref``,
    ``e_pw_exponent``, ``e_pw_v_ref``): each contact takes e(v) at its normal approach speed
    at first touch, kept in its history, for its whole duration
    (``simulate.contact.hertz_mindlin``), in every rig and in heaps.
    :func:`parameters_for_impact` instead sets the constant e of a single-impact twin (the
    drop rig) to e(v) at its impact speed, which is the same for one impact of known speed.
``inverted_restitution``
    The contact restitution that makes the drop twin reproduce the measured apparent
    restitution: an elongated body turns part of its energy into rotation, so sqrt(h2/h1) is
    not the contact restitution. :func:`invert_drop_twin` solves twin(e) = measured.
``size_distribution``
    Particles drawn from the calliper size distribution (:class:`SizeDistribution`): a twin
    of one trial uses its own specimen's sizes (:func:`particle_of_size`); a heap draws each
    particle from the measured sizes (engine hook ``particle_sizes``: a particle factory with
    one template per size, ``simulate.scenes.build_paper_repose_case``).
``more_spheres``
    More spheres per clump (:func:`with_more_spheres`): a smoother surface, closer to the
    cylinder's volume and inertia (:func:`surface_ripple`).
``contact_effective_mass``
    The Hertz-Mindlin dashpot of a multi-sphere body is set, as in LIGGGHTS and EDEM, with the
    mass of the whole body, while a contact moves only the body's effective mass there: for
    one contact of lever a from the centre of mass and normal n, 1 / (1/m + (a x n) . I^-1
    (a x n)) (Stronge 2000, ch. 3), and m / n for each of n contacts pressing together. Every
    off-centre or shared contact so dissipates as if overdamped: a segment landing flat on its
    n spheres rebounds far below the contact restitution (the glued-sphere damping of Kodam et
    al. 2010), and one striking a frictionless plate with an end sphere at 10 deg leaves it at
    -0.40 times its impact velocity where rigid-body impact theory gives -0.32 (e = 0.36,
    400 mm); end on (lever along n) the two agree. Engine hook (``contact_effective_mass=True``,
    :func:`with_contact_effective_mass`): each normal dashpot damps the smaller of the body's
    effective mass at the contact, rotation included, and its mass over its number of touching
    contacts this step (``simulate.integrate.damping_inverse_mass``). So n equal contacts of a
    flat landing damp exactly like one contact of n times the stiffness and the body's mass,
    and a lone off-centre contact rebounds at the contact restitution, as the rigid body does.
    It replaces the former ``multi_contact_damping`` hook, renamed: that hook damped the same
    min(m / n, m_eff), which is already the effective mass at each contact shared among the
    simultaneous ones, so a second switch would only duplicate it (files naming the former
    hook read as this one, ``simulate.params.RENAMED``). Checked against rigid-body impact
    theory (``simulate.rigid_impact``): dropped on a frictionless plate, a segment rebounds
    within 1 % of the rigid body's sequence of end impacts from 0.5 to 60 deg when its contacts
    are short against its turn and against the time between its two end impacts. Within about
    t_c v / (L - D) rad of flat (t_c the contact time, v the impact speed, L - D the distance of
    the end spheres; about 6 deg for the default particle dropped 400 mm) the two end contacts
    overlap in time, and the rebound is that of the contacts, which no theory of instantaneous
    impacts gives (Stoianovici & Hurmuzlu 1996 measured such drops of steel bars).
``rolling_spring_dashpot``
    Elastic-plastic spring-dashpot rolling resistance (Ai et al. 2011, model type C). Engine
    hook (``rolling_model="epsd"``, ``rolling_damping_ratio``): the contact kernel's rolling
    model, with the spring torque of each contact in its history
    (``simulate.contact.rolling``: :func:`epsd_stiffness`, :func:`epsd_damping`,
    :func:`epsd_rolling_torque`).

References
----------
Ai, J., Chen, J.-F., Rotter, J. M., Ooi, J. Y. (2011). Assessment of rolling resistance models
in discrete element simulations. Powder Technol. 206, 269-282.
Iwashita, K., Oda, M. (1998). Rolling resistance at contacts in simulation of shear band
development by DEM. J. Eng. Mech. 124(3), 285-292.
Kodam, M., Bharadwaj, R., Curtis, J., Hancock, B., Wassgren, C. (2010). Cylindrical object
contact detection for use in discrete element method simulations, Part II: Experimental
validation. Chem. Eng. Sci. 65, 5863-5871.
Johnson, K. L. (1985). Contact Mechanics. Cambridge University Press, sec. 11.5.
Stoianovici, D., Hurmuzlu, Y. (1996). A critical study of the applicability of rigid-body
collision theory. J. Appl. Mech. 63, 307-316.
Stronge, W. J. (2000). Impact Mechanics. Cambridge University Press.
Thornton, C., Ning, Z. (1998). A theoretical model for the stick/bounce behaviour of adhesive,
elastic-plastic spheres. Powder Technol. 99, 154-162.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace

import numpy as np
from scipy import stats

from demcal.errors import InputError
from demcal.simulate.clump import ClumpTemplate
from demcal.simulate.shapes.segment import Segment
from demcal.simulate.params import DEMParameters
from demcal.simulate.shapes import Shape
from demcal.units import GRAVITY

#: Extension names, in the order of the critique's catalogue.
EXTENSIONS = ("velocity_dependent_restitution", "inverted_restitution", "size_distribution",
              "more_spheres", "rolling_spring_dashpot", "contact_effective_mass")


#: Loosest stopping tolerance of :func:`invert_drop_twin` on the mean apparent restitution [-].
MAX_TOLERANCE = 0.01

#: Parameter of ``DEMParameters`` holding the restitution of each pair the rigs know.
RESTITUTION_PARAMETER = {"particle-steel": "e_pw", "particle-particle": "e_pp"}

#: Extensions that are engine hooks: the ``DEMParameters`` fields that switch and set them.
ENGINE_HOOKS = {
    "velocity_dependent_restitution": ("e_pp_exponent", "e_pp_v_ref", "e_pp_v_min",
                                       "e_pw_exponent", "e_pw_v_ref", "e_pw_v_min"),
    "rolling_spring_dashpot": ("rolling_model", "rolling_damping_ratio"),
    "size_distribution": ("particle_sizes",),
    "contact_effective_mass": ("contact_effective_mass",),
}


def describe(name: str, **settings) -> dict:
    """Provenance record of an extension: ``{"extension": name, **settings}``; an unknown name
    lists the valid ones."""
    if name not in EXTENSIONS:
        raise InputError(f"unknown model extension {name!r}; valid: {', '.join(EXTENSIONS)}")
    return {"extension": name, **settings}


def engine_hooks(params: DEMParameters) -> list[dict]:
    """Provenance records (:func:`describe`) of the engine hooks ``params`` switches on, with
    their settings; empty for the default model."""
    out = []
    if params.e_pp_exponent != 0.0 or params.e_pw_exponent != 0.0:
        laws = {pair: {"e_ref": getattr(params, f"e_{pair}"), "v_ref": getattr(params, f"e_{pair}_v_ref"),
                       "exponent": getattr(params, f"e_{pair}_exponent"),
                       "v_min": getattr(params, f"e_{pair}_v_min")}
                for pair in ("pp", "pw") if getattr(params, f"e_{pair}_exponent") != 0.0}
        out.append(describe("velocity_dependent_restitution", mode="per contact (engine)", laws=laws))
    if params.rolling_model == "epsd":
        out.append(describe("rolling_spring_dashpot", rolling_model=params.rolling_model,
                            damping_ratio=params.rolling_damping_ratio))
    if params.particle_sizes is not None:
        sizes = np.asarray(params.particle_sizes)
        out.append(describe("size_distribution", mode="particles drawn per clump (engine)",
                            n_sizes=int(sizes.shape[0]),
                            means={name: float(v) for name, v in zip(params.shape.sizes, sizes.mean(axis=0))}))
    if params.contact_effective_mass:
        out.append(describe("contact_effective_mass", mode="each normal dashpot damps the smaller of the "
                            "contact's rigid-body effective mass and the body's mass over its "
                            "simultaneous contacts (engine)"))
    return out


def restitution_parameter(pair: str) -> str:
    """The ``DEMParameters`` field of a pair's restitution (``e_pw`` or ``e_pp``)."""
    try:
        return RESTITUTION_PARAMETER[pair]
    except KeyError:
        raise InputError(f"no DEM restitution parameter for pair {pair!r}; "
                         f"valid: {', '.join(RESTITUTION_PARAMETER)}") from None


def impact_speed(drop_height: float, g: float = GRAVITY) -> float:
    """Free-fall impact speed sqrt(2 g h) [m/s] from a drop height [m]."""
    if not drop_height > 0:
        raise InputError(f"drop height must be positive, got {drop_height!r}")
    return math.sqrt(2.0 * g * drop_height)


# ----------------------------------------------------------------------------------------------
# velocity-dependent restitution


@dataclass(frozen=True)
class VelocityRestitution:
    """Power law e(v) = e_ref (v / v_ref)^(-n) of the restitution against impact speed.

    Attributes
    ----------
    pair : str
        Material pair it was fitted for.
    e_ref : float
        Restitution at ``v_ref`` [-].
    v_ref : float
        Reference speed, the geometric mean of the fitted speeds [m/s].
    exponent : float
        n [-]; positive when e falls with speed (Johnson 1985: 1/4 for plastic impacts).
    exponent_ci95 : tuple of float
        Student-t 95 % interval of n [-].
    e_ref_ci95 : tuple of float
        95 % interval of e_ref [-].
    n : int
        Drops fitted.
    speeds : tuple of float
        Distinct impact speeds fitted [m/s].

    Notes
    -----
    :func:`with_velocity_restitution` puts the law into the contact model (each contact's
    damping from e(v) at its first-touch approach speed); :func:`parameters_for_impact`
    applies it to a single-impact twin as a constant e instead.
    """

    pair: str
    e_ref: float
    v_ref: float
    exponent: float
    exponent_ci95: tuple
    e_ref_ci95: tuple
    n: int
    speeds: tuple

    def __call__(self, speed):
        """e at impact speed(s) ``speed`` [m/s], capped to (0, 1]."""
        v = np.asarray(speed, dtype=float)
        if np.any(v <= 0):
            raise InputError("impact speed must be positive")
        e = self.e_ref * (v / self.v_ref) ** (-self.exponent)
        e = np.clip(e, 1e-6, 1.0)
        return float(e) if e.ndim == 0 else e

    def to_dict(self) -> dict:
        return asdict(self)


def fit_velocity_restitution(drop_height, restitution, *, pair: str = "particle-steel",
                             g: float = GRAVITY) -> VelocityRestitution:
    """Fit e(v) = e_ref (v / v_ref)^(-n) to drops from several heights.

    Least squares of ln e on ln(v / v_ref), v = sqrt(2 g h) the impact speed of each drop and
    v_ref the geometric mean of the speeds (which makes the two estimates uncorrelated). The
    power law is the form of Johnson's plastic-impact theory (1985, sec. 11.5) and of Thornton
    & Ning (1998) at speeds above yield.

    Parameters
    ----------
    drop_height : array_like
        Drop height of each drop [m]; at least two distinct values.
    restitution : array_like
        Restitution of each drop [-], > 0.
    pair : str
        Material pair (recorded).
    g : float
        Gravitational acceleration [m/s^2].

    Returns
    -------
    VelocityRestitution
    """
    h = np.asarray(drop_height, dtype=float)
    e = np.asarray(restitution, dtype=float)
    if h.shape != e.shape or h.ndim != 1:
        raise InputError("drop_height and restitution must be 1-D arrays of equal length")
    if np.any(h <= 0) or np.any(e <= 0):
        raise InputError("drop heights and restitutions must be positive")
    if np.unique(h).size < 2 or h.size < 3:
        raise InputError("e(v) needs at least 3 drops from at least 2 drop heights")
    v = np.sqrt(2.0 * g * h)
    v_ref = float(np.exp(np.mean(np.log(v))))
    x = np.log(v / v_ref)
    y = np.log(e)
    X = np.column_stack([np.ones_like(x), x])
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    resid = y - X @ coef
    dof = x.size - 2
    s2 = float(resid @ resid) / dof if dof > 0 else math.nan
    cov = s2 * np.linalg.inv(X.T @ X)
    t = float(stats.t.ppf(0.975, dof)) if dof > 0 else math.nan
    a, b = float(coef[0]), float(coef[1])
    sa, sb = math.sqrt(cov[0, 0]), math.sqrt(cov[1, 1])
    return VelocityRestitution(pair=pair, e_ref=math.exp(a), v_ref=v_ref, exponent=-b,
                               exponent_ci95=(-b - t * sb, -b + t * sb),
                               e_ref_ci95=(math.exp(a - t * sa), math.exp(a + t * sa)),
                               n=int(h.size), speeds=tuple(float(s) for s in np.unique(v)))


def parameters_for_impact(params: DEMParameters, pair: str, law: VelocityRestitution,
                          speed: float) -> DEMParameters:
    """Parameters of a single-impact twin with the pair's restitution e(speed) of ``law``."""
    return params.with_(**{restitution_parameter(pair): law(speed)})


def with_velocity_restitution(params: DEMParameters, pair: str, law: VelocityRestitution, *,
                              hold_below_fitted: bool = True) -> DEMParameters:
    """``params`` with ``law`` as the engine's e(v) of ``pair`` (``particle-steel`` or
    ``particle-particle``): e = e_ref at v_ref, exponent n, and (``hold_below_fitted``) e held
    at its value at the slowest fitted impact below it (``v_min``), rather than extrapolated to
    e = 1. An e_ref above 1 (possible from a fit) is refused, as it would be for a constant e."""
    name = restitution_parameter(pair)
    v_min = min(law.speeds) if hold_below_fitted and law.speeds else 0.0
    return params.with_(**{name: law.e_ref, f"{name}_v_ref": law.v_ref, f"{name}_exponent": law.exponent,
                           f"{name}_v_min": v_min})


def with_contact_effective_mass(params: DEMParameters, on: bool = True) -> DEMParameters:
    """``params`` with the ``contact_effective_mass`` engine hook switched on (or off)."""
    return params.with_(contact_effective_mass=bool(on))


def with_spring_dashpot_rolling(params: DEMParameters, damping_ratio: float | None = None) -> DEMParameters:
    """``params`` with the spring-dashpot (type C) rolling model, keeping ``mu_r`` (and the
    damping ratio unless given)."""
    changes = {"rolling_model": "epsd"}
    if damping_ratio is not None:
        changes["rolling_damping_ratio"] = damping_ratio
    return params.with_(**changes)


# ----------------------------------------------------------------------------------------------
# restitution by inverting the drop twin


@dataclass(frozen=True)
class InvertedRestitution:
    """Contact restitution that makes the drop twin reproduce the measured drops.

    Attributes
    ----------
    pair : str
    target : float
        Measured mean apparent restitution of the trials fitted [-].
    contact : float
        Contact restitution found [-] (NaN when the twin cannot reach the target).
    contact_ci95 : tuple of float
        95 % interval of ``contact``: the interval of the mean paired residual (measured minus
        twin) at the solution, divided by the local slope d(twin mean)/de (least squares over
        the evaluations within 0.2 of the solution) [-].
    twin_mean : float
        Twin's mean apparent restitution at ``contact`` [-].
    residual_ci95 : tuple of float
        95 % interval of the mean paired residual at ``contact`` [-].
    slope : float
        d(twin mean)/de near the solution [-].
    evaluations : tuple of (float, float)
        (e, twin mean) of every evaluation, in order.
    converged : bool
    note : str
    """

    pair: str
    target: float
    contact: float
    contact_ci95: tuple
    twin_mean: float
    residual_ci95: tuple
    slope: float
    evaluations: tuple
    converged: bool
    note: str = ""

    def to_dict(self) -> dict:
        return asdict(self)


def invert_drop_twin(twin, measured, *, pair: str = "particle-steel", start: float | None = None,
                     lo: float = 0.02, hi: float = 1.0, tol: float = 0.005,
                     max_evaluations: int = 8) -> InvertedRestitution:
    """Solve mean(twin(e)) = mean(measured) for the contact restitution e.

    ``twin(e)`` returns the twin's apparent restitution of every trial (same order as
    ``measured``). The mean is close to monotone in e but not smooth (a pivoting segment's
    rebound changes abruptly with e), so the root is found by the Illinois variant of false
    position once bracketed, by secant steps (clipped to [lo, hi]) before.

    Parameters
    ----------
    twin : callable
        ``twin(e) -> array`` of per-trial apparent restitutions [-].
    measured : array_like
        Measured apparent restitution of the same trials [-].
    pair : str
        Recorded.
    start : float, optional
        First e tried; default the measured mean (what the paper would use).
    lo, hi : float
        Search range of e [-].
    tol : float
        Stop when |twin mean - target| < tol [-] or the bracket is narrower than tol; tol is
        raised to a quarter of the half-width of the measured mean's 95 % interval, at most
        ``MAX_TOLERANCE``.
    max_evaluations : int

    Returns
    -------
    InvertedRestitution
    """
    y = np.asarray(measured, dtype=float)
    if y.ndim != 1 or y.size < 2:
        raise InputError("invert_drop_twin needs at least 2 measured trials")
    target = float(y.mean())
    # no point in matching the mean much closer than its own uncertainty (but never looser than
    # MAX_TOLERANCE)
    half = float(stats.t.ppf(0.975, y.size - 1)) * float(y.std(ddof=1)) / math.sqrt(y.size)
    tol = max(tol, min(0.25 * half, MAX_TOLERANCE))
    e = float(np.clip(start if start is not None else target, lo, hi))
    evals: list[tuple[float, float]] = []
    cache: dict[float, np.ndarray] = {}

    def f(x):
        sim = np.asarray(twin(x), dtype=float)
        if sim.shape != y.shape:
            raise InputError(f"twin(e) returned {sim.shape} values for {y.size} trials")
        cache[x] = sim
        evals.append((x, float(sim.mean())))
        return float(sim.mean()) - target

    a, fa = e, f(e)
    b = fb = None
    if abs(fa) >= tol:
        # second point: proportional guess (the twin's rebound scales roughly with e)
        mean_a = fa + target
        guess = a * target / mean_a if mean_a > 1e-3 else 2.0 * a
        b = float(np.clip(guess, lo, hi))
        if b == a:
            b = float(np.clip(a + (0.1 if fa < 0 else -0.1), lo, hi))
        fb = f(b)
    side = 0
    while b is not None and len(evals) < max_evaluations and abs(fb) >= tol and abs(b - a) >= tol:
        if fa * fb < 0:
            c = b - fb * (b - a) / (fb - fa)            # false position inside the bracket
        else:
            c = b - fb * (b - a) / (fb - fa) if fb != fa else b + (0.1 if fb < 0 else -0.1)
            c = float(np.clip(c, lo, hi))
            if c == b:                                   # pinned at the edge of the range
                break
        fc = f(c)
        if fa * fb < 0:
            if fc * fb < 0:
                a, fa = b, fb
                side = 0
            else:
                side += 1
                if side >= 2:                            # Illinois: halve the stale end
                    fa *= 0.5
            b, fb = c, fc
        else:
            a, fa, b, fb = b, fb, c, fc
    best_e, best_m = min(evals, key=lambda em: abs(em[1] - target))
    resid = y - cache[best_e]
    n = resid.size
    half = float(stats.t.ppf(0.975, n - 1)) * float(resid.std(ddof=1)) / math.sqrt(n)
    r_mean = float(resid.mean())
    # local slope: least squares over the evaluations within 0.2 of the solution (a secant over
    # a tiny step would be dominated by the twin's jagged response)
    near = [(em_e, em_m) for em_e, em_m in evals if abs(em_e - best_e) <= 0.2]
    if len({em_e for em_e, _ in near}) < 2:
        near = [(best_e, best_m), max(evals, key=lambda em: abs(em[0] - best_e))]
    ex = np.array([em[0] for em in near])
    ey = np.array([em[1] for em in near])
    slope = float(np.polyfit(ex, ey, 1)[0]) if np.unique(ex).size >= 2 else math.nan
    converged = abs(best_m - target) < max(tol, half)
    note = ""
    if not converged:
        top = max(evals)[1] if evals else math.nan
        note = (f"the twin's mean apparent restitution does not reach the measured {target:.3g} "
                f"(closest {best_m:.3g} at e = {best_e:.3g}; at the largest e tried, {top:.3g})")
    if converged and math.isfinite(slope) and slope > 0:
        ci = (best_e + (r_mean - half) / slope, best_e + (r_mean + half) / slope)
    else:
        ci = (math.nan, math.nan)
    return InvertedRestitution(pair=pair, target=target,
                               contact=best_e if converged else math.nan, contact_ci95=ci,
                               twin_mean=best_m, residual_ci95=(r_mean - half, r_mean + half),
                               slope=slope, evaluations=tuple(evals), converged=converged,
                               note=note)


# ----------------------------------------------------------------------------------------------
# size distribution from the callipers


@dataclass(frozen=True)
class SizeDistribution:
    """Particle sizes measured with callipers, one entry per specimen, drawn jointly.

    Attributes
    ----------
    sizes : tuple of tuple of float
        Each specimen's lengths [m] in the order of its shape's ``sizes`` (a segment's
        (length, diameter), a sphere's (diameter,), a kernel's (length, width, thickness)).
    specimen_ids : tuple of str
        Specimen of each entry.
    """

    sizes: tuple
    specimen_ids: tuple = ()

    def __post_init__(self):
        sizes = tuple(tuple(float(v) for v in entry) for entry in self.sizes)
        if not sizes or len({len(e) for e in sizes}) != 1:
            raise InputError("a size distribution needs a non-empty list of entries of equal length")
        if self.specimen_ids and len(self.specimen_ids) != len(sizes):
            raise InputError(f"a size distribution of {len(sizes)} entries names {len(self.specimen_ids)} specimens")
        for entry in sizes:
            if not all(math.isfinite(v) and v > 0 for v in entry):
                raise InputError(f"a particle size must be lengths > 0 [m], got {entry!r}")
        object.__setattr__(self, "sizes", sizes)
        object.__setattr__(self, "specimen_ids", tuple(str(v) for v in self.specimen_ids))

    @classmethod
    def from_specimens(cls, frame, shape: Shape) -> "SizeDistribution":
        """From a ``specimens`` sheet frame (``specimen_id`` and ``shape``'s calliper columns
        [mm]), each row read as the shape reads a specimen (``Shape.from_specimen``)."""
        return cls(tuple(shape.sized_as(row).size_values for row in frame.to_dict("records")),
                   tuple(str(v) for v in frame["specimen_id"]))

    def size_of(self, specimen_id: str) -> tuple:
        """The sizes [m] of one specimen."""
        try:
            i = self.specimen_ids.index(str(specimen_id))
        except ValueError:
            raise InputError(f"specimen {specimen_id!r} is not in the size distribution") from None
        return self.sizes[i]

    def draw(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """``n`` entries [m] resampled from the measured ones, shape (n, number of sizes)."""
        idx = rng.integers(0, len(self.sizes), int(n))
        return np.asarray(self.sizes)[idx]

    def to_dict(self) -> dict:
        return asdict(self)


def with_size_distribution(params: DEMParameters, distribution: SizeDistribution) -> DEMParameters:
    """``params`` whose heaps draw each particle from ``distribution``'s sizes."""
    if not isinstance(distribution, SizeDistribution):
        raise InputError(f"distribution must be a SizeDistribution, got {type(distribution).__name__}")
    return params.with_(particle_sizes=distribution.sizes)


def particle_of_size(params: DEMParameters, sizes) -> ClumpTemplate:
    """The template of ``params``' shape at other ``sizes`` [m] (in the order of the shape's
    ``sizes``; same sphere count, density and mass model; a ``scaled`` mass model keeps its
    mass per volume)."""
    shape = params.shape
    sized = shape.with_sizes(sizes)
    mean_mass = params.mean_mass_kg
    if params.mass_model == "scaled" and mean_mass:
        mean_mass = mean_mass * sized.volume() / shape.volume()
    return sized.template(params.particle_density_kg_m3, params.mass_model, mean_mass,
                          name=f"{shape.name} " + " x ".join(f"{v * 1e3:.2f}" for v in sized.size_values) + " mm")


# ----------------------------------------------------------------------------------------------
# more spheres per clump


def surface_ripple(length: float, diameter: float, n_spheres: int) -> float:
    """Depth of the grooves between neighbouring spheres of a segment clump [m].

    Equal spheres of radius r = D/2 at spacing s = (L - D) / (n - 1) meet at a waist of radius
    sqrt(r^2 - s^2/4); the ripple is r minus that (0 for touching-in-line spheres at s -> 0).
    """
    if n_spheres < 2:
        return 0.0
    r = 0.5 * diameter
    s = (length - diameter) / (n_spheres - 1)
    if s >= 2.0 * r:
        return r
    return r - math.sqrt(r * r - 0.25 * s * s)


def with_more_spheres(params: DEMParameters, n_spheres: int | None = None, *,
                      max_ripple: float | None = None) -> DEMParameters:
    """``params`` with more spheres per clump: ``n_spheres`` given, or the fewest whose
    :func:`surface_ripple` is at most ``max_ripple`` [m]."""
    if (n_spheres is None) == (max_ripple is None):
        raise InputError("give exactly one of n_spheres, max_ripple")
    if n_spheres is None:
        if not max_ripple > 0:
            raise InputError(f"max_ripple must be positive, got {max_ripple!r}")
        n_spheres = 2
        if not isinstance(params.shape, Segment):
            raise InputError(f"more spheres by surface ripple: a segment's; the shape is {params.shape.name}")
        while surface_ripple(params.shape.length_m, params.shape.diameter_m, n_spheres) > max_ripple:
            n_spheres += 1
            if n_spheres > 200:
                raise InputError(f"max_ripple {max_ripple!r} m needs more than 200 spheres")
    if int(n_spheres) != n_spheres or n_spheres < 1:
        raise InputError(f"n_spheres must be a positive integer, got {n_spheres!r}")
    if not hasattr(params.shape, "n_spheres"):
        raise InputError(f"more spheres per clump: shape {params.shape.name} has no sphere count")
    return params.with_(shape=replace(params.shape, n_spheres=int(n_spheres)))
