"""Power of a lab design: the smallest effect of each catalogue mechanism that the critique would
find with a given probability (80 % by default), from virtual workbooks.

For a data-effect mechanism M of the catalogue (``simulate.virtual_lab.EFFECT_KINDS``) and an
effect size S, the *detection rate* is the share of N virtual workbooks of the planned design,
with M planted at size S, in which the critique names M: each workbook is read and measured
(``measure``), its per-row series tested against every covariate, each tier of tests adjusted
on its own (``diagnosis.run_tests``) and the catalogue judged (``mechanisms.judge``), the same
steps and defaults as ``demcal critique --no-twins``; M is detected when its verdict is
``found``. The rate at S is given with its Clopper-Pearson 95 % interval (Clopper & Pearson
1934).

Search. The smallest detectable effect is sought on the effect's *strength* (its size for most
kinds, minus its size for a restitution falling with height, 90 deg minus the lowest release
angle for segments released by hand): from a start value the strength is halved or doubled
until the rate crosses the target power, then bisected geometrically ``steps`` times; the
result is the smallest strength evaluated whose rate reaches the target, reported with the
rate of its own N workbooks. Every point uses the same N workbook seeds (common random
numbers), so that two sizes differ by the effect and not by their noise and the bisection does
not chase noise; the power at the result is the target within the binomial error of N
workbooks (about 9 % for N = 20, 5 % for N = 60), which its interval shows. A workbook the
measure stage refuses (e.g. rebound heights that fall with drop height) counts as not detected,
since the critique stops there too, and the plan says how many there were.

Design and truth. From a truth file (``simulate.truth_file``): its truth and design. From a
lab workbook: the design read from its sheets (drop pairs and heights, drops per pair and
height, release angles, filmed drops, incline surfaces and trials, specimens, density samples,
compressions, photos) and the truth from its measured values (means, and scatter from their
sd; the reading noise is part of the measured scatter, so the virtual reading noise is set to
0); what the workbook does not measure keeps ``Truth``'s defaults. A mechanism is planted in
the first sheet of ``TARGETS`` whose covariate the design varies (moisture in the drops when the
incline trials name no specimen); if none does (one drop height, no operator column, one-flank
photos) it is listed as not testable instead of simulated. The virtual workbooks log
every covariate, a few more than a sparse real workbook, so their multiple-testing correction
is, if anything, slightly stricter than the real critique's.

Cost. No heap photos by default (``photos="none"``; ``camera_tilt`` then is not testable), and
the drop twin runs only for ``orientation_rotation``, once per release-angle grid point, pair
and height (``virtual_lab.drop_twin_ratio`` keeps them in memory), not per workbook.

References
----------
Clopper, C. J., Pearson, E. S. (1934). The use of confidence or fiducial limits illustrated in
the case of the binomial. Biometrika 26(4), 404-413.
"""

from __future__ import annotations

import math
import sys
import tempfile
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from statsmodels.stats.proportion import proportion_confint

from demcal.analyse.critique.diagnosis import CORRECTIONS, DEFAULT_ALPHA
from demcal.errors import InputError
from demcal.provenance import Provenance

#: Power the smallest detectable effect is defined by.
DEFAULT_POWER = 0.8

#: Where each kind can be planted and tested, in order of preference: (sheet, covariate).
TARGETS = {
    "velocity_dependent_restitution": (("drop", "drop_height_mm"),),
    "orientation_rotation": (("drop", "orientation_deg"),),
    "size_dependence": (("drop", "length_mm"), ("incline", "length_mm")),
    "block_effect": (("incline", "operator"), ("drop", "operator"), ("incline", "date"), ("drop", "date"),
                     ("incline", "batch"), ("drop", "batch"), ("repose", "operator"), ("repose", "date")),
    "trial_order_drift": (("incline", "trial_order"), ("drop", "trial_order")),
    "moisture_dependence": (("incline", "moisture_pct"), ("drop", "moisture_pct")),
    "camera_tilt": (("repose", "side"),),
}

#: Start strength of the search and unit of the size, per kind and sheet.
START = {("velocity_dependent_restitution", "drop"): 2e-4, ("orientation_rotation", "drop"): 30.0,
         ("size_dependence", "drop"): 0.02, ("size_dependence", "incline"): 0.02,
         ("block_effect", "drop"): 0.06, ("block_effect", "incline"): 2.0, ("block_effect", "repose"): 2.0,
         ("trial_order_drift", "drop"): 0.004, ("trial_order_drift", "incline"): 0.004,
         ("moisture_dependence", "drop"): 0.01, ("moisture_dependence", "incline"): 0.01,
         ("camera_tilt", "repose"): 2.0}
