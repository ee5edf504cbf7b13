"""The lab workbook: reading and validating what the lab hands in (see docs/workbook.md).

A workbook is an ``.xlsx`` file or a folder with one ``<sheet>.csv`` per sheet, with the same
sheets and columns either way. Photos, force curves and camera tracks are paths relative to
the workbook (the folder holding the ``.xlsx``, or the CSV folder itself).

Rules applied by :func:`read_workbook`:

- Sheet and column names are matched case-insensitively and stored under the names of
  docs/workbook.md; every other column of a known sheet is a covariate, kept with its row.
  Covariates whose non-empty cells are all numbers become numbers; dates become ISO text.
- ``meta`` and ``specimens`` must be present; every other known sheet is optional, but if
  present its required columns must be there. Sheets we do not know are kept and listed in
  ``Workbook.unknown_sheets``.
- Rows are numbered from 1 = the first row under the header, as in the spreadsheet; fully
  empty rows are skipped (the numbering of the others does not change).
- Cells are read by :mod:`measure.rawsheets` within stated bounds (file size, what an .xlsx
  unpacks to, characters per cell); CSV records must have the header's field count, and the
  separator and decimal mark are given (:class:`ReadOptions`) or detected and stated in
  ``Workbook.notes``. Hidden rows, columns and sheets, and cells merged within a column, are read
  with a note naming them; cells merged across columns, and formulas without a stored value in
  a known column, are refused.
- A required cell must not be empty (exceptions: in ``drop``, the heights of a row with a
  ``track_file``; in ``incline``, a row gives either ``angle_deg`` or all of ``slope_deg``,
  ``release_height_mm``, ``runout_mm``, and roll-out rows must have mode ``roll``).
- Numeric cells must be finite numbers within the plausible range of their column
  (:data:`RANGES`, overridable); sizes, masses, volumes and drop heights must be positive; a
  rebound height may be 0 (no rebound, e = 0) but not negative nor above its drop height;
  ``volume_after_ml`` must exceed ``volume_before_ml``; a compressed specimen's thickness must
  change; angles must lie strictly between 0 and 90 degrees. Covariate numbers must lie within
  +-:data:`COVARIATE_LIMIT`; a missing-value marker (``NaN``, ``n/a``...) among them reads as
  empty, and text among numbers makes the column text; both with a note.
- Ids (``specimen_id``, ``sample_id``, ``trial_id``, ``photo_id``; a compressed specimen once
  per axis) are unique within their sheet, and no file is named twice in one column.
- Names, ids, headers, sheet names, paths and the meta ``material`` hold no line break or other
  control character (they reach exports and the terminal); in covariate text such characters
  read as spaces, with a note.
- Names: ``pair`` is ``particle-<material>`` and ``surface`` is ``particle`` or a material,
  where a material name is a letter followed by letters, digits or ``_`` (case is ignored, so
  ``Steel`` is ``steel``). Anything else (empty, ``steel`` as a pair, ``particle steel``, a
  number) is unknown. ``mode`` is ``slide`` or ``roll``, ``axis`` ``radial`` or ``axial``,
  ``side`` ``left``, ``right`` or ``both`` (empty means ``both``).
- ``compression`` may carry the segment's ``length_mm`` (used for the radial contact area;
  otherwise it is taken from the ``specimens`` row with the same ``specimen_id``).
- Referenced files (paths relative to the workbook; ``\\`` separators accepted) must resolve,
  links followed, inside the workbook's folder (or a folder allowed in :class:`ReadOptions`),
  checked before the file is opened; they must exist and be readable: a photo's header must
  name an image within the pixel limit (decoded once, later, by the estimator), a curve or track
  must be a CSV with its columns (``displacement_mm``, ``force_N``; ``t_s``, ``y_mm``, optional
  ``angle_deg``) holding numbers, at least 3 rows.

Every violation raises :class:`demcal.errors.WorkbookError` naming the file, sheet, data row,
column and value.
"""

from __future__ import annotations

import datetime as _dt
import functools
import math
import numbers
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from demcal.errors import InputError, WorkbookError
from demcal.measure import rawsheets
from demcal.measure.rawsheets import RawSheet, is_missing_marker, row_ranges
from demcal.provenance import sha256_file
from demcal.simulate.shapes import DEFAULT_SHAPE, shape_class, size_columns
from demcal.simulate.shapes.base import SpecimenError
from demcal.text import control_characters, one_line

#: A material name: a letter, then letters, digits or underscores (lower case after reading).
NAME_PATTERN = re.compile(r"[a-z][a-z0-9_]*")
MODES = ("slide", "roll")
AXES = ("radial", "axial")
SIDES = ("left", "right", "both", "drum")
#: What carries the particle down an incline: the particle itself, or a sled of glued particles.
CARRIERS = ("particle", "sled")
ROLLOUT_COLUMNS = ("slope_deg", "release_height_mm", "runout_mm")
#: Calliper columns of the ``specimens`` sheet, those of every shape; the meta ``shape`` says
#: which it needs.
SIZE_COLUMNS = size_columns()


@dataclass(frozen=True)
class SheetSpec:
    """What a known sheet must hold."""

    required: tuple = ()
    optional: tuple = ()
    ids: tuple = ()          # identifiers, kept as text
    positive: tuple = ()     # numbers > 0
    nonnegative: tuple = ()  # numbers >= 0
    numeric: tuple = ()      # other numbers
    angles: tuple = ()       # numbers in (0, 90) [deg]
    choices: tuple = ()      # name columns checked by _check_choice
    files: tuple = ()        # (column, kind) with kind "photo", "curve" or "track"

    @property
    def numbers(self) -> tuple:
        return self.positive + self.nonnegative + self.numeric + self.angles


