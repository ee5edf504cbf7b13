"""The calibration campaign: from a lab workbook to calibrated DEM parameters, every DEM run
driven by demcal itself. Two workflows share the measurement, the run store and the results file:

``plausible`` (the default with the quick profile; ``analyse.plausible``)
    For a noisy simulator: the noise measured first, replicates sized by it, a surrogate that
    models it, sequential runs where the answer is uncertain, the set of parameters consistent
    with the lab (per parameter a 95 % interval and what the heap identifies), and a
    validation by equivalence that can fail.

``design-expert`` (the default with the paper profile): the source paper's procedure
    1. measure the workbook (``measure.pipeline.measure_workbook``);
    2. Plackett-Burman screening of the seven measured contact parameters (A Poisson's ratio,
       B e p-p, C mu_s p-p, D mu_r p-p, E e p-wall, F mu_s p-wall, G mu_r p-wall), -1/+1 = the
       measured min/max (``levels="minmax"``, as the paper) or mean -+ sd (``levels="sd"``),
       12 runs, the four unused columns as dummies;
    3. seed-to-seed noise of the DEM: the screening centre run repeated with different seeds;
       each effect is compared with it;
    4. steepest climb of the significant factors toward the measured angle, others at their
       measured means; the best level (closest to the target on the monotone fit of the
       climb's responses) becomes the Box-Behnken centre, its neighbours -1/+1 (when the best
       level is an end of the climb the window moves inward: no level leaves the measured
       range);
    5. Box-Behnken (12 edge runs + 5 centre points with different seeds), full quadratic,
       Design-Expert ANOVA, canonical analysis;
    6. optimisation to the measured angle: several solutions, the one closest to the measured
       means preferred;
    7. validation: the preferred solution simulated with three fresh seeds, with
       Design-Expert's confirmation check (the 95 % prediction interval of their mean, the
       model's own variance at the point included) and the equivalence test.

    Replicates: each design point is run ``replicates`` times (default 1 with the paper profile,
    the paper's procedure) and its response is their median. Screening runs share their seeds;
    repeated centre points and validation runs use their own seeds.

In both workflows a heap that neither the photo method nor its fallbacks can read (e.g. nothing
left the container) is poured again with a fresh seed, as the lab pours again a heap it cannot
measure (``plausible.pour_until_read``); the results list those runs (``repoured_runs``).

Every DEM run goes through the run store (``analyse.runs``): a rerun of a killed campaign
redoes nothing that had finished.
"""

from __future__ import annotations

import math
import os
import time
from contextlib import contextmanager
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

from demcal.analyse.designs import box_behnken, plackett_burman, to_actual
from demcal.analyse.equivalence import default_tolerance, equivalence_test
from demcal.analyse.parameters import PARAMETER_BOUNDS, SCREENING_FACTORS, base_parameters, wall_of
from demcal.analyse.optimise import (canonical_analysis, confirmation_interval, optimise_to_target,
                              steepest_climb_analysis, steepest_climb_plan, validate_repeats)
from demcal.analyse.regression import fit_response_surface
from demcal.analyse.results import CampaignResult
from demcal.analyse.runs import RunStore, Workers, run_all, run_key
from demcal.analyse.screening import plackett_burman_screening
from demcal.errors import AnalysisError, InputError
from demcal.jsonio import write_json
from demcal.provenance import Provenance
from demcal.simulate.scenes import compile_kernels
from demcal.simulate.timestep import material_time_step

#: Seed offset between the replicates of one design point.
REPLICATE_SEED_STRIDE = 10_000
#: Default workflow by repose profile.
DEFAULT_WORKFLOW = {"quick": "plausible", "paper": "design-expert"}
WORKFLOWS = ("plausible", "design-expert")

#: The response's name in the paper's analyses (every repose rig's compared observable).
RESPONSE = "angle_deg"