UNITS = {("velocity_dependent_restitution", "drop"): "e per mm of drop height",
         ("orientation_rotation", "drop"): "deg (lowest release angle, up to 90)",
         ("size_dependence", "drop"): "e per mm of length", ("size_dependence", "incline"): "mu per mm of length",
         ("block_effect", "drop"): "e between extreme levels",
         ("block_effect", "incline"): "deg of incline angle between extreme levels",
         ("block_effect", "repose"): "deg between extreme levels",
         ("trial_order_drift", "drop"): "e per trial", ("trial_order_drift", "incline"): "mu_s per trial",
         ("moisture_dependence", "drop"): "e per %", ("moisture_dependence", "incline"): "mu_s per %",
         ("camera_tilt", "repose"): "deg (each flank)"}

#: Halvings or doublings of the start strength tried before the search gives up.
MAX_DOUBLINGS = 6


# ----------------------------------------------------------------------------------------------
# statistics: the interval of a rate, and the search for the target power


def clopper_pearson(k: int, n: int, level: float = 0.95) -> tuple:
    """Exact (Clopper-Pearson) interval of a binomial proportion, k successes in n trials."""
    if n <= 0:
        return (math.nan, math.nan)
    lo, hi = proportion_confint(k, n, alpha=1.0 - level, method="beta")
    return (float(lo), float(hi))


@dataclass(frozen=True)
class Search:
    """Outcome of :func:`smallest_reaching`.

    Attributes
    ----------
    strength : float
        Smallest strength evaluated whose rate reached the target (if ``reached``), else the
        largest evaluated.
    hits, n : int
        Detections and workbooks at ``strength``.
    reached : bool
        Whether any strength evaluated reached the target.
    at_floor : bool
        The rate still reached the target at the smallest strength tried (the result is an
        upper bound of the smallest detectable strength).
    points : tuple of (float, int, int)
        Every (strength, hits, n) evaluated, in order.
    """

    strength: float
    hits: int
    n: int
    reached: bool
    at_floor: bool
    points: tuple


def _round3(x: float) -> float:
    """Three significant digits, so that the printed size is the planted one."""
    return float(f"{x:.3g}")


def smallest_reaching(rate, start: float, *, target: float = DEFAULT_POWER, steps: int = 4,
                      limit: float = math.inf, max_doublings: int = MAX_DOUBLINGS) -> Search:
    """Smallest strength x whose rate reaches ``target``, by bracketing and geometric bisection.

    Parameters
    ----------
    rate : callable
        ``rate(x) -> (hits, n)``, rising with x.
    start : float
        First strength tried (> 0).
    target : float
        Rate to reach, in (0, 1).
    steps : int
        Bisections after the bracket (each halves its log width).
    limit : float
        Largest strength allowed.
    max_doublings : int
        Halvings (or doublings) of ``start`` tried to bracket the target.

    Returns
    -------
    Search
    """
    if not 0 < target < 1:
        raise InputError(f"the target power must be in (0, 1), got {target!r}")
    points = []
    seen = {}

    def meets(x):
        if x not in seen:
            seen[x] = rate(x)
            points.append((x, *seen[x]))
        hits, n = seen[x]
        return hits >= target * n

    lo = hi = None
    x = _round3(min(start, limit))
    if meets(x):
        hi = x
        for _ in range(max_doublings):
            y = _round3(hi / 2.0)
            if meets(y):
                hi = y
            else:
                lo = y
                break
    else:
        lo = x
        for _ in range(max_doublings):
            if lo >= limit:
                break
            y = _round3(min(2.0 * lo, limit))
            if meets(y):
                hi = y
                break
            lo = y
    if hi is None:
        return Search(lo, *seen[lo], reached=False, at_floor=False, points=tuple(points))
    if lo is None:
        return Search(hi, *seen[hi], reached=True, at_floor=True, points=tuple(points))
    for _ in range(steps):
        mid = _round3(math.sqrt(lo * hi))
        if mid in (lo, hi):
            break
        if meets(mid):
            hi = mid
        else:
            lo = mid
    return Search(hi, *seen[hi], reached=True, at_floor=False, points=tuple(points))


