"""The virtual lab writes complete workbooks that the measure stage reads back to the truth,
and plants effects of known size."""

import json
import math

import numpy as np
import pytest

from demcal.errors import InputError
from demcal.measure.pipeline import measure_workbook
from demcal.measure.workbook import read_workbook
from demcal.simulate.params import DEMParameters, parse_shape
from demcal.simulate.virtual_lab import (EFFECT_KINDS, PlantedEffect, Truth, VirtualWorkbook, drop_twin_ratio,
                                  write_virtual_workbook)


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    path = tmp_path_factory.mktemp("virtual") / "clean"
    vw = write_virtual_workbook(Truth(), path, rng=11, n_photos=3)
    return vw, measure_workbook(vw.path)


def test_clean_workbook_has_every_sheet_and_file(clean):
    vw, _ = clean
    wb = read_workbook(vw.path)
    assert set(wb.sheets) == {"meta", "specimens", "density", "drop", "incline", "compression", "repose"}
    drop = wb.sheet("drop")
    assert {"specimen_id", "operator", "date", "orientation_deg", "trial_order"} <= set(drop.covariates)
    assert sorted(set(drop.frame["drop_height_mm"])) == [200.0, 400.0, 600.0]
    assert sum(bool(v) for v in drop.frame["track_file"] if isinstance(v, str)) == 2
    assert {"moisture_pct", "batch"} <= set(wb.sheet("specimens").covariates)
    assert vw.expected == ()
    truth = json.loads((vw.path / "truth.json").read_text())
    assert truth["truth"]["params"]["e_pw"] == 0.35 and truth["effects"] == []


def test_clean_workbook_measures_back_to_the_truth(clean):
    _, m = clean
    q = m.quantities
    p = Truth().params
    for name, truth in (("static_friction.particle", p.mu_s_pp), ("static_friction.steel", p.mu_s_pw),
                        ("rolling_friction.particle", p.mu_r_pp), ("rolling_friction.steel", p.mu_r_pw),
                        ("particle_density_kg_m3", p.particle_density_kg_m3),
                        ("poisson_ratio", p.poisson_ratio), ("length_mm", 25.0), ("diameter_mm", 11.0),
                        ("shear_modulus_pa", p.shear_modulus_pa),
                        ("elastic_modulus_pa", 2 * p.shear_modulus_pa * (1 + p.poisson_ratio))):
        lo, hi = q[name].ci95
        se = (hi - lo) / 4
        assert lo - se < truth < hi + se, name            # within the CI widened by half
    # released end on, the apparent restitution is the contact one within the twin's 1 %
    assert q["restitution.particle-steel"].value == pytest.approx(p.e_pw, abs=0.02)


def test_drop_twin_ratio_end_on_and_tilted():
    params = DEMParameters()
    end_on = drop_twin_ratio(params, "particle-steel", 0.4, [90.0])
    assert end_on[0] == pytest.approx(1.0, abs=0.01)       # one contact through the centre of mass
    tilted = drop_twin_ratio(params, "particle-steel", 0.4, [45.0])
    assert tilted[0] < 0.7                                  # energy into rotation


def test_planted_sizes_are_the_true_effects(tmp_path):
    effects = (PlantedEffect("velocity_dependent_restitution", quantity="restitution.particle-steel"),
               PlantedEffect("block_effect"), PlantedEffect("trial_order_drift"),
               PlantedEffect("moisture_dependence", sheet="drop"))
    vw = write_virtual_workbook(Truth(), tmp_path / "wb", effects=effects, rng=3, photos="none",
                                pairs=("particle-steel",))
    exp = {(x["kind"], x["quantity"]): x["true_effect"] for x in vw.expected}
    # linear effects: the slope of the noise-free rows is the planted size (times the end-on
    # twin ratio, 0.99-1, for the drops)
    assert exp[("velocity_dependent_restitution", "restitution.particle-steel")] == pytest.approx(-2e-4, rel=0.015)
    assert exp[("trial_order_drift", "static_friction.steel")] == pytest.approx(0.004, rel=0.02)
    assert exp[("moisture_dependence", "restitution.particle-steel")] == pytest.approx(0.01, rel=0.015)
    # an operator reading 2 deg higher raises tan(angle) by about sec^2(theta) x 2 deg
    hand = (1 + 0.65 ** 2) * math.radians(2.0)
    assert exp[("block_effect", "static_friction.particle")] == pytest.approx(hand, rel=0.05)
    assert ("trial_order_drift", "rolling_friction.steel") not in exp     # drift acts on static friction


