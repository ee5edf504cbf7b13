"""The report's figures, drawn with matplotlib from stored results only.

Each function draws one figure of the paper's kind and writes it as a PNG: the processed heap
photos with their fitted lines (the measure stage's annotated images), the Plackett-Burman
Pareto chart, the response-surface contours of every factor pair (a contour of the stored
polynomial), the steepest-climb relative-error curve, and the simulated heaps of the
validation runs against the photographed one. Nothing is fitted or estimated here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import combinations
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure as _MplFigure
from matplotlib.image import imread

from demcal.analyse.results import CampaignResult, NoiseStudy
from demcal.report.tables import paper_material, parameter_label
from demcal.text import one_line

#: Resolution of every PNG [dots per inch].
DPI = 200

#: Text properties of a label holding workbook text: drawn as typed, never as mathtext (a photo
#: id such as ``heap $\frac$ 1`` is not a formula, and matplotlib would fail to parse it).
PLAIN_TEXT = {"parse_math": False}
#: Longest workbook text in a figure label [characters].
LABEL_CHARS = 40

_BLUE, _RED, _GREY, _GREEN = "#1f4e79", "#b22222", "#7f7f7f", "#2e7d32"


@dataclass(frozen=True)
class Figure:
    """One figure of the report.

    Attributes
    ----------
    id : str
        Short name (``photos``, ``pareto``, ``surfaces``, ``climb``, ``validation``).
    path : Path
        The PNG file.
    caption : str
        Caption without the "Fig. N" label.
    """

    id: str
    path: Path
    caption: str

    def to_dict(self) -> dict:
        return {"id": self.id, "path": str(self.path), "caption": self.caption}


def _new(width_in: float, height_in: float) -> _MplFigure:
    fig = _MplFigure(figsize=(width_in, height_in), layout="constrained")
    fig.set_facecolor("white")
    return fig


def _save(fig: _MplFigure, path: Path, dpi: int) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    # zlib level 1: a photo panel encodes three times faster for a file about 13 % larger
    fig.savefig(path, dpi=dpi, pil_kwargs={"compress_level": 1})
    return path


def _photo(image: Path, width_in: float, dpi: int) -> np.ndarray:
    """The image ``image`` area-averaged down to twice the pixels of the ``width_in`` [in] it
    is drawn across, so that matplotlib does not resample the whole photo at every draw."""
    import cv2

    pixels = imread(image)
    width = int(2 * width_in * dpi)
    if pixels.shape[1] <= width:
        return pixels
    height = max(1, round(pixels.shape[0] * width / pixels.shape[1]))
    return cv2.resize(pixels, (width, height), interpolation=cv2.INTER_AREA)


def workbook_label(text) -> str:
    """Workbook text (a photo id) for a figure label: one line of at most ``LABEL_CHARS``
    characters; draw it with ``PLAIN_TEXT``."""
    return one_line(text, limit=LABEL_CHARS)


def annotated_photos(measurement: dict, folder) -> list[tuple[dict, Path]]:
    """(row, image) of each heap photo the measure stage annotated. The recorded path is relative
    to where the campaign ran, so the image is looked for in the campaign folder's
    ``annotated/`` first: a moved or copied folder keeps its photos."""
    out = []
    for r in measurement.get("per_row", {}).get("repose_angle_deg", []):
        if not r.get("annotated"):
            continue
        recorded = Path(r["annotated"])
        found = [p for p in ([Path(folder) / "annotated" / recorded.name] if folder else []) + [recorded]
                 if p.is_file()]
        if found:
            out.append((r, found[0]))
    return out


def heap_photos(measurement: dict, path: Path, folder=None, *, dpi: int = DPI, draw: bool = True) -> Path | None:
    """The heap photos as processed by the measure stage (boundary, floor and fitted flank lines
    drawn on each), side by side with the angle found. None when no annotated photo exists."""
    rows = annotated_photos(measurement, folder)
    if not rows:
        return None
    n = min(len(rows), 3)
    if not draw:
        return path
    fig = _new(6.8, 2.1 * math.ceil(len(rows) / n) + 0.2)
    axes = fig.subplots(math.ceil(len(rows) / n), n, squeeze=False).ravel()
    for ax, (rec, image) in zip(axes, rows):
        ax.imshow(_photo(image, 6.8 / n, dpi))
        flanks = ", ".join(f"{k} {v:.2f}°" for k, v in (rec.get("flanks") or {}).items() if v is not None)
        used = "" if rec.get("used", True) else " (rejected)"
        ax.set_title(f"{workbook_label(rec.get('id', ''))}: {rec['value']:.2f}°{used}\n{flanks}", fontsize=7,
                     **PLAIN_TEXT)
    for ax in axes:
        ax.set_axis_off()
    return _save(fig, path, dpi)


def pareto_chart(results: CampaignResult, path: Path, *, dpi: int = DPI, draw: bool = True) -> Path | None:
    """Pareto chart of the Plackett-Burman effects: |t| of each factor, sorted, with the
    t-value and Bonferroni limits (Design-Expert's chart)."""
    p = results.plackett_burman.screening.pareto if results.plackett_burman else None
    if not p:
        return None
    names, t, signs = p["names"], np.abs(p["t_values"]), p["signs"]
    if not draw:
        return path
    fig = _new(5.2, 2.6)
    ax = fig.subplots()
    colours = [_RED if s > 0 else _BLUE for s in signs]
    ax.bar(range(len(names)), t, color=colours, width=0.6)
    ax.set_xticks(range(len(names)), names)
    ax.axhline(p["t_limit"], color="k", lw=1, ls="--")
    ax.axhline(p["bonferroni_limit"], color="k", lw=1, ls=":")
    ax.text(len(names) - 0.6, p["t_limit"], f"t limit {p['t_limit']:.3g}", va="bottom", ha="right", fontsize=7)
    ax.text(len(names) - 0.6, p["bonferroni_limit"], f"Bonferroni {p['bonferroni_limit']:.3g}",
            va="bottom", ha="right", fontsize=7)
    ax.set_ylabel("|t| of the effect")
    ax.set_xlabel("factor (red: raises the angle, blue: lowers it)")
    ax.set_ylim(0, max(float(t.max()), p["bonferroni_limit"]) * 1.15)
    for spine in ("top", "right"):
        ax.spines[spine].set_visible(False)
    return _save(fig, path, dpi)


def _term_value(term: str, x: dict) -> np.ndarray | float:
    """Value of one coded model term (``Intercept``, ``A``, ``AB``, ``A^2``) at coded ``x``."""
    if term == "Intercept":
        return 1.0
    if term.endswith("^2"):
        return x[term[0]] ** 2
    out = 1.0
    for ch in term:
        out = out * x[ch]
    return out


def polynomial(coefficients: dict, x: dict):
    """Evaluate a stored coded polynomial ``{term: coefficient}`` at coded ``x`` (arrays)."""
    return sum(b * _term_value(term, x) for term, b in coefficients.items())


def response_surfaces(results: CampaignResult, path: Path, target: float | None = None,
                      labels: dict | None = None, *, dpi: int = DPI, draw: bool = True) -> Path | None:
    """Contours of the fitted quadratic over each pair of Box-Behnken factors, in actual
    units, the remaining factors held at the preferred solution (at their centre when there is
    none), so the preferred solution lies on the drawn target contour. Box-Behnken runs of the
    plane through the centre are marked.

    ``labels`` maps a screening letter to its axis label (e.g. its symbol).
    """
    b = results.box_behnken
    if not b:
        return None
    fit = b.fit
    codes = list(fit.factors)          # coded letters, e.g. A B C
    letters = [fit.factors[c] for c in codes]
    labels = labels or {}
    low, high = np.asarray(b.low, float), np.asarray(b.high, float)
    pairs = list(combinations(range(len(codes)), 2))
    if not pairs:
        return None
    ncol = min(3, len(pairs))
    nrow = math.ceil(len(pairs) / ncol)
    if not draw:
        return path
    fig = _new(2.35 * ncol + 0.3, 2.35 * nrow + 0.2)
    axes = np.atleast_1d(fig.subplots(nrow, ncol, squeeze=False).ravel())
    g = np.linspace(-1.0, 1.0, 81)
    pref = results.optimisation.preferred.coded if results.optimisation else {}
    held = {c: float(pref.get(c, 0.0)) for c in codes}
    design = np.asarray(b.design_coded, float)

    def actual(k, coded):
        return low[k] + (np.asarray(coded) + 1) * (high[k] - low[k]) / 2

    for ax, (i, j) in zip(axes, pairs):
        gi, gj = np.meshgrid(g, g)
        x = {c: np.full_like(gi, held[c]) for c in codes}
        x[codes[i]], x[codes[j]] = gi, gj
        y = polynomial(fit.coefficients, x)
        ai, aj = actual(i, gi), actual(j, gj)
        cf = ax.contourf(ai, aj, y, levels=12, cmap="viridis")
        cs = ax.contour(ai, aj, y, levels=cf.levels, colors="k", linewidths=0.3)
        ax.clabel(cs, cs.levels[::2], fontsize=5, fmt="%.1f")
        if target is not None and np.nanmin(y) < target < np.nanmax(y):
            ax.contour(ai, aj, y, levels=[target], colors=_RED, linewidths=1.2, linestyles="--")
        pts = design[np.all(np.delete(design, [i, j], axis=1) == 0, axis=1)]
        ax.plot(actual(i, pts[:, i]), actual(j, pts[:, j]), "o", ms=3.5, mfc="white", mec="k",
                mew=0.6, clip_on=False, zorder=5)
        if pref:
            ax.plot(actual(i, pref[codes[i]]), actual(j, pref[codes[j]]), "*", ms=8, color=_RED,
                    clip_on=False, zorder=6)
        ax.set_xlabel(f"{codes[i]}: {labels.get(letters[i], letters[i])}", fontsize=7)
        ax.set_ylabel(f"{codes[j]}: {labels.get(letters[j], letters[j])}", fontsize=7)
        ax.tick_params(labelsize=6)
        others = [f"{codes[k]} = {held[codes[k]]:+.2f}" for k in range(len(codes)) if k not in (i, j)]
        ax.set_title("angle [deg]" + (f", {', '.join(others)} (coded)" if others else ""), fontsize=7)
    for ax in axes[len(pairs):]:
        ax.set_axis_off()
    return _save(fig, path, dpi)


def climb_curve(results: CampaignResult, path: Path, *, dpi: int = DPI, draw: bool = True) -> Path | None:
    """Relative error of the simulated angle along the steepest climb, the chosen centre and
    its neighbours marked."""
    sc = results.steepest_climb
    if not sc:
        return None
    err = np.asarray(sc.result.relative_error_pct, float)
    y = np.asarray(sc.response, float)
    lv = np.arange(1, err.size + 1)
    best = int(sc.result.best_level)
    if not draw:
        return path
    fig = _new(5.2, 2.5)
    ax = fig.subplots()
    ax.plot(lv, err, "o-", color=_BLUE, lw=1.2, ms=4, label="relative error")
    ax.plot([best], [err[best - 1]], "o", ms=9, mfc="none", mec=_RED, mew=1.5, label="Box-Behnken centre")
    for k in (best - 1, best + 1):
        if 1 <= k <= err.size:
            ax.axvline(k, color=_GREY, lw=0.8, ls=":")
    ax.set_xlabel("level of the steepest climb")
    ax.set_ylabel("relative error [%]")
    ax.set_xticks(lv)
    ax2 = ax.twinx()
    ax2.plot(lv, y, "s--", color=_GREEN, lw=0.8, ms=3, label="angle")
    ax2.axhline(sc.result.target, color=_GREEN, lw=0.6, ls=":")
    ax2.set_ylabel("simulated angle [deg]", color=_GREEN)
    ax2.tick_params(axis="y", colors=_GREEN)
    ax.legend(loc="upper center", fontsize=7, frameon=False)
    return _save(fig, path, dpi)


def heap_profile(record: dict) -> dict | None:
    """The heap's top profile ``{"x", "z"}`` [m] of a repose run record (``record.profile``
    or ``record.profile_x`` / ``profile_z``), finite points only; None when there is none."""
    rec = (record.get("result") or {}).get("record") or {}
    prof = rec.get("profile") or {}
    x, z = prof.get("x", rec.get("profile_x")), prof.get("z", rec.get("profile_z"))
    if x is None or z is None:
        return None
    x, z = np.asarray(x, dtype=float), np.asarray(z, dtype=float)
    ok = np.isfinite(x) & np.isfinite(z)
    if ok.sum() < 2 or not np.any(z[ok] > 0):
        return None
    return {"x": x[ok], "z": z[ok], "plate_x": (rec.get("geometry") or {}).get("box_length")}


def _flank_midpoint(x: np.ndarray, z: np.ndarray) -> tuple[float, float, int]:
    """Point of the outer flank at half the heap height, and the side (+1: the heap falls
    toward +x). Used only to place the photo's angle line beside the profile."""
    zmax = float(np.max(z))
    side = 1 if z[0] >= z[-1] else -1
    order = np.arange(x.size) if side > 0 else np.arange(x.size)[::-1]
    above = [k for k in order if z[k] >= zmax / 2]
    k = above[-1]
    nxt = order[min(list(order).index(k) + 1, x.size - 1)]
    if z[nxt] == z[k]:
        return float(x[k]), zmax / 2, side
    t = (z[k] - zmax / 2) / (z[k] - z[nxt])
    return float(x[k] + t * (x[nxt] - x[k])), zmax / 2, side


def validation_heaps(results: CampaignResult, runs: dict, measurement: dict, path: Path,
                     paper: dict | None = None, folder=None, *, dpi: int = DPI, draw: bool = True) -> Path | None:
    """Simulated heap profiles of the validation runs against the photographed heap: one
    annotated photo, the profiles with the photo's mean angle drawn through their flank, and
    the simulated angles against the measured one (the paper's values beside)."""
    v = results.validation
    if not v.runs:
        return None
    records = [runs.get(r["key"], {}) for r in v.runs]
    profiles = [heap_profile(rec) for rec in records]
    photo_rows = annotated_photos(measurement, folder)
    target = float(v.result["target"]) if v.result else float(v.target_deg)
    est = measurement.get("quantities", {}).get("repose_angle_deg", {})
    sd = est.get("sd")
    panels = (1 if photo_rows else 0) + (1 if any(profiles) else 0) + 1
    if not draw:
        return path
    fig = _new(6.8, 2.4)
    axes = list(np.atleast_1d(fig.subplots(1, panels, width_ratios=[1.4] * (panels - 1) + [1])))
    if photo_rows:
        ax = axes.pop(0)
        ax.imshow(_photo(photo_rows[0][1], 6.8 * 1.4 / (1.4 * (panels - 1) + 1), dpi))
        ax.set_title(f"photographed heap {workbook_label(photo_rows[0][0].get('id', ''))}", fontsize=7,
                     **PLAIN_TEXT)
        ax.set_axis_off()
    if any(profiles):
        ax = axes.pop(0)
        for k, (prof, run) in enumerate(zip(profiles, v.runs)):
            if not prof:
                continue
            ax.plot(prof["x"] * 1e3, prof["z"] * 1e3, lw=1.1, label=f"seed {run['seed']}")
        first = next(p for p in profiles if p)
        x, z = first["x"] * 1e3, first["z"] * 1e3
        if first["plate_x"]:
            ax.axvline(first["plate_x"] * 1e3, color=_GREY, lw=0.7, ls=":")
        xm, zm, side = _flank_midpoint(x, z)
        for angle, style in [(target, "-")] + ([(target - sd, ":"), (target + sd, ":")]
                                               if sd is not None and math.isfinite(sd) else []):
            run_ = zm / math.tan(math.radians(angle))
            ax.plot([xm - side * run_, xm + side * run_], [2 * zm, 0.0], style, color="k", lw=0.9)
        ax.plot([], [], "-", color="k", lw=0.9, label=f"photos {target:.2f}°" + (f" ± {sd:.2f}" if sd else ""))
        ax.set_aspect("equal", adjustable="box")
        ax.set_ylim(-5, 1.25 * float(np.max(z)) + 5)
        ax.set_xlabel("x [mm]", fontsize=7)
        ax.set_ylabel("height [mm]", fontsize=7)
        ax.tick_params(labelsize=6)
        ax.legend(fontsize=6, frameon=False)
        ax.set_title("simulated heap profiles", fontsize=7)
    ax = axes.pop(0)
    ys = np.asarray(v.responses, float)
    ax.plot(np.arange(1, ys.size + 1), ys, "o", color=_BLUE, label="ours")
    ax.axhline(target, color=_BLUE, lw=0.9, label=f"measured {target:.2f}°")
    if sd is not None and math.isfinite(sd):
        ax.axhspan(target - sd, target + sd, color=_BLUE, alpha=0.12, lw=0)
    paper = (paper or {}).get("validation", {})
    if paper.get("runs_deg"):
        pr = np.asarray(paper["runs_deg"], float)
        ax.plot(np.arange(1, pr.size + 1) + 0.15, pr, "^", mfc="none", color=_RED, label="paper")
        ax.axhline(paper["target_deg"], color=_RED, lw=0.8, ls="--", label=f"paper {paper['target_deg']:.2f}°")
    ax.set_xticks(np.arange(1, ys.size + 1))
    ax.set_xlabel("validation run", fontsize=7)
    ax.set_ylabel("angle of repose [deg]", fontsize=7)
    ax.tick_params(labelsize=6)
    ax.legend(fontsize=6, frameon=False)
    return _save(fig, path, dpi)


def noise_panels(results: CampaignResult, path: Path, *, dpi: int = DPI, draw: bool = True) -> Path | None:
    """Plausible workflow: the same-seed pairs of the noise measurement, and every design
    point's runs around its mean against the pooled noise."""
    n = results.noise
    if not isinstance(n, NoiseStudy):
        return None
    pairs = n.pairs
    if not draw:
        return path
    fig = _new(6.4, 2.5)
    ax1, ax2 = fig.subplots(1, 2)
    a, b = np.asarray(pairs["a_responses"]), np.asarray(pairs["b_responses"])
    ax1.plot(a, b, "o", color=_BLUE, ms=4)
    lo, hi = float(min(a.min(), b.min())) - 1, float(max(a.max(), b.max())) + 1
    ax1.plot([lo, hi], [lo, hi], ":", color=_GREY, lw=0.8)
    ax1.set_title(f"same seed at two nearby points: r = {n.seed_correlation.r:.2f}", fontsize=7)
    ax1.set_xlabel("angle at the prior mean [deg]", fontsize=7)
    ax1.set_ylabel("angle half a prior SD higher [deg]", fontsize=7)
    resid = np.concatenate([np.asarray(p.responses) - p.mean for p in results.design.points
                            if len(p.responses) > 1])
    sd = n.all_points.sd
    ax2.hist(resid, bins=15, density=True, color=_BLUE, alpha=0.5)
    x = np.linspace(-4 * sd, 4 * sd, 200)
    # a run's deviation from its point's mean has variance sd^2 (1 - 1/k)
    k = n.replicates
    s_dev = sd * math.sqrt(1 - 1 / k) if k > 1 else sd
    ax2.plot(x, np.exp(-0.5 * (x / s_dev) ** 2) / (s_dev * math.sqrt(2 * math.pi)), color=_RED, lw=1)
    ax2.set_title(f"runs about their point's mean; pooled run SD {sd:.2f}°", fontsize=7)
    ax2.set_xlabel("deviation [deg]", fontsize=7)
    for ax in (ax1, ax2):
        ax.tick_params(labelsize=6)
    return _save(fig, path, dpi)


def plausible_set(results: CampaignResult, path: Path, labels: dict, panels: int = 4, *,
                  dpi: int = DPI, draw: bool = True) -> Path | None:
    """Plausible workflow: pairwise panels of the ``panels`` parameters the heap narrows most:
    prior samples (grey), the plausible ones (light blue, implausibility < 3), posterior draws
    (blue), the prior mean (+) and the recommended point (red star)."""
    cal = results.calibration
    if not cal:
        return None
    smp = cal.samples
    names = smp["names"]
    order = sorted(names, key=lambda n: cal.parameters[n].sd_ratio)[:panels]
    idx = [names.index(n) for n in order]
    prior = np.asarray(smp["prior"])
    imp = np.asarray(smp["prior_implausibility"])
    post = np.asarray(smp["posterior"])
    rec = cal.recommended.values
    pairs = list(combinations(range(len(order)), 2))
    cols = 3 if len(pairs) > 3 else len(pairs)
    rows = math.ceil(len(pairs) / cols)
    if not draw:
        return path
    fig = _new(6.8, 2.2 * rows)
    axes = np.atleast_1d(fig.subplots(rows, cols)).ravel()
    for ax, (i, j) in zip(axes, pairs):
        a, b = idx[i], idx[j]
        ax.plot(prior[:, a], prior[:, b], ".", color=_GREY, ms=1.5, alpha=0.4)
        keep = imp < cal.plausible["cut"]
        ax.plot(prior[keep, a], prior[keep, b], ".", color="#9ecae1", ms=1.5)
        ax.plot(post[:, a], post[:, b], ".", color=_BLUE, ms=1.2, alpha=0.5)
        ax.plot(cal.parameters[order[i]].prior_mean, cal.parameters[order[j]].prior_mean, "+",
                color="k", ms=8)
        ax.plot(rec[order[i]], rec[order[j]], "*", color=_RED, ms=9)
        ax.set_xlabel(labels.get(order[i], order[i]), fontsize=7)
        ax.set_ylabel(labels.get(order[j], order[j]), fontsize=7)
        ax.tick_params(labelsize=6)
    for ax in axes[len(pairs):]:
        ax.set_axis_off()
    return _save(fig, path, dpi)


def validation_runs(results: CampaignResult, path: Path, *, dpi: int = DPI, draw: bool = True) -> Path | None:
    """Plausible workflow: every validation run, the running mean with the interval of each
    look, the target and the tolerance band."""
    v = results.validation
    if not v.test or not v.responses:
        return None
    ys = np.asarray(v.responses, float)
    target, tol = v.target_deg, v.tolerance_deg
    if not draw:
        return path
    fig = _new(6.0, 2.4)
    ax = fig.subplots()
    ax.plot(np.arange(1, ys.size + 1), ys, "o", color=_BLUE, ms=3, alpha=0.6, label="runs")
    ax.plot(np.arange(1, ys.size + 1), np.cumsum(ys) / np.arange(1, ys.size + 1), "-", color=_BLUE, lw=1,
            label="running mean")
    ax.axhline(target, color="k", lw=0.9, label=f"lab {target:.2f}°")
    ax.axhspan(target - tol, target + tol, color=_GREEN, alpha=0.12, lw=0, label=f"± tolerance {tol:.2g}°")
    for look in v.test["looks"]:
        lo, hi = look["difference_ci90"]
        ax.errorbar(look["n_runs"], target + 0.5 * (lo + hi), yerr=0.5 * (hi - lo), fmt="s", color=_RED,
                    ms=3, capsize=2, lw=0.9)
    ax.plot([], [], "s", color=_RED, ms=3, label="look: interval of the difference")
    ax.set_xlabel("validation run", fontsize=7)
    ax.set_ylabel("angle of repose [deg]", fontsize=7)
    ax.set_title(f"verdict: {v.verdict}", fontsize=7)
    ax.tick_params(labelsize=6)
    ax.legend(fontsize=6, frameon=False, ncol=3)
    return _save(fig, path, dpi)


#: Key of the figures' record in ``tables.json`` ``artefacts`` (:func:`figure_record`).
FIGURES = "figures"


def figure_record(figures: list, out_dir, dpi: int) -> dict:
    """What ``tables.json`` records of the drawn ``figures`` for the audit: the matplotlib
    version and resolution they were drawn with, and each PNG's SHA-256 by its path relative to
    ``out_dir``. Drawn again with the same version and resolution, a figure gives the same bytes."""
    import matplotlib

    from demcal.provenance import sha256_file

    return {"matplotlib": matplotlib.__version__, "dpi": int(dpi),
            "sha256": {f.path.relative_to(out_dir).as_posix(): sha256_file(f.path) for f in figures}}


def make_figures(campaign, fig_dir, *, dpi: int = DPI, draw: bool = True) -> list[Figure]:
    """Draw every figure the stored results allow into ``fig_dir`` at ``dpi``; return them in
    order. With ``draw`` False nothing is drawn: the figures are those that would be, at the
    paths they would be written to (the audit renders the report again with its own PNGs)."""
    fig_dir = Path(fig_dir)
    m, r = campaign.measurement, campaign.results
    target = r.target_angle_deg if r else None
    out = []

    def add(fid, path, caption):
        if path is not None:
            out.append(Figure(fid, path, caption))

    add("photos", heap_photos(m, fig_dir / "heap_photos.png", campaign.folder, dpi=dpi, draw=draw),
        "Image processing of the heap photos: heap boundary, floor line and the straight line fitted "
        "to each measured flank (measure stage, annotated images).")
    wall = str(m.get("meta", {}).get("contact_material", "steel")).lower()
    if r and r.workflow == "plausible":
        labels = {n: parameter_label(n, wall)[1] for n in r.prior}
        add("noise", noise_panels(r, fig_dir / "noise.png", dpi=dpi, draw=draw),
            "Seed-to-seed noise: runs with the same seed at two nearby points (dotted: equal angles), "
            "and every design point's runs about their mean with the pooled noise (red).")
        add("plausible", plausible_set(r, fig_dir / "plausible_set.png", labels, dpi=dpi, draw=draw),
            "The plausible set for the parameters the heap narrows most: prior samples (grey), those "
            "not ruled out by the measured angle (light blue, implausibility < 3), posterior draws "
            "(blue), the measured means (+) and the recommended point (red star).")
        add("validation", validation_runs(r, fig_dir / "validation.png", dpi=dpi, draw=draw),
            "Validation: every run at the recommended point, their running mean, and at each look the "
            "interval of the difference from the lab (red), against the lab's angle and the "
            "equivalence tolerance (green).")
    elif r:
        add("pareto", pareto_chart(r, fig_dir / "pareto.png", dpi=dpi, draw=draw),
            "Pareto chart of the Plackett-Burman effects (|t| of each factor; dashed: t limit at "
            "p = 0.05, dotted: Bonferroni limit).")
        add("climb", climb_curve(r, fig_dir / "steepest_climb.png", dpi=dpi, draw=draw),
            "Steepest climb: relative error between simulated and measured angle at each level "
            "(circle: the Box-Behnken centre, dotted: its -1/+1 neighbours).")
        labels = {f: parameter_label(v["parameter"], wall)[1] for f, v in r.factors.items()}
        add("surfaces", response_surfaces(r, fig_dir / "response_surfaces.png", target, labels, dpi=dpi, draw=draw),
            "Response surfaces of the fitted quadratic model for each factor pair, the remaining "
            "factor held at the preferred solution (dashed red: the measured angle; star: the "
            "preferred solution; circles: Box-Behnken runs of the plane through the centre).")
        # the paper's validation heaps are of its own material only
        paper = campaign.paper if paper_material(campaign) else None
        add("validation", validation_heaps(r, campaign.runs, m, fig_dir / "validation.png", paper,
                                           campaign.folder, dpi=dpi, draw=draw),
            "Validation: the photographed heap, the simulated heap profiles of the validation runs "
            "with the photos' mean angle (± SD, dotted) drawn through their flank (grey dotted: the "
            "carton's end plate, when recorded), and the "
            "simulated angles against the measured one (shaded: ± SD of the photos).")
    return out