@dataclass(frozen=True)
class CampaignConfig:
    """Settings of a calibration campaign.

    Attributes
    ----------
    profile : str
        Repose-rig profile, ``quick`` or ``paper`` (see ``simulate.rigs.repose``).
    workflow : str or None
        ``plausible`` or ``design-expert`` (module docstring); None: ``DEFAULT_WORKFLOW`` of the
        profile.
    levels : str
        ``minmax``: screening levels -1/+1 = measured min/max of the rows used (the paper);
        ``sd``: mean -+ one standard deviation.
    workers : int
        Local worker processes (default: the machine's cores).
    scheduler : str or None
        Dask scheduler address; runs go to that cluster instead of local processes.
    seed : int
        The campaign's seed: every run seed of every stage derives from it.
    replicates : int or None
        DEM runs per design point. ``plausible``: None chooses it from the measured noise
        (``analyse.noise.replicates_for``), the point's response is their mean.
        ``design-expert``: seeds ``seed + REPLICATE_SEED_STRIDE * r``, the response is their
        median; None: one run.
    noise_repeats : int
        Seeds of the noise measurement (``plausible``: per point of the pair;
        ``design-expert``: extra seeds of the screening centre run).
    initial_points, batch, budget_runs : int
        ``plausible``: points of the space-filling design, points per sequential round, and
        the most runs of design and sequential rounds together.
    refine_rounds, refine_runs : int
        ``plausible``: rounds of runs at the recommended point before the validation, and runs
        per round.
    validation_first, validation_step, validation_cap : int
        ``plausible``: validation runs before the first look, between looks, and at most.
    tolerance : float or None
        Equivalence tolerance of the validation [deg]; None: the larger of 1 deg and the lab's
        heap-to-heap sd.
    discrepancy_sd : float
        sd allowed for what the model cannot represent, added to the target's [deg].
    likelihood : str
        ``plausible``: ``joint`` (the drop and incline twins constrain the restitutions and
        frictions, the heap the rest) or ``heap`` (the heap alone, the lab's direct readings as
        the prior).
    climb_levels : int
        Levels of the steepest climb.
    validation_seeds : tuple of int
        ``design-expert``: seeds of the validation runs.
    alpha : float
        Significance level.
    n_significant : tuple of int
        Least and most factors carried from the screening to the Box-Behnken design; when the
        screening flags fewer or more, the largest effects fill up or are kept (and it is said).
    model_extensions : dict
        Model settings of ``DEMParameters`` set on every run of the campaign (``MODEL_SETTINGS``):
        an engine hook's fields (``simulate.extensions.ENGINE_HOOKS``), e.g.
        ``{"contact_effective_mass": True}``, the model extended (the critique's heap-side gain
        recalibrates this way); the time step ``dt``; the rolling lever; the mass model; the
        segment's sphere count. Empty: the default model.
    extra_targets : tuple of str
        ``plausible``: the rigs' other readings to fit beside the angle (``Rig.targets``, e.g.
        ``crest_height_mm``: every repose rig of the workbook that declares it, from its photos'
        crest heights, which need their ``scale_mm_per_px``). Empty (default): the angles alone.
    """

    profile: str = "quick"
    workflow: str | None = None
    levels: str = "minmax"
    workers: int = field(default_factory=lambda: os.cpu_count() or 1)
    scheduler: str | None = None
    seed: int = 1
    replicates: int | None = None
    noise_repeats: int = 6
    initial_points: int = 18
    batch: int = 4
    budget_runs: int = 56
    refine_rounds: int = 4
    refine_runs: int = 8
    validation_first: int = 10
    validation_step: int = 10
    validation_cap: int = 40
    tolerance: float | None = None
    discrepancy_sd: float = 0.0
    likelihood: str = "joint"
    climb_levels: int = 6
    validation_seeds: tuple = (101, 102, 103)
    alpha: float = 0.05
    n_significant: tuple = (3, 3)
    progress: bool = True
    model_extensions: dict = field(default_factory=dict)
    extra_targets: tuple = ()

    def __post_init__(self):
        if self.levels not in ("minmax", "sd"):
            raise InputError(f"levels must be 'minmax' or 'sd', got {self.levels!r}")
        if self.workflow is None:
            object.__setattr__(self, "workflow", DEFAULT_WORKFLOW.get(self.profile, "plausible"))
        if self.workflow not in WORKFLOWS:
            raise InputError(f"workflow must be one of {', '.join(WORKFLOWS)}, got {self.workflow!r}")
        if self.noise_repeats < (4 if self.workflow == "plausible" else 2):
            raise InputError(f"noise_repeats must be >= {4 if self.workflow == 'plausible' else 2} "
                             f"with the {self.workflow} workflow, got {self.noise_repeats}")
        if self.replicates is None and self.workflow == "design-expert":
            object.__setattr__(self, "replicates", 1)
        if self.replicates is not None and (int(self.replicates) != self.replicates or self.replicates < 1):
            raise InputError(f"replicates must be a positive integer, got {self.replicates!r}")
        if int(self.refine_rounds) != self.refine_rounds or self.refine_rounds < 0:
            raise InputError(f"refine_rounds must be a non-negative integer, got {self.refine_rounds!r}")
        for name in ("initial_points", "batch", "budget_runs", "refine_runs", "validation_first",
                     "validation_step", "validation_cap"):
            value = getattr(self, name)
            if int(value) != value or value < 1:
                raise InputError(f"{name} must be a positive integer, got {value!r}")
        if self.validation_first < 2 or self.validation_cap < self.validation_first:
            raise InputError("validation needs validation_first >= 2 and validation_cap >= validation_first, "
                             f"got {self.validation_first} and {self.validation_cap}")
        if self.tolerance is not None and not self.tolerance > 0:
            raise InputError(f"tolerance must be positive, got {self.tolerance!r}")
        if self.likelihood not in ("joint", "heap"):
            raise InputError(f"likelihood must be 'joint' or 'heap', got {self.likelihood!r}")
        if not self.discrepancy_sd >= 0:
            raise InputError(f"discrepancy_sd must be >= 0, got {self.discrepancy_sd!r}")
        if len(set(self.extra_targets)) != len(self.extra_targets):
            raise InputError(f"extra_targets names a target twice: {', '.join(self.extra_targets)}")
        if self.extra_targets and self.workflow != "plausible":
            raise InputError("extra_targets are fitted by the plausible workflow only")
        unknown = sorted(set(self.model_extensions) - set(model_settings()))
        if unknown:
            raise InputError(f"model_extensions: {', '.join(unknown)} not a model setting; valid: "
                             f"{', '.join(model_settings())}")

    @classmethod
    def from_dict(cls, d: dict) -> "CampaignConfig":
        """Rebuild the settings stored in ``results.json`` (``results["config"]``). Settings
        stored before the plausible workflow existed name no workflow: they were design-expert
        campaigns; settings stored before the refinement rounds existed had none. Model
        extensions stored under a former field name read as the field it became."""
        from demcal.simulate.params import current_names

        names = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - names)
        if unknown:
            raise InputError(f"unknown campaign settings {unknown}; valid: {sorted(names)}")
        d = {"workflow": "design-expert", "refine_rounds": 0, **d}
        if "model_extensions" in d:
            d["model_extensions"] = current_names(d["model_extensions"])
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items()})


