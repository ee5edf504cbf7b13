"""``demcal virtual-lab``: a workbook written from a stated truth measures back to that truth
within its uncertainty; the truth file is read strictly; errors are one line."""

import json
import math
from pathlib import Path

import pandas as pd
import pytest
import yaml
from scipy import stats

from demcal.cli import main
from demcal.errors import InputError
from demcal.simulate.truth_file import design_defaults, parse_params, parse_truth, read_truth_file
from demcal.simulate.virtual_lab import EFFECT_KINDS, Truth
from demcal.simulate.virtual_lab_cli import parse_plant

EXAMPLE = Path(__file__).resolve().parents[2] / "data" / "virtual_lab" / "truth.yaml"


def stated_values(doc: dict) -> dict:
    """What each quantity of ``demcal measure`` should read, straight from a truth file's numbers
    (none planted, segments released end on: the apparent restitution is the contact one)."""
    p = doc["params"]
    L, d = p["segment_length_m"], p["segment_diameter_m"]
    envelope = doc["envelope_ratio"] * p["particle_density_kg_m3"]
    return {
        "length_mm": 1e3 * L, "diameter_mm": 1e3 * d,
        "mass_g": 1e3 * envelope * math.pi / 4 * (d ** 2 + doc["diameter_sd_m"] ** 2) * L,   # E[d^2] L
        "particle_density_kg_m3": p["particle_density_kg_m3"], "envelope_density_kg_m3": envelope,
        "restitution.particle-particle": p["e_pp"], "restitution.particle-steel": p["e_pw"],
        "static_friction.particle": p["mu_s_pp"], "static_friction.steel": p["mu_s_pw"],
        "rolling_friction.particle": p["mu_r_pp"], "rolling_friction.steel": p["mu_r_pw"],
        "poisson_ratio": p["poisson_ratio"],
        "elastic_modulus_pa": 2 * p["shear_modulus_pa"] * (1 + p["poisson_ratio"]),
        "shear_modulus_pa": p["shear_modulus_pa"], "repose_angle_deg": doc["repose_angle_deg"]}


def _measure(workbook, out, *extra):
    assert main(["measure", str(workbook), "--json", str(out), *extra]) == 0
    return json.loads(Path(out).read_text())["quantities"]


def _misses(quantities, truth, level=0.95):
    """Quantities whose Student-t interval at ``level`` (measure's 95 % interval rescaled) misses
    the truth."""
    out = []
    for name, value in truth.items():
        q = quantities[name]
        lo, hi = q["ci95"]
        half = (hi - lo) / 2 * stats.t.ppf((1 + level) / 2, q["n"] - 1) / stats.t.ppf(0.975, q["n"] - 1)
        if not (q["value"] - half <= value <= q["value"] + half):
            out.append((name, q["value"], lo, hi, value))
    return out


def test_example_truth_file_states_the_defaults():
    spec = read_truth_file(EXAMPLE)
    assert spec.truth == Truth()
    assert spec.design == design_defaults()


def test_virtual_lab_then_measure_reads_back_the_truth(tmp_path, capsys):
    """The README's two commands: every quantity the truth file states is printed and read back.
    Each lies in its 99.9 % interval, and at most two of the 15 miss their 95 % interval
    (probability 3.6 % for correct intervals)."""
    lab = tmp_path / "lab"
    assert main(["virtual-lab", str(EXAMPLE), "--out", str(lab), "--seed", "5"]) == 0
    printed = capsys.readouterr().out
    quantities = _measure(lab, tmp_path / "measurement.json")
    truth = stated_values(yaml.safe_load(EXAMPLE.read_text()))
    assert set(truth) == set(quantities)                   # the truth states everything measured
    for name, value in truth.items():                      # and the command prints it
        line = next(line for line in printed.splitlines() if line.startswith(name + " "))
        assert float(line.split()[1]) == pytest.approx(value, rel=1e-3)
    assert _misses(quantities, truth, level=0.999) == []
    assert len(_misses(quantities, truth)) <= 2