SHEETS = {
    "meta": SheetSpec(required=("key", "value")),
    # the size columns required are those of the meta's shape (simulate.shapes)
    "specimens": SheetSpec(required=("specimen_id", "mass_g"), optional=SIZE_COLUMNS,
                           ids=("specimen_id",), positive=SIZE_COLUMNS + ("mass_g",)),
    # sphere centres and radii of one reference particle, for the meta shape clump
    "clump": SheetSpec(required=("x_mm", "y_mm", "z_mm", "radius_mm"), optional=("sphere_id",),
                       ids=("sphere_id",), positive=("radius_mm",), numeric=("x_mm", "y_mm", "z_mm")),
    "density": SheetSpec(required=("sample_id", "mass_g", "volume_before_ml", "volume_after_ml"),
                         ids=("sample_id",),
                         positive=("mass_g", "volume_before_ml", "volume_after_ml")),
    "drop": SheetSpec(required=("trial_id", "pair", "drop_height_mm", "rebound_height_mm"),
                      optional=("track_file",), ids=("trial_id",), positive=("drop_height_mm",),
                      nonnegative=("rebound_height_mm",), choices=("pair",),
                      files=(("track_file", "track"),)),
    "incline": SheetSpec(required=("trial_id", "surface", "mode"),
                         optional=("angle_deg", "carrier") + ROLLOUT_COLUMNS, ids=("trial_id",),
                         positive=("release_height_mm",), nonnegative=("runout_mm",),
                         angles=("angle_deg", "slope_deg"), choices=("surface", "mode", "carrier")),
    "compression": SheetSpec(required=("specimen_id", "axis", "width_before_mm", "width_after_mm",
                                       "thickness_before_mm", "thickness_after_mm"),
                             optional=("curve_file", "length_mm"), ids=("specimen_id",),
                             positive=("width_before_mm", "width_after_mm", "thickness_before_mm",
                                       "thickness_after_mm", "length_mm"),
                             choices=("axis",), files=(("curve_file", "curve"),)),
    "repose": SheetSpec(required=("photo_id", "file"),
                        optional=("side", "rig", "scale_mm_per_px", "angle_deg_manual"), ids=("photo_id",),
                        positive=("scale_mm_per_px",), angles=("angle_deg_manual",),
                        choices=("side", "rig"), files=(("file", "photo"),)),
}

#: Sheets every workbook must have.
REQUIRED_SHEETS = ("meta", "specimens")

#: Columns of the CSV files a workbook points to: (required, optional).
ATTACHMENTS = {"curve": (("displacement_mm", "force_N"), ()),
               "track": (("t_s", "y_mm"), ("angle_deg",))}

#: Meta keys we check when present (others are kept as read).
META_POSITIVE = ("contact_density_kg_m3", "contact_shear_modulus_pa", "particle_shear_modulus_pa",
                 "box_length_mm", "box_width_mm", "box_height_mm", "plate_lift_speed_mm_s",
                 "fill_count", "time_step_s", "spheres_per_particle")
#: Meta keys that must be whole numbers.
META_WHOLE = ("fill_count", "spheres_per_particle")

#: Physically plausible range of each number, inclusive, in the unit its name carries: wide
#: enough for anything from a rapeseed to a tuber and a lab's rigs, narrow enough that a typo
#: (1e308 mm, a diameter in m) is refused naming its cell instead of overflowing an estimate.
#: Listed in docs/workbook.md; ``--range NAME=LO:HI`` widens or narrows one.
RANGES = {
    # specimens and compression [mm, g]
    "length_mm": (0.05, 1000.0), "diameter_mm": (0.05, 1000.0), "mass_g": (1e-6, 1e4),
    "width_mm": (0.05, 1000.0), "thickness_mm": (0.05, 1000.0),
    # clump sheet [mm] (its y_mm shares the range of a track's, below)
    "x_mm": (-1e6, 1e6), "z_mm": (-1e6, 1e6), "radius_mm": (0.01, 1000.0),
    "width_before_mm": (0.05, 1000.0), "width_after_mm": (0.05, 1000.0),
    "thickness_before_mm": (0.05, 1000.0), "thickness_after_mm": (0.05, 1000.0),
    # density [ml]
    "volume_before_ml": (1e-3, 1e6), "volume_after_ml": (1e-3, 1e6),
    # drop and incline [mm]
    "drop_height_mm": (1.0, 1e5), "rebound_height_mm": (0.0, 1e5),
    "release_height_mm": (0.1, 1e5), "runout_mm": (0.0, 1e5),
    # repose photos [mm/px]
    "scale_mm_per_px": (1e-4, 100.0),
    # meta [kg/m^3, Pa, mm, mm/s, particles]
    "contact_density_kg_m3": (10.0, 1e5), "contact_shear_modulus_pa": (1e3, 1e13),
    "particle_shear_modulus_pa": (1e3, 1e13), "box_length_mm": (1.0, 1e5),
    "box_width_mm": (1.0, 1e5), "box_height_mm": (1.0, 1e5), "plate_lift_speed_mm_s": (1e-3, 1e5),
    "fill_count": (1.0, 1e6), "time_step_s": (1e-9, 1e-2), "spheres_per_particle": (1.0, 100.0),
    # curve and track files [mm, N, s, deg]
    "displacement_mm": (-1e3, 1e3), "force_N": (-1e6, 1e6), "t_s": (-1e4, 1e4),
    "y_mm": (-1e6, 1e6), "track.angle_deg": (-1e6, 1e6),
}
#: Largest magnitude of a number in a covariate column: a covariate has no stated unit, but
#: its squares must stay finite in the diagnosis' regressions.
COVARIATE_LIMIT = 1e12


