"""The report's tables, built from a campaign's stored results and nothing else.

Tables 1-9 are those of the source paper (dimensions; basic physical parameters; Plackett-Burman
levels, design and results, ANOVA; steepest climb; Box-Behnken levels, design and results,
ANOVA); the others show what the paper printed only in its text (regression coefficients, fit
statistics, calibrated values, validation), what demcal adds (methods, seed-to-seed noise,
optimisation solutions, critique) and the provenance appendix.

:func:`build_tables` is a pure function of a :class:`Campaign`: ``demcal report`` feeds it the
stored results and writes the tables to ``DIR/tables.json``; ``demcal audit`` feeds it the
workbook measured again and the analysis replayed from the run store, and compares. Every
table carries its ``sources`` (workbook file, sheet, rows and SHA-256; run keys; the path of
the numbers in ``results.json``; the reference file of the paper's values).

Cells hold numbers in the unit of their column (SI or the unit named in the workbook column),
text, or None for "not available"; the ``formats`` only say how to print them.
"""

from __future__ import annotations

import json
import math
import statistics
from dataclasses import dataclass, field
from pathlib import Path

from demcal.analyse.critique.diagnosis import TIER_SHARES
from demcal.analyse.critique.loop import Critique, load_critique
from demcal.analyse.results import CampaignResult, Validation, read_campaign_results
from demcal.errors import DemcalError, InputError
from demcal.jsonio import read_json, to_jsonable
from demcal.provenance import sha256_file

#: Files that ship with demcal (``data/``), named in reports as ``demcal:data/<file>``: the same
#: on every install, so that a report audits on another machine (:func:`shipped_file`).
DATA_DIR = Path(__file__).resolve().parents[1] / "data"
SHIPPED_PREFIX = "demcal:data/"
#: The source paper's printed numbers (its text; its Tables 1-9 are not available).
PAPER_FILE = DATA_DIR / "paper_defaults.json"
PAPER_NAME = SHIPPED_PREFIX + PAPER_FILE.name
#: What the critique finds at a lab's sample size (benchmarks/critique_power.md, as numbers).
POWER_FILE = DATA_DIR / "critique_power.json"
POWER_NAME = SHIPPED_PREFIX + POWER_FILE.name


def shipped_file(name: str) -> Path | None:
    """The file a ``demcal:data/<file>`` name stands for on this install (None for another name)."""
    return DATA_DIR / name[len(SHIPPED_PREFIX):] if name.startswith(SHIPPED_PREFIX) else None

#: The paper's significance note, printed under both ANOVA tables.
SIGNIFICANCE_NOTE = ("Note: 0.01<P<0.05, significant effect (*); P<0.01, highly significant "
                     "effect (**); P>0.05, no significant effect.")

_MARK = {"highly significant": "**", "significant": "*"}

#: Instrument behind each workbook sheet (docs/workbook.md; the paper's in brackets).
INSTRUMENTS = {
    "specimens": "digital vernier callipers and electronic balance",
    "density": "measuring cylinder, liquid displacement",
    "drop": "free-fall drop onto a plate; rebound read on a grid or from a high-speed camera "
            "track (paper: high-speed camera and TEMA)",
    "incline": "tilting-plane inclinometer (paper: CNY-1)",
    "compression": "texture analyser, compression to about 30 % (paper: 5 mm/s)",
    "meta": "given in the workbook meta sheet",
}

_PARAMETERS = {
    "poisson_ratio": ("Poisson's ratio of the {particle}", "ν"),
    "e_pp": ("Restitution coefficient, {particle}-{particle}", "e_pp"),
    "e_pw": ("Restitution coefficient, {particle}-{wall}", "e_pw"),
    "mu_s_pp": ("Static friction coefficient, {particle}-{particle}", "μs_pp"),
    "mu_s_pw": ("Static friction coefficient, {particle}-{wall}", "μs_pw"),
    "mu_r_pp": ("Rolling friction coefficient, {particle}-{particle}", "μr_pp"),
    "mu_r_pw": ("Rolling friction coefficient, {particle}-{wall}", "μr_pw"),
}

#: The calliper quantities of the specimens sheet (whichever the shape uses), in table order.
SIZES = ("length_mm", "diameter_mm", "width_mm", "thickness_mm")

_RUN_STAGES = (("Plackett-Burman", "plackett_burman"), ("noise", "noise"),
               ("steepest climb", "steepest_climb"), ("Box-Behnken", "box_behnken"),
               ("validation", "validation"))


@dataclass(frozen=True)
class Table:
    """One table of the report, as stored in ``tables.json``.

    Attributes
    ----------
    id : str
        ``"1"`` ... ``"9"`` for the paper's tables, ``"2a"``, ``"9a"``, ``"10"``, ``"C1"``,
        ``"A1"``... for the others.
    title : str
        Caption, without the "Table N" label.
    columns : tuple of str
        Column headings.
    units : tuple of str
        Unit of each column (``""`` dimensionless or text; ``"row"``: in the row's unit column).
    rows : tuple of tuple
        Cells: float, int, str, None (not available) or a list of those.
    notes : tuple of str
        Printed under the table.
    sources : tuple of dict
        Where the cells come from: ``{"kind": "workbook", "file", "sha256", "sheet", "rows"}``,
        ``{"kind": "file", "file", "sha256"}`` (photos, tracks, curves),
        ``{"kind": "runs", "keys"}``, ``{"kind": "results", "file", "path"}``,
        ``{"kind": "reference", "file", "sha256", "path"}``, ``{"kind": "critique", ...}``.
    formats : tuple of str
        How to print each column: a format spec (``".4g"``), ``"p"`` (p-value), ``"coded"``,
        ``"mono"`` (hashes, keys) or ``""`` (as is).
    """

    id: str
    title: str
    columns: tuple
    units: tuple
    rows: tuple
    notes: tuple = ()
    sources: tuple = ()
    formats: tuple = ()

    def __post_init__(self):
        n = len(self.columns)
        if len(self.units) != n or (self.formats and len(self.formats) != n):
            raise ValueError(f"table {self.id}: columns, units and formats differ in length")
        for i, row in enumerate(self.rows):
            if len(row) != n:
                raise ValueError(f"table {self.id}: row {i + 1} has {len(row)} cells, expected {n}")

    @property
    def label(self) -> str:
        return f"Table {self.id}"

    def to_dict(self) -> dict:
        """JSON layout of one entry of ``tables.json``."""
        return to_jsonable({"id": self.id, "title": self.title, "columns": list(self.columns),
                            "units": list(self.units), "rows": [list(r) for r in self.rows],
                            "notes": list(self.notes), "sources": list(self.sources),
                            "formats": list(self.formats or ("",) * len(self.columns))})

    @classmethod
    def from_dict(cls, d: dict) -> "Table":
        return cls(id=str(d["id"]), title=d["title"], columns=tuple(d["columns"]),
                   units=tuple(d["units"]), rows=tuple(tuple(r) for r in d["rows"]),
                   notes=tuple(d.get("notes", ())), sources=tuple(d.get("sources", ())),
                   formats=tuple(d.get("formats", ())))


@dataclass(frozen=True)
class Campaign:
    """What the tables are built from.

    Attributes
    ----------
    measurement : dict
        ``measure.pipeline.Measurement.to_dict()`` (stored in ``measure.json``, or measured again).
    results : CampaignResult or None
        ``results.json`` (stored, or replayed by ``analyse.campaign.derive_results``); None when
        the analysis could not be derived: only the measurement tables are built then.
    runs : dict
        Run key -> run record (``analyse.runs`` layout) of every run the results name.
    paper : dict
        The paper's printed numbers (``data/paper_defaults.json``), empty when not available.
    paper_source : dict
        ``{"file", "sha256"}`` of that file (empty when not available).
    critique : analyse.critique.loop.Critique or None
        ``critique.json`` when the critique stage has run.
    critique_source : dict
        ``{"file", "sha256"}`` of ``critique.json`` (empty when absent).
    folder : Path or None
        The campaign folder (where its annotated photos are).
    """

    measurement: dict
    results: CampaignResult | None
    runs: dict = field(default_factory=dict)
    paper: dict = field(default_factory=dict)
    paper_source: dict = field(default_factory=dict)
    critique: Critique | None = None
    critique_source: dict = field(default_factory=dict)
    folder: Path | None = None


def load_paper() -> tuple[dict, dict]:
    """The paper's numbers and ``{"file", "sha256"}`` of their file (empty if it is absent)."""
    if not PAPER_FILE.exists():
        return {}, {}
    return read_json(PAPER_FILE), {"file": PAPER_NAME, "sha256": sha256_file(PAPER_FILE)}