# ----------------------------------------------------------------------------------------------
# the planned design: truth, workbook options and the covariates it varies


@dataclass(frozen=True)
class LabDesign:
    """What the plan simulates.

    Attributes
    ----------
    truth : simulate.virtual_lab.Truth
    design : dict
        Options of ``write_virtual_workbook``.
    varied : dict
        Sheet -> covariates the design varies in it (with those of the specimens its rows
        name): what the mechanisms can be tested against.
    source : str
        The truth file or workbook.
    kind : str
        ``truth file`` or ``workbook``.
    notes : tuple of str
        What the reader should know (pairs the virtual lab cannot drop, ...).
    inputs : dict
        File -> SHA-256 of what the design was read from (every file of a workbook).
    """

    truth: object
    design: dict
    varied: dict
    source: str
    kind: str
    notes: tuple = ()
    inputs: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"truth": self.truth.to_dict(), "design": dict(self.design),
                "varied": {k: sorted(v) for k, v in self.varied.items()}, "source": self.source,
                "kind": self.kind, "notes": list(self.notes), "inputs": dict(self.inputs)}


def _virtual_varied(truth, design: dict) -> dict:
    """Covariates a virtual workbook of ``design`` varies, per sheet."""
    per_specimen = {"specimen_id"}
    if truth.length_sd_m > 0:
        per_specimen.add("length_mm")
    if truth.moisture_sd_pct > 0:
        per_specimen.add("moisture_pct")
    if len(truth.batches) >= 2:
        per_specimen.add("batch")
    # a date block spreads the sheet's trials over the campaign's days
    blocks = {c for c, levels in (("operator", truth.operators), ("date", truth.days)) if len(levels) >= 2}
    trial = {"trial_order"} | blocks
    varied = {}
    if design["pairs"]:
        # orientation_deg is always logged, and planting segments released by hand varies it
        varied["drop"] = trial | per_specimen | {"orientation_deg"} | (
            {"drop_height_mm"} if len(set(design["drop_heights_mm"])) >= 2 else set())
    if design["surfaces"]:
        varied["incline"] = trial | per_specimen
    if design["photos"] != "none" and design["n_photos"] >= 2:
        varied["repose"] = {"side"} | blocks
    return varied


def design_from_truth_file(path, *, photos: str = "none") -> LabDesign:
    """The design and truth of a truth file (heap photos as ``photos`` asks)."""
    from demcal.simulate.truth_file import read_truth_file

    from demcal.provenance import sha256_file

    spec = read_truth_file(path)
    design = dict(spec.design, photos=photos)
    notes = []
    if spec.design["photos"] != photos:
        notes.append(f"heap photos: {photos} (the truth file's design has {spec.design['photos']})")
    return LabDesign(truth=spec.truth, design=design, varied=_virtual_varied(spec.truth, design),
                     source=str(path), kind="truth file", notes=tuple(notes),
                     inputs={str(path): sha256_file(path)})


def _levels(frame, column) -> list:
    if frame is None or column not in frame:
        return []
    values = frame[column].dropna()
    return sorted({v.isoformat()[:10] if hasattr(v, "isoformat") else str(v) for v in values})


def _pooled_sd(estimates) -> float:
    """Pooled sd of several quantities' rows (their sample variances weighted by n - 1)."""
    ok = [e for e in estimates if e.n >= 2 and math.isfinite(e.sd)]
    dof = sum(e.n - 1 for e in ok)
    return math.sqrt(sum((e.n - 1) * e.sd ** 2 for e in ok) / dof) if dof else math.nan


