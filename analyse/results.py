"""The typed result of a calibration campaign: what ``analyse`` hands to ``report`` and the audit.

``results.json`` is ``CampaignResult.to_dict()``, and ``CampaignResult.from_dict`` reads it back,
refusing unknown or missing keys by name, so that a renamed key fails where the result is made
or read, not half-way through a report. ``SCHEMA_VERSION`` is recorded in the file.

Every section is a record whose fields are its keys: the headline (calibration and
validation), the plausible workflow's prior, noise study, design runs and surrogate, and the
paper procedure's screening, steepest climb, Box-Behnken fit and optimisation. Run references,
logs and the analyses' small lookup tables (effects per factor, coefficients per term) stay
dictionaries and lists.
"""

from __future__ import annotations

import math
from dataclasses import MISSING, dataclass, field, fields, is_dataclass, replace
from types import UnionType
from typing import Union, get_args, get_origin, get_type_hints

from demcal.errors import InputError
from demcal.jsonio import check_schema, restore_nan, to_jsonable
from demcal.analyse.noise import NoiseSummary, SeedCorrelation
from demcal.analyse.regression import AnovaRow, FitStatistics
from demcal.provenance import Provenance

#: Version of the layout of ``results.json``; files without one were written before it was
#: recorded and have the layout of version 1 without ``posterior_mode``.
SCHEMA_VERSION = 1


def _build(cls, d: dict, where: str):
    """``cls(**d)``, naming the unknown or missing keys instead of a TypeError."""
    if not isinstance(d, dict):
        raise InputError(f"{where}: expected an object, got {type(d).__name__}")
    names = {f.name for f in fields(cls)}
    unknown = sorted(set(d) - names)
    if unknown:
        raise InputError(f"{where}: unknown key(s) {', '.join(unknown)} (results schema version {SCHEMA_VERSION})")
    missing = sorted(f.name for f in fields(cls)
                     if f.default is MISSING and f.default_factory is MISSING and f.name not in d)
    if missing:
        raise InputError(f"{where}: missing key(s) {', '.join(missing)}")
    return cls(**d)


def _typed(tp, value, where: str):
    """``value`` (as JSON holds it) as the annotated type ``tp``: dataclasses (records, and the
    analysis modules' ANOVA rows, fit statistics and noise summaries) are built from their keys,
    tuples, lists and dicts of them element by element; anything else is kept as it is."""
    if value is None:
        return None
    origin, args = get_origin(tp), get_args(tp)
    if origin in (Union, UnionType):
        kinds = [a for a in args if a is not type(None)]
        return _typed(kinds[0], value, where) if len(kinds) == 1 else value
    if isinstance(tp, type) and is_dataclass(tp):
        if isinstance(value, tp):
            return value
        if issubclass(tp, Record):
            return tp.from_dict(value, where)
        return _build(tp, value, where)
    if tp is tuple:
        return tuple(value)
    if origin is tuple and len(args) == 2 and args[1] is Ellipsis:
        return tuple(_typed(args[0], v, f"{where}[{i}]") for i, v in enumerate(value))
    if origin is tuple:
        return tuple(value)
    if origin is list and args:
        return [_typed(args[0], v, f"{where}[{i}]") for i, v in enumerate(value)]
    if origin is dict and len(args) == 2:
        return {k: _typed(args[1], v, f"{where}.{k}") for k, v in value.items()}
    return value


def _plain(value):
    """``value`` with every record replaced by its ``to_dict``."""
    if isinstance(value, Record):
        return value.to_dict()
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


