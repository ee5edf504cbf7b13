"""Raw cells of a workbook's sheets, read from ``.xlsx`` and CSV files within stated bounds.

The workbook is untrusted input, so this layer reads nothing it has not sized first:

- an ``.xlsx`` is a zip archive: the sizes its directory states are checked before any member
  is unpacked (a 0.5 MB file can unpack to gigabytes), then only the cells that exist are
  kept, so a stray cell at XFD1048576 costs one cell, not a sheet padded to 16 384 columns;
- a CSV is parsed record by record with the separator and decimal mark given or detected and
  stated (never guessed silently); a record with more or fewer fields than the header is
  refused naming its line.

What a spreadsheet program shows differently from the stored cells is made explicit: hidden
sheets, rows and columns, and merged cells within one column, are returned with a note naming
them; cells merged across columns and formulas without a stored value are refused, since
their value cannot be known.

Each sheet comes back as a :class:`RawSheet`: text header, object cells, indexed by data-row
number (1 = the first row under the header), holding only the rows with a value.
"""

from __future__ import annotations

import csv
import io
import re
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from demcal.errors import WorkbookError

#: Largest workbook file read (an .xlsx, a CSV sheet, a curve or track CSV) [bytes].
MAX_FILE_BYTES = 50 * 2**20
#: Largest total an .xlsx may unpack to, as its zip directory states [bytes].
MAX_UNPACKED_BYTES = 50 * 2**20
#: Longest text a cell may hold [characters]: far above any name, id or note.
MAX_CELL_CHARS = 10_000

#: CSV separators recognised when none is given, and their names for messages and options.
SEPARATORS = {",": "comma", ";": "semicolon", "\t": "tab"}
DECIMAL_MARKS = (".", ",")

_COMMA_NUMBER = re.compile(r"[+-]?\d+,\d+(?:[eE][+-]?\d+)?")
_DOT_NUMBER = re.compile(r"[+-]?\d*\.\d+(?:[eE][+-]?\d+)?")


@dataclass(frozen=True)
class RawSheet:
    """One sheet's cells as stored.

    Attributes
    ----------
    name : str
        Sheet name as written (for a CSV, the file's stem).
    file : Path
        The file read.
    frame : pandas.DataFrame
        Object cells; columns are the header cells as text ("" for an empty header cell);
        index the data-row numbers of the rows holding at least one value.
    notes : tuple of str
        What the reader did that the user should know (hidden rows, merged cells, the CSV
        dialect detected).
    dialect : dict
        For a CSV: ``{"separator", "decimal"}`` as used; empty for an .xlsx sheet.
    formulas_without_value : dict
        ``{(data row, header): formula}`` of the cells holding a formula whose value was never
        stored (a file written by a program that does not calculate); they read as empty
        here, and the caller decides whether the column can do without them.
    """

    name: str
    file: Path
    frame: pd.DataFrame
    notes: tuple = ()
    dialect: dict = field(default_factory=dict)
    formulas_without_value: dict = field(default_factory=dict)


def column_letter(index: int) -> str:
    """Spreadsheet column letter of a 1-based column index (1 -> A, 16384 -> XFD)."""
    letters = ""
    while index > 0:
        index, rem = divmod(index - 1, 26)
        letters = chr(65 + rem) + letters
    return letters


def row_ranges(numbers) -> str:
    """``[2, 3, 4, 7]`` as ``"2-4, 7"``."""
    numbers = sorted(set(numbers))
    parts, start = [], None
    for i, n in enumerate(numbers):
        if start is None:
            start = n
        if i + 1 == len(numbers) or numbers[i + 1] != n + 1:
            parts.append(str(start) if start == n else f"{start}-{n}")
            start = None
    return ", ".join(parts)


def check_file_size(path: Path, limit: int, *, sheet=None) -> None:
    """Refuse a file larger than ``limit`` bytes before reading it."""
    size = path.stat().st_size
    if size > limit:
        raise WorkbookError(f"the file has {size / 2**20:.1f} MB, above the {limit / 2**20:.0f} MB "
                            "limit for a workbook file (raise it with --max-file-mb)",
                            file=str(path), sheet=sheet)


