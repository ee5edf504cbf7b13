"""The measure stage end to end: a validated workbook in, every material quantity out.

:func:`measure_workbook` runs the estimator of each sheet present and gathers the results in a
:class:`Measurement`, whose :meth:`Measurement.to_dict` is the JSON written by
``demcal measure``::

    {"material": str,
     "quantities": {NAME: {"value", "sd", "n", "ci95": [lo, hi], "unit", "rows_used",
                           "rows_rejected": [{"row", "reason"}],
                           "source": {"file", "sheet", "sha256"}, "method", "extra"}},
     "per_row": {NAME: [{"row", "value", "used", ..., "covariates": {...}}]},
     "meta": {...}, "shape": {"shape": NAME, ...}, "unknown_sheets": [...], "workbook": {...},
     "provenance": {...}, "notes": [...]}

``shape`` is the particle's shape at the mean readings (``simulate.shapes``, the meta ``shape``,
default ``segment``), what the DEM's clumps are built from; a note compares the mass of its
sphere model at the measured particle density with the balance's.

Quantity names are those of docs/workbook.md: ``length_mm``, ``diameter_mm``, ``mass_g``,
``particle_density_kg_m3``, ``envelope_density_kg_m3``, ``restitution.<pair>``,
``static_friction.<surface>``, ``rolling_friction.<surface>``, ``poisson_ratio``,
``elastic_modulus_pa``, ``shear_modulus_pa`` (when curves are given) and ``repose_angle_deg``
(the meta's first repose rig; ``repose_angle_deg.<rig>`` for each further one, see
:func:`photo_rigs`).
Each value is in the unit its name carries (mm, g, kg/m^3, Pa, deg) or is dimensionless.

The angle of repose comes from the heap photos through a photo estimator
``angle_from_photo(path, side=..., annotate_to=..., max_pixels=...)`` returning an object with
``angle_deg``, ``flanks`` (``{"left": deg or None, "right": deg or None}``) and
``base_tilt_deg``; by default :func:`measure.repose.angle_from_photo`. The estimator decodes
each photo, once, and refuses one with more than ``max_pixels`` pixels before decoding it. A
``target_repose_deg`` in ``meta`` overrides it (the override is reported, the photo estimate
kept in ``extra``); the lab's ``angle_deg_manual`` is only compared with the photo estimate,
never used as the result.
"""

from __future__ import annotations

import functools
import math
import re
from collections import Counter
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from demcal.errors import DemcalError, WorkbookError
from demcal.provenance import Provenance
from demcal.measure.density import density_estimates
from demcal.measure.dimensions import specimen_statistics
from demcal.measure.elasticity import compression_estimates
from demcal.measure.estimate import Estimate, parse_outlier_rule, summarise
from demcal.measure.friction import friction_estimates
from demcal.measure.images import MAX_PHOTO_PIXELS
from demcal.measure.restitution import restitution_estimates
from demcal.measure.shape import mean_shape
from demcal.measure.workbook import ReadOptions, Workbook, read_workbook
from demcal.units import GRAVITY

#: Order of the quantities in outputs (prefixes stand for their families).
ORDER = ("length_mm", "diameter_mm", "width_mm", "thickness_mm", "mass_g", "particle_density_kg_m3", "envelope_density_kg_m3",
         "restitution.", "static_friction.", "rolling_friction.", "poisson_ratio",
         "elastic_modulus_pa", "shear_modulus_pa", "repose_angle_deg", "repose_angle_deg.", "crest_height_mm",
         "crest_height_mm.")


def _order_key(name: str):
    for i, key in enumerate(ORDER):
        if name == key or (key.endswith(".") and name.startswith(key)):
            return (i, name)
    return (len(ORDER), name)