def truth_from_measurement(measurement, workbook):
    """A ``Truth`` whose means and scatter are the workbook's measured ones.

    The parameters measured replace the defaults (restitution, friction, density, Poisson's
    ratio, shear modulus, segment size); the scatter of each family is the pooled sd of its rows
    and the reading noise 0 (the measured scatter holds it); moisture, operators, days and
    batches are those of the sheets. What is not measured keeps ``Truth``'s default.
    """
    from demcal.simulate.virtual_lab import Truth

    q = measurement.quantities

    def value(name):
        e = q.get(name)
        return e.value if e is not None and math.isfinite(e.value) else None

    def sd(name):
        e = q.get(name)
        return e.sd if e is not None and e.n >= 2 and math.isfinite(e.sd) else None

    params = {"e_pp": value("restitution.particle-particle"), "e_pw": value("restitution.particle-steel"),
              "mu_s_pp": value("static_friction.particle"), "mu_s_pw": value("static_friction.steel"),
              "mu_r_pp": value("rolling_friction.particle"), "mu_r_pw": value("rolling_friction.steel"),
              "particle_density_kg_m3": value("particle_density_kg_m3"),
              "poisson_ratio": value("poisson_ratio"), "shear_modulus_pa": value("shear_modulus_pa"),
              "shape": measurement.shape or None}
    fields = {"height_noise_mm": 0.0, "angle_noise_deg": 0.0}
    e_sd = _pooled_sd([e for n, e in q.items() if n.startswith("restitution.")])
    mu_sd = _pooled_sd([e for n, e in q.items() if n.startswith(("static_friction.", "rolling_friction."))])
    for name, x in (("e_sd", e_sd), ("mu_sd", mu_sd)):
        if math.isfinite(x):
            fields[name] = x
    for name, x in (("length_sd_m", sd("length_mm")), ("diameter_sd_m", sd("diameter_mm"))):
        if x is not None:
            fields[name] = x * 1e-3
    for name, x in (("density_sd", sd("particle_density_kg_m3")), ("poisson_sd", sd("poisson_ratio")),
                    ("repose_angle_deg", value("repose_angle_deg")), ("repose_sd_deg", sd("repose_angle_deg"))):
        if x is not None:
            fields[name] = x
    if value("envelope_density_kg_m3") and value("particle_density_kg_m3"):
        fields["envelope_ratio"] = value("envelope_density_kg_m3") / value("particle_density_kg_m3")
    if sd("elastic_modulus_pa") is not None and value("elastic_modulus_pa"):
        fields["modulus_sd_rel"] = sd("elastic_modulus_pa") / value("elastic_modulus_pa")
    specimens = workbook.sheet("specimens").frame if workbook.sheet("specimens") is not None else None
    if specimens is not None and "moisture_pct" in specimens:
        moisture = specimens["moisture_pct"].dropna().to_numpy(float)
        if moisture.size >= 2:
            fields["moisture_pct"], fields["moisture_sd_pct"] = float(moisture.mean()), float(moisture.std(ddof=1))
    frames = [workbook.sheet(s).frame for s in ("drop", "incline", "repose") if workbook.sheet(s) is not None]
    operators = sorted({v for f in frames for v in _levels(f, "operator")})
    days = sorted({v for f in frames for v in _levels(f, "date")})
    batches = _levels(specimens, "batch")
    for name, levels in (("operators", operators), ("days", days), ("batches", batches)):
        if levels:
            fields[name] = tuple(levels)
    try:
        base = Truth().params.with_(**{k: v for k, v in params.items() if v is not None},
                                    dt=measurement.meta.get("time_step_s"))   # None: from the material
        return Truth(params=base, **fields)
    except InputError as exc:
        raise InputError(f"{workbook.source}: its measured values are no valid truth for the virtual lab: "
                         f"{exc}") from None