def _check_cell(text: str, limit: int, where: dict) -> None:
    if len(text) > limit:
        raise WorkbookError(f"the cell holds {len(text)} characters, above the {limit} allowed",
                            **where)


def _frame(header: list, rows: dict) -> pd.DataFrame:
    """A frame from the header cells and ``{data row: {column position: value}}``."""
    index = sorted(rows)
    columns = {i: [rows[r].get(i) for r in index] for i in range(len(header))}
    frame = pd.DataFrame(columns, index=pd.Index(index, name="row"), dtype=object)
    frame.columns = list(header)
    return frame


# ----------------------------------------------------------------------------------------------
# .xlsx

def _unpacked_size(path: Path, limit: int) -> None:
    try:
        with zipfile.ZipFile(path) as archive:
            total = sum(info.file_size for info in archive.infolist())
    except zipfile.BadZipFile:
        raise WorkbookError("cannot read the workbook as .xlsx: it is not a zip archive "
                            "(is it an .xls or a renamed file? save it as .xlsx)", file=str(path)) from None
    if total > limit:
        raise WorkbookError(f"the .xlsx unpacks to {total / 2**20:.0f} MB, above the "
                            f"{limit / 2**20:.0f} MB limit (raise it with --max-file-mb)", file=str(path))


def _load(path: Path, data_only: bool):
    import openpyxl

    try:
        return openpyxl.load_workbook(path, data_only=data_only)
    except Exception as exc:  # openpyxl raises many types for a damaged file
        reason = str(exc).strip() or type(exc).__name__
        raise WorkbookError(f"cannot read the workbook as .xlsx: {reason}", file=str(path)) from None


def _empty(value) -> bool:
    return value is None or (isinstance(value, str) and not value.strip())


def read_xlsx(path, *, max_unpacked_bytes: int = MAX_UNPACKED_BYTES,
              max_cell_chars: int = MAX_CELL_CHARS) -> dict:
    """Every worksheet of an ``.xlsx`` as a :class:`RawSheet`, by name.

    Raises
    ------
    WorkbookError
        The file is not an .xlsx, unpacks beyond ``max_unpacked_bytes``, or a sheet holds a
        cell that cannot be read (text over ``max_cell_chars``, a formula without a stored
        value, data without a header, cells merged across columns), naming the cell.
    """
    path = Path(path)
    _unpacked_size(path, max_unpacked_bytes)
    values = _load(path, data_only=True)
    formulas = _load(path, data_only=False)
    return {ws.title: _xlsx_sheet(path, ws, formulas[ws.title], max_cell_chars)
            for ws in values.worksheets}


