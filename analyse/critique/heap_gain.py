"""Heap-side gain of a model extension: the campaign run again with it, compared with the one
under critique.

A gain on held-out drops shows that an extension mends the twin of one lab test. What the
calibration is for is the heap. For each extension accepted for a found mechanism (an engine
hook a heap can switch on that does not make the held-out trials worse: a calibration that
compensates an artefact with a parameter fits the drops as well as the mended model does, and
the question is then what the mended model changes on the heap), :func:`recalibrate`
runs the campaign again with the same workbook, settings and seed and the extension on
(``CampaignConfig.model_extensions``), in ``DIR/heap_gain/<extension>/``, and
:func:`compare_campaigns` compares the two:

- **the calibrated parameters**, each with its 95 % plausible interval (plausible workflow; the
  paper's procedure gives none). A recalibrated value inside the interval of the campaign under
  critique has moved by less than the parameter's own uncertainty;
- **the heap observables the calibration does not fit**, over the validation runs of each
  campaign at its calibrated point: every observable the campaign's repose rig declares
  (``simulate.rigs.Rig.observables``; the carton's outflow fraction, outside pile angle and
  crest height, a cone's base diameter...); the difference of the means with Welch's 95 %
  interval, every run an independent draw of the chaotic heap. The fitted angle is listed too,
  marked as fitted.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy import stats

from demcal.analyse.results import CampaignResult, Record
from demcal.errors import AnalysisError

def heap_observables(rig) -> tuple:
    """The observables of a repose rig (``simulate.rigs.Rig``) as compared here: (name, scale to
    the unit shown, unit shown, fitted), lengths in mm, the rig's compared angle marked fitted."""
    return tuple((name, 1e3 if unit == "m" else 1.0, "mm" if unit == "m" else unit, name == rig.compared)
                 for name, unit in rig.observables.items())


def _rig_of(result: CampaignResult):
    from demcal.simulate.rigs import repose_rig_named

    return repose_rig_named(result.repose_rig)


#: An interval at most this share of its width before the extension counts as narrowed by it.
NARROWED = 0.5


@dataclass(frozen=True)
class ParameterShift(Record):
    """One calibrated parameter before and after the extension.

    Attributes
    ----------
    name : str
        DEM parameter (``--set`` name).
    before, after : float
        Calibrated value of the campaign under critique and of the recalibration.
    before_ci95, after_ci95 : tuple of float or None
        Their 95 % plausible intervals (None: the workflow gives none).
    shift : float
        after - before.
    within_uncertainty : bool or None
        ``after`` inside ``before_ci95`` (None without an interval).
    """

    name: str
    before: float
    after: float
    before_ci95: tuple | None
    after_ci95: tuple | None
    shift: float
    within_uncertainty: bool | None

    @property
    def narrowed(self) -> bool:
        """Whether the extension at least halved the 95 % interval (``NARROWED``): a twin that
        could not reach the lab leaves its parameter unidentified, one that can pins it down."""
        widths = []
        for ci in (self.before_ci95, self.after_ci95):
            if ci is None or any(v is None or not math.isfinite(v) for v in ci):
                return False
            widths.append(ci[1] - ci[0])
        return bool(widths[0] > 0 and widths[1] <= NARROWED * widths[0])

    @property
    def verdict(self) -> str:
        """In words: within or beyond its uncertainty, and whether its interval narrowed."""
        if self.within_uncertainty is None:
            return "no interval"
        if not self.within_uncertainty:
            return "beyond its uncertainty"
        return "within its uncertainty, interval narrowed" if self.narrowed else "within its uncertainty"


@dataclass(frozen=True)
class ObservableShift(Record):
    """One heap observable over the validation runs before and after.

    Attributes
    ----------
    name, unit : str
    fitted : bool
        The calibration fits it (the angle); the others are predictions it was not fitted to.
    before, after : float
        Mean over the runs (NaN when no run recorded it).
    before_sd, after_sd : float
        Run-to-run sd.
    n_before, n_after : int
    difference : float
        after - before.
    ci95 : tuple of float
        Welch 95 % interval of the difference.
    beyond_noise : bool or None
        The interval excludes 0 (None when it could not be formed).
    """

    name: str
    unit: str
    fitted: bool
    before: float
    before_sd: float
    n_before: int
    after: float
    after_sd: float
    n_after: int
    difference: float
    ci95: tuple
    beyond_noise: bool | None

    _nan_fields = ("before", "before_sd", "after", "after_sd", "difference")

    @classmethod
    def from_dict(cls, d: dict, where: str | None = None) -> "ObservableShift":
        return super().from_dict({**d, "ci95": tuple(math.nan if x is None else x for x in d["ci95"])}, where)