def run_stages(results: CampaignResult) -> list[tuple[str, list]]:
    """(stage, run references) of every stage of the campaign, in campaign order."""
    if results.workflow == "plausible":
        stages: dict = {f"{t['rig']} twins, {name}": t["runs"]
                        for name, t in results.calibration.twins.items()}
        for p in results.design.points:
            stages.setdefault(p.stage, []).extend(p.runs)
        out = list(stages.items()) + [("validation", results.validation.runs)]
        for o in results.other_rigs or ():          # a further repose rig's stages, named by it
            rig_stages: dict = {}
            for p in o.design.points:
                rig_stages.setdefault(f"{p.stage} ({o.workbook_name})", []).extend(p.runs)
            out += list(rig_stages.items()) + [(f"validation ({o.workbook_name})", o.validation.runs)]
    else:
        out = [(stage, _part_runs(results, part)) for stage, part in _RUN_STAGES]
    repoured = results.response.get("repoured_runs")
    if repoured:
        out.append(("unreadable heaps, each poured again", repoured))
    return out


def _part_runs(results: CampaignResult, part: str) -> list:
    """The run references of one part of the paper's procedure (``plackett_burman``, ...)."""
    x = getattr(results, part)
    return [] if x is None else x.runs


def run_keys(results: CampaignResult | None) -> list[str]:
    """Every run key the results name, in campaign order (first occurrence)."""
    return list(dict.fromkeys(r["key"] for _, runs in run_stages(results) for r in runs))


def load_campaign(out_dir) -> Campaign:
    """Read a campaign directory's stored results for the report.

    Raises
    ------
    InputError
        ``results.json`` is missing, or a run record it names is missing from ``runs/``.
    """
    out = Path(out_dir)
    results = read_campaign_results(out)
    measurement = results.measurement or read_json(out / "measure.json")
    runs = {}
    for key in run_keys(results):
        p = out / "runs" / f"{key}.json"
        if not p.exists():
            raise InputError(f"run record {p} named in {out / 'results.json'} is missing")
        runs[key] = read_json(p)
    paper, paper_source = load_paper()
    critique, critique_source = load_critique(out)
    return Campaign(measurement=measurement, results=results, runs=runs, paper=paper,
                    paper_source=paper_source, critique=critique, critique_source=critique_source, folder=out)


# ----------------------------------------------------------------------------------------------
# small helpers

def _wall(measurement: dict) -> str:
    return str(measurement.get("meta", {}).get("contact_material", "steel")).strip().lower() or "steel"


def shape_name(measurement: dict) -> str:
    """The workbook's particle shape (``simulate.shapes`` name): the measurement's ``shape``,
    else its meta ``shape``; ``segment`` for a measurement stored before shapes existed."""
    name = (measurement.get("shape") or {}).get("shape") or measurement.get("meta", {}).get("shape")
    return str(name or "segment").strip().lower() or "segment"


def particle_noun(measurement: dict, plural: bool = False) -> str:
    """The word the report uses for one particle of the workbook: "segment" (the paper's root
    segments), "kernel", or "particle" (spheres, clumps)."""
    noun = {"segment": "segment", "kernel": "kernel"}.get(shape_name(measurement), "particle")
    return noun + "s" if plural else noun


def paper_material(c: "Campaign") -> bool:
    """Whether the workbook's particles are the paper's: segments of the material named in
    ``paper_defaults.json`` (its ``material``, found case-insensitively in the workbook's).
    The paper's measured, calibrated and validation figures are shown only then."""
    name = str(c.paper.get("material", "")).strip().lower()
    return (bool(name) and name in str(c.measurement.get("material", "")).lower()
            and shape_name(c.measurement) == "segment")


def _paper_own(c: "Campaign", *path, default=None):
    """A figure the paper gives for its own material, or ``default`` when the workbook's
    particles are not the paper's (:func:`paper_material`)."""
    return _get(c.paper, *path, default=default) if paper_material(c) else default


def _not_paper_note(c: "Campaign") -> str:
    """Why a Paper column is empty: the paper's figures belong to its material."""
    name = c.paper.get("material")
    return ("Paper: not shown; the paper's figures belong to its own material"
            + (f", {name}," if name else "") + " only.")


def _get(d, *path, default=None):
    for p in path:
        if not isinstance(d, dict) or p not in d:
            return default
        d = d[p]
    return d


def row_ranges(rows) -> str:
    """``[1, 2, 3, 5]`` -> ``"1-3, 5"``."""
    rows = sorted({int(r) for r in rows})
    parts, i = [], 0
    while i < len(rows):
        j = i
        while j + 1 < len(rows) and rows[j + 1] == rows[j] + 1:
            j += 1
        parts.append(str(rows[i]) if i == j else f"{rows[i]}-{rows[j]}")
        i = j + 1
    return ", ".join(parts)


def _files_of(measurement: dict, name: str) -> list[dict]:
    """Photos, tracks and curves the rows of one quantity read, with their SHA-256."""
    root = Path(measurement.get("workbook", {}).get("root", "."))
    hashes = measurement.get("workbook", {}).get("files", {})
    out = []
    for rec in measurement.get("per_row", {}).get(name, []):
        for key in ("file", "track_file", "curve_file"):
            rel = rec.get(key)
            if rel:
                path = str(root / rel)
                out.append({"kind": "file", "file": path, "sha256": hashes.get(path), "row": rec.get("row")})
    return out


def _workbook_source(measurement: dict, name: str) -> list[dict]:
    """Source entries of one measured quantity: sheet and rows, then the files its rows read."""
    est = measurement["quantities"][name]
    src = est.get("source", {})
    rows = list(est.get("rows_used", [])) + [r["row"] for r in est.get("rows_rejected", [])]
    entry = {"kind": "workbook", "quantity": name, "file": src.get("file"), "sha256": src.get("sha256"),
             "sheet": src.get("sheet"), "rows": row_ranges(rows)}
    return [entry] + _files_of(measurement, name)


def _meta_source(measurement: dict, keys) -> dict:
    sheet = _get(measurement, "workbook", "sheets", "meta", default={})
    return {"kind": "workbook", "file": sheet.get("file"), "sha256": sheet.get("sha256"),
            "sheet": "meta", "keys": list(keys)}


def _results_source(path: str) -> dict:
    return {"kind": "results", "file": "results.json", "path": path}


def _reference_source(campaign: Campaign, path: str) -> list[dict]:
    if not campaign.paper_source:
        return []
    return [{"kind": "reference", **campaign.paper_source, "path": path}]


def _runs_source(results: CampaignResult, part: str) -> dict:
    return {"kind": "runs", "keys": [r["key"] for r in _part_runs(results, part)]}


def _replicates(results: CampaignResult, part: str) -> tuple[int, list, list]:
    """Replicates per design point, and per point its runs and its replicate angles (a campaign
    runs each point with several seeds and takes the median, ``analyse.campaign``)."""
    k = int(results.config.get("replicates", 1))
    runs = _part_runs(results, part)
    x = getattr(results, part)
    angles = x.replicate_responses or [[y] for y in (x.responses if isinstance(x, Validation) else x.response)]
    return k, [runs[i:i + k] for i in range(0, len(runs), k)], angles


def _replicate_cells(runs: list, angles: list) -> tuple[str, str]:
    """The replicate angles and their seeds of one design point, as text."""
    return (" / ".join(f"{a:.4g}" for a in angles), " / ".join(str(r["seed"]) for r in runs))


def _replicate_note(k: int) -> str:
    return (f"Each design point was simulated with {k} seeds; its angle is their median (the "
            "replicate angles and seeds are listed). Every run's key is in runs.csv (Table A2)."
            if k > 1 else "Every run's key is in runs.csv (Table A2).")


def _paper_measured(campaign: Campaign, name: str):
    """(value, spread) the paper printed for a measured quantity, or (None, None) (also when the
    workbook's particles are not the paper's)."""
    paper = campaign.paper if paper_material(campaign) else {}
    entry = _get(paper, "measured", name.replace(f"-{_wall(campaign.measurement)}", "-steel")
                 if _wall(campaign.measurement) != "steel" else name)
    if isinstance(entry, dict):
        return entry.get("value"), entry.get("spread")
    return None, None


def parameter_label(parameter: str, wall: str, particle: str = "segment") -> tuple[str, str]:
    """Readable name and symbol of a DEM contact parameter (``particle``: :func:`particle_noun`)."""
    name, symbol = _PARAMETERS.get(parameter, (parameter, parameter))
    return name.format(wall=wall, particle=particle), symbol


def quantity_label(name: str, particle: str = "segment") -> str:
    """Readable name of a measured quantity (docs/workbook.md names; ``particle``:
    :func:`particle_noun`)."""
    fixed = {"length_mm": "Length", "diameter_mm": "Diameter", "width_mm": "Width",
             "thickness_mm": "Thickness", "mass_g": f"Mass of one {particle}",
             "particle_density_kg_m3": "Particle density (liquid displacement)",
             "envelope_density_kg_m3": "Envelope density (callipers and balance)",
             "poisson_ratio": "Poisson's ratio", "elastic_modulus_pa": "Elastic modulus",
             "shear_modulus_pa": "Shear modulus", "repose_angle_deg": "Angle of repose (heap photos)"}
    if name in fixed:
        return fixed[name]
    family, _, what = name.partition(".")
    if family in ("repose_angle_deg", "crest_height_mm"):      # a further repose rig's, or a crest
        words = "Angle of repose" if family == "repose_angle_deg" else "Crest height of the heap"
        return f"{words} ({what + ' ' if what else ''}photos)"
    words = {"restitution": "Restitution coefficient", "static_friction": "Static friction coefficient",
             "rolling_friction": "Rolling friction coefficient"}.get(family, family)
    if family == "restitution":
        return f"{words}, {what.replace('particle', particle)}"
    return f"{words}, {particle}-{particle if what == 'particle' else what}"