def test_coverage_over_seeds_is_binomial(tmp_path, capsys):
    """Over 40 seeds each truth value lies in its 95 % interval as often as a 95 % interval should:
    per quantity at most the 99.9 % quantile of Binomial(40, 0.05) misses, and over all of them
    at most that of Binomial(40 x 14, 0.05), with measure's default settings."""
    doc = yaml.safe_load(EXAMPLE.read_text())
    doc["design"]["photos"] = "none"
    truth_file = tmp_path / "truth.yaml"
    truth_file.write_text(yaml.safe_dump(doc))
    truth = stated_values(doc)
    del truth["repose_angle_deg"]
    seeds = range(100, 140)
    misses = {name: 0 for name in truth}
    for seed in seeds:
        lab = tmp_path / f"lab{seed}"
        assert main(["virtual-lab", str(truth_file), "--out", str(lab), "--seed", str(seed)]) == 0
        quantities = _measure(lab, tmp_path / f"m{seed}.json")
        for name, *_ in _misses(quantities, truth):
            misses[name] += 1
    capsys.readouterr()
    per_quantity = stats.binom.ppf(0.999, len(seeds), 0.05)
    overall = stats.binom.ppf(0.999, len(seeds) * len(truth), 0.05)
    assert max(misses.values()) <= per_quantity, misses
    assert sum(misses.values()) <= overall, misses


def test_params_are_checked_together_not_one_by_one():
    # each alone breaks a check between fields against the defaults (diameter 11 mm > length
    # 10 mm; a scaled mass model without a mass); together they are valid
    p = parse_params({"segment_length_m": 0.01, "segment_diameter_m": 0.008})
    assert (p.shape.length_m, p.shape.diameter_m) == (0.01, 0.008)
    p = parse_params({"mass_model": "scaled", "mean_mass_kg": 0.002})
    assert (p.mass_model, p.mean_mass_kg) == ("scaled", 0.002)
    with pytest.raises(InputError, match=r"^params: segment shape: the diameter \(20 mm\) exceeds the length \(15 mm\)"):
        parse_params({"segment_length_m": 0.015, "segment_diameter_m": 0.02})


def test_params_read_former_names_and_blame_the_wrong_field_on_the_files_shape():
    # a truth file written before the rename of segment_sizes reads as the distribution it meant
    p = parse_params({"segment_sizes": [[0.025, 0.011], [0.03, 0.012]]})
    assert p.particle_sizes == ((0.025, 0.011), (0.03, 0.012))
    # a sphere's sizes are valid on the file's sphere: the bad field, not particle_sizes, is named
    with pytest.raises(InputError, match=r"^params\.e_pw: e_pw must be in"):
        parse_params({"shape": "sphere:0.0066", "particle_sizes": [[0.006], [0.007]], "e_pw": 1.5})


def test_hand_released_segments_are_compared_with_their_apparent_restitution(tmp_path, capsys):
    """Released at any angle, a segment turns part of its energy into rotation: the drops read
    the drop twin's apparent restitution, which the command prints, not the contact one."""
    doc = {"design": {"pairs": ["particle-steel"], "drop_heights_mm": [400], "n_drop": 24, "surfaces": [],
                      "n_compression": 0, "n_tracks": 0, "photos": "none"}}
    truth_file = tmp_path / "truth.yaml"
    truth_file.write_text(yaml.safe_dump(doc))
    lab = tmp_path / "lab"
    assert main(["virtual-lab", str(truth_file), "--out", str(lab), "--plant", "orientation_rotation=0"]) == 0
    line = next(line for line in capsys.readouterr().out.splitlines()
                if line.startswith("restitution.particle-steel "))
    apparent = float(line.split()[1])
    assert apparent < 0.9 * Truth().params.e_pw
    q = _measure(lab, tmp_path / "m.json")["restitution.particle-steel"]
    assert _misses({"e": q}, {"e": apparent}, level=0.999) == []
    assert not q["ci95"][0] <= Truth().params.e_pw <= q["ci95"][1]


def test_planted_effect_is_recorded(tmp_path, capsys):
    lab = tmp_path / "lab"
    doc = {"design": {"photos": "none", "n_compression": 0}}
    (tmp_path / "t.yaml").write_text(yaml.safe_dump(doc))
    assert main(["virtual-lab", str(tmp_path / "t.yaml"), "--out", str(lab), "--seed", "3",
                 "--plant", "velocity_dependent_restitution=-1e-4", "--plant", "trial_order_drift"]) == 0
    out = capsys.readouterr().out
    assert "planted: velocity_dependent_restitution, size -0.0001" in out
    assert "planted: trial_order_drift, size 0.004" in out
    recorded = json.loads((lab / "truth.json").read_text())
    assert [e["kind"] for e in recorded["effects"]] == ["velocity_dependent_restitution", "trial_order_drift"]
    assert recorded["seed"] == 3


