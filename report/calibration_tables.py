"""Tables of the plausible workflow (``analyse.plausible``): prior, noise, runs, surrogate, the
parameters consistent with the lab, and the validation by equivalence.

Like every table of the report they are pure functions of the stored results (``Campaign``), so
``demcal audit`` rebuilds them from the replayed analysis and compares cell by cell.
"""

from __future__ import annotations

from demcal.analyse.results import CampaignResult
from demcal.report.tables import Campaign, Table, _results_source, _wall, parameter_label, particle_noun


def _names(r: CampaignResult) -> list[str]:
    return list(r.prior)


def _label(c: Campaign, name: str) -> tuple[str, str]:
    """Readable name and symbol of a contact parameter, in the words of the workbook's particle."""
    return parameter_label(name, _wall(c.measurement), particle_noun(c.measurement))


def _symbols(c: Campaign) -> dict:
    wall = _wall(c.measurement)
    return {n: parameter_label(n, wall)[1] for n in _names(c.results)}


def table_prior(c: Campaign) -> Table:
    """Table P1: the prior, each contact parameter's measured mean and sd."""
    r = c.results
    rows = []
    for name, p in r.prior.items():
        label, symbol = _label(c, name)
        rows.append((label, symbol, p.source, p.mean, p.sd, p.low, p.high))
    return Table("P1", "Prior of the contact parameters: the lab's measured mean and sd of each",
                 ("Parameter", "Symbol", "Measured quantity", "Mean", "SD", "Lowest", "Highest"),
                 ("", "", "", "", "", "", ""), tuple(rows),
                 notes=("A normal of the mean and the SD of single measurements (for the joint calibration, "
                        "those of the twin-implied values of Table P1a), truncated to mean ± 3 SD and to the "
                        "admissible range (lowest, highest): what the lab knows before the heap is used. "
                        "The design spreads over it.",),
                 sources=(_results_source("prior"),),
                 formats=("", "", "", ".4g", ".3g", ".4g", ".4g"))


def table_twins(c: Campaign) -> Table | None:
    """Table P1a: what each lab test's twin says about its parameter (joint calibration)."""
    r = c.results
    twins = r.calibration.twins
    if not twins:
        return None
    rows = []
    for name, t in twins.items():
        label, symbol = _label(c, name)
        used = t.get("informative", True)
        rows.append((label, symbol, t["quantity"], t["rig"], t["trials"], t["measured_mean"], t["measured_sd"],
                     t["mean"] if used else None, t["sd"] if used else None, [t["grid"][0], t["grid"][-1]],
                     "yes" if t["at_edge"] else "no", "yes" if used else "no"))
    keys = [run["key"] for t in twins.values() for run in t["runs"]]
    deaf = tuple(f"{_label(c, n)[0]}: {t['note']}." for n, t in twins.items()
                 if not t.get("informative", True))
    return Table("P1a", "Every lab test's twin: the DEM parameter that reproduces each reading",
                 ("Parameter", "Symbol", "Measured quantity", "Twin", "Trials", "Lab reading", "SD",
                  "Twin-implied value", "SD", "Grid", "At the grid's edge", "Informative"),
                 ("",) * 12, tuple(rows),
                 notes=("The twin of each lab trial (the logged drop height and landing orientation; the "
                        "incline surface and mode) run over a grid of the parameter; the value whose twin "
                        "readings match the lab's on average, and the spread of single readings carried "
                        "through the twin. These are the prior of the joint calibration (Table P1); Poisson's "
                        "ratio has no twin and keeps its measurement. A twin whose reading changes over its "
                        "grid by less than the lab mean's 95 % half-width is uninformative: its parameter "
                        "keeps the measured prior.",) + deaf,
                 sources=({"kind": "runs", "keys": keys}, _results_source("calibration.twins")),
                 formats=("", "", "", "", "d", ".4g", ".3g", ".4g", ".3g", ".3g", "", ""))


