"""Rigs: the twins of the lab tests, each measuring its observable the way the lab does.

================  ==================================  ============================================
rig               lab test                            observable
================  ==================================  ============================================
repose            plate withdrawal ("pumping plate")  ``angle_deg`` (photo method, one flank),
                  heap (``simulate.rigs.repose``)     profile and outside-heap angles, escapes
lifting_cylinder  cylinder lifted off its fill: a     ``angle_deg`` (photo method, both flanks),
                  cone (``...rigs.lifting_cylinder``) each flank, profile angle, crest height
funnel            cone poured through a fixed funnel  as the lifting cylinder, and the particles
                  (``simulate.rigs.funnel``)          left in the funnel
drum              rotating drum, free surface seen    ``angle_deg`` (drum estimator, mean of frames),
                  end-on (``simulate.rigs.drum``)     frame sd, profile angle
drop              free fall onto a plate, rebound     ``apparent_restitution`` = sqrt(h_rebound /
                  filmed (``simulate.rigs.drop``)     h_drop) of the centre of mass
incline           inclinometer, plate tilted slowly   ``slide_angle_deg``, ``roll_angle_deg``
                  (``simulate.rigs.incline``)
================  ==================================  ============================================

A rig is one module plus one line in :data:`RIGS`: the module declares ``RIG = Rig(...)``
(:class:`Rig`: its workbook sheet, its dimensions, its observables, how it runs), so the
stages above loop over the registered rigs and never dispatch on a rig's name. Every rig
returns a :class:`RigResult`; :func:`run_rig` runs one by name. A rig's ``task(params, seed,
...)`` gives the inputs of one run as a plain dict naming its rig (what a run store keys,
``analyse.runs.run_key``), and :func:`run_task` runs any task on the rig it names.

The repose rigs (the workbook's ``repose`` sheet) are chosen by the meta key ``repose_rig``
(:func:`repose_rigs`): ``lifted_plate`` (the default), ``lifting_cylinder``, ``funnel`` or ``drum``,
or several separated by commas (the sheet's ``rig`` column then names each photo's rig, and a
dimension they share is each rig's own, :func:`meta_names`).

Rigs whose sheets hold single trials (the drop, the incline) also say how the lab's rows become
twin runs (:class:`TrialGroup`, ``Rig.trial_groups`` and ``Rig.group_tasks``) and what a run
reads (``Rig.reading``): the joint calibration (``analyse.twin_likelihood``) and the critique
loop over them. Each rig also declares its ``demcal simulate`` options and, for a repose rig,
its case in LIGGGHTS (``Rig.liggghts_case``).

>>> from simulate.params import DEMParameters
>>> result = run_rig("drop", DEMParameters(), seed=1, height=0.4, orientation_deg=0.0)
>>> result.observable["apparent_restitution"]                      # doctest: +SKIP

Progress and frames. Every rig accepts ``callback(sim, t_end, final)``, called after each
chunk of steps it runs (``t_end``: the planned, or for runs that may end early the largest,
simulated time [s]; ``final``: True on the last call, with the final state).
"""

from __future__ import annotations

import importlib
import operator
from dataclasses import dataclass, field
from typing import Callable

from demcal.errors import InputError, WorkbookError
from demcal.provenance import Provenance

#: Rig name -> the module that declares it (``RIG``): the one registration line of a rig.
RIGS = {"repose": "demcal.simulate.rigs.repose",
        "lifting_cylinder": "demcal.simulate.rigs.lifting_cylinder",
        "funnel": "demcal.simulate.rigs.funnel",
        "drum": "demcal.simulate.rigs.drum",
        "drop": "demcal.simulate.rigs.drop",
        "incline": "demcal.simulate.rigs.incline"}