@pytest.mark.parametrize("text,message", [
    ("e_sdd: 0.1", "unknown key 'e_sdd'; valid: params, e_sd"),
    ("e_sd: -0.1", "e_sd: must be a number >= 0, got -0.1"),
    ("e_sd: lots", "e_sd: must be a number >= 0, got 'lots'"),
    ("icc: 1", "icc: must be a number in [0, 1), got 1"),
    ("repose_angle_deg: 85", "repose_angle_deg: must be a number in (0, 80), got 85"),
    ("operators: []", "operators: must name at least one level"),
    ("params: {e_pp: 1.5}", "params.e_pp: e_pp must be in (0, 1], got 1.5"),
    ("params: {e_ppp: 0.3}", "unknown DEM parameter 'e_ppp'; valid: poisson_ratio"),
    ("params: {mu_s_pw: yes}", "params.mu_s_pw: must be a number, got True"),
    ("design: {n_drop: 0}", "design.n_drop: must be an integer >= 1, got 0"),
    ("design: {pairs: [particle-rubber]}", "design.pairs: 'particle-rubber' not valid; valid: particle-particle, "
                                           "particle-steel"),
    ("design: {photos: film}", "design.photos: must be one of analytic, dem, none, got 'film'"),
    ("design: {orientation_range_deg: [80, 20]}", "design.orientation_range_deg: must be [low, high] with 0 <= low"),
    ("design: {drop_heights_mm: [400, -1]}", "design.drop_heights_mm: must be a number > 0, got -1"),
    ("design: {heights: [400]}", "design: unknown key 'heights'; valid: photos, n_specimens"),
    ("design: {repose_rig: {repose_rig: drum}}", "design.repose_rig: sheet 'meta', column 'value': meta "
                                                 "drum_diameter_mm: missing"),
    ("design: {repose_rig: {repose_rig: lifting_cylinder, cylinder_diameter_mm: 60, lift_speed_mm_s: 10}}",
     "design.repose_rig: sheet 'meta', column 'value': meta cylinder_height_mm: missing"),
    ("design: {repose_rig: lifting_cylinder}", "design.repose_rig must be a mapping of workbook meta keys"),
    ("- e_sd", "must be a mapping"),
])
def test_truth_file_refuses_what_it_does_not_know(tmp_path, text, message):
    path = tmp_path / "bad.yaml"
    path.write_text(text + "\n")
    with pytest.raises(InputError) as info:
        read_truth_file(path)
    assert str(path) in str(info.value) and message in str(info.value)


def test_truth_file_reads_dates_and_fills_defaults():
    spec = parse_truth(yaml.safe_load("days: [2024-05-01, 2024-05-02]\nparams: {e_pw: 0.4}\n"
                                      "design: {drop_heights_mm: 300, pairs: particle-steel}"))
    assert spec.truth.days == ("2024-05-01", "2024-05-02") and spec.truth.params.e_pw == 0.4
    assert spec.truth.params.e_pp == Truth().params.e_pp and spec.truth.e_sd == Truth().e_sd
    assert spec.design["drop_heights_mm"] == [300.0] and spec.design["pairs"] == ["particle-steel"]
    assert spec.design["n_drop"] == design_defaults()["n_drop"]


def test_plant_option_names_the_valid_kinds():
    with pytest.raises(InputError, match="valid: " + ", ".join(EFFECT_KINDS)):
        parse_plant(["wet_segments=2"])
    with pytest.raises(InputError, match="SIZE must be a number"):
        parse_plant(["block_effect=big"])
    with pytest.raises(InputError, match=r"lowest release angle\) must be in \[0, 90\)"):
        parse_plant(["orientation_rotation=95"])
    (effect,) = parse_plant(["camera_tilt"])
    assert effect.size == 2.0