class Record:
    """JSON round trip of a frozen dataclass whose fields are its keys.

    ``from_dict`` builds nested records from their annotations, refusing unknown or missing
    keys by name; ``to_dict`` is the inverse.
    """

    #: Fields left out of ``to_dict`` when they are None (sections of the other workflow).
    _omit_if_none: tuple = ()
    #: Float fields JSON holds as None for NaN (``to_jsonable``), restored on reading.
    _nan_fields: tuple = ()

    def to_dict(self) -> dict:
        d = {f.name: getattr(self, f.name) for f in fields(self)
             if not (f.name in self._omit_if_none and getattr(self, f.name) is None)}
        return to_jsonable(_plain(d))

    @classmethod
    def from_dict(cls, d: dict, where: str | None = None):
        where = where or cls.__name__
        if not isinstance(d, dict):
            raise InputError(f"{where}: expected an object, got {type(d).__name__}")
        hints = get_type_hints(cls)
        d = restore_nan(d, *cls._nan_fields)
        return _build(cls, {k: _typed(hints[k], v, f"{where}.{k}") if k in hints else v
                            for k, v in d.items()}, where)


@dataclass(frozen=True)
class ParameterEstimate(Record):
    """What the calibration says about one contact parameter (``--set`` name).

    Attributes
    ----------
    value : float
        Recommended value.
    ci95 : tuple of float
        95 % interval of the posterior (the plausible set's extent in this parameter).
    prior_mean, prior_sd : float
        The prior: the parameter's own lab test (or its twin).
    posterior_mean, posterior_sd : float
    sd_ratio : float
        posterior_sd / prior_sd: near 1 the heap does not identify the parameter.
    identifiability : str
        The ratio in words.
    source : str
        Where the prior comes from (quantity, and the twin when one was used).
    """

    value: float
    ci95: tuple
    prior_mean: float
    prior_sd: float
    sd_ratio: float
    posterior_mean: float
    posterior_sd: float
    identifiability: str
    source: str



@dataclass(frozen=True)
class Point(Record):
    """A point of the parameter space with the surrogate's prediction of the mean angle there.

    Attributes
    ----------
    values : dict
        Parameter name -> value.
    predicted, predicted_sd : float
        Surrogate mean of the mean angle and its sd [deg].
    implausibility : float
        |target - predicted| over the combined sd.
    log_posterior : float
        Unnormalised.
    chosen : str
        How the point was chosen (``posterior mode``, ``refined point of round 2``).
    """

    values: dict
    predicted: float
    predicted_sd: float
    implausibility: float
    log_posterior: float
    chosen: str = "posterior mode"



@dataclass(frozen=True)
class HeapOnly(Record):
    """The heap-only posterior on the same surrogate, for comparison with a joint calibration."""

    parameters: dict[str, ParameterEstimate]
    recommended: Point
    ess: float


@dataclass(frozen=True)
class Calibration(Record):
    """The plausible set and the recommended point (``results["calibration"]``).

    Attributes
    ----------
    method, likelihood : str
        How the posterior was made; ``joint`` or ``heap``.
    parameters : dict of str -> ParameterEstimate
    recommended : Point
        Where the validation runs.
    posterior_mode : Point or None
        The posterior mode (the recommended point unless refinement chose a measured one).
    recommended_inside_ci95 : dict of str -> bool
    target_deg, target_sd_deg, target_n, target_var : float, float or None, int or None, float
        The lab's angle, its heap-to-heap sd, heaps, and the variance of its mean.
    discrepancy_sd_deg : float
    plausible : dict
        ``cut``, ``share_of_prior``, ``box`` of the history-matching set.
    ess : float
        Effective sample size of the importance-sampled posterior.
    twins : dict
        Per parameter, what its lab test's twin says (joint calibration).
    heap_only : HeapOnly or None
    by_rig : dict or None
        With several repose rigs: per rig (workbook name), per parameter, the ``sd_ratio`` and
        ``ci95`` of the posterior given that rig's heap alone (same prior, the rig's own
        surrogate), beside ``parameters`` given every rig's.
    samples : dict
        Prior and posterior samples kept for the plots.
    """

    _omit_if_none = ("by_rig",)

    method: str
    likelihood: str
    parameters: dict[str, ParameterEstimate]
    recommended: Point
    recommended_inside_ci95: dict
    target_deg: float
    target_sd_deg: float | None
    target_n: int | None
    target_var: float
    discrepancy_sd_deg: float
    plausible: dict
    ess: float
    twins: dict = field(default_factory=dict)
    heap_only: HeapOnly | None = None
    posterior_mode: Point | None = None
    samples: dict = field(default_factory=dict)
    by_rig: dict | None = None


