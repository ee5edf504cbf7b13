"""Model discrepancies of the drop twin and their causes, each tested and given its share.

The lab's sqrt(h2/h1) and the drop twin's apparent restitution at the lab's heights and
orientations differ for three reasons, which the twin itself separates:

- ``contact_effective_mass``: each contact's dashpot damps the whole body mass where the
  contact moves only the body's effective mass there (a segment landing on several spheres at
  once, the glued-sphere damping of Kodam et al. 2010, or striking with one end sphere); the
  part of the twin's deficit that goes away when the dashpots damp the effective mass at each
  contact (``simulate.extensions``, ``contact_effective_mass``): twin(on) - twin(off);
- ``orientation_rotation``: a rigid segment turns part of its energy into rotation; the part
  left with the damping corrected: e_contact - twin(on);
- the contact restitution itself: measured - e_contact (what a recalibration would move).

The three parts add up to measured - twin(off). Each part's interval is a percentile bootstrap
over the trials (the same resample for every part); a cause is ``found`` when its part's
interval excludes 0 and the part reaches the practical threshold of restitution (0.03),
``ruled_out`` otherwise. ``contact_effective_mass`` also needs its signature: at the logged
orientations the twin rebounds below the rigid-body reference by more than that threshold on
average. The reference is the same segment as a rigid body with the contact restitution at
each instantaneous impact, on a frictionless plate (``simulate.rigid_impact``: one end impact,
or the two of a segment a few degrees off flat), each drop at its own height and orientation;
drops with no logged orientation are judged by a flat landing, whose reference is the contact
restitution itself. Friction, the twin's finite contact durations and its rebound ending where
the centre of mass falls back below its contact height also keep a twin below the reference,
so the signature is necessary, not sufficient: the hook's own part decides.

The twin's dependence on orientation is compared with the lab's as a discrepancy of its own
(slope of the rebound against ``orientation_deg``, twin against lab): a dependence the twin
shows and the data do not is a model discrepancy, never a data effect.

References
----------
Kodam, M., Bharadwaj, R., Curtis, J., Hancock, B., Wassgren, C. (2010). Cylindrical object
contact detection for use in discrete element method simulations, Part II: Experimental
validation. Chem. Eng. Sci. 65, 5863-5871.
Efron, B., Tibshirani, R. J. (1993). An Introduction to the Bootstrap. Chapman & Hall, ch. 13.
Stronge, W. J. (2000). Impact Mechanics. Cambridge University Press, ch. 2-3.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy import stats

from demcal.analyse.critique.diagnosis import MIN_ROWS, PRACTICAL_THRESHOLDS, trend_test
from demcal.analyse.critique.gain import N_BOOTSTRAP, _gain, split_trials
from demcal.analyse.critique.twins import Discrepancy, run_drop_twins
from demcal.simulate.extensions import engine_hooks
from demcal.simulate.rigid_impact import rigid_drop

#: Orientation of a flat landing [deg]: the long axis horizontal.
FLAT_DEG = 0.0
#: Drops logged this close to flat are the held-out set of the damping extension [deg].
FLAT_WITHIN_DEG = 15.0

VERDICTS = ("found", "ruled_out", "not_testable")


@dataclass(frozen=True)
class ModelFinding:
    """A model-level cause of a discrepancy between twin and lab, tested.

    Attributes
    ----------
    mechanism : str
        Catalogue id (``contact_effective_mass``, ``orientation_rotation``).
    verdict : str
        ``found``, ``ruled_out`` or ``not_testable``.
    observable : str
        The discrepancy it is a cause of.
    measured, simulated : float or None
        The lab's and the twin's value of the observable.
    share : float or None
        The cause's part of measured - simulated, as a fraction of it (None when that
        difference is within its own interval: there is nothing to share).
    part, part_ci95 : float or None, list or None
        The part itself [unit of the observable] and its bootstrap interval.
    evidence : str
        One sentence with the numbers.
    """

    mechanism: str
    verdict: str
    observable: str
    measured: float | None = None
    simulated: float | None = None
    share: float | None = None
    part: float | None = None
    part_ci95: list | None = None
    evidence: str = ""

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "ModelFinding":
        return cls(**d)


def _fmt(x, d=3) -> str:
    return "n/a" if x is None or not np.isfinite(x) else f"{x:.{d}g}"


def orientation_discrepancy(quantity: str, twins) -> Discrepancy | None:
    """Slope of the rebound against ``orientation_deg``: the lab's against the twin's at the
    same trials (straight lines, Student-t intervals); None when orientation is not logged on
    enough trials or does not vary."""
    rows = [(t.covariates.get("orientation_deg"), t.measured, t.simulated) for t in twins]
    rows = [r for r in rows if r[0] is not None and math.isfinite(r[2])]
    if len(rows) < MIN_ROWS or len({r[0] for r in rows}) < 2:
        return None
    o, y, s = (np.asarray(c, dtype=float) for c in zip(*rows))
    lab, twin = trend_test(o, y), trend_test(o, s)
    u_lab, u_twin = 0.5 * (lab["ci95"][1] - lab["ci95"][0]), 0.5 * (twin["ci95"][1] - twin["ci95"][0])
    u = math.hypot(u_lab, u_twin)
    d = lab["effect"] - twin["effect"]
    span = float(o.max() - o.min())
    exceeds = bool(abs(d) > u and abs(d) * span >= PRACTICAL_THRESHOLDS["restitution"])
    note = (f"the twin predicts {_fmt(twin['effect'])} per deg, the lab shows {_fmt(lab['effect'])} "
            f"[{_fmt(lab['ci95'][0])}, {_fmt(lab['ci95'][1])}] per deg over {_fmt(span)} deg of orientation")
    return Discrepancy(f"{quantity}: slope against orientation_deg (drop twin)", "drop", lab["effect"],
                       tuple(lab["ci95"]), twin["effect"], tuple(twin["ci95"]), d, u, exceeds, len(rows),
                       len(rows), note)


def _bootstrap_parts(measured, off, on, contact: float, rng) -> dict:
    """Parts of mean(measured - off) and their percentile intervals, resampling trials."""
    m, a, b = (np.asarray(v, dtype=float) for v in (measured, off, on))
    idx = np.random.default_rng(rng).integers(0, m.size, (N_BOOTSTRAP, m.size))

    def parts(i):
        return {"total": m[i].mean() - a[i].mean(), "damping": b[i].mean() - a[i].mean(),
                "rotation": contact - b[i].mean(), "contact": m[i].mean() - contact}

    point = {k: float(v) for k, v in parts(np.arange(m.size)).items()}
    boot = [parts(i) for i in idx]
    ci = {k: [float(np.percentile([p[k] for p in boot], 2.5)), float(np.percentile([p[k] for p in boot], 97.5))]
          for k in point}
    return {"point": point, "ci95": ci}


def attribute_drop_discrepancy(runner, params, pair: str, state: dict, rng) -> tuple[list, list]:
    """Model findings of one drop pair and the gain of ``contact_effective_mass`` on held-out
    flat drops (see the module docstring).

    Parameters
    ----------
    runner : twins.TwinRunner
    params : DEMParameters
        The model under critique.
    pair : str
    state : dict
        ``loop._drop_twins``'s record of the pair: ``rig_pair``, ``trials``, ``twins``
        (row -> TwinTrial), ``parameter``, ``contact``.
    rng : numpy.random.Generator

    Returns
    -------
    (list of ModelFinding, list of ExtensionGain)
    """
    quantity = f"restitution.{pair}"
    observable = f"{quantity} (drop twin, apparent sqrt(h2/h1))"
    rig_pair, trials, e_c = state["rig_pair"], state["trials"], state["contact"]
    on_params = params.with_(contact_effective_mass=True)
    twins_on = {t.row: t for t in run_drop_twins(runner, on_params, trials, rig_pair, quantity=quantity,
                                                 desc=f"drop twins, contact effective mass ({pair})")}
    state["twins_on"] = twins_on
    rows = [r for r in state["twins"] if math.isfinite(state["twins"][r].simulated)
            and math.isfinite(twins_on[r].simulated)]
    bar = PRACTICAL_THRESHOLDS["restitution"]
    if len(rows) < 2:
        why = "fewer than 2 drops the twin could measure"
        return [ModelFinding(m, "not_testable", observable, evidence=why)
                for m in ("contact_effective_mass", "orientation_rotation")], []
    measured = [state["twins"][r].measured for r in rows]
    off = [state["twins"][r].simulated for r in rows]
    on = [twins_on[r].simulated for r in rows]
    parts = _bootstrap_parts(measured, off, on, e_c, rng)
    p, ci = parts["point"], parts["ci95"]
    total = p["total"]
    where, reference, sig_off, sig_on = _rigid_body_signature(runner, params, on_params, rig_pair, trials,
                                                              {r: (off[i], on[i]) for i, r in enumerate(rows)}, e_c)

    # a share of a discrepancy that is not there (its interval holds 0) means nothing
    real = ci["total"][0] > 0 or ci["total"][1] < 0

    def share(x):
        return x / total if real and total != 0 else None

    def judged(part):
        lo, hi = ci[part]
        return (lo > 0 or hi < 0) and abs(p[part]) >= bar

    common = dict(observable=observable, measured=float(np.mean(measured)), simulated=float(np.mean(off)))
    signature = reference - sig_off > bar
    damping_found = signature and judged("damping")
    findings = [
        ModelFinding("contact_effective_mass", "found" if damping_found else "ruled_out",
                     share=share(p["damping"]), part=p["damping"], part_ci95=ci["damping"],
                     evidence=(f"{where} the twin rebounds at {_fmt(sig_off)} where a rigid body with contact "
                               f"{state['parameter']} = {_fmt(e_c)} rebounds at {_fmt(reference)} "
                               f"({_fmt(sig_on)} with the contact effective mass); at the lab's drops the "
                               f"effective mass raises the twin from {_fmt(np.mean(off))} to "
                               f"{_fmt(np.mean(on))}: {_fmt(p['damping'])} [{_fmt(ci['damping'][0])}, "
                               f"{_fmt(ci['damping'][1])}] of the discrepancy {_fmt(total)}"
                               + ("" if signature else "; the twin does not rebound below the rigid body")),
                     **common),
        ModelFinding("orientation_rotation", "found" if judged("rotation") else "ruled_out",
                     share=share(p["rotation"]), part=p["rotation"], part_ci95=ci["rotation"],
                     evidence=(f"with the effective mass damped, the twin's apparent restitution {_fmt(np.mean(on))} lies "
                               f"{_fmt(p['rotation'])} [{_fmt(ci['rotation'][0])}, {_fmt(ci['rotation'][1])}] "
                               f"below its contact restitution {_fmt(e_c)}: energy into rotation; the rest, "
                               f"measured minus contact restitution, is {_fmt(p['contact'])} "
                               f"[{_fmt(ci['contact'][0])}, {_fmt(ci['contact'][1])}]"), **common),
    ]
    gains = []
    if damping_found:
        gain = _damping_gain(runner, params, on_params, pair, state, rng)
        if gain is not None:
            gains.append(gain)
    return findings, gains


def _rigid_body_signature(runner, params, on_params, rig_pair: str, trials, twins: dict, e_c: float):
    """Where the signature of ``contact_effective_mass`` is read, the rigid-body reference there
    and the twin's rebound without and with the hook (means over the drops).

    ``twins`` maps a data row to the twin's (off, on) apparent restitution. The drops with a
    logged orientation: each against ``simulate.rigid_impact.rigid_drop`` of the segment at its
    orientation and height, contact restitution ``e_c``. Without one: a flat landing of the
    twin at the median height (run here), against the flat rigid body (``e_c``)."""
    body = params.template()
    logged = [(row, h, o) for row, _, h, o, _, _ in trials if o is not None and row in twins]
    if logged:
        reference = float(np.mean([rigid_drop(body, float(o), e_c, float(h)).apparent_restitution
                                   for _, h, o in logged]))
        off, on = (float(np.mean([twins[row][k] for row, _, _ in logged])) for k in (0, 1))
        return f"at the {len(logged)} drops' logged orientations", reference, off, on
    height = float(np.median([t[2] for t in trials]))
    from demcal.simulate.rigs import drop, rig, run_task

    tasks = [drop.task(params, rig_pair, height, FLAT_DEG, 0), drop.task(on_params, rig_pair, height, FLAT_DEG, 0)]
    flat = runner(run_task, tasks, "flat landing")
    off, on = (rig("drop").reading(t, r) for t, r in zip(tasks, flat))
    return "landing flat", rigid_drop(body, FLAT_DEG, e_c, height).apparent_restitution, off, on


def _damping_gain(runner, params, on_params, pair: str, state: dict, rng):
    """|mean residual| of the held-out drops logged near flat (all drops when too few are),
    before (the model under critique) and after (contact effective mass, the contact restitution taken
    as the mean sqrt(h2/h1) of the other half: two-fold cross-fit)."""
    quantity = f"restitution.{pair}"
    trials = state["trials"]
    flat = [t for t in trials if t[3] is not None and float(t[3]) <= FLAT_WITHIN_DEG]
    pool, where = (flat, f"drops logged within {FLAT_WITHIN_DEG:g} deg of flat") if len(flat) >= 4 else (trials, "drops")
    if len(pool) < 4:
        return None
    half_a, half_b = split_trials(pool)
    param = state["parameter"]
    before, after, fitted = [], [], []
    for train, test in ((half_a, half_b), (half_b, half_a)):
        e_train = float(np.mean([t[1] for t in train]))
        fitted.append(e_train)
        twins = run_drop_twins(runner, on_params.with_(**{param: min(max(e_train, 1e-3), 1.0)}), test,
                               state["rig_pair"], quantity=quantity, desc=f"held-out drops, contact effective mass ({pair})")
        for t in twins:
            if math.isfinite(t.simulated) and math.isfinite(state["twins"][t.row].simulated):
                before.append(t.measured - state["twins"][t.row].simulated)
                after.append(t.measured - t.simulated)
    if len(before) < 2:
        return None
    d = float(np.mean(after))
    u = float(stats.t.ppf(0.975, len(after) - 1)) * float(np.std(after, ddof=1)) / math.sqrt(len(after))
    note = (f"held-out discrepancy with the extension {_fmt(d)} +- {_fmt(u)} (95 %): "
            + ("inside its uncertainty" if abs(d) <= u else "beyond its uncertainty"))
    return _gain("contact_effective_mass", "contact_effective_mass", "abs_mean_residual", quantity,
                 f"{len(before)} {where}, each judged with the contact restitution of the other half "
                 "(two-fold cross-fit)", before, after, rng,
                 fitted=(f"{param} = mean sqrt(h2/h1) of the other half: "
                         + ", ".join(_fmt(e) for e in fitted)), note=note,
                 extension=next(h for h in engine_hooks(on_params) if h["extension"] == "contact_effective_mass"),
                 heap_settings={"contact_effective_mass": True})
