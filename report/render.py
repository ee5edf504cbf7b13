"""Render a campaign's stored results as a report laid out like the source paper.

``build_report(DIR)`` reads ``DIR/results.json`` (with the measurement), the run records in
``DIR/runs/`` and, when present, ``DIR/critique.json``; writes the tables to
``DIR/tables.json``, every DEM run to ``DIR/runs.csv``, the figures to ``DIR/figures/``, then
renders ``DIR/report.html`` (jinja2; figures embedded as data URIs, no network resource, system
fonts only) and ``DIR/report.pdf`` (weasyprint, A4) from those tables. Nothing is computed that
the campaign did not store: the text and tables print stored numbers, the figures draw them.

``preflight(measurement)`` renders the parts that rest on the workbook alone before the DEM
campaign starts, so that workbook text the report cannot render costs no DEM run.
"""

from __future__ import annotations

import base64
import html
import math
import re
import tempfile
from pathlib import Path

import jinja2
from markupsafe import Markup

from demcal.analyse.results import CampaignResult
from demcal.errors import DemcalError, InputError
from demcal.jsonio import read_json, write_json
from demcal.provenance import sha256_file
from demcal.report.figures import DPI, FIGURES, figure_record, make_figures
from demcal.report.runs_csv import RUNS_CSV, write_runs_csv
from demcal.report.tables import (SIZES, Campaign, build_tables, instrument, load_campaign, load_paper, paper_material,
                                  parameter_label, particle_noun, quantity_label, tables_document,
                                  POWER_FILE, POWER_NAME)
from demcal.text import one_line

HERE = Path(__file__).resolve().parent

#: References cited by the methods and the analysis (short key -> full reference).
REFERENCES = {
    "paper": "Calibration and experimentation of discrete meta-simulation parameters of Astragalus "
             "membranaceus (the source paper; Plackett-Burman, steepest climb and Box-Behnken "
             "calibration of the angle of repose in EDEM 2018 with Design-Expert 11).",
    "Plackett 1946": "Plackett, R. L. & Burman, J. P. (1946). The design of optimum multifactorial "
                     "experiments. Biometrika 33(4), 305-325.",
    "Box 1960": "Box, G. E. P. & Behnken, D. W. (1960). Some new three level designs for the study "
                "of quantitative variables. Technometrics 2(4), 455-475.",
    "Myers 2009": "Myers, R. H., Montgomery, D. C. & Anderson-Cook, C. M. (2009). Response Surface "
                  "Methodology, 3rd ed. Wiley.",
    "Lenth 1989": "Lenth, R. V. (1989). Quick and easy analysis of unreplicated factorials. "
                  "Technometrics 31(4), 469-473.",
    "Student 1908": "Student (1908). The probable error of a mean. Biometrika 6(1), 1-25.",
    "Mohsenin 1986": "Mohsenin, N. N. (1986). Physical Properties of Plant and Animal Materials, "
                     "2nd ed. Gordon and Breach.",
    "Dai 2021": "Dai, N., Hou, Z., Qiu, Y., et al. (2021). Calibration and testing of discrete "
                "meta-simulation parameters for red clover seeds. J. Hebei Agric. Univ. 44(06), 92-98.",
    "Zhang 2018": "Zhang, T., Liu, F., Zhao, M., et al. (2018). Determination of physical parameters "
                  "of corn stover contact and calibration by discrete element simulation. J. China "
                  "Agric. Univ. 23(4), 120-127.",
    "Ma 2020": "Ma, Y., Song, C., Xuan, C., et al. (2020). Parameter calibration of discrete element "
               "model for alfalfa straw compression simulation. J. Agric. Eng. 36(11), 22-30.",
    "Iglewicz 1993": "Iglewicz, B. & Hoaglin, D. C. (1993). How to Detect and Handle Outliers. ASQC "
                     "Quality Press.",
    "Stat-Ease": "Stat-Ease (2018). Design-Expert 11 user's guide: ANOVA, fit statistics (Adeq "
                 "Precision, PRESS) and Pareto chart.",
}


# ----------------------------------------------------------------------------------------------
# cell formatting (presentation only)

def _sci(x: float, spec: str) -> str:
    text = format(x, spec)
    m = re.fullmatch(r"(-?[\d.]+)e([+-])0*(\d+)", text)
    if not m:
        return text
    exp = ("-" if m.group(2) == "-" else "") + m.group(3)
    return f"{m.group(1)}×10<sup>{exp}</sup>"


def format_cell(value, fmt: str = "") -> Markup:
    """One table cell as HTML (escaped here; marked safe because this code builds its markup)."""
    return Markup(_cell_html(value, fmt))