def design_from_workbook(path, *, photos: str = "none", reading=None) -> LabDesign:
    """The design of a lab workbook (read with ``reading``, a ``measure.workbook.ReadOptions``)
    and the truth of its measured values (see the module docstring); pairs and surfaces the
    virtual lab cannot simulate are left out with a note."""
    from demcal.measure.pipeline import measure_workbook
    from demcal.measure.workbook import read_workbook
    from demcal.simulate.truth_file import PAIRS, SURFACES, design_defaults

    wb = read_workbook(path, reading)
    measurement = measure_workbook(wb)
    truth = truth_from_measurement(measurement, wb)
    design = dict(design_defaults(), photos=photos, trials_per_specimen=None)
    notes = []

    def frame(name):
        sheet = wb.sheet(name)
        return sheet.frame if sheet is not None and sheet.rows else None

    drop, incline = frame("drop"), frame("incline")
    specimens, repose = frame("specimens"), frame("repose")
    design["n_specimens"] = max(3, 0 if specimens is None else len(specimens))
    design["n_density"] = max(2, 0 if frame("density") is None else len(frame("density")))
    design["n_compression"] = 0 if frame("compression") is None else len(frame("compression"))
    design["n_photos"] = 0 if repose is None else len(repose)
    pairs = [] if drop is None else sorted(set(drop["pair"]))
    design["pairs"] = [p for p in PAIRS if p in pairs]
    if set(pairs) - set(PAIRS):
        notes.append(f"drop pairs the virtual lab cannot drop, left out: {', '.join(sorted(set(pairs) - set(PAIRS)))}")
    design["drop_heights_mm"], design["n_tracks"] = [400.0], 0
    if design["pairs"]:
        rows = drop[drop["pair"].isin(design["pairs"])]
        heights = sorted({float(h) for h in rows["drop_height_mm"]})
        design["drop_heights_mm"] = heights
        design["n_drop"] = max(1, round(len(rows) / (len(design["pairs"]) * len(heights))))
        if "orientation_deg" in rows and rows["orientation_deg"].notna().any():
            o = rows["orientation_deg"].dropna().to_numpy(float).clip(0.0, 90.0)
            design["orientation_range_deg"] = [float(o.min()), float(o.max())]
        if "track_file" in rows:
            steel = rows[rows["pair"] == "particle-steel"]
            design["n_tracks"] = int(steel["track_file"].notna().sum())
    surfaces = [] if incline is None else sorted(set(incline["surface"]))
    design["surfaces"] = [s for s in SURFACES if s in surfaces]
    if set(surfaces) - set(SURFACES):
        notes.append(f"incline surfaces the virtual lab cannot tilt, left out: "
                     f"{', '.join(sorted(set(surfaces) - set(SURFACES)))}")
    if design["surfaces"]:
        rows = incline[incline["surface"].isin(design["surfaces"])]
        design["n_incline"] = max(2, round(len(rows) / (2 * len(design["surfaces"]))))

    def varies(f, column):
        return f is not None and column in f and f[column].dropna().nunique() >= 2

    per_specimen = {c for c in ("length_mm", "moisture_pct", "batch") if varies(specimens, c)}
    varied = {}
    for name, f, present in (("drop", drop, bool(design["pairs"])), ("incline", incline, bool(design["surfaces"]))):
        if not present:
            continue
        cols = {c for c in ("drop_height_mm", "orientation_deg", "operator", "date", "trial_order") if varies(f, c)}
        if "specimen_id" in f and f["specimen_id"].notna().any():
            cols |= {"specimen_id"} | per_specimen
        varied[name] = cols
    if photos != "none" and repose is not None and len(repose) >= 2:
        two_flanks = "side" not in repose or (repose["side"].fillna("both") == "both").any()
        varied["repose"] = ({"side"} if two_flanks else set()) | {c for c in ("operator", "date") if varies(repose, c)}
    elif photos != "none":
        design["n_photos"] = 0
    return LabDesign(truth=truth, design=design, varied=varied, source=str(path), kind="workbook",
                     notes=tuple(notes), inputs=dict(measurement.provenance.inputs))


def read_design(source, *, photos: str = "none", reading=None) -> LabDesign:
    """:class:`LabDesign` of a truth file (``.yaml``, ``.yml``) or a lab workbook (read with
    ``reading``)."""
    if photos not in ("none", "analytic"):
        raise InputError(f"photos must be none or analytic for a plan, got {photos!r}")
    path = Path(source)
    if not path.exists():
        raise InputError(f"workbook or truth file not found: {path}")
    if path.suffix.lower() in (".yaml", ".yml"):
        return design_from_truth_file(path, photos=photos)
    return design_from_workbook(path, photos=photos, reading=reading)


# ----------------------------------------------------------------------------------------------
# one mechanism: where to plant it, and its detection rate


@dataclass(frozen=True)
class Target:
    """Where a kind is planted: sheet and covariate, the size's sign and unit, the search's start."""

    kind: str
    sheet: str
    covariate: str
    unit: str
    start: float

    def size(self, strength: float) -> float:
        """The planted size of a strength (see the module docstring)."""
        if self.kind == "orientation_rotation":
            return _round3(90.0 - strength)
        if self.kind == "velocity_dependent_restitution":
            return -strength
        return strength

    @property
    def limit(self) -> float:
        return 90.0 if self.kind == "orientation_rotation" else math.inf

    def effect(self, strength: float):
        from demcal.simulate.virtual_lab import PlantedEffect

        return PlantedEffect(self.kind, size=self.size(strength), sheet=self.sheet,
                             covariate=self.covariate if self.kind == "block_effect" else None)