def model_settings() -> tuple:
    """The ``DEMParameters`` fields a campaign may set on every run (``--set``): the engine
    hooks' fields, the time step, the rolling lever, the mass model and the segment's sphere
    count. The others are calibrated or measured."""
    from demcal.simulate.extensions import ENGINE_HOOKS

    hooks = sorted(f for fields_ in ENGINE_HOOKS.values() for f in fields_)
    return tuple(hooks) + ("dt", "rolling_lever", "mass_model", "mean_mass_kg", "spheres_per_clump")


def campaign_runner(inputs: dict) -> dict:
    """Run one campaign task on the rig it names (``simulate.rigs.run_task``): the repose
    twin, or the drop and incline twins of the joint calibration. The name a campaign records
    as its runner (top level, so workers can pickle it)."""
    from demcal.simulate.rigs import run_task

    return run_task(inputs)


# ----------------------------------------------------------------------------------------------
# levels from the measurement

def _per_row_values(estimate) -> np.ndarray:
    used = [r["value"] for r in estimate.per_row if r.get("used", True) and r.get("value") is not None]
    return np.asarray(used, dtype=float)


def factor_levels(measurement, levels: str = "minmax") -> dict:
    """Screening levels of the seven contact parameters from the measured quantities.

    Returns ``{letter: {"parameter", "quantity", "low", "high", "mean"}}`` [parameter units].
    """
    wall = wall_of(measurement.meta)
    table = {}
    for letter, parameter, quantity in SCREENING_FACTORS:
        name = quantity.format(wall=wall)
        est = measurement.quantities.get(name)
        if est is None:
            raise InputError(f"the campaign needs the measured quantity {name!r} (factor {letter}, "
                             f"DEM parameter {parameter}); the workbook has no rows for it")
        values = _per_row_values(est)
        if levels == "minmax" and values.size >= 2:
            lo, hi = float(values.min()), float(values.max())
            how = f"min/max of {values.size} rows"
        else:
            if not (est.sd > 0):
                raise InputError(f"{name}: cannot set screening levels, its spread is {est.sd}")
            lo, hi = est.value - est.sd, est.value + est.sd
            how = "mean -+ sd"
        bound = PARAMETER_BOUNDS[parameter]
        lo, hi = max(lo, bound[0]), min(hi, bound[1])
        if not hi > lo:
            raise InputError(f"{name}: measured levels give an empty range [{lo}, {hi}]")
        mean = min(max(float(est.value), lo), hi)
        table[letter] = {"parameter": parameter, "quantity": name, "low": lo, "high": hi,
                         "mean": mean, "how": how}
    return table


def repose_setups(measurement) -> list:
    """The repose rigs of a measurement's workbook with their dimensions
    (``simulate.rigs.ReposeSetup``), the first one's photos the target's; a rig without a twin,
    or a dimension of a rig not named, refused naming its meta key."""
    from demcal.simulate.rigs import repose_setups as setups_of

    return setups_of(measurement.meta, file=measurement.workbook.get("source"))


def repose_setup(measurement):
    """The first repose rig of a measurement's workbook (:func:`repose_setups`)."""
    return repose_setups(measurement)[0]


# ----------------------------------------------------------------------------------------------