def _cell_html(value, fmt: str) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "–"
    if isinstance(value, list):
        return "[" + ", ".join(_cell_html(v, fmt) for v in value) + "]"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, str):
        return html.escape(value)
    if isinstance(value, dict):
        return html.escape(", ".join(f"{k}: {v}" for k, v in value.items()))
    if fmt == "coded":
        return f"{value:+d}" if isinstance(value, int) and value else str(int(value))
    if fmt == "p":
        return "&lt; 0.0001" if value < 1e-4 else f"{value:.4f}"
    if fmt == "d" and float(value).is_integer():
        return str(int(value))
    if isinstance(value, int) and not fmt.endswith("e"):
        return str(value)
    spec = fmt if fmt and fmt not in ("mono", "d") else ".4g"
    return _sci(float(value), spec)


def format_unit(unit: str) -> str:
    """A unit as text (plain: the template escapes it)."""
    return unit.replace("^2", "²").replace("^3", "³")


#: Run keys printed under a table; the rest are in runs.csv.
MAX_KEYS_SHOWN = 24


def describe_sources(sources) -> list[str]:
    """The ``sources`` of a table as short lines of plain text."""
    lines, seen = [], set()
    workbook: dict = {}
    files, runs = [], []
    for s in sources:
        kind = s.get("kind")
        if kind == "workbook":
            key = (s.get("file"), s.get("sha256"))
            where = f"sheet {s.get('sheet')}"
            if s.get("rows"):
                where += f" rows {s['rows']}"
            if s.get("keys"):
                where += " keys " + ", ".join(s["keys"])
            if s.get("path"):
                where = s["path"]
            workbook.setdefault(key, [])
            if where not in workbook[key]:
                workbook[key].append(where)
        elif kind == "file":
            if s.get("file") not in seen:
                seen.add(s.get("file"))
                files.append(f"{Path(s['file']).name} ({(s.get('sha256') or '?')[:16]})")
        elif kind == "runs":
            runs += [k for k in s.get("keys", []) if k not in runs]
        elif kind == "results":
            lines.append(f"{s['file']}: {s['path']}")
        elif kind in ("reference", "critique"):
            lines.append(f"{Path(s['file']).name}: {s.get('path', '')} (SHA-256 {s.get('sha256')})")
    out = [f"{Path(f).name if f else '?'} (SHA-256 {sha}): {'; '.join(w)}" for (f, sha), w in workbook.items()]
    if files:
        out.append("files read by those rows (SHA-256, first 16 hex digits; all in Table A1): "
                   + ", ".join(files))
    if runs:
        # a long list of keys says nothing to a reader: runs.csv lists every run with its stage
        shown = runs if len(runs) <= MAX_KEYS_SHOWN else runs[:MAX_KEYS_SHOWN]
        out.append(f"{len(runs)} DEM run record(s), runs/<key>.json (each in runs.csv): "
                   + ", ".join(k[:10] for k in shown)
                   + (f", ... ({len(runs) - len(shown)} more in runs.csv)" if len(shown) < len(runs) else ""))
    return out + lines


# ----------------------------------------------------------------------------------------------
# text

def _f(x, spec=".4g") -> str:
    return "–" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, spec)


def _signed_terms(coefs: dict, names: dict) -> str:
    scale = max(abs(v) for v in coefs.values()) if coefs else 1.0
    parts = []
    for term, b in coefs.items():
        b = 0.0 if abs(b) < 1e-12 * max(scale, 1.0) else b
        name = "" if term == "Intercept" else names.get(term, term)
        mag = format(abs(b), ".4g")
        if not parts:
            parts.append(("-" if b < 0 else "") + mag + (f" {name}" if name else ""))
        else:
            parts.append(("− " if b < 0 else "+ ") + mag + (f" {name}" if name else ""))
    return " ".join(parts)


def equations(c: Campaign) -> dict:
    """The fitted model as equations in coded and actual terms, and the paper's eq. (5)."""
    r = c.results
    fit = r.box_behnken.fit
    wall = str(c.measurement.get("meta", {}).get("contact_material", "steel")).lower()
    codes = fit.factors
    symbol = {code: parameter_label(r.factors[letter]["parameter"], wall)[1]
              for code, letter in codes.items()}

    def coded_name(term):
        return term.replace("^2", "²")

    def actual_name(term):
        if term.endswith("^2"):
            return f"{symbol[term[0]]}²"
        return "·".join(symbol[ch] for ch in term)

    coded, actual = fit.coefficients, fit.coefficients_actual
    out = {"coded": "θ = " + _signed_terms(coded, {t: coded_name(t) for t in coded}),
           "actual": "θ = " + _signed_terms(actual, {t: actual_name(t) for t in actual if t != "Intercept"}),
           "codes": ", ".join(f"{code} = {symbol[code]} (screening factor {letter})"
                              for code, letter in codes.items())}
    pc = (c.paper.get("regression") or {}).get("coefficients")
    if pc:
        out["paper"] = "θ = " + _signed_terms(pc, {t: coded_name(t) for t in pc})
        pf = (c.paper.get("regression") or {}).get("factors", {})
        out["paper_codes"] = ", ".join(f"{k} = {v}" for k, v in pf.items())
    return out