_SYMBOLS = {"length_mm": "L", "diameter_mm": "D", "width_mm": "W", "thickness_mm": "T", "mass_g": "m",
            "particle_density_kg_m3": "ρ", "envelope_density_kg_m3": "ρe", "poisson_ratio": "ν",
            "elastic_modulus_pa": "E", "shear_modulus_pa": "G", "repose_angle_deg": "θ", "crest_height_mm": "h",
            "restitution": "e",
            "static_friction": "μs", "rolling_friction": "μr"}


def _symbol(name: str) -> str:
    return _SYMBOLS.get(name, _SYMBOLS.get(name.partition(".")[0], ""))


def _unit(est: dict) -> str:
    unit = est.get("unit", "")
    return "" if unit in ("1", "-") else unit


# ----------------------------------------------------------------------------------------------
# Tables 1, 2, 2a: the measurement

def table_dimensions(c: Campaign) -> Table:
    """Table 1: outer dimensions of the particles (callipers), one row per calliper quantity
    the shape uses; the paper's segment size beside them for the paper's material only."""
    q = c.measurement["quantities"]
    own = paper_material(c)
    rows, sources = [], []
    for name in SIZES:
        if name not in q:
            continue
        e = q[name]
        rows.append((quantity_label(name), _symbol(name), e["n"], e["value"], e["sd"],
                     _get(e, "extra", "min"), _get(e, "extra", "max"), e["ci95"][0], e["ci95"][1],
                     _paper_own(c, "segment", name)))
        sources += _workbook_source(c.measurement, name)
    paper_note = ("Paper: the mean segment size printed in its text (Table 1 of the paper is not "
                  "available)." if own else _not_paper_note(c))
    return Table("1", f"External dimensions of the {particle_noun(c.measurement, plural=True)}",
                 ("Dimension", "Symbol", "n", "Mean", "SD", "Min", "Max", "95 % CI low",
                  "95 % CI high", "Paper"),
                 ("", "", "", "mm", "mm", "mm", "mm", "mm", "mm", "mm"), tuple(rows),
                 notes=("SD with n - 1; 95 % CI of the mean from Student's t. " + paper_note,),
                 sources=tuple(sources + (_reference_source(c, "segment") if own else [])),
                 formats=("", "", "d", ".4g", ".3g", ".4g", ".4g", ".4g", ".4g", ".4g"))


#: Meta keys shown in Table 2: label, symbol, unit, path of the paper's value.
_META_ROWS = (
    ("contact_density_kg_m3", "Density of the {wall} plate", "ρw", "kg/m^3", ("steel", "density_kg_m3")),
    ("contact_poisson", "Poisson's ratio of the {wall} plate", "νw", "", ("steel", "poisson_ratio")),
    ("contact_shear_modulus_pa", "Shear modulus of the {wall} plate", "Gw", "Pa", ("steel", "shear_modulus_pa")),
    ("particle_shear_modulus_pa", "Shear modulus of the {particle} used by the DEM", "G", "Pa", None))


def table_physical(c: Campaign) -> Table:
    """Table 2: basic physical and contact parameters as measured, the paper's beside them."""
    m = c.measurement
    q = m["quantities"]
    wall = _wall(m)
    noun = particle_noun(m)
    rows, sources, notes = [], [], []
    for name, e in q.items():
        if name in SIZES:
            continue
        pv, ps = _paper_measured(c, name)
        if name in ("particle_density_kg_m3", "poisson_ratio"):
            pv = _paper_own(c, "segment", name)
        label = quantity_label(name, noun)
        if _get(e, "extra", "override"):
            label += " (meta target_repose_deg)"
        rows.append((label, _symbol(name), _unit(e), e["n"], e["value"], e["sd"], e["ci95"][0],
                     e["ci95"][1], pv, ps))
        sources += _workbook_source(m, name)
        eq1 = _get(e, "extra", "eq1")
        if name == "poisson_ratio" and isinstance(eq1, dict):
            rows.append(("Poisson's ratio, paper eq. (1) |Δw|/|Δt|", "ν1", "", eq1.get("n"),
                         eq1.get("value"), eq1.get("sd"), eq1["ci95"][0], eq1["ci95"][1], pv, None))
            notes.append(f"Poisson's ratio: the DEM uses {_get(e, 'extra', 'used', default='the normalised strains')}; "
                         "the paper's eq. (1), absolute changes not divided by the original size, "
                         "is shown below it.")
    meta = m.get("meta", {})
    used_keys = []
    for key, label, symbol, unit, paper_path in _META_ROWS:
        if meta.get(key) in (None, ""):
            continue
        used_keys.append(key)
        pv = _get(c.paper, *paper_path) if paper_path and wall == "steel" else None  # paper: steel
        if key == "particle_shear_modulus_pa":
            notes.append(f"The {noun}'s shear modulus is not in the paper's text; the DEM uses "
                         "the workbook's meta value.")
        rows.append((label.format(wall=wall, particle=noun), symbol, unit, None, float(meta[key]), None,
                     None, None, pv, None))
    if used_keys:
        sources.append(_meta_source(m, used_keys))
    own = paper_material(c)
    if own:
        notes.append("Paper: values printed in the paper's text as mean ± spread (its Table 2 is "
                     "not available); the paper does not say whether the spread is an SD or a range.")
    else:
        notes.append(_not_paper_note(c) + (" Its steel plate's figures are shown." if wall == "steel" else ""))
    reference = "measured" if own else "steel" if wall == "steel" else None
    return Table("2", f"Basic physical and contact parameters of the {particle_noun(m, plural=True)} (measured)",
                 ("Parameter", "Symbol", "Unit", "n", "Mean", "SD", "95 % CI low",
                  "95 % CI high", "Paper", "Paper ±"),
                 ("", "", "", "", "row", "row", "row", "row", "row", "row"), tuple(rows),
                 notes=tuple(notes),
                 sources=tuple(sources + (_reference_source(c, reference) if reference else [])),
                 formats=("", "", "", "d", ".4g", ".3g", ".4g", ".4g", ".4g", ".3g"))


def instrument(sheet: str, measurement: dict, quantity: str = "") -> str:
    """The instrument behind a sheet; for the heap photos the repose rig of the quantity (its
    ``.<rig>`` suffix, else the workbook's first)."""
    if sheet == "repose":
        from demcal.simulate.rigs import repose_rig, repose_rig_named
        try:
            named = quantity.partition(".")[2]
            return (repose_rig_named(named) if named else repose_rig(measurement.get("meta", {}))).lab_test
        except DemcalError:
            return "heap, side photograph"
    return INSTRUMENTS.get(sheet, "")


def table_methods(c: Campaign) -> Table:
    """Table 2a: instrument, formula and rows of every measured quantity (the estimates' own
    ``method`` text)."""
    m = c.measurement
    noun = particle_noun(m)
    rows, sources = [], []
    for name, e in m["quantities"].items():
        sheet = _get(e, "source", "sheet", default="")
        rejected = [f"{r['row']}: {r['reason']}" for r in e.get("rows_rejected", [])]
        rows.append((quantity_label(name, noun), sheet, instrument(sheet, m, name), e.get("method", ""),
                     row_ranges(e.get("rows_used", [])), "; ".join(rejected) or "none",
                     _get(e, "extra", "outlier_rule", default="")))
        src = _get(e, "source", default={})
        sources.append({"kind": "workbook", "quantity": name, "file": src.get("file"),
                        "sha256": src.get("sha256"), "sheet": sheet,
                        "rows": row_ranges(list(e.get("rows_used", []))
                                           + [r["row"] for r in e.get("rows_rejected", [])])})
    return Table("2a", "Instruments, formulas and rows of each measured quantity",
                 ("Quantity", "Sheet", "Instrument", "Formula used (reference)", "Rows used",
                  "Rows rejected", "Outlier rule"),
                 ("",) * 7, tuple(rows),
                 notes=("Rows count data rows from 1 under the header of each sheet.",),
                 sources=tuple(sources))


# ----------------------------------------------------------------------------------------------
# Tables 3-5a: Plackett-Burman screening

