"""The typed result of a calibration campaign: what ``analyse`` hands to ``report`` and the audit.

``results.json`` is ``CampaignResult.to_dict()``, and ``CampaignResult.from_dict`` reads it back,
refusing unknown or missing keys by name, so that a renamed key fails where the result is made
or read, not half-way through a report. ``SCHEMA_VERSION`` is recorded in the file.

The headline (calibration and validation) is typed field by field. The workflows' working
sections (the noise study, the design runs, the surrogate; the Plackett-Burman screening,
steepest climb, Box-Behnken fit and optimisation of the paper's procedure) are carried as the
dictionaries their analysis objects serialise to.
"""

from __future__ import annotations

import math
from dataclasses import MISSING, dataclass, field, fields, replace

from demcal.errors import InputError
from demcal.jsonio import check_schema, restore_nan, to_jsonable
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


class _Record:
    """JSON round trip of a frozen dataclass whose fields are its keys."""

    #: Fields left out of ``to_dict`` when they are None (sections of the other workflow).
    _omit_if_none: tuple = ()

    def to_dict(self) -> dict:
        d = {f.name: getattr(self, f.name) for f in fields(self)
             if not (f.name in self._omit_if_none and getattr(self, f.name) is None)}
        return to_jsonable({k: v.to_dict() if isinstance(v, _Record) else v for k, v in d.items()})


@dataclass(frozen=True)
class ParameterEstimate(_Record):
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

    @classmethod
    def from_dict(cls, d: dict, where: str = "parameter") -> "ParameterEstimate":
        return _build(cls, {**d, "ci95": tuple(d.get("ci95") or ())}, where)


@dataclass(frozen=True)
class Point(_Record):
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

    @classmethod
    def from_dict(cls, d: dict, where: str = "point") -> "Point":
        return _build(cls, d, where)


def _parameters(d: dict, where: str) -> dict:
    return {n: ParameterEstimate.from_dict(p, f"{where}.{n}") for n, p in d.items()}


@dataclass(frozen=True)
class HeapOnly(_Record):
    """The heap-only posterior on the same surrogate, for comparison with a joint calibration."""

    parameters: dict
    recommended: Point
    ess: float

    def to_dict(self) -> dict:
        return to_jsonable({"parameters": {n: p.to_dict() for n, p in self.parameters.items()},
                            "recommended": self.recommended.to_dict(), "ess": self.ess})

    @classmethod
    def from_dict(cls, d: dict, where: str = "heap_only") -> "HeapOnly":
        d = dict(d)
        d["parameters"] = _parameters(d.get("parameters", {}), f"{where}.parameters")
        d["recommended"] = Point.from_dict(d.get("recommended", {}), f"{where}.recommended")
        return _build(cls, d, where)


@dataclass(frozen=True)
class Calibration(_Record):
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
    samples : dict
        Prior and posterior samples kept for the plots.
    """

    method: str
    likelihood: str
    parameters: dict
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

    def to_dict(self) -> dict:
        d = super().to_dict()
        d["parameters"] = {n: p.to_dict() for n, p in self.parameters.items()}
        return d

    @classmethod
    def from_dict(cls, d: dict, where: str = "calibration") -> "Calibration":
        d = dict(d)
        d["parameters"] = _parameters(d.get("parameters", {}), f"{where}.parameters")
        d["recommended"] = Point.from_dict(d.get("recommended", {}), f"{where}.recommended")
        if d.get("posterior_mode") is not None:
            d["posterior_mode"] = Point.from_dict(d["posterior_mode"], f"{where}.posterior_mode")
        if d.get("heap_only") is not None:
            d["heap_only"] = HeapOnly.from_dict(d["heap_only"], f"{where}.heap_only")
        return _build(cls, d, where)


@dataclass(frozen=True)
class Validation(_Record):
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

    @classmethod
    def from_dict(cls, d: dict, where: str = "validation") -> "Validation":
        d = restore_nan({**d, "ci95": tuple(d.get("ci95") or (math.nan, math.nan))}, "detectable_bias_deg")
        return _build(cls, d, where)


@dataclass(frozen=True)
class CampaignResult(_Record):
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
        repose twin's box.
    validation : Validation
    calibrated_parameters : dict
        The DEM parameters after calibration (``DEMParameters.to_dict()``).
    stages : list
        Per stage: runs asked, run, reused.
    provenance : Provenance
    calibration : Calibration or None
        Plausible workflow.
    prior, noise, design, surrogate : dict or None
        Plausible workflow (``noise`` also in the paper's procedure, with its own layout).
    plackett_burman, significant, steepest_climb, box_behnken, optimisation : dict or None
        The paper's procedure.
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
    prior: dict | None = None
    noise: dict | None = None
    design: dict | None = None
    surrogate: dict | None = None
    plackett_burman: dict | None = None
    significant: dict | None = None
    steepest_climb: dict | None = None
    box_behnken: dict | None = None
    optimisation: dict | None = None
    runner: str | None = None
    wall_s: float | None = None
    schema_version: int = SCHEMA_VERSION

    _omit_if_none = ("calibration", "prior", "noise", "design", "surrogate", "plackett_burman",
                     "significant", "steepest_climb", "box_behnken", "optimisation", "runner", "wall_s")

    @classmethod
    def from_dict(cls, d: dict, where: str = "results.json") -> "CampaignResult":
        d = dict(d)
        check_schema(d, SCHEMA_VERSION, where)
        d["validation"] = Validation.from_dict(d.get("validation", {}), f"{where}: validation")
        if d.get("calibration") is not None:
            d["calibration"] = Calibration.from_dict(d["calibration"], f"{where}: calibration")
        prov = d.get("provenance")
        if isinstance(prov, dict):
            d["provenance"] = _build(Provenance, prov, f"{where}: provenance")
        return _build(cls, d, where)

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
                lines.append(f"  {name:14s} {p.value:.4g}  95 % set [{p.ci95[0]:.4g}, {p.ci95[1]:.4g}]"
                             f"  posterior/prior sd {p.sd_ratio:.2f} ({p.identifiability})")
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
        conf = v.confirmation
        if conf:
            lo, hi = conf["pi95"]
            lines.append(f"Design-Expert confirmation: predicted {conf['predicted']:.2f} deg, 95 % PI of the "
                         f"mean of {v.n_runs} runs [{lo:.2f}, {hi:.2f}]: the target lies "
                         + ("inside" if conf["target_inside"] else "outside"))
        return "\n".join(lines)