def choose_target(kind: str, lab: LabDesign) -> tuple:
    """(Target, None) for the first sheet and covariate of ``TARGETS[kind]`` the design varies,
    else (None, reason)."""
    for sheet, covariate in TARGETS[kind]:
        if covariate in lab.varied.get(sheet, ()):
            return Target(kind, sheet, covariate, UNITS[(kind, sheet)], START[(kind, sheet)]), None
    if kind == "camera_tilt":
        if lab.design["photos"] == "none":
            return None, "no heap photos in the plan (--photos analytic adds two-flank photos; slower)"
        return None, "needs two or more heap photos showing both flanks"
    if kind == "velocity_dependent_restitution" and "drop" in lab.varied:
        return None, f"drops from one height ({lab.design['drop_heights_mm'][0]:g} mm); it needs two or more"
    wanted = ", ".join(f"{c} in {s}" for s, c in TARGETS[kind])
    return None, f"the design varies none of: {wanted}"


def detected_mechanisms(path, *, alpha: float = DEFAULT_ALPHA, correction: str = "bh") -> set:
    """Mechanisms the critique's data diagnosis names in a workbook (``demcal critique --no-twins``)."""
    from demcal.analyse.critique.loop import run_critique

    critique = run_critique(path, twins=False, extensions=(), alpha=alpha, correction=correction)
    return {f.mechanism for f in critique.found()}


@dataclass(frozen=True)
class DetectionRate:
    """Detections among the virtual workbooks of one effect size.

    Attributes
    ----------
    hits, n : int
        Workbooks in which the critique named the mechanism, and workbooks.
    refused : int
        Workbooks the measure stage refused (counted as not detected: the critique stops there).
    reason : str
        The last refusal's message.
    """

    hits: int
    n: int
    refused: int = 0
    reason: str = ""


def detection_rate(lab: LabDesign, effect, seeds, workdir, *, alpha: float = DEFAULT_ALPHA,
                   correction: str = "bh", bar=None) -> DetectionRate:
    """In how many virtual workbooks of ``lab`` with ``effect`` planted, one per seed, the
    critique names the effect's mechanism.

    Parameters
    ----------
    lab : LabDesign
    effect : simulate.virtual_lab.PlantedEffect
    seeds : sequence of numpy.random.SeedSequence or int
        One workbook each (the same seeds at every size: common random numbers).
    workdir : Path
        Folder the workbooks are written to, one after the other.
    alpha, correction
        The critique's significance level and multiple-testing correction.
    bar : tqdm, optional
        Advanced by one per workbook.

    Returns
    -------
    DetectionRate
    """
    from demcal.errors import DemcalError
    from demcal.simulate.virtual_lab import write_virtual_workbook

    hits, refused, reason = 0, 0, ""
    for seed in seeds:
        vw = write_virtual_workbook(lab.truth, Path(workdir) / "workbook", effects=(effect,),
                                    rng=np.random.default_rng(seed), **lab.design)
        try:
            hits += effect.kind in detected_mechanisms(vw.path, alpha=alpha, correction=correction)
        except DemcalError as exc:
            # e.g. rebound heights that fall with drop height: `demcal critique` stops there too
            refused += 1
            reason = str(exc)
        if bar is not None:
            bar.update(1)
    return DetectionRate(hits, len(seeds), refused, reason)


# ----------------------------------------------------------------------------------------------
# the plan


@dataclass(frozen=True)
class MechanismPower:
    """The smallest detectable effect of one mechanism.

    Attributes
    ----------
    mechanism : str
    sheet, covariate, unit : str or None
        Where it was planted, what it varies with, the unit of ``size``.
    size : float or None
        Smallest planted size found whose detection rate reached the power (``reached``), else
        the largest tried; None when not testable.
    strength : float or None
        |size| (90 - size for the lowest release angle).
    hits, n : int
        Detections and workbooks at ``size``.
    rate : float or None
        hits / n.
    ci95 : list of float or None
        Clopper-Pearson 95 % interval of the rate.
    reached : bool
        The rate reached the power at some size tried.
    at_floor : bool
        It reached it at the smallest size tried: ``size`` bounds the smallest detectable effect.
    points : list of dict
        Every size evaluated: ``size``, ``hits``, ``n``.
    note : str
        Why not testable, not reached, or only bounded.
    """

    mechanism: str
    sheet: str | None = None
    covariate: str | None = None
    unit: str | None = None
    size: float | None = None
    strength: float | None = None
    hits: int = 0
    n: int = 0
    rate: float | None = None
    ci95: list | None = None
    reached: bool = False
    at_floor: bool = False
    points: list = field(default_factory=list)
    note: str = ""

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class Plan:
    """A power plan (:func:`plan_design`); ``to_dict`` is the JSON of ``demcal plan --json``."""

    lab: LabDesign
    mechanisms: list
    reps: int
    seed: int
    power: float
    alpha: float
    correction: str
    provenance: Provenance

    def to_dict(self) -> dict:
        lab = self.lab.to_dict()
        del lab["inputs"]                    # in the provenance
        return {**lab, "power": self.power, "reps": self.reps, "seed": self.seed,
                "seeds": f"numpy.random.SeedSequence({self.seed}).spawn({self.reps})",
                "alpha": self.alpha, "correction": self.correction,
                "mechanisms": [m.to_dict() for m in self.mechanisms], "provenance": self.provenance.to_dict()}