def table_pb_levels(c: Campaign) -> Table:
    """Table 3: the seven contact parameters and their -1/+1 levels."""
    r, m = c.results, c.measurement
    wall = _wall(m)
    rows, sources = [], []
    for letter, f in r.factors.items():
        name, symbol = parameter_label(f["parameter"], wall, particle_noun(m))
        pv, ps = _paper_measured(c, f["quantity"])
        if f["quantity"] == "poisson_ratio":
            pv = _paper_own(c, "segment", "poisson_ratio")
        rows.append((letter, name, symbol, f["low"], f["mean"], f["high"], f["how"], pv, ps))
        if f["quantity"] in m["quantities"]:
            sources += _workbook_source(m, f["quantity"])[:1]
    return Table("3", "Plackett-Burman test: factors and level codes",
                 ("Code", "Parameter", "Symbol", "Low (-1)", "Mean", "High (+1)", "Levels from",
                  "Paper mean", "Paper ±"),
                 ("",) * 9, tuple(rows),
                 notes=("-1/+1 are the measured minimum and maximum of the rows used (as the "
                        "paper) or the mean -+ one SD (levels 'sd'), clipped to the admissible "
                        "range of the parameter. "
                        + ("Paper: measured mean ± spread from its text." if paper_material(c)
                           else _not_paper_note(c)),),
                 sources=tuple(sources + [_results_source("factors")]
                               + (_reference_source(c, "measured") if paper_material(c) else [])),
                 formats=("", "", "", ".4g", ".4g", ".4g", "", ".4g", ".3g"))


def table_pb_design(c: Campaign) -> Table:
    """Table 4: the 12-run Plackett-Burman design (coded) and the simulated angle."""
    pb = c.results.plackett_burman
    cols = list(pb.columns)
    shown = ["d" + col.split("_")[-1] if col.startswith("dummy") else col for col in cols]
    k, point_runs, angles = _replicates(c.results, "plackett_burman")
    rows = []
    for i, (coded, y, runs, ys) in enumerate(zip(pb.design_coded, pb.response, point_runs, angles), 1):
        rows.append((i, *[int(round(v)) for v in coded], y, *_replicate_cells(runs, ys)))
    return Table("4", "Design and results of the Plackett-Burman test",
                 ("Run", *shown, "Angle of repose", "Replicates", "Seeds"),
                 ("", *[""] * len(cols), "deg", "deg", ""), tuple(rows),
                 notes=(f"Columns {', '.join(s for s in shown if s.startswith('d'))} are the unused "
                        "(dummy) columns of the 12-run design; they estimate the error. Actual "
                        "levels in Table 3.", _replicate_note(k)),
                 sources=(_runs_source(c.results, "plackett_burman"),
                          _results_source("plackett_burman.design_coded, plackett_burman.response, "
                                          "plackett_burman.replicate_responses")),
                 formats=("d", *["coded"] * len(cols), ".4g", "", ""))


def _number(value) -> str:
    """A stored number for running text; ``n/a`` when it is missing (JSON null, e.g. Lenth's
    PSE when most contrasts are exactly zero)."""
    return "n/a" if value is None else f"{value:.4g}"


def _anova_rows(anova, effects=None, extra=None):
    rows = []
    for a in anova:
        src = a.source
        row = [src, a.ss, a.df, a.ms, a.f, a.p, _MARK.get(a.significance, "")]
        if effects is not None:
            row += [effects.get(src), (extra or {}).get(src)]
        rows.append(tuple(row))
    return rows


def table_pb_anova(c: Campaign) -> Table:
    """Table 5: Type III ANOVA of the Plackett-Burman test, with effects and contributions."""
    r = c.results
    s = r.plackett_burman.screening
    noise = r.plackett_burman.effects_vs_noise
    rows = []
    for row in _anova_rows(s.anova, s.effects, s.contribution_pct):
        ratio = _get(noise, row[0], "ratio")
        rows.append(row + (ratio,))
    paper_sig = _get(c.paper, "screening", "significant", default=[])
    notes = [SIGNIFICANCE_NOTE,
             f"Significant at p < {s.alpha:g}: {', '.join(s.significant) or 'none'}"
             + (f" (paper: {', '.join(paper_sig)})" if paper_sig else "") + ".",
             "Effect = mean(+1) - mean(-1); contribution = Design-Expert's % of the model sum of "
             "squares; effect/noise = |effect| over the standard error the seed-to-seed noise "
             "alone would give it (Table 5a).",
             f"Lenth's method over all contrasts: PSE {_number(_get(s.lenth, 'pse'))} deg, "
             f"ME {_number(_get(s.lenth, 'me'))} deg, active: "
             f"{', '.join(_get(s.lenth, 'active', default=None) or []) or 'none'}."]
    if r.significant.note:
        notes.append(f"Carried forward: {', '.join(r.significant.carried_forward)} ({r.significant.note}).")
    return Table("5", "Analysis of variance of the Plackett-Burman test",
                 ("Source", "Sum of squares", "df", "Mean square", "F value", "p-value", "Sig.",
                  "Effect", "Contribution", "Effect/noise"),
                 ("", "deg^2", "", "deg^2", "", "", "", "deg", "%", ""), tuple(rows),
                 notes=tuple(notes),
                 sources=(_runs_source(r, "plackett_burman"),
                          _results_source("plackett_burman.screening"))
                 + tuple(_reference_source(c, "screening.significant")),
                 formats=("", ".4g", "d", ".4g", ".4g", "p", "", ".4g", ".3g", ".3g"))


def table_noise(c: Campaign) -> Table:
    """Table 5a: seed-to-seed noise of the DEM at the screening centre."""
    r = c.results
    n = r.noise
    k, point_runs, angles = _replicates(r, "noise")
    cells = [_replicate_cells(runs, ys) for runs, ys in zip(point_runs, angles)]
    rows = [(f"centre point {i}, seeds {seeds}", y, reps)
            for i, ((reps, seeds), y) in enumerate(zip(cells, n.responses), 1)]
    rows.append(("SD between centre points (n - 1)", n.sd, ""))
    if k > 1 and n.sd_single_run is not None:
        rows.append(("SD of a single run (all replicates)", n.sd_single_run, ""))
    se = next(iter(r.plackett_burman.effects_vs_noise.values()), {}).get("se_noise")
    rows.append(("Standard error of a screening effect from that noise", se, ""))
    rows.append(("SD of the Box-Behnken centre points", n.bbd_centre_sd, ""))
    _, bbd_runs, _ = _replicates(r, "box_behnken")
    bbd_keys = [run["key"] for runs, coded in zip(bbd_runs, r.box_behnken.design_coded)
                if not any(coded) for run in runs]
    return Table("5a", "Seed-to-seed noise of the simulated angle of repose",
                 ("Item", "Angle of repose", "Replicates"), ("", "deg", "deg"), tuple(rows),
                 notes=("The screening centre (all factors at the middle of their range) run with "
                        "different seeds; the paper does not measure this noise. A centre point's "
                        "angle is the median of its replicates, like every design point's.",),
                 sources=(_runs_source(r, "noise"), {"kind": "runs", "keys": bbd_keys},
                          _results_source("noise")),
                 formats=("", ".4g", ""))


# ----------------------------------------------------------------------------------------------
# Table 6: steepest climb

def table_climb(c: Campaign) -> Table:
    """Table 6: steepest climb of the significant factors, relative error per level."""
    r = c.results
    sc = r.steepest_climb
    plan, res = sc.plan, sc.result
    stepped = list(plan.stepped)
    best = int(res.best_level)
    mid = int(res.centre_level or best)
    k, point_runs, angles = _replicates(r, "steepest_climb")
    smoothed = res.smoothed
    rows = []
    for i, (lv, y, err, ys) in enumerate(zip(plan.levels, sc.response, res.relative_error_pct,
                                             angles), 1):
        # each factor steps in its own direction: a neighbour is -1 for some factors, +1 for others
        role = {mid: "centre (0)", mid - 1: "-1/+1", mid + 1: "-1/+1"}.get(i, "")
        if i == best != mid:
            role = "best, outside the window"
        fit = (smoothed[i - 1],) if smoothed is not None else ()
        rows.append((i, *[lv[f] for f in stepped], y, " / ".join(f"{a:.4g}" for a in ys), *fit, err, role))
    wall = _wall(c.measurement)
    names = [parameter_label(r.factors[f]["parameter"], wall)[1] for f in stepped]
    fixed = [f for f in plan.factors if f not in stepped]
    paper_lv = _get(c.paper, "screening", "steepest_climb", default={})
    notes = [res.note,
             "Steps: " + ", ".join(f"{f} {'+' if plan.directions[f] > 0 else '-'}{plan.step[f]:.4g}"
                                   for f in stepped)
             + f"; the other factors ({', '.join(fixed)}) at their measured means; relative error "
             f"= |angle - {res.target:.4g}| / {res.target:.4g}."]
    if paper_lv:
        notes.append(f"Paper: level {paper_lv.get('bbd_centre_level')} of its climb was the centre, "
                     f"levels {paper_lv.get('bbd_low_level')} and {paper_lv.get('bbd_high_level')} "
                     "the low and high levels (its Table 6 is not available).")
    if res.at_edge:
        notes.append("The best level is at the edge of the climb: the optimum may lie beyond it.")
    if k > 1:
        notes.append(_replicate_note(k))
    if smoothed is not None:
        notes.append("Monotone fit: the least-squares non-decreasing (or non-increasing) sequence "
                     "through the angles; the best level is the one closest to the target on it, "
                     "so one noisy level cannot move the window (the paper takes the raw angles).")
    fit_col = ("Monotone fit",) if smoothed is not None else ()
    return Table("6", "Design and results of the steepest climb test",
                 ("Level", *[f"{f} ({n})" for f, n in zip(stepped, names)], "Angle of repose",
                  "Replicates", *fit_col, "Relative error", "Box-Behnken"),
                 ("", *[""] * len(stepped), "deg", "deg", *["deg"] * len(fit_col), "%", ""), tuple(rows),
                 notes=tuple(n for n in notes if n),
                 sources=(_runs_source(r, "steepest_climb"), _results_source("steepest_climb"))
                 + tuple(_reference_source(c, "screening.steepest_climb")),
                 formats=("d", *[".4g"] * len(stepped), ".4g", "", *[".4g"] * len(fit_col), ".3g", ""))