@dataclass(frozen=True)
class Measurement:
    """Every quantity measured from one workbook.

    Attributes
    ----------
    material : str
        ``meta`` material name.
    quantities : dict of str -> Estimate
        Quantity name -> estimate, in the order of docs/workbook.md.
    workbook : dict
        ``source``, ``root``, ``files`` (path -> SHA-256), ``sheets`` (file, hash, row count,
        required/optional/covariate columns per sheet) and ``unknown_sheets``.
    meta : dict
        The ``meta`` sheet (key -> value).
    provenance : Provenance
        Code version, input hashes and the options used.
    notes : list of str
        What the user should know (e.g. photos not measured because no estimator was available).
    shape : dict
        The particle's shape at the mean readings (``simulate.shapes.Shape.to_dict``); empty
        when a size has no estimate.
    """

    material: str
    quantities: dict
    workbook: dict
    meta: dict
    provenance: Provenance
    notes: list = field(default_factory=list)
    shape: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """The JSON layout described in the module docstring."""
        return {"material": self.material,
                "quantities": {n: e.to_dict() for n, e in self.quantities.items()},
                "per_row": {n: [dict(r) for r in e.per_row] for n, e in self.quantities.items()},
                "meta": dict(self.meta),
                "shape": dict(self.shape),
                "unknown_sheets": list(self.workbook.get("unknown_sheets", [])),
                "workbook": dict(self.workbook),
                "provenance": self.provenance.to_dict(),
                "notes": list(self.notes)}

    @classmethod
    def from_dict(cls, d: dict) -> "Measurement":
        """Rebuild a measurement from :meth:`to_dict` output (e.g. a stored JSON)."""
        per_row = d.get("per_row", {})
        quantities = {n: Estimate.from_dict(q, per_row.get(n, [])) for n, q in d["quantities"].items()}
        return cls(material=d["material"], quantities=quantities, workbook=dict(d.get("workbook", {})),
                   meta=dict(d.get("meta", {})), provenance=Provenance(**d["provenance"]),
                   notes=list(d.get("notes", [])), shape=dict(d.get("shape") or _segment_of(quantities)))

    @property
    def read_options(self) -> ReadOptions:
        """How the workbook was read (recorded in provenance), to read it again the same way."""
        return ReadOptions.from_dict(self.provenance.options.get("reading"))

    def table(self) -> str:
        """A short human-readable table of the quantities."""
        def num(x):
            return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.4g}"
        lines = [f"{'quantity':<34} {'value':>10} {'sd':>10} {'n':>4}  {'95 % CI':<23} {'unit':<7} rejected"]
        for name, e in self.quantities.items():
            ci = "-" if math.isnan(e.ci95[0]) else f"[{num(e.ci95[0])}, {num(e.ci95[1])}]"
            flag = " (override)" if e.extra.get("override") else ""
            lines.append(f"{name:<34} {num(e.value):>10} {num(e.sd):>10} {e.n:>4}  {ci:<23} "
                         f"{e.unit:<7} {len(e.rows_rejected)}{flag}")
        return "\n".join(lines)


def _default_photo_estimator():
    """:func:`measure.repose.angle_from_photo`, or None when that module is not installed."""
    try:
        from demcal.measure.repose import angle_from_photo
    except ModuleNotFoundError as exc:
        if exc.name == "demcal.measure.repose":
            return None
        raise
    return angle_from_photo