@dataclass
class _Runner:
    """Executes batches of runs through the store (``runner`` for those not yet finished) on
    ``workers``, kept open for all of a campaign's stages."""

    config: CampaignConfig
    store: RunStore
    runner: object
    workers: Workers
    log: list = field(default_factory=list)

    @classmethod
    @contextmanager
    def opened(cls, config: CampaignConfig, store_dir, runner):
        """A runner whose workers close when the ``with`` block ends."""
        prepare = compile_kernels if runner is campaign_runner else None
        with Workers(config.workers, config.scheduler, prepare=prepare) as workers:
            yield cls(config, RunStore(store_dir), runner, workers)

    def __call__(self, stage: str, tasks: list[dict]) -> list[dict]:
        out = run_all(tasks, self.runner, self.store, desc=stage, progress=self.config.progress,
                      executor=self.workers)
        failed = [r for r in out.records if r["status"] != "ok"]
        self.log.append({"stage": stage, "runs": len(tasks), "ran": out.ran, "reused": out.reused,
                         "failed": len(failed)})
        if failed:
            raise AnalysisError(f"{stage}: {len(failed)} of {len(tasks)} DEM runs failed twice; "
                                f"first error: {failed[0]['error']} (run record "
                                f"{self.store.path(failed[0]['key'])})")
        return out.records


@dataclass
class _StoredRuns:
    """Serves batches of runs from the store only, for a replay: never runs the DEM and never
    writes; a run that is not in the store as finished is an error naming its key."""

    store: RunStore
    log: list = field(default_factory=list)

    def __call__(self, stage: str, tasks: list[dict]) -> list[dict]:
        records = []
        for task in tasks:
            key = run_key(task)
            rec = self.store.get(key)
            if rec is None or rec.get("status") != "ok":
                state = "is not in the run store" if rec is None else f"has status {rec.get('status')!r}"
                raise AnalysisError(f"{stage}: DEM run {key} {state} ({self.store.path(key)}); "
                                    "its inputs differ from the stored campaign's, or the run "
                                    "never finished")
            records.append(rec)
        self.log.append({"stage": stage, "runs": len(tasks), "ran": 0,
                         "reused": len({r["key"] for r in records}), "failed": 0})
        return records


def _responses(records, fallbacks: list | None = None, unreadable: list | None = None) -> np.ndarray:
    """The response of each run: its rig's compared observable (the photo-method angle), else
    the first finite one of its rig's fallbacks (``{"key", "used"}`` is then appended to
    ``fallbacks``); when none is finite, NaN with the run's index appended to ``unreadable``,
    or an error without that list."""
    from demcal.simulate.rigs import rig

    y = []
    for r in records:
        obs = r["result"]["observable"]
        twin = rig(r["result"].get("rig", "repose"))
        names = (twin.compared,) + twin.fallbacks
        for name in names:
            value = obs.get(name)
            if value is not None and math.isfinite(value):
                break
        else:
            if unreadable is None:
                raise AnalysisError(f"DEM run {r['key']} gave none of {', '.join(names)} "
                                    f"(run record runs/{r['key']}.json)")
            unreadable.append(len(y))
            y.append(math.nan)
            continue
        if name != twin.compared and fallbacks is not None:
            fallbacks.append({"key": r["key"], "used": name})
        y.append(float(value))
    return np.array(y)


def _point_responses(y, replicates: int) -> tuple[np.ndarray, np.ndarray]:
    """Median response of each design point and the (points, replicates) array it comes from;
    ``y`` holds each point's replicates one after the other."""
    y_all = np.asarray(y, dtype=float).reshape(-1, replicates)
    return np.median(y_all, axis=1), y_all


def _run_refs(records) -> list[dict]:
    return [{"key": r["key"], "seed": r["inputs"]["seed"], "wall_s": r["result"].get("wall_s")}
            for r in records]


def calibrate(workbook, out_dir, config: CampaignConfig | None = None, *, runner=None,
              measurement=None) -> CampaignResult:
    """Run the whole calibration campaign and write ``out_dir/results.json``.

    Parameters
    ----------
    workbook : str or Path
        Lab workbook (``.xlsx`` or folder of CSVs).
    out_dir : str or Path
        Output folder: ``results.json``, ``measure.json``, ``runs/`` (one record per DEM run),
        ``annotated/`` (processed heap photos).
    config : CampaignConfig
    runner : callable, optional
        ``runner(inputs) -> dict`` performing one DEM run (default :func:`campaign_runner`);
        tests pass a cheap stand-in. Its qualified name is kept in ``results["runner"]``.
    measurement : measure.pipeline.Measurement, optional
        Use this measurement instead of measuring ``workbook`` again.

    Returns
    -------
    CampaignResult
        What ``results.json`` holds (``to_dict()``).
    """
    from demcal.measure.pipeline import measure_workbook

    config = config or CampaignConfig()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    if measurement is None:
        measurement = measure_workbook(workbook, annotate_dir=out / "annotated")
    write_json(out / "measure.json", measurement.to_dict())
    runner = runner or campaign_runner
    with _Runner.opened(config, out / "runs", runner) as execute:
        results = _derive(measurement, config, execute)
    results = results.with_(
        runner=f"{getattr(runner, '__module__', '?')}.{getattr(runner, '__qualname__', repr(runner))}",
        wall_s=time.perf_counter() - t_start)
    write_json(out / "results.json", results.to_dict())
    return results