@dataclass(frozen=True)
class Validation(Record):
    """Runs at the calibrated point, tested for equivalence with the lab (``results["validation"]``).

    Attributes
    ----------
    verdict : str
        ``equivalent``, ``different`` or ``undecided``.
    mean_deg : float
        Mean simulated angle.
    ci95 : tuple of float
    tolerance_deg, target_deg : float
    n_runs : int
    detectable_bias_deg : float
        Smallest bias the test detects with 80 % power (NaN when no test was possible).
    settings : dict
        The calibrated parameters that were run.
    responses, seeds, runs : list
        One angle, seed and run reference per validation run (the paper's procedure: per
        validation point, the median of its replicates).
    test : dict or None
        The equivalence test (``analyse.equivalence``), with its looks when sequential.
    power_if_on_target, runs_for_power, runs_for_power_exact_target, lab_heaps_for_power
        Plausible workflow: could this validation have succeeded at all.
    replicate_responses, noise_sd, noise_df, result, confirmation
        The paper's procedure: every replicate, the pooled noise, the t-interval check and
        Design-Expert's confirmation interval.
    """

    verdict: str
    mean_deg: float
    ci95: tuple
    tolerance_deg: float
    target_deg: float
    n_runs: int
    detectable_bias_deg: float | None
    settings: dict
    responses: list
    seeds: list
    runs: list
    test: dict | None = None
    power_if_on_target: float | None = None
    runs_for_power: int | None = None
    runs_for_power_exact_target: int | None = None
    lab_heaps_for_power: int | None = None
    replicate_responses: list | None = None
    noise_sd: float | None = None
    noise_df: int | None = None
    result: dict | None = None
    confirmation: dict | None = None

    _omit_if_none = ("power_if_on_target", "runs_for_power", "runs_for_power_exact_target",
                     "lab_heaps_for_power", "replicate_responses", "noise_sd", "noise_df", "result",
                     "confirmation")

    _nan_fields = ("detectable_bias_deg",)

    @classmethod
    def from_dict(cls, d: dict, where: str = "validation") -> "Validation":
        return super().from_dict({**d, "ci95": d.get("ci95") or (math.nan, math.nan)}, where)


# --------------------------------------------------------------------------------------------
# Working sections of the plausible workflow (``analyse.plausible``)

@dataclass(frozen=True)
class PriorMarginal(Record):
    """One parameter's prior: normal (mean, sd) truncated to [low, high], from its lab test."""

    mean: float
    sd: float
    low: float
    high: float
    truncated_mean: float
    truncated_sd: float
    source: str | None


@dataclass(frozen=True)
class NoiseStudy(Record):
    """The seed-to-seed noise of the plausible workflow (``analyse.noise``).

    Attributes
    ----------
    centre : NoiseSummary
        From the same-seed pair of points.
    design : NoiseSummary or None
        From the replicates of the design points.
    all_points : NoiseSummary
        Pooled over every point; its ``sd`` is the noise the surrogate carries.
    seed_correlation : SeedCorrelation
        Of the same-seed pairs: whether common random numbers would pay off.
    replicates : int
        Runs per design point, and how that was chosen (``replicates_rule``).
    pairs : dict
        The pair's two points (``a``, ``b``), seeds and responses (``b_seeds`` when a heap of the
        pair was poured again, so that the pair no longer shares every seed).
    """

    centre: NoiseSummary
    design: NoiseSummary | None
    all_points: NoiseSummary
    seed_correlation: SeedCorrelation
    replicates: int
    replicates_rule: str
    pairs: dict