def _safe_name(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", str(text)).strip("_") or "photo"


def _annotated_names(ids: dict) -> dict:
    """Row -> file name of its annotated photo: the photo id made safe for a file name, with
    ``@row<n>`` added where two ids would give the same name (``a/b`` and ``a_b``, or ``A`` and
    ``a`` on a case-insensitive file system); a safe name never holds ``@``."""
    stems = {r: _safe_name(i) for r, i in ids.items()}
    count = Counter(s.casefold() for s in stems.values())
    return {r: f"{s}@row{r}_annotated.png" if count[s.casefold()] > 1 else f"{s}_annotated.png"
            for r, s in stems.items()}


def repose_quantity(index: int, workbook_name: str, quantity: str = "repose_angle_deg") -> str:
    """The ``quantity`` of the photos of the workbook's ``index``-th repose rig (meta
    ``repose_rig``): e.g. ``repose_angle_deg`` for the first, ``repose_angle_deg.<rig>`` for the
    others (and ``crest_height_mm``, ``crest_height_mm.<rig>``)."""
    return quantity if index == 0 else f"{quantity}.{workbook_name}"


def photo_rigs(wb: Workbook) -> dict:
    """The rows of the ``repose`` sheet by the repose rig they photograph, in the meta's order
    (``{workbook name: [row, ...]}``): the sheet's ``rig`` column, a blank cell meaning the
    meta's first rig. Without a ``rig`` column every row is the first rig's, as the meta names
    it (an unknown name is left to the calibration to refuse: its photos still measure). A row
    of a rig the meta does not name, a rig named without photos, several rigs without a ``rig``
    column, and a drum photo read as a heap (or the reverse) are refused naming sheet, row and
    column."""
    from demcal.simulate.rigs import repose_rigs

    sheet = wb.sheet("repose")
    f = sheet.frame
    file = str(sheet.file)
    if "rig" not in f:
        raw = wb.meta.get("repose_rig")
        if raw is not None and "," in str(raw):
            names = [r.workbook_name for r in repose_rigs(wb.meta, str(wb.source))]
            raise WorkbookError(f"meta repose_rig names {len(names)} rigs ({', '.join(names)}): the repose sheet "
                                "needs a column rig saying which rig each photo shows", file=file,
                                sheet=sheet.name, column="rig")
        first = str(raw).strip().lower() if raw is not None and str(raw).strip() else "lifted_plate"
        return {first: list(sheet.rows)}
    rigs = repose_rigs(wb.meta, str(wb.source))
    names = [r.workbook_name for r in rigs]
    out = {n: [] for n in names}
    for r in sheet.rows:
        name = f.at[r, "rig"] or names[0]
        if name not in out:
            raise WorkbookError(f"rig {name}: meta repose_rig names {', '.join(names)}, not this rig",
                                file=file, sheet=sheet.name, row=r, column="rig", value=name)
        drum = next(x for x in rigs if x.workbook_name == name).flanks == "drum"
        side = f.at[r, "side"] if "side" in f else "both"
        if (side == "drum") != drum:
            raise WorkbookError(f"side {side}: a photo of the {name} rig " + (
                "shows a drum's free surface: its side is drum" if drum else "shows a heap, not a drum"),
                file=file, sheet=sheet.name, row=r, column="side", value=side)
        out[name].append(r)
    empty = [n for n, rows in out.items() if not rows]
    if empty:
        raise WorkbookError(f"meta repose_rig names {', '.join(empty)} but no photo has that rig",
                            file=file, sheet=sheet.name, column="rig")
    return out


def _photo_estimate(wb: Workbook, estimator, *, outliers, annotate_dir, max_photo_pixels,
                    rows_of_rig=None, name="repose_angle_deg") -> Estimate:
    """The quantity ``name`` from the heap photos of the ``repose`` sheet's rows
    ``rows_of_rig`` (default: every row)."""
    sheet = wb.sheet("repose")
    f = sheet.frame
    values, rows, records, rejected = [], [], [], []
    names = _annotated_names({r: f.at[r, "photo_id"] for r in sheet.rows})
    if annotate_dir is not None:
        Path(annotate_dir).mkdir(parents=True, exist_ok=True)
    for r in (sheet.rows if rows_of_rig is None else rows_of_rig):
        rel = f.at[r, "file"]
        side = f.at[r, "side"] if "side" in f else "both"
        annotate_to = None if annotate_dir is None else Path(annotate_dir) / names[r]
        scale = f.at[r, "scale_mm_per_px"] if "scale_mm_per_px" in f else math.nan
        # the scale only turns the crest height into mm (an estimator without lengths needs none)
        extra_args = {} if math.isnan(scale) or side == "drum" else {"scale_mm_per_px": float(scale)}
        try:
            result = estimator(wb.resolve(rel), side=side, annotate_to=annotate_to,
                               max_pixels=max_photo_pixels, **extra_args)
        except DemcalError as exc:
            raise WorkbookError(f"photo {wb.resolve(rel)}: {exc}", file=str(sheet.file), sheet=sheet.name,
                                row=r, column="file", value=rel) from None
        angle = float(result.angle_deg) if result.angle_deg is not None else math.nan
        manual = f.at[r, "angle_deg_manual"] if "angle_deg_manual" in f else math.nan
        rec = {"id": f.at[r, "photo_id"], "file": rel, "side": side,
               "flanks": {k: (None if v is None else float(v)) for k, v in dict(result.flanks).items()},
               "base_tilt_deg": None if result.base_tilt_deg is None else float(result.base_tilt_deg),
               "angle_deg_manual": None if math.isnan(manual) else float(manual),
               "annotated": None if annotate_to is None else str(annotate_to),
               "covariates": sheet.covariates_of(r)}
        crest = _crest_height_mm(result)
        if crest is not None:                     # only a photo with its scale has one
            rec["crest_height_mm"] = crest
        if not 0 < angle < 90:
            rejected.append({"row": r, "reason": f"the photo estimator found no angle ({angle!r})"})
            continue
        values.append(angle)
        rows.append(r)
        records.append(rec)
    extra = {}
    drums = [rec["side"] == "drum" for rec in records]
    method = ("drum photo: central chord of the free surface (measure.repose.angle_from_drum)"
              if drums and all(drums) else "heap photo: mean slope of the heap flanks (measure.repose)")
    est = summarise(name, values, rows, unit="deg", source=sheet.source(), method=method,
                    outliers=outliers, rejected=rejected, per_row=records)
    pairs = [(rec["value"], rec["angle_deg_manual"]) for rec in est.per_row
             if rec["used"] and rec["angle_deg_manual"] is not None]
    if pairs:
        photo, manual = np.array(pairs).T
        extra["manual_comparison"] = {
            "n": len(pairs), "mean_manual_deg": float(manual.mean()),
            "mean_photo_minus_manual_deg": float((photo - manual).mean()),
            "note": "angle_deg_manual is the lab's own reading, compared only, never used"}
    for flank in ("left", "right"):
        x = [rec["flanks"].get(flank) for rec in est.per_row if rec["used"]]
        x = [v for v in x if v is not None]
        if x:
            extra.setdefault("flank_mean_deg", {})[flank] = float(np.mean(x))
    return replace(est, extra=dict(est.extra, **extra))


def _crest_height_mm(result) -> float | None:
    """The photo's crest height above the floor [mm], when its scale was given."""
    height = getattr(result, "crest_height_m", None)
    return float(height) * 1e3 if height is not None and math.isfinite(height) else None


def crest_height_estimate(angle: Estimate, name: str) -> Estimate | None:
    """The crest height [mm] of the heaps of one rig (``angle``: its angle estimate, whose
    used photos' records hold their crest heights), or None unless every used photo has one
    (a ``scale_mm_per_px``): a target of the calibration only when asked for
    (``CampaignConfig.extra_targets``)."""
    used = [rec for rec in angle.per_row if rec.get("used", True)]
    heights = [rec.get("crest_height_mm") for rec in used]
    if not used or any(h is None for h in heights):
        return None
    rows = [rec["row"] for rec in used]
    return summarise(name, heights, rows, unit="mm", source=angle.source,
                     method="heap photo: height of the smoothed crest above the floor line, times the photo's "
                            "scale_mm_per_px (measure.repose)")


def _segment_of(quantities: dict) -> dict:
    """The segment shape a measurement stored before shapes existed describes (its mean length
    and diameter), or an empty dict."""
    from demcal.simulate.shapes.segment import Segment
    from demcal.units import MM

    if "length_mm" in quantities and "diameter_mm" in quantities:
        return Segment(quantities["length_mm"].value * MM, quantities["diameter_mm"].value * MM).to_dict()
    return {}


#: Grid lines of the union's mass in the particle note (relative error about 3e-5).
NOTE_RESOLUTION = 200


@functools.lru_cache(maxsize=64)
def _union_volume(shape) -> float:
    """Volume [m^3] of the shape's sphere model (the union of its spheres), on a coarse grid: 4
    digits in 0.02 s (the DEM's 600 lines take 0.3 s); kept, since a critique or a calibration
    measures one workbook several times."""
    return shape.template(1.0, resolution=NOTE_RESOLUTION).mass


def shape_note(shape, quantities: dict) -> str | None:
    """The mass of the shape's sphere model (union) and of its body at the measured particle
    density against the balance's mean mass, as a sentence; None without both."""
    rho, mass = quantities.get("particle_density_kg_m3"), quantities.get("mass_g")
    if shape is None or rho is None or mass is None:
        return None
    union = rho.value * _union_volume(shape) * 1e3
    body = rho.value * shape.volume() * 1e3
    return (f"particle model: {shape.describe()}; at the measured particle density "
            f"({rho.value:.4g} kg/m^3) its spheres weigh {union:.4g} g and its body ({type(shape).body}) "
            f"{body:.4g} g, against the balance's mean {mass.value:.4g} g (ratio {union / mass.value:.3g})")


def _check_finite(est: Estimate) -> None:
    """Refuse an estimate that is not a finite number (an sd and interval may be undefined only
    for a single value, or a stated override): JSON would write it as null."""
    numbers = [est.value] + ([est.sd, *est.ci95] if est.n >= 2 and not est.extra.get("override") else [])
    if not all(math.isfinite(x) for x in numbers):
        src = est.source or {}
        raise WorkbookError(f"the estimate of {est.name} is not a finite number (value {est.value!r}, "
                            f"sd {est.sd!r}): check the values of rows {est.rows_used[:10]}",
                            file=src.get("file"), sheet=src.get("sheet"))


def repose_estimate(wb: Workbook, *, photo_estimator=None, outliers="none", annotate_dir=None,
                    max_photo_pixels=MAX_PHOTO_PIXELS):
    """The angle of repose of each repose rig from its photos (:func:`photo_rigs`,
    :func:`repose_quantity`), the first one's overridden by ``meta`` ``target_repose_deg`` if
    given.

    ``max_photo_pixels``, the most pixels a photo may have [px], is passed to the photo
    estimator as ``max_pixels``.

    Returns
    -------
    (dict of str -> Estimate, list of str)
        The estimates by quantity (empty when there is neither a photo nor a target) and notes.
    """
    notes = []
    found = {}
    sheet = wb.sheet("repose")
    if sheet is not None and sheet.rows:
        estimator = photo_estimator or _default_photo_estimator()
        if estimator is None:
            notes.append("repose photos not measured: no photo estimator (measure.repose) available")
        else:
            for i, (rig, rows) in enumerate(photo_rigs(wb).items()):
                name = repose_quantity(i, rig)
                found[name] = _photo_estimate(wb, estimator, outliers=outliers, annotate_dir=annotate_dir,
                                              max_photo_pixels=max_photo_pixels, rows_of_rig=rows, name=name)
                crest = crest_height_estimate(found[name], repose_quantity(i, rig, "crest_height_mm"))
                if crest is not None:
                    found[crest.name] = crest
    target = wb.meta.get("target_repose_deg")
    if target is None:
        return found, notes
    photo = found.get("repose_angle_deg")
    meta = wb.sheet("meta")
    row = next(r for r in meta.rows if meta.frame.at[r, "key"] == "target_repose_deg")
    found["repose_angle_deg"] = Estimate(
        name="repose_angle_deg", value=float(target), sd=math.nan, n=1, ci95=(math.nan, math.nan),
        unit="deg", rows_used=[row], rows_rejected=[], source=meta.source(),
        method="meta target_repose_deg (overrides the photo estimate)",
        extra={"override": True, "photo_estimate": None if photo is None else photo.to_dict()},
        per_row=[] if photo is None else list(photo.per_row))
    notes.append(f"repose_angle_deg: meta target_repose_deg = {target:g} deg overrides the photo estimate"
                 + ("" if photo is None else f" ({photo.value:.4g} deg)"))
    return found, notes


def measure_particle(wb, reading: ReadOptions | None = None) -> Measurement:
    """The particle alone (what a twin needs to simulate the workbook's material): the
    specimens' sizes and mass, the densities, the shape and the meta; no drop, incline,
    compression or photo is measured."""
    if not isinstance(wb, Workbook):
        wb = read_workbook(wb, reading)
    quantities = {**specimen_statistics(wb.sheet("specimens")), **density_estimates(wb)}
    shape = mean_shape(wb, quantities)
    return Measurement(material=str(wb.meta["material"]), quantities=quantities,
                       workbook={"source": str(wb.source), "files": dict(wb.files)}, meta=dict(wb.meta),
                       provenance=Provenance(inputs=dict(wb.files), options={"reading": wb.options.to_dict()}),
                       shape={} if shape is None else shape.to_dict())


def measure_workbook(wb, *, photo_estimator=None, outliers="none", annotate_dir=None,
                     r2_min=0.995, g=GRAVITY, reading: ReadOptions | None = None) -> Measurement:
    """Measure every quantity the workbook holds data for.

    Parameters
    ----------
    wb : Workbook or str or Path
        A workbook from :func:`measure.workbook.read_workbook`, or its path.
    photo_estimator : callable, optional
        ``f(path, side=..., annotate_to=..., max_pixels=...)`` for heap photos; default
        ``measure.repose.angle_from_photo`` (imported on use).
    outliers : str
        Outlier rule for every quantity, see :func:`measure.estimate.screen_outliers`. The
        default ``"none"`` uses every valid row, as the lab's own means do; ``"mad"`` or
        ``"grubbs"`` screen each quantity and list every rejected row with its reason.
    annotate_dir : str or Path, optional
        Folder for annotated heap photos (none written if None).
    r2_min : float
        R^2 that the initial linear window of a compression curve must reach.
    g : float
        Gravitational acceleration for camera tracks [m/s^2].
    reading : ReadOptions, optional
        How to read ``wb`` when it is a path (a :class:`Workbook` carries its own). Its
        ``max_photo_pixels`` (default ``measure.images.MAX_PHOTO_PIXELS``) also bounds the
        photos the estimator decodes; the options are recorded in provenance, so the workbook
        can be read again the same way (``ReadOptions.from_dict``).

    Returns
    -------
    Measurement

    Raises
    ------
    WorkbookError
        For a bad workbook, and for an estimate that came out infinite or NaN (it names the
        quantity and its sheet: a value the plausible ranges let through).
    """
    if not isinstance(wb, Workbook):
        wb = read_workbook(wb, reading)
    max_photo_pixels = wb.options.max_photo_pixels or MAX_PHOTO_PIXELS
    rule, limit = parse_outlier_rule(outliers)
    quantities: dict = {}
    quantities.update(specimen_statistics(wb.sheet("specimens"), outliers=outliers))
    quantities.update(density_estimates(wb, outliers=outliers))
    quantities.update(restitution_estimates(wb, outliers=outliers, g=g))
    quantities.update(friction_estimates(wb, outliers=outliers))
    quantities.update(compression_estimates(wb, outliers=outliers, r2_min=r2_min))
    repose, notes = repose_estimate(wb, photo_estimator=photo_estimator, outliers=outliers,
                                    annotate_dir=annotate_dir, max_photo_pixels=max_photo_pixels)
    quantities.update(repose)
    quantities = {n: quantities[n] for n in sorted(quantities, key=_order_key)}
    for est in quantities.values():
        _check_finite(est)
    notes = list(wb.notes) + notes
    shape = mean_shape(wb, quantities)
    note = shape_note(shape, quantities)
    if note:
        notes.append(note)
    sheets = {name: {"file": str(s.file), "sha256": s.sha256, "rows": len(s.rows),
                     "required": list(s.required), "optional": list(s.optional),
                     "covariates": list(s.covariates)} for name, s in wb.sheets.items()}
    info = {"source": str(wb.source), "root": str(wb.root), "files": dict(wb.files),
            "sheets": sheets, "unknown_sheets": list(wb.unknown_sheets)}
    if wb.unknown_sheets:
        notes.append(f"unknown sheets kept but not used: {', '.join(wb.unknown_sheets)}")
    estimator = photo_estimator or (_default_photo_estimator() if "repose" in wb.sheets else None)
    options = {"outliers": rule if limit is None else f"{rule}:{limit:g}", "r2_min": r2_min, "g": g,
               "photo_estimator": None if estimator is None else
               f"{getattr(estimator, '__module__', '?')}.{getattr(estimator, '__qualname__', repr(estimator))}"}
    if estimator is not None and photo_estimator is None:
        from demcal.measure.repose import FLANK_BAND
        options["flank_band"] = list(FLANK_BAND)  # the twins' angles must be read the same way
    options["reading"] = wb.options.to_dict()
    return Measurement(material=str(wb.meta["material"]), quantities=quantities, workbook=info,
                       meta=dict(wb.meta), provenance=Provenance(inputs=dict(wb.files), options=options),
                       notes=notes, shape={} if shape is None else shape.to_dict())
