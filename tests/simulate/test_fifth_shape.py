"""A new shape is one module and one line in ``simulate.shapes.SHAPES``: a doublet (two equal
touching spheres, as twin pellets or a dumbbell-shaped seed are modelled), written below as a
shape module would be and registered for these tests only, goes through the virtual lab,
measure, the drop twin run from the workbook and the LIGGGHTS, Yade and EDEM exports without
any other file knowing it."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import pytest
import yaml

from demcal.cli import main
from demcal.simulate.clump import MassProperties
from demcal.simulate.export import export_model, render
from demcal.simulate.params import DEMParameters, parse_shape
from demcal.simulate.shapes import SHAPES
from demcal.simulate.shapes.base import Shape, specimen_value
from demcal.simulate.truth_file import read_truth_file
from demcal.units import MM
from tests.simulate.test_virtual_lab_cli import EXAMPLE, _measure, _misses


@dataclass(frozen=True)
class Doublet(Shape):
    """Two touching spheres of ``diameter_m`` along x."""

    name: ClassVar[str] = "doublet"
    specimen_columns: ClassVar[tuple] = (("diameter_mm",),)
    sizes: ClassVar[tuple] = ("diameter_m",)
    body: ClassVar[str] = "two touching spheres of the diameter, pi d^3 / 3"

    diameter_m: float

    @classmethod
    def from_specimen(cls, row: dict, **_) -> "Doublet":
        return cls(specimen_value(row, "diameter_mm", cls.name))

    def spheres(self):
        r = self.diameter_m / 2.0
        return np.array([[-r, 0.0, 0.0], [r, 0.0, 0.0]]), np.array([r, r])

    def volume(self) -> float:
        return math.pi * self.diameter_m ** 3 / 3.0

    def body_mass_properties(self, density: float) -> MassProperties:
        # each ball: 2/5 (m/2) r^2 about its centre, plus (m/2) r^2 off the x axis
        m, r = density * self.volume(), self.diameter_m / 2.0
        return MassProperties(float(m), np.zeros(3), np.diag([0.4 * m * r * r, 1.4 * m * r * r, 1.4 * m * r * r]))

    def describe(self) -> str:
        return f"two touching spheres of {self.diameter_m / MM:.3g} mm diameter"


@pytest.fixture
def doublet(monkeypatch):
    """The registration line, for this test only."""
    monkeypatch.setitem(SHAPES, "doublet", f"{__name__}:Doublet")


def test_a_registered_shape_goes_from_the_workbook_to_the_exports(doublet, tmp_path, capsys):
    d = 0.005
    doc = yaml.safe_load(EXAMPLE.read_text())
    doc["params"] = {**{k: v for k, v in doc["params"].items() if not k.startswith("segment_")},
                     "shape": {"shape": "doublet", "diameter_m": d}, "particle_density_kg_m3": 1200.0, "dt": None}
    doc["design"].update(photos="none", n_tracks=0, drop_heights_mm=[400], orientation_range_deg=[0, 90])
    truth_file = tmp_path / "truth.yaml"
    truth_file.write_text(yaml.safe_dump(doc))
    spread = read_truth_file(truth_file).truth.size_sd_rel
    lab = tmp_path / "lab"
    assert main(["virtual-lab", str(truth_file), "--out", str(lab), "--seed", "11"]) == 0
    capsys.readouterr()

    # measure: the diameter, and the mass of the body pi d^3 / 3 at the envelope density, with
    # E[d^3] = mu^3 + 3 mu sigma^2 for normal diameters
    quantities = _measure(lab, tmp_path / "m.json")
    envelope = doc["envelope_ratio"] * 1200.0
    mean_volume = math.pi / 3.0 * (d ** 3 + 3.0 * d * (spread * d) ** 2)
    truth = {"diameter_mm": d / MM, "mass_g": 1e3 * envelope * mean_volume, "envelope_density_kg_m3": envelope,
             "particle_density_kg_m3": 1200.0}
    assert _misses(quantities, truth, level=0.999) == []

    # the drop twin runs the workbook's particle: two spheres of the measured diameter
    out = tmp_path / "drop.json"
    assert main(["simulate", "drop", "--workbook", str(lab), "--json", str(out)]) == 0
    run = json.loads(out.read_text())
    shape = parse_shape(run["params"]["shape"])
    assert isinstance(shape, Doublet) and shape.diameter_m == pytest.approx(quantities["diameter_mm"]["value"] * MM)
    assert 0.0 < run["observable"]["apparent_restitution"] < 1.0

    # the exports carry both spheres, each of the measured radius, and say what they stand for
    model = export_model(DEMParameters(shape=shape, particle_density_kg_m3=1200.0, dt=None), material="doublet")
    r = f"{shape.diameter_m / 2.0:.9g}"
    liggghts = render(model, "liggghts")
    assert "nspheres 2 " in liggghts and "two touching spheres" in liggghts
    listed = render(model, "yade").split("PARTICLE_SPHERES = [")[1].split("\n]")[0]
    assert listed.count(f"), {r})") == 2
    template_rows = [row.split(",") for row in render(model, "edem").splitlines() if row.startswith("template,")]
    assert [row[-1] for row in template_rows if row[1] in ("1", "2")] == [r, r]
