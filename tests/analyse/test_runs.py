"""The run store: atomic records, resume after a kill, failures recorded and retried once,
local processes and a local Dask cluster give the same records."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from demcal.analyse.runs import RunStore, Workers, run_all, run_key

ROOT = Path(__file__).resolve().parents[2]


def square_runner(inputs):
    """A stand-in for a DEM run: deterministic in its inputs, logs each call."""
    log = inputs.get("log")
    if log:
        with open(log, "a") as f:
            f.write(f"{inputs['x']}\n")
    time.sleep(inputs.get("sleep", 0.0))
    if inputs.get("fail_always"):
        raise RuntimeError(f"rig exploded at x={inputs['x']}")
    return {"y": inputs["x"] ** 2, "seed": inputs["seed"]}


def flaky_runner(inputs):
    """Fails on the first attempt (marker file absent), succeeds on the retry."""
    marker = Path(inputs["marker"])
    if not marker.exists():
        marker.write_text("tried")
        raise RuntimeError("transient failure")
    return {"y": inputs["x"]}


def test_run_key_is_order_independent():
    assert run_key({"a": 1, "b": [1, 2]}) == run_key({"b": [1, 2], "a": 1})
    assert run_key({"a": 1}) != run_key({"a": 2})


def test_rerun_reuses_finished_runs(tmp_path):
    store = RunStore(tmp_path / "runs")
    log = tmp_path / "calls.log"
    tasks = [{"x": x, "seed": x, "log": str(log)} for x in range(5)]
    first = run_all(tasks, square_runner, store, progress=False)
    assert (first.ran, first.reused, first.failed) == (5, 0, 0)
    assert [r["result"]["y"] for r in first.records] == [0, 1, 4, 9, 16]
    second = run_all(tasks, square_runner, store, progress=False)
    assert (second.ran, second.reused) == (0, 5)
    assert log.read_text().split() == ["0", "1", "2", "3", "4"]  # nothing ran twice
    rec = first.records[2]
    assert rec["provenance"]["seed"] == 2 and rec["provenance"]["code"]["demcal"]


def test_records_of_another_model_version_are_not_reused(tmp_path, monkeypatch):
    """A change of what the DEM computes (MODEL_VERSION) changes every key: the runs are made
    again beside the old records, which stay on disk."""
    import demcal.provenance as provenance

    store = RunStore(tmp_path / "runs")
    log = tmp_path / "calls.log"
    tasks = [{"x": x, "seed": x, "log": str(log)} for x in range(3)]
    first = run_all(tasks, square_runner, store, progress=False)
    assert first.records[0]["provenance"]["code"]["model_version"] == provenance.MODEL_VERSION
    monkeypatch.setattr(provenance, "MODEL_VERSION", provenance.MODEL_VERSION + 1)
    second = run_all(tasks, square_runner, store, progress=False)
    assert (second.ran, second.reused) == (3, 0)
    assert {r["key"] for r in second.records}.isdisjoint(r["key"] for r in first.records)
    assert len(list((tmp_path / "runs").glob("*.json"))) == 6


def test_failed_run_is_recorded_and_retried_once(tmp_path):
    store = RunStore(tmp_path / "runs")
    out = run_all([{"x": 3, "seed": 0, "fail_always": True}], square_runner, store, progress=False)
    rec = out.records[0]
    assert rec["status"] == "failed" and rec["attempts"] == 2
    assert "rig exploded at x=3" in rec["error"]
    assert out.failed == 1
    ok = run_all([{"x": 4, "seed": 0, "marker": str(tmp_path / "m")}], flaky_runner, store, progress=False)
    assert ok.records[0]["status"] == "ok" and ok.records[0]["attempts"] == 2


def test_killed_campaign_resumes_without_redoing_finished_runs(tmp_path):
    """Kill a campaign process midway (SIGKILL, no clean-up), rerun it: every run ends up done,
    and no run that had finished before the kill runs again."""
    log = tmp_path / "calls.log"
    script = f"""
