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
- A required cell must not be empty (exceptions: in ``drop``, the heights of a row with a
  ``track_file``; in ``incline``, a row gives either ``angle_deg`` or all of ``slope_deg``,
  ``release_height_mm``, ``runout_mm``, and roll-out rows must have mode ``roll``).
- Numeric cells must be finite numbers; sizes, masses, volumes and drop heights must be
  positive; a rebound height may be 0 (no rebound, e = 0) but not negative nor above its drop
  height; ``volume_after_ml`` must exceed ``volume_before_ml``; a compressed specimen's
  thickness must change; angles must lie strictly between 0 and 90 degrees.
- Names: ``pair`` is ``particle-<material>`` and ``surface`` is ``particle`` or a material,
  where a material name is a letter followed by letters, digits or ``_`` (case is ignored, so
  ``Steel`` is ``steel``). Anything else (empty, ``steel`` as a pair, ``particle steel``, a
  number) is unknown. ``mode`` is ``slide`` or ``roll``, ``axis`` ``radial`` or ``axial``,
  ``side`` ``left``, ``right`` or ``both`` (empty means ``both``).
- ``compression`` may carry the segment's ``length_mm`` (used for the radial contact area;
  otherwise it is taken from the ``specimens`` row with the same ``specimen_id``).
- Referenced files (paths relative to the workbook; ``\\`` separators accepted) must exist
  and be readable: a photo must open with OpenCV, a curve or track must be a CSV with its
  columns (``displacement_mm``, ``force_N``; ``t_s``, ``y_mm``, optional ``angle_deg``)
  holding numbers, at least 3 rows.

Every violation raises :class:`demcal.errors.WorkbookError` naming the file, sheet, data row,
column and value.
"""

from __future__ import annotations

import datetime as _dt
import math
import numbers
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from demcal.errors import InputError, WorkbookError
from demcal.provenance import sha256_file

#: A material name: a letter, then letters, digits or underscores (lower case after reading).
NAME_PATTERN = re.compile(r"[a-z][a-z0-9_]*")
MODES = ("slide", "roll")
AXES = ("radial", "axial")
SIDES = ("left", "right", "both")
ROLLOUT_COLUMNS = ("slope_deg", "release_height_mm", "runout_mm")


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
    "specimens": SheetSpec(required=("specimen_id", "length_mm", "diameter_mm", "mass_g"),
                           ids=("specimen_id",), positive=("length_mm", "diameter_mm", "mass_g")),
    "density": SheetSpec(required=("sample_id", "mass_g", "volume_before_ml", "volume_after_ml"),
                         ids=("sample_id",),
                         positive=("mass_g", "volume_before_ml", "volume_after_ml")),
    "drop": SheetSpec(required=("trial_id", "pair", "drop_height_mm", "rebound_height_mm"),
                      optional=("track_file",), ids=("trial_id",), positive=("drop_height_mm",),
                      nonnegative=("rebound_height_mm",), choices=("pair",),
                      files=(("track_file", "track"),)),
    "incline": SheetSpec(required=("trial_id", "surface", "mode"),
                         optional=("angle_deg",) + ROLLOUT_COLUMNS, ids=("trial_id",),
                         positive=("release_height_mm",), nonnegative=("runout_mm",),
                         angles=("angle_deg", "slope_deg"), choices=("surface", "mode")),
    "compression": SheetSpec(required=("specimen_id", "axis", "width_before_mm", "width_after_mm",
                                       "thickness_before_mm", "thickness_after_mm"),
                             optional=("curve_file", "length_mm"), ids=("specimen_id",),
                             positive=("width_before_mm", "width_after_mm", "thickness_before_mm",
                                       "thickness_after_mm", "length_mm"),
                             choices=("axis",), files=(("curve_file", "curve"),)),
    "repose": SheetSpec(required=("photo_id", "file"),
                        optional=("side", "scale_mm_per_px", "angle_deg_manual"), ids=("photo_id",),
                        positive=("scale_mm_per_px",), angles=("angle_deg_manual",),
                        choices=("side",), files=(("file", "photo"),)),
}

#: Sheets every workbook must have.
REQUIRED_SHEETS = ("meta", "specimens")

#: Columns of the CSV files a workbook points to: (required, optional).
ATTACHMENTS = {"curve": (("displacement_mm", "force_N"), ()),
               "track": (("t_s", "y_mm"), ("angle_deg",))}

#: Meta keys we check when present (others are kept as read).
META_POSITIVE = ("contact_density_kg_m3", "contact_shear_modulus_pa", "particle_shear_modulus_pa",
                 "box_length_mm", "box_width_mm", "box_height_mm", "plate_lift_speed_mm_s",
                 "fill_count")


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
        return {c: _plain(self.frame.at[row, c]) for c in self.covariates}

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
    """

    source: Path
    root: Path
    meta: dict
    sheets: dict
    unknown_sheets: list
    files: dict
    attachments: dict = field(default_factory=dict)

    def sheet(self, name: str) -> Sheet | None:
        """The sheet ``name``, or None if the workbook does not have it."""
        return self.sheets.get(name)

    def resolve(self, relative) -> Path:
        """A path written in the workbook, relative to :attr:`root` (absolute paths stay)."""
        return _resolve(self.root, relative)

    def attachment(self, relative) -> pd.DataFrame:
        """The parsed curve or track CSV that a cell points to."""
        return self.attachments[str(self.resolve(relative))]