@dataclass(frozen=True)
class Rig:
    """One twin of a lab test, as its module declares it (``RIG = Rig(...)``).

    Attributes
    ----------
    name : str
        Registry name: tasks, run keys and ``demcal simulate NAME`` use it.
    sheet : str
        The workbook sheet whose rows it mirrors (``repose``, ``drop``, ``incline``).
    run : callable
        ``run(params, seed, **options) -> RigResult``.
    task : callable
        ``task(params, seed, **options) -> dict``, the inputs of one run (naming ``name``).
    run_task : callable
        ``run_task(task) -> dict``, the run's ``RigResult.to_dict()``.
    observables : dict
        Observable name -> unit, as ``RigResult.observable`` holds them.
    observable_notes : dict
        Observable name -> what it measures, in the report's words (those the name does not say).
    targets : dict
        The lab's other readings of the rig's heaps the calibration can fit beside the angle
        (``CampaignConfig.extra_targets``, off by default): lab quantity (``crest_height_mm``)
        -> (the observable that mirrors it, factor from its unit to the lab's).
    recorded_as : dict
        Observables that runs stored before they became observables hold in their record:
        observable -> record key (``Rig.observed_value`` reads either).
    compared : str or None
        The observable compared with the lab's reading.
    fallbacks : tuple of str
        Observables used in this order when ``compared`` is not finite (a heap the photo method
        finds no slope in), each a reading of the same quantity by another method.
    geometry : type or None
        Its dimensions from the workbook's meta: ``from_meta(meta, file)``, ``META_KEYS``,
        ``meta_rows()``, ``to_dict()``, ``describe()``.
    workbook_name : str or None
        The value of the meta key ``repose_rig`` that chooses it (repose rigs).
    flanks : str
        What its photos show, as the repose sheet's ``side`` says: ``right`` (one flank),
        ``both`` (a cone) or ``drum`` (a drum's free surface, end-on).
    lab_test : str
        The lab test it is the twin of, in the report's words.
    measure : callable or None
        ``measure(centres, radii, geometry) -> dict``: the angle observables of a settled heap
        of spheres in the rig (demcal's or another code's), measured as the lab's photos are.
    liggghts_case : callable or None
        ``liggghts_case(params, geometry, lift_time) -> case``: the rig in LIGGGHTS-PUBLIC
        (``simulate.liggghts.deck``), its particle and contact model from demcal's export, the
        wall lifted at ``lift_time`` [s].
    analytic_photo, run_photo : callable or None
        How the virtual lab draws the rig's photo (None: a heap seen from the side):
        ``analytic_photo(angle_deg, rng) -> image`` of a heap at a given angle, and
        ``run_photo(record, rng) -> image`` of a run's ``RigResult.record``.

    A rig whose sheet holds single trials (a drop, a tilt) also says how the lab's rows become
    twin runs and readings:

    trial_groups : callable or None
        ``trial_groups(quantities, wall) -> list of TrialGroup``: the used rows of the measured
        quantities it mirrors (``quantities``: name -> estimate with ``per_row`` records;
        ``wall``: the workbook's plate material), grouped by twin setting, the preferred group
        of a quantity first.
    group_tasks : callable or None
        ``group_tasks(params, group, **options) -> list of task``: one run per trial
        (``per_trial``) or one for the whole group (a deterministic twin).
    observed : callable or None
        ``observed(task) -> str``: the observable that is a task's reading of the lab quantity.
    grid : callable or None
        ``grid(value, sd, bounds) -> array``: the parameter values the joint calibration runs
        the twin at (``analyse.twin_likelihood``), from the lab's mean and sd and the
        parameter's bounds.
    per_trial : bool
        Each trial has its own twin run (its own settings, e.g. height and orientation).
    reading_label : str
        How the report names the twin's reading (e.g. ``apparent sqrt(h2/h1)``).
    describe_twin : callable or None
        ``describe_twin(group, params, results) -> str``: what the discrepancy table notes of a
        group's twin runs (their settings; why a reading is missing).

    And what ``demcal simulate SHEET`` offers (the rigs of one sheet share them):

    cli_arguments : callable or None
        ``cli_arguments(group)``: adds its options to an ``argparse`` argument group.
    cli_options : callable or None
        ``cli_options(args) -> dict``: the run's keyword options from the parsed arguments (a
        bad value raises ``InputError`` naming the option).
    """

    name: str
    sheet: str
    run: Callable
    task: Callable
    run_task: Callable
    observables: dict
    observable_notes: dict = field(default_factory=dict)
    targets: dict = field(default_factory=dict)
    recorded_as: dict = field(default_factory=dict)
    compared: str | None = None
    fallbacks: tuple = ()
    geometry: type | None = None
    workbook_name: str | None = None
    flanks: str = "both"
    lab_test: str = ""
    measure: Callable | None = None
    liggghts_case: Callable | None = None
    analytic_photo: Callable | None = None
    run_photo: Callable | None = None
    trial_groups: Callable | None = None
    group_tasks: Callable | None = None
    observed: Callable | None = None
    grid: Callable | None = None
    per_trial: bool = False
    reading_label: str = ""
    describe_twin: Callable | None = None
    cli_arguments: Callable | None = None
    cli_options: Callable | None = None

    def reading(self, task: dict, result: dict) -> float:
        """A run's reading of the lab quantity (NaN when the twin could not measure it):
        ``result`` is the task's ``run_task`` result."""
        name = self.observed(task) if self.observed is not None else self.compared
        value = result["observable"].get(name)
        return float(value) if value is not None else float("nan")

    def observed_value(self, result: dict, name: str):
        """Observable ``name`` of a run's ``RigResult.to_dict()`` (None when it has none), read
        from the record of a run stored before it was an observable (``recorded_as``)."""
        value = (result.get("observable") or {}).get(name)
        if value is None and name in self.recorded_as:
            value = (result.get("record") or {}).get(self.recorded_as[name])
        return value

    def label(self, quantity: str) -> str:
        """The discrepancy table's name of the twin's reading of ``quantity``."""
        return f"{quantity} ({self.name} twin{', ' + self.reading_label if self.reading_label else ''})"


