"""The default calibration workflow: a plausible set from a noisy simulated heap.

Every DEM run is an independent draw (the heap is chaotic: a 1e-6 change of one parameter
redraws it), so this workflow spends its runs on knowing the *mean* angle where it matters and
says what the lab data pin down, instead of picking one optimum of one noisy surface:

1. **Noise.** Two nearby points (the prior mean, and half a prior sd above it in every
   parameter) are run with the same ``noise_repeats`` seeds: their replicate variance is the
   noise at the centre, and the correlation of the pairs says whether common random numbers
   would help (``analyse.noise``). Replicates per design point ``k`` follow from that noise.
2. **Design.** ``initial_points`` points (at most half of ``budget_runs``) of a
   space-filling design over the prior (Latin hypercube through the prior's quantiles), each
   run ``k`` times with its own seeds; the noise is pooled over all points and tested for
   constancy.
3. **Surrogate.** A Gaussian process of the mean angle with each point's noise over ``k`` on its
   diagonal (stochastic kriging, ``analyse.surrogate``); leave-one-out residuals check it.
4. **Sequential runs.** Batches of ``batch`` points where it is least certain whether the mean
   angle equals the target, until that is settled everywhere (U >= 2) or ``budget_runs`` runs
   of design and sequence are spent.
5. **Posterior and plausible set.** The prior of the seven contact parameters: with the
   ``joint`` likelihood (default) what each one's lab test says through its twin (drops for
   the restitutions, the incline for the frictions; ``analyse.twin_likelihood``), with
   ``heap`` the measured means and sds read directly; the lab target with its own uncertainty
   as the datum; per parameter a 95 % interval and posterior sd / prior sd. Then
   ``refine_rounds`` times, ``refine_runs`` runs at the posterior mode join the surrogate and
   the posterior is computed again. The recommended point is the refined point of highest
   posterior density, so that the mean angle where the validation runs is measured, not only
   extrapolated (a last refit may move the mode to where no run was made, and the surrogate
   is least reliable there); without refinement it is the mode. A joint campaign also reports
   the heap-only posterior on the same surrogate, for comparison.
6. **Validation that can fail.** Fresh runs at the recommended point: a first batch sized by
   power (the runs the test needs for 80 % power at the predicted bias, at least
   ``validation_first``), then ``validation_step`` more at a time up to ``validation_cap``,
   tested for equivalence with the lab (two one-sided tests, tolerance the larger of 1 deg and
   the lab's heap-to-heap sd, the lab mean's uncertainty included): equivalent, different or
   undecided.

A heap that neither the photo method nor its fallbacks can read (nothing left the container,
say) is poured again with a fresh seed of its own stream, up to ``MAX_POURS`` pours, as the lab
pours again a heap it cannot measure and as the virtual lab does for its photos; results.json
lists those runs (``response.repoured_runs``) and the report counts them in Table A2.

All seeds come from ``config.seed`` through ``numpy.random.SeedSequence``, one stream per stage,
so ``--seed`` redraws every run of every stage and a replay of the same campaign asks the run
store for exactly the same runs.
"""

from __future__ import annotations

import math

import numpy as np

from demcal.analyse.equivalence import (default_tolerance, lab_heaps_for_power, runs_for_power,
                                 sequential_equivalence, tost_power)
from demcal.analyse.noise import pooled_noise, replicates_for, seed_correlation
from demcal.analyse.results import (Calibration, ExtraTarget, HeapOnly, OtherRig, ParameterEstimate, Point,
                                    Validation)
from demcal.analyse.surrogate import (IMPLAUSIBILITY_CUT, U_STOP, HeapDatum, NoisySurrogate, Prior, next_points,
                               posterior, recommend, recommend_among, space_filling)
from demcal.errors import AnalysisError

#: Stage numbers of the seed streams (never reorder: they define which seeds a campaign uses).
SEED_STREAMS = {"noise": 1, "design": 2, "sequential": 3, "validation": 4, "surrogate": 5, "refine": 6,
                "pour again": 7}
#: Pours of one run's heap (the first and those poured again with fresh seeds) before a heap the
#: photo method cannot read ends the campaign.
MAX_POURS = 5
#: Marks the seed streams of a workbook's second and further repose rigs.
RIG_STREAM = 100
#: Marks the surrogate seeds of a rig's extra targets.
EXTRA_STREAM = 200
#: Prior samples kept in results.json for the plausible-set plots.
KEPT_SAMPLES = 1500
#: A design point's own replicate variance is shrunk toward the pooled one with this weight
#: (degrees of freedom) when the noise is not constant across points.
NOISE_PRIOR_DF = 4