# ----------------------------------------------------------------------------------------------
# cells

def _is_empty(cell) -> bool:
    if cell is None:
        return True
    if isinstance(cell, float) and math.isnan(cell):
        return True
    if cell is pd.NaT or (isinstance(cell, str) and not cell.strip()):
        return True
    try:
        return bool(pd.isna(cell)) if not isinstance(cell, (str, bytes)) else False
    except (TypeError, ValueError):
        return False


def _resolve(root: Path, text) -> Path:
    """A path cell relative to ``root``; Windows separators are accepted."""
    p = Path(str(text).replace("\\", "/"))
    return p if p.is_absolute() else root / p


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
    if isinstance(cell, bool):
        raise ValueError("boolean")
    if isinstance(cell, numbers.Real):
        x = float(cell)
    elif isinstance(cell, str):
        x = float(cell.strip())
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

def _raw_xlsx(path: Path) -> dict:
    try:
        frames = pd.read_excel(path, sheet_name=None, header=0, dtype=object, engine="openpyxl",
                               keep_default_na=False, na_values=[])
    except Exception as exc:  # openpyxl raises many types for a damaged file
        raise WorkbookError(f"cannot read the workbook as .xlsx: {exc}", file=str(path)) from None
    return {str(name): frame for name, frame in frames.items()}


def _read_csv(path: Path) -> pd.DataFrame:
    """A CSV as text cells, keeping blank lines so row numbers match the file."""
    return pd.read_csv(path, dtype=str, keep_default_na=False, skip_blank_lines=False,
                       encoding="utf-8-sig")


def _raw_csv(path: Path, sheet: str) -> pd.DataFrame:
    try:
        return _read_csv(path)
    except Exception as exc:  # pandas raises ParserError, UnicodeDecodeError, EmptyDataError...
        raise WorkbookError(f"cannot read the CSV sheet: {exc}", file=str(path), sheet=sheet) from None


def _canonical_columns(raw: pd.DataFrame, known: tuple, file: Path, sheet: str) -> pd.DataFrame:
    """Strip headers, map known columns case-insensitively, drop empty unnamed columns."""
    lookup = {k.lower(): k for k in known}
    names, keep = [], []
    for i, col in enumerate(raw.columns):
        header = "" if _is_empty(col) or str(col).startswith("Unnamed:") else str(col).strip()
        if not header:
            if raw.iloc[:, i].map(_is_empty).all():
                continue
            raise WorkbookError(f"column {i + 1} has data but no header", file=str(file), sheet=sheet,
                                column=f"#{i + 1}")
        header = lookup.get(header.lower(), header)
        if header in names:
            raise WorkbookError("duplicate column", file=str(file), sheet=sheet, column=header)
        names.append(header)
        keep.append(i)
    frame = raw.iloc[:, keep].copy()
    frame.columns = names
    frame.index = pd.RangeIndex(1, len(frame) + 1, name="row")
    return frame