def derive_results(measurement, config: CampaignConfig, store_dir) -> CampaignResult:
    """Replay a campaign's analysis from its stored DEM runs, running no DEM.

    Every step of :func:`calibrate` after the measurement is redone with the same code; each
    DEM run it asks for is read from the run store by its key (the SHA-256 of its inputs).
    This is how ``demcal audit`` re-derives a campaign's tables.

    Parameters
    ----------
    measurement : measure.pipeline.Measurement
        The measurement to start from (e.g. the workbook measured again).
    config : CampaignConfig
        The campaign's settings (``CampaignConfig.from_dict(results["config"])``).
    store_dir : str or Path
        The campaign's run store (``DIR/runs``).

    Returns
    -------
    CampaignResult
        What ``results.json`` holds, without ``runner`` and ``wall_s``.

    Raises
    ------
    AnalysisError
        A run the analysis needs is not in the store (its inputs changed, e.g. because a
        measured level did) or did not finish.
    """
    store_dir = Path(store_dir)
    if not store_dir.is_dir():
        raise InputError(f"run store {store_dir} does not exist")
    return _derive(measurement, config, _StoredRuns(RunStore(store_dir)))


def _prepare(measurement, config: CampaignConfig) -> tuple:
    """What a campaign checks and sets up before its first run: the factors with their levels,
    the DEM parameters before calibration and the repose rigs (a time step above the safe limit,
    a rig without its lab angle, and a heap no photo could read, refused)."""
    from demcal.measure.pipeline import repose_quantity

    if "repose_angle_deg" not in measurement.quantities:
        raise InputError("the campaign needs a target angle of repose: the workbook has no "
                         "'repose' photos and no meta 'target_repose_deg'")
    factors = factor_levels(measurement, config.levels)
    base = base_parameters(measurement).with_(**config.model_extensions)
    material_time_step(base)
    setups = repose_setups(measurement)
    for i, s in enumerate(setups[1:], 1):
        quantity = repose_quantity(i, s.workbook_name)
        if quantity not in measurement.quantities:
            raise InputError(f"the campaign needs the angle of every repose rig the workbook names: it has no "
                             f"{quantity} (no photos of the {s.workbook_name} rig were measured)")
    for s in setups:
        s.check_for(base.shape, measurement.workbook.get("source"))
    _check_extra_targets(measurement, config, setups)
    return factors, base, setups


def _check_extra_targets(measurement, config: CampaignConfig, setups) -> None:
    """Refuse, before any run, an extra target no rig of the workbook mirrors, or one a rig
    mirrors but its photos did not measure, naming what is missing."""
    from demcal.measure.pipeline import repose_quantity
    from demcal.simulate.rigs import rig

    for name in config.extra_targets:
        reading = [(i, s) for i, s in enumerate(setups) if name in rig(s.rig).targets]
        if not reading:
            offered = sorted({t for s in setups for t in rig(s.rig).targets})
            raise InputError(f"extra target {name}: no repose rig of the workbook "
                             f"({', '.join(s.workbook_name for s in setups)}) reads it; they offer "
                             f"{', '.join(offered) or 'none'}")
        for i, s in reading:
            quantity = repose_quantity(i, s.workbook_name, name)
            if quantity not in measurement.quantities:
                raise InputError(f"extra target {name}: the workbook has no {quantity}; the {s.workbook_name} rig's "
                                 "photos need their scale (repose sheet column scale_mm_per_px) on every row")


def identify_rigs(measurement, config: CampaignConfig, out_dir, runner=None) -> dict:
    """What each repose rig of the measurement's workbook pins down alone and all together: the
    plausible workflow up to its sequential runs (``analyse.plausible.derive_plausible`` with
    ``identify_only``), its runs kept in ``out_dir/runs`` so that a second call reruns nothing."""
    from demcal.analyse.plausible import derive_plausible

    factors, base, setups = _prepare(measurement, config)
    with _Runner.opened(config, Path(out_dir) / "runs", runner or campaign_runner) as execute:
        found = derive_plausible(measurement, config, execute, factors=factors, base=base, setups=setups,
                                 responses=_responses, run_refs=_run_refs, identify_only=True)
    return {**found, "stages": list(execute.log)}