def _runner_text(r: CampaignResult) -> tuple[str, bool]:
    runner = r.runner
    if runner is None:
        return "The DEM runner of this campaign is not recorded in results.json.", True
    # Campaigns stored before the demcal namespace name the runner without the prefix; the
    # first ones ran their heaps by analyse.campaign.repose_runner.
    if runner.removeprefix("demcal.") in ("analyse.campaign.campaign_runner",
                                          "analyse.campaign.repose_runner"):
        from demcal.simulate.rigs import repose_rig_named

        return ("Every DEM run was made by demcal's own DEM (numba; Hertz-Mindlin contacts, "
                "constant-torque rolling friction, multi-sphere clumps) on its twin of the lab's "
                f"repose test ({repose_rig_named(r.repose_rig).lab_test}); the paper used EDEM 2018."), False
    return (f"The DEM runs of this campaign were made by {runner}, not by demcal's repose rig: the "
            "numbers below exercise the analysis, they are not a DEM calibration of the material."), True


def particle_model(base: dict) -> str:
    """The DEM particle of a campaign's base parameters (``DEMParameters.to_dict``, stored
    results of any version) in words."""
    from demcal.simulate.params import DEMParameters

    return DEMParameters.from_names(base).shape.describe()


def _specimens(quantities: dict) -> int:
    """How many specimens were measured with callipers."""
    return next((quantities[n].get("n", 0) for n in SIZES if n in quantities), 0)


def calliper_text(measurement: dict) -> str:
    """The calliper quantities the specimens sheet gives, in words ("length and diameter")."""
    q = measurement.get("quantities", {})
    words = [quantity_label(n).lower() for n in SIZES if n in q]
    if len(words) < 2:
        return "".join(words) or "the sizes"
    return ", ".join(words[:-1]) + " and " + words[-1]


def differences(c: Campaign) -> list[str]:
    """Where this campaign's procedure differs from the paper's, from the stored settings."""
    if c.results.workflow == "plausible":
        return differences_plausible(c)
    r, m, p = c.results, c.measurement, c.paper
    cfg = r.config
    q = m["quantities"]
    own, noun, nouns = paper_material(c), particle_noun(m), particle_noun(m, plural=True)
    out = [_runner_text(r)[0]]
    sim = p.get("simulation", {})
    if cfg.get("profile") != "paper":
        out.append(f"Repose rig profile '{cfg.get('profile')}', not the paper-fidelity case "
                   f"(profile 'paper': {sim.get('segments', 500)} {nouns} generated in the first "
                   f"{sim.get('generation_time_s', 1):g} s, plate withdrawn at "
                   f"{sim.get('plate_withdrawn_at_s', 4):g} s, {sim.get('total_time_s', 10):g} s in all).")
    base = r.base_parameters
    if base:
        seg = p.get("segment", {}) if own else {}
        paper = (f"; the paper: {seg['spheres_per_clump']} spheres of {seg['sphere_radius_mm']:g} mm radius"
                 if {"spheres_per_clump", "sphere_radius_mm"} <= set(seg) else "")
        out.append(f"Particle model: {particle_model(base)} (from the measured means), mass model "
                   f"'{base.get('mass_model')}', rolling-friction lever '{base.get('rolling_lever')}'{paper}.")
    rep = q.get("repose_angle_deg", {})
    if (rep.get("extra") or {}).get("override"):
        out.append(f"Target angle {rep['value']:.4g}° from the workbook's meta target_repose_deg "
                   "(overrides the photos).")
    else:
        paper_angle = (f"{(p.get('measured', {}).get('repose_angle_deg') or {}).get('value', 35.79)}°"
                       if own else "angles")
        out.append(f"Target angle {rep.get('value', float('nan')):.4g}° from {rep.get('n')} heap photo(s) "
                   f"by demcal's photo estimator ({rep.get('method')}); the paper's "
                   f"{paper_angle} came from Matlab binarisation and Origin 2018 digitising.")
    pr = q.get("poisson_ratio", {})
    if pr:
        out.append(f"Poisson's ratio: {pr.get('extra', {}).get('used', 'normalised strains')} is used; the "
                   "paper's eq. (1) (absolute changes) is shown beside it in Table 2.")
    for name, e in q.items():
        n_track = (e.get("extra") or {}).get("n_from_track")
        if name.startswith("restitution.") and n_track:
            out.append(f"{name}: {n_track} drop(s) take restitution from the camera track velocities "
                       "(free-flight fits), the others from heights (paper eq. 4).")
    out.append("Screening levels: " + ("the measured minimum and maximum, as the paper."
                                       if cfg.get("levels") == "minmax"
                                       else "measured mean -+ one SD (the paper used min/max)."))
    n = r.noise
    out.append(f"Seed-to-seed noise, not measured by the paper: the screening centre run with "
               f"{len(n.seeds)} seeds (SD {_f(n.sd, '.3g')}°) and the Box-Behnken "
               f"centre points with different seeds (SD {_f(n.bbd_centre_sd, '.3g')}°).")
    flagged = r.significant.flagged
    paper_sig = p.get("screening", {}).get("significant", [])
    if paper_sig and sorted(flagged) != sorted(paper_sig):
        out.append(f"Significant factors: {', '.join(flagged) or 'none'} here, "
                   f"{', '.join(paper_sig)} in the paper.")
    if r.significant.note:
        out.append("Factors carried forward: " + r.significant.note + ".")
    out.append(f"Steepest climb with {cfg.get('climb_levels')} levels in equal steps across the measured "
               f"range of each significant factor; level {r.steepest_climb.result.best_level} was best "
               "(the paper's number of levels is not in its text; it used its level 4).")
    out.append("The regression models the simulated angle itself (as the paper's eq. 5 does; its text "
               "speaks of the relative error).")
    out.append("Optimisation: every setting whose predicted angle equals the target ties, so several "
               "are listed (Table 10) and the one closest to the measured means is preferred; "
               "Design-Expert returned one.")
    out.append(f"Validation with seeds {', '.join(str(s) for s in cfg.get('validation_seeds', []))} "
               "(the paper repeated its validation three times).")
    meta = m.get("meta", {})
    if meta.get("particle_shear_modulus_pa") not in (None, ""):
        out.append(f"{noun.capitalize()} shear modulus {float(meta['particle_shear_modulus_pa']):.3g} Pa from the "
                   "workbook meta (not stated in the paper).")
    return out


