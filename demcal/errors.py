"""Domain errors. Every error a user can cause is one of these; the CLI prints its message
(no traceback) and exits non-zero."""

from __future__ import annotations


class DemcalError(Exception):
    """Base class of every error demcal reports to the user."""


class InputError(DemcalError, ValueError):
    """A bad argument, option or input file (not a workbook cell)."""


class WorkbookError(InputError):
    """A problem in the lab workbook, located by file, sheet, row and column.

    ``row`` counts data rows from 1 (the first row under the header), as docs/workbook.md does.
    """

    def __init__(self, message: str, *, file=None, sheet=None, row=None, column=None, value=None):
        self.file, self.sheet, self.row, self.column, self.value = file, sheet, row, column, value
        where = []
        if file is not None:
            where.append(f"file {file}")
        if sheet is not None:
            where.append(f"sheet '{sheet}'")
        if row is not None:
            where.append(f"row {row}")
        if column is not None:
            where.append(f"column '{column}'")
        text = message if not where else f"{', '.join(where)}: {message}"
        if value is not None:
            text += f" (value: {value!r})"
        super().__init__(text)


class SimulationError(DemcalError, RuntimeError):
    """The DEM cannot run or has gone wrong (unsafe time step, non-finite state, runaway energy)."""


class UnsafeTimeStepError(SimulationError):
    """The time step exceeds the allowed fraction of the Rayleigh time."""


class AnalysisError(DemcalError, ValueError):
    """A design or table cannot be analysed as asked (e.g. too few runs for the model)."""
