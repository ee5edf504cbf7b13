"""``demcal simulate``: the JSON it writes, the rig options, and its errors (exit 2, one line)."""

import math

import pytest

from demcal.cli import main
from demcal.jsonio import read_json
from demcal.measure.workbook import write_workbook

JSON_KEYS = {"rig", "observable", "wall_s", "steps", "spheres", "sphere_steps_per_s", "seed",
             "params", "record", "provenance"}


def test_simulate_drop_writes_json(tmp_path, capsys):
    """End on, the apparent restitution is the contact's e (set to 0.5 here)."""
    out = tmp_path / "drop.json"
    rc = main(["simulate", "drop", "--orientation", "90", "--height", "100", "--seed", "4",
               "--set", "e_pw=0.5", "--json", str(out)])
    assert rc == 0
    doc = read_json(out)
    assert JSON_KEYS <= set(doc)
    assert doc["rig"] == "drop" and doc["seed"] == 4
    assert doc["params"]["e_pw"] == 0.5
    assert doc["observable"]["apparent_restitution"] == pytest.approx(0.5, rel=0.015)
    assert doc["observable"]["drop_height_m"] == pytest.approx(0.1, abs=1e-4)
    assert doc["spheres"] == 5 and doc["steps"] > 0 and doc["wall_s"] > 0
    assert doc["provenance"]["seed"] == 4
    assert doc["provenance"]["options"]["height"] == pytest.approx(0.1)
    assert "apparent_restitution" in capsys.readouterr().out


def test_simulate_incline_slide(tmp_path):
    out = tmp_path / "incline.json"
    assert main(["simulate", "incline", "--mode", "slide", "--set", "mu_s_pw=0.3", "--json", str(out)]) == 0
    obs = read_json(out)["observable"]
    assert obs["slide_angle_deg"] == pytest.approx(math.degrees(math.atan(0.3)), abs=0.5)
    assert obs["roll_angle_deg"] is None          # NaN in the rig, null in JSON


def test_simulate_repose_geometry_from_workbook(tmp_path):
    """--workbook: carton and fill from the meta sheet (quick profile scales them), the
    workbook's files hashed into the provenance, the big record arrays summarised."""
    wb = tmp_path / "wb"
    write_workbook({"meta": {"material": "segments", "box_length_mm": 80, "box_width_mm": 60,
                             "box_height_mm": 80, "plate_lift_speed_mm_s": 100, "fill_count": 60},
                    "specimens": [{"specimen_id": "S1", "length_mm": 25, "diameter_mm": 11, "mass_g": 2.0}]},
                   wb)
    out = tmp_path / "repose.json"
    rc = main(["simulate", "repose", "--workbook", str(wb), "--set", "rolling_lever=liggghts_reff",
               "--seed", "1", "--json", str(out)])
    assert rc == 0
    doc = read_json(out)
    assert JSON_KEYS <= set(doc) and doc["profile"] == "quick"
    assert set(doc["observable"]) == {"angle_deg", "angle_profile_deg", "angle_outside_deg", "escaped",
                                      "outside_fraction", "crest_height_m"}
    from demcal.simulate.rigs.heap import PROFILES
    s = PROFILES["quick"].scale
    assert doc["record"]["geometry"]["box_length"] == pytest.approx(0.08 * s)
    assert doc["record"]["geometry"]["fill_count"] == round(60 * s ** 3)
    assert len(doc["record"]["sphere_positions"]) == 5 * round(60 * s ** 3)   # small: kept whole
    assert doc["record"]["ke"] and doc["record"]["t_lift"] < doc["record"]["t_clear"]
    assert any(p.endswith("meta.csv") for p in doc["provenance"]["inputs"])


def test_simulate_vtk_frames(tmp_path):
    pytest.importorskip("demcal.simulate.vtk")
    frames = tmp_path / "frames"
    assert main(["simulate", "incline", "--tilt-rate", "4", "--vtk", str(frames)]) == 0
    written = sorted(p.name for p in frames.glob("*.vtp") if "walls" not in p.name)
    # a frame every 1/50 of the longest run (up to 60 deg), the run ends at the slide (11.3 deg)
    assert "last.vtp" in written and 8 <= len(written) <= 14
    assert "<VTKFile" in (frames / "last.vtp").read_text()[:300]