def _xlsx_sheet(path: Path, ws, ws_formulas, max_cell_chars: int) -> RawSheet:
    name = ws.title

    def where(r, c, header_row):
        row = r - header_row if header_row and r > header_row else None
        return {"file": str(path), "sheet": name, "row": row,
                "column": column_letter(c) if row is None else header.get(c) or column_letter(c)}

    # the stored cells only: iterating the sheet would pad every row to its widest column
    cells = {rc: cell.value for rc, cell in ws._cells.items() if not _empty(cell.value)}
    notes = []
    header_row = min((r for r, _ in cells), default=0)
    header = {c: str(v).strip() for (r, c), v in cells.items() if r == header_row}

    # openpyxl cannot tell a formula whose stored value is "" from one never calculated: both
    # read as empty, and the caller refuses them only where a value is required
    formulas = {(r - header_row, header.get(c) or column_letter(c)): str(cell.value)
                for (r, c), cell in ws_formulas._cells.items()
                if cell.data_type == "f" and (r, c) not in cells and r > header_row}

    for rng in ws.merged_cells.ranges:
        if rng.max_row < header_row:
            continue
        top = cells.get((rng.min_row, rng.min_col))
        span = f"{column_letter(rng.min_col)}{rng.min_row}:{column_letter(rng.max_col)}{rng.max_row}"
        if rng.min_col != rng.max_col:
            if top is None:
                continue  # an empty merged block carries no value
            raise WorkbookError(f"cells {span} are merged across columns: each column needs its "
                                "own value (unmerge them)", **where(rng.min_row, rng.min_col, header_row),
                                value=top)
        if rng.min_row <= header_row:
            raise WorkbookError(f"cells {span} merge the header with data rows (unmerge them)",
                                **where(header_row, rng.min_col, header_row))
        if top is None:
            continue
        for r in range(rng.min_row + 1, rng.max_row + 1):
            cells[(r, rng.min_col)] = top
        notes.append(f"sheet '{name}': cells {span} are merged; their value {top!r} is used in "
                     f"each of rows {row_ranges(range(rng.min_row - header_row, rng.max_row - header_row + 1))}")

    width = max(header, default=0)
    rows: dict = {}
    for (r, c), value in cells.items():
        if r == header_row:
            continue
        if c not in header:
            raise WorkbookError(f"column {column_letter(c)} has data but no header",
                                file=str(path), sheet=name, row=r - header_row,
                                column=column_letter(c), value=value)
        if isinstance(value, str):
            _check_cell(value, max_cell_chars, where(r, c, header_row))
        rows.setdefault(r - header_row, {})[c - 1] = value
    for value in header.values():
        _check_cell(value, max_cell_chars, {"file": str(path), "sheet": name})

    hidden_rows = [r for r in sorted(rows) if ws.row_dimensions[r + header_row].hidden]
    if hidden_rows:
        notes.append(f"sheet '{name}': rows {row_ranges(hidden_rows)} are hidden in the workbook; they "
                     "are read like every other row (delete them to leave them out)")
    hidden = {c for dim in ws.column_dimensions.values() if dim.hidden
              for c in range(dim.min or 0, (dim.max or 0) + 1)}
    hidden_columns = [header[c] for c in sorted(header) if c in hidden]
    if hidden_columns:
        notes.append(f"sheet '{name}': column(s) {', '.join(map(repr, hidden_columns))} are hidden in "
                     "the workbook; they are read like every other column")
    if ws.sheet_state != "visible":
        notes.append(f"sheet '{name}' is hidden in the workbook; it is read like every other sheet")
    frame = _frame([header.get(c, "") for c in range(1, width + 1)], rows)
    return RawSheet(name=name, file=path, frame=frame, notes=tuple(notes),
                    formulas_without_value=formulas)


# ----------------------------------------------------------------------------------------------
# CSV

def _decode(path: Path, sheet: str) -> str:
    data = path.read_bytes()
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise WorkbookError(f"not UTF-8 text (byte {exc.start + 1}): save the sheet as "
                            "'CSV UTF-8'", file=str(path), sheet=sheet) from None


def _records(text: str, separator: str) -> list:
    """``[(line, fields)]`` of every record, blank lines as empty field lists."""
    reader = csv.reader(io.StringIO(text, newline=""), delimiter=separator, strict=True)
    out = []
    try:
        for fields in reader:
            out.append((reader.line_num, fields))
    except csv.Error as exc:
        raise ValueError(f"line {reader.line_num}: {exc}") from None
    return out


def _separator(text: str, path: Path, sheet: str) -> str:
    """The separator: the one candidate that splits the header, or, when several do, the one
    that gives every record the header's field count."""
    splits = []
    for sep in SEPARATORS:
        try:
            records = [f for _, f in _records(text, sep) if f]
        except ValueError:
            continue
        if records and len(records[0]) > 1:
            splits.append((sep, all(len(f) == len(records[0]) for f in records)))
    if len(splits) == 1:
        return splits[0][0]
    if not splits:
        return ","  # one column: no separator to choose
    fits = [sep for sep, ok in splits if ok]
    if len(fits) == 1:
        return fits[0]
    names = " or ".join(SEPARATORS[s] for s, _ in splits)
    raise WorkbookError(f"cannot tell the separator ({names} would do): give it with "
                        "--csv-separator", file=str(path), sheet=sheet)


def _decimal(rows: list, path: Path, sheet: str, separator: str) -> str:
    """``","`` when the file writes numbers with a decimal comma and never with a point."""
    comma = dot = None
    for line, fields in rows:
        for j, cell in enumerate(fields):
            cell = cell.strip()
            if comma is None and _COMMA_NUMBER.fullmatch(cell):
                comma = (line, j, cell)
            elif dot is None and _DOT_NUMBER.fullmatch(cell):
                dot = (line, j, cell)
    if comma is None or separator == ",":
        return "."
    if dot is not None:
        raise WorkbookError(f"numbers are written both with a decimal comma (line {comma[0]}: "
                            f"{comma[2]!r}) and a decimal point (line {dot[0]}: {dot[2]!r}): "
                            "give the decimal mark with --csv-decimal", file=str(path), sheet=sheet)
    return ","