def table_joint_vs_heap(c: Campaign) -> Table | None:
    """Table P5a: the joint calibration beside the heap-only one, on the same surrogate."""
    r = c.results
    cal = r.calibration
    heap = cal.heap_only
    if not heap:
        return None
    rows = []
    for name, p in cal.parameters.items():
        h = heap.parameters[name]
        rows.append((_label(c, name)[0], p.value, p.ci95, p.sd_ratio, h.value, h.ci95, h.sd_ratio))
    return Table("P5a", "Joint calibration (every lab test's twin) beside the heap alone",
                 ("Parameter", "Joint: recommended", "Joint: 95 % interval", "Joint: posterior/prior SD",
                  "Heap only: recommended", "Heap only: 95 % interval", "Heap only: posterior/prior SD"),
                 ("", "", "", "", "", "", ""), tuple(rows),
                 notes=("Heap only: the lab's direct readings as the prior (sqrt(h2/h1) as the contact "
                        "restitution, tan of the onset angle as the friction), the same surrogate and target. "
                        "Where the two differ, the lab's reading is not the DEM parameter, and only the joint "
                        "calibration knows it.",),
                 sources=(_results_source("calibration.heap_only"), _results_source("calibration.parameters")),
                 formats=("", ".4g", ".4g", ".2f", ".4g", ".4g", ".2f"))


def table_noise_study(c: Campaign) -> Table:
    """Table P2: the seed-to-seed noise, its constancy and the seed correlation."""
    r = c.results
    n = r.noise
    pairs = n.pairs
    rows = [("Runs at the prior mean (seeds shared with the next row)", " / ".join(f"{a:.4g}" for a in pairs["a_responses"]), None, None),
            ("Runs half a prior SD higher in every parameter", " / ".join(f"{a:.4g}" for a in pairs["b_responses"]), None, None)]
    for label, s in (("SD of one run, these two points", n.centre), ("SD of one run, design points", n.design),
                     ("SD of one run, all points (used)", n.all_points)):
        if s:
            rows.append((f"{label} ({s.points} points, {s.df} df)", s.sd, s.ci95, None))
    allp = n.all_points
    rows.append(("Same variance at every point: Bartlett's p", allp.constant_p, None,
                 "kept" if allp.constant else "rejected: per-point noise"))
    sc = n.seed_correlation
    rows.append((f"Correlation of same-seed runs at the two points ({sc.n} pairs)", sc.r, sc.ci95,
                 "common random numbers would halve the variance of a difference only above 0.5"))
    rows.append(("Runs per design point", n.replicates, None, n.replicates_rule))
    return Table("P2", "Seed-to-seed noise of the simulated angle of repose",
                 ("Item", "Value", "95 % interval", "Note"), ("", "deg", "deg", ""), tuple(rows),
                 notes=("Every run is an independent draw of the heap: a design point's angle is the mean "
                        "of its runs, and the surrogate carries each point's noise over its number of runs.",),
                 sources=({"kind": "runs", "keys": [run["key"] for p in r.design.points[:2] for run in p.runs]},
                          _results_source("noise")),
                 formats=("", ".4g", ".3g", ""))


def table_design_runs(c: Campaign) -> Table:
    """Table P3: every design point, its stage, settings, runs and mean angle."""
    r = c.results
    names = _names(r)
    sym = _symbols(c)
    rows = []
    for i, p in enumerate(r.design.points, 1):
        ys = p.responses
        sd = (sum((y - p.mean) ** 2 for y in ys) / (len(ys) - 1)) ** 0.5 if len(ys) > 1 else None
        rows.append((i, p.stage, *[p.settings[n] for n in names], len(ys), p.mean, sd))
    d = r.design
    return Table("P3", "Design points: noise pair, space-filling design, sequential rounds, and runs at "
                 "the recommended point",
                 ("#", "Stage", *[sym[n] for n in names], "Runs", "Mean angle", "Run SD"),
                 ("", "", *[""] * len(names), "", "deg", "deg"), tuple(rows),
                 notes=(f"{d.initial_points} points of a Latin hypercube through the prior's quantiles, then "
                        f"rounds of {d.batch} points where it was least certain whether the mean angle equals "
                        f"the target (at most {d.budget_runs} runs of design and rounds); stopped: "
                        f"{d.stopped_because}. Every run has its own seed (runs.csv, Table A2).",),
                 sources=({"kind": "runs", "keys": [run["key"] for p in d.points for run in p.runs]},
                          _results_source("design.points")),
                 formats=("d", "", *[".3g"] * len(names), "d", ".4g", ".3g"))


