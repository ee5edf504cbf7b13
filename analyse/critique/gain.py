"""The gain of a model extension: the same discrepancy before and after, on data not used to fit.

For each extension that answers a found mechanism (``analyse.critique.mechanisms``), the drop
trials of the pair are split by row order into two halves (``split_trials``): the inverted
restitution is fitted on each half and judged on the other (two-fold cross-fit, every trial
held out once), the size extension is judged on one half; the velocity law holds out the
highest drop height instead, so that its gain is an extrapolation to a speed it never saw. The twins of the
held-out trials are run with the model before (the calibrated parameter, or the constant
fitted to the same training trials) and after the extension; the discrepancy measure is

- ``abs_mean_residual``: |mean(measured - simulated)| over the held-out trials (a bias the
  extension is meant to remove), or
- ``rms_residual``: sqrt(mean((measured - simulated)^2)) (structure the extension is meant to
  explain, e.g. a trend with segment size),

and the gain is before minus after. Intervals are percentile bootstrap intervals, resampling
the held-out trials in pairs (the same trials before and after), 2000 resamples from an
explicit seed (Efron & Tibshirani 1993, ch. 13).

References
----------
Efron, B., Tibshirani, R. J. (1993). An Introduction to the Bootstrap. Chapman & Hall.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from demcal.analyse.critique.twins import run_drop_twins
from demcal.errors import InputError
from demcal.jsonio import restore_nan
from demcal.simulate.extensions import (describe, fit_velocity_restitution, impact_speed, invert_drop_twin,
                                        restitution_parameter)

MEASURES = ("abs_mean_residual", "rms_residual")
N_BOOTSTRAP = 2000


@dataclass(frozen=True)
class ExtensionGain:
    """One row of the extension table.

    Attributes
    ----------
    name : str
        Extension (``simulate.extensions.EXTENSIONS``).
    mechanism : str
        Catalogue mechanism it answers.
    measure : str
        Discrepancy measure (``MEASURES``), on ``quantity``.
    quantity : str
    held_out : str
        Which data the measure is taken on.
    before, after : float
        Discrepancy of the model without and with the extension [unit of the quantity].
    before_ci95, after_ci95 : tuple of float
    gain : float
        before - after (positive: the extension helps).
    ci95 : tuple of float
        Paired bootstrap interval of the gain.
    n_held_out : int
    fitted : str
        What the extension fitted on the training trials, with its interval.
    note : str
    extension : dict
        Provenance record of the extension (``simulate.extensions.describe``).
    heap_settings : dict
        The ``DEMParameters`` engine-hook fields that switch the extension on in a heap (a
        recalibration's ``CampaignConfig.model_extensions``); empty when it is no model switch.
    """

    name: str
    mechanism: str
    measure: str
    quantity: str
    held_out: str
    before: float
    before_ci95: tuple
    after: float
    after_ci95: tuple
    gain: float
    ci95: tuple
    n_held_out: int
    fitted: str = ""
    note: str = ""
    extension: dict = field(default_factory=dict)
    heap_settings: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """Flat, JSON-ready (the keys the report's critique table shows first)."""
        def lst(c):
            return [float(c[0]), float(c[1])]
        return {"name": self.name, "mechanism": self.mechanism, "before": self.before, "after": self.after,
                "gain": self.gain, "ci95": lst(self.ci95), "measure": f"{self.measure} of {self.quantity}",
                "held_out": self.held_out, "before_ci95": lst(self.before_ci95),
                "after_ci95": lst(self.after_ci95), "n_held_out": self.n_held_out, "fitted": self.fitted,
                "note": self.note}

    def as_dict(self) -> dict:
        """Every field (``critique.json``'s ``extension_records``), provenance included."""
        return asdict(self)

    @classmethod
    def from_dict(cls, record: dict) -> "ExtensionGain":
        """From :meth:`as_dict` as JSON holds it."""
        d = restore_nan(record, "before", "after", "gain")
        return cls(**{**d, **{k: tuple(math.nan if x is None else x for x in d[k])
                              for k in ("before_ci95", "after_ci95", "ci95")}})


def discrepancy(residuals, measure: str) -> float:
    """The discrepancy ``measure`` of residuals (measured - simulated)."""
    r = np.asarray(residuals, dtype=float)
    if measure == "abs_mean_residual":
        return float(abs(r.mean()))
    if measure == "rms_residual":
        return float(math.sqrt(np.mean(r * r)))
    raise InputError(f"unknown discrepancy measure {measure!r}; valid: {', '.join(MEASURES)}")


def paired_bootstrap(before, after, measure: str, rng, n_boot: int = N_BOOTSTRAP) -> dict:
    """Discrepancies before and after, their gain, and percentile 95 % intervals from resampling
    the trials in pairs."""
    b = np.asarray(before, dtype=float)
    a = np.asarray(after, dtype=float)
    if b.shape != a.shape or b.size < 2:
        raise InputError("paired bootstrap needs the same held-out trials (at least 2) before and after")
    rng = np.random.default_rng(rng)
    idx = rng.integers(0, b.size, (n_boot, b.size))
    db = np.array([discrepancy(b[i], measure) for i in idx])
    da = np.array([discrepancy(a[i], measure) for i in idx])

    def ci(x):
        lo, hi = np.percentile(x, [2.5, 97.5])
        return (float(lo), float(hi))

    vb, va = discrepancy(b, measure), discrepancy(a, measure)
    return {"before": vb, "before_ci95": ci(db), "after": va, "after_ci95": ci(da), "gain": vb - va,
            "ci95": ci(db - da)}


def split_trials(trials) -> tuple[list, list]:
    """Every other trial (by row order) to fit, the others held out."""
    ordered = sorted(trials, key=lambda t: t[0])
    if len(ordered) < 4:
        raise InputError(f"{len(ordered)} trials: at least 4 are needed to fit on half and hold out half")
    return ordered[0::2], ordered[1::2]


def _gain(name, mechanism, measure, quantity, held_out, before, after, rng, **kw) -> ExtensionGain:
    stats_ = paired_bootstrap(before, after, measure, rng)
    return ExtensionGain(name=name, mechanism=mechanism, measure=measure, quantity=quantity,
                         held_out=held_out, n_held_out=len(before), **stats_, **kw)


def inverted_restitution_gain(runner, params, lab_pair: str, rig_pair: str, trials, before_twins: dict,
                              *, rng) -> tuple[ExtensionGain, list]:
    """Contact restitution by inverting the drop twin, cross-fitted over two halves of the trials.

    The trials are split by row order (``split_trials``); the twin is inverted on each half and
    run with that contact restitution on the other half, so every trial is held out once and
    judged by a fit that never saw it (two-fold cross-validation). ``before_twins`` maps a row
    to its twin with the calibrated parameters.

    Returns
    -------
    (ExtensionGain, list of simulate.extensions.InvertedRestitution)
        The gain, and the inversion of each half.
    """
    quantity = f"restitution.{lab_pair}"
    halves = split_trials(trials)
    param = restitution_parameter(rig_pair)
    calibrated = getattr(params, param)
    inversions, before, after, notes = [], [], [], []
    for k, (fit, held) in enumerate((halves, halves[::-1]), 1):
        def twin(e, fit=fit):
            ext = describe("inverted_restitution", pair=lab_pair, parameter=param, value=float(e))
            out = run_drop_twins(runner, params.with_(**{param: float(e)}), fit, rig_pair, quantity=quantity,
                                 extension=ext, desc=f"inverting the drop twin ({lab_pair}, half {k}, e = {e:.3g})")
            return [t.simulated for t in out]

        inv = invert_drop_twin(twin, [t[1] for t in fit], pair=lab_pair, start=calibrated)
        inversions.append(inv)
        if not inv.converged:
            notes.append(f"half {k}: {inv.note}")
            continue
        ext = describe("inverted_restitution", pair=lab_pair, parameter=param, value=inv.contact,
                       fitted_rows=[t[0] for t in fit])
        after_tw = run_drop_twins(runner, params.with_(**{param: inv.contact}), held, rig_pair,
                                  quantity=quantity, extension=ext,
                                  desc=f"held-out drops ({lab_pair}, half {k}, inverted e)")
        before += [before_twins[t[0]].residual for t in held]
        after += [t.residual for t in after_tw]
    fitted = "; ".join(f"half {k}: {param} = {inv.contact:.3g} [{inv.contact_ci95[0]:.3g}, "
                       f"{inv.contact_ci95[1]:.3g}] from {len(h[0])} drops"
                       for k, (inv, h) in enumerate(zip(inversions, (halves, halves[::-1])), 1)) + \
        f" (calibrated {calibrated:.3g})"
    ext = describe("inverted_restitution", pair=lab_pair, parameter=param,
                   values=[inv.contact for inv in inversions], cross_fit="two halves by row order")
    held_text = f"{len(after)} drops, each judged by the inversion of the other half (two-fold cross-fit)"
    if len(after) < 2:
        nan = (math.nan, math.nan)
        return ExtensionGain("inverted_restitution", "orientation_rotation", "abs_mean_residual", quantity,
                             held_text, before=math.nan, before_ci95=nan, after=math.nan, after_ci95=nan,
                             gain=math.nan, ci95=nan, n_held_out=len(after), fitted=fitted,
                             note="; ".join(notes), extension=ext), inversions
    return _gain("inverted_restitution", "orientation_rotation", "abs_mean_residual", quantity, held_text,
                 before, after, rng, fitted=fitted, extension=ext,
                 note="; ".join(["the twin's contact restitution set so that its mean apparent restitution over "
                                 "the fitted drops equals theirs"] + notes)), inversions


def combined_inversion(inversions) -> dict | None:
    """The contact restitution of the halves together: their mean and the hull of their
    intervals (None unless every half converged)."""
    if not inversions or not all(inv.converged for inv in inversions):
        return None
    values = [inv.contact for inv in inversions]
    return {"contact": float(np.mean(values)), "halves": values,
            "ci95": (float(min(inv.contact_ci95[0] for inv in inversions)),
                     float(max(inv.contact_ci95[1] for inv in inversions))),
            "target": float(np.mean([inv.target for inv in inversions]))}


def velocity_gain(runner, params, lab_pair: str, rig_pair: str, trials, *, rng,
                  contact_scale: float = 1.0) -> ExtensionGain:
    """e(v) fitted to the drops from all heights but the highest, measured on the highest.

    ``contact_scale`` converts the apparent restitution to the contact one (the inverted
    contact e over the measured mean, when the drop twin turns energy into rotation); it is
    taken as the same at every height. Before: the constant e of the training drops (times
    ``contact_scale``); after: e(v) at the held-out impact speed.
    """
    quantity = f"restitution.{lab_pair}"
    heights = sorted({round(t[2], 9) for t in trials})
    if len(heights) < 3:
        raise InputError(f"{quantity}: {len(heights)} drop height(s); e(v) needs two to fit and one held out")
    top = heights[-1]
    fit = [t for t in trials if round(t[2], 9) != top]
    held = [t for t in trials if round(t[2], 9) == top]
    law = fit_velocity_restitution([t[2] for t in fit], [t[1] for t in fit], pair=lab_pair)
    param = restitution_parameter(rig_pair)
    e_const = float(np.clip(np.mean([t[1] for t in fit]) * contact_scale, 0.01, 1.0))
    e_v = float(np.clip(law(impact_speed(top)) * contact_scale, 0.01, 1.0))
    ext = describe("velocity_dependent_restitution", pair=lab_pair, parameter=param, law=law.to_dict(),
                   contact_scale=contact_scale, mode="per impact (single-impact twin)")
    before_tw = run_drop_twins(runner, params.with_(**{param: e_const}), held, rig_pair, quantity=quantity,
                               desc=f"held-out height ({lab_pair}, constant e)")
    after_tw = run_drop_twins(runner, params.with_(**{param: e_v}), held, rig_pair, quantity=quantity,
                              extension=ext, desc=f"held-out height ({lab_pair}, e(v))")
    fitted = (f"e(v) = {law.e_ref:.3g} (v / {law.v_ref:.3g} m/s)^-{law.exponent:.3g}, n "
              f"[{law.exponent_ci95[0]:.3g}, {law.exponent_ci95[1]:.3g}]; at {top * 1e3:.0f} mm: "
              f"{param} = {e_v:.3g} (constant: {e_const:.3g})")
    # in a heap the law's shape goes to the engine (``with_velocity_restitution``); its level
    # stays the calibrated restitution
    heap = {f"{param}_v_ref": law.v_ref, f"{param}_exponent": law.exponent,
            f"{param}_v_min": min(law.speeds) if law.speeds else 0.0}
    return _gain("velocity_dependent_restitution", "velocity_dependent_restitution", "abs_mean_residual",
                 quantity, f"{len(held)} drops from the highest height ({top * 1e3:.0f} mm), not used to fit",
                 [t.residual for t in before_tw], [t.residual for t in after_tw], rng, fitted=fitted,
                 extension=ext, heap_settings=heap)


def size_gain(runner, params, lab_pair: str, rig_pair: str, trials, before_twins: dict, *, rng) -> ExtensionGain:
    """Per-trial particles of the specimen's own calliper size, on the held-out half of the drops."""
    quantity = f"restitution.{lab_pair}"
    _, held = split_trials(trials)
    sizes = {row: s for row, s in ((t[0], _specimen_sizes(params.shape, t[4])) for t in held) if s is not None}
    held = [t for t in held if t[0] in sizes]
    if len(held) < 2:
        raise InputError(f"{quantity}: fewer than 2 held-out drops name a specimen with a calliper size")
    ext = describe("size_distribution", pair=lab_pair, source="specimens sheet (callipers), per trial")
    after_tw = run_drop_twins(runner, params, held, rig_pair, quantity=quantity, sizes=sizes, extension=ext,
                              desc=f"held-out drops ({lab_pair}, specimen sizes)")
    before = [before_twins[t[0]].residual for t in held]
    # a heap draws its particles from the sizes of every dropped specimen
    every = [s for s in (_specimen_sizes(params.shape, t[4]) for t in trials) if s is not None]
    return _gain("size_distribution", "size_dependence", "rms_residual", quantity,
                 f"{len(held)} drops (every other row)", before, [t.residual for t in after_tw], rng,
                 fitted=f"nothing fitted: each {params.shape.name} has its specimen's "
                        f"{', '.join(n.removesuffix('_m') for n in params.shape.sizes)}", extension=ext,
                 heap_settings={"particle_sizes": [list(x) for x in every]})


def _specimen_sizes(shape, covariates: dict):
    """The sizes [m] (``Shape.size_values``) of the specimen a trial names, from the calliper
    readings among its ``covariates``; None when it has none the shape can take."""
    try:
        return shape.sized_as(covariates).size_values
    except InputError:
        return None