def _drop_empty_rows(frame: pd.DataFrame) -> pd.DataFrame:
    if frame.shape[1] == 0:
        return frame.iloc[0:0]
    empty = frame.apply(lambda r: all(_is_empty(c) for c in r), axis=1)
    return frame.loc[~empty.astype(bool)]


# ----------------------------------------------------------------------------------------------
# validation

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
    valid = {"mode": MODES, "axis": AXES, "side": SIDES}[column]
    if value in valid:
        return None
    return f"unknown {column}; valid: {', '.join(valid)}"


def _typed_frame(name: str, spec: SheetSpec, frame: pd.DataFrame, file: Path) -> pd.DataFrame:
    """Convert and check every cell of a known sheet; covariates are typed loosely."""
    out = {}
    numbers_ = set(spec.numbers)
    for col in frame.columns:
        cells = frame[col]
        if col in numbers_:
            values = []
            for row, cell in cells.items():
                if _is_empty(cell):
                    values.append(math.nan)
                    continue
                try:
                    x = _number(cell)
                except ValueError:
                    raise WorkbookError("not a number", file=str(file), sheet=name, row=row,
                                        column=col, value=cell) from None
                if col in spec.positive and not x > 0:
                    raise WorkbookError("must be positive", file=str(file), sheet=name, row=row,
                                        column=col, value=cell)
                if col in spec.nonnegative and x < 0:
                    raise WorkbookError("must not be negative", file=str(file), sheet=name,
                                        row=row, column=col, value=cell)
                if col in spec.angles and not 0 < x < 90:
                    raise WorkbookError("angle must lie strictly between 0 and 90 degrees",
                                        file=str(file), sheet=name, row=row, column=col, value=cell)
                values.append(x)
            out[col] = pd.Series(values, index=frame.index, dtype=float)
        elif col in spec.choices:
            values = []
            for row, cell in cells.items():
                value = _name(cell)
                if value is None and col == "side":
                    value = "both"
                problem = _check_choice(col, value)
                if problem:
                    raise WorkbookError(problem, file=str(file), sheet=name, row=row, column=col,
                                        value=None if _is_empty(cell) else cell)
                values.append(value)
            out[col] = pd.Series(values, index=frame.index, dtype=object)
        elif col in spec.ids or col in spec.required or col in spec.optional:
            out[col] = pd.Series([None if _is_empty(c) else _text(c) for c in cells],
                                 index=frame.index, dtype=object)
        else:
            out[col] = _covariate(cells)
    return pd.DataFrame(out, index=frame.index)


def _covariate(cells: pd.Series) -> pd.Series:
    """A covariate column: numbers if every non-empty cell is one, else text."""
    present = [c for c in cells if not _is_empty(c)]
    try:
        [_number(c) for c in present]
    except ValueError:
        return pd.Series([None if _is_empty(c) else _text(c) for c in cells], index=cells.index,
                         dtype=object)
    return pd.Series([math.nan if _is_empty(c) else _number(c) for c in cells], index=cells.index,
                     dtype=float)


def _require_cells(name: str, frame: pd.DataFrame, columns, file: Path, rows=None):
    for col in columns:
        for row, cell in frame[col].items():
            if (rows is None or row in rows) and _is_empty(cell):
                raise WorkbookError("missing value", file=str(file), sheet=name, row=row, column=col)