import sys
sys.path.insert(0, {str(ROOT)!r})
from demcal.analyse.runs import RunStore, run_all
from tests.analyse.test_runs import square_runner
tasks = [{{"x": x, "seed": x, "log": {str(log)!r}, "sleep": 0.4}} for x in range(8)]
out = run_all(tasks, square_runner, RunStore({str(tmp_path / 'runs')!r}), progress=False)
print(out.ran, out.reused)
"""
    proc = subprocess.Popen([sys.executable, "-c", script], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    runs = tmp_path / "runs"
    deadline = time.time() + 60
    while time.time() < deadline:
        if runs.exists() and len(list(runs.glob("*.json"))) >= 3:
            break
        time.sleep(0.05)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    finished_before = {RunStore(runs).get(p.stem)["inputs"]["x"] for p in runs.glob("*.json")}
    assert 3 <= len(finished_before) < 8
    done = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    ran, reused = map(int, done.stdout.split())
    assert reused == len(finished_before) and ran == 8 - len(finished_before)
    calls = [int(x) for x in log.read_text().split()]
    for x in finished_before:
        assert calls.count(x) == 1, f"run x={x} finished before the kill but ran again"
    assert sorted(set(calls)) == list(range(8))


def test_local_processes_match_in_process(tmp_path):
    tasks = [{"x": x, "seed": 1} for x in range(4)]
    a = run_all(tasks, square_runner, RunStore(tmp_path / "a"), progress=False)
    b = run_all(tasks, square_runner, RunStore(tmp_path / "b"), workers=2, progress=False)
    assert [r["result"] for r in a.records] == [r["result"] for r in b.records]


def test_dask_local_cluster(tmp_path):
    distributed = pytest.importorskip("dask.distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        tasks = [{"x": x, "seed": 2} for x in range(4)]
        out = run_all(tasks, square_runner, RunStore(tmp_path / "d"),
                      scheduler=cluster.scheduler_address, progress=False)
    assert [r["result"]["y"] for r in out.records] == [0, 1, 4, 9]
    assert all(r["status"] == "ok" for r in out.records)


def test_prepare_runs_once_here_before_local_workers_and_only_when_needed(tmp_path):
    """``prepare`` (the campaign's: load or compile the DEM kernels) runs in this process
    before the worker processes start, and not at all when every run is already stored or the
    runs are made here."""
    calls = []
    tasks = [{"x": x, "seed": 0} for x in range(4)]
    store = RunStore(tmp_path / "runs")
    run_all(tasks, square_runner, store, workers=2, progress=False, prepare=lambda: calls.append(os.getpid()))
    assert calls == [os.getpid()]
    run_all(tasks, square_runner, store, workers=2, progress=False, prepare=lambda: calls.append("again"))
    run_all([{"x": 9, "seed": 0}], square_runner, RunStore(tmp_path / "one"), workers=1, progress=False,
            prepare=lambda: calls.append("inline"))
    assert calls == [os.getpid()]


def test_prepare_runs_before_the_progress_bar_opens(tmp_path, monkeypatch):
    """The campaign's ``prepare`` (a first compile of the DEM: half a minute or more) runs before
    the bar opens, so the bar's rate and time left count runs only, not the compilation."""
    import demcal.analyse.runs as runs

    calls = []

    class Bar:
        def __init__(self, *args, **kwargs):
            calls.append("bar")

        def update(self, n):
            pass

        def close(self):
            pass

    monkeypatch.setattr(runs, "tqdm", Bar)
    run_all([{"x": 1, "seed": 0}], square_runner, RunStore(tmp_path / "runs"), workers=2,
            prepare=lambda: calls.append("prepared"))
    assert calls == ["prepared", "bar"]


def pid_runner(inputs):
    """A stand-in run that says which process made it (and can kill that process)."""
    if inputs.get("die"):
        os._exit(3)
    return {"pid": os.getpid()}


def test_stages_sharing_workers_run_on_the_same_processes_prepared_once(tmp_path):
    """A campaign's stages share its :class:`Workers`: the second batch runs on the processes
    the first started (no new start, import and kernel load), ``prepare`` ran once before
    them, and closing ends them."""
    calls = []
    store = RunStore(tmp_path / "runs")
    with Workers(2, prepare=lambda: calls.append("prepared")) as workers:
        first = run_all([{"x": x, "seed": 1} for x in range(6)], pid_runner, store, progress=False,
                        executor=workers)
        second = run_all([{"x": x, "seed": 2} for x in range(6)], pid_runner, store, progress=False,
                         executor=workers)
        pids = {r["result"]["pid"] for r in first.records} | {r["result"]["pid"] for r in second.records}
        assert os.getpid() not in pids and 1 <= len(pids) <= 2
        assert {p.pid for p in workers._pool._processes.values()} >= pids
    assert calls == ["prepared"] and workers._pool is None


def die_once_runner(inputs):
    """Kills its worker process on the first attempt (marker file absent), succeeds after."""
    marker = Path(inputs["marker"])
    if not marker.exists():
        marker.write_text("died")
        os._exit(3)
    return {"pid": os.getpid()}


def test_a_pool_broken_by_a_dying_worker_is_replaced_for_the_retry_and_the_next_stage(tmp_path):
    """A worker process that dies breaks the pool; its run counts as a failed attempt, and the
    retry and the next batch get fresh processes instead of failing on the broken pool."""
    with Workers(2) as workers:
        out = run_all([{"x": 0, "seed": 0, "marker": str(tmp_path / "died")}], die_once_runner,
                      RunStore(tmp_path / "a"), progress=False, executor=workers)
        assert (out.failed, out.records[0]["status"], out.records[0]["attempts"]) == (0, "ok", 2)
        later = run_all([{"x": 1, "seed": 0}], pid_runner, RunStore(tmp_path / "b"), progress=False,
                        executor=workers)
        assert later.records[0]["status"] == "ok"


def test_compile_kernels_runs_the_engine_once_per_process(monkeypatch):
    from demcal.simulate import scenes
    steps = []

    class Case:
        def run(self, n_steps):
            steps.append(n_steps)

        def add_clump(self, template, position):
            steps.append("clump")

    monkeypatch.setattr(scenes, "build_paper_repose_case", lambda *a, **k: Case())
    scenes.compile_kernels.cache_clear()
    try:
        scenes.compile_kernels()
        scenes.compile_kernels()
    finally:
        scenes.compile_kernels.cache_clear()
    assert steps == [1, "clump", 1]     # one step, one admitted clump, one step: once