@pytest.mark.parametrize("argv, needle", [
    (["--set", "mu_q=0.3"], "unknown DEM parameter(s) 'mu_q'; valid names: poisson_ratio"),
    (["--set", "e_pw=high"], "DEM parameter e_pw needs a number, got 'high'"),
    (["--set", "e_pw"], "--set 'e_pw': expected NAME=VALUE; valid names:"),
    (["--set", "e_pw=1.5"], "e_pw must be in (0, 1]"),
    (["--orientation", "sideways"], "--orientation must be an angle in [0, 90] deg or 'random'"),
    (["--pair", "particle-wood"], "surface_material of 'wood' is needed"),
])
def test_simulate_bad_input_exits_2_with_one_line(argv, needle, capsys):
    rc = main(["simulate", "drop", *argv])
    err = capsys.readouterr().err
    assert rc == 2
    assert needle in err
    assert "Traceback" not in err and err.count("\n") == 1


@pytest.fixture(scope="module")
def lab_folder(tmp_path_factory):
    """A small virtual workbook as a folder of CSV sheets, written once for the module."""
    from demcal.simulate.virtual_lab import Truth, write_virtual_workbook

    return write_virtual_workbook(Truth(), tmp_path_factory.mktemp("lab") / "lab", rng=1, photos="analytic",
                                  n_photos=3, n_drop=2, n_incline=3, n_tracks=0, n_specimens=5,
                                  n_compression=3).path


DRUM = (["repose_rig,drum\n"], ["meta", "drum_diameter_mm", "missing"])
NO_HEIGHT = (["repose_rig,lifting_cylinder\n", "lift_speed_mm_s,10\n"], ["cylinder_diameter_mm", "missing"])


@pytest.mark.parametrize("command, rows, needles", [
    ("simulate", *DRUM), ("calibrate", *DRUM),
    ("simulate", ["repose_rig,pile\n"], ["repose_rig", "'pile' is not a repose rig",
                                          "lifted_plate, lifting_cylinder, funnel, drum"]),
    ("simulate", *NO_HEIGHT), ("calibrate", *NO_HEIGHT),
    ("simulate", ["drum_speed_rpm,5\n"], ["drum_speed_rpm", "a dimension of the drum rig"]),
    # the workbook's 25 mm segments would arch in a 60 mm tube
    ("calibrate", ["repose_rig,lifting_cylinder\n", "cylinder_diameter_mm,60\n", "cylinder_height_mm,120\n",
                   "lift_speed_mm_s,10\n"], ["under 4 particle lengths", "cylinder_diameter_mm"]),
])
def test_a_heap_the_twin_cannot_simulate_is_refused_before_any_run(command, rows, needles, lab_folder, tmp_path,
                                                                    capsys):
    """A lab whose heap came from a rig without a twin, from an unknown rig, or from a lifting
    cylinder whose dimensions are not all given or too small for its particles, is refused naming
    the file, the sheet and the key, instead of having another heap simulated."""
    import shutil

    wb = shutil.copytree(lab_folder, tmp_path / "lab")
    meta = (wb / "meta.csv").read_text(encoding="utf-8").splitlines(keepends=True)
    # the lifted plate's rows go: each test names its own rig
    keep = [line for line in meta if not line.startswith(("repose_rig,", "box_", "plate_lift", "fill_count"))]
    (wb / "meta.csv").write_text("".join(keep + rows), encoding="utf-8")
    argv = (["simulate", "repose", "--workbook", str(wb), "--json", str(tmp_path / "r.json")] if command == "simulate"
            else ["calibrate", str(wb), "--out", str(tmp_path / "out"), "--profile", "quick"])
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == 2 and "Traceback" not in err and err.count("\n") == 1
    assert "sheet 'meta'" in err and all(n in err for n in needles), err
    assert not (tmp_path / "r.json").exists() and not list((tmp_path / "out").glob("runs/*.json"))