def _row_rules(name: str, frame: pd.DataFrame, file: Path) -> None:
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
        for row in frame.index:
            has_angle = "angle_deg" in frame and not math.isnan(frame.at[row, "angle_deg"])
            rollout = [c for c in ROLLOUT_COLUMNS if c in frame and not math.isnan(frame.at[row, c])]
            if has_angle and rollout:
                raise err("give either angle_deg or the roll-out columns, not both", row,
                          rollout[0], frame.at[row, rollout[0]])
            if not has_angle and not rollout:
                raise err("missing value (or give slope_deg, release_height_mm and runout_mm "
                          "for a roll-out trial)", row, "angle_deg")
            if rollout:
                missing = [c for c in ROLLOUT_COLUMNS if c not in rollout]
                if missing:
                    raise err("missing value of a roll-out trial", row, missing[0])
                if frame.at[row, "mode"] != "roll":
                    raise err("a roll-out trial measures rolling friction: mode must be roll",
                              row, "mode", frame.at[row, "mode"])
        return
    _require_cells(name, frame, spec.required, file)
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


def _required_columns(name: str, columns: list, file: Path) -> list:
    spec = SHEETS[name]
    required = list(spec.required)
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


def _parse_meta(frame: pd.DataFrame, file: Path) -> dict:
    meta, seen = {}, {}
    for row in frame.index:
        key, cell = frame.at[row, "key"], frame.at[row, "value"]
        if _is_empty(key):
            raise WorkbookError("missing key", file=str(file), sheet="meta", row=row, column="key",
                                value=None if _is_empty(cell) else cell)
        key = _text(key).lower()
        if key in seen:
            raise WorkbookError(f"duplicate key (first in row {seen[key]})", file=str(file),
                                sheet="meta", row=row, column="key", value=key)
        seen[key] = row
        value = _text(cell) if key == "material" and not _is_empty(cell) else _meta_value(cell)

        def bad(message):
            return WorkbookError(f"meta {key}: {message}", file=str(file), sheet="meta", row=row,
                                 column="value", value=cell)

        if key in META_POSITIVE or key in ("contact_poisson", "target_repose_deg"):
            if value is not None and not isinstance(value, (int, float)):
                raise bad("not a number")
            if value is not None:
                if key in META_POSITIVE and not value > 0:
                    raise bad("must be positive")
                if key == "fill_count" and not float(value).is_integer():
                    raise bad("must be a whole number")
                if key == "contact_poisson" and not -1 < value < 0.5:
                    raise bad("a Poisson's ratio must lie in (-1, 0.5)")
                if key == "target_repose_deg" and not 0 < value < 90:
                    raise bad("angle must lie strictly between 0 and 90 degrees")
        meta[key] = value
    if not isinstance(meta.get("material"), str) or not meta["material"]:
        raise WorkbookError("meta key 'material' is missing or empty", file=str(file), sheet="meta",
                            row=seen.get("material"), column="value" if "material" in seen else "key",
                            value=meta.get("material"))
    return meta


def _read_attachment(kind: str, path: Path) -> pd.DataFrame:
    """Parse a curve or track CSV; raises ValueError with a readable reason."""
    required, optional = ATTACHMENTS[kind]
    try:
        raw = _read_csv(path)
    except Exception as exc:
        raise ValueError(f"cannot parse as CSV: {exc}") from None
    try:
        frame = _drop_empty_rows(_canonical_columns(raw, required + optional, path, kind))
    except WorkbookError as exc:
        raise ValueError(str(exc)) from None
    for col in required:
        if col not in frame.columns:
            raise ValueError(f"lacks column '{col}' (needs {', '.join(required)})")
    out = {}
    for col in required + tuple(c for c in optional if c in frame.columns):
        values = []
        for row, cell in frame[col].items():
            try:
                values.append(_number(cell))
            except ValueError:
                if _is_empty(cell) and col in optional:
                    values.append(math.nan)
                    continue
                raise ValueError(f"data row {row}, column '{col}': not a number ({cell!r})") from None
        out[col] = values
    table = pd.DataFrame(out, index=frame.index, dtype=float)
    if len(table) < 3:
        raise ValueError(f"has {len(table)} data rows; at least 3 are needed")
    return table


