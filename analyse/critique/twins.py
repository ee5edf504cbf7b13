"""Twins of the lab tests with the calibrated parameters, trial by trial, and the discrepancy table.

For every trial the lab made, the twin of its test is run with that trial's settings
(``simulate.rigs``):

drop
    one run per drop, at the drop's height and release orientation (``orientation_deg``; a
    random orientation from the row's seed when the sheet does not log it), on the pair's
    plate: ``particle-<contact_material>`` on the DEM's wall material, ``particle-particle`` on
    a plate of the particle material. Pairs the DEM has no parameters for (e.g.
    ``particle-rubber``) are listed, not run.
incline
    one run per surface and mode (the rig is deterministic, so every trial of a group has the
    same twin); tan(onset angle) against the lab's per-trial friction.
repose
    the campaign's validation runs (``DIR/runs``), or ``repose_seeds`` new runs of the quick
    profile when only a workbook is given.

Runs go through a run store (``analyse.runs``): with a campaign folder they are kept in
``DIR/critique_runs`` and a second critique reuses them.

Discrepancy (one row per observable): the measured mean and its Student-t 95 % interval, the
simulated mean and its interval (over trials or seeds; a deterministic twin has none), the
difference and the half-width of its 95 % interval (the combined uncertainty: paired t for
per-trial twins, Welch for independent samples), and whether the difference exceeds it.

References
----------
Welch, B. L. (1947). The generalization of "Student's" problem when several different
population variances are involved. Biometrika 34, 28-35.
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import stats

from demcal.analyse.runs import RunStore, Workers, run_all, run_key
from demcal.errors import SimulationError
from demcal.jsonio import restore_nan
from demcal.simulate.scenes import compile_kernels


def twin_parameters(measurement, results=None):
    """The parameters the twins use, and where they come from.

    With a campaign's result (``analyse.results.CampaignResult``): its ``calibrated_parameters``. Otherwise the measured
    means fed directly to the DEM, as the paper's first step does: measured shape, density and
    materials (``analyse.parameters.base_parameters``) and each contact parameter at the mean of
    its test.

    Returns
    -------
    (simulate.params.DEMParameters, str)
    """
    from demcal.analyse.parameters import PARAMETER_BOUNDS, SCREENING_FACTORS, base_parameters, wall_of
    from demcal.simulate.params import DEMParameters

    if results and results.calibrated_parameters:
        return DEMParameters.from_names(results.calibrated_parameters), "calibrated (campaign results.json)"
    params = base_parameters(measurement)
    wall = wall_of(measurement.meta)
    changes = {}
    for _, name, quantity in SCREENING_FACTORS:
        est = measurement.quantities.get(quantity.format(wall=wall))
        if est is not None and math.isfinite(est.value):
            lo, hi = PARAMETER_BOUNDS[name]
            changes[name] = min(max(float(est.value), lo), hi)
    return params.with_(**changes), "measured means fed directly (no campaign given)"


# ----------------------------------------------------------------------------------------------
# run execution


class TwinRunner:
    """Runs twins through a run store (a temporary one when ``store_dir`` is None).

    ``runner(function, tasks, desc)`` returns the result dicts in task order; a run that
    failed twice raises ``SimulationError`` naming its record.
    """

    def __init__(self, store_dir=None, *, workers: int = 1, progress: bool = False):
        self._tmp = None
        if store_dir is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="demcal-twins-")
            store_dir = self._tmp.name
        self.store = RunStore(store_dir)
        self.workers = Workers(int(workers), prepare=compile_kernels)
        self.progress = bool(progress)
        self.log: list = []

    def __call__(self, function, tasks: list, desc: str) -> list:
        if not tasks:
            return []
        out = run_all(tasks, function, self.store, desc=desc, progress=self.progress, executor=self.workers)
        self.log.append({"stage": desc, "runs": len(tasks), "ran": out.ran, "reused": out.reused,
                         "failed": out.failed})
        bad = [r for r in out.records if r["status"] != "ok"]
        if bad:
            raise SimulationError(f"{desc}: {len(bad)} of {len(tasks)} twin runs failed; first: {bad[0]['error']} "
                                  f"(record {self.store.path(bad[0]['key'])})")
        return [r["result"] for r in out.records]

    def close(self):
        self.workers.close()
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


# ----------------------------------------------------------------------------------------------
# twins of the trials


@dataclass(frozen=True)
class TwinTrial:
    """One lab trial and its twin.

    Attributes
    ----------
    sheet, quantity : str
    row : int
        Data row of the trial.
    measured : float
        The lab's per-row value [unit of the quantity].
    simulated : float
        The twin's value of the same observable (NaN when the twin could not measure it).
    covariates : dict
        Covariates of the row (as the diagnosis sees them).
    task : dict
        The twin run's inputs (its run-store key is ``run_key(task)``).
    """

    sheet: str
    quantity: str
    row: int
    measured: float
    simulated: float
    covariates: dict
    task: dict

    @property
    def residual(self) -> float:
        return self.measured - self.simulated

    def to_dict(self) -> dict:
        return {"sheet": self.sheet, "quantity": self.quantity, "row": self.row, "measured": self.measured,
                "simulated": self.simulated, "residual": self.residual, "run_key": run_key(self.task)}


def run_drop_twins(runner: TwinRunner, params, trials, rig_pair_name: str, *, quantity: str,
                   sizes=None, extension=None, desc="drop twins") -> list:
    """Twin of each drop trial with ``params``: ``trials`` are the critique's drop records
    ``(row, measured e, height [m], orientation or None, covariates, record)``
    (``loop._restitution_twins``); ``sizes`` maps a row to its specimen's sizes [m]
    (``Shape.size_values``) for per-trial templates."""
    from demcal.simulate.rigs import drop, rig, run_task

    tasks = [drop.task(params, rig_pair_name, h, o, row,
                       template=None if sizes is None else sizes.get(row), extension=extension)
             for row, _, h, o, _, _ in trials]
    results = runner(run_task, tasks, desc)
    out = []
    for (row, y, h, o, cov, _), task, res in zip(trials, tasks, results):
        out.append(TwinTrial("drop", quantity, row, y, rig("drop").reading(task, res), cov, task))
    return out


# ----------------------------------------------------------------------------------------------
# discrepancies


def _mean_ci(x) -> tuple[float, tuple]:
    x = np.asarray(x, dtype=float)
    m = float(x.mean())
    if x.size < 2:
        return m, (math.nan, math.nan)
    half = float(stats.t.ppf(0.975, x.size - 1)) * float(x.std(ddof=1)) / math.sqrt(x.size)
    return m, (m - half, m + half)


@dataclass(frozen=True)
class Discrepancy:
    """One row of the discrepancy table.

    Attributes
    ----------
    observable : str
        What is compared (quantity and how it is observed).
    sheet : str
    measured : float
        Mean of the lab's values [unit].
    measured_ci95 : tuple of float
    simulated : float or None
        Mean of the twin's values [unit] (None when the twin could not measure it).
    simulated_ci95 : tuple of float or None
        Over trials or seeds; None for a deterministic twin.
    difference : float or None
        Measured minus simulated [unit].
    combined_u95 : float or None
        Half-width of the 95 % interval of the difference [unit].
    exceeds : bool or None
        |difference| > combined_u95.
    n_measured, n_simulated : int
    note : str
        Parameters used and anything the reader must know.
    """

    observable: str
    sheet: str
    measured: float
    measured_ci95: tuple
    simulated: float | None
    simulated_ci95: tuple | None
    difference: float | None
    combined_u95: float | None
    exceeds: bool | None
    n_measured: int
    n_simulated: int
    note: str = ""

    def to_dict(self) -> dict:
        def lst(c):
            return None if c is None else [float(c[0]), float(c[1])]
        return {"observable": self.observable, "sheet": self.sheet, "measured": self.measured,
                "measured_ci95": lst(self.measured_ci95), "simulated": self.simulated,
                "simulated_ci95": lst(self.simulated_ci95), "difference": self.difference,
                "combined_u95": self.combined_u95, "exceeds": self.exceeds,
                "n_measured": self.n_measured, "n_simulated": self.n_simulated, "note": self.note}

    @classmethod
    def from_dict(cls, d: dict) -> "Discrepancy":
        def tup(c):
            return None if c is None else tuple(math.nan if x is None else x for x in c)
        d = restore_nan(d, "measured")
        return cls(**{**d, "measured_ci95": tup(d["measured_ci95"]), "simulated_ci95": tup(d["simulated_ci95"])})


def paired_discrepancy(observable: str, sheet: str, measured, simulated, note: str = "") -> Discrepancy:
    """Per-trial twin: difference and its interval from the paired differences (Student t)."""
    y = np.asarray(measured, dtype=float)
    s = np.asarray(simulated, dtype=float)
    ok = np.isfinite(y) & np.isfinite(s)
    if ok.sum() < 2:
        m, mci = _mean_ci(y)
        return Discrepancy(observable, sheet, m, mci, None, None, None, None, None, int(y.size), int(ok.sum()),
                           (note + "; " if note else "") + "the twin measured fewer than 2 trials")
    m, mci = _mean_ci(y[ok])
    sm, sci = _mean_ci(s[ok])
    d, dci = _mean_ci(y[ok] - s[ok])
    u = 0.5 * (dci[1] - dci[0])
    return Discrepancy(observable, sheet, m, mci, sm, sci, d, u, bool(abs(d) > u), int(ok.sum()), int(ok.sum()),
                       note)


def independent_discrepancy(observable: str, sheet: str, measured, simulated, note: str = "") -> Discrepancy:
    """Independent samples (photos against seeds): Welch's interval of the difference of means."""
    y = np.asarray(measured, dtype=float)
    s = np.asarray(simulated, dtype=float)
    y, s = y[np.isfinite(y)], s[np.isfinite(s)]
    m, mci = _mean_ci(y)
    if s.size == 0:
        return Discrepancy(observable, sheet, m, mci, None, None, None, None, None, int(y.size), 0, note)
    sm, sci = _mean_ci(s)
    d = m - sm
    vy = y.var(ddof=1) / y.size if y.size > 1 else math.nan
    vs = s.var(ddof=1) / s.size if s.size > 1 else 0.0
    se = math.sqrt(vy + vs)
    dof = (vy + vs) ** 2 / (vy ** 2 / (y.size - 1) + (vs ** 2 / (s.size - 1) if s.size > 1 else 0.0)) \
        if (vy + vs) > 0 else math.nan
    u = float(stats.t.ppf(0.975, dof)) * se if math.isfinite(dof) else math.nan
    return Discrepancy(observable, sheet, m, mci, sm, sci if s.size > 1 else None, d, u,
                       None if not math.isfinite(u) else bool(abs(d) > u), int(y.size), int(s.size), note)