@dataclass(frozen=True)
class ReadOptions:
    """How a workbook is read: the choices the user may make, recorded in provenance so that
    a campaign's workbook is read again (by ``audit``, ``critique``) exactly as it was.

    Attributes
    ----------
    csv_separator, csv_decimal : str or None
        CSV separator (``,`` ``;`` or a tab) and decimal mark (``.`` or ``,``); None detects
        them (see :func:`measure.rawsheets.read_csv`).
    ranges : dict of str -> (float, float)
        Plausible ranges that replace those of :data:`RANGES`, by column or meta key.
    allowed_folders : tuple of str
        Folders outside the workbook's own that photo, curve and track paths may point into.
    max_photo_pixels : int
        Largest photo read, width x height [pixels] (checked from the file's header).
    max_file_bytes : int
        Largest workbook file read; also the largest an .xlsx may unpack to [bytes].
    """

    csv_separator: str | None = None
    csv_decimal: str | None = None
    ranges: dict = field(default_factory=dict)
    allowed_folders: tuple = ()
    max_photo_pixels: int | None = None
    max_file_bytes: int = rawsheets.MAX_FILE_BYTES

    def __post_init__(self):
        if self.csv_separator not in (None, *rawsheets.SEPARATORS):
            raise InputError(f"CSV separator {self.csv_separator!r}: valid are ',', ';' and a tab")
        if self.csv_decimal not in (None, *rawsheets.DECIMAL_MARKS):
            raise InputError(f"CSV decimal mark {self.csv_decimal!r}: valid are '.' and ','")
        if self.csv_decimal == "," and self.csv_separator == ",":
            raise InputError("a CSV cannot have ',' as both its separator and its decimal mark")
        for name, bounds in self.ranges.items():
            lo, hi = bounds
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise InputError(f"range of {name}: need finite LO < HI, got {lo!r}:{hi!r}")
        if not self.max_file_bytes > 0:
            raise InputError(f"the largest workbook file must be positive, got {self.max_file_bytes}")

    def range_of(self, name: str):
        """The plausible (lo, hi) of a column or meta key, or None when it has none."""
        return self.ranges.get(name, RANGES.get(name))

    def to_dict(self) -> dict:
        return {"csv_separator": self.csv_separator, "csv_decimal": self.csv_decimal,
                "ranges": {k: list(v) for k, v in self.ranges.items()},
                "allowed_folders": list(self.allowed_folders),
                "max_photo_pixels": self.max_photo_pixels, "max_file_bytes": self.max_file_bytes}

    @classmethod
    def from_dict(cls, d: dict | None) -> "ReadOptions":
        d = dict(d or {})
        return cls(csv_separator=d.get("csv_separator"), csv_decimal=d.get("csv_decimal"),
                   ranges={k: tuple(v) for k, v in d.get("ranges", {}).items()},
                   allowed_folders=tuple(d.get("allowed_folders", ())),
                   max_photo_pixels=d.get("max_photo_pixels"),
                   max_file_bytes=d.get("max_file_bytes", rawsheets.MAX_FILE_BYTES))


@dataclass(frozen=True)
class Sheet:
    """One sheet of a workbook.

    Attributes
    ----------
    name : str
        Sheet name (docs/workbook.md spelling for known sheets).
    file : Path
        The file the sheet was read from (the ``.xlsx`` or the sheet's CSV).
    sha256 : str
        SHA-256 of that file.
    frame : pandas.DataFrame
        The non-empty rows, indexed by data-row number (1 = first row under the header).
        Numeric columns hold floats (NaN = empty cell); text columns hold str or None.
    required : list of str
        Required columns of the sheet (for ``incline``, those of the variants present).
    optional : list of str
        Optional columns of docs/workbook.md present in the sheet (files, manual readings).
    covariates : list of str
        Every other column: kept with each row and offered to the diagnosis.
    """

    name: str
    file: Path
    sha256: str
    frame: pd.DataFrame
    required: list
    optional: list
    covariates: list

    @property
    def rows(self) -> list:
        """Data-row numbers of the non-empty rows."""
        return [int(r) for r in self.frame.index]

    def source(self) -> dict:
        """``{"file", "sheet", "sha256"}`` for an estimate's provenance."""
        return {"file": str(self.file), "sheet": self.name, "sha256": self.sha256}

    def covariates_of(self, row: int) -> dict:
        """Covariate values of one row (empty cells as None)."""
        return dict(self._covariate_rows[row])

    @functools.cached_property
    def _covariate_rows(self) -> dict:
        # built once: a frame lookup per cell costs more than the estimators that ask
        columns = {c: [_plain(v) for v in self.frame[c].tolist()] for c in self.covariates}
        return {int(r): {c: columns[c][i] for c in self.covariates} for i, r in enumerate(self.frame.index)}

    def column(self, name: str) -> dict:
        """``{row: frame.at[row, name]}``, the same values and types, taken once per column:
        the estimators read their cells row by row, and a frame lookup per cell costs more
        than the estimate."""
        columns = self.__dict__.setdefault("_columns", {})
        if name not in columns:
            columns[name] = dict(zip(self.rows, self.frame[name].to_numpy()))
        return columns[name]

    def error(self, message, *, row=None, column=None, value=None) -> WorkbookError:
        """A :class:`WorkbookError` located in this sheet."""
        return WorkbookError(message, file=str(self.file), sheet=self.name, row=row,
                             column=column, value=value)


@dataclass(frozen=True)
class Workbook:
    """A validated lab workbook.

    Attributes
    ----------
    source : Path
        The ``.xlsx`` file or the CSV folder.
    root : Path
        Folder that photo, curve and track paths are relative to.
    meta : dict
        ``meta`` sheet, key -> value (numbers parsed; empty values are None).
    sheets : dict of str -> Sheet
        Every sheet read, known and unknown.
    unknown_sheets : list of str
        Names of the sheets this version does not know (kept in ``sheets`` too).
    files : dict of str -> str
        Path -> SHA-256 of every file read: the workbook, every CSV sheet, every referenced
        photo, curve and track.
    attachments : dict of str -> pandas.DataFrame
        Parsed curve and track CSVs by path (the keys of ``files``), columns in lab units.
    notes : list of str
        What reading did that the user should know: hidden rows and sheets, merged cells, a
        detected decimal comma, covariate cells read as missing or as text.
    options : ReadOptions
        How the workbook was read.
    """

    source: Path
    root: Path
    meta: dict
    sheets: dict
    unknown_sheets: list
    files: dict
    attachments: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    options: ReadOptions = field(default_factory=ReadOptions)

    def sheet(self, name: str) -> Sheet | None:
        """The sheet ``name``, or None if the workbook does not have it."""
        return self.sheets.get(name)

    def resolve(self, relative) -> Path:
        """A path written in the workbook, resolved from :attr:`root` (links followed)."""
        return _resolve(self.root, relative)

    def attachment(self, relative) -> pd.DataFrame:
        """The parsed curve or track CSV that a cell points to."""
        return self.attachments[str(self.resolve(relative))]


# ----------------------------------------------------------------------------------------------
# cells

def _is_empty(cell) -> bool:
    if isinstance(cell, str):     # most cells: checked first, it is the cheap test
        return not cell.strip()
    if cell is None:
        return True
    if isinstance(cell, float) and math.isnan(cell):
        return True
    if cell is pd.NaT:
        return True
    try:
        return bool(pd.isna(cell)) if not isinstance(cell, bytes) else False
    except (TypeError, ValueError):
        return False


def _resolve(root: Path, text) -> Path:
    """A path cell relative to ``root``, resolved (links followed); Windows separators are
    accepted."""
    p = Path(str(text).replace("\\", "/"))
    return (p if p.is_absolute() else root / p).resolve()