@dataclass(frozen=True)
class HeapGain(Record):
    """What an extension changes on the heap (``critique.json``'s ``heap_gains``).

    Attributes
    ----------
    extension, mechanism : str
    settings : dict
        The ``DEMParameters`` fields the recalibration set (``CampaignConfig.model_extensions``).
    campaign : str
        Folder of the recalibration, relative to the campaign under critique.
    verdict_before, verdict_after : str
        Validation verdicts of the two campaigns.
    parameters : list of ParameterShift
    observables : list of ObservableShift
    conclusion : str
        The comparison in sentences.
    """

    extension: str
    mechanism: str
    settings: dict
    campaign: str
    verdict_before: str
    verdict_after: str
    parameters: list[ParameterShift] = field(default_factory=list)
    observables: list[ObservableShift] = field(default_factory=list)
    conclusion: str = ""


def _fmt(x, d=3) -> str:
    return "n/a" if x is None or not math.isfinite(x) else f"{x:.{d}g}"


def with_unit(x, unit: str) -> str:
    """``x`` formatted, followed by its unit unless it has none (``-``)."""
    return _fmt(x) + ("" if unit in ("", "-") else f" {unit}")


def validation_values(campaign_dir, result: CampaignResult) -> dict:
    """``{observable name: array}`` over the validation runs of a campaign (its run store)."""
    from demcal.analyse.runs import RunStore

    store = RunStore(Path(campaign_dir) / "runs")
    twin = _rig_of(result)
    observables = heap_observables(twin)
    out = {name: [] for name, *_ in observables}
    for ref in result.validation.runs:
        rec = store.get(ref["key"])
        if rec is None or rec.get("result") is None:
            raise AnalysisError(f"{campaign_dir}: validation run {ref['key'][:12]} is not in its run store")
        for name, scale, _, _ in observables:
            value = twin.observed_value(rec["result"], name)
            if isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value):
                out[name].append(float(value) * scale)
    return {k: np.asarray(v, dtype=float) for k, v in out.items()}


def welch_interval(a, b) -> tuple[float, tuple]:
    """mean(b) - mean(a) and its Welch 95 % interval (NaN with fewer than 2 values on a side)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    if len(a) < 2 or len(b) < 2:
        d = float(b.mean() - a.mean()) if len(a) and len(b) else math.nan
        return d, (math.nan, math.nan)
    va, vb = a.var(ddof=1) / len(a), b.var(ddof=1) / len(b)
    d = float(b.mean() - a.mean())
    se = math.sqrt(va + vb)
    if se == 0:
        return d, (d, d)
    dof = (va + vb) ** 2 / (va ** 2 / (len(a) - 1) + vb ** 2 / (len(b) - 1))
    half = float(stats.t.ppf(0.975, dof)) * se
    return d, (d - half, d + half)


def _mean_sd(x: np.ndarray) -> tuple[float, float]:
    return (float(x.mean()) if len(x) else math.nan, float(x.std(ddof=1)) if len(x) > 1 else math.nan)


def _estimates(result: CampaignResult) -> dict:
    """``{parameter: (value, ci95 or None)}`` of a campaign's calibrated parameters."""
    if result.calibration is not None:
        return {n: (p.value, tuple(p.ci95)) for n, p in result.calibration.parameters.items()}
    return {n: (float(v), None) for n, v in result.validation.settings.items()}


def compare_campaigns(before: CampaignResult, before_values: dict, after: CampaignResult,
                      after_values: dict, *, extension: str, mechanism: str, settings: dict,
                      campaign: str) -> HeapGain:
    """The :class:`HeapGain` of two campaigns: their calibrated parameters and the heap
    observables of their validation runs (``validation_values``)."""
    est_b, est_a = _estimates(before), _estimates(after)
    params = []
    for name in est_b:
        if name not in est_a:
            continue
        (vb, cb), (va, ca) = est_b[name], est_a[name]
        inside = None if cb is None else bool(cb[0] <= va <= cb[1])
        params.append(ParameterShift(name, vb, va, cb, ca, va - vb, inside))
    obs = []
    for name, _, unit, fitted in heap_observables(_rig_of(before)):
        a, b = before_values.get(name, np.array([])), after_values.get(name, np.array([]))
        d, ci = welch_interval(a, b)
        (mb, sb), (ma, sa) = _mean_sd(a), _mean_sd(b)
        beyond = None if not all(math.isfinite(c) for c in ci) else bool(ci[0] > 0 or ci[1] < 0)
        obs.append(ObservableShift(name, unit, fitted, mb, sb, len(a), ma, sa, len(b), d, ci, beyond))
    return HeapGain(extension, mechanism, dict(settings), campaign, before.validation.verdict,
                    after.validation.verdict, params, obs,
                    _conclusion(extension, params, obs, before.validation.verdict, after.validation.verdict))