def test_xlsx_output_reads_back(tmp_path):
    vw = write_virtual_workbook(Truth(), tmp_path / "lab" / "book.xlsx", rng=np.random.default_rng(2),
                                photos="none", n_drop=2, n_incline=3, n_compression=2, n_specimens=5)
    assert isinstance(vw, VirtualWorkbook) and vw.path.suffix == ".xlsx"
    wb = read_workbook(vw.path)
    assert len(wb.sheet("incline").rows) == 12 and (tmp_path / "lab" / "truth.json").exists()


def test_errors_name_the_problem(tmp_path):
    with pytest.raises(InputError, match="valid: " + ", ".join(EFFECT_KINDS)):
        PlantedEffect("wet_segments")
    with pytest.raises(InputError, match="calibration campaign"):
        PlantedEffect("ill_conditioned_parameter")
    with pytest.raises(InputError, match="rng"):
        write_virtual_workbook(Truth(), tmp_path / "a")
    with pytest.raises(InputError, match="sheet must be one of"):
        PlantedEffect("camera_tilt", sheet="drop")
    with pytest.raises(InputError, match="needs photos"):
        write_virtual_workbook(Truth(), tmp_path / "b", effects=("camera_tilt",), rng=1, photos="none")
    with pytest.raises(InputError, match="e_sd"):
        Truth(e_sd=-0.1)
    # a photo size is never dropped silently: only a drawn heap profile is rendered at any size
    with pytest.raises(InputError, match="photo_size sets the size of the analytic photos.*the DEM photos"):
        write_virtual_workbook(Truth(), tmp_path / "c", rng=1, photos="dem", n_photos=2, photo_size=(450, 600))
    drum = {"repose_rig": "drum", "drum_diameter_mm": 150, "drum_width_mm": 40, "drum_speed_rpm": 10,
            "drum_fill_fraction": 0.4}
    seeds = Truth(params=DEMParameters(shape=parse_shape("sphere:0.00646"), particle_density_kg_m3=1200, dt=None))
    with pytest.raises(InputError, match="the drum photos are framed"):
        write_virtual_workbook(seeds, tmp_path / "d", rng=1, n_photos=2, repose_rig=drum, photo_size=(450, 600))


def test_a_lifting_cylinder_lab_writes_its_rig_and_reads_back(tmp_path):
    """The virtual lab writes the lifting cylinder's meta rows, which read back to the same tube,
    and refuses a tube the truth's particles could not make a readable cone in."""
    from demcal.simulate.rigs import repose_setup
    from demcal.simulate.rigs.lifting_cylinder import CylinderGeometry
    from demcal.simulate.shapes.sphere import Sphere

    rig = {"repose_rig": "lifting_cylinder", "cylinder_diameter_mm": 60, "cylinder_height_mm": 120,
           "lift_speed_mm_s": 10}
    seeds = Truth(params=DEMParameters(shape=Sphere(0.00646), particle_density_kg_m3=1200, dt=None))
    vw = write_virtual_workbook(seeds, tmp_path / "lab", rng=3, n_photos=3, n_drop=2, n_incline=3, n_tracks=0,
                                n_specimens=5, n_compression=3, repose_rig=rig)
    meta = read_workbook(vw.path).meta
    assert meta["repose_rig"] == "lifting_cylinder" and "box_length_mm" not in meta
    setup = repose_setup(meta)
    assert setup.rig == "lifting_cylinder" and CylinderGeometry(**setup.geometry) == CylinderGeometry(0.06, 0.12, 0.01)
    # the paper's 25 mm segments would arch in a 60 mm tube
    with pytest.raises(InputError, match="under 4 particle lengths"):
        write_virtual_workbook(Truth(), tmp_path / "segments", rng=3, n_photos=3, repose_rig=rig)
    with pytest.raises(InputError, match="repose_rig: .*cylinder_height_mm: missing"):
        write_virtual_workbook(seeds, tmp_path / "bad", rng=3, n_photos=3,
                               repose_rig={k: v for k, v in rig.items() if k != "cylinder_height_mm"})