def _outside(path: Path, root: Path, allowed: tuple) -> bool:
    """True when ``path`` (resolved) lies outside ``root`` and every allowed folder."""
    return not any(path.is_relative_to(Path(folder).resolve()) for folder in (root, *allowed))


def _plain(value):
    """A frame cell as a plain Python value for JSON (NaN -> None)."""
    if value is None:
        return None
    if isinstance(value, (float, np.floating)):
        return None if math.isnan(value) else float(value)
    if isinstance(value, np.integer):
        return int(value)
    return value


def _number(cell) -> float:
    """A cell as a finite float; raises ValueError if it is not one."""
    if isinstance(cell, str):     # a CSV's cells: checked first, before the abstract number test
        x = float(cell.strip())
    elif isinstance(cell, bool):
        raise ValueError("boolean")
    elif isinstance(cell, numbers.Real):
        x = float(cell)
    else:
        raise ValueError(type(cell).__name__)
    if not math.isfinite(x):
        raise ValueError("not finite")
    return x


def _text(cell) -> str:
    """A cell as text: integral numbers without '.0', dates in ISO form."""
    if isinstance(cell, bool):
        return str(cell)
    if isinstance(cell, numbers.Integral):
        return str(int(cell))
    if isinstance(cell, numbers.Real):
        x = float(cell)
        return str(int(x)) if x.is_integer() else repr(x)
    if isinstance(cell, (_dt.datetime, pd.Timestamp)):
        ts = pd.Timestamp(cell)
        return ts.date().isoformat() if ts == ts.normalize() else ts.isoformat()
    if isinstance(cell, _dt.date):
        return cell.isoformat()
    return str(cell).strip()


def _meta_value(cell):
    """A meta value: int or float when it reads as a number, else stripped text."""
    if _is_empty(cell):
        return None
    if isinstance(cell, numbers.Integral) and not isinstance(cell, bool):
        return int(cell)
    try:
        x = _number(cell)
    except ValueError:
        return _text(cell)
    # whole numbers as int, so xlsx (which stores floats) and CSV read alike
    return int(x) if x.is_integer() and abs(x) < 2**53 else x


def _name(cell) -> str | None:
    """A name cell in lower case, or None when empty."""
    return None if _is_empty(cell) else _text(cell).lower()


# ----------------------------------------------------------------------------------------------
# raw reading

def _check_text(text: str, where: dict, what: str) -> None:
    """Refuse a name, id, header or path holding a line break or another control character:
    such text would print as a fake line or end a comment in an export."""
    bad = control_characters(text)
    if bad:
        raise WorkbookError(f"{what} holds the control character(s) {' '.join(bad)} (a line break "
                            "or a tab typed into the cell?): remove them", **where, value=text)


def _canonical_columns(raw: pd.DataFrame, known: tuple, file: Path, sheet: str) -> pd.DataFrame:
    """Strip headers, map known columns case-insensitively, drop empty unnamed columns; the
    index (data-row numbers) is kept."""
    lookup = {k.lower(): k for k in known}
    names, keep = [], []
    for i, col in enumerate(raw.columns):
        header = "" if _is_empty(col) else str(col).strip()
        if not header:
            if raw.iloc[:, i].map(_is_empty).all():
                continue
            raise WorkbookError(f"column {i + 1} has data but no header", file=str(file), sheet=sheet,
                                column=f"#{i + 1}")
        _check_text(header, {"file": str(file), "sheet": sheet, "column": f"#{i + 1}"}, "the header")
        header = lookup.get(header.lower(), header)
        if header in names:
            raise WorkbookError(f"duplicate column: columns {names.index(header) + 1} and {i + 1} "
                                "have this header", file=str(file), sheet=sheet, column=header)
        names.append(header)
        keep.append(i)
    frame = raw.iloc[:, keep].copy()
    frame.columns = names
    return frame


def _drop_empty_rows(frame: pd.DataFrame) -> pd.DataFrame:
    if frame.shape[1] == 0:
        return frame.iloc[0:0]
    empty = frame.map(_is_empty).all(axis=1)
    return frame.loc[~empty.to_numpy(bool)]


# ----------------------------------------------------------------------------------------------
# validation

def _rig_dimension(key: str) -> str:
    """The meta key whose checks apply to ``key``: a repose rig's own name of a dimension
    several rigs share (``drum_fill_count``, ``simulate.rigs.meta_names``) is checked as that
    dimension (``fill_count``); any other key as itself."""
    from demcal.simulate.rigs import repose_rig_names

    for name in repose_rig_names():
        if key.startswith(name + "_") and key[len(name) + 1:] in META_POSITIVE:
            return key[len(name) + 1:]
    return key


def _check_choice(column: str, value: str | None) -> str | None:
    """Return an error message if ``value`` is not a valid name for this column."""
    if column == "pair":
        if value and value.startswith("particle-") and NAME_PATTERN.fullmatch(value[len("particle-"):]):
            return None
        return ("unknown pair; valid: particle-particle, particle-steel, particle-rubber or "
                "particle-<material> (material: a letter then letters, digits or _)")
    if column == "surface":
        if value and NAME_PATTERN.fullmatch(value):
            return None
        return ("unknown surface; valid: particle, steel or another material name "
                "(a letter then letters, digits or _)")
    if column == "rig":
        from demcal.simulate.rigs import repose_rig_names

        valid = repose_rig_names()
        if value is None or value in valid:     # a blank rig: the meta's first repose rig
            return None
        return f"unknown rig; valid: {', '.join(valid)}"
    valid = {"mode": MODES, "axis": AXES, "side": SIDES, "carrier": CARRIERS}[column]
    if value in valid:
        return None
    return f"unknown {column}; valid: {', '.join(valid)}"