@dataclass(frozen=True)
class Trial:
    """One lab row a twin mirrors.

    Attributes
    ----------
    row : int
        The row's number in its sheet (as the measurement's records give it).
    measured : float
        The lab's reading of the row, in its quantity's unit.
    settings : dict
        The twin's settings of this row (e.g. a drop's ``height`` [m] and ``orientation_deg``).
    record : dict
        The measurement's record of the row (its covariates included).
    """

    row: int
    measured: float
    settings: dict
    record: dict


@dataclass(frozen=True)
class TrialGroup:
    """The lab trials of one quantity that one twin setting mirrors.

    Attributes
    ----------
    rig : str
        The registered rig whose twin runs them.
    quantity : str
        The measured quantity (``restitution.particle-steel``, ``static_friction.particle``).
    setting : dict or None
        The twin's settings shared by the group (a drop's ``pair``; an incline's ``mode`` and
        ``surface``); None when the DEM has no parameters for the lab's setting.
    trials : tuple of Trial
    why : str
        Why the group is not simulated (``setting`` None).
    """

    rig: str
    quantity: str
    setting: dict | None
    trials: tuple
    why: str = ""

    @property
    def measured(self) -> list:
        """The lab's readings, trial by trial."""
        return [t.measured for t in self.trials]


def used_rows(estimate) -> list:
    """The used per-row records of a measured quantity that carry a value."""
    return [r for r in estimate.per_row if r.get("used", True) and r.get("value") is not None]


def trial_rigs() -> list:
    """The registered rigs whose sheets hold single trials (``Rig.trial_groups``)."""
    return [r for r in map(rig, RIGS) if r.trial_groups is not None]