@dataclass(frozen=True)
class DesignPoint(Record):
    """A design point's runs: its stage (``noise``, ``design``, ``sequential``, ``refine``),
    settings, one response, seed and run reference per run, and their mean [deg]."""

    stage: str
    settings: dict
    responses: list
    mean: float
    seeds: list
    runs: list


@dataclass(frozen=True)
class DesignRuns(Record):
    """Every design point of the plausible workflow and how the sequence of rounds went.

    ``rounds`` logs each sequential round, ``refinements`` each refinement at the posterior
    mode, ``stopped_because`` why the design ended."""

    points: tuple[DesignPoint, ...]
    replicates: int
    initial_points: int
    batch: int
    budget_runs: int
    rounds: list
    stopped_because: str
    refinements: list


@dataclass(frozen=True)
class SurrogateSummary(Record):
    """The fitted surrogate: its kernel, length scales per parameter, leave-one-out check and
    noise model (pooled, or per point shrunk to the pooled)."""

    kernel: str
    length_scales: dict
    leave_one_out: dict
    noise_model: str


@dataclass(frozen=True)
class OtherRig(Record):
    """A workbook's second (or further) repose rig in the plausible workflow: its heaps join the
    posterior through a surrogate of their own (``results["other_rigs"]``).

    Attributes
    ----------
    rig, workbook_name, quantity : str
        The registered rig, its name in the workbook and the measured quantity
        (``repose_angle_deg.<rig>``).
    geometry : dict
        Its dimensions.
    target_deg, target_sd_deg, target_n, target_var
        The lab's angle in this rig, heap-to-heap sd, heaps and the variance of the mean.
    noise, design, surrogate : NoiseStudy, DesignRuns, SurrogateSummary
        As the first rig's sections of the same names.
    predicted : dict
        The rig's surrogate at the recommended point: ``mean_deg``, ``sd_deg``.
    validation : Validation
        The rig's runs at the recommended point, tested for equivalence with its lab angle.
    """

    rig: str
    workbook_name: str
    quantity: str
    geometry: dict
    target_deg: float
    target_sd_deg: float | None
    target_n: int | None
    target_var: float
    noise: NoiseStudy
    design: DesignRuns
    surrogate: SurrogateSummary
    predicted: dict
    validation: Validation


@dataclass(frozen=True)
class ExtraTarget(Record):
    """Another reading of a rig's heaps the plausible workflow fitted because it was asked to
    (``CampaignConfig.extra_targets``), beside the angle (``results["extra_targets"]``).

    Attributes
    ----------
    name, quantity, rig, observable, unit : str
        The target (``crest_height_mm``), the lab's quantity (``crest_height_mm.<rig>`` for a
        further rig), the rig, the twin's observable that mirrors it and the lab's unit.
    target, target_sd, target_n, target_var
        The lab's mean, heap-to-heap sd, heaps and the variance of the mean.
    lab_cov : float
        Covariance of the lab's mean reading and its rig's mean angle (the same photos): the
        likelihood of the two is a bivariate normal.
    run_sd : float
        Pooled sd of one run's reading.
    point_means : list
        The mean reading at each of the rig's design points (None: no run read it).
    length_scales, leave_one_out : dict
        Its surrogate's.
    predicted : dict
        Its surrogate at the recommended point: ``mean``, ``sd``.
    validation : dict
        The validation runs' readings: ``mean``, ``sd``, ``n``, ``values``.
    """

    name: str
    quantity: str
    rig: str
    observable: str
    unit: str
    target: float
    target_sd: float | None
    target_n: int | None
    target_var: float
    lab_cov: float
    run_sd: float
    point_means: list
    length_scales: dict
    leave_one_out: dict
    predicted: dict
    validation: dict


# --------------------------------------------------------------------------------------------
# Working sections of the paper's procedure (``analyse.campaign``); the analysis summaries
# are the ``to_dict`` of ``ResponseSurface``, ``PlackettBurmanScreening``, ``SteepestClimbPlan``,
# ``SteepestClimbResult``, ``CanonicalAnalysis`` and ``TargetOptimum``.