def _typed_frame(name: str, spec: SheetSpec, raw: RawSheet, frame: pd.DataFrame, file: Path,
                 options: ReadOptions, notes: list) -> pd.DataFrame:
    """Convert and check every cell of a known sheet; covariates are typed loosely."""
    out = {}
    numbers_ = set(spec.numbers)
    known = set(spec.ids) | set(spec.required) | set(spec.optional)
    for (row, col), formula in raw.formulas_without_value.items():
        if col in known:
            raise WorkbookError("a formula without a stored value (the file was saved by a program "
                                "that does not calculate): open and save it in a spreadsheet "
                                "program, or type the value", file=str(file), sheet=name, row=row,
                                column=col, value=formula)
    for col in frame.columns:
        cells = frame[col]

        def err(message, row, cell):
            return WorkbookError(message, file=str(file), sheet=name, row=row, column=col, value=cell)

        if col in numbers_:
            values = []
            bounds = options.range_of(col)
            for row, cell in cells.items():
                if _is_empty(cell):
                    values.append(math.nan)
                    continue
                try:
                    x = _number(cell)
                except ValueError:
                    raise err("not a number", row, cell) from None
                if col in spec.positive and not x > 0:
                    raise err("must be positive", row, cell)
                if col in spec.nonnegative and x < 0:
                    raise err("must not be negative", row, cell)
                if col in spec.angles and not 0 < x < 90:
                    raise err("angle must lie strictly between 0 and 90 degrees", row, cell)
                if bounds is not None and not bounds[0] <= x <= bounds[1]:
                    raise err(f"outside the plausible range {bounds[0]:g} to {bounds[1]:g} "
                              f"(docs/workbook.md; --range {col}=LO:HI sets another)", row, cell)
                values.append(x)
            out[col] = pd.Series(values, index=frame.index, dtype=float)
        elif col in spec.choices:
            values = []
            for row, cell in cells.items():
                value = _name(cell)
                if value is None and col == "side":
                    value = "both"
                if value is None and col == "carrier":
                    value = "particle"
                problem = _check_choice(col, value)
                if problem:
                    raise err(problem, row, None if _is_empty(cell) else cell)
                values.append(value)
            out[col] = pd.Series(values, index=frame.index, dtype=object)
        elif col in known:
            values = []
            for row, cell in cells.items():
                value = None if _is_empty(cell) else _text(cell)
                if value is not None:
                    _check_text(value, {"file": str(file), "sheet": name, "row": row, "column": col},
                                "the cell")
                values.append(value)
            out[col] = pd.Series(values, index=frame.index, dtype=object)
        else:
            out[col] = _covariate(name, col, cells, file, notes)
    formulas = sorted(r for (r, c) in raw.formulas_without_value if c not in known)
    if formulas:
        notes.append(f"sheet '{name}': row(s) {row_ranges(formulas)} hold formulas without a "
                     "stored value in covariate columns; they read as empty (open and save the file "
                     "in a spreadsheet program to store their values)")
    return pd.DataFrame(out, index=frame.index)


def _covariate(sheet: str, column: str, cells: pd.Series, file: Path, notes: list) -> pd.Series:
    """A covariate column: numbers if every non-empty cell is one (a missing-value marker such
    as ``NaN`` or ``n/a`` among numbers reads as empty), else text; either way with a note
    naming the cells that decided it."""
    present = {row: c for row, c in cells.items() if not _is_empty(c)}
    numeric, text = {}, {}
    for row, c in present.items():
        try:
            numeric[row] = _number(c)
        except ValueError:
            text[row] = c
    for row, x in numeric.items():
        if abs(x) > COVARIATE_LIMIT:
            raise WorkbookError(f"a covariate number must lie within +-{COVARIATE_LIMIT:g}",
                                file=str(file), sheet=sheet, row=row, column=column, value=present[row])
    markers = {row: c for row, c in text.items() if isinstance(c, str) and is_missing_marker(c)}
    if not text or (numeric and len(markers) == len(text)):
        if markers:
            notes.append(f"sheet '{sheet}', column '{column}': row(s) {row_ranges(markers)} "
                         f"({', '.join(sorted({repr(m) for m in markers.values()}))}) read as missing numbers")
        return pd.Series([numeric.get(row, math.nan) for row in cells.index], index=cells.index,
                         dtype=float)
    if numeric and text:
        shown = ", ".join(f"row {r}: {one_line(text[r], limit=40)!r}" for r in list(text)[:3])
        notes.append(f"sheet '{sheet}', column '{column}' is read as text, not numbers, because of "
                     f"{len(text)} cell(s) ({shown}{', ...' if len(text) > 3 else ''})")
    values, cleaned = [], []
    for row in cells.index:
        if row not in present:
            values.append(None)
            continue
        value = _text(present[row])
        if control_characters(value):
            cleaned.append(row)
            value = one_line(value, limit=rawsheets.MAX_CELL_CHARS)
        values.append(value)
    if cleaned:
        notes.append(f"sheet '{sheet}', column '{column}': line breaks and control characters in "
                     f"row(s) {row_ranges(cleaned)} read as spaces")
    return pd.Series(values, index=cells.index, dtype=object)


def _cells(frame: pd.DataFrame, column: str) -> dict:
    """``{row: frame.at[row, column]}``, the same values and types, in one pass over the column."""
    return dict(zip(frame.index, frame[column].to_numpy()))


def _require_cells(name: str, frame: pd.DataFrame, columns, file: Path, rows=None):
    for col in columns:
        for row, cell in frame[col].items():
            if (rows is None or row in rows) and _is_empty(cell):
                raise WorkbookError("missing value", file=str(file), sheet=name, row=row, column=col)


