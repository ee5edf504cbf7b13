"""``demcal plan TRUTH --rigs``: what each repose rig of a design pins down alone and together,
with the linear stand-ins of ``test_several_rigs`` (two rigs reading rolling and steel friction in
other combinations) and analytic photos."""

import pytest

from demcal.analyse.campaign import CampaignConfig
from demcal.analyse.rig_plan import plan_rigs
from demcal.errors import InputError
from tests.analyse.test_several_rigs import ANGLE, two_rig_runner

TRUTH = """
params: {{}}
repose_angle_deg: {angle}
design:
  pairs: [particle-particle, particle-steel]
  drop_heights_mm: [400]
  n_drop: 6
  n_tracks: 0
  photos: analytic
  n_photos: 6
  repose_rig:
    repose_rig: {rigs}
    drum_diameter_mm: 400
    drum_width_mm: 150
    drum_speed_rpm: 5
"""


def _truth(tmp_path, rigs="lifted_plate, drum"):
    path = tmp_path / "truth.yaml"
    path.write_text(TRUTH.format(angle=ANGLE, rigs=rigs))
    return path


def test_the_plan_says_what_a_second_rig_buys_and_reruns_nothing(tmp_path):
    config = CampaignConfig(workers=1, progress=False, likelihood="heap", budget_runs=32)
    plan = plan_rigs(_truth(tmp_path), tmp_path / "plan", seed=3, config=config, runner=two_rig_runner)
    assert list(plan.by_rig) == ["lifted_plate", "drum"]
    # each rig alone narrows both frictions a little; together they pin them down
    for name in ("mu_r_pp", "mu_s_pw"):
        assert plan.gain(name) >= 0.1, name
    for name in ("e_pp", "e_pw", "poisson_ratio"):
        assert plan.together[name]["sd_ratio"] > 0.9
    assert any("analytic photos" in n for n in plan.notes)
    text = plan.table()
    assert "lifted_plate alone" in text and "drum alone" in text and "narrowed by combining" in text
    # the same truth file and seed again: the same workbook measured, every run from the store
    again = plan_rigs(_truth(tmp_path), tmp_path / "plan", seed=3, config=config, runner=_no_runs)
    assert again.together == plan.together and again.by_rig == plan.by_rig
    assert any("measured again" in n for n in again.notes)


def _no_runs(inputs):
    raise AssertionError("a second plan of the same truth file reran a DEM run")


def test_a_plan_without_rigs_or_from_a_workbook_is_refused(tmp_path):
    bad = tmp_path / "none.yaml"
    bad.write_text("params: {}\ndesign:\n  photos: analytic\n")
    with pytest.raises(InputError, match="names no repose rig"):
        plan_rigs(bad, tmp_path / "p")
    with pytest.raises(InputError, match="starts from a truth file"):
        plan_rigs(tmp_path / "workbook.xlsx", tmp_path / "p")


def test_the_command_refuses_a_rig_plan_without_its_folder(tmp_path, capsys):
    from demcal.cli import main

    truth = _truth(tmp_path)
    assert main(["plan", str(truth), "--rigs"]) == 2
    assert "--rigs needs --out DIR" in capsys.readouterr().err
    assert main(["plan", str(truth), "--rigs", "--out", str(tmp_path / "p"), "--mechanisms", "block_effect"]) == 2
    assert main(["plan", str(truth), "--out", str(tmp_path / "p")]) == 2
    assert "belong to --rigs" in capsys.readouterr().err