# ----------------------------------------------------------------------------------------------
# Tables 7-9b: Box-Behnken

def _bbd_letters(r: CampaignResult) -> list[tuple[str, str]]:
    """(coded letter of the fit, screening letter) pairs, in the fit's order."""
    return list(r.box_behnken.fit.factors.items())


def table_bbd_levels(c: Campaign) -> Table:
    """Table 7: Box-Behnken factors and their -1/0/+1 levels (from the steepest climb)."""
    r = c.results
    b = r.box_behnken
    wall = _wall(c.measurement)
    rows = []
    for j, (code, letter) in enumerate(_bbd_letters(r)):
        name, symbol = parameter_label(r.factors[letter]["parameter"], wall, particle_noun(c.measurement))
        rows.append((code, letter, name, symbol, b.low[j], b.centre[j], b.high[j]))
    fixed = ", ".join(f"{f} = {v:.4g}" for f, v in b.fixed.items())
    return Table("7", "Box-Behnken test: factors and level codes",
                 ("Code", "Screening factor", "Parameter", "Symbol", "Low (-1)", "Centre (0)", "High (+1)"),
                 ("",) * 7, tuple(rows),
                 notes=("Centre = the best level of the steepest climb, -1/+1 = its neighbours "
                        "(clipped to the admissible range). Other factors fixed at their measured "
                        f"means: {fixed}.",),
                 sources=(_results_source("box_behnken.low, box_behnken.centre, box_behnken.high"),
                          _runs_source(r, "steepest_climb")),
                 formats=("", "", "", "", ".4g", ".4g", ".4g"))


def table_bbd_design(c: Campaign) -> Table:
    """Table 8: the 17-run Box-Behnken design, actual levels and simulated angle."""
    r = c.results
    b = r.box_behnken
    letters = _bbd_letters(r)
    k, point_runs, angles = _replicates(r, "box_behnken")
    rows = []
    for i, (coded, actual, y, runs, ys) in enumerate(zip(b.design_coded, b.design_actual,
                                                         b.response, point_runs, angles), 1):
        rows.append((i, *[int(round(v)) for v in coded], *actual, y, *_replicate_cells(runs, ys)))
    return Table("8", "Design and results of the Box-Behnken test",
                 ("Run", *[code for code, _ in letters], *[f"{letter} actual" for _, letter in letters],
                  "Angle of repose", "Replicates", "Seeds"),
                 ("", *[""] * len(letters), *[""] * len(letters), "deg", "deg", ""), tuple(rows),
                 notes=("Centre points (0, 0, 0) are repeated with different seeds; edge runs "
                        "share the design seeds.", _replicate_note(k)),
                 sources=(_runs_source(r, "box_behnken"),
                          _results_source("box_behnken.design_coded, box_behnken.response, "
                                          "box_behnken.replicate_responses")),
                 formats=("d", *["coded"] * len(letters), *[".4g"] * len(letters), ".4g", "", ""))


def table_bbd_anova(c: Campaign) -> Table:
    """Table 9: ANOVA of the quadratic Box-Behnken model (Design-Expert layout)."""
    r = c.results
    fit = r.box_behnken.fit
    key = ", ".join(f"{code} = {letter}" for code, letter in _bbd_letters(r))
    return Table("9", "Analysis of variance of the quadratic regression model (Box-Behnken test)",
                 ("Source", "Sum of squares", "df", "Mean square", "F value", "p-value", "Sig."),
                 ("", "deg^2", "", "deg^2", "", "", ""), tuple(_anova_rows(fit.anova)),
                 notes=(SIGNIFICANCE_NOTE, f"Codes: {key} (Table 7). Fit statistics in Table 9a."),
                 sources=(_runs_source(r, "box_behnken"), _results_source("box_behnken.fit.anova")),
                 formats=("", ".4g", "d", ".4g", ".4g", "p", ""))


def table_fit_statistics(c: Campaign) -> Table:
    """Table 9a: fit statistics beside the paper's."""
    r = c.results
    fit = r.box_behnken.fit
    st = fit.fit
    paper = _get(c.paper, "regression", "fit", default={})
    model_p = getattr(fit.anova_row("Model"), "p", None)
    lof_p = getattr(fit.anova_row("Lack of Fit"), "p", None)
    below = _get(c.paper, "regression", "model_p_below")
    rows = [("Std. Dev.", "deg", st.std_dev, None),
            ("Mean", "deg", st.mean, None),
            ("C.V.", "%", st.cv_pct, paper.get("cv_pct")),
            ("R²", "", st.r2, paper.get("r2")),
            ("Adjusted R²", "", st.adj_r2, paper.get("adj_r2")),
            ("Predicted R²", "", st.pred_r2, None),
            ("PRESS", "deg^2", st.press, None),
            ("Adeq Precision", "", st.adeq_precision, paper.get("adeq_precision")),
            ("Model p-value", "", model_p, None if below is None else f"< {below:g}"),
            ("Lack of fit p-value", "", lof_p, None)]
    return Table("9a", "Fit statistics of the quadratic regression model",
                 ("Statistic", "Unit", "Ours", "Paper"), ("", "", "row", "row"), tuple(rows),
                 notes=("Adeq Precision = (max ŷ - min ŷ) / sqrt(p MSE / n), p counting the "
                        "intercept (Design-Expert). Paper: figures printed in its text.",),
                 sources=(_runs_source(r, "box_behnken"), _results_source("box_behnken.fit.fit"))
                 + tuple(_reference_source(c, "regression.fit")),
                 formats=("", "", ".4g", ".4g"))


def _paper_term(term: str, ours_to_quantity: dict, paper: dict) -> float | None:
    """The paper's eq. (5) coefficient of the same term (matched through the measured quantity)."""
    pf = _get(paper, "regression", "factors", default={})
    pc = _get(paper, "regression", "coefficients", default={})
    if term == "Intercept":
        return pc.get("Intercept")
    q_to_paper = {q: letter for letter, q in pf.items()}
    letters = term.replace("^2", "")
    mapped = [q_to_paper.get(ours_to_quantity.get(ch)) for ch in letters]
    if None in mapped:
        return None
    if term.endswith("^2"):
        return pc.get(f"{mapped[0]}^2")
    return pc.get("".join(sorted(mapped)))


def _actual_term(term: str, code_to_letter: dict) -> str:
    if term == "Intercept":
        return "Intercept"
    if term.endswith("^2"):
        return f"{code_to_letter.get(term[0], term[0])}²"
    return "·".join(code_to_letter.get(ch, ch) for ch in term)


def table_coefficients(c: Campaign) -> Table:
    """Table 9b: regression coefficients in coded and actual terms, eq. (5) of the paper beside."""
    r = c.results
    fit = r.box_behnken.fit
    code_to_letter = dict(_bbd_letters(r))
    wall = _wall(c.measurement)
    to_quantity = {code: r.factors[letter]["quantity"].replace(f"-{wall}", "-steel")
                   .replace(f".{wall}", ".steel") for code, letter in code_to_letter.items()}
    rows = []
    for term, coef in fit.coefficients.items():
        ci = fit.ci95.get(term) or [None, None]
        rows.append((term, _actual_term(term, code_to_letter), coef, fit.std_errors.get(term),
                     ci[0], ci[1], _paper_term(term, to_quantity, c.paper),
                     fit.coefficients_actual.get(term)))
    pf = _get(c.paper, "regression", "factors", default={})
    notes = ["Coded: each factor scaled to -1/+1 over its Box-Behnken range (Table 7); actual: "
             "the factors in their own units (" + ", ".join(
                 f"{letter} = {parameter_label(r.factors[letter]['parameter'], wall)[1]}"
                 for letter in code_to_letter.values()) + ")."]
    if pf:
        notes.append("Paper eq. (5) is matched term by term through the measured quantity of each "
                     "factor (paper: " + ", ".join(f"{k} = {v}" for k, v in pf.items()) + "); its "
                     "coded units span the paper's own ranges, so the coefficients compare in sign "
                     "and size only.")
    return Table("9b", "Regression coefficients of the angle of repose (eq. 5)",
                 ("Term (coded)", "Term (actual)", "Coefficient (coded)", "Std. error", "95 % CI low",
                  "95 % CI high", "Paper eq. (5)", "Coefficient (actual)"),
                 ("", "", "deg", "deg", "deg", "deg", "deg", "deg per unit"), tuple(rows),
                 notes=tuple(notes),
                 sources=(_runs_source(r, "box_behnken"), _results_source("box_behnken.fit.coefficients"))
                 + tuple(_reference_source(c, "regression.coefficients")),
                 formats=("", "", ".4g", ".3g", ".4g", ".4g", ".4g", ".4g"))


