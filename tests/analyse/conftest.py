"""Reference data for the analyse tests: real published data sets in the team's shared
external folder (see its README.md for sources and licences). ``DEMCAL_EXTERNAL`` overrides the
location; without the folder the tests that need it are skipped with the reason shown."""

import os
from pathlib import Path

import pandas as pd
import pytest

EXTERNAL = Path(os.environ.get("DEMCAL_EXTERNAL", "/work/shared/external"))


@pytest.fixture
def external():
    """Load ``<subfolder>/<file>.csv`` from the external reference folder as a DataFrame."""
    def load(relpath: str) -> pd.DataFrame:
        path = EXTERNAL / relpath
        if not path.exists():
            pytest.skip(f"reference data not found: {path} (set DEMCAL_EXTERNAL)")
        return pd.read_csv(path)
    return load


#: The bundled example workbook.
EXAMPLE = Path(__file__).resolve().parents[2] / "data" / "astragalus" / "workbook.xlsx"


@pytest.fixture(scope="session")
def measurement():
    """The example workbook measured once for every campaign test."""
    from demcal.measure.pipeline import measure_workbook

    if not EXAMPLE.exists():
        pytest.skip(f"example workbook missing: {EXAMPLE}")
    return measure_workbook(EXAMPLE)