def _row_rules(name: str, frame: pd.DataFrame, file: Path, required, meta: dict) -> None:
    """Checks across the cells of a row, and required cells that may be empty in some rows."""
    def err(message, row, column, value=None):
        return WorkbookError(message, file=str(file), sheet=name, row=row, column=column, value=value)

    spec = SHEETS[name]
    if name == "drop":
        has_track = frame["track_file"].notna() if "track_file" in frame else pd.Series(False, index=frame.index)
        _require_cells(name, frame, ("trial_id", "pair"), file)
        _require_cells(name, frame, ("drop_height_mm", "rebound_height_mm"), file,
                       rows=set(frame.index[~has_track]))
        for row in frame.index:
            h1, h2 = frame.at[row, "drop_height_mm"], frame.at[row, "rebound_height_mm"]
            if h2 > h1:  # False when either is NaN
                raise err(f"rebound height above its drop height ({h1:g} mm)", row,
                          "rebound_height_mm", h2)
        return
    if name == "incline":
        _require_cells(name, frame, spec.required, file)
        cell = {c: _cells(frame, c) for c in ("angle_deg", "carrier", "mode", *ROLLOUT_COLUMNS) if c in frame}
        for row in frame.index:
            has_angle = "angle_deg" in cell and not math.isnan(cell["angle_deg"][row])
            rollout = [c for c in ROLLOUT_COLUMNS if c in cell and not math.isnan(cell[c][row])]
            if has_angle and rollout:
                raise err("give either angle_deg or the roll-out columns, not both", row,
                          rollout[0], cell[rollout[0]][row])
            if not has_angle and not rollout:
                raise err("missing value (or give slope_deg, release_height_mm and runout_mm "
                          "for a roll-out trial)", row, "angle_deg")
            if "carrier" in cell and cell["carrier"][row] == "sled" and cell["mode"][row] != "slide":
                raise err("a sled of glued particles measures static friction: mode must be slide", row,
                          "carrier", "sled")
            if rollout:
                missing = [c for c in ROLLOUT_COLUMNS if c not in rollout]
                if missing:
                    raise err("missing value of a roll-out trial", row, missing[0])
                if cell["mode"][row] != "roll":
                    raise err("a roll-out trial measures rolling friction: mode must be roll",
                              row, "mode", cell["mode"][row])
        return
    _require_cells(name, frame, required, file)
    if name == "specimens":
        shape = shape_class(meta.get("shape") or DEFAULT_SHAPE)
        sizes = [c for c in required if c in SIZE_COLUMNS]
        for row in frame.index:
            try:
                shape.check_specimen({c: frame.at[row, c] for c in sizes})
            except SpecimenError as exc:
                raise err(exc.reason, row, exc.column, frame.at[row, exc.column]) from None
    if name == "density":
        for row in frame.index:
            v0, v1 = frame.at[row, "volume_before_ml"], frame.at[row, "volume_after_ml"]
            if not v1 > v0:
                raise err(f"volume after immersion must exceed the volume before ({v0:g} ml)", row,
                          "volume_after_ml", v1)
    if name == "compression":
        for row in frame.index:
            t0, t1 = frame.at[row, "thickness_before_mm"], frame.at[row, "thickness_after_mm"]
            if t1 == t0:
                raise err("thickness did not change: Poisson's ratio is undefined", row,
                          "thickness_after_mm", t1)


def _required_columns(name: str, columns: list, file: Path, meta: dict) -> list:
    spec = SHEETS[name]
    required = list(spec.required)
    if name == "specimens":
        shape = shape_class(meta.get("shape") or DEFAULT_SHAPE)
        options = shape.specimen_columns
        chosen = next((o for o in options if set(o) <= set(columns)), None)
        if chosen is None:
            wanted = " or ".join("(" + ", ".join(o) + ")" for o in options)
            missing = next(c for c in options[0] if c not in columns)
            raise WorkbookError(f"missing required column: shape {shape.name} (meta shape) is measured by "
                                f"{wanted}", file=str(file), sheet=name, column=missing)
        required[1:1] = list(chosen)
    if name == "incline":
        has_rollout = [c for c in ROLLOUT_COLUMNS if c in columns]
        if has_rollout:
            missing = [c for c in ROLLOUT_COLUMNS if c not in columns]
            if missing:
                raise WorkbookError("missing column of the roll-out variant", file=str(file),
                                    sheet=name, column=missing[0])
            required += list(ROLLOUT_COLUMNS)
        if "angle_deg" in columns:
            required.insert(3, "angle_deg")
        elif not has_rollout:
            raise WorkbookError("missing column (or slope_deg, release_height_mm and runout_mm "
                                "for roll-out trials)", file=str(file), sheet=name, column="angle_deg")
    for col in required:
        if col not in columns:
            raise WorkbookError("missing required column", file=str(file), sheet=name, column=col)
    return required


#: Meta values that name things and so reach exports, reports and the terminal verbatim.
META_NAMES = ("material", "contact_material")


def _parse_meta(frame: pd.DataFrame, file: Path, options: ReadOptions) -> dict:
    meta, seen = {}, {}
    for row in frame.index:
        key, cell = frame.at[row, "key"], frame.at[row, "value"]
        if _is_empty(key):
            raise WorkbookError("missing key", file=str(file), sheet="meta", row=row, column="key",
                                value=None if _is_empty(cell) else cell)
        key = _text(key).lower()
        _check_text(key, {"file": str(file), "sheet": "meta", "row": row, "column": "key"}, "the key")
        if key in seen:
            raise WorkbookError(f"duplicate key (first in row {seen[key]})", file=str(file),
                                sheet="meta", row=row, column="key", value=key)
        seen[key] = row
        value = _text(cell) if key == "material" and not _is_empty(cell) else _meta_value(cell)
        if key in META_NAMES and isinstance(value, str):
            _check_text(value, {"file": str(file), "sheet": "meta", "row": row, "column": "value"},
                        f"meta {key}")

        def bad(message):
            return WorkbookError(f"meta {key}: {message}", file=str(file), sheet="meta", row=row,
                                 column="value", value=cell)

        rule = _rig_dimension(key)      # drum_fill_count is checked as fill_count
        if rule in META_POSITIVE or rule in ("contact_poisson", "target_repose_deg"):
            if value is not None and not isinstance(value, (int, float)):
                raise bad("not a number")
            if value is not None:
                if rule in META_POSITIVE and not value > 0:
                    raise bad("must be positive")
                if rule in META_WHOLE and not float(value).is_integer():
                    raise bad("must be a whole number")
                if rule == "contact_poisson" and not -1 < value < 0.5:
                    raise bad("a Poisson's ratio must lie in (-1, 0.5)")
                if rule == "target_repose_deg" and not 0 < value < 90:
                    raise bad("angle must lie strictly between 0 and 90 degrees")
                bounds = options.range_of(key) or options.range_of(rule)
                if bounds is not None and not bounds[0] <= value <= bounds[1]:
                    raise bad(f"outside the plausible range {bounds[0]:g} to {bounds[1]:g} "
                              f"(docs/workbook.md; --range {key}=LO:HI sets another)")
        if key == "shape" and value is not None:
            try:
                value = shape_class(value).name
            except InputError as exc:
                raise bad(str(exc)) from None
        meta[key] = value
    if meta.get("spheres_per_particle") is not None:
        try:
            shape_class(meta.get("shape") or DEFAULT_SHAPE).check_spheres(int(meta["spheres_per_particle"]))
        except InputError as exc:
            raise WorkbookError(f"meta spheres_per_particle: {exc}", file=str(file), sheet="meta",
                                row=seen["spheres_per_particle"], column="value",
                                value=meta["spheres_per_particle"]) from None
    if not isinstance(meta.get("material"), str) or not meta["material"]:
        raise WorkbookError("meta key 'material' is missing or empty", file=str(file), sheet="meta",
                            row=seen.get("material"), column="value" if "material" in seen else "key",
                            value=meta.get("material"))
    return meta