# ----------------------------------------------------------------------------------------------
# Tables 10-12: optimisation, calibrated values, validation

def table_solutions(c: Campaign) -> Table:
    """Table 10: settings whose predicted angle equals the target (they all tie)."""
    r = c.results
    o = r.optimisation
    letters = _bbd_letters(r)
    rows = []
    for i, s in enumerate(o.solutions, 1):
        rows.append((i, *[s.coded[code] for code, _ in letters],
                     *[s.actual[letter] for _, letter in letters], s.predicted, s.distance,
                     "preferred" if s == o.preferred else ""))
    return Table("10", "Optimisation to the measured angle of repose: solutions",
                 ("Solution", *[code for code, _ in letters], *[f"{letter} actual" for _, letter in letters],
                  "Predicted angle", "Distance", ""),
                 ("", *[""] * len(letters), *[""] * len(letters), "deg", "coded", ""), tuple(rows),
                 notes=(o.note, f"Target {o.target:.4g} deg; distance from the "
                        "measured means in coded units."),
                 sources=(_results_source("optimisation"), _runs_source(r, "box_behnken")),
                 formats=("d", *[".3f"] * len(letters), *[".4g"] * len(letters), ".4g", ".3g", ""))


def table_calibrated(c: Campaign) -> Table:
    """Table 11: calibrated contact parameters, the measured means and the paper's beside."""
    r = c.results
    wall = _wall(c.measurement)
    settings = r.validation.settings
    chosen = set(r.box_behnken.factors)
    paper_cal = _paper_own(c, "calibrated", default={})
    rows = []
    for letter, f in r.factors.items():
        name, symbol = parameter_label(f["parameter"], wall, particle_noun(c.measurement))
        pq = f["quantity"].replace(f"-{wall}", "-steel").replace(f".{wall}", ".steel")
        pm, _ = _paper_measured(c, f["quantity"])
        if f["quantity"] == "poisson_ratio":
            pm = _paper_own(c, "segment", "poisson_ratio")
        rows.append((letter, name, symbol, f["mean"], settings.get(f["parameter"]),
                     "optimised" if letter in chosen else "measured mean", paper_cal.get(pq), pm))
    return Table("11", "Calibrated DEM contact parameters",
                 ("Code", "Parameter", "Symbol", "Measured mean", "Calibrated", "How", "Paper calibrated",
                  "Paper measured"),
                 ("",) * 8, tuple(rows),
                 notes=("Paper: its calibrated values (0.32, 0.36, 0.22 for e_pp, e_pw, μs_pw) and "
                        "measured means from its text; the non-significant factors kept their "
                        "measured means there too." if paper_material(c) else _not_paper_note(c),),
                 sources=(_results_source("validation.settings, factors"), _runs_source(r, "box_behnken"))
                 + tuple(_reference_source(c, "calibrated") if paper_material(c) else ()),
                 formats=("", "", "", ".4g", ".4g", "", ".4g", ".4g"))


def _observable_columns(records) -> list[str]:
    cols = []
    for rec in records:
        for k, v in (_get(rec, "result", "observable", default={}) or {}).items():
            if k.endswith("_deg") and isinstance(v, (int, float)) and k not in cols:
                cols.append(k)
    return cols


def table_validation(c: Campaign) -> Table:
    """Table 12: validation runs at the calibrated parameters, the paper's beside."""
    r = c.results
    v = r.validation
    res = v.result
    records = [c.runs.get(run["key"], {}) for run in v.runs]
    extra = [k for k in _observable_columns(records) if k != "angle_deg"]
    paper = _paper_own(c, "validation", default={})
    paper_runs = list(paper.get("runs_deg", []))
    k, point_runs, angles = _replicates(r, "validation")
    rows = []
    for i, (runs, y, ys) in enumerate(zip(point_runs, v.responses, angles)):
        obs = [[_get(c.runs.get(run["key"], {}), "result", "observable", name) for run in runs]
               for name in extra]
        # other angles: the median over the replicates too, as the compared one
        med = [float(statistics.median([x for x in o if x is not None])) if any(x is not None for x in o) else None
               for o in obs]
        reps, seeds = _replicate_cells(runs, ys)
        rows.append((f"run {i + 1}", seeds, y, reps, *med, paper_runs[i] if i < len(paper_runs) else None))
    blank = [None] * len(extra)
    rows.append(("mean", None, res["mean"], None, *blank, paper.get("mean_deg")))
    rows.append(("SD (n - 1)", None, res["std"], None, *blank, None))
    rows.append(("measured angle (target)", None, res["target"], None, *blank, paper.get("target_deg")))
    rows.append(("relative error of the mean [%]", None, res["relative_error_pct"], None, *blank,
                 paper.get("relative_error_pct")))
    ci = res.get("ci95") or [None, None]
    if ci[0] is not None:
        rows.append(("95 % CI of the mean, low", None, ci[0], None, *blank, None))
        rows.append(("95 % CI of the mean, high", None, ci[1], None, *blank, None))
    notes = ["'Angle compared' is the observable the campaign compares with the photos (the "
             "response of every design); other angles the rig reports are shown beside it. The "
             "relative error is in %."]
    if k > 1:
        notes.append(_replicate_note(k))
    if ci[0] is not None:
        notes.append(f"The interval is t-based with the seed-to-seed sd of a design point's angle "
                     f"pooled over the screening centre and the Box-Behnken centre points "
                     f"({_number(v.noise_sd)} deg, {v.noise_df} degrees of freedom). The target "
                     + ("lies inside it: these runs cannot tell the calibrated heap from the measured one."
                        if res.get("target_in_ci") else "lies outside it: the calibrated heap differs "
                        "from the measured one by more than the DEM's seed noise."))
    if not paper_material(c):
        notes.append(_not_paper_note(c))
    return Table("12", "Validation: angle of repose simulated with the calibrated parameters",
                 ("Run", "Seeds", "Angle compared (angle_deg)", "Replicates", *extra, "Paper"),
                 ("", "", "deg", "deg", *["deg"] * len(extra), "deg"), tuple(rows),
                 notes=tuple(notes),
                 sources=(_runs_source(r, "validation"), _results_source("validation"))
                 + tuple(_reference_source(c, "validation") if paper_material(c) else ()),
                 formats=("", "", ".4g", "", *[".4g"] * len(extra), ".4g"))


# ----------------------------------------------------------------------------------------------
# Critique (``analyse.critique.loop.Critique``, stored as critique.json)

#: Columns of the critique tables: attributes of the records, which are also critique.json's
#: keys, so that a reader finds each cell there.
DISCREPANCY_COLUMNS = ("observable", "sheet", "measured", "measured_ci95", "simulated", "simulated_ci95",
                       "difference", "combined_u95", "exceeds", "n_measured", "n_simulated")
FINDING_COLUMNS = ("mechanism", "verdict", "sheet", "covariate", "effect", "ci95", "p_adjusted", "quantity",
                   "source", "effect_unit", "rows_to_decide")
MODEL_FINDING_COLUMNS = ("mechanism", "verdict", "observable", "measured", "simulated", "part", "part_ci95",
                         "share")
EXTENSION_COLUMNS = ("name", "mechanism", "before", "after", "gain", "ci95", "measure", "quantity",
                     "before_ci95", "after_ci95", "n_held_out")


def _cell(value):
    """A record's field as a table cell (intervals as lists, like critique.json holds them)."""
    return list(value) if isinstance(value, tuple) else value


def _long(value) -> str:
    return value if isinstance(value, str) else json.dumps(to_jsonable(value), sort_keys=True)


def _record_table(table_id: str, title: str, records: list, columns: tuple, note_fields: tuple, source: dict,
                  path: str) -> Table:
    """A table of critique records, one row each; the text fields (``note_fields``) go under the
    table as numbered notes, so that nothing is left out."""
    rows = tuple(tuple(_cell(getattr(r, attr)) for attr in columns) for r in records)
    notes = [] if records else ["None."]
    for i, r in enumerate(records, 1):
        for attr in note_fields:
            value = getattr(r, attr)
            if value not in (None, "", {}, []):
                notes.append(f"Row {i}, {attr}: {_long(value)}")
    return Table(table_id, title, columns, ("",) * len(columns), rows, notes=tuple(notes),
                 sources=({"kind": "critique", **source, "path": path},))


#: Fields of a covariate test (``analyse.critique.diagnosis.CovariateTest``) that Table C4 has
#: no column for; they are in critique.json.
_TEST_DETAILS = ("se", "dof", "span", "p_curvature", "levels")


def _p_key(p) -> float:
    """Sort key of a p-value: missing or NaN last."""
    return p if isinstance(p, (int, float)) and not isinstance(p, bool) and p == p else float("inf")