def trial_groups(quantities: dict, wall: str) -> list:
    """Every trial rig's groups of the lab's rows (:class:`TrialGroup`), rig by rig."""
    return [g for r in trial_rigs() for g in r.trial_groups(quantities, wall)]


def rig(name: str) -> Rig:
    """The registered rig ``name``; an unknown name lists the valid ones."""
    if name not in RIGS:
        raise InputError(f"unknown rig {name!r}; valid rigs: {', '.join(RIGS)}")
    return importlib.import_module(RIGS[name]).RIG


def rigs_of_sheet(sheet: str) -> list:
    """The registered rigs that mirror the workbook sheet ``sheet``."""
    return [r for r in map(rig, RIGS) if r.sheet == sheet]


def repose_rig_named(workbook_name: str) -> Rig:
    """The repose rig whose workbook name (meta ``repose_rig``) is ``workbook_name``."""
    for r in rigs_of_sheet("repose"):
        if r.workbook_name == workbook_name:
            return r
    raise InputError(f"no repose rig is named {workbook_name!r}; valid: "
                     f"{', '.join(r.workbook_name for r in rigs_of_sheet('repose'))}")


def rig_of_geometry(geometry) -> Rig:
    """The registered repose rig whose dimensions ``geometry`` is."""
    for r in rigs_of_sheet("repose"):
        if isinstance(geometry, r.geometry):
            return r
    raise InputError(f"geometry must be the dimensions of a repose rig, got {type(geometry).__name__}")


def repose_rig_names() -> list:
    """The workbook names of the registered repose rigs (meta ``repose_rig``, sheet column ``rig``)."""
    return [r.workbook_name for r in rigs_of_sheet("repose")]


def meta_names(rigs) -> dict:
    """How the repose rigs ``rigs`` of one workbook name their dimensions in its meta
    (``{workbook name: {key: meta key}}``): a key several of them share (``fill_count``) is
    each one's own, prefixed with its name (``lifted_plate_fill_count``, ``drum_fill_count``)."""
    count = {}
    for r in rigs:
        for key in r.geometry.META_KEYS:
            count[key] = count.get(key, 0) + 1
    return {r.workbook_name: {k: f"{r.workbook_name}_{k}" for k in r.geometry.META_KEYS if count[k] > 1}
            for r in rigs}


def repose_rigs(meta: dict, file=None) -> list:
    """The repose rigs a workbook's ``meta`` names (key ``repose_rig``: one name or several
    separated by commas, default ``lifted_plate``), the first one's photos being the heap the
    lab's target angle comes from.

    An unknown or repeated name and a dimension of a repose rig not named raise
    ``WorkbookError`` naming the key: the twin must never simulate another heap than the one
    the lab photographed.
    """
    meta = meta or {}
    rigs = {r.workbook_name: r for r in rigs_of_sheet("repose")}
    raw = meta.get("repose_rig")
    text = str(raw).strip().lower() if raw is not None else ""
    names = [n.strip() for n in text.split(",")] if text else ["lifted_plate"]
    for name in names:
        if name not in rigs:
            raise WorkbookError(f"meta repose_rig: {name!r} is not a repose rig with a twin, so its heaps cannot "
                                f"be calibrated against (its photos still measure with demcal measure); repose "
                                f"rigs: {', '.join(rigs)} (several: separated by commas)",
                                file=file, sheet="meta", column="value", value=raw)
        if names.count(name) > 1:
            raise WorkbookError(f"meta repose_rig: {name!r} is named twice", file=file, sheet="meta",
                                column="value", value=raw)
    chosen = [rigs[n] for n in names]
    renamed = meta_names(chosen)
    own = {renamed[r.workbook_name].get(key, key) for r in chosen for key in r.geometry.META_KEYS}
    shared = {key: [n for n, m in renamed.items() if key in m] for m in renamed.values() for key in m}
    others = {key: r.workbook_name for r in rigs.values() if r not in chosen for key in r.geometry.META_KEYS}
    prefixed = {f"{r.workbook_name}_{k}": (r.workbook_name, k) for r in rigs.values() for k in r.geometry.META_KEYS}
    for key, value in meta.items():
        if value is None or (isinstance(value, str) and not value.strip()) or key in own:
            continue                              # a blank row of a template says nothing
        if key in prefixed:
            rig_name, plain = prefixed[key]
            mine = renamed.get(rig_name, {}).get(plain, plain) if rig_name in names else None
            raise WorkbookError(f"meta {key}: " + (f"the {rig_name} rig's {plain} is meta {mine} in this workbook"
                                                   if mine else f"a dimension of the {rig_name} rig, which meta "
                                                   f"repose_rig does not name ({', '.join(names)})"),
                                file=file, sheet="meta", column="key", value=key)
        if key in shared:
            raise WorkbookError(f"meta {key}: a dimension of each of the rigs {', '.join(shared[key])}; give each "
                                f"its own: {', '.join(f'{n}_{key}' for n in shared[key])}",
                                file=file, sheet="meta", column="key", value=key)
        other = others.get(key)
        if other is not None:
            raise WorkbookError(f"meta {key}: a dimension of the {other} rig, which meta repose_rig does not "
                                f"name ({', '.join(names)}); their dimensions: "
                                f"{', '.join(k for r in chosen for k in r.geometry.META_KEYS)}",
                                file=file, sheet="meta", column="key", value=key)
    return chosen