def test_errors_are_one_line_and_an_earlier_workbook_is_replaced_only_when_asked(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("e_sd: -1\n")
    assert main(["virtual-lab", str(bad), "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "e_sd" in err and str(bad) in err
    assert main(["virtual-lab", str(EXAMPLE), "--out", str(tmp_path / "x"), "--plant", "wet=1"]) == 2
    assert "valid: velocity_dependent_restitution" in capsys.readouterr().err
    truth = tmp_path / "t.yaml"
    truth.write_text("design: {photos: analytic, n_photos: 2, n_compression: 0}\n")
    lab = tmp_path / "lab"
    assert main(["virtual-lab", str(truth), "--out", str(lab)]) == 0
    assert main(["virtual-lab", str(truth), "--out", str(lab)]) == 2
    assert "not empty" in capsys.readouterr().err
    truth.write_text("design: {photos: none, n_compression: 0}\n")
    assert main(["virtual-lab", str(truth), "--out", str(lab), "--force"]) == 0
    assert not (lab / "repose.csv").exists() and not list((lab / "photos").glob("*.jpg"))
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    assert main(["virtual-lab", str(truth), "--out", str(other), "--force"]) == 2
    assert "holds other files" in capsys.readouterr().err and (other / "notes.txt").exists()
    # a design the virtual lab refuses leaves the earlier workbook in place, even with --force
    before = sorted(p.name for p in lab.iterdir())
    assert main(["virtual-lab", str(truth), "--out", str(lab), "--force", "--plant", "camera_tilt"]) == 2
    assert "needs photos" in capsys.readouterr().err
    assert sorted(p.name for p in lab.iterdir()) == before


#: Truth files of the other shapes (sizes in m, 6 % relative spread), and the mean envelope
#: volume their specimens have, in closed form: a sphere's E[pi d^3 / 6] with
#: E[d^3] = mu^3 + 3 mu sigma^2; an ellipsoid's pi E[L] E[W] E[T] / 6 (independent axes); the
#: clump's union of two touching spheres, scaled with L: V(L0) E[(L / L0)^3].
OTHER_SHAPES = {
    "sphere": ("sphere:0.0066", lambda d=0.0066, s=0.06: math.pi / 6 * (d ** 3 + 3 * d * (s * d) ** 2),
               {"diameter_mm": 6.6}),
    "kernel": ("kernel:0.0072:0.0030:0.0021", lambda: math.pi / 6 * 0.0072 * 0.0030 * 0.0021,
               {"length_mm": 7.2, "width_mm": 3.0, "thickness_mm": 2.1}),
    "clump": ({"shape": "clump", "length_m": 0.008, "table": [[0, 0, 0, 0.002], [0.004, 0, 0, 0.002]]},
              lambda s=0.06: 2 * 4 / 3 * math.pi * 0.002 ** 3 * (1 + 3 * s ** 2), {"length_mm": 8.0}),
}


@pytest.mark.parametrize("shape", sorted(OTHER_SHAPES))
def test_every_shape_is_written_and_read_back_by_measure(shape, tmp_path, capsys):
    """A virtual workbook of each shape: its calliper columns, masses, densities, restitutions
    (a sphere rebounds at its contact restitution at any orientation) and frictions (a sphere's
    static friction by a sled) each lie in their 99.9 % interval around the truth stated in
    closed form."""
    value, volume, sizes = OTHER_SHAPES[shape]
    doc = yaml.safe_load(EXAMPLE.read_text())
    doc["params"] = {**{k: v for k, v in doc["params"].items() if not k.startswith("segment_")},
                     "shape": value, "particle_density_kg_m3": 1200.0, "dt": None}
    doc["design"].update(photos="none", n_tracks=0, drop_heights_mm=[400], orientation_range_deg=[0, 90])
    truth_file = tmp_path / "truth.yaml"
    truth_file.write_text(yaml.safe_dump(doc))
    lab = tmp_path / "lab"
    assert main(["virtual-lab", str(truth_file), "--out", str(lab), "--seed", "11"]) == 0
    capsys.readouterr()
    quantities = _measure(lab, tmp_path / "m.json")
    p = doc["params"]
    envelope = doc["envelope_ratio"] * 1200.0
    truth = {**sizes, "mass_g": 1e3 * envelope * volume(), "particle_density_kg_m3": 1200.0,
             "envelope_density_kg_m3": envelope,
             "static_friction.particle": p["mu_s_pp"], "static_friction.steel": p["mu_s_pw"],
             "rolling_friction.particle": p["mu_r_pp"], "rolling_friction.steel": p["mu_r_pw"]}
    if shape == "sphere":
        truth.update({"restitution.particle-particle": p["e_pp"], "restitution.particle-steel": p["e_pw"]})
    truth["poisson_ratio"] = p["poisson_ratio"]           # the compressions' strains, any shape
    if shape == "kernel":                               # its curves read like a segment's
        truth["shear_modulus_pa"] = p["shear_modulus_pa"]
    assert ("shear_modulus_pa" in quantities) == (shape == "kernel")
    assert _misses(quantities, truth, level=0.999) == []
    book = read_truth_file(truth_file)
    assert book.truth.params.shape.name == shape
    incline = pd.read_excel(lab / "workbook.xlsx", sheet_name="incline") if (lab / "workbook.xlsx").exists() \
        else pd.read_csv(lab / "incline.csv")
    sled = set(incline.loc[incline["mode"] == "slide", "carrier"])
    assert sled == ({"sled"} if shape == "sphere" else {"particle"})