def read_csv(path, *, sheet: str | None = None, separator: str | None = None,
             decimal: str | None = None, max_bytes: int = MAX_FILE_BYTES,
             max_cell_chars: int = MAX_CELL_CHARS) -> RawSheet:
    """A CSV sheet as a :class:`RawSheet`.

    Parameters
    ----------
    path : str or Path
        The CSV file (UTF-8, with or without a byte-order mark).
    sheet : str, optional
        The sheet name for messages (default: the file's stem).
    separator : {",", ";", "\\t"}, optional
        Field separator; detected when None: the one candidate that splits the header and
        gives every record the header's field count.
    decimal : {".", ","}, optional
        Decimal mark; detected when None: a comma when the separator is not one and numbers
        are written with a decimal comma and never with a point (stated in ``notes``).

    Raises
    ------
    WorkbookError
        Too large, not UTF-8, an unclosed quote, a record with more or fewer fields than the
        header (naming its line), a duplicate or unnamed header, mixed decimal marks.
    """
    path = Path(path)
    sheet = sheet or path.stem
    check_file_size(path, max_bytes, sheet=sheet)
    text = _decode(path, sheet)
    notes = []
    sep = separator if separator is not None else _separator(text, path, sheet)
    try:
        records = _records(text, sep)
    except ValueError as exc:
        raise WorkbookError(f"cannot parse as CSV, {exc}", file=str(path), sheet=sheet) from None
    start = next((i for i, (_, f) in enumerate(records) if any(c.strip() for c in f)), None)
    if start is None:
        raise WorkbookError("cannot parse as CSV: the file holds no header", file=str(path), sheet=sheet)
    header = records[start][1]
    # data rows are numbered from the header on, blank lines included, as a spreadsheet shows them
    data = [(line, f) for line, f in records[start + 1:]]
    for line, fields in data:
        if fields and len(fields) != len(header):
            raise WorkbookError(f"cannot parse as CSV: line {line} has {len(fields)} fields where the header has "
                                f"{len(header)} (separator {SEPARATORS.get(sep, sep)!s}; a decimal "
                                "comma in a comma-separated file? give --csv-separator and "
                                "--csv-decimal)", file=str(path), sheet=sheet)
    mark = decimal if decimal is not None else _decimal(data, path, sheet, sep)
    if decimal is None and mark == ",":
        notes.append(f"{path.name}: decimal comma detected (separator {SEPARATORS[sep]})")
    rows = {}
    for i, (line, fields) in enumerate(data, start=1):
        if not any(c.strip() for c in fields):
            continue
        row = {}
        for j, cell in enumerate(fields):
            if len(cell) > max_cell_chars:
                _check_cell(cell, max_cell_chars, {"file": str(path), "sheet": sheet, "row": i,
                                                   "column": header[j].strip() or f"#{j + 1}"})
            if mark == ",":
                if _DOT_NUMBER.fullmatch(cell.strip()):
                    raise WorkbookError("a decimal point in a file whose decimal mark is a comma",
                                        file=str(path), sheet=sheet, row=i,
                                        column=header[j].strip() or f"#{j + 1}", value=cell)
                if _COMMA_NUMBER.fullmatch(cell.strip()):
                    cell = cell.strip().replace(",", ".")
            row[j] = cell
        rows[i] = row
    for j, cell in enumerate(header):
        _check_cell(cell, max_cell_chars, {"file": str(path), "sheet": sheet, "column": f"#{j + 1}"})
    frame = _frame([h.strip() for h in header], rows)
    return RawSheet(name=sheet, file=path, frame=frame, notes=tuple(notes),
                    dialect={"separator": sep, "decimal": mark})


def is_missing_marker(text: str) -> bool:
    """Text a spreadsheet or a statistics program writes for a missing number."""
    return text.strip().lower() in {"nan", "na", "n/a", "#n/a", "null", "none", "-", "--"}