def table_surrogate(c: Campaign) -> Table:
    """Table P4: the surrogate's length scales and its leave-one-out check."""
    r = c.results
    s = r.surrogate
    sym = _symbols(c)
    rows = [(f"Length scale, {sym[n]}", v, "fraction of the prior range: large = the angle hardly depends on it")
            for n, v in s.length_scales.items()]
    loo = s.leave_one_out
    rows.append(("Leave-one-out RMSE of a point's mean angle", loo["rmse"], "deg"))
    rows.append(("Share of points within 2 predicted SD (leave-one-out)", loo["share_within_2"], "about 0.95 when the surrogate and its noise are right"))
    rows.append(("Noise model", s.noise_model, ""))
    return Table("P4", "Surrogate of the mean angle: Gaussian process with per-point noise",
                 ("Item", "Value", "Note"), ("", "", ""), tuple(rows),
                 notes=(f"Kernel {s.kernel}.",),
                 sources=(_results_source("surrogate"),), formats=("", ".3g", ""))


def table_identifiability(c: Campaign) -> Table:
    """Table P5: what the heap identifies: per parameter the 95 % interval, the ratio of
    posterior to prior SD and the recommended value."""
    r = c.results
    cal = r.calibration
    rows = []
    for name, p in cal.parameters.items():
        label, symbol = _label(c, name)
        rows.append((label, symbol, p.prior_mean, p.prior_sd, p.posterior_mean, p.ci95, p.sd_ratio,
                     p.identifiability, p.value))
    rec = cal.recommended
    pl = cal.plausible
    return Table("P5", "Calibrated parameters: the set consistent with the measured angle of repose",
                 ("Parameter", "Symbol", "Prior mean", "Prior SD", "Posterior mean", "95 % interval",
                  "Posterior/prior SD", "The heap", "Recommended"),
                 ("", "", "", "", "", "", "", "", ""), tuple(rows),
                 notes=(f"Posterior of the prior (Table P1) given the lab's angle {cal.target_deg:.4g}° "
                        f"(SD of its mean {cal.target_var ** 0.5:.3g}°), by importance sampling on the "
                        f"surrogate (effective sample size {cal.ess:.0f}). A ratio near 1: the heap does not "
                        "identify the parameter; its value then rests on its own measurement.",
                        f"Recommended point: the {rec.chosen}; predicted mean angle {rec.predicted:.4g} ± "
                        f"{rec.predicted_sd:.2g}° (surrogate SD), implausibility {rec.implausibility:.2g}. "
                        f"{100 * pl['share_of_prior']:.0f} % of the prior is plausible (implausibility < {pl['cut']:g}).",),
                 sources=(_results_source("calibration"),),
                 formats=("", "", ".4g", ".3g", ".4g", ".4g", ".2f", "", ".4g"))