def _conclusion(extension, params, obs, verdict_before, verdict_after) -> str:
    judged = [p for p in params if p.within_uncertainty is not None]
    moved = [p for p in judged if not p.within_uncertainty]
    narrowed = [p for p in judged if p.within_uncertainty and p.narrowed]
    text = [f"Recalibrated with {extension}:"]
    if narrowed:
        text.append("; ".join(f"{p.name}: its 95 % interval narrowed from [{_fmt(p.before_ci95[0])}, "
                              f"{_fmt(p.before_ci95[1])}] to [{_fmt(p.after_ci95[0])}, {_fmt(p.after_ci95[1])}] "
                              f"({_fmt(p.before)} -> {_fmt(p.after)})" for p in narrowed) + ".")
    if not judged:
        text.append("the workflow gives no interval on the parameters, so their shifts "
                    + ", ".join(f"{p.name} {_fmt(p.before)} -> {_fmt(p.after)}" for p in params)
                    + " cannot be judged against their uncertainty.")
    elif not moved and not narrowed:
        text.append("every calibrated parameter moved by less than its own uncertainty (each new value "
                    "inside the 95 % plausible interval of the campaign under critique), so the extension "
                    "does not change the calibration.")
    elif not moved:
        text.append("every calibrated parameter's new value lies inside its 95 % plausible interval of the "
                    "campaign under critique.")
    else:
        text.append("; ".join(f"{p.name} moved beyond its uncertainty, {_fmt(p.before)} "
                              f"[{_fmt(p.before_ci95[0])}, {_fmt(p.before_ci95[1])}] -> {_fmt(p.after)}"
                              for p in moved)
                    + (f"; the other {len(judged) - len(moved)} moved by less than their own uncertainty."
                       if len(judged) > len(moved) else "."))
    for o in obs:
        if o.fitted or not math.isfinite(o.difference):
            continue
        if o.beyond_noise is None:
            text.append(f"{o.name}: {_fmt(o.before)} -> {with_unit(o.after, o.unit)}, too few runs for an interval.")
            continue
        text.append(f"{o.name} {_fmt(o.before)} -> {with_unit(o.after, o.unit)} (difference {_fmt(o.difference)} "
                    f"[{_fmt(o.ci95[0])}, {_fmt(o.ci95[1])}]): "
                    + ("beyond the run-to-run noise." if o.beyond_noise else "within the run-to-run noise."))
    text.append(f"Validation: {verdict_before} before, {verdict_after} after.")
    return " ".join(text)


def recalibrate(campaign_dir, results: CampaignResult, settings: dict, name: str, *, runner=None,
                workers: int | None = None, progress: bool = False) -> tuple[Path, CampaignResult]:
    """Run the campaign of ``campaign_dir`` again with ``settings`` added to its model
    extensions, in ``campaign_dir/heap_gain/name`` (resumable: finished runs are kept).
    Returns (folder, result)."""
    from demcal.analyse.campaign import CampaignConfig, calibrate
    from demcal.measure.pipeline import Measurement

    config = CampaignConfig.from_dict(results.config)
    changes = {"model_extensions": {**config.model_extensions, **settings}, "progress": progress}
    if workers is not None:
        changes["workers"] = workers
    config = replace(config, **changes)
    out = Path(campaign_dir) / "heap_gain" / name
    measurement = Measurement.from_dict(results.measurement)
    return out, calibrate(measurement.workbook.get("source"), out, config, runner=runner, measurement=measurement)


def heap_gain(campaign_dir, results: CampaignResult, gain, *, folder: str | None = None, runner=None,
              workers: int | None = None, progress: bool = False) -> HeapGain:
    """The heap-side gain of one accepted extension (``gain``: its ``ExtensionGain``, whose
    ``heap_settings`` switch it on in a heap), recalibrated in ``heap_gain/<folder>``
    (default: the extension's name)."""
    out, after = recalibrate(campaign_dir, results, gain.heap_settings, folder or gain.name, runner=runner,
                             workers=workers, progress=progress)
    return compare_campaigns(results, validation_values(campaign_dir, results), after,
                             validation_values(out, after), extension=gain.name, mechanism=gain.mechanism,
                             settings=gain.heap_settings,
                             campaign=str(out.relative_to(Path(campaign_dir))))