def _read_attachment(kind: str, path: Path, options: ReadOptions, notes: list) -> pd.DataFrame:
    """Parse a curve or track CSV; raises ValueError with a readable reason."""
    required, optional = ATTACHMENTS[kind]
    try:
        raw = rawsheets.read_csv(path, sheet=kind, separator=options.csv_separator,
                                 decimal=options.csv_decimal, max_bytes=options.max_file_bytes)
        frame = _drop_empty_rows(_canonical_columns(raw.frame, required + optional, path, kind))
    except WorkbookError as exc:
        raise ValueError(str(exc)) from None
    notes.extend(raw.notes)
    for col in required:
        if col not in frame.columns:
            raise ValueError(f"lacks column '{col}' (needs {', '.join(required)})")
    out = {}
    for col in required + tuple(c for c in optional if c in frame.columns):
        bounds = options.range_of(f"track.{col}" if kind == "track" and col == "angle_deg" else col)
        values = []
        for row, cell in frame[col].items():
            try:
                x = _number(cell)
            except ValueError:
                if _is_empty(cell) and col in optional:
                    values.append(math.nan)
                    continue
                raise ValueError(f"data row {row}, column '{col}': not a number ({cell!r})") from None
            if bounds is not None and not bounds[0] <= x <= bounds[1]:
                raise ValueError(f"data row {row}, column '{col}': {x:g} is outside the plausible "
                                 f"range {bounds[0]:g} to {bounds[1]:g} (--range sets another)")
            values.append(x)
        out[col] = values
    table = pd.DataFrame(out, index=frame.index, dtype=float)
    if len(table) < 3:
        raise ValueError(f"has {len(table)} data rows; at least 3 are needed")
    return table


def _check_files(wb: dict, name: str, spec: SheetSpec, frame: pd.DataFrame, file: Path) -> None:
    """Resolve, bound and read every file a sheet points to, before any is opened: a path
    must lead (links followed) into the workbook's folder or a folder the user allowed."""
    from demcal.measure.images import MAX_PHOTO_PIXELS, check_image

    root, options = wb["root"], wb["options"]
    for column, kind in spec.files:
        if column not in frame:
            continue
        first: dict = {}
        for row, rel in frame[column].items():
            if rel is None:
                if column in spec.required:
                    raise WorkbookError("missing value", file=str(file), sheet=name, row=row, column=column)
                continue

            def err(message):
                return WorkbookError(f"{kind} file {message}", file=str(file), sheet=name, row=row,
                                     column=column, value=rel)

            path = _resolve(root, rel)
            if _outside(path, root, options.allowed_folders):
                raise err(f"lies outside the workbook's folder {root} ({path}): copy it into the "
                          "folder, or allow its folder with --allow-folder")
            if path in first:
                raise err(f"is the same file as row {first[path]}'s")
            first[path] = row
            if not path.is_file():
                raise err(f"not found: {path}")
            key = str(path)
            if key in wb["files"]:
                continue
            if kind == "photo":
                try:
                    check_image(path, options.max_photo_pixels or MAX_PHOTO_PIXELS)
                except (ValueError, OSError) as exc:
                    raise err(f"{path}: {exc}") from None
            else:
                try:
                    rawsheets.check_file_size(path, options.max_file_bytes)
                    wb["attachments"][key] = _read_attachment(kind, path, options, wb["notes"])
                except (ValueError, WorkbookError) as exc:
                    raise err(f"{path}: {exc}") from None
            wb["files"][key] = sha256_file(path)


def _check_unique(name: str, frame: pd.DataFrame, file: Path) -> None:
    """Refuse an id given twice, naming both rows (compression: a specimen once per axis)."""
    keys = {"specimens": ("specimen_id",), "density": ("sample_id",), "drop": ("trial_id",),
            "incline": ("trial_id",), "compression": ("specimen_id", "axis"),
            "repose": ("photo_id",), "clump": ("sphere_id",)}[name]
    if not set(keys) <= set(frame.columns):      # an optional id (a clump's sphere_id) not given
        return
    seen: dict = {}
    cells = [_cells(frame, k) for k in keys]
    for row in frame.index:
        key = tuple(cell[row] for cell in cells)
        if any(k is None for k in key):
            continue
        if key in seen:
            what = " on the same axis" if len(keys) > 1 else ""
            raise WorkbookError(f"duplicate {keys[0]}{what}: row {seen[key]} has it too",
                                file=str(file), sheet=name, row=row, column=keys[0], value=key[0])
        seen[key] = row


# ----------------------------------------------------------------------------------------------
# public API

def resolve_workbook(path) -> Path:
    """The workbook a path names: an ``.xlsx`` file, a folder of ``<sheet>.csv``, or a campaign
    folder holding no CSV sheets and exactly one ``.xlsx`` (e.g. ``data/astragalus``)."""
    source = Path(path)
    if source.is_dir() and not (source / "meta.csv").exists():
        books = sorted(p for p in source.glob("*.xls[xm]") if not p.name.startswith("~$"))
        if len(books) == 1:
            return books[0]
        if len(books) > 1:
            raise InputError(f"folder {source} holds {len(books)} workbooks "
                             f"({', '.join(p.name for p in books)}): name one")
    return source


