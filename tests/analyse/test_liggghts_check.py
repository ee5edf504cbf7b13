"""``demcal export --to liggghts --check``: a calibrated set run in LIGGGHTS in the lab's repose
rig and its angle tested against the lab's.

The small case is a carton of 60 soybean-sized spheres, run for 2.6 s (a few seconds of
LIGGGHTS each); it is skipped without the binary (CI installs it). The angles the check reports
are measured again from the final positions LIGGGHTS wrote, and the verdict is recomputed from
them by the two one-sided tests at the last look's level.
"""

import json
import math
from types import SimpleNamespace

import numpy as np
import pytest

from demcal.simulate.liggghts.run import find_liggghts

needs_liggghts = pytest.mark.skipif(find_liggghts() is None, reason="LIGGGHTS not installed")


def _params():
    from demcal.simulate.params import DEMParameters
    from demcal.simulate.shapes.sphere import Sphere

    return DEMParameters(shape=Sphere(0.0066), particle_density_kg_m3=1200.0, shear_modulus_pa=1.04e6, dt=None,
                         mu_s_pp=0.5, mu_r_pp=0.3, mu_s_pw=0.5, mu_r_pw=0.3)


def _results(target: float, tolerance: float, lab_sd: float = 1.0, lab_n: int = 5):
    """The parts of a ``CampaignResult`` the check reads: a small carton, the calibrated set,
    the lab's target and the validation's tolerance."""
    from demcal.simulate.rigs.repose import ReposeGeometry

    geometry = ReposeGeometry(box_length=0.06, box_width=0.04, box_height=0.08, lift_speed=0.2, fill_count=60)
    test = {"target_sd_deg": lab_sd, "target_n": lab_n, "alpha": 0.05}
    validation = SimpleNamespace(target_deg=target, tolerance_deg=tolerance, test=test, verdict="equivalent",
                                 mean_deg=target, ci95=(target - 1, target + 1), n_runs=10)
    return SimpleNamespace(repose_rig="lifted_plate", calibrated_parameters=_params().to_dict(),
                           geometry=geometry.to_dict(), validation=validation)


@needs_liggghts
def test_the_check_reads_each_heap_as_the_rig_does_and_tests_it_against_the_lab(tmp_path):
    from demcal.analyse.equivalence import equivalence_test
    from demcal.analyse.liggghts_check import check_calibration
    from demcal.simulate.liggghts.run import read_positions
    from demcal.simulate.rigs import rig

    far = check_calibration(_results(target=80.0, tolerance=1.0), tmp_path / "far", lift_time=1.0,
                            duration=2.6, first=3, step=1, cap=3)
    angles = [r.angle_deg for r in far.runs if math.isfinite(r.angle_deg)]
    assert len(angles) == 3 and all(5.0 < a < 60.0 for a in angles)
    # each angle is the rig's own reading of the positions LIGGGHTS wrote
    for run in far.runs:
        _, _, positions, radii = read_positions(f"{run.workdir}/final_positions.txt")
        heap = rig("repose").measure(positions, radii, far.case)
        assert heap[run.read_by] == pytest.approx(run.angle_deg, abs=1e-9)
    # a lab at 80 deg is far beyond LIGGGHTS' heaps: different, and the test is the TOST
    assert far.verdict == "different" and far.test["n_runs"] == 3
    again = equivalence_test(angles, 80.0, 1.0, 5, 1.0, far.test["alpha"])
    assert again.verdict == "different" and again.p_tost == pytest.approx(far.test["p_tost"])
    # a lab at LIGGGHTS' own mean, with a tolerance far above the run scatter: equivalent
    mean, spread = float(np.mean(angles)), float(np.ptp(angles))
    near = check_calibration(_results(target=mean, tolerance=5.0 + 3.0 * spread), tmp_path / "near",
                             lift_time=1.0, duration=2.6, first=3, step=1, cap=3)
    assert near.verdict == "equivalent"
    assert [r.angle_deg for r in near.runs] == pytest.approx([r.angle_deg for r in far.runs], abs=1e-9)
    doc = json.loads(json.dumps(near.to_dict()))
    assert doc["schedule"] == {"lift_time_s": 1.0, "duration_s": 2.6,
                               "settling_from_s": pytest.approx(1.0 + 0.08 / 0.2)}