def rig_entropy(entropy: list, rig: int) -> list:
    """``SeedSequence`` entropy of the workbook's ``rig``-th repose rig: the first rig's is
    ``entropy`` itself, so that a single-rig campaign draws what it always drew."""
    return list(entropy) + ([RIG_STREAM, rig] if rig else [])


class SeedStream:
    """Distinct run seeds per stage from one campaign seed (and, for the workbook's second and
    further repose rigs, the rig's place ``rig``: each rig draws its own seeds)."""

    def __init__(self, seed: int, rig: int = 0):
        self.seed = int(seed)
        self.rig = int(rig)
        self.used: dict = {}

    def entropy(self, stage: str) -> list[int]:
        """The ``SeedSequence`` entropy of a stage's stream (the first rig's as ever)."""
        return rig_entropy([self.seed, SEED_STREAMS[stage]], self.rig)

    def take(self, stage: str, n: int) -> list[int]:
        start = self.used.get(stage, 0)
        state = np.random.SeedSequence(self.entropy(stage)).generate_state(start + n, dtype=np.uint64)
        self.used[stage] = start + n
        return [int(s % (2 ** 31 - 1)) for s in state[start:]]


def pour_until_read(execute, stage: str, again_stage: str, tasks: list, pour_again, fresh_seeds, responses,
                    fallbacks: list, repoured: list, run_refs) -> tuple[np.ndarray, list]:
    """Run ``tasks`` (``execute(stage, tasks)``) and read their heaps by ``responses``. A heap
    the photo method and its fallbacks cannot read is poured again with a fresh seed, as the
    lab pours again a heap it cannot measure: ``fresh_seeds(n)`` gives n new seeds,
    ``pour_again(k, seed)`` the task of run ``k`` with one (run in the stage ``again_stage``), and
    each run set aside is listed in ``repoured`` (stage, key, seed, the seed that replaced it).
    After ``MAX_POURS`` pours of one run the campaign ends, naming its last record. Returns
    the responses and the records, those poured again in their runs' places."""
    records = execute(stage, tasks)
    unread: list = []
    y = responses(records, fallbacks, unreadable=unread)
    for _ in range(MAX_POURS - 1):
        if not unread:
            break
        again_tasks = []
        for k, s in zip(unread, fresh_seeds(len(unread))):
            repoured.append({"stage": stage, **run_refs([records[k]])[0], "poured_again_with_seed": s})
            again_tasks.append(pour_again(k, s))
        again = execute(again_stage, again_tasks)
        still: list = []
        y_again = responses(again, fallbacks, unreadable=still)
        for n, k in enumerate(unread):
            records[k], y[k] = again[n], y_again[n]
        unread = [unread[n] for n in still]
    if unread:
        r = records[unread[0]]
        raise AnalysisError(f"{stage}: {MAX_POURS} heaps in a row of one run could not be read "
                            f"(last: DEM run {r['key']}, run record runs/{r['key']}.json); the rig's "
                            "dimensions leave no measurable heap at these parameters")
    return y, records


def measured_prior(measurement, factors, constraints: dict | None = None) -> Prior:
    """The prior of the seven contact parameters: each one's measured mean and sd, or, for a
    parameter in ``constraints`` (``analyse.twin_likelihood``), the mean and sd its lab test's
    twin gives it."""
    from demcal.analyse.parameters import PARAMETER_BOUNDS

    constraints = constraints or {}
    names, mean, sd, bounds, sources = [], [], [], [], []
    for f in factors.values():
        est = measurement.quantities[f["quantity"]]
        c = constraints.get(f["parameter"])
        c = c if c is not None and c.informative else None     # an uninformative twin: the measured prior
        names.append(f["parameter"])
        mean.append(float(c.mean if c else est.value))
        sd.append(float(c.sd if c else est.sd))
        bounds.append(PARAMETER_BOUNDS[f["parameter"]])
        sources.append(f"{f['quantity']} ({c.rig} twin)" if c else f["quantity"])
    return Prior.from_measured(names, mean, sd, bounds, sources)


def _noise_variances(groups, pooled) -> np.ndarray:
    """Variance of each design point's mean: the pooled noise when it is constant, else each
    point's own replicate variance shrunk toward the pooled one."""
    out = []
    for g in groups:
        g = np.asarray(g, dtype=float)
        s2 = pooled.sd ** 2
        if not pooled.constant and g.size >= 2:
            df = g.size - 1
            s2 = (df * float(np.var(g, ddof=1)) + NOISE_PRIOR_DF * s2) / (df + NOISE_PRIOR_DF)
        out.append(max(s2, 1e-6) / g.size)
    return np.array(out)