def table_by_rig(c: Campaign) -> Table | None:
    """Table P5b: with several repose rigs, what each rig's heap says alone beside all together."""
    r = c.results
    cal = r.calibration
    if not cal.by_rig:
        return None
    rigs = list(cal.by_rig)
    heads = [g if g.endswith(" only") else f"{g} alone" for g in rigs]
    rows = []
    for name, p in cal.parameters.items():
        alone = [cal.by_rig[g][name]["sd_ratio"] for g in rigs]
        rows.append((_label(c, name)[0], *alone, p.sd_ratio, min(alone) - p.sd_ratio,
                     *[cal.by_rig[g][name]["ci95"] for g in rigs], p.ci95))
    return Table("P5b", "What each repose rig says: posterior/prior SD with each rig's heap alone and with all together",
                 ("Parameter", *heads, "All together", "Narrowed by combining",
                  *[f"95 % interval, {h}" for h in heads], "95 % interval, together"),
                 ("",) * (2 * len(rigs) + 4), tuple(rows),
                 notes=("Each rig alone: the posterior of the same prior given that rig's angle of repose, on "
                        "that rig's own surrogate; together: given every rig's (Table P5). Narrowed by combining: "
                        "the better single rig's posterior/prior SD minus the combined one; a parameter neither "
                        "rig pins down alone can be pinned down by two rigs whose angles depend on it in other "
                        "combinations with the rest. With extra targets (Table P8) a rig alone is its angle and "
                        "its extra targets; 'angle only' is the first rig's angle by itself.",),
                 sources=(_results_source("calibration.by_rig"), _results_source("calibration.parameters")),
                 formats=("", *[".2f"] * len(rigs), ".2f", "+.2f", *[".4g"] * (len(rigs) + 1)))


def table_other_rigs(c: Campaign) -> Table | None:
    """Table P7: with several repose rigs, each further rig's target, noise, runs and surrogate."""
    r = c.results
    if not r.other_rigs:
        return None
    rows = []
    for o in r.other_rigs:
        runs = sum(len(p.responses) for p in o.design.points)
        loo = o.surrogate.leave_one_out
        rows.append((o.workbook_name, o.target_deg, o.target_sd_deg, o.target_n, o.noise.all_points.sd,
                     o.noise.replicates, len(o.design.points), runs, loo["rmse"], o.predicted["mean_deg"],
                     o.predicted["sd_deg"], o.validation.verdict))
    keys = [run["key"] for o in r.other_rigs for p in o.design.points for run in p.runs]
    return Table("P7", "The further repose rigs: their lab angles, noise, design runs and surrogates",
                 ("Rig", "Lab angle", "SD of one heap", "Heaps", "SD of one run", "Runs per point",
                  "Design points", "Runs", "Leave-one-out RMSE", "Predicted at the recommended point", "SD",
                  "Validation"),
                 ("", "deg", "deg", "", "deg", "", "", "", "deg", "deg", "deg", ""), tuple(rows),
                 notes=("Each further rig's heaps were run at the same noise pair and design as the first rig's "
                        "(Tables P2, P3), with seeds of their own, then in rounds where its own surrogate was "
                        "least certain; its validation is in the table after P6 named by the rig.",),
                 sources=({"kind": "runs", "keys": keys}, _results_source("other_rigs")),
                 formats=("", ".4g", ".3g", "d", ".3g", "d", "d", "d", ".3g", ".4g", ".2g", ""))


def table_extra_targets(c: Campaign) -> Table | None:
    """Table P8: the rigs' other readings fitted beside the angles (asked for: off by default)."""
    r = c.results
    if not r.extra_targets:
        return None
    rows = []
    for e in r.extra_targets:
        v = e.validation
        rows.append((e.quantity, e.rig, e.observable, e.target, e.target_sd, e.target_n, e.run_sd,
                     e.leave_one_out["rmse"], e.predicted["mean"], e.predicted["sd"], v["mean"], v["n"]))
    kinds = tuple(dict.fromkeys(e.unit for e in r.extra_targets))
    u = kinds[0] if len(kinds) == 1 else ""
    return Table("P8", "Extra targets: the heaps' other readings fitted beside the angle",
                 ("Quantity", "Rig", "Twin's reading", "Lab mean", "SD of one heap", "Heaps", "SD of one run",
                  "Leave-one-out RMSE", "Predicted at the recommended point", "SD", "Validation runs' mean",
                  "Validation runs"), ("", "", "", u, u, "", u, u, u, u, u, ""),
                 tuple(rows),
                 notes=("Asked for with --target (off by default). The lab's reading comes from the same photos as "
                        "the angle (the crest height of the smoothed heap boundary above the floor line, times the "
                        "photo's scale_mm_per_px); the twin's from each run's rendered side view, read the same way. "
                        "Each has its own surrogate over the rig's design points, and its likelihood joins the "
                        "angles' (Table P5b).",),
                 sources=(_results_source("extra_targets"),),
                 formats=("", "", "", ".4g", ".3g", "d", ".3g", ".3g", ".4g", ".2g", ".4g", "d"))