def _derive(measurement, config: CampaignConfig, execute) -> CampaignResult:
    """The campaign after the measurement; ``execute(stage, tasks) -> records`` supplies the DEM
    runs. The workflow's results plus what every campaign records."""
    from demcal.simulate.rigs import rig

    factors, base, setups = _prepare(measurement, config)
    setup = setups[0]
    setup_rig = rig(setup.rig)
    if config.workflow == "plausible":
        from demcal.analyse.plausible import derive_plausible

        results = derive_plausible(measurement, config, execute, factors=factors, base=base,
                                   setups=setups, responses=_responses, run_refs=_run_refs)
        fallbacks = results.pop("fallback_runs")
        repoured = results.pop("repoured_runs")
    else:
        if len(setups) > 1:
            raise InputError(f"the design-expert workflow fits the angle of one heap; the workbook names "
                             f"{len(setups)} repose rigs ({', '.join(s.workbook_name for s in setups)}): "
                             "calibrate with --workflow plausible, which conditions on every rig")
        results = _derive_design_expert(measurement, config, execute, factors, base, setup)
        fallbacks, repoured = results.pop("fallback_runs"), results.pop("repoured_runs")
    # the sections come as their analyses' dictionaries; from_dict types them here, so that a
    # renamed key fails where the result is made
    return CampaignResult.from_dict(dict(
        workflow=config.workflow,
        response={"name": setup_rig.compared, "fallbacks": list(setup_rig.fallbacks),
                  "fallback_runs": fallbacks,
                  # (only when there are: a campaign without keeps the results it always had)
                  **({"repoured_runs": repoured} if repoured else {}),
                  "note": "; ".join(filter(None, (
                      f"{len(fallbacks)} run(s) left no slope for the photo method (e.g. the heap spread "
                      "flat); their response is the fallback named per run" if fallbacks else "",
                      f"{len(repoured)} heap(s) could be read by no method (e.g. nothing left the "
                      "container) and were poured again with fresh seeds, as the lab pours again a heap "
                      "it cannot measure (repoured_runs)" if repoured else "")))},
        material=measurement.material,
        target_angle_deg=float(measurement.quantities["repose_angle_deg"].value),
        config={k_: (list(v) if isinstance(v, tuple) else v) for k_, v in config.__dict__.items()
                if not (k_ == "extra_targets" and not v)},     # as recorded before there were any
        measurement=measurement.to_dict(),
        factors=factors,
        base_parameters=base.to_dict(),
        geometry=setup.geometry,
        repose_rig=setup.workbook_name,
        **results,
        stages=list(execute.log),
        provenance=Provenance(inputs=dict(measurement.provenance.inputs), seed=config.seed,
                              options={"profile": config.profile, "levels": config.levels,
                                       "workflow": config.workflow}),
    ), "campaign result")