def abstract(c: Campaign) -> dict:
    """Key numbers for the abstract and the conclusions (stored values, formatted)."""
    if c.results.workflow == "plausible":
        return abstract_plausible(c)
    r, m, p = c.results, c.measurement, c.paper
    q = m["quantities"]
    wall = str(m.get("meta", {}).get("contact_material", "steel")).lower()
    rep = q.get("repose_angle_deg", {})
    fit = r.box_behnken.fit.fit
    val = r.validation.result
    settings = r.validation.settings
    chosen = r.box_behnken.factors
    noun = particle_noun(m)
    cal = ", ".join(f"{parameter_label(r.factors[f]['parameter'], wall, noun)[0].lower()} "
                    f"{settings[r.factors[f]['parameter']]:.3g}" for f in chosen)
    pv = p.get("validation", {}) if paper_material(c) else {}
    pf = (p.get("regression") or {}).get("fit", {})
    sizes = " × ".join(f"{_f(q[n].get('value'))} mm" for n in SIZES if n in q)
    text = (f"The physical and contact parameters of {m.get('material')} were measured "
            f"({_specimens(q)} {particle_noun(m, plural=True)} measured with callipers: {sizes}). "
            f"The angle of repose of the heap, {_f(rep.get('value'), '.4g')}° "
            f"(n = {rep.get('n')}), is the calibration target. A Plackett-Burman test of the seven "
            f"contact parameters found {', '.join(r.significant.flagged) or 'no factor'} significant; "
            f"a steepest climb and a Box-Behnken test of {', '.join(chosen)} gave a quadratic model with "
            f"R² = {fit.r2:.4f}, adjusted R² = {fit.adj_r2:.4f}, Adeq Precision = "
            f"{fit.adeq_precision:.4g} and C.V. = {fit.cv_pct:.3g} %. Optimised to the measured angle, "
            f"the calibrated parameters are {cal}. Simulated with them over {val['n']} seeds the angle "
            f"is {val['mean']:.4g}°, a relative error of {val['relative_error_pct']:.3g} % to the "
            "measured angle.")
    paper = ""
    if pv:
        paper = (f"The source paper reported {pv.get('target_deg')}° measured, R² {pf.get('r2')}, "
                 f"adjusted R² {pf.get('adj_r2')}, Adeq Precision {pf.get('adeq_precision')}, "
                 f"C.V. {pf.get('cv_pct')} %, calibrated e_pp 0.32, e_pw 0.36, μs_pw 0.22, and "
                 f"{pv.get('mean_deg')}° in validation ({pv.get('relative_error_pct')} %).")
    return {"text": text, "paper": paper}