def constant_discrepancy(observable: str, sheet: str, measured, simulated: float, note: str = "") -> Discrepancy:
    """A deterministic twin (one value for the whole group) against per-trial measurements."""
    y = np.asarray(measured, dtype=float)
    m, mci = _mean_ci(y)
    if simulated is None or not math.isfinite(simulated):
        return Discrepancy(observable, sheet, m, mci, None, None, None, None, None, int(y.size), 1, note)
    u = 0.5 * (mci[1] - mci[0])
    d = m - simulated
    return Discrepancy(observable, sheet, m, mci, float(simulated), None, d, u, bool(abs(d) > u),
                       int(y.size), 1, note)


def repose_validation_angles(campaign_dir, results, validation=None) -> tuple[list, str]:
    """Angles of the campaign's validation runs (``CampaignResult``; ``validation``: a further
    repose rig's, default the first rig's), from ``DIR/runs``: the campaign's response
    (``results.response``), as the calibration read it."""
    from demcal.simulate.rigs import repose_rig_named

    response = (results.response or {}).get("name") or repose_rig_named(results.repose_rig).compared
    validation = validation or results.validation
    runs = validation.runs
    store = RunStore(Path(campaign_dir) / "runs")
    angles, missing = [], []
    for ref in runs:
        rec = store.get(ref["key"])
        if rec is None or rec.get("status") != "ok":
            missing.append(ref["key"])
            continue
        angles.append(float(rec["result"]["observable"][response]))
    if not angles:
        responses = validation.responses
        note = "validation responses from results.json (run records not found)" if responses else \
            "the campaign has no validation runs"
        return [float(v) for v in responses], note
    note = f"{len(angles)} validation runs of the campaign (DIR/runs)"
    if missing:
        note += f"; {len(missing)} run record(s) missing"
    return angles, note