def repose_rig(meta: dict, file=None) -> Rig:
    """The workbook's first repose rig (:func:`repose_rigs`), whose photos give the target."""
    return repose_rigs(meta, file)[0]


@dataclass(frozen=True)
class RigResult:
    """What one run of a rig produced.

    Attributes
    ----------
    rig : str
        The registered rig that ran (``RIGS``).
    observable : dict
        The measured quantities, named as in the lab (e.g. ``angle_deg``,
        ``apparent_restitution``, ``slide_angle_deg``); NaN when the run could not measure one.
    record : dict
        The full record: heap profile, sphere positions and radii, trajectories, time series
        (numpy arrays, SI units).
    meta : dict
        ``seed``, ``dt`` [s], ``steps``, ``wall_s`` (real time of the simulation) [s],
        ``spheres`` (spheres simulated at the end), ``sphere_steps_per_s`` [1/s], ``profile``
        (repose profile, None for the other rigs), ``simulated_s`` [s] and rig-specific notes.
    params : dict
        The ``DEMParameters`` used, as a dict.
    provenance : demcal.provenance.Provenance
        Code version, seed and the rig options.
    """

    rig: str
    observable: dict
    record: dict
    meta: dict
    params: dict
    provenance: Provenance

    def to_dict(self) -> dict:
        return {"rig": self.rig, "observable": dict(self.observable), "record": dict(self.record),
                "meta": dict(self.meta), "params": dict(self.params),
                "provenance": self.provenance.to_dict()}


@dataclass(frozen=True)
class ReposeSetup:
    """The workbook's repose rig and its dimensions: what a campaign's repose runs are.

    Attributes
    ----------
    rig : str
        The registered rig (``RIGS``).
    geometry : dict
        Its dimensions, the ``to_dict()`` of its ``geometry`` class.
    """

    rig: str
    geometry: dict

    @property
    def workbook_name(self) -> str:
        """The rig's name in the workbook (meta ``repose_rig``)."""
        return rig(self.rig).workbook_name

    def task(self, params, seed: int, *, profile: str) -> dict:
        """The inputs of one run of the rig (what a run store keys)."""
        return rig(self.rig).task(params, seed, profile=profile, geometry=self.geometry)

    def dimensions(self):
        """The rig's dimensions as an object of its geometry class."""
        return rig(self.rig).geometry(**self.geometry)

    def check_for(self, shape, file=None) -> None:
        """Refuse, before any run, a rig whose heap of ``shape`` could not be read (a
        ``WorkbookError`` on the meta sheet of ``file``, whose dimensions say so)."""
        try:
            dims = self.dimensions()
            dims.check_fill(shape)
            dims.check_for(shape)
        except WorkbookError:
            raise
        except InputError as exc:
            raise WorkbookError(str(exc), file=file, sheet="meta") from None

    def describe(self, noun: str = "particles") -> str:
        """What the report says of the rig (``noun``: the particles' name, plural)."""
        return self.dimensions().describe(noun)