def abstract_plausible(c: Campaign) -> dict:
    """The abstract of a plausible-workflow campaign (stored values, formatted)."""
    r, m = c.results, c.measurement
    q = m["quantities"]
    wall = str(m.get("meta", {}).get("contact_material", "steel")).lower()
    rep = q.get("repose_angle_deg", {})
    cal, v, noise = r.calibration, r.validation, r.noise
    noun = particle_noun(m)

    def names(kind):
        return [parameter_label(n, wall, noun)[0].lower() for n, p in cal.parameters.items()
                if p.identifiability == kind]

    ident, partly, not_ident = names("identified"), names("partly identified"), names("not identified")
    runs = sum(len(p.runs) for p in r.design.points)
    # the lab readings the twins translate into other DEM values (beyond a reading's spread)
    moved = [f"{parameter_label(n, wall, noun)[0].lower()} {t['mean']:.3g} where the lab reads {t['measured_mean']:.3g}"
             for n, t in cal.twins.items()
             if t.get("informative", True) and abs(t["mean"] - t["measured_mean"]) > t["measured_sd"]]
    twins = (" The twins of the drop and incline tests put " + "; ".join(moved)
             + ": the lab's reading is not the DEM's parameter there." if moved else "")
    deaf = [f"{parameter_label(n, wall, noun)[0].lower()} ({t['note']})" for n, t in cal.twins.items()
            if not t.get("informative", True)]
    if deaf:
        twins += " Uninformative twins, not used: " + "; ".join(deaf) + "."
    text = (f"The physical and contact parameters of {m.get('material')} were measured "
            f"({_specimens(q)} {particle_noun(m, plural=True)} measured with callipers; the DEM particle: "
            f"{particle_model(r.base_parameters)}). "
            f"The angle of repose of the heap, {_f(rep.get('value'), '.4g')}° (n = {rep.get('n')}), is the "
            f"calibration target. One simulated heap scatters by {noise.all_points.sd:.2g}° (SD) from "
            f"seed to seed, so the calibration ran {runs} independent heaps over the measured range of the "
            f"seven contact parameters, modelled their mean angle with a Gaussian process that carries the "
            f"noise, and reports the parameters consistent with the measured angle.{twins} "
            + (f"The heap identifies {', '.join(ident)}; " if ident else "The heap identifies no parameter alone; ")
            + (f"it narrows {', '.join(partly)}; " if partly else "")
            + (f"it does not identify {', '.join(not_ident)}, whose values rest on their own "
               "measurements. " if not_ident else "")
            + f"At the recommended point the mean angle is predicted at {cal.recommended.predicted:.4g} ± "
            f"{cal.recommended.predicted_sd:.2g}°. Validated with {v.n_runs} fresh heaps, the mean is "
            f"{v.mean_deg:.4g}° against the measured {v.target_deg:.4g}°: {v.verdict} at a tolerance "
            f"of {v.tolerance_deg:.3g}° (the validation would detect a bias of {v.detectable_bias_deg:.2g}°).")
    return {"text": text, "paper": ""}


def differences_plausible(c: Campaign) -> list[str]:
    """Where the plausible workflow differs from the paper's procedure."""
    r = c.results
    out = [_runner_text(r)[0]]
    cfg = r.config
    if cfg.get("profile") != "paper":
        out.append(f"Repose rig profile '{cfg.get('profile')}', not the paper-fidelity case.")
    out.append("No Plackett-Burman screening, steepest climb or Box-Behnken design: with a simulated "
               f"angle that scatters by {r.noise.all_points.sd:.2g}° from seed to seed, effects of the "
               "size being screened are not distinguishable run by run. All runs feed one surrogate "
               "instead (--profile paper keeps the paper's procedure and its Tables 3-9).")
    out.append("Every run has its own seed; a design point's angle is the mean of "
               f"{r.noise.replicates} runs; the paper ran each point once.")
    out.append("The answer is a set of parameters with intervals, not one optimum; the recommended point "
               f"is the {r.calibration.recommended.chosen}.")
    out.append("Validation by an equivalence test at a stated tolerance, with runs added until decided, "
               "instead of the relative error of three runs.")
    return out


def time_step_text(c: Campaign) -> str:
    """The bulk rigs' time step in words: its value, its fraction of the Rayleigh time of the
    smallest sphere and where it came from, and how many runs the damped limit divided into
    sub-steps (``simulate.timestep``). Empty without base parameters."""
    from demcal.simulate.params import DEMParameters
    from demcal.simulate.timestep import (RESTITUTION_FLOOR, lowest_safe_restitution, material_rayleigh_time,
                                          smallest_radius, stated_time_step)

    r = c.results
    if r is None or not r.base_parameters:
        return ""
    base = DEMParameters.from_names(r.base_parameters)
    t_r = material_rayleigh_time(base)
    dt = stated_time_step(base)
    origin = ("as the workbook states (meta time_step_s)" if base.dt is not None
              else "following the material")
    text = (f"The time step is {dt:.4g} s, {dt / t_r:.3f} of the Rayleigh time ({t_r:.4g} s) of the smallest "
            f"sphere ({smallest_radius(base) * 1e3:.3g} mm radius) at the particles' shear modulus, {origin}.")
    e_safe = lowest_safe_restitution(dt / t_r)
    if e_safe <= RESTITUTION_FLOOR:
        return text + " It is below the stability limit of a contact at any restitution."
    bulk = [rec for rec in c.runs.values() if rec.get("inputs", {}).get("rig") != "drop"]
    # a heap rig records its step in the result's meta, the incline twin in the result itself
    ran_at = [(rec.get("result") or {}).get("meta", {}).get("dt", (rec.get("result") or {}).get("dt", dt))
              for rec in bulk]
    divided = [step for step in ran_at if step < dt * (1 - 1e-9)]
    return text + (f" A contact whose restitution is below {e_safe:.3g} damps too hard for that step to be stable "
                   f"(its tangential dashpot); {len(divided)} of the {len(bulk)} runs of the bulk rigs met one "
                   "and ran in equal sub-steps below the limit.")