def check_options(*, mechanisms=None, reps: int = 20, steps: int = 4, power: float = DEFAULT_POWER,
                  alpha: float = DEFAULT_ALPHA, correction: str = "bh") -> tuple:
    """Refuse options :func:`plan_design` cannot use; the mechanisms to plan (default all)."""
    from demcal.simulate.virtual_lab import EFFECT_KINDS

    kinds = tuple(mechanisms) if mechanisms else EFFECT_KINDS
    unknown = [k for k in kinds if k not in EFFECT_KINDS]
    if unknown:
        raise InputError(f"unknown mechanism(s) {', '.join(unknown)}; valid: {', '.join(EFFECT_KINDS)}")
    if int(reps) != reps or reps < 2:
        raise InputError(f"reps must be an integer >= 2, got {reps!r}")
    if int(steps) != steps or steps < 0:
        raise InputError(f"steps must be an integer >= 0, got {steps!r}")
    if correction not in CORRECTIONS:
        raise InputError(f"correction must be one of {', '.join(CORRECTIONS)}, got {correction!r}")
    if not 0 < alpha < 1:
        raise InputError(f"alpha must be in (0, 1), got {alpha!r}")
    if not 0 < power < 1:
        raise InputError(f"power must be in (0, 1), got {power!r}")
    return kinds


def plan_design(lab: LabDesign, *, mechanisms=None, reps: int = 20, seed: int = 0,
                power: float = DEFAULT_POWER, steps: int = 4, alpha: float = DEFAULT_ALPHA,
                correction: str = "bh", progress: bool = False) -> Plan:
    """The smallest effect of each mechanism the design detects with probability ``power``.

    Parameters
    ----------
    lab : LabDesign
        From :func:`read_design`.
    mechanisms : sequence of str, optional
        Kinds to plan (default every one of ``EFFECT_KINDS``).
    reps : int
        Virtual workbooks per effect size.
    seed : int
        Root of the workbooks' seeds (``SeedSequence(seed).spawn(reps)``, the same at every size
        and for every mechanism).
    power : float
        Detection rate to reach.
    steps : int
        Bisections after the bracket (:func:`smallest_reaching`).
    alpha, correction
        The critique's significance level and multiple-testing correction.
    progress : bool
        A progress bar on stderr (shown on a terminal).

    Returns
    -------
    Plan
    """
    kinds = check_options(mechanisms=mechanisms, reps=reps, steps=steps, power=power, alpha=alpha,
                          correction=correction)
    seeds = np.random.SeedSequence(seed).spawn(int(reps))
    out = []
    with tempfile.TemporaryDirectory(prefix="demcal-plan-") as workdir:
        for kind in kinds:
            target, reason = choose_target(kind, lab)
            if target is None:
                out.append(MechanismPower(kind, note=f"not testable: {reason}"))
                continue
            out.append(_plan_one(lab, target, seeds, workdir, power=power, steps=steps, alpha=alpha,
                                 correction=correction, progress=progress))
    options = {"mechanisms": list(kinds), "reps": reps, "power": power, "steps": steps, "alpha": alpha,
               "correction": correction, "photos": lab.design["photos"]}
    return Plan(lab=lab, mechanisms=out, reps=int(reps), seed=seed, power=power, alpha=alpha,
                correction=correction, provenance=Provenance(inputs=dict(lab.inputs), seed=seed, options=options))