def covariate_verdict(t) -> str:
    """What the critique concluded from one covariate test (``CovariateTest``), in a few words."""
    if not t.significant:
        return "not significant"
    if t.relevant is False:
        return "significant, below threshold"
    if t.explained_by:
        return f"significant, explained by {t.explained_by}"
    return "significant: cause"


def table_covariate_tests(c: Campaign) -> Table:
    """Table C4: every covariate test of the critique (``Critique.tests``), sorted by adjusted
    p-value; ``Test`` is the test's position in critique.json's ``tests``, so each row can be
    found again. All tests are listed; the fields too wide for an A4 column are in critique.json."""
    items = list(c.critique.tests) if c.critique is not None else []
    order = sorted(range(len(items)), key=lambda i: (_p_key(items[i].p_adjusted), _p_key(items[i].p_value), i))
    rows, notes = [], []
    for i in order:
        t = items[i]
        rows.append((i + 1, t.series, t.sheet, t.source, t.covariate, f"{t.method} ({t.tier})", t.level, t.n, t.effect,
                     list(t.ci95), t.effect_unit, t.practical, t.threshold, t.p_value, t.p_adjusted,
                     covariate_verdict(t)))
    opts = c.critique.provenance.options if c.critique is not None else {}
    how = {"bh": "Benjamini-Hochberg", "holm": "Holm"}.get(opts.get("correction"), opts.get("correction"))
    shares = ", ".join(f"{tier} {share:g}" for tier, share in TIER_SHARES.items())
    notes.append("Sorted by adjusted p-value" + (f" ({how} within each tier; share of the level: {shares})"
                                                  if how else "")
                 + "; significant rows in bold" + (f" (adjusted p < {opts['alpha']:g})"
                                                   if isinstance(opts.get("alpha"), (int, float)) else "")
                 + ". Test: position in critique.json's tests. Method: line (slope), trend (line and "
                 "curvature), anova or mean, with its tier. Effect: slope per "
                 "covariate unit (trend, line), range of level means (anova) or mean (mean), with its marginal 95 % interval; "
                 "over range: the effect across the covariate's observed range, in the unit of the series, "
                 "against the practical threshold. A cause is significant, above the threshold and not "
                 "explained by another covariate.")
    if items:
        notes.append("Standard errors, degrees of freedom, covariate spans, curvature p-values and the "
                     "level means of each anova (" + ", ".join(_TEST_DETAILS) + ") are in critique.json (tests).")
    else:
        notes.append("None: critique.json holds no covariate tests.")
    for i in order:
        if items[i].ci_selected:
            lo, hi = items[i].ci_selected
            notes.append(f"Test {i + 1}: interval after selection (false-coverage rate, Benjamini & "
                         f"Yekutieli 2005) [{lo:.3g}, {hi:.3g}] {items[i].effect_unit or ''}".rstrip() + ".")
    return Table("C4", "Covariate tests of the lab's measurements (every test, by adjusted p-value)",
                 ("Test", "Series", "Sheet", "Source", "Covariate", "Method", "Unit of test", "n", "Effect",
                  "95 % CI", "Effect unit", "Over range", "Threshold", "p", "Adjusted p", "Verdict"),
                 ("",) * 16, tuple(rows), notes=tuple(notes),
                 sources=({"kind": "critique", **c.critique_source, "path": "tests"},),
                 formats=("d", "", "", "", "", "", "", "d", ".3g", ".3g", "", ".3g", ".3g", "p", "p", ""))


def table_heap_parameters(c: Campaign) -> Table:
    """Table C5: the calibrated parameters before and after recalibrating with each accepted
    extension (``Critique.heap_gains``), each against its own 95 % plausible interval."""
    gains = c.critique.heap_gains
    rows = tuple((h.extension, p.name, p.before, _cell(p.before_ci95), p.after, _cell(p.after_ci95), p.shift,
                  p.verdict) for h in gains for p in h.parameters)
    notes = [f"{h.extension} (recalibrated in {h.campaign} with "
             + ", ".join(f"{k} = {_long(v)}" for k, v in h.settings.items()) + f"): {h.conclusion}" for h in gains]
    if not gains:
        notes.append("None: no extension was recalibrated (see the conclusions above for why).")
    notes.append("A recalibrated value inside the 95 % plausible interval of the campaign under critique "
                 "has moved by less than the parameter's own uncertainty; its interval narrowed when the "
                 "extension at least halved its width (a twin that could not reach the lab left it "
                 "unidentified).")
    return Table("C5", "Heap-side gain: calibrated parameters recalibrated with each accepted extension",
                 ("Extension", "Parameter", "Before", "Before 95 % set", "After", "After 95 % set", "Shift",
                  "Shift judged"), ("",) * 8, rows, notes=tuple(notes),
                 sources=({"kind": "critique", **c.critique_source, "path": "heap_gains"},),
                 formats=("", "", ".4g", ".4g", ".4g", ".4g", ".3g", ""))


def table_heap_observables(c: Campaign) -> Table:
    """Table C6: the heap observables over the validation runs of the campaign under critique
    and of each recalibration; all but the fitted angle are predictions the calibration was not
    fitted to."""
    gains = c.critique.heap_gains
    rows = tuple((h.extension, o.name, o.unit, "yes" if o.fitted else "no", o.before, o.before_sd, o.n_before,
                  o.after, o.after_sd, o.n_after, o.difference, _cell(o.ci95),
                  {True: "beyond the noise", False: "within the noise"}.get(o.beyond_noise, "too few runs"))
                 for h in gains for o in h.observables)
    notes = ["Over the validation runs at each campaign's calibrated point, every run an independent draw; "
             "difference after - before with Welch's 95 % interval; the observables of the campaign's repose "
             "rig, lengths in mm."]
    if gains and c.results is not None:
        from demcal.simulate.rigs import repose_rig_named

        described = repose_rig_named(c.results.repose_rig).observable_notes
        shown = list(dict.fromkeys(o.name for h in gains for o in h.observables if o.name in described))
        if shown:
            notes.append("; ".join(f"{n}: {described[n]}" for n in shown) + ".")
    if not gains:
        notes.append("None: no extension was recalibrated.")
    return Table("C6", "Heap-side gain: heap observables before and after each accepted extension",
                 ("Extension", "Observable", "Unit", "Fitted", "Before", "sd", "n", "After", "sd", "n",
                  "Difference", "95 % CI", "Judged"), ("",) * 13, rows, notes=tuple(notes),
                 sources=({"kind": "critique", **c.critique_source, "path": "heap_gains"},),
                 formats=("", "", "", "", ".4g", ".3g", "d", ".4g", ".3g", "d", ".3g", ".3g", ""))


def table_target_codes(c: Campaign) -> Table:
    """Table C7: whether LIGGGHTS, Yade and EDEM can run each extension the critique accepted
    and recalibrated with, and which of the two calibrated sets ``demcal export`` writes."""
    from demcal.simulate.export import TARGET_NAMES, expresses

    gains = c.critique.heap_gains
    rows = []
    for h in gains:
        for target, name in TARGET_NAMES.items():
            ok = expresses(target, h.extension)
            rows.append((h.extension, h.mechanism, name, "yes" if ok else "no",
                         "calibrated without it (Table C5, Before)" + ("" if ok else ": it compensates for "
                                                                      "the extension in its values")))
    notes = []
    for h in gains:
        lacking = [name for t, name in TARGET_NAMES.items() if not expresses(t, h.extension)]
        if lacking:
            notes.append(f"{', '.join(lacking)} cannot express {h.extension}: the export "
                         f"gives them the parameters calibrated without it, and the set calibrated with it "
                         f"(Table C5, After; {h.campaign}) beside them, for demcal.")
    if not gains:
        notes.append("None: no extension was accepted and recalibrated with.")
    return Table("C7", "Target codes: the accepted extensions other DEM codes can run, and the set the export "
                 "writes", ("Extension", "Mechanism", "Target", "Expresses it", "Exported set"), ("",) * 5,
                 tuple(rows), notes=tuple(notes),
                 sources=({"kind": "critique", **c.critique_source, "path": "heap_gains"},))


def table_critique_power(c: Campaign) -> Table:
    """Table C8: how often the critique names each kind of planted effect, and a clean
    workbook any cause, at a lab's usual sample size (``data/critique_power.json``, the numbers of
    benchmarks/critique_power.md); the bounds are Clopper-Pearson, computed here."""
    from scipy import stats

    doc = read_json(POWER_FILE)
    rows = []
    for r in doc["power"]:
        n, k = r["workbooks"], r["found"]
        lower = float(stats.beta.ppf(0.05, k, n - k + 1)) if k else 0.0
        rows.append((r["kind"], "planted", n, k, lower, None, r["inconclusive"], r["ruled_out"]))
    for r in doc["false_alarms"]:
        n, k = r["workbooks"], r["naming_any_cause"]
        upper = float(stats.beta.ppf(0.95, k + 1, n - k)) if k < n else 1.0
        rows.append((r["design"], "clean", n, k, None, upper, None, None))
    return Table("C8", "What the critique finds at a lab's usual sample size (virtual-lab workbooks)",
                 ("Effect or design", "Workbooks", "n", "Found / naming a cause", "Lower 95 % bound",
                  "Upper 95 % bound", "Inconclusive", "Ruled out"), ("",) * 8, tuple(rows),
                 notes=(doc["source"] + ".", f"Bounds: {doc['bound']}, from the counts. A planted effect "
                        "should be found with at least 80 % power; a clean workbook should name a cause at "
                        "most 5 % of the time."),
                 sources=({"kind": "reference", "file": POWER_NAME, "sha256": sha256_file(POWER_FILE),
                           "path": "power, false_alarms"},),
                 formats=("", "", "d", "d", ".3f", ".3f", "d", "d"))