def rig_text(c: Campaign) -> str:
    """The repose rig of the campaign (its results, else the workbook meta) in words."""
    from demcal.simulate.rigs import ReposeSetup, repose_rig_named, repose_setup

    nouns = particle_noun(c.measurement, plural=True)
    r = c.results
    try:
        if r is not None and r.geometry:
            setup = ReposeSetup(repose_rig_named(r.repose_rig).name, r.geometry)
        else:
            setup = repose_setup(c.measurement.get("meta", {}))
        text = setup.describe(nouns)
        text = text[0].upper() + text[1:] + " (workbook meta)"
        for o in (r.other_rigs or ()) if r is not None else ():
            other = ReposeSetup(repose_rig_named(o.workbook_name).name, o.geometry).describe(nouns)
            text += f"; and {other} (the {o.workbook_name} rig's photos)"
    except (DemcalError, TypeError):
        text = "The rig's dimensions come from the workbook meta"
    profile = r.config.get("profile") if r else None
    return text + (f"; rig profile '{profile}'." if profile else ".")


def provenance(c: Campaign) -> dict:
    r = c.results
    prov = r.provenance
    code = prov.code
    mp = c.measurement.get("provenance", {})
    return {"created": prov.created, "demcal": code.get("demcal"), "git_sha": code.get("git_sha"),
            "python": code.get("python"), "platform": code.get("platform"), "seed": prov.seed,
            "options": prov.options, "runner": r.runner,
            "wall_s": r.wall_s, "measure_options": mp.get("options", {}),
            "workbook": c.measurement.get("workbook", {}).get("source"),
            "stages": r.stages}


# ----------------------------------------------------------------------------------------------
# critique text (critique.json's own sentences and numbers; nothing recomputed)

#: Observable of a drop-twin row of critique.json's discrepancies (``analyse.critique.loop``).
_DROP_TWIN = re.compile(r"^(restitution\.(\S+)) \(drop twin, apparent")
#: The verdict loop.py writes into the note of a simulated drop-twin row.
_DIRECT_VERDICT = re.compile(r"sqrt\(h2/h1\) (may not|may) feed the DEM directly|"
                             r"whether sqrt\(h2/h1\) may feed the DEM directly is undetermined")


def _g(x) -> str:
    return "–" if not isinstance(x, (int, float)) or isinstance(x, bool) or x != x else f"{x:.3g}"


def _ci(ci) -> str:
    return f"[{_g(ci[0])}, {_g(ci[1])}]" if isinstance(ci, (list, tuple)) and len(ci) == 2 else ""


def _extension_sentence(e) -> str:
    lo, hi = e.ci95
    verdict = ("it helps" if lo > 0 else "it makes it worse" if hi < 0 else "no clear gain")
    return (f"Extension {e.name} ({e.mechanism}): {e.measure} of {e.quantity}"
            + (f" on {e.held_out}" if e.held_out else "")
            + f" {_g(e.before)} before, {_g(e.after)} after, gain {_g(e.gain)} "
            f"{_ci(e.ci95)}: {verdict} (Table C3).")


def _direct_headline(d, quantity: str) -> str:
    """One drop-twin row of Table C1 (a ``Discrepancy``) as the answer to "may sqrt(h2/h1) feed
    the DEM directly?"."""
    if d.simulated is None:
        return (f"{quantity}: not assessed; the lab's sqrt(h2/h1) is {_g(d.measured)} "
                f"{_ci(d.measured_ci95)}, the drop twin was {d.note or 'not run'}.")
    m = _DIRECT_VERDICT.search(d.note)
    verdict = m.group(0) if m else "critique.json states no verdict on direct use (too few simulated drops)"
    beyond = {True: "beyond", False: "within"}.get(d.exceeds, "against")
    return (f"{quantity}: {verdict}. The lab's drops give sqrt(h2/h1) = {_g(d.measured)} "
            f"{_ci(d.measured_ci95)} (n {d.n_measured}); the drop twin rebounds with an "
            f"apparent {_g(d.simulated)} {_ci(d.simulated_ci95)} (n {d.n_simulated}): "
            f"measured minus twin {_g(d.difference)}, {beyond} its 95 % uncertainty "
            f"±{_g(d.combined_u95)} (Table C1).")