def read_workbook(path, options: ReadOptions | None = None) -> Workbook:
    """Read and validate a lab workbook (``.xlsx`` or a folder of ``<sheet>.csv``).

    Parameters
    ----------
    path : str or Path
        The ``.xlsx`` file, the folder holding one CSV per sheet, or a folder holding one
        ``.xlsx`` (see :func:`resolve_workbook`).
    options : ReadOptions, optional
        CSV dialect, plausible ranges, extra folders and size limits (defaults: detected,
        :data:`RANGES`, none, :mod:`measure.rawsheets`' limits).

    Returns
    -------
    Workbook

    Raises
    ------
    WorkbookError
        For anything wrong in the workbook, naming file, sheet, row, column and value.
    InputError
        If ``path`` does not exist or is neither an ``.xlsx`` file nor a folder.
    """
    options = options or ReadOptions()
    source = resolve_workbook(path).absolute()  # absolute: provenance and audit work from any folder
    files: dict = {}
    notes: list = []
    if source.is_dir():
        root = source.resolve()
        csvs = {}
        for p in sorted(source.glob("*.csv")):
            if not p.is_file():
                continue
            if _outside(p.resolve(), root, ()):
                raise WorkbookError(f"the sheet is a link to {p.resolve()}, outside the workbook's "
                                    "folder", file=str(p), sheet=p.stem)
            _check_text(p.stem, {"file": str(p)}, "the sheet name")
            csvs[p.stem.strip()] = p
        raws = None
    elif source.is_file():
        if source.suffix.lower() not in (".xlsx", ".xlsm"):
            raise InputError(f"workbook {source}: expected an .xlsx file or a folder of CSV files")
        root = source.parent.resolve()
        rawsheets.check_file_size(source, options.max_file_bytes)
        raws = rawsheets.read_xlsx(source, max_unpacked_bytes=options.max_file_bytes)
        for n in raws:
            _check_text(n, {"file": str(source)}, "the sheet name")
        files[str(source)] = sha256_file(source)
        csvs = None
    else:
        raise InputError(f"workbook not found: {source}")

    names = list(raws) if raws is not None else list(csvs)
    by_key: dict = {}
    for n in names:
        key = n.strip().lower()
        if key in by_key:
            raise WorkbookError(f"two sheets named '{by_key[key]}' and '{n}'", file=str(source))
        by_key[key] = n
    for required in REQUIRED_SHEETS:
        if required not in by_key:
            where = source if raws is not None else source / f"{required}.csv"
            raise WorkbookError("missing sheet", file=str(where), sheet=required)

    def raw_sheet(original: str, name: str) -> RawSheet:
        if raws is not None:
            raw = raws[original]
        else:
            raw = rawsheets.read_csv(csvs[original], sheet=name, separator=options.csv_separator,
                                     decimal=options.csv_decimal, max_bytes=options.max_file_bytes)
            files[str(raw.file)] = sha256_file(raw.file)
        notes.extend(raw.notes)
        return raw

    state = {"root": root, "options": options, "files": files, "attachments": {}, "notes": notes}
    sheets: dict = {}
    meta: dict = {}
    for key in [k for k in SHEETS if k in by_key]:
        raw = raw_sheet(by_key[key], key)
        file = raw.file
        spec = SHEETS[key]
        frame = _drop_empty_rows(_canonical_columns(raw.frame, spec.required + spec.optional, file, key))
        required = _required_columns(key, list(frame.columns), file, meta)
        if key in REQUIRED_SHEETS and frame.empty:
            raise WorkbookError("the sheet has no data rows", file=str(file), sheet=key)
        if key == "meta":
            meta = _parse_meta(frame, file, options)
            typed = pd.DataFrame({"key": [_text(k).lower() for k in frame["key"]],
                                  "value": [_meta_value(v) for v in frame["value"]]},
                                 index=frame.index, dtype=object)
        else:
            typed = _typed_frame(key, spec, raw, frame, file, options, notes)
            _row_rules(key, typed, file, required, meta)
            _check_unique(key, typed, file)
            _check_files(state, key, spec, typed, file)
        optional = [c for c in spec.optional if c in typed.columns and c not in required]
        covariates = [c for c in typed.columns if c not in required and c not in optional]
        sheets[key] = Sheet(name=key, file=file, sha256=files[str(file)], frame=typed,
                            required=required, optional=optional, covariates=covariates)

    if (meta.get("shape") == "clump") != ("clump" in sheets):
        raise WorkbookError("the meta shape clump needs the clump sheet (x_mm, y_mm, z_mm, radius_mm), and the "
                            "clump sheet needs the meta shape clump", file=str(source),
                            sheet="clump" if "clump" not in sheets else "meta")
    unknown = []
    for key, original in by_key.items():
        if key in SHEETS:
            continue
        if raws is None and str(csvs[original].resolve()) in files:
            continue  # a curve or track CSV that sits beside the sheets
        raw = raw_sheet(original, original)
        frame = _drop_empty_rows(_canonical_columns(raw.frame, (), raw.file, original))
        typed = pd.DataFrame({c: _covariate(original, c, frame[c], raw.file, notes)
                              for c in frame.columns}, index=frame.index)
        sheets[original] = Sheet(name=original, file=raw.file, sha256=files[str(raw.file)],
                                 frame=typed, required=[], optional=[], covariates=list(typed.columns))
        unknown.append(original)
    return Workbook(source=source, root=root, meta=meta, sheets=sheets, unknown_sheets=unknown,
                    files=files, attachments=state["attachments"], notes=notes, options=options)


def _as_frame(name: str, content) -> pd.DataFrame:
    if isinstance(content, Sheet):
        return content.frame.reset_index(drop=True)
    if isinstance(content, pd.DataFrame):
        return content.reset_index(drop=True)
    if name == "meta" and isinstance(content, dict):
        return pd.DataFrame({"key": list(content), "value": list(content.values())}, dtype=object)
    if isinstance(content, (list, tuple)):
        return pd.DataFrame(list(content))
    if isinstance(content, dict):
        return pd.DataFrame(content)
    raise InputError(f"sheet {name!r}: cannot write a {type(content).__name__}")


def write_workbook(wb_or_sheets, path) -> Path:
    """Write a workbook as ``.xlsx`` (``path`` ending in .xlsx) or as a folder of CSVs.

    Parameters
    ----------
    wb_or_sheets : Workbook or dict
        A :class:`Workbook`, or a dict sheet name -> DataFrame, list of row dicts, dict of
        columns, or (for ``meta``) a dict key -> value.
    path : str or Path
        Target ``.xlsx`` file, or folder for ``<sheet>.csv`` files (created if needed).

    Notes
    -----
    Only the sheets are written; photos, curves and tracks are not copied, so their paths must
    already be valid relative to the target. Empty values are written as empty cells.
    """
    sheets = wb_or_sheets.sheets if isinstance(wb_or_sheets, Workbook) else dict(wb_or_sheets)
    frames = {name: _as_frame(name, content) for name, content in sheets.items()}
    path = Path(path)
    if path.suffix.lower() == ".xlsx":
        path.parent.mkdir(parents=True, exist_ok=True)
        with pd.ExcelWriter(path, engine="openpyxl") as writer:
            for name, frame in frames.items():
                frame.to_excel(writer, sheet_name=name, index=False)
    else:
        path.mkdir(parents=True, exist_ok=True)
        for name, frame in frames.items():
            frame.to_csv(path / f"{name}.csv", index=False)
    return path