class _Heap:
    """One repose rig of the workbook: its lab angle (target, heap-to-heap sd, heaps), the
    equivalence tolerance, and, as the workflow goes, its noise, design runs and surrogate.

    ``index`` is the rig's place in the meta's ``repose_rig``; the first rig's stages, stream
    seeds and results are those of a single-rig campaign."""

    def __init__(self, index, setup, estimate, config):
        self.index, self.setup = index, setup
        self.quantity = estimate.name
        self.target = float(estimate.value)
        self.lab_sd = float(estimate.sd) if estimate.n >= 2 and math.isfinite(estimate.sd) else None
        self.lab_n = int(estimate.n) if self.lab_sd is not None else None
        self.target_var = self.lab_sd ** 2 / self.lab_n if self.lab_sd is not None else 0.0
        self.tolerance = float(config.tolerance) if config.tolerance else default_tolerance(self.lab_sd)
        self.seeds = SeedStream(config.seed, index)
        self.design: list = []                    # every design point: x, runs, stage, seeds, refs
        self.rounds: list = []
        self.refinements: list = []
        self.extras: list = []
        self.stopped = "budget"

    def stage(self, name: str) -> str:
        """A stage's name in the campaign's log (the rig named from the second rig on)."""
        return name if self.index == 0 else f"{name} ({self.setup.workbook_name})"

    def stream(self, *entropy) -> np.random.SeedSequence:
        """A seed sequence of this rig (the first rig's as a single-rig campaign's)."""
        return np.random.SeedSequence(rig_entropy(entropy, self.index))

    def datum(self) -> HeapDatum:
        return HeapDatum(self.model, self.target, self.target_var)

    def data(self) -> list:
        """Every datum of this rig: its angle, then its extra targets'."""
        return [self.datum()] + [e.datum() for e in self.extras]


class _Extra:
    """Another reading of a rig's heaps the calibration fits when asked (``config.extra_targets``):
    the lab's ``quantity`` (e.g. ``crest_height_mm``) and the observable of the rig's own runs
    that mirrors it, scaled to the lab's unit; its surrogate is fitted to the same design points."""

    def __init__(self, heap, name, quantity, estimate, angle, observable, factor):
        self.heap, self.name, self.quantity = heap, name, quantity
        self.observable, self.factor = observable, float(factor)
        self.target = float(estimate.value)
        self.lab_sd = float(estimate.sd) if estimate.n >= 2 and math.isfinite(estimate.sd) else None
        self.lab_n = int(estimate.n) if self.lab_sd is not None else None
        self.target_var = self.lab_sd ** 2 / self.lab_n if self.lab_sd is not None else 0.0
        self.unit = estimate.unit
        self.lab_cov = _lab_covariance(angle, name)
        self.values: list = []                    # per design point of the rig: the runs' readings
        self.validation_values = np.array([])

    def read(self, records) -> np.ndarray:
        """The runs' readings in the lab's unit (NaN where a run has none)."""
        from demcal.simulate.rigs import rig

        twin = rig(self.heap.setup.rig)
        out = []
        for r in records:
            value = twin.observed_value(r["result"], self.observable)
            out.append(float(value) * self.factor if value is not None else math.nan)
        return np.array(out)

    def datum(self) -> HeapDatum:
        """Its likelihood, conditional on its rig's angle (the same photos), with no angle
        discrepancy (another unit)."""
        return HeapDatum(self.model, self.target, self.target_var, discrepancy_var=0.0,
                         given=self.heap.datum(), lab_cov=self.lab_cov)


def _lab_covariance(angle, name: str) -> float:
    """Covariance of the lab's mean angle and mean reading ``name`` (its per-photo record key)
    of one rig, from the photos that gave both (0 with fewer than 3)."""
    pairs = [(r["value"], r.get(name)) for r in angle.per_row if r.get("used", True)]
    pairs = np.array([p for p in pairs if p[1] is not None], dtype=float)
    if len(pairs) < 3:
        return 0.0
    return float(np.cov(pairs[:, 0], pairs[:, 1], ddof=1)[0, 1] / len(pairs))