def critique_text(critique) -> dict:
    """The critique's sentences for the start of its section (``critique``: a ``Critique`` or None).

    ``direct``: per restitution pair with a drop twin, whether sqrt(h2/h1) may feed the DEM
    directly (the twin's apparent restitution against the measured one, from Table C1's row),
    followed by the critique's own conclusions on that pair (its drop statement, the gain of
    each extension of that quantity; an extension the conclusions do not state is stated from
    Table C3). ``summary``: the other conclusions, in their order. Every conclusion appears once.
    """
    if critique is None:
        return {"direct": [], "summary": []}
    summary = [str(x) for x in critique.conclusions]
    used: set = set()
    direct = []
    for d in critique.discrepancies:
        m = _DROP_TWIN.match(d.observable)
        if not m:
            continue
        quantity, pair = m.groups()
        mine = [i for i, s in enumerate(summary) if i not in used and (
            s.startswith(f"{quantity}: ") or s.startswith("Extension ") and f"({quantity})" in s
            or re.match(rf"\w+ \({re.escape(pair)}\) not evaluated", s))]
        used.update(mine)
        paragraphs = [summary[i] for i in mine]
        for e in critique.extensions:
            if e.quantity == quantity and not any(
                    s.startswith(f"Extension {e.name} ({quantity})") for s in paragraphs):
                paragraphs.append(_extension_sentence(e))
        direct.append({"headline": _direct_headline(d, quantity), "paragraphs": paragraphs})
    return {"direct": direct, "summary": [s for i, s in enumerate(summary) if i not in used]}


def marked_rows(table: dict) -> set:
    """Rows (from 0) to print in bold: those whose ``Verdict`` says significant (Table C4)."""
    if "Verdict" not in table["columns"]:
        return set()
    j = table["columns"].index("Verdict")
    return {i for i, row in enumerate(table["rows"]) if str(row[j]).startswith("significant")}


# ----------------------------------------------------------------------------------------------

def _data_uri(path: Path) -> str:
    return "data:image/png;base64," + base64.b64encode(Path(path).read_bytes()).decode("ascii")


def _environment() -> jinja2.Environment:
    # Everything is escaped except what this module builds as markup (cells, the stylesheet).
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(HERE)),
                             autoescape=jinja2.select_autoescape(["html", "html.j2"]),
                             undefined=jinja2.StrictUndefined, trim_blocks=True, lstrip_blocks=True)
    env.filters["cell"] = format_cell
    env.filters["unit"] = format_unit
    env.filters["sources"] = describe_sources
    env.filters["kv"] = lambda d: ", ".join(f"{k} {v}" for k, v in d.items())
    env.globals["fnum"] = _f
    return env


def input_hashes(c: Campaign, out_dir: Path) -> dict:
    """SHA-256 of every file the tables rest on: the workbook's files as the campaign recorded
    them, the paper's numbers, critique.json and each run record (hashed now)."""
    inputs = dict(c.measurement.get("workbook", {}).get("files", {}))
    if c.paper_source:
        inputs[c.paper_source["file"]] = c.paper_source["sha256"]
    if c.critique_source:
        inputs["critique.json"] = c.critique_source["sha256"]
        inputs[POWER_NAME] = sha256_file(POWER_FILE)
    for key in c.runs:
        inputs[f"runs/{key}.json"] = sha256_file(out_dir / "runs" / f"{key}.json")
    return inputs


def render_html(c: Campaign, tables: list[dict], figures: list) -> str:
    """The report as one HTML document (figures embedded, no external resource).

    Without ``c.results`` (a measurement alone, see :func:`preflight`) only what rests on the
    workbook is rendered: the title, the measurements with their tables and heap photos, and
    the input files.
    """
    by_id = {t["id"]: t for t in tables}
    figs = {f.id: {"n": i, "src": _data_uri(f.path), "caption": f.caption} for i, f in enumerate(figures, 1)}
    css = Markup((HERE / "report.css").read_text())
    r = c.results
    context = {
        "material": one_line(c.measurement.get("material", "")), "css": css, "t": by_id, "fig": figs,
        "tables": tables, "rig": rig_text(c), "runner_warn": False,
        "synthetic": c.measurement.get("meta", {}).get("synthetic"),
        "notes": c.measurement.get("notes", []), "critique": c.critique is not None,
        "critique_text": critique_text(c.critique),
        "marked": {t["id"]: marked_rows(t) for t in tables},
        "references": REFERENCES, "results": r,
        "critique_ids": [t["id"] for t in tables if t["id"].startswith("C")],
        "particle_model": particle_model(r.base_parameters) if r is not None and r.base_parameters else "",
        "time_step": time_step_text(c),
        "particle": particle_noun(c.measurement), "particles": particle_noun(c.measurement, plural=True),
        "repose_test": instrument("repose", c.measurement),
        "callipers": calliper_text(c.measurement), "paper_material": paper_material(c),
    }
    if r is not None:
        runner_text, runner_warn = _runner_text(r)
        context.update(abstract=abstract(c), equations=equations(c) if r.workflow != "plausible" else {},
                       differences=differences(c), runner_text=runner_text, runner_warn=runner_warn,
                       provenance=provenance(c))
    return _environment().get_template("report.html.j2").render(**context)