def repose_setups(meta: dict, file=None) -> list:
    """The repose rigs a workbook's ``meta`` names (:func:`repose_rigs`), each with its
    dimensions read from the same meta (a missing or bad one refused naming its key)."""
    rigs = repose_rigs(meta, file)
    renamed = meta_names(rigs)
    return [ReposeSetup(r.name, r.geometry.from_meta(meta, file, renamed[r.workbook_name]).to_dict()) for r in rigs]


def repose_setup(meta: dict, file=None) -> ReposeSetup:
    """The workbook's first repose rig with its dimensions (:func:`repose_setups`)."""
    return repose_setups(meta, file)[0]


def rig_function(name: str):
    """The run function of rig ``name``; an unknown name lists the valid ones."""
    return rig(name).run


def run_rig(name: str, params, seed: int = 0, **opts) -> RigResult:
    """Run rig ``name`` (``repose``, ``drop``, ``incline``) with ``params`` and ``seed``.

    ``opts`` are the rig's keyword options (see ``run_repose``, ``run_drop``, ``run_incline``).
    """
    return rig_function(name)(params, seed, **opts)


def run_task(inputs: dict) -> dict:
    """Run one task (a rig module's ``task(...)``) on the rig it names; a task naming no rig is
    a repose run, as the first campaigns stored them (top level, so worker processes run it)."""
    name = inputs.get("rig", "repose")
    if name not in RIGS:
        raise InputError(f"unknown rig {name!r} in a run's task; valid rigs: {', '.join(RIGS)}")
    return rig(name).run_task(inputs)


def run_meta(seed, dt, tally, spheres, simulated_s, profile=None, **extra) -> dict:
    """The ``meta`` dict of a :class:`RigResult` from a :class:`RunTally` of its runs."""
    wall = tally.wall_s
    return {"seed": seed, "dt": float(dt), "steps": int(tally.steps), "wall_s": float(wall),
            "spheres": int(spheres),
            "sphere_steps_per_s": float(tally.sphere_steps / wall) if wall > 0 else 0.0,
            "profile": profile, "simulated_s": float(simulated_s), **extra}


class RunTally:
    """Totals over successive ``Simulation.run`` calls: steps, wall time, sphere-steps."""

    def __init__(self):
        self.steps = 0
        self.wall_s = 0.0
        self.sphere_steps = 0.0

    def add(self, summary) -> None:
        """Add one ``RunSummary``."""
        self.steps += summary.steps
        self.wall_s += summary.wall_time
        self.sphere_steps += summary.sphere_steps_per_second * summary.wall_time


def check_seed(seed) -> int:
    """A run seed: a non-negative integer (Python or numpy)."""
    try:
        value = operator.index(seed)
    except TypeError:
        value = None
    if value is None or isinstance(seed, bool) or value < 0:
        raise InputError(f"seed must be a non-negative integer, got {seed!r}")
    return value


__all__ = ["RIGS", "ReposeSetup", "Rig", "RigResult", "RunTally", "Trial", "TrialGroup", "check_seed", "meta_names", "repose_rig", "repose_rig_named", "repose_rig_names", "repose_rigs", "repose_setup", "repose_setups", "rig", "rig_of_geometry", "rig_function", "rigs_of_sheet",
           "run_meta", "run_rig", "run_task", "trial_groups", "trial_rigs", "used_rows"]
