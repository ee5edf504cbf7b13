"""Every lab test's twin in the likelihood: the drops constrain the restitutions, the incline
the frictions, and the heap has to explain only what they leave open (the "joint" calibration).

The lab measures each contact parameter through a rig: sqrt(h2/h1) of a dropped segment, tan of
the tilt at which it slides or rolls. A DEM parameter is not that reading: a five-sphere
segment landing at an angle turns part of its energy into rotation, so its apparent
restitution falls below the contact value. Each rig's twin is therefore run over a grid of the
parameter, at every logged trial (drop height and landing orientation, as the lab logged them;
a random orientation seeded by the row where it did not), and the parameter's likelihood is
that of the trials' mean residual, lab minus twin:

    r_i(theta) = y_i - twin_i(theta),   t(theta) = mean_i r_i / (sd_i(r_i) / sqrt(n)),
    L(theta) = (1 + t^2 / (n - 1))^(-n/2) / (sd_i(r_i) / sqrt(n))

the Student-t likelihood of the mean when its standard error is estimated from the same n
trials (a normal one, exp(-t^2 / 2), would trust the sd of two drops as if it were known and
give a prior several times too narrow; the two agree as n grows), by linear interpolation
between grid points, with a flat prior over the grid. For the incline the
twin is deterministic and the same for every trial of a group, so r_i spreads only by the lab's
scatter. The posterior on the grid has a mean and an sd (of the parameter's mean value). The
heap stage then uses, as its prior for the parameter, a normal of that mean and of the spread
of single trials carried through the twin, sd x sqrt(n) = s / |d twin / d theta|: the same
meaning as the heap-only prior (the lab's mean and the sd of its single readings), translated
into the DEM's parameter. Poisson's ratio has no twin: its measured mean and sd stay the
prior.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from scipy import stats

#: Fine grid on which the interpolated likelihood is evaluated.
FINE = 401


@dataclass
class TwinConstraint:
    """What one lab test's twin says about one DEM parameter.

    Attributes
    ----------
    parameter : str
        DEM parameter (``e_pw``, ``mu_s_pp``, ...).
    quantity : str
        The lab's measured quantity.
    rig : str
        ``drop`` or ``incline``.
    grid : list of float
        Parameter values the twin was run at.
    residual_mean, residual_se : list of float
        Mean lab-minus-twin residual over the trials, and its standard error, at each grid value.
    mean, sd_of_mean : float
        Posterior mean and sd of the parameter on the grid (flat prior over it).
    sd : float
        The spread of single trials in the parameter's units, ``sd_of_mean`` x sqrt(trials):
        the prior sd the heap stage uses.
    measured_mean, measured_sd : float
        The lab's direct reading (what the heap-only calibration uses as the prior).
    trials : int
    at_edge : bool
        The posterior piles up at an end of the grid: the twin cannot reach the lab's value
        inside it.
    runs : list of dict
        Run references (key, seed) of every twin run.
    response : float or None
        How much the twin's mean reading changes from one end of the grid to the other
        (least-squares line through the readings), in the lab quantity's unit.
    informative : bool
        The response exceeds the half-width of the 95 % interval of the lab's mean: the twin
        tells the grid's ends apart at the lab's precision. An uninformative twin (a sphere on
        the sliding incline rolls first, whatever its friction) does not constrain its
        parameter, which keeps its measured prior; ``note`` says why.
    note : str
    """

    parameter: str
    quantity: str
    rig: str
    grid: list
    residual_mean: list
    residual_se: list
    mean: float
    sd_of_mean: float
    sd: float
    measured_mean: float
    measured_sd: float
    trials: int
    at_edge: bool
    runs: list = field(default_factory=list)
    response: float | None = None
    informative: bool = True
    note: str = ""

    def to_dict(self) -> dict:
        return asdict(self)


def _grid_posterior(grid, r_mean, r_se, n: int) -> tuple[float, float, bool]:
    fine = np.linspace(grid[0], grid[-1], FINE)
    m = np.interp(fine, grid, r_mean)
    se = np.maximum(np.interp(fine, grid, r_se), 1e-9)
    logw = -0.5 * n * np.log1p((m / se) ** 2 / (n - 1)) - np.log(se)
    w = np.exp(logw - logw.max())
    w /= w.sum()
    mean = float(np.sum(w * fine))
    sd = float(math.sqrt(max(np.sum(w * (fine - mean) ** 2), 0.0)))
    # more than 5 % of the mass in the outer grid cell at either end
    cell = (fine[-1] - fine[0]) / (len(grid) - 1)
    edge = bool(w[fine <= fine[0] + cell].sum() > 0.05 or w[fine >= fine[-1] - cell].sum() > 0.05)
    return mean, max(sd, 1e-6), edge


def twin_constraints(measurement, base, factors: dict, execute, run_refs) -> dict:
    """Run the trial rigs' twins (``simulate.rigs.trial_rigs``: the drop, the incline) over
    each parameter's grid and return ``{parameter: TwinConstraint}`` for every parameter a lab
    test's twin can constrain.

    ``execute(stage, tasks) -> records`` runs the twins (the campaign's run store; the task's
    ``rig`` says which twin); ``factors`` is ``analyse.campaign.factor_levels``'s table. While
    one parameter is varied the others stay at their measured means. A quantity measured in
    several ways (a sled and single particles) is read from its rig's preferred group.
    """
    from demcal.analyse.parameters import PARAMETER_BOUNDS, wall_of
    from demcal.simulate.rigs import rig, trial_groups

    groups = {}
    for g in trial_groups(measurement.quantities, wall_of(measurement.meta)):
        groups.setdefault(g.quantity, g)
    # every other contact parameter at its measured mean while one is varied
    base = base.with_(**{f["parameter"]: min(max(float(measurement.quantities[f["quantity"]].value),
                                                 PARAMETER_BOUNDS[f["parameter"]][0]),
                                             PARAMETER_BOUNDS[f["parameter"]][1])
                         for f in factors.values()})
    out = {}
    for f in factors.values():
        name, quantity = f["parameter"], f["quantity"]
        group = groups.get(quantity)
        if group is None or group.setting is None or len(group.trials) < 2:
            continue
        twin = rig(group.rig)
        est = measurement.quantities[quantity]
        grid = np.asarray(twin.grid(float(est.value), float(est.sd), PARAMETER_BOUNDS[name]), dtype=float)
        tasks = [twin.group_tasks(base.with_(**{name: float(g)}), group) for g in grid]
        records = execute(f"{twin.name} twins, {name}", [t for ts in tasks for t in ts])
        readings = np.array([twin.reading(t, r["result"]) for t, r in zip((t for ts in tasks for t in ts), records)])
        y = np.array(group.measured)
        sim = readings.reshape(len(grid), -1)
        if sim.shape[1] == 1:        # one deterministic run stands for every trial of the group
            sim = np.repeat(sim, len(y), axis=1)
        ok = np.all(np.isfinite(sim), axis=1)
        half = float(stats.t.ppf(0.975, len(y) - 1)) * float(np.std(y, ddof=1)) / math.sqrt(len(y))
        if ok.sum() < 3:
            out[name] = TwinConstraint(
                name, quantity, twin.name, grid.tolist(), [], [], math.nan, math.nan, math.nan, float(est.value),
                float(est.sd), int(len(y)), False, run_refs(records), None, False,
                f"the {twin.name} twin gave a reading at {int(ok.sum())} of {len(grid)} grid values of {name}; it "
                f"does not constrain it, which keeps its measured prior")
            continue
        resid = y[None, :] - sim[ok]
        r_mean = resid.mean(axis=1)
        r_se = resid.std(axis=1, ddof=1) / math.sqrt(len(y))
        mean, sd, edge = _grid_posterior(grid[ok], r_mean, r_se, len(y))
        response = _response(grid[ok], sim[ok].mean(axis=1))
        informative = bool(abs(response) > half)
        note = "" if informative else (
            f"the {twin.name} twin's reading changes by {response:.3g} over {name} {grid[ok][0]:.3g}-{grid[ok][-1]:.3g}, "
            f"less than the lab mean's 95 % half-width {half:.3g}: it does not respond to its parameter, "
            f"which keeps its measured prior")
        out[name] = TwinConstraint(name, quantity, twin.name, grid[ok].tolist(), r_mean.tolist(), r_se.tolist(),
                                   mean, sd, sd * math.sqrt(len(y)), float(est.value), float(est.sd),
                                   int(len(y)), edge, run_refs(records), response, informative, note)
    return out


def _response(grid, readings) -> float:
    """Change of the readings over the grid along their least-squares line."""
    slope = np.polyfit(np.asarray(grid, float), np.asarray(readings, float), 1)[0]
    return float(slope * (grid[-1] - grid[0]))