def _write_tables(c: Campaign, out: Path, figures: dict | None = None) -> list[dict]:
    """Write ``runs.csv`` (when the campaign has results) and ``tables.json`` (with the SHA-256
    of every file the tables rest on, of runs.csv and, given their record, of the figures) in
    ``out``; return the tables as written."""
    artefacts = {}
    if c.results is not None:
        artefacts[RUNS_CSV] = sha256_file(write_runs_csv(c, out / RUNS_CSV))
    if figures is not None:
        artefacts[FIGURES] = figures
    write_json(out / "tables.json", tables_document(build_tables(c), input_hashes(c, out), artefacts))
    return read_json(out / "tables.json")["tables"]


def write_tables(out_dir) -> Path:
    """Build every table from the stored results and write ``out_dir/tables.json`` (with the
    SHA-256 of every file they rest on) and ``out_dir/runs.csv``. Returns the path of
    tables.json."""
    out = Path(out_dir)
    _write_tables(load_campaign(out), out)
    return out / "tables.json"


def _render(c: Campaign, out: Path, pdf: bool, dpi: int = DPI) -> tuple[Path, ...]:
    """Write the tables, figures (at ``dpi``), HTML and (``pdf``) PDF of ``c`` in ``out``."""
    figures = make_figures(c, out / "figures", dpi=dpi)
    # rendered from what was written, so the report shows exactly what audit checks
    stored = _write_tables(c, out, figure_record(figures, out, dpi))
    text = render_html(c, stored, figures)
    html_path = out / "report.html"
    html_path.write_text(text, encoding="utf-8")
    if not pdf:
        return (html_path,)
    return html_path, write_pdf(text, out / "report.pdf", base_url=out)


def build_report(out_dir, *, pdf: bool = True) -> tuple[Path, ...]:
    """Write ``tables.json``, ``runs.csv``, ``figures/``, ``report.html`` and ``report.pdf`` in
    ``out_dir``.

    Parameters
    ----------
    out_dir : str or Path
        A campaign directory made by ``demcal calibrate`` (``results.json``, ``runs/``).
    pdf : bool
        Also write the PDF (weasyprint).

    Returns
    -------
    tuple of Path
        ``(report.html, report.pdf)`` (only the HTML when ``pdf`` is False).
    """
    out = Path(out_dir)
    return _render(load_campaign(out), out, pdf)


#: Resolution of the figures :func:`preflight` draws [dots per inch]: it checks their labels,
#: and a coarse raster keeps it quick.
PREFLIGHT_DPI = 30


def preflight(measurement, folder=None) -> None:
    """Render the parts of the report that rest on the workbook alone (its text in the title,
    the measurement tables, the heap photos with their labels), HTML and PDF, into a temporary
    folder, with the code of the final report (the figures at ``PREFLIGHT_DPI``).

    ``demcal calibrate`` calls it between the measurement and the DEM campaign, so that workbook
    text the report cannot render is refused at the start instead of after the campaign.

    Parameters
    ----------
    measurement : measure.pipeline.Measurement
    folder : str or Path, optional
        The campaign folder (where the measure stage wrote the annotated photos).

    Raises
    ------
    InputError
        The report cannot be rendered from this workbook; the message says why, on one line.
    """
    paper, paper_source = load_paper()
    c = Campaign(measurement=measurement.to_dict(), results=None, paper=paper, paper_source=paper_source,
                 folder=None if folder is None else Path(folder))
    with tempfile.TemporaryDirectory(prefix="demcal-preflight-") as tmp:
        try:
            _render(c, Path(tmp), pdf=True, dpi=PREFLIGHT_DPI)
        except Exception as exc:  # whatever breaks the report here would break it after the campaign
            source = measurement.workbook.get("source")
            raise InputError(f"the report cannot be rendered from the workbook {source}: "
                             f"{type(exc).__name__}: {one_line(exc)}") from exc


def write_pdf(text: str, path: Path, base_url) -> Path:
    """Render HTML to an A4 PDF with weasyprint (fonts from the system only)."""
    try:
        import weasyprint
    except ImportError as exc:  # pragma: no cover - weasyprint is a dependency
        raise InputError(f"the PDF needs weasyprint ({exc}); use --no-pdf for the HTML only") from exc
    weasyprint.HTML(string=text, base_url=str(base_url)).write_pdf(str(path))
    return path
