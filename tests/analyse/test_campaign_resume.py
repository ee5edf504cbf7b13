"""A calibration campaign on the real DEM, killed midway (SIGKILL) and run again, completes
without redoing any run that had finished (the run store, analyse.runs).

The rig is the repose twin itself, on a tiny carton (80 x 50 x 100 mm, 12 segments) so that one
run takes about half a second: the example workbook with its meta carton changed. What is
tested is the run store's bookkeeping across a kill, which does not depend on the heap's size."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import openpyxl

ROOT = Path(__file__).resolve().parents[2]
TINY_CARTON = {"box_length_mm": 80, "box_width_mm": 50, "box_height_mm": 100, "fill_count": 12}
#: replicates 1, 2 noise repeats and 3 climb levels: 12 + 2 + 3 + 17 + 3 = 37 DEM runs
CONFIG = ("CampaignConfig(workers=1, progress=False, workflow='design-expert', replicates=1, "
          "noise_repeats=2, climb_levels=3)")
KILL_AFTER = 6


def tiny_repose_runner(inputs: dict) -> dict:
    """The campaign's repose runner; a heap of 12 segments that slid flat and shows no slope
    counts as 0 deg (this test is about the run store, not about the angle)."""
    from demcal.analyse.campaign import campaign_runner

    result = campaign_runner(inputs)
    obs = result["observable"]
    if all(obs[k] is None or obs[k] != obs[k] for k in ("angle_deg", "angle_profile_deg")):
        obs["angle_deg"] = 0.0
    return result


def tiny_workbook(tmp_path: Path) -> Path:
    root = tmp_path / "lab"
    shutil.copytree(ROOT / "data" / "astragalus", root)
    path = root / "workbook.xlsx"
    wb = openpyxl.load_workbook(path)
    for row in wb["meta"].iter_rows(min_row=2):
        if row[0].value in TINY_CARTON:
            row[1].value = TINY_CARTON[row[0].value]
    wb.save(path)
    return path


def killed_and_rerun(tmp_path, config: str, kill_after: int, most: int):
    """Run a tiny-carton campaign with ``config`` in a subprocess, SIGKILL it once
    ``kill_after`` run records exist (fewer than ``most``, the campaign's runs), run it again to
    the end. Returns the records before the kill, the records after, and results.json."""
    workbook, out = tiny_workbook(tmp_path), tmp_path / "campaign"
    script = f"""
import sys
sys.path.insert(0, {str(ROOT)!r})
from demcal.analyse.campaign import CampaignConfig, calibrate
from tests.analyse.test_campaign_resume import tiny_repose_runner
calibrate({str(workbook)!r}, {str(out)!r}, {config}, runner=tiny_repose_runner)
"""
    proc = subprocess.Popen([sys.executable, "-c", script], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    runs = out / "runs"
    deadline = time.time() + 600
    while time.time() < deadline and proc.poll() is None:
        if runs.exists() and len(list(runs.glob("*.json"))) >= kill_after:
            break
        time.sleep(0.05)
    assert proc.poll() is None, f"the campaign ended before it could be killed: {proc.stderr.read()}"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    before = {p.name: p.read_bytes() for p in runs.glob("*.json")}
    assert kill_after <= len(before) < most
    assert not (out / "results.json").exists()

    done = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    results = json.loads((out / "results.json").read_text())
    records = {p.name: p.read_bytes() for p in runs.glob("*.json")}
    return before, records, results


def check_nothing_redone(before, records, results, asked):
    ran = sum(s["ran"] for s in results["stages"])
    reused = sum(s["reused"] for s in results["stages"])
    assert set(records) == asked and len(records) == ran + len(before)
    assert reused >= len(before)
    for name, content in before.items():
        assert records[name] == content, f"run {name} finished before the kill but was redone"
        assert json.loads(content)["status"] == "ok"


def test_killed_dem_campaign_resumes_without_redoing_finished_runs(tmp_path):
    before, records, results = killed_and_rerun(tmp_path, CONFIG, KILL_AFTER, 37)
    # every run the campaign asked for (37 tasks, fewer distinct ones when two design points
    # coincide) is stored once, and the ones finished before the kill were reused as they were
    asked = {run["key"] + ".json" for stage in ("plackett_burman", "noise", "steepest_climb",
                                                "box_behnken", "validation")
             for run in results[stage]["runs"]}
    assert sum(s["runs"] for s in results["stages"]) == 37
    check_nothing_redone(before, records, results, asked)
    assert results["validation"]["result"]["mean"] > 0


#: The plausible workflow on the heap alone (no twins), small: 8 noise runs, 4 design points
#: and up to 2 rounds of 2 points at 2 runs each (at most 16), 4 to 8 validation runs.
PLAUSIBLE = ("CampaignConfig(workers=1, progress=False, noise_repeats=4, likelihood='heap', "
             "initial_points=4, batch=2, budget_runs=16, validation_first=4, validation_step=4, "
             "validation_cap=8, replicates=2)")


def test_killed_plausible_campaign_resumes_without_redoing_finished_runs(tmp_path):
    # killed inside the design: the rerun must reach the same sequential choices from the store
    before, records, results = killed_and_rerun(tmp_path, PLAUSIBLE, 12, 32)
    asked = {run["key"] + ".json" for p in results["design"]["points"] for run in p["runs"]}
    asked |= {run["key"] + ".json" for run in results["validation"]["runs"]}
    check_nothing_redone(before, records, results, asked)
    assert results["validation"]["verdict"] in ("equivalent", "different", "undecided")