def test_a_drum_lab_writes_end_on_frames_that_measure_read_back_at_the_truths_angle(tmp_path):
    """The virtual lab's drum: its meta rows read back to the same drum, its photos are drum
    frames (side ``drum``) of a bed at the truth's angle, and ``demcal measure`` reads them back
    with the drum estimator to within the heap-to-heap scatter."""
    from demcal.measure.pipeline import measure_workbook
    from demcal.simulate.rigs import repose_setup
    from demcal.simulate.rigs.drum import DrumGeometry
    from demcal.simulate.shapes.sphere import Sphere

    rig = {"repose_rig": "drum", "drum_diameter_mm": 150, "drum_width_mm": 40, "drum_speed_rpm": 10,
           "drum_fill_fraction": 0.4}
    seeds = Truth(params=DEMParameters(shape=Sphere(0.00646), particle_density_kg_m3=1200, dt=None),
                  repose_angle_deg=35.0, repose_sd_deg=1.0)
    vw = write_virtual_workbook(seeds, tmp_path / "lab", rng=3, n_photos=6, n_drop=2, n_incline=3, n_tracks=0,
                                n_specimens=5, n_compression=3, repose_rig=rig)
    wb = read_workbook(vw.path)
    assert DrumGeometry(**repose_setup(wb.meta).geometry) == DrumGeometry(0.15, 0.04, 10.0, 0.4)
    assert set(wb.sheet("repose").frame["side"]) == {"drum"}
    est = measure_workbook(vw.path).quantities["repose_angle_deg"]
    assert est.n == 6 and est.value == pytest.approx(35.0, abs=3.0 * 1.0 / math.sqrt(6) + 0.5)


def test_dem_photos_are_the_same_poured_on_one_process_or_on_two(tmp_path):
    """The heaps of ``photos="dem"`` poured at once on worker processes give the workbook the
    same heaps poured one after the other give: every sheet and every photo byte for byte."""
    from demcal.simulate.rigs.repose import ReposeGeometry
    from demcal.simulate.shapes.sphere import Sphere

    seeds = Truth(params=DEMParameters(shape=Sphere(0.0066), particle_density_kg_m3=1200, shear_modulus_pa=1.04e6,
                                       dt=None))
    small = ReposeGeometry.for_particle(seeds.params.shape).scaled(0.35)
    design = dict(rng=5, photos="dem", geometry=small, n_photos=3, n_drop=2, n_incline=3, n_tracks=0,
                  n_specimens=5, n_compression=2, drop_heights_mm=(400.0,), orientation_range_deg=(0.0, 90.0))
    one = write_virtual_workbook(seeds, tmp_path / "one", workers=1, **design)
    two = write_virtual_workbook(seeds, tmp_path / "two", workers=2, **design)
    files = sorted(p.relative_to(tmp_path / "one") for p in (tmp_path / "one").rglob("*")
                   if p.is_file() and p.name != "truth.json")
    assert any(f.suffix == ".jpg" for f in files) and any(f.name == "repose.csv" for f in files)
    for f in files:
        assert (tmp_path / "one" / f).read_bytes() == (tmp_path / "two" / f).read_bytes(), f
    assert one.provenance.options["discarded_heaps"] == two.provenance.options["discarded_heaps"]