def _plan_one(lab, target: Target, seeds, workdir, *, power, steps, alpha, correction, progress) -> MechanismPower:
    from tqdm.auto import tqdm

    bar = tqdm(total=len(seeds) * (steps + 2), desc=target.kind, unit="workbook", file=sys.stderr,
               disable=None if progress else True, leave=False)

    rates = {}

    def rate(strength):
        if bar.n + len(seeds) > bar.total:
            bar.total = bar.n + len(seeds)
            bar.refresh()
        bar.set_postfix_str(f"size {target.size(strength):.3g}")
        rates[strength] = detection_rate(lab, target.effect(strength), seeds, workdir, alpha=alpha,
                                         correction=correction, bar=bar)
        return rates[strength].hits, rates[strength].n

    try:
        found = smallest_reaching(rate, target.start, target=power, steps=steps, limit=target.limit)
    finally:
        bar.close()
    notes = []
    if not found.reached:
        notes.append(f"not reached: largest size tried detected in {found.hits} of {found.n} workbooks")
    elif found.at_floor:
        notes.append("reached at the smallest size tried: the smallest detectable effect is at most this")
    refused = {x: r for x, r in rates.items() if r.refused}
    if refused:
        x, r = max(refused.items())
        notes.append(f"the measure stage refused {sum(r.refused for r in refused.values())} workbooks (counted "
                     f"as not detected), {r.refused} of {r.n} at size {target.size(x):.3g}: {r.reason}")
    return MechanismPower(
        target.kind, sheet=target.sheet, covariate=target.covariate, unit=target.unit,
        size=target.size(found.strength), strength=found.strength, hits=found.hits, n=found.n,
        rate=found.hits / found.n, ci95=list(clopper_pearson(found.hits, found.n)), reached=found.reached,
        at_floor=found.at_floor,
        points=[{"size": target.size(x), "hits": k, "n": n, "refused": rates[x].refused} for x, k, n in found.points],
        note="; ".join(notes))


# ----------------------------------------------------------------------------------------------
# where to drop: the drop twin's sensitivity to the contact restitution by orientation

#: Release orientations of the orientation design [deg].
ORIENTATION_GRID = tuple(range(0, 91, 10))
#: Half step of the central difference in the contact restitution [-].
RESTITUTION_STEP = 0.05


@dataclass(frozen=True)
class OrientationSensitivity:
    """How well drops released at one orientation identify a pair's contact restitution.

    Attributes
    ----------
    pair : str
    orientation_deg : float
        Angle of the long axis to the horizontal at release [deg].
    apparent : float
        The drop twin's apparent restitution sqrt(h2/h1) there [-].
    sensitivity : float
        d apparent / d e of the twin [-]: 1 where sqrt(h2/h1) reads e itself (one contact
        through the centre of mass), near 0 where the drop says nothing of e.
    """

    pair: str
    orientation_deg: float
    apparent: float
    sensitivity: float

    def to_dict(self) -> dict:
        return asdict(self)


def orientation_design(params, pairs, height_m: float, *, grid=ORIENTATION_GRID,
                       step: float = RESTITUTION_STEP) -> list:
    """The drop twin's sensitivity of the apparent restitution to each pair's contact
    restitution, release orientation by orientation: the central difference of the drop rig
    (``simulate.rigs.drop``) at e - step and e + step (clipped to (0, 1)), from ``height_m``,
    with ``params`` otherwise (its extensions included). A lab that releases its drops where
    the sensitivity is near 1 measures e directly; where it is small, the rebound hardly
    depends on e (the body turns the energy into rotation, or lands on several spheres).

    Returns
    -------
    list of OrientationSensitivity
        One per pair and orientation, in the order given.
    """
    from demcal.simulate.extensions import restitution_parameter
    from demcal.simulate.rigs import rig, run_rig

    out = []
    for pair in pairs:
        name = restitution_parameter(pair)
        e = float(getattr(params, name))
        lo, hi = max(e - step, 0.01), min(e + step, 1.0)

        def apparent(value, angle):
            return float(run_rig("drop", params.with_(**{name: value}), 0, height=height_m, pair=pair,
                                 orientation_deg=float(angle)).observable[rig("drop").compared])

        for angle in grid:
            out.append(OrientationSensitivity(pair, float(angle), apparent(e, angle),
                                              (apparent(hi, angle) - apparent(lo, angle)) / (hi - lo)))
    return out
