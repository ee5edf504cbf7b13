"""The critique loop end to end: twins, discrepancies, residual structure, mechanisms, extensions.

:func:`run_critique` takes a lab workbook or a calibration campaign folder and returns a
:class:`Critique`, whose :meth:`Critique.to_dict` is ``critique.json``::

    {"discrepancies": [{"observable", "measured", "measured_ci95", "simulated", "simulated_ci95",
                        "difference", "combined_u95", "exceeds", ...}],
     "findings": [{"mechanism", "verdict", "sheet", "covariate", "effect", "ci95",
                   "p_adjusted", "quantity", "source", "effect_unit", "evidence", "reason",
                   "rows_to_decide"}],
     "model_findings": [{"mechanism", "verdict", "observable", "measured", "simulated",
                         "share", "part", "part_ci95", "evidence"}],
     "extensions": [{"name", "mechanism", "before", "after", "gain", "ci95", "measure",
                     "held_out", ...}],
     "heap_gains": [{"extension", "mechanism", "settings", "campaign", "verdict_before",
                     "verdict_after", "parameters": [...], "observables": [...], "conclusion"}],
     "summary": [str], "extension_records": [...], "tests": [...], "untestable": [...],
     "catalogue": [...], "parameters": {...}, "twin_runs": [...], "provenance": {...},
     "schema_version": 1}

``extensions`` holds flat rows for the report's table; ``extension_records`` the same with the
provenance record of each extension (``simulate.extensions.describe``).

Steps (docs/design.md, "The critique loop"):

1. the workbook measured (or the campaign's ``measure.json``), and the parameters of the
   model under critique (the campaign's calibrated parameters, else the measured means);
2. the twin of every drop and incline trial, the campaign's repose validation runs, and the
   discrepancy table;
3. data effects: every measured per-row value tested against every covariate, each tier of
   tests adjusted on its own (``diagnosis``), and the catalogue's verdicts on them (``mechanisms``),
   ``ill_conditioned_parameter`` from the campaign;
4. model findings: each drop discrepancy split into its causes, each tested, and the twin's
   orientation dependence against the lab's (``attribution``);
5. for each found mechanism that a model extension answers, its gain on held-out trials
   (``gain``);
6. with ``heap_gain`` (a campaign folder), for each extension of a found mechanism that a heap
   can switch on and that does not make its held-out trials worse: the campaign again with it, and what that changes in the
   calibrated parameters and in the heap observables the calibration does not fit
   (``heap_gain``).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import stats

from demcal.analyse.critique.diagnosis import (CORRECTIONS, DEFAULT_ALPHA, POOLED, PRACTICAL_THRESHOLDS,
                                        CovariateTest, Untestable, measured_series, row_covariates, run_tests,
                                        specimen_lookup)
from demcal.analyse.critique.attribution import ModelFinding, attribute_drop_discrepancy, orientation_discrepancy
from demcal.analyse.critique.gain import ExtensionGain
from demcal.analyse.critique.heap_gain import HeapGain, with_unit
from demcal.analyse.critique.mechanisms import CATALOGUE, Finding, ill_conditioned, judge
from demcal.analyse.critique.twins import (Discrepancy, TwinRunner, TwinTrial, constant_discrepancy,
                                    independent_discrepancy, paired_discrepancy, repose_validation_angles,
                                    twin_parameters)
from demcal.analyse.parameters import wall_of
from demcal.analyse.results import read_campaign_results
from demcal.errors import InputError
from demcal.jsonio import check_schema, read_json, to_jsonable
from demcal.provenance import Provenance, sha256_file

#: The sheets whose trials the critique compares with their twins.
RIGS = ("drop", "incline", "repose")
#: Extensions evaluated by default (the others need engine hooks or a new campaign).
DEFAULT_EXTENSIONS = ("inverted_restitution", "velocity_dependent_restitution", "size_distribution")


#: Version of the layout of ``critique.json`` (files without one have the layout of version 1).
CRITIQUE_SCHEMA_VERSION = 1


@dataclass(frozen=True)
class Critique:
    """Everything the critique found.

    Attributes
    ----------
    discrepancies : list of Discrepancy
        Model discrepancies: where a twin disagrees with the lab.
    findings : list of Finding
        Data effects: covariate effects in the lab's measurements.
    model_findings : list of ModelFinding
        The tested causes of the discrepancies, each with its share.
    extensions : list of ExtensionGain
    heap_gains : list of HeapGain
        What each accepted extension changes on the heap, after recalibrating with it.
    tests : list of CovariateTest
        Every test of the residual structure (adjusted).
    untestable : list of Untestable
    conclusions : list of str
        The conclusions in sentences, with numbers (``critique.json``'s ``summary``).
    parameters : dict
        ``{"values": DEMParameters as dict, "source": str}``.
    twin_runs : list of dict
        Per stage: runs asked, run, reused from the store.
    provenance : Provenance
    """

    discrepancies: list
    findings: list
    extensions: list
    tests: list
    untestable: list
    conclusions: list
    parameters: dict
    twin_runs: list = field(default_factory=list)
    provenance: Provenance = field(default_factory=Provenance)
    model_findings: list = field(default_factory=list)
    heap_gains: list = field(default_factory=list)

    def found(self) -> list:
        """The findings with verdict ``found``."""
        return [f for f in self.findings if f.verdict == "found"]

    def summary(self) -> str:
        """The headline: what differs from the lab beyond its uncertainty, the mechanisms found,
        each extension's gain, then the conclusions."""
        lines = [f"critique of the model with {self.parameters.get('source', 'its')} parameters"]
        off = [d for d in self.discrepancies if d.exceeds]
        lines.append(f"  discrepancies beyond their 95 % interval: {len(off)} of {len(self.discrepancies)}")
        for d in off:
            lines.append(f"    {d.observable}: measured {_fmt(d.measured)}, simulated {_fmt(d.simulated)} "
                         f"(difference {_fmt(d.difference)} +- {_fmt(d.combined_u95)})")
        found = self.found()
        lines.append(f"  data effects found: {len(found)} ("
                     + (", ".join(sorted({f.mechanism for f in found})) or "none") + ")")
        open_ = [f for f in self.findings if f.verdict == "inconclusive"]
        if open_:
            lines.append("  inconclusive: " + ", ".join(
                f"{f.mechanism}" + (f" ({f.rows_to_decide} rows would decide it)" if f.rows_to_decide else "")
                for f in open_))
        for m in self.model_findings:
            if m.verdict == "found":
                lines.append(f"  model: {m.mechanism} explains {_fmt(m.part)} [{_fmt(m.part_ci95[0])}, "
                             f"{_fmt(m.part_ci95[1])}] of {m.observable} (share {_fmt(m.share)})")
        for e in self.extensions:
            lines.append(f"  extension {e.name}: {e.measure} of {e.quantity} {_fmt(e.before)} -> {_fmt(e.after)}, "
                         f"gain {_fmt(e.gain)} [{_fmt(e.ci95[0])}, {_fmt(e.ci95[1])}]")
        for h in self.heap_gains:
            lines.append(f"  heap-side gain of {h.extension} ({h.campaign}):")
            for p in h.parameters:
                lines.append(f"    {p.name:14s} {_fmt(p.before, 4)} -> {_fmt(p.after, 4)}"
                             + ("" if p.within_uncertainty is None else f"  ({p.verdict})"))
            for o in h.observables:
                lines.append(f"    {o.name:26s} {_fmt(o.before)} -> {with_unit(o.after, o.unit)}, difference "
                             f"{_fmt(o.difference)} [{_fmt(o.ci95[0])}, {_fmt(o.ci95[1])}]"
                             + ("  (fitted)" if o.fitted else ""))
        return "\n".join(lines + list(self.conclusions))

    def to_dict(self) -> dict:
        return {"schema_version": CRITIQUE_SCHEMA_VERSION,
                "discrepancies": [d.to_dict() for d in self.discrepancies],
                "findings": [f.to_dict() for f in self.findings],
                "model_findings": [m.to_dict() for m in self.model_findings],
                "extensions": [e.to_dict() for e in self.extensions],
                "heap_gains": [h.to_dict() for h in self.heap_gains],
                "summary": list(self.conclusions),
                "extension_records": [e.as_dict() for e in self.extensions],
                "tests": [t.to_dict() for t in self.tests],
                "untestable": [u.to_dict() for u in self.untestable],
                "catalogue": [m.to_dict() for m in CATALOGUE],
                "parameters": dict(self.parameters), "twin_runs": list(self.twin_runs),
                "provenance": self.provenance.to_dict()}

    @classmethod
    def from_dict(cls, d: dict, where: str = "critique.json") -> "Critique":
        """Read ``critique.json`` back (``extensions`` and ``catalogue`` are derived: the
        extensions come from ``extension_records``)."""
        check_schema(d, CRITIQUE_SCHEMA_VERSION, where)
        try:
            return cls(discrepancies=[Discrepancy.from_dict(x) for x in d["discrepancies"]],
                       findings=[Finding.from_dict(x) for x in d["findings"]],
                       model_findings=[ModelFinding.from_dict(x) for x in d.get("model_findings", [])],
                       extensions=[ExtensionGain.from_dict(x) for x in d.get("extension_records", [])],
                       heap_gains=[HeapGain.from_dict(x, f"{where}: heap_gains[{i}]")
                                   for i, x in enumerate(d.get("heap_gains", []))],
                       tests=[CovariateTest.from_dict(x) for x in d.get("tests", [])],
                       untestable=[Untestable.from_dict(x) for x in d.get("untestable", [])],
                       conclusions=list(d.get("summary", [])), parameters=dict(d.get("parameters", {})),
                       twin_runs=list(d.get("twin_runs", [])),
                       provenance=Provenance(**d["provenance"]) if d.get("provenance") else Provenance())
        except (KeyError, TypeError) as exc:
            raise InputError(f"{where}: not a critique of this layout ({type(exc).__name__}: {exc})") from None


def load_critique(out_dir) -> tuple[Critique | None, dict]:
    """The critique of a campaign folder (``critique.json``, typed) and ``{"file", "sha256"}``."""
    p = Path(out_dir) / "critique.json"
    if not p.exists():
        return None, {}
    try:
        doc = read_json(p)
    except json.JSONDecodeError as exc:
        raise InputError(f"{p} is not valid JSON ({exc})") from None
    # named relative to the campaign folder, so that a moved or copied folder still audits
    return Critique.from_dict(doc, str(p)), {"file": "critique.json", "sha256": sha256_file(p)}


def load_source(source, reading=None):
    """(measurement, workbook or None, results or None, campaign folder or None) of a workbook
    path (read with ``reading``, a ``measure.workbook.ReadOptions``) or a campaign folder (one
    holding ``results.json``; its workbook is read again as the campaign read it)."""
    from demcal.measure.pipeline import Measurement, measure_workbook
    from demcal.measure.workbook import read_workbook

    path = Path(source)
    if path.is_dir() and (path / "results.json").is_file():
        results = read_campaign_results(path)
        if (path / "measure.json").is_file():
            measurement = Measurement.from_dict(read_json(path / "measure.json"))
        elif results.measurement:
            measurement = Measurement.from_dict(results.measurement)
        else:
            raise InputError(f"campaign {path}: neither measure.json nor a measurement in results.json")
        wb_path = measurement.workbook.get("source")
        workbook = (read_workbook(wb_path, measurement.read_options)
                    if wb_path and Path(wb_path).exists() else None)
        return measurement, workbook, results, path
    if not path.exists():
        raise InputError(f"workbook or campaign folder not found: {path}")
    workbook = read_workbook(path, reading)
    return measure_workbook(workbook), workbook, None, None


def _fmt(x, d=3):
    return "n/a" if x is None or not np.isfinite(x) else f"{x:.{d}g}"


def run_critique(source, *, twins: bool = True, rigs=RIGS, extensions=DEFAULT_EXTENSIONS,
                 alpha: float = DEFAULT_ALPHA, correction: str = "bh", store_dir=None, workers: int = 1,
                 progress: bool = False, repose_seeds: int = 0, seed: int = 0, heap_gain: bool = False,
                 campaign_runner=None, reading=None) -> Critique:
    """Critique the model calibrated from a workbook (see the module docstring).

    Parameters
    ----------
    source : str or Path
        Lab workbook (``.xlsx``, CSV folder) or calibration campaign folder (``results.json``).
    twins : bool
        Run the twins (False: only the measured data's residual structure).
    rigs : sequence of str
        Twins to run, among ``drop``, ``incline``, ``repose``.
    extensions : sequence of str
        Extensions to evaluate for found mechanisms (``DEFAULT_EXTENSIONS``); empty for none.
    alpha : float
        Significance level after the correction (``diagnosis.DEFAULT_ALPHA``).
    correction : {"bh", "holm"}
    store_dir : path, optional
        Run store of the twins; default ``DIR/critique_runs`` for a campaign, else temporary.
    workers : int
        Worker processes for the twin runs.
    progress : bool
        Progress bars.
    repose_seeds : int
        Repose twins to run when no campaign gives validation runs (0: none).
    seed : int
        Seed of the bootstrap intervals.
    heap_gain : bool
        Recalibrate the campaign with each accepted extension and compare (``heap_gain``);
        needs a campaign folder. Each is a campaign of its own, with the campaign's own
        settings (its worker count too), kept and resumable in ``DIR/heap_gain/<extension>``.
    campaign_runner : callable, optional
        The recalibrations' DEM runner (default ``analyse.campaign.campaign_runner``).
    reading : measure.workbook.ReadOptions, optional
        How to read a workbook ``source`` (a campaign's workbook is read as it was).

    Returns
    -------
    Critique
    """
    if correction not in CORRECTIONS:
        raise InputError(f"correction must be one of {', '.join(CORRECTIONS)}, got {correction!r}")
    unknown = sorted(set(rigs) - set(RIGS))
    if unknown:
        raise InputError(f"unknown rig(s) {unknown}; valid: {', '.join(RIGS)}")
    measurement, workbook, results, campaign = load_source(source, reading)
    if heap_gain and campaign is None:
        raise InputError(f"{source}: the heap-side gain recalibrates a campaign; give a campaign folder "
                         "(one holding results.json), not a workbook")
    params, param_source = twin_parameters(measurement, results)
    wall = wall_of(measurement.meta)
    series = measured_series(measurement, workbook)
    discrepancies, summary = [], []
    drop_state: dict = {}
    runner = None
    if twins:
        if store_dir is None and campaign is not None:
            store_dir = campaign / "critique_runs"
        runner = TwinRunner(store_dir, workers=workers, progress=progress)
    try:
        if twins:
            _trial_twins(runner, measurement, workbook, params, wall, rigs, discrepancies, drop_state)
        if twins and "repose" in rigs:
            _repose_twins(runner, measurement, results, campaign, params, repose_seeds, discrepancies)
        # data effects: the lab's measurements against their covariates
        tests, untestable = run_tests(series, method=correction, alpha=alpha)
        findings = judge(tests, untestable) + ill_conditioned(results)
        # model findings: the causes of the twins' discrepancies, each tested
        rng = np.random.default_rng(seed)
        model_findings, gains = [], []
        for pair, s in drop_state.items():
            mf, g = attribute_drop_discrepancy(runner, params, pair, s, rng)
            model_findings += mf
            gains += g
        if twins and extensions:
            gains += _extensions(runner, params, findings, model_findings, drop_state, tuple(extensions), seed,
                                 summary)
        heap_gains = _heap_gains(campaign, results, gains, findings + model_findings, heap_gain, summary,
                                 runner=campaign_runner, progress=progress)
        summary[:0] = _drop_statements(drop_state, params)
        summary += _finding_statements(findings)
        runs = list(runner.log) if runner is not None else []
    finally:
        if runner is not None:
            runner.close()
    opts = {"twins": twins, "rigs": list(rigs), "extensions": list(extensions), "alpha": alpha,
            "correction": correction, "repose_seeds": repose_seeds, "source": str(source)}
    opts["heap_gain"] = heap_gain
    return Critique(discrepancies=discrepancies, findings=findings, model_findings=model_findings,
                    extensions=gains, heap_gains=heap_gains, tests=tests,
                    untestable=untestable, conclusions=summary,
                    parameters={"values": params.to_dict(), "source": param_source}, twin_runs=runs,
                    provenance=Provenance(inputs=dict(measurement.provenance.inputs), seed=seed, options=opts))


# ----------------------------------------------------------------------------------------------
# twins


def _trial_twins(runner, measurement, workbook, params, wall, sheets, discrepancies, state) -> None:
    """The twin of every group of the lab's trials (``simulate.rigs.trial_groups``), on the rigs
    whose sheets ``sheets`` names: a per-trial twin against its trials in pairs, a deterministic
    one against the group's mean. A restitution's twins are kept in ``state`` (by lab pair) for
    the attribution of their discrepancy and the model extensions."""
    from demcal.simulate.rigs import rig, run_task, trial_groups

    specimens = specimen_lookup(workbook)
    runs = {}
    for group in trial_groups(measurement.quantities, wall):
        twin = rig(group.rig)
        if twin.sheet not in sheets:
            continue
        if group.setting is None or (twin.per_trial and len(group.trials) < 2):
            why = group.why or "fewer than 2 trials"
            discrepancies.append(constant_discrepancy(twin.label(group.quantity), twin.sheet, group.measured,
                                                      None, f"not simulated: {why}"))
            continue
        runs.setdefault(twin.name, []).append((group, twin.group_tasks(params, group)))
    for name, planned in runs.items():
        twin = rig(name)
        results = iter(runner(run_task, [t for _, tasks in planned for t in tasks], f"{name} twins"))
        for group, tasks in planned:
            done = [next(results) for _ in tasks]
            readings = [twin.reading(t, r) for t, r in zip(tasks, done)]
            note = twin.describe_twin(group, params, done) if twin.describe_twin else ""
            if not twin.per_trial:
                value = readings[0] if math.isfinite(readings[0]) else None
                discrepancies.append(constant_discrepancy(twin.label(group.quantity), twin.sheet, group.measured,
                                                          value, note))
                continue
            trials = [TwinTrial(twin.sheet, group.quantity, t.row, t.measured, y,
                                row_covariates(t.record, twin.sheet, specimens), task)
                      for t, y, task in zip(group.trials, readings, tasks)]
            extra = []
            if group.quantity.partition(".")[0] == "restitution":
                note, extra = _restitution_twins(group, trials, params, specimens, note, state)
            discrepancies.append(paired_discrepancy(twin.label(group.quantity), twin.sheet,
                                                    [t.measured for t in trials], [t.simulated for t in trials],
                                                    note))
            discrepancies += extra


def _restitution_twins(group, twins, params, specimens, note, state) -> tuple[str, list]:
    """What the critique adds to a restitution's drop twins: whether sqrt(h2/h1) may feed the
    DEM directly (to the ``note``), the twin's own slope against orientation (a model
    discrepancy, never a data effect), and the pair's record in ``state`` for the attribution
    and the extensions. Returns the note and the extra discrepancies."""
    from demcal.simulate.extensions import restitution_parameter

    rig_pair = group.setting["pair"]
    param = restitution_parameter(rig_pair)
    e_contact = float(getattr(params, param))
    note = f"contact {param} = {e_contact:.3g}; {note}" if note else f"contact {param} = {e_contact:.3g}"
    direct = _direct_use(twins, e_contact)
    if direct is not None:
        note += (f"; twin apparent / contact = {direct['ratio']:.3g}: " +
                 ("whether sqrt(h2/h1) may feed the DEM directly is undetermined with these drops"
                  if direct["verdict"] == "undetermined" else
                  f"sqrt(h2/h1) {direct['verdict']} feed the DEM directly"))
    slope = orientation_discrepancy(group.quantity, twins)
    trials = [(t.row, t.measured, t.settings["height"], t.settings["orientation_deg"],
               row_covariates(t.record, "drop", specimens), t.record) for t in group.trials]
    state[group.quantity.partition(".")[2]] = {"rig_pair": rig_pair, "trials": trials,
                                               "twins": {t.row: t for t in twins},
                                               "parameter": param, "contact": e_contact}
    return note, [] if slope is None else [slope]


def _repose_twins(runner, measurement, results, campaign, params, repose_seeds, discrepancies):
    """Each repose rig's photographed angles beside its twin's: the campaign's validation runs in
    that rig, else ``repose_seeds`` quick runs at ``params``."""
    from demcal.measure.pipeline import repose_quantity
    from demcal.simulate.rigs import repose_setups, rig, run_task

    if measurement.quantities.get("repose_angle_deg") is None:
        return
    setups = repose_setups(measurement.meta, file=measurement.workbook.get("source"))
    validations = [None] + [o.validation for o in (results.other_rigs or ())] if results is not None else []
    for i, setup in enumerate(setups):
        quantity = repose_quantity(i, setup.workbook_name)
        est = measurement.quantities.get(quantity)
        if est is None:                           # the rig's photos were not measured
            continue
        label = f"{quantity} (photo method)" if i == 0 else f"{quantity} ({setup.workbook_name} photos)"
        photo = est.extra.get("photo_estimate") if est.extra.get("override") else None
        measured = [r["value"] for r in est.per_row if r.get("used", True)] if est.per_row else [est.value]
        if results is not None and i < len(validations):
            angles, note = repose_validation_angles(campaign, results, validations[i])
        elif repose_seeds > 0:
            tasks = [setup.task(params, 9000 + j, profile="quick") for j in range(repose_seeds)]
            twin = rig(setup.rig)
            name = "repose" if i == 0 else setup.workbook_name
            angles = [twin.reading(t, r) for t, r in zip(tasks, runner(run_task, tasks, f"{name} twins"))]
            note = f"{repose_seeds} quick-profile {name} runs"
        else:
            discrepancies.append(independent_discrepancy(label, "repose", measured, [],
                                                         "not simulated: give the campaign folder (its validation "
                                                         "runs) or repose_seeds"))
            continue
        if photo is not None:
            note += "; measured: the photos (the meta target_repose_deg overrides them in the campaign)"
        discrepancies.append(independent_discrepancy(label, "repose", measured, angles, note))


# ----------------------------------------------------------------------------------------------
# extensions and statements


def _pairs_named(findings, mechanism: str, state: dict) -> list:
    """Drop pairs of ``state`` with a ``found`` finding of ``mechanism`` (data effects name the
    quantity, model findings the observable ``restitution.<pair> (...)``)."""
    pairs = []
    for f in findings:
        where = getattr(f, "quantity", None) or getattr(f, "observable", "")
        if f.mechanism == mechanism and f.verdict == "found" and where == f"{POOLED}restitution":
            pairs += [p for p in state if p not in pairs]       # an effect every drop pair shares
        elif f.mechanism == mechanism and f.verdict == "found" and where.startswith("restitution."):
            pair = where.split(" ", 1)[0].split(".", 1)[-1]
            if pair in state and pair not in pairs:
                pairs.append(pair)
    return pairs


def _extensions(runner, params, findings, model_findings, state, chosen, seed, summary) -> list:
    from demcal.analyse.critique.gain import combined_inversion, inverted_restitution_gain, size_gain, velocity_gain

    gains = []
    rng = np.random.default_rng(seed)
    scale = {}
    if "inverted_restitution" in chosen:
        # the contact restitution that absorbs the rotation the twin (with the damping artefact
        # corrected where it was found) puts into a rebound
        for pair in _pairs_named(model_findings, "orientation_rotation", state):
            s = state[pair]
            damped = pair in _pairs_named(model_findings, "contact_effective_mass", state)
            model = params.with_(contact_effective_mass=True) if damped else params
            twins_now = s["twins_on"] if damped else s["twins"]
            try:
                g, inv = inverted_restitution_gain(runner, model, pair, s["rig_pair"], s["trials"], twins_now,
                                                   rng=rng)
            except InputError as exc:
                summary.append(f"inverted_restitution ({pair}) not evaluated: {exc}")
                continue
            gains.append(g)
            s["inverted"] = combined_inversion(inv)
            s["inversion_notes"] = [i.note for i in inv if not i.converged]
            if s["inverted"] is not None and s["inverted"]["target"] > 0:
                scale[pair] = s["inverted"]["contact"] / s["inverted"]["target"]
    if "velocity_dependent_restitution" in chosen:
        for pair in _pairs_named(findings, "velocity_dependent_restitution", state):
            s = state[pair]
            try:
                gains.append(velocity_gain(runner, params, pair, s["rig_pair"], s["trials"], rng=rng,
                                           contact_scale=scale.get(pair, 1.0)))
            except InputError as exc:
                summary.append(f"velocity_dependent_restitution ({pair}) not evaluated: {exc}")
    if "size_distribution" in chosen:
        for pair in _pairs_named(findings, "size_dependence", state):
            s = state[pair]
            try:
                gains.append(size_gain(runner, params, pair, s["rig_pair"], s["trials"], s["twins"], rng=rng))
            except InputError as exc:
                summary.append(f"size_distribution ({pair}) not evaluated: {exc}")
    for g in gains:
        if g.name == "contact_effective_mass":
            continue  # stated with the attribution
        verdict = ("helps" if g.ci95[0] > 0 else "makes it worse" if g.ci95[1] < 0 else "has no clear gain")
        summary.append(f"Extension {g.name} ({g.quantity}): {g.measure} on {g.held_out} {_fmt(g.before)} "
                       f"before, {_fmt(g.after)} after, gain {_fmt(g.gain)} [{_fmt(g.ci95[0])}, {_fmt(g.ci95[1])}]: "
                       f"it {verdict}. Fitted: {g.fitted}.")
    return gains


def _heap_gains(campaign, results, gains, found, run: bool, summary, **kw) -> list:
    """The heap-side gain of every extension accepted for a found mechanism: a switch a heap can
    take that does not make the held-out trials worse (its gain's interval is not below 0; a
    calibration that absorbed an artefact into a parameter fits them as well as the mended
    model, so no gain is required). Without ``run`` (or without a campaign) the
    summary says which would be measured and how."""
    from demcal.analyse.critique.heap_gain import heap_gain

    found_mechanisms = {f.mechanism for f in found if f.verdict == "found"}
    out, done = [], {}
    for g in gains:
        if g.mechanism not in found_mechanisms:
            continue
        if not g.heap_settings:
            summary.append(f"Heap-side gain of {g.name} ({g.quantity}): none to measure, it sets a "
                           "parameter value rather than switching the model.")
            continue
        settings = json.dumps(to_jsonable(g.heap_settings), sort_keys=True)
        if (g.name, settings) in done:  # the same switch accepted on another pair
            continue
        # one folder per extension, and per pair when pairs switch it differently
        folder = g.name if g.name not in {n for n, _ in done} else f"{g.name}-{g.quantity.rsplit('.', 1)[-1]}"
        done[(g.name, settings)] = folder
        if not (math.isfinite(g.ci95[1]) and g.ci95[1] >= 0):
            summary.append(f"Heap-side gain of {g.name} ({g.quantity}): not measured, the extension is not "
                           f"accepted: it makes the held-out trials worse (gain {_fmt(g.gain)} "
                           f"[{_fmt(g.ci95[0])}, {_fmt(g.ci95[1])}]).")
        elif not run or campaign is None:
            summary.append(f"Heap-side gain of {g.name} ({g.quantity}): not measured; "
                           + ("`demcal critique DIR --heap-gain` recalibrates the campaign with it and "
                              "compares the heaps." if campaign is not None else
                              "it needs a calibration campaign to recalibrate."))
        else:
            h = heap_gain(campaign, results, g, folder=folder, **kw)
            out.append(h)
            summary.append(f"Heap-side gain of {g.name} ({g.quantity}). {h.conclusion}")
    return out


def _direct_use(twins, e_contact: float) -> dict | None:
    """Whether the drop twin's apparent restitution equals its contact one, over the lab's trials:
    the mean, its Student-t interval, and the verdict ``may`` (the offset from the contact value
    is below the practical threshold of restitution, 0.03), ``may not`` (above it, with an
    interval excluding 0) or ``undetermined``."""
    sim = np.array([t.simulated for t in twins if math.isfinite(t.simulated)])
    if sim.size < 2:
        return None
    half = float(stats.t.ppf(0.975, sim.size - 1)) * float(sim.std(ddof=1)) / math.sqrt(sim.size)
    offset = float(sim.mean()) - e_contact
    bar = PRACTICAL_THRESHOLDS["restitution"]
    verdict = "may" if abs(offset) < bar else "may not" if abs(offset) > half else "undetermined"
    return {"mean": float(sim.mean()), "half": half, "offset": offset, "n": int(sim.size),
            "ratio": float(sim.mean()) / e_contact, "verdict": verdict}


def _drop_statements(state: dict, params) -> list:
    """Whether sqrt(h2/h1) may feed the DEM directly, per pair, with the numbers."""
    out = []
    for pair, s in state.items():
        d = _direct_use(s["twins"].values(), s["contact"])
        if d is None:
            continue
        y = np.mean([t.measured for t in s["twins"].values() if math.isfinite(t.simulated)])
        e, offset = s["contact"], d["offset"]
        text = (f"restitution.{pair}: the lab's sqrt(h2/h1) is {y:.3g}; the drop twin with contact "
                f"{s['parameter']} = {e:.3g}, at the lab's {d['n']} drop heights and orientations, rebounds "
                f"with an apparent {d['mean']:.3g} [{d['mean'] - d['half']:.3g}, {d['mean'] + d['half']:.3g}] "
                f"(ratio {d['ratio']:.3g}). ")
        if d["verdict"] == "may":
            text += ("sqrt(h2/h1) may feed the DEM directly: the twin's apparent restitution is within the "
                     f"0.03 practical threshold of its contact restitution (offset {offset:.3g}).")
        elif d["verdict"] == "undetermined":
            text += (f"Whether sqrt(h2/h1) may feed the DEM directly is undetermined: the offset {offset:.3g} "
                     f"is within the uncertainty +-{d['half']:.3g} of these drops.")
        else:
            text += ("sqrt(h2/h1) may not feed the DEM directly: the twin's apparent restitution differs from "
                     f"its contact restitution by {offset:.3g}")
            on = [t.simulated for t in s.get("twins_on", {}).values() if math.isfinite(t.simulated)]
            text += (f"; with the dashpots damping the effective mass at each contact it rebounds at "
                     f"{np.mean(on):.3g}, so {np.mean(on) - d['mean']:.3g} of it is the overdamping of "
                     f"off-centre and simultaneous contacts and {e - np.mean(on):.3g} rotation (model "
                     f"findings)." if on else ".")
            inv = s.get("inverted")
            if inv is not None:
                halves = ", ".join(f"{v:.3g}" for v in inv["halves"])
                text += (f" The contact restitution that reproduces the drops is {s['parameter']} = "
                         f"{inv['contact']:.3g} (halves {halves}; interval [{inv['ci95'][0]:.3g}, "
                         f"{inv['ci95'][1]:.3g}]).")
            elif s.get("inversion_notes"):
                text += f" Inverting the twin failed: {'; '.join(s['inversion_notes'])}."
        out.append(text)
    return out


def _finding_statements(findings) -> list:
    found = [f for f in findings if f.verdict == "found"]
    open_ = [f for f in findings if f.verdict == "inconclusive"]
    ruled = sorted({f.mechanism for f in findings if f.verdict == "ruled_out"})
    out = []
    if found:
        names = sorted({f.mechanism for f in found})
        out.append(f"Found: {', '.join(names)}. " + " ".join(f"{f.mechanism}: {f.evidence}." for f in found[:6]))
    else:
        out.append("No mechanism of the catalogue is found in this data.")
    if open_:
        out.append("Inconclusive (neither found nor excluded by the data): " + "; ".join(
            f"{f.mechanism} ({f.quantity} vs {f.covariate}"
            + (f", about {f.rows_to_decide} rows would decide it" if f.rows_to_decide else "") + ")"
            for f in open_) + ".")
    if ruled:
        out.append(f"Ruled out (every interval within the practical threshold): {', '.join(ruled)}.")
    return out