def _derive_design_expert(measurement, config: CampaignConfig, execute, factors, base, setup) -> dict:
    """Steps 2-7 of the source paper's procedure (module docstring)."""
    from demcal.analyse.plausible import SeedStream, pour_until_read

    target = float(measurement.quantities["repose_angle_deg"].value)
    letters = list(factors)
    low = np.array([factors[f]["low"] for f in letters])
    high = np.array([factors[f]["high"] for f in letters])
    means = {f: factors[f]["mean"] for f in letters}
    param_of = {f: factors[f]["parameter"] for f in letters}

    def inputs(settings: dict, seed: int) -> dict:
        return setup.task(base.with_(**settings), seed, profile=config.profile)

    def settings(actual_by_letter: dict) -> dict:
        return {param_of[f]: float(v) for f, v in actual_by_letter.items()}

    fallbacks: list = []  # runs measured by the profile fit because the photo method found no slope
    repoured: list = []   # runs whose heap no method could read, each poured again
    seeds = SeedStream(config.seed)     # the fresh seeds of heaps poured again

    def run_points(stage: str, points: list) -> tuple[np.ndarray, np.ndarray, list]:
        """Run each (settings, seed) design point ``config.replicates`` times; returns the
        points' median responses, every replicate's response and the run records. A heap no
        method can read is poured again with a fresh seed (``plausible.pour_until_read``)."""
        tasks = [inputs(point, seed + REPLICATE_SEED_STRIDE * r)
                 for point, seed in points for r in range(config.replicates)]
        y, records = pour_until_read(
            execute, stage, f"{stage}, poured again", tasks,
            lambda k, s: inputs(points[k // config.replicates][0], s),
            lambda n: seeds.take("pour again", n), _responses, fallbacks, repoured, _run_refs)
        return (*_point_responses(y, config.replicates), records)

    # 2. Plackett-Burman screening --------------------------------------------------------
    pb = plackett_burman(len(letters), runs=12)
    pb_actual = to_actual(pb.coded[:, :len(letters)], low, high)
    y_pb, y_pb_all, pb_records = run_points(
        "Plackett-Burman", [(settings(dict(zip(letters, row))), config.seed) for row in pb_actual])
    dummies = pb.coded[:, len(letters):]
    screening = plackett_burman_screening(pb.coded[:, :len(letters)], y_pb, factors=letters,
                                          dummies=dummies if dummies.size else None,
                                          alpha=config.alpha, response_name=RESPONSE,
                                          low=low, high=high)

    # 3. seed-to-seed noise at the screening centre ----------------------------------------
    centre = {f: (factors[f]["low"] + factors[f]["high"]) / 2 for f in letters}
    noise_seeds = [config.seed + 1000 + i for i in range(config.noise_repeats)]
    y_noise, y_noise_all, noise_records = run_points("noise", [(settings(centre), s) for s in noise_seeds])
    sigma = float(np.std(y_noise, ddof=1))  # of a design point's response (a median)
    sigma_run = float(np.std(y_noise_all, ddof=1))  # of one DEM run
    se_effect = sigma * math.sqrt(4.0 / len(y_pb))  # mean(+) - mean(-), n/2 runs each
    effect_vs_noise = {f: {"effect": screening.effects[f], "se_noise": se_effect,
                           "ratio": abs(screening.effects[f]) / se_effect if se_effect > 0 else math.inf,
                           "exceeds_noise": bool(abs(screening.effects[f]) > 2 * se_effect)}
                       for f in letters}

    # choose the factors carried forward
    flagged = list(screening.significant)
    lo_n, hi_n = config.n_significant
    chosen, chosen_note = list(flagged), []
    if len(chosen) < lo_n:
        extra = [f for f in screening.ranking if f not in chosen][:lo_n - len(chosen)]
        chosen += extra
        chosen_note.append(f"the screening flagged {len(flagged)} factor(s) "
                           f"({', '.join(flagged) or 'none'}) at p < {config.alpha}; the next largest "
                           f"effects ({', '.join(extra)}) fill the response-surface design up to {lo_n}")
    if len(chosen) > hi_n:
        dropped = sorted(chosen, key=lambda f: -abs(screening.effects[f]))[hi_n:]
        chosen = [f for f in chosen if f not in dropped]
        chosen_note.append(f"{len(flagged)} factors were significant; the {hi_n} largest effects are "
                           f"kept, {', '.join(dropped)} stay at their measured means")
    chosen = sorted(chosen, key=letters.index)

    # 4. steepest climb ---------------------------------------------------------------------
    increase = bool(target > float(np.mean(y_pb)))
    plan = steepest_climb_plan({f: factors[f]["low"] for f in letters},
                               {f: factors[f]["high"] for f in letters},
                               screening.effects, chosen, increase=increase,
                               n_levels=config.climb_levels, fixed=means)
    y_climb, y_climb_all, climb_records = run_points(
        "steepest climb", [(settings(dict(zip(letters, row))), config.seed) for row in plan.levels])
    # the climb is planned to move the angle monotonically toward the target: choosing the
    # level on the monotone fit keeps one noisy level from moving the window
    climb = steepest_climb_analysis(plan, y_climb, target, extrapolate=False, monotone=increase)

    # 5. Box-Behnken --------------------------------------------------------------------------
    k = len(chosen)
    bbd = box_behnken(k, centre_points=5)
    b_low = np.array([climb.low[f] for f in chosen])
    b_high = np.array([climb.high[f] for f in chosen])
    for j, f in enumerate(chosen):
        lo_b, hi_b = PARAMETER_BOUNDS[param_of[f]]
        b_low[j], b_high[j] = max(b_low[j], lo_b), min(b_high[j], hi_b)
    bbd_actual = to_actual(bbd.coded, b_low, b_high)
    fixed = {f: means[f] for f in letters if f not in chosen}
    centre_count = 0
    bbd_points = []
    for coded_row, row in zip(bbd.coded, bbd_actual):
        is_centre = not np.any(coded_row)
        seed = config.seed + centre_count if is_centre else config.seed
        centre_count += is_centre
        bbd_points.append((settings({**fixed, **dict(zip(chosen, row))}), seed))
    y_bbd, y_bbd_all, bbd_records = run_points("Box-Behnken", bbd_points)
    fit = fit_response_surface(bbd.coded, y_bbd, "quadratic", factors=chosen,
                               response_name=RESPONSE, low=b_low, high=b_high)
    canonical = canonical_analysis(fit)
    centre_sd = float(np.std(y_bbd[~np.any(bbd.coded, axis=1)], ddof=1))
    term_vs_noise = terms_against_noise(fit, centre_sd)

    # 6. optimisation to the measured angle ---------------------------------------------------
    reference = np.array([means[f] for f in chosen])
    optimum = optimise_to_target(fit, target, reference_actual=reference, seed=config.seed)
    best = optimum.preferred
    best_actual = {f: float(v) for f, v in best["actual"].items()}

    # 7. validation ------------------------------------------------------------------------------
    val_settings = settings({**fixed, **best_actual})
    y_val, y_val_all, val_records = run_points("validation",
                                               [(val_settings, s) for s in config.validation_seeds])
    # the interval uses the noise of a design point's response pooled over the screening centre
    # and the Box-Behnken centre points (more degrees of freedom than the three repeats)
    centre_y = y_bbd[~np.any(bbd.coded, axis=1)]
    df_pool = (y_noise.size - 1) + (centre_y.size - 1)
    sd_pool = math.sqrt(((y_noise.size - 1) * sigma ** 2 + (centre_y.size - 1) * centre_sd ** 2) / df_pool)
    validation = validate_repeats(y_val, target, noise_sd=sd_pool, noise_df=df_pool)
    confirmation = confirmation_interval(fit, list(best["coded"].values()), y_val.size)
    confirmation["target_inside"] = bool(confirmation["pi95"][0] <= target <= confirmation["pi95"][1])
    est = measurement.quantities["repose_angle_deg"]
    lab_sd = float(est.sd) if est.n >= 2 and math.isfinite(est.sd) else None
    tolerance = float(config.tolerance) if config.tolerance else default_tolerance(lab_sd)
    equivalence = equivalence_test(y_val_all.ravel(), target, lab_sd, est.n if lab_sd else None,
                                   tolerance, alpha=config.alpha).to_dict() if y_val_all.size >= 2 else None

    calibrated = base.with_(**{param_of[f]: means[f] for f in letters}).with_(**val_settings)
    results = {
        "fallback_runs": fallbacks,
        "repoured_runs": repoured,
        "plackett_burman": {
            "design_coded": pb.coded.tolist(), "columns": list(pb.columns),
            "design_actual": pb_actual.tolist(), "response": y_pb.tolist(),
            "replicate_responses": y_pb_all.tolist(),
            "runs": _run_refs(pb_records), "screening": screening.to_dict(),
            "effects_vs_noise": effect_vs_noise},
        "noise": {"settings": centre, "seeds": noise_seeds, "responses": y_noise.tolist(),
                  "replicate_responses": y_noise_all.tolist(), "sd": sigma, "sd_single_run": sigma_run,
                  "replicates": config.replicates, "runs": _run_refs(noise_records),
                  "bbd_centre_sd": centre_sd},
        "significant": {"flagged": flagged, "carried_forward": chosen, "note": "; ".join(chosen_note)},
        "steepest_climb": {"plan": plan.to_dict(), "response": y_climb.tolist(),
                           "replicate_responses": y_climb_all.tolist(),
                           "runs": _run_refs(climb_records), "result": climb.to_dict(),
                           "increase": increase},
        "box_behnken": {"factors": chosen, "low": b_low.tolist(), "high": b_high.tolist(),
                        "centre": [climb.centre[f] for f in chosen], "fixed": fixed,
                        "design_coded": bbd.coded.tolist(), "design_actual": bbd_actual.tolist(),
                        "response": y_bbd.tolist(), "replicate_responses": y_bbd_all.tolist(),
                        "runs": _run_refs(bbd_records),
                        "fit": fit.to_dict(), "canonical": canonical.to_dict(),
                        "terms_vs_noise": term_vs_noise},
        "optimisation": optimum.to_dict(),
        "validation": {"settings": val_settings, "seeds": list(config.validation_seeds),
                       "responses": y_val.tolist(), "replicate_responses": y_val_all.tolist(),
                       "noise_sd": sd_pool, "noise_df": df_pool, "runs": _run_refs(val_records),
                       "result": validation.to_dict(), "confirmation": confirmation,
                       "test": equivalence,
                       "verdict": equivalence["verdict"] if equivalence else "undecided",
                       "mean_deg": float(np.mean(y_val_all)), "ci95": list(validation.ci95),
                       "tolerance_deg": tolerance, "target_deg": target, "n_runs": int(y_val_all.size),
                       "detectable_bias_deg": equivalence["detectable_bias_deg"] if equivalence else math.nan},
        "calibrated_parameters": calibrated.to_dict(),
    }
    return results


def terms_against_noise(fit, sigma: float) -> dict:
    """Each coded coefficient against the seed-to-seed noise: its standard error if the only
    error were a DEM noise of sd ``sigma`` (sigma^2 (X'X)^-1), and whether it exceeds twice that."""
    from demcal.analyse.regression import term_columns

    x = term_columns(np.asarray(fit.coded, dtype=float), ((),) + tuple(fit.term_powers))
    cov = np.linalg.pinv(x.T @ x)
    out = {}
    for i, name in enumerate(("Intercept",) + tuple(fit.terms)):
        se = sigma * math.sqrt(max(cov[i, i], 0.0))
        coef = float(fit.coefficients[name])
        out[name] = {"coefficient": coef, "se_noise": se, "exceeds_noise": bool(abs(coef) > 2 * se)}
    return out