def derive_plausible(measurement, config, execute, *, factors, base, setups, responses, run_refs,
                     identify_only: bool = False) -> dict:
    """The workflow of the module docstring; ``execute(stage, tasks) -> records`` supplies the
    DEM runs (the run store, or a replay from it); ``setups`` the workbook's repose rigs
    (``simulate.rigs.ReposeSetup``), the first one's angle ``repose_angle_deg``, each further
    one's the measurement's ``repose_angle_deg.<rig>``. Each rig has its own noise, design and
    surrogate; the posterior is conditioned on every rig's heap at once. Returns what
    ``results.json`` holds; with ``identify_only``, after the sequential runs, only what each rig
    alone and all together say of each parameter (``analyse.rig_plan``)."""
    from demcal.measure.pipeline import repose_quantity
    from demcal.simulate.rigs import rig

    heaps = [_Heap(i, setup, measurement.quantities[repose_quantity(i, setup.workbook_name)], config)
             for i, setup in enumerate(setups)]
    for heap in heaps:
        for name in config.extra_targets:
            if name not in rig(heap.setup.rig).targets:
                continue                          # a rig whose twin does not read it (a drum's crest)
            observable, factor = rig(heap.setup.rig).targets[name]
            quantity = repose_quantity(heap.index, heap.setup.workbook_name, name)
            heap.extras.append(_Extra(heap, name, quantity, measurement.quantities[quantity],
                                      measurement.quantities[heap.quantity], observable, factor))
    first = heaps[0]
    flank_band = measurement.provenance.options.get("flank_band")
    heap_prior = measured_prior(measurement, factors)
    fallbacks: list = []
    repoured: list = []      # runs whose heap no method could read, each poured again
    constraints = {}
    if config.likelihood == "joint":
        from demcal.analyse.twin_likelihood import twin_constraints

        constraints = twin_constraints(measurement, base, factors, execute, run_refs)
    prior = measured_prior(measurement, factors, constraints)
    names = prior.names
    # the surrogate spans both priors, so that the heap-only posterior can be compared on it
    box_low, box_high = np.minimum(prior.low, heap_prior.low), np.maximum(prior.high, heap_prior.high)

    def run(heap, stage, points, seed_lists):
        """The responses of each point's runs, their records and the seeds they ran with: a
        heap the photo method (and its fallbacks) cannot read is poured again with a fresh
        seed, as the lab pours again a heap it cannot measure (``repoured``)."""
        def task(i, j):
            return heap.setup.task(base.with_(**{n: float(v) for n, v in zip(names, points[i])}),
                                   seed_lists[i][j], profile=config.profile)

        seed_lists = [list(ss) for ss in seed_lists]
        slots = [(i, j) for i, ss in enumerate(seed_lists) for j in range(len(ss))]

        def pour_again(k, s):
            i, j = slots[k]
            seed_lists[i][j] = s
            return task(i, j)

        y, records = pour_until_read(execute, heap.stage(stage), heap.stage(f"{stage}, poured again"),
                                     [task(i, j) for i, j in slots], pour_again,
                                     lambda n: heap.seeds.take("pour again", n), responses, fallbacks, repoured,
                                     run_refs)
        _check_band(records, flank_band)
        out, i = [], 0
        for ss in seed_lists:
            out.append(y[i:i + len(ss)])
            i += len(ss)
        return out, records, seed_lists

    def add(heap, stage, points, seed_lists, ys, records):
        i = 0
        for x, ss, y in zip(points, seed_lists, ys):
            heap.design.append({"stage": stage, "x": np.asarray(x, dtype=float), "seeds": list(ss),
                                "responses": np.asarray(y, dtype=float),
                                "runs": run_refs(records[i:i + len(ss)])})
            for e in heap.extras:
                e.values.append(e.read(records[i:i + len(ss)]))
            i += len(ss)

    def fit(heap):
        groups = [p["responses"] for p in heap.design]
        heap.pooled = pooled_noise(groups)
        x = np.array([p["x"] for p in heap.design])
        y = np.array([p["responses"].mean() for p in heap.design])
        seed = int(heap.stream(config.seed, SEED_STREAMS["surrogate"]).generate_state(1)[0] % (2 ** 31))
        heap.model = NoisySurrogate(box_low, box_high, seed=seed).fit(x, y, _noise_variances(groups, heap.pooled))
        for j, e in enumerate(heap.extras, 1):
            # the points where the runs read it (a heap too flat to show a crest reads none)
            keep = [k for k, v in enumerate(e.values) if np.isfinite(v).any()]
            if len(keep) < 3:
                raise AnalysisError(f"{e.quantity}: fewer than 3 design points of the {heap.setup.workbook_name} "
                                    f"rig read {e.observable}; it cannot be a target")
            groups_e = [e.values[k][np.isfinite(e.values[k])] for k in keep]
            e.pooled = pooled_noise(groups_e)
            seed_e = int(heap.stream(config.seed, SEED_STREAMS["surrogate"], EXTRA_STREAM, j).generate_state(1)[0] % (2 ** 31))
            e.model = NoisySurrogate(box_low, box_high, seed=seed_e).fit(
                x[keep], np.array([g.mean() for g in groups_e]), _noise_variances(groups_e, e.pooled))

    # 1. noise at the centre, and the seed correlation --------------------------------------
    a = prior.truncated_mean_sd()[0]
    b = np.minimum(a + 0.5 * prior.sd, prior.high - 1e-9 * (prior.high - prior.low))
    for heap in heaps:
        pair_seeds = heap.seeds.take("noise", config.noise_repeats)
        (ya, yb), noise_records, pair_lists = run(heap, "noise", [a, b], [pair_seeds, pair_seeds])
        add(heap, "noise", [a, b], pair_lists, [ya, yb], noise_records)
        heap.centre_noise = pooled_noise([ya, yb])
        heap.correlation = seed_correlation(ya, yb)
        heap.pair = {"a": a.tolist(), "b": b.tolist(), "seeds": pair_lists[0],
                     "a_responses": ya.tolist(), "b_responses": yb.tolist()}
        if pair_lists[1] != pair_lists[0]:      # a heap poured again: that pair shares no seed
            heap.pair["b_seeds"] = pair_lists[1]
        k = heap.k = int(config.replicates) if config.replicates else replicates_for(heap.centre_noise.sd, heap.tolerance)

        # 2. space-filling design (at most half the budget: the rest goes where it informs) ----
        heap.n0 = max(min(config.initial_points, config.budget_runs // (2 * k)), 3)
        # rigs with as many points share them
        x0 = space_filling(prior, heap.n0, np.random.SeedSequence([config.seed, SEED_STREAMS["design"], 0]))
        s0 = heap.seeds.take("design", len(x0) * k)
        seed_lists = [s0[i * k:(i + 1) * k] for i in range(len(x0))]
        ys, records, seed_lists = run(heap, "design", list(x0), seed_lists)
        add(heap, "design", list(x0), seed_lists, ys, records)
        fit(heap)

        # 3. sequential runs where the sign of mean - target is least certain -----------------
        spent = len(x0) * k
        r = 0
        while spent + config.batch * k <= config.budget_runs:
            r += 1
            pts, u_min = next_points(heap.model, prior, heap.target, config.batch, noise_var=heap.pooled.sd ** 2 / k,
                                     seed=heap.stream(config.seed, SEED_STREAMS["sequential"], r))
            if u_min >= U_STOP:
                heap.rounds.append({"round": r, "u_min": u_min, "points": 0})
                heap.stopped = f"settled: every candidate has |m - target| / s >= {U_STOP:g}"
                break
            ss = heap.seeds.take("sequential", len(pts) * k)
            seed_lists = [ss[i * k:(i + 1) * k] for i in range(len(pts))]
            ys, records, seed_lists = run(heap, f"sequential {r}", list(pts), seed_lists)
            add(heap, f"sequential {r}", list(pts), seed_lists, ys, records)
            spent += len(pts) * k
            heap.rounds.append({"round": r, "u_min": u_min, "points": len(pts)})
            fit(heap)

    if identify_only:
        together = posterior(first.model, prior, first.target, first.target_var,
                             discrepancy_var=config.discrepancy_sd ** 2,
                             seed=np.random.SeedSequence([config.seed, SEED_STREAMS["surrogate"], 1]),
                             others=_others(heaps))
        return {"prior": prior.to_dict(), "by_rig": _each_rig_alone(heaps, prior, config),
                "together": _sd_ratios(together),
                "rigs": {h.setup.workbook_name: {"target_deg": h.target, "target_sd_deg": h.lab_sd, "heaps": h.lab_n,
                                                 "run_sd_deg": h.pooled.sd, "replicates": h.k,
                                                 "runs": sum(len(p["responses"]) for p in h.design),
                                                 "loo_rmse_deg": h.model.leave_one_out()["rmse"]}
                         for h in heaps},
                "twins": {n: c.to_dict() for n, c in constraints.items()}}

    # 4. posterior, plausible set, recommended point --------------------------------------------
    def calibrated():
        post = posterior(first.model, prior, first.target, first.target_var,
                         discrepancy_var=config.discrepancy_sd ** 2,
                         seed=np.random.SeedSequence([config.seed, SEED_STREAMS["surrogate"], 1]),
                         others=_others(heaps))
        return post, recommend(post, first.model)

    post, best = calibrated()
    # the validation runs at the recommended point, so the surrogate's mean there decides it:
    # pin it down with runs of its own (in every rig), refit, and let the recommended point move
    for r in range(1, config.refine_rounds + 1):
        x_r = np.array([best["values"][n] for n in names])
        for heap in heaps:
            predicted = [float(v[0]) for v in heap.model.predict(x_r[None, :])]
            ss = heap.seeds.take("refine", config.refine_runs)
            (y,), records, (ss,) = run(heap, f"refine {r}", [x_r], [ss])
            add(heap, f"refine {r}", [x_r], [ss], [y], records)
            fit(heap)
            heap.refinements.append({"round": r, "runs": len(ss), "predicted": predicted[0],
                                     "predicted_sd": predicted[1], "mean": float(y.mean()),
                                     "sd": float(y.std(ddof=1)) if y.size > 1 else None})
        post, best = calibrated()
    mode = best
    if config.refine_rounds:
        # the surrogate is least sure where no run has been made: the validation goes to the
        # refined point (its mean angle measured by refine_runs runs) the posterior rates
        # highest, not to a mode the last refit may have moved to unmeasured ground
        refined = [p["x"] for p in first.design if p["stage"].startswith("refine")]
        best = recommend_among(post, first.model, refined)
        best["chosen"] = f"refined point of round {best.pop('index') + 1}"
        for heap in heaps:
            for i, ref in enumerate(heap.refinements):
                m, s = heap.model.predict(refined[i][None, :])
                ref.update(final_predicted=float(m[0]), final_predicted_sd=float(s[0]))
    else:
        best["chosen"] = "posterior mode"
    parameters = _parameter_table(post, best)
    heap_only = None
    if constraints:
        hp = posterior(first.model, heap_prior, first.target, first.target_var, discrepancy_var=config.discrepancy_sd ** 2,
                       seed=np.random.SeedSequence([config.seed, SEED_STREAMS["surrogate"], 3]),
                       others=_others(heaps))
        hb = recommend(hp, first.model)
        heap_only = HeapOnly(parameters=_parameter_table(hp, hb), recommended=Point(**hb), ess=hp.ess)
    by_rig = _each_rig_alone(heaps, prior, config) if len(heaps) > 1 or first.extras else None
    inside = {n: bool(parameters[n].ci95[0] <= best["values"][n] <= parameters[n].ci95[1]) for n in names}

    # 5. validation by equivalence, in every rig ------------------------------------------------
    x_best = np.array([best["values"][n] for n in names])
    for heap in heaps:
        heap.validation = _validate(heap, config, x_best, best, run, run_refs)

    # what is kept for plots and the audit
    keep = np.random.default_rng(np.random.SeedSequence([config.seed, SEED_STREAMS["surrogate"], 2]))
    draws = keep.choice(post.weights.size, size=KEPT_SAMPLES, p=post.weights)
    rigs = ", ".join(h.setup.workbook_name for h in heaps)
    out = {
        "prior": prior.to_dict(),
        **_heap_sections(first, names, config),
        "calibration": Calibration(
            method=("posterior of the measured-mean-and-sd prior given the lab's angle of repose"
                    + (f" in each of its repose rigs ({rigs}), each with its own surrogate" if len(heaps) > 1 else "")
                    + ", by importance sampling on a stochastic-kriging surrogate of the mean heap angle; "
                    f"plausible set: implausibility < {IMPLAUSIBILITY_CUT:g} (history matching"
                    + ("; the largest over the rigs); " if len(heaps) > 1 else "); ")
                    + ("recommended point: the refined point of highest posterior density; "
                       if config.refine_rounds else "recommended point: the posterior mode; ")
                    + ("joint: the drop and incline twins constrain the restitutions and frictions "
                       "first (analyse.twin_likelihood)" if constraints else "heap only")),
            likelihood=config.likelihood,
            twins={n: c.to_dict() for n, c in constraints.items()},
            heap_only=heap_only,
            by_rig=by_rig,
            parameters=parameters,
            recommended=Point(**best), posterior_mode=Point(**mode), recommended_inside_ci95=inside,
            target_deg=first.target, target_sd_deg=first.lab_sd, target_n=first.lab_n, target_var=first.target_var,
            discrepancy_sd_deg=config.discrepancy_sd,
            plausible={"cut": IMPLAUSIBILITY_CUT, "share_of_prior": float(np.mean(post.plausible)),
                       "box": post.plausible_box()},
            ess=post.ess,
            samples={"names": list(names),
                     "prior": post.samples[:KEPT_SAMPLES].tolist(),
                     "prior_implausibility": post.implausibility[:KEPT_SAMPLES].tolist(),
                     "posterior": post.samples[draws].tolist()}),
        "validation": first.validation,
        "calibrated_parameters": base.with_(**best["values"]).to_dict(),
        "fallback_runs": fallbacks,
        "repoured_runs": repoured,
    }
    extras = [e for h in heaps for e in h.extras]
    if extras:
        out["extra_targets"] = [_extra_record(e, x_best, names) for e in extras]
    if len(heaps) > 1:
        out["other_rigs"] = [OtherRig.from_dict(dict(
            rig=h.setup.rig, workbook_name=h.setup.workbook_name, quantity=h.quantity, geometry=h.setup.geometry,
            target_deg=h.target, target_sd_deg=h.lab_sd, target_n=h.lab_n, target_var=h.target_var,
            **_heap_sections(h, names, config), predicted=_predicted(h, x_best), validation=h.validation),
            f"other_rigs[{h.index - 1}]") for h in heaps[1:]]
    return out


def _sd_ratios(post) -> dict:
    """Per parameter, the posterior/prior sd and the 95 % interval of a posterior."""
    return {n: {"sd_ratio": v["sd_ratio"], "ci95": v["ci95"]} for n, v in post.summary().items()}


def _others(heaps) -> list:
    """The data the posterior is conditioned on besides the first rig's angle: its extra targets,
    and every further rig's angle and extra targets."""
    return [e.datum() for e in heaps[0].extras] + [d for h in heaps[1:] for d in h.data()]


def _each_rig_alone(heaps, prior, config) -> dict:
    """What each rig says alone (its angle, and its extra targets if any), on its own surrogates
    and the same prior: per rig, per parameter, the posterior/prior sd and the 95 % interval;
    with extra targets, the first rig's angle alone too (``<rig> angle only``)."""
    out = {}
    if heaps[0].extras:
        first = heaps[0]
        alone = posterior(first.model, prior, first.target, first.target_var, discrepancy_var=config.discrepancy_sd ** 2,
                          seed=first.stream(config.seed, SEED_STREAMS["surrogate"], 4))
        out[f"{first.setup.workbook_name} angle only"] = _sd_ratios(alone)
    for heap in heaps:
        alone = posterior(heap.model, prior, heap.target, heap.target_var, discrepancy_var=config.discrepancy_sd ** 2,
                          seed=heap.stream(config.seed, SEED_STREAMS["surrogate"], 4),
                          others=[e.datum() for e in heap.extras])
        out[heap.setup.workbook_name] = _sd_ratios(alone)
    return out


def _extra_record(e, x_best, names) -> ExtraTarget:
    """What ``results.json`` keeps of an extra target: the lab's reading, the runs' noise, the
    surrogate and its prediction at the recommended point, and the validation runs' readings."""
    m, sd = e.model.predict(np.asarray(x_best, dtype=float)[None, :])
    v = e.validation_values[np.isfinite(e.validation_values)]
    return ExtraTarget.from_dict(dict(
        name=e.name, quantity=e.quantity, rig=e.heap.setup.workbook_name, observable=e.observable, unit=e.unit,
        target=e.target, target_sd=e.lab_sd, target_n=e.lab_n, target_var=e.target_var, lab_cov=e.lab_cov,
        run_sd=e.pooled.sd,
        point_means=[float(np.nanmean(x)) if np.isfinite(x).any() else None for x in e.values],
        length_scales=dict(zip(names, e.model.length_scales().tolist())),
        leave_one_out=e.model.leave_one_out(), predicted={"mean": float(m[0]), "sd": float(sd[0])},
        validation={"mean": float(v.mean()) if v.size else None, "sd": float(v.std(ddof=1)) if v.size > 1 else None,
                    "n": int(v.size), "values": e.validation_values.tolist()}), f"extra_targets[{e.quantity}]")


def _predicted(heap, x) -> dict:
    """The rig's surrogate at the point ``x``: mean angle and sd [deg]."""
    m, s = heap.model.predict(np.asarray(x, dtype=float)[None, :])
    return {"mean_deg": float(m[0]), "sd_deg": float(s[0])}


def _heap_sections(heap, names, config) -> dict:
    """A rig's noise study, design runs and surrogate, as ``results.json`` holds them."""
    design = heap.design
    design_pooled = pooled_noise([p["responses"] for p in design if p["stage"] != "noise"]) \
        if sum(p["stage"] != "noise" for p in design) else None
    noise = {"centre": heap.centre_noise.to_dict(), "design": design_pooled.to_dict() if design_pooled else None,
             "all_points": heap.pooled.to_dict(), "seed_correlation": heap.correlation.to_dict(),
             "replicates": heap.k, "replicates_rule": ("set by --replicates" if config.replicates else
                                                       "fewest k >= 2 with run SD / sqrt(k) <= 3 x tolerance, at most 4"),
             "pairs": heap.pair}
    return {
        "noise": noise,
        "design": {"points": [{"stage": p["stage"], "settings": dict(zip(names, p["x"].tolist())),
                               "responses": p["responses"].tolist(), "mean": float(p["responses"].mean()),
                               "seeds": p["seeds"], "runs": p["runs"]} for p in design],
                   "replicates": heap.k, "initial_points": int(heap.n0), "batch": config.batch,
                   "budget_runs": config.budget_runs, "rounds": heap.rounds, "stopped_because": heap.stopped,
                   "refinements": heap.refinements},
        "surrogate": {"kernel": str(heap.model.kernel), "length_scales": dict(zip(names, heap.model.length_scales().tolist())),
                      "leave_one_out": heap.model.leave_one_out(),
                      "noise_model": "pooled" if heap.pooled.constant else "per point, shrunk to pooled"},
    }


def _validate(heap, config, x_best, best, run, run_refs) -> Validation:
    """Fresh runs of the rig at the recommended point, tested for equivalence with its lab angle
    (module docstring, step 6)."""
    val = {"responses": [], "seeds": [], "runs": []}
    target, lab_sd, lab_n, tolerance, pooled = heap.target, heap.lab_sd, heap.lab_n, heap.tolerance, heap.pooled

    def draw(n):
        ss = heap.seeds.take("validation", n)
        (y,), records, (ss,) = run(heap, f"validation {len(val['seeds']) + n}", [x_best], [ss])
        val["responses"] += y.tolist()
        val["seeds"] += ss
        val["runs"] += run_refs(records)
        for e in heap.extras:
            e.validation_values = np.concatenate([e.validation_values, e.read(records)])
        return y

    # the first look comes when the test has 80 % power to decide at the predicted bias (at
    # least validation_first runs, at most the cap); then validation_step more at a time
    predicted = best["predicted"] if heap.index == 0 else _predicted(heap, x_best)["mean_deg"]
    first = runs_for_power(predicted - target, pooled.sd, tolerance, 0.8, lab_sd, lab_n,
                           config.alpha, n_max=config.validation_cap)
    first = max(config.validation_first, first) if first is not None else config.validation_first
    seq = sequential_equivalence(draw, target, lab_sd, lab_n, tolerance, first=first,
                                 step=config.validation_step, cap=config.validation_cap, alpha=config.alpha)
    vdict = seq.to_dict()
    # could this validation have succeeded? its power at the cap for a model exactly on target,
    # at the measured noise; the runs 80 % power would take against this lab target and against
    # an exactly known one; the lab heaps it would take at the cap
    power = tost_power(0.0, pooled.sd, config.validation_cap, tolerance, lab_sd, lab_n, config.alpha)
    needed = runs_for_power(0.0, pooled.sd, tolerance, 0.8, lab_sd, lab_n, config.alpha, n_max=1000)
    needed_exact = runs_for_power(0.0, pooled.sd, tolerance, 0.8, alpha=config.alpha, n_max=1000)
    heaps = lab_heaps_for_power(pooled.sd, config.validation_cap, tolerance, lab_sd) if lab_sd else None
    return Validation(verdict=vdict["verdict"], mean_deg=vdict["mean_deg"], ci95=tuple(vdict["ci95"]),
                      tolerance_deg=tolerance, target_deg=target, n_runs=vdict["n_runs"],
                      detectable_bias_deg=vdict["detectable_bias_deg"], settings=best["values"],
                      power_if_on_target=power, runs_for_power=needed,
                      runs_for_power_exact_target=needed_exact, lab_heaps_for_power=heaps,
                      test=vdict, **val)


def _parameter_table(post, best) -> dict:
    """Per parameter: the recommended value, the 95 % interval, prior and posterior mean and sd,
    their ratio and what the heap says about it."""
    summary = post.summary()
    return {n: ParameterEstimate(value=best["values"][n], ci95=tuple(s["ci95"]), prior_mean=s["prior_mean"],
                                 prior_sd=s["prior_sd"], sd_ratio=s["sd_ratio"], posterior_mean=s["mean"],
                                 posterior_sd=s["sd"], identifiability=s["identifiability"], source=s["source"])
            for n, s in summary.items()}


def _check_band(records, flank_band) -> None:
    """Angles read with another fitting band than the lab's photos are never compared."""
    if flank_band is None:
        return
    for r in records:
        band = (r["result"].get("provenance") or {}).get("options", {}).get("flank_band")
        if band is not None and [round(v, 6) for v in band] != [round(v, 6) for v in flank_band]:
            raise AnalysisError(f"DEM run {r['key']} read its heap with the fitting band {band}, the lab's "
                                f"photos with {flank_band}: angles read differently are not compared; "
                                "delete the run store (runs/) to rerun with the current band")