def critique_tables(c: Campaign) -> list[Table]:
    """Tables C1-C7 of the critique: model discrepancies, data effects, the causes of the
    discrepancies, extensions, covariate tests, the extensions' heap-side gains and what the
    target codes can take of them."""
    if c.critique is None:
        return []
    cr, src = c.critique, c.critique_source
    return [_record_table("C1", "Model discrepancies: where the twins disagree with the lab", cr.discrepancies,
                          DISCREPANCY_COLUMNS, ("note",), src, "discrepancies"),
            _record_table("C2", "Data effects: covariate effects in the lab's measurements", cr.findings,
                          FINDING_COLUMNS, ("reason", "evidence"), src, "findings"),
            _record_table("C2b", "Causes of the model discrepancies, each tested, with its share",
                          cr.model_findings, MODEL_FINDING_COLUMNS, ("evidence",), src, "model_findings"),
            _record_table("C3", "Model extensions and their gain on held-out trials", cr.extensions,
                          EXTENSION_COLUMNS, ("held_out", "fitted", "note"), src, "extension_records"),
            table_covariate_tests(c), table_heap_parameters(c), table_heap_observables(c), table_target_codes(c),
            table_critique_power(c)]


# ----------------------------------------------------------------------------------------------
# Appendix

def _role(path: str, source: str) -> str:
    if path == source:
        return "workbook"
    suffix = Path(path).suffix.lower()
    return {".jpg": "photo", ".jpeg": "photo", ".png": "photo", ".tif": "photo", ".tiff": "photo",
            ".csv": "sheet, track or curve"}.get(suffix, "input")


def table_inputs(c: Campaign) -> Table:
    """Table A1: every input file with its SHA-256."""
    wb = c.measurement.get("workbook", {})
    root = Path(wb.get("root", "."))
    rows = []
    for path, sha in wb.get("files", {}).items():
        p = Path(path)
        rel = str(p.relative_to(root)) if p.is_relative_to(root) else path
        rows.append((rel, _role(path, wb.get("source")), sha))
    for name, src in (("paper_defaults.json", c.paper_source), ("critique.json", c.critique_source)):
        if src:
            rows.append((name, "the paper's printed numbers" if name.startswith("paper") else
                         "critique results", src["sha256"]))
    return Table("A1", "Input files", ("File", "Role", "SHA-256"), ("", "", ""), tuple(rows),
                 notes=(f"Workbook files relative to {root}; the paper's numbers from {PAPER_FILE.name} "
                        "(data/).",),
                 sources=({"kind": "results", "file": "measure.json", "path": "workbook.files"},)
                 + tuple({"kind": "reference", **src, "path": "(whole file)"}
                         for src in (c.paper_source, c.critique_source) if src),
                 formats=("", "", "mono"))


def run_observable(inputs: dict, response: str) -> str:
    """The reading the campaign takes from a run: the response of a heap, or the observable a
    trial rig's task reads (``simulate.rigs.Rig.observed``: a drop's apparent restitution, an
    incline's apparent friction in its mode)."""
    from demcal.simulate.rigs import RIGS, rig

    name = inputs.get("rig")
    if name not in RIGS or rig(name).trial_groups is None:
        return response
    twin = rig(name)
    return twin.observed(inputs) if twin.observed is not None else twin.compared


def _finite(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _run_counts(records: list) -> tuple:
    """Runs, finished, failed, distinct seeds, total and median wall time of some run records."""
    ok = sum(rec.get("status") == "ok" for rec in records)
    seeds = {_get(rec, "inputs", "seed") for rec in records}
    wall = [rec["wall_s"] for rec in records if _finite(rec.get("wall_s"))]
    return (len(records), ok, len(records) - ok, len(seeds), math.fsum(wall),
            statistics.median(wall) if wall else None)


def table_runs(c: Campaign) -> Table:
    """Table A2: the DEM runs summed up by stage, from the run store (every run, with its key,
    is in runs.csv)."""
    r = c.results
    response = r.response["name"]
    rows, keys = [], []
    for stage, runs in run_stages(r):
        named = list(dict.fromkeys(run["key"] for run in runs))
        records = [c.runs.get(key, {}) for key in named]
        observables = {run_observable(rec.get("inputs") or {}, response) for rec in records}
        name = observables.pop() if len(observables) == 1 else None
        values = [v for rec in records if _finite(v := _get(rec, "result", "observable", name))]
        rows.append((stage, *_run_counts(records), name, statistics.fmean(values) if values else None,
                     statistics.stdev(values) if len(values) > 1 else None))
        keys += named
    keys = list(dict.fromkeys(keys))
    rows.append(("all runs", *_run_counts([c.runs.get(key, {}) for key in keys]), None, None, None))
    repoured = r.response.get("repoured_runs") or ()
    again = (f"{len(repoured)} heap(s) could be read by no method (e.g. nothing left the container) and "
             "were poured again with fresh seeds, as the lab pours again a heap it cannot measure: the row "
             "'unreadable heaps, each poured again' counts the runs set aside, and the runs that replaced "
             "them count in their stages.",) if repoured else ()
    return Table("A2", "DEM runs by stage (every run, with its key, is listed in runs.csv)",
                 ("Stage", "Runs", "Finished", "Failed", "Seeds", "Wall time, total", "Wall time, median",
                  "Observable", "Mean", "SD"),
                 ("", "", "", "", "", "s", "s", "", "", ""), tuple(rows),
                 notes=("Every run is listed in runs.csv beside this report, one row each: its key (the "
                        "SHA-256 of its inputs; its record is runs/<key>.json), stage(s), rig, seed, status, "
                        "attempts, wall time and observables.",
                        "Runs: the distinct run records of the stage; a run used by several stages counts in "
                        "each, and once in 'all runs'. Seeds: distinct seeds. Observable: what the campaign "
                        "reads from the stage's runs, with its mean and SD (n - 1) over the runs that gave it.",
                        *again),
                 sources=({"kind": "runs", "keys": keys},),
                 formats=("", "d", "d", "d", "d", ".4g", ".3g", "", ".4g", ".3g"))


# ----------------------------------------------------------------------------------------------

#: Builders of the tables that need the campaign's analysis (``Campaign.results``).
RESULT_TABLES = (table_pb_levels, table_pb_design, table_pb_anova, table_noise, table_climb,
                 table_bbd_levels, table_bbd_design, table_bbd_anova, table_fit_statistics,
                 table_coefficients, table_solutions, table_calibrated, table_validation)

#: Ids of the tables :data:`RESULT_TABLES` build, in order.
RESULT_TABLE_IDS = ("3", "4", "5", "5a", "6", "7", "8", "9", "9a", "9b", "10", "11", "12", "A2",
                    "P1", "P1a", "P2", "P3", "P4", "P5", "P5a", "P5b", "P6", "P6b", "P6c", "P6d", "P7", "P8")


def build_tables(c: Campaign) -> list[Table]:
    """Every table of the report, in the order they appear.

    Without ``c.results`` only the measurement tables (1, 2, 2a, A1) and the critique tables
    are built.
    """
    tables = [table_dimensions(c), table_physical(c), table_methods(c)]
    if c.results is not None and c.results.workflow == "plausible":
        from demcal.report.calibration_tables import PLAUSIBLE_TABLES

        for built in (f(c) for f in PLAUSIBLE_TABLES):      # a table, none, or one per further rig
            tables += built if isinstance(built, list) else [built] if built is not None else []
    elif c.results is not None:
        tables += [f(c) for f in RESULT_TABLES]
    tables += critique_tables(c)
    tables.append(table_inputs(c))
    if c.results is not None:
        tables.append(table_runs(c))
    return tables


def tables_document(tables: list[Table], inputs: dict, artefacts: dict | None = None) -> dict:
    """The content of ``tables.json``: the tables, the SHA-256 of every file they rest on
    (``inputs``) and of the report's files written beside them (``artefacts``: runs.csv, and
    the figures once drawn, ``report.figures.figure_record``)."""
    return {"format": "demcal-tables/1", "inputs": dict(inputs), "artefacts": dict(artefacts or {}),
            "tables": [t.to_dict() for t in tables]}


def normalised(tables: list[Table]) -> list[dict]:
    """Tables as they read back from JSON (tuples as lists, NaN as None), for comparison."""
    return json.loads(json.dumps([t.to_dict() for t in tables], allow_nan=False))