@dataclass(frozen=True)
class SurfaceFit(Record):
    """A fitted response surface (``ResponseSurface.to_dict()``): coded coefficients, ANOVA
    with lack of fit, Design-Expert's fit statistics, equations and stationary point."""

    model: str
    response: str
    factors: dict
    low: dict
    high: dict
    coefficients: dict
    std_errors: dict
    ci95: dict
    block_effects: dict | None
    anova: tuple[AnovaRow, ...]
    fit: FitStatistics
    equation_coded: str
    equation_actual: str
    coefficients_actual: dict
    significant: list
    stationary_point: dict | None

    def anova_row(self, source: str) -> AnovaRow | None:
        """The ANOVA row named ``source``, or None."""
        return next((row for row in self.anova if row.source == source), None)


@dataclass(frozen=True)
class Screening(SurfaceFit):
    """A Plackett-Burman screening (``PlackettBurmanScreening.to_dict()``): the first-order fit
    plus effects, % contributions, ranking, the Pareto chart and Lenth's margins."""

    effects: dict
    dummy_effects: dict
    contribution_pct: dict
    ranking: list
    alpha: float
    pareto: dict | None
    lenth: dict | None


@dataclass(frozen=True)
class ScreeningStage(Record):
    """Step 2: the Plackett-Burman runs, their screening, and each effect against the noise."""

    design_coded: list
    columns: list
    design_actual: list
    response: list
    replicate_responses: list
    runs: list
    screening: Screening
    effects_vs_noise: dict


@dataclass(frozen=True)
class CentreNoise(Record):
    """Step 3: the screening centre run with different seeds (``sd`` of a point's response,
    ``sd_single_run`` of one run); the Box-Behnken centre points' sd for comparison."""

    settings: dict
    seeds: list
    responses: list
    replicate_responses: list
    sd: float
    sd_single_run: float
    replicates: int
    runs: list
    bbd_centre_sd: float


@dataclass(frozen=True)
class FactorChoice(Record):
    """The factors the screening flagged, those carried forward, and why they differ."""

    flagged: list
    carried_forward: list
    note: str


@dataclass(frozen=True)
class ClimbPlan(Record):
    """``SteepestClimbPlan.to_dict()``: the stepped factors, their directions and steps, and
    every factor's value at each level."""

    factors: list
    stepped: list
    directions: dict
    step: dict
    levels: list


@dataclass(frozen=True)
class ClimbResult(Record):
    """``SteepestClimbResult.to_dict()``: the level closest to the target and the window the
    Box-Behnken design takes from it (levels are numbered from 1)."""

    responses: list
    smoothed: list | None
    relative_error_pct: list
    target: float
    best_level: int
    centre: dict
    low: dict
    high: dict
    at_edge: bool
    note: str
    centre_level: int


@dataclass(frozen=True)
class SteepestClimbStage(Record):
    """Step 4: the climb's runs and its analysis; ``increase`` is the direction toward the target."""

    plan: ClimbPlan
    response: list
    replicate_responses: list
    runs: list
    result: ClimbResult
    increase: bool


@dataclass(frozen=True)
class Canonical(Record):
    """``CanonicalAnalysis.to_dict()``: eigenvalues and vectors of B, the stationary point and
    its nature (``maximum``, ``minimum``, ``saddle``, with a ridge when one is near flat)."""

    eigenvalues: list
    eigenvectors: list
    stationary_coded: dict | None
    stationary_actual: dict | None
    predicted: float | None
    inside_region: bool
    verdict: str
    ridge: str | None
    near_zero: list


@dataclass(frozen=True)
class BoxBehnkenStage(Record):
    """Step 5: the Box-Behnken design in the window the climb chose, its runs, the quadratic
    fit with its canonical analysis, and each coefficient against the noise."""

    factors: list
    low: list
    high: list
    centre: list
    fixed: dict
    design_coded: list
    design_actual: list
    response: list
    replicate_responses: list
    runs: list
    fit: SurfaceFit
    canonical: Canonical
    terms_vs_noise: dict


