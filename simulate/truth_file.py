"""The truth file of the virtual lab: a YAML that states a material and the design of its lab
campaign, read into a :class:`~simulate.virtual_lab.Truth` and the options of
:func:`~simulate.virtual_lab.write_virtual_workbook`.

Layout (every key optional; data/virtual_lab/truth.yaml is a commented example)::

    params:                  # DEMParameters fields (SI units), e.g. e_pw: 0.35, mu_s_pp: 0.65
      e_pw: 0.35
    e_sd: 0.03               # any other field of Truth: scatter, reading noise, levels
    operators: [op1, op2]
    design:                  # the shape of the workbook (write_virtual_workbook's options)
      pairs: [particle-particle, particle-steel]
      drop_heights_mm: [200, 400, 600]
      n_drop: 10
      photos: analytic
      repose_rig:            # the heap's rig, as workbook meta rows (default: the lifted plate)
        repose_rig: lifting_cylinder
        cylinder_diameter_mm: 60
        cylinder_height_mm: 120
        lift_speed_mm_s: 10

Omitted keys take the defaults of ``Truth``, ``DEMParameters`` and ``write_virtual_workbook``.
An unknown key, or a value of the wrong type or out of range, is refused with the file, the key
and the valid range.
"""

from __future__ import annotations

import dataclasses
import datetime
import inspect
import math
from dataclasses import dataclass
from pathlib import Path

from demcal.errors import InputError
from demcal.simulate.params import SEGMENT_FIELDS, DEMParameters, current_names
from demcal.simulate.virtual_lab import PHOTO_MODES, Truth, write_virtual_workbook

#: Valid range of each numeric field of ``Truth``: (low, high, low included, high included).
TRUTH_RANGES = {
    "e_sd": (0.0, math.inf, True, False), "mu_sd": (0.0, math.inf, True, False),
    "length_sd_m": (0.0, math.inf, True, False), "diameter_sd_m": (0.0, math.inf, True, False),
    "envelope_ratio": (0.0, math.inf, False, False), "density_sd": (0.0, math.inf, True, False),
    "moisture_pct": (0.0, math.inf, True, False), "moisture_sd_pct": (0.0, math.inf, True, False),
    "repose_angle_deg": (0.0, 80.0, False, False), "repose_sd_deg": (0.0, math.inf, True, False),
    "poisson_sd": (0.0, math.inf, True, False), "modulus_sd_rel": (0.0, math.inf, True, False),
    "height_noise_mm": (0.0, math.inf, True, False), "angle_noise_deg": (0.0, math.inf, True, False),
    "camera_roll_sd_deg": (0.0, math.inf, True, False), "icc": (0.0, 1.0, True, False),
}

#: Fields of ``Truth`` that name levels (lists of labels).
TRUTH_LEVELS = ("operators", "batches", "days")

#: Drop pairs and incline surfaces the virtual lab can simulate.
PAIRS = ("particle-particle", "particle-steel")
SURFACES = ("particle", "steel")

#: Keys of the ``design`` section: the options of ``write_virtual_workbook`` that shape the workbook.
DESIGN_KEYS = ("photos", "n_specimens", "n_density", "pairs", "drop_heights_mm", "n_drop",
               "orientation_range_deg", "n_tracks", "surfaces", "n_incline", "n_compression",
               "n_photos", "trials_per_specimen", "interleaved", "repose_rig")

#: Smallest count of each integer design option (those of ``write_virtual_workbook``).
DESIGN_MIN_COUNTS = {"n_specimens": 3, "n_density": 2, "n_drop": 1, "n_incline": 2, "n_compression": 0,
                     "n_photos": 0, "n_tracks": 0, "trials_per_specimen": 1}


def design_defaults() -> dict:
    """The ``design`` options' defaults, those of ``write_virtual_workbook`` (lists for tuples)."""
    params = inspect.signature(write_virtual_workbook).parameters
    return {k: list(params[k].default) if isinstance(params[k].default, tuple) else params[k].default
            for k in DESIGN_KEYS}