def test_runs_with_no_heap_end_the_check_as_failed_keeping_the_runs_made(tmp_path, monkeypatch):
    """LIGGGHTS runs whose heaps the estimator cannot read are replaced by the next seed, twice;
    then the check ends as ``failed``, saying why, with every run it made listed."""
    import demcal.simulate.liggghts.run as lig
    from demcal.analyse.liggghts_check import MAX_TRIES_PER_RUN, check_calibration

    def empty_heap(seed, workdir, duration, case, binary=None, nice=0):
        return {"version": "LIGGGHTS-PUBLIC 3.8.0", "positions": np.zeros((0, 3)), "radii": np.zeros(0),
                "deck": {"case": case.to_dict()}, "wall_s": 0.1, "spheres": 0, "lost_spheres": 60}

    monkeypatch.setattr(lig, "run_liggghts", empty_heap)
    check = check_calibration(_results(target=30.0, tolerance=2.0), tmp_path, lift_time=1.0, duration=2.6,
                              first=3, step=1, cap=3)
    assert check.verdict == "failed" and check.test is None
    assert len(check.runs) == MAX_TRIES_PER_RUN and [r.seed for r in check.runs] == [1, 2]
    assert "gave no angle of repose" in check.failure and "failed after 2 run(s)" in check.summary()
    assert all("60 spheres left LIGGGHTS' box" in r.notes for r in check.runs)
    json.dumps(check.to_dict())


def test_the_check_is_refused_without_liggghts_and_for_another_format(tmp_path, monkeypatch, capsys):
    """--check with another format is refused by name; without a LIGGGHTS binary the check
    says how to install it and exits 2, after writing the export."""
    import shutil

    from demcal.cli import main

    campaign = tmp_path / "campaign"
    campaign.mkdir()
    assert main(["export", str(campaign), "--to", "yade", "--check"]) == 2
    assert "--check runs the calibrated set in LIGGGHTS" in capsys.readouterr().err
    example = tmp_path / "example"
    shutil.copytree(_stand_in_campaign(tmp_path), example)
    monkeypatch.setenv("DEMCAL_LIGGGHTS", str(tmp_path / "no-such-liggghts"))
    monkeypatch.setattr("shutil.which", lambda *a, **k: None)
    assert main(["export", str(example), "--to", "liggghts", "--check"]) == 2
    captured = capsys.readouterr()
    assert (example / "export" / "liggghts_materials.in").exists()
    assert "apt-get install liggghts" in captured.err and "Traceback" not in captured.err


def test_the_schedule_lifts_the_wall_and_settles_as_the_papers_carton():
    """The paper's carton: lifted at 4 s at 0.1 m/s past its 250 mm, settled 3.5 s after: the
    paper's 10 s."""
    from demcal.analyse.liggghts_check import schedule_for
    from demcal.errors import InputError
    from demcal.simulate.liggghts.deck import ReposeCase

    plan = schedule_for(ReposeCase())
    assert plan["settling_from_s"] == pytest.approx(6.5)
    assert plan["duration_s"] == pytest.approx(10.0)
    with pytest.raises(InputError, match="--lift-time"):
        schedule_for(ReposeCase(plate_lift_start=0.5))
    with pytest.raises(InputError, match="--duration"):
        schedule_for(ReposeCase(), duration=3.0)


def _stand_in_campaign(tmp_path):
    """A finished calibration of the example with the heap stand-in (no DEM)."""
    import shutil
    from pathlib import Path

    from demcal.analyse.campaign import CampaignConfig, calibrate
    from tests.analyse.standin import heap_standin_runner

    example = Path(__file__).resolve().parents[2] / "data" / "astragalus"
    data = tmp_path / "data"
    shutil.copytree(example, data)
    out = tmp_path / "standin"
    calibrate(data / "workbook.xlsx", out, CampaignConfig(workers=1, progress=False, seed=3),
              runner=heap_standin_runner)
    return out