@dataclass(frozen=True)
class Solution(Record):
    """A point where the fitted surface meets the target, coded and actual."""

    coded: dict
    actual: dict
    predicted: float
    distance: float


@dataclass(frozen=True)
class Optimisation(Record):
    """Step 6, ``TargetOptimum.to_dict()``: the solutions of yhat = target in the coded cube,
    the preferred one (closest to the measured means) first."""

    target: float
    reached: bool
    preferred: Solution
    solutions: tuple[Solution, ...]
    reference_coded: dict
    reference_actual: dict
    note: str


@dataclass(frozen=True)
class CampaignResult(Record):
    """Everything a calibration campaign found, in the layout of ``results.json``.

    Attributes
    ----------
    workflow : str
        ``plausible`` or ``design-expert``.
    response : dict
        The response's name and the runs read by a fallback method.
    material : str
    target_angle_deg : float
        The lab's angle of repose.
    config : dict
        The settings (``CampaignConfig.from_dict`` rebuilds them).
    measurement : dict
        ``Measurement.to_dict()`` of the workbook the campaign started from.
    factors, base_parameters, geometry : dict
        The seven factors with their levels, the DEM parameters before calibration, the
        repose twin's dimensions.
    repose_rig : str
        The repose rig (the workbook's meta ``repose_rig``: ``lifted_plate``,
        ``lifting_cylinder``).
    validation : Validation
    calibrated_parameters : dict
        The DEM parameters after calibration (``DEMParameters.to_dict()``).
    stages : list
        Per stage: runs asked, run, reused.
    provenance : Provenance
    calibration : Calibration or None
        Plausible workflow.
    prior : dict of str -> PriorMarginal, or None
    noise : NoiseStudy (plausible) or CentreNoise (the paper's procedure)
    design, surrogate : DesignRuns, SurrogateSummary or None
        Plausible workflow.
    plackett_burman, significant, steepest_climb, box_behnken, optimisation
        The paper's procedure: ScreeningStage, FactorChoice, SteepestClimbStage,
        BoxBehnkenStage, Optimisation, or None.
    other_rigs : list of OtherRig or None
        Plausible workflow with several repose rigs: the second and further rigs (the first
        rig's are the sections above).
    extra_targets : list of ExtraTarget or None
        Plausible workflow: the rigs' other readings fitted beside the angles, when asked.
    runner, wall_s : str, float or None
        The DEM runner and the campaign's wall time (not re-derived by the audit).
    schema_version : int
    """

    workflow: str
    response: dict
    material: str
    target_angle_deg: float
    config: dict
    measurement: dict
    factors: dict
    base_parameters: dict
    geometry: dict
    validation: Validation
    calibrated_parameters: dict
    stages: list
    provenance: Provenance
    calibration: Calibration | None = None
    prior: dict[str, PriorMarginal] | None = None
    noise: NoiseStudy | CentreNoise | None = None
    design: DesignRuns | None = None
    surrogate: SurrogateSummary | None = None
    plackett_burman: ScreeningStage | None = None
    significant: FactorChoice | None = None
    steepest_climb: SteepestClimbStage | None = None
    box_behnken: BoxBehnkenStage | None = None
    optimisation: Optimisation | None = None
    other_rigs: list[OtherRig] | None = None
    extra_targets: list[ExtraTarget] | None = None
    runner: str | None = None
    wall_s: float | None = None
    repose_rig: str = "lifted_plate"
    schema_version: int = SCHEMA_VERSION

    _omit_if_none = ("calibration", "prior", "noise", "design", "surrogate", "plackett_burman",
                     "significant", "steepest_climb", "box_behnken", "optimisation", "other_rigs", "extra_targets", "runner",
                     "wall_s")

    @classmethod
    def from_dict(cls, d: dict, where: str = "results.json") -> "CampaignResult":
        check_schema(d, SCHEMA_VERSION, where)
        noise = d.get("noise")
        if isinstance(noise, dict):  # each workflow measures the noise its own way
            kind = NoiseStudy if d.get("workflow") == "plausible" else CentreNoise
            d = {**d, "noise": kind.from_dict(noise, f"{where}: noise")}
        return super().from_dict(d, where)

    def with_(self, **changes) -> "CampaignResult":
        """A copy with some fields replaced (e.g. ``runner`` and ``wall_s`` after the run)."""
        return replace(self, **changes)

    def summary(self) -> str:
        """The headline: calibrated values (with the plausible set's 95 % intervals) and the
        validation verdict."""
        v = self.validation
        lines = [f"target angle {self.target_angle_deg:.2f} deg ({self.workflow} workflow)"]
        cal = self.calibration
        if cal:
            for name, p in cal.parameters.items():
                alone = ", ".join(f"{rig} {v[name]['sd_ratio']:.2f}" for rig, v in (cal.by_rig or {}).items())
                lines.append(f"  {name:14s} {p.value:.4g}  95 % set [{p.ci95[0]:.4g}, {p.ci95[1]:.4g}]"
                             f"  posterior/prior sd {p.sd_ratio:.2f} ({p.identifiability})"
                             + (f"; each rig alone: {alone}" if alone else ""))
            rec = cal.recommended
            lines.append(f"  predicted mean angle at the recommended point ({rec.chosen}) {rec.predicted:.2f} "
                         f"+- {rec.predicted_sd:.2f} deg")
        else:
            lines.append("calibrated " + ", ".join(f"{k} = {x:.4g}" for k, x in v.settings.items()))
        lo, hi = v.ci95
        lines.append(f"validation: {v.verdict} (tolerance {v.tolerance_deg:.2f} deg): mean "
                     f"{v.mean_deg:.2f} deg over {v.n_runs} runs, 95 % CI [{lo:.2f}, {hi:.2f}], "
                     f"target {v.target_deg:.2f}; smallest bias it would detect {v.detectable_bias_deg:.2f} deg")
        if v.power_if_on_target is not None and v.power_if_on_target < 0.8:
            def n(x):
                return "more than 1000" if x is None else str(x)
            lines.append(f"  power to show equivalence even exactly on target: {v.power_if_on_target:.2f}; "
                         f"80 % would take {n(v.runs_for_power)} runs against this lab target, "
                         f"{n(v.runs_for_power_exact_target)} against an exactly known one")
        for o in self.other_rigs or ():
            w = o.validation
            lo, hi = w.ci95
            lines.append(f"validation in the {o.workbook_name} rig: {w.verdict} (tolerance {w.tolerance_deg:.2f} deg): "
                         f"mean {w.mean_deg:.2f} deg over {w.n_runs} runs, 95 % CI [{lo:.2f}, {hi:.2f}], "
                         f"target {w.target_deg:.2f}")
        conf = v.confirmation
        if conf:
            lo, hi = conf["pi95"]
            lines.append(f"Design-Expert confirmation: predicted {conf['predicted']:.2f} deg, 95 % PI of the "
                         f"mean of {v.n_runs} runs [{lo:.2f}, {hi:.2f}]: the target lies "
                         + ("inside" if conf["target_inside"] else "outside"))
        return "\n".join(lines)


def read_campaign_results(folder) -> CampaignResult:
    """``CampaignResult`` of a campaign folder's ``results.json``; a folder without one is
    refused with the command that makes it."""
    from pathlib import Path

    from demcal.jsonio import read_json

    path = Path(folder) / "results.json"
    if not path.is_file():
        raise InputError(f"{Path(folder)} holds no results.json: run 'demcal calibrate WORKBOOK "
                         f"--out {Path(folder)}' first")
    return CampaignResult.from_dict(read_json(path), str(path))