def table_equivalence(c: Campaign) -> Table:
    """Table P6: the validation, an equivalence test with the lab that can fail."""
    return _equivalence(c, c.results.validation, "P6", "Validation at the recommended point: equivalence with "
                        "the lab (two one-sided tests)", "validation")


def tables_other_equivalence(c: Campaign) -> list:
    """Tables P6b, P6c...: each further repose rig's validation at the recommended point."""
    return [_equivalence(c, o.validation, f"P6{'bcdefgh'[i]}", f"Validation in the {o.workbook_name} rig: "
                         "equivalence with the lab's angle in that rig", f"other_rigs[{i}].validation")
            for i, o in enumerate(c.results.other_rigs or ())]


def _equivalence(c: Campaign, v, tid: str, title: str, path: str) -> Table:
    """An equivalence table of the validation ``v`` (stored at ``path`` in results.json)."""
    r = c.results
    t = v.test
    rows = [(f"Look after {look['n_runs']} runs", look["verdict"], look["difference_ci90"], look["p_tost"])
            for look in t["looks"]]
    rows += [("Simulated mean angle (95 % CI)", v.mean_deg, v.ci95, None),
             ("Lab target (SD of one heap, heaps)", v.target_deg, None,
              None if t.get("target_sd_deg") is None else t["target_sd_deg"]),
             ("Difference simulated - lab", t["difference_deg"], t["difference_ci90"], t["p_tost"]),
             ("Tolerance", v.tolerance_deg, None, None),
             ("Smallest bias detected with 80 % power", v.detectable_bias_deg, None, None),
             (f"Power to show equivalence with {r.config['validation_cap']} runs if exactly on target",
              v.power_if_on_target, None, None),
             ("Runs that would give 80 % power (this lab target; an exact one)",
              [v.runs_for_power, v.runs_for_power_exact_target], None, None),
             (f"Lab heaps that would give 80 % power with {r.config['validation_cap']} runs",
              v.lab_heaps_for_power, None, None),
             ("Verdict", v.verdict, None, None)]
    return Table(tid, title,
                 ("Item", "Value", "Interval", "p (TOST) / SD"), ("", "deg", "deg", ""), tuple(rows),
                 notes=(t["note"],
                        "Equivalent: the interval of the difference lies within ± tolerance; different: it lies "
                        "entirely beyond it; otherwise undecided. Runs are added until the verdict is decided "
                        "or the cap is reached. The power rows say whether this validation could have "
                        "shown equivalence at all (none: not within 1000 runs, or 50 heaps)."),
                 sources=({"kind": "runs", "keys": [run["key"] for run in v.runs]}, _results_source(path)),
                 formats=("", ".4g", ".4g", ".3g"))


#: Tables of the plausible workflow, in report order (a builder returning None has nothing to
#: show for this campaign, e.g. the twins of a heap-only calibration).
PLAUSIBLE_TABLES = (table_prior, table_twins, table_noise_study, table_design_runs, table_surrogate,
                    table_identifiability, table_joint_vs_heap, table_by_rig, table_extra_targets,
                    table_equivalence, tables_other_equivalence, table_other_rigs)