@dataclass(frozen=True)
class TruthFile:
    """A truth file read.

    Attributes
    ----------
    truth : Truth
    design : dict
        Every ``design`` option (defaults filled in), keyword arguments of
        ``write_virtual_workbook``.
    path : Path or None
        The file it was read from.
    """

    truth: Truth
    design: dict
    path: Path | None = None

    def to_dict(self) -> dict:
        return {"truth": self.truth.to_dict(), "design": dict(self.design),
                "path": None if self.path is None else str(self.path)}


def _range_text(lo, hi, lo_in, hi_in) -> str:
    if hi == math.inf:
        return f">= {lo:g}" if lo_in else f"> {lo:g}"
    return f"in {'[' if lo_in else '('}{lo:g}, {hi:g}{']' if hi_in else ')'}"


def _number(value, where: str, valid: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InputError(f"{where}: must be a number {valid}, got {value!r}")
    return float(value)


def _in_range(value, where: str, lo, hi, lo_in=True, hi_in=True) -> float:
    valid = _range_text(lo, hi, lo_in, hi_in)
    x = _number(value, where, valid)
    if not ((x >= lo if lo_in else x > lo) and (x <= hi if hi_in else x < hi)):
        raise InputError(f"{where}: must be a number {valid}, got {value!r}")
    return x


def _count(value, where: str, least: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or int(value) != value or value < least:
        raise InputError(f"{where}: must be an integer >= {least}, got {value!r}")
    return int(value)


def _labels(value, where: str, valid=None) -> list:
    """A list of labels (YAML dates become ISO text); with ``valid``, each one of them."""
    if isinstance(value, (str, int, float, datetime.date)):
        value = [value]
    if not isinstance(value, (list, tuple)):
        raise InputError(f"{where}: must be a list of labels, got {value!r}")
    out = [v.isoformat() if isinstance(v, datetime.date) else str(v) for v in value]
    if valid is not None:
        bad = [v for v in out if v not in valid]
        if bad:
            raise InputError(f"{where}: {', '.join(map(repr, bad))} not valid; valid: {', '.join(valid)}")
    return out


def parse_params(values, where: str = "params") -> DEMParameters:
    """``DEMParameters`` from a mapping of field names (SI), each checked with its name."""
    if values is None:
        return DEMParameters()
    if not isinstance(values, dict):
        raise InputError(f"{where}: must be a mapping of DEM parameter names to values, got {values!r}")
    values = current_names(values)                  # a file written before a rename reads as it meant
    names = DEMParameters.names() + tuple(SEGMENT_FIELDS)
    unknown = [k for k in values if k not in names]
    if unknown:
        raise InputError(f"{where}: unknown DEM parameter {unknown[0]!r}; valid: {', '.join(names)}")
    defaults = {f.name: f.default for f in dataclasses.fields(DEMParameters)}
    defaults.update({k: 0.0 for k in SEGMENT_FIELDS})         # the segment's former fields: numbers
    for name, value in values.items():
        default = defaults[name]
        if isinstance(value, bool) != isinstance(default, bool) and isinstance(default, (int, float)):
            raise InputError(f"{where}.{name}: must be a "
                             f"{'true or false' if isinstance(default, bool) else 'number'}, got {value!r}")
    errors = (InputError, TypeError, ValueError)
    try:
        # all at once: checks between fields (diameter <= length, a mass for mass_model) see the
        # file's values, not a mix of them and the defaults
        return DEMParameters.from_names(values)
    except errors as exc:
        # name the field when one alone is wrong (on the file's shape: sizes are the shape's)
        shape = {"shape": values["shape"]} if "shape" in values else {}
        for name, value in (*shape.items(), *values.items()):
            try:
                DEMParameters.from_names({**shape, name: value})
            except errors as one:
                raise InputError(f"{where}.{name}: {one}") from None
        raise InputError(f"{where}: {exc}") from None


def parse_design(values, where: str = "design") -> dict:
    """The ``design`` section: every option checked, defaults filled in."""
    design = design_defaults()
    if values is None:
        return design
    if not isinstance(values, dict):
        raise InputError(f"{where}: must be a mapping of design options, got {values!r}")
    for key, value in values.items():
        at = f"{where}.{key}"
        if key not in DESIGN_KEYS:
            raise InputError(f"{where}: unknown key {key!r}; valid: {', '.join(DESIGN_KEYS)}")
        if key == "photos":
            if value not in PHOTO_MODES:
                raise InputError(f"{at}: must be one of {', '.join(PHOTO_MODES)}, got {value!r}")
        elif key == "trials_per_specimen" and value is None:
            pass
        elif key == "repose_rig":
            from demcal.simulate.virtual_lab import repose_geometries
            try:
                repose_geometries(value)            # checked now, used by write_virtual_workbook
            except InputError as exc:
                raise InputError(f"{where}.{exc}") from None
        elif key == "interleaved":
            if not isinstance(value, bool):
                raise InputError(f"{at}: must be true or false, got {value!r}")
        elif key in DESIGN_MIN_COUNTS:
            value = _count(value, at, DESIGN_MIN_COUNTS[key])
        elif key == "pairs":
            value = _labels(value, at, PAIRS)
        elif key == "surfaces":
            value = _labels(value, at, SURFACES)
        elif key == "drop_heights_mm":
            heights = value if isinstance(value, (list, tuple)) else [value]
            if not heights:
                raise InputError(f"{at}: must list at least one drop height [mm] > 0")
            value = [_in_range(h, at, 0.0, math.inf, False, False) for h in heights]
        elif key == "orientation_range_deg":
            if not isinstance(value, (list, tuple)) or len(value) != 2:
                raise InputError(f"{at}: must be [low, high] with 0 <= low <= high <= 90 deg, got {value!r}")
            lo, hi = (_in_range(v, at, 0.0, 90.0) for v in value)
            if lo > hi:
                raise InputError(f"{at}: must be [low, high] with 0 <= low <= high <= 90 deg, got {value!r}")
            value = [lo, hi]
        design[key] = value
    return design


def parse_truth(doc, where: str = "truth file") -> TruthFile:
    """A :class:`TruthFile` from the mapping of a truth file (see the module docstring)."""
    if doc is None:
        doc = {}
    if not isinstance(doc, dict):
        raise InputError(f"{where}: must be a mapping of Truth fields, params and design, got {type(doc).__name__}")
    fields = [f.name for f in dataclasses.fields(Truth)]
    known = fields + ["design"]
    kwargs = {}
    for key, value in doc.items():
        if key not in known:
            raise InputError(f"{where}: unknown key {key!r}; valid: {', '.join(known)}")
        if key == "design":
            continue
        if key == "params":
            kwargs[key] = parse_params(value, f"{where}: params")
        elif key in TRUTH_LEVELS:
            kwargs[key] = tuple(_labels(value, f"{where}: {key}"))
            if not kwargs[key]:
                raise InputError(f"{where}: {key}: must name at least one level")
        elif key in TRUTH_RANGES:
            kwargs[key] = _in_range(value, f"{where}: {key}", *TRUTH_RANGES[key])
        else:
            kwargs[key] = value
    design = parse_design(doc.get("design"), f"{where}: design")
    try:
        truth = Truth(**kwargs)
    except InputError as exc:
        raise InputError(f"{where}: {exc}") from None
    return TruthFile(truth=truth, design=design)


def read_truth_file(path) -> TruthFile:
    """Read and check a truth file (YAML, see the module docstring).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    TruthFile
    """
    import yaml

    path = Path(path)
    if not path.is_file():
        raise InputError(f"truth file not found: {path}")
    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise InputError(f"{path}: not valid YAML ({exc})") from None
    return dataclasses.replace(parse_truth(doc, str(path)), path=path)
