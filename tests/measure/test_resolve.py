"""A campaign folder holding one .xlsx names that workbook; ambiguity is an error."""

import shutil
from pathlib import Path

import pytest

from demcal.errors import InputError
from demcal.measure.workbook import read_workbook, resolve_workbook

EXAMPLE = Path(__file__).resolve().parents[2] / "data" / "astragalus" / "workbook.xlsx"


def test_folder_with_one_xlsx_resolves_to_it(tmp_path):
    shutil.copy(EXAMPLE, tmp_path / "lab.xlsx")
    assert resolve_workbook(tmp_path) == tmp_path / "lab.xlsx"
    assert resolve_workbook(tmp_path / "lab.xlsx") == tmp_path / "lab.xlsx"


def test_folder_with_two_xlsx_is_refused(tmp_path):
    for name in ("a.xlsx", "b.xlsx"):
        shutil.copy(EXAMPLE, tmp_path / name)
    with pytest.raises(InputError, match="holds 2 workbooks"):
        read_workbook(tmp_path)


def test_example_campaign_folder_reads():
    wb = read_workbook(EXAMPLE.parent)
    assert wb.source == EXAMPLE and "drop" in wb.sheets