def _check_files(wb_root: Path, name: str, spec: SheetSpec, frame: pd.DataFrame, file: Path,
                 files: dict, attachments: dict) -> None:
    import cv2  # imported here: only needed when a workbook points to photos

    for column, kind in spec.files:
        if column not in frame:
            continue
        for row, rel in frame[column].items():
            if rel is None:
                if column in spec.required:
                    raise WorkbookError("missing value", file=str(file), sheet=name, row=row, column=column)
                continue
            path = _resolve(wb_root, rel)
            key = str(path)

            def err(message):
                return WorkbookError(f"{kind} file {message}", file=str(file), sheet=name, row=row,
                                     column=column, value=rel)

            if not path.is_file():
                raise err(f"not found: {path}")
            if key not in files:
                if kind == "photo":
                    if cv2.imread(str(path), cv2.IMREAD_UNCHANGED) is None:
                        raise err(f"cannot be read as an image: {path}")
                else:
                    try:
                        attachments[key] = _read_attachment(kind, path)
                    except ValueError as exc:
                        raise err(f"{path}: {exc}") from None
                files[key] = sha256_file(path)


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


def read_workbook(path) -> Workbook:
    """Read and validate a lab workbook (``.xlsx`` or a folder of ``<sheet>.csv``).

    Parameters
    ----------
    path : str or Path
        The ``.xlsx`` file, the folder holding one CSV per sheet, or a folder holding one
        ``.xlsx`` (see :func:`resolve_workbook`).

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
    source = resolve_workbook(path).absolute()  # absolute: provenance and audit work from any folder
    files: dict = {}
    if source.is_dir():
        root = source
        csvs = {p.stem.strip(): p for p in sorted(source.glob("*.csv")) if p.is_file()}
        raws = None
    elif source.is_file():
        if source.suffix.lower() not in (".xlsx", ".xlsm"):
            raise InputError(f"workbook {source}: expected an .xlsx file or a folder of CSV files")
        root = source.parent
        raws = _raw_xlsx(source)
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

    sheets: dict = {}
    attachments: dict = {}
    meta: dict = {}
    for key in [k for k in SHEETS if k in by_key]:
        original = by_key[key]
        file = source if raws is not None else csvs[original]
        raw = raws[original] if raws is not None else _raw_csv(file, key)
        if raws is None:
            files[str(file)] = sha256_file(file)
        spec = SHEETS[key]
        frame = _drop_empty_rows(_canonical_columns(raw, spec.required + spec.optional, file, key))
        required = _required_columns(key, list(frame.columns), file)
        if key in REQUIRED_SHEETS and frame.empty:
            raise WorkbookError("the sheet has no data rows", file=str(file), sheet=key)
        if key == "meta":
            meta = _parse_meta(frame, file)
            typed = pd.DataFrame({"key": [_text(k).lower() for k in frame["key"]],
                                  "value": [_meta_value(v) for v in frame["value"]]},
                                 index=frame.index, dtype=object)
        else:
            typed = _typed_frame(key, spec, frame, file)
            _row_rules(key, typed, file)
            _check_files(root, key, spec, typed, file, files, attachments)
        optional = [c for c in spec.optional if c in typed.columns and c not in required]
        covariates = [c for c in typed.columns if c not in required and c not in optional]
        sheets[key] = Sheet(name=key, file=file, sha256=files[str(file)], frame=typed,
                            required=required, optional=optional, covariates=covariates)

    unknown = []
    for key, original in by_key.items():
        if key in SHEETS:
            continue
        file = source if raws is not None else csvs[original]
        if raws is None and str(file) in files:
            continue  # a curve or track CSV that sits beside the sheets
        raw = raws[original] if raws is not None else _raw_csv(file, original)
        if raws is None:
            files[str(file)] = sha256_file(file)
        frame = _drop_empty_rows(_canonical_columns(raw, (), file, original))
        typed = pd.DataFrame({c: _covariate(frame[c]) for c in frame.columns}, index=frame.index)
        sheets[original] = Sheet(name=original, file=file, sha256=files[str(file)], frame=typed,
                                 required=[], optional=[], covariates=list(typed.columns))
        unknown.append(original)
    return Workbook(source=source, root=root, meta=meta, sheets=sheets, unknown_sheets=unknown,
                    files=files, attachments=attachments)


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
