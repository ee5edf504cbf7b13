"""Runs on a real Dask cluster: a ``dask scheduler`` and two ``dask worker`` processes on
127.0.0.1, one worker SIGKILLed while it has a run in flight. Every run ends up stored exactly
once, no run that had finished is run again, a rerun skips everything, and the campaign that
went through ``demcal calibrate --scheduler`` is complete.

Workers run without a nanny, so the killed worker stays dead and its run in flight is lost for
good: the other worker has to take it over. The runs are the slow analytic stand-in
(``tests.analyse.standin.slow_standin_runner``), which logs where each run starts and ends."""

import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import pytest

from demcal.analyse.runs import RunStore, run_all, run_key
from tests.analyse.standin import SLOW_STANDIN_LOG, slow_standin_runner, standin_runner

ROOT = Path(__file__).resolve().parents[2]
#: The ``dask`` command of the interpreter running the tests (the project's venv).
DASK = Path(sys.executable).parent / "dask"


@dataclass
class Cluster:
    address: str
    workers: list  # subprocess.Popen of each worker; its pid is the worker process's
    log: Path  # where the slow stand-in logs its runs
    closed: threading.Event  # set when the fixture tears the cluster down


def _stop(proc: subprocess.Popen) -> None:
    """End a process the fixture started, and anything it started (its own session)."""
    if proc.poll() is None:
        try:
            os.killpg(proc.pid, signal.SIGTERM)
            os.killpg(proc.pid, signal.SIGCONT)  # a worker a failed test left stopped
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    proc.wait()


@pytest.fixture
def dask_cluster(tmp_path, request):
    """A scheduler and two single-threaded workers without nanny, as separate processes.

    Parametrised indirectly, the parameter is the scheduler's ``allowed-failures``: how many
    workers may die running a task before its future fails with ``KilledWorker``."""
    distributed = pytest.importorskip("distributed")
    if not DASK.exists():
        pytest.skip(f"the dask command is missing: {DASK} (install dask[distributed])")
    log = tmp_path / "standin.log"
    # the workers import the runner from tests.analyse.standin, and log where it runs
    env = {**os.environ, SLOW_STANDIN_LOG: str(log),
           "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    procs, closed = [], threading.Event()

    def start(name, *args, env=env):
        with open(tmp_path / f"{name}.out", "w") as out:
            proc = subprocess.Popen([str(DASK), *args], cwd=tmp_path, env=env, stdout=out,
                                    stderr=subprocess.STDOUT, start_new_session=True)
        procs.append(proc)
        return proc

    try:
        scheduler_file = tmp_path / "scheduler.json"
        allowed = getattr(request, "param", None)
        start("scheduler", "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
              "--scheduler-file", str(scheduler_file),
              env=env if allowed is None else {**env, "DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES": str(allowed)})
        deadline, address = time.time() + 30, None
        while address is None:
            if procs[0].poll() is not None or time.time() > deadline:
                pytest.fail("the Dask scheduler did not start: " + (tmp_path / "scheduler.out").read_text())
            time.sleep(0.05)
            try:
                address = json.loads(scheduler_file.read_text())["address"]
            except (OSError, ValueError, KeyError):  # not there yet, or half written
                pass
        workers = [start(f"worker{i}", "worker", address, "--nthreads", "1", "--no-nanny",
                         "--no-dashboard", "--name", f"w{i}", "--local-directory", str(tmp_path / f"w{i}"))
                   for i in range(2)]
        with distributed.Client(address, timeout="10s") as client:
            client.wait_for_workers(2, timeout=30)
        yield Cluster(address, workers, log, closed)
    finally:
        closed.set()
        for proc in reversed(procs):
            _stop(proc)


def read_log(log: Path) -> list[tuple[str, str, int]]:
    """(event, run key, pid) of each complete line of the stand-in's log."""
    if not log.exists():
        return []
    lines = [line.split() for line in log.read_text().splitlines()]
    return [(e, k, int(p)) for e, k, p in (line for line in lines if len(line) == 3)]


def in_flight(events, pid: int) -> set:
    started = Counter(k for e, k, p in events if e == "start" and p == pid)
    ended = Counter(k for e, k, p in events if e == "end" and p == pid)
    return set((started - ended).keys())


@dataclass
class Kill:
    pid: int = 0
    lost: set = None  # runs the victim had started and not ended when it was killed
    stored: set = None  # keys of the records stored before the kill
    error: BaseException = None


class Killer(threading.Thread):
    """Once ``after`` records are stored, SIGKILL a worker that has a run in flight.

    The worker is stopped (SIGSTOP) while its log is read, so the run seen in flight is still in
    flight when SIGKILL arrives."""

    def __init__(self, cluster: Cluster, runs: Path, after: int):
        super().__init__(daemon=True)
        self.cluster, self.runs, self.after, self.kill = cluster, runs, after, Kill()

    def run(self):
        try:
            deadline = time.time() + 60
            while time.time() < deadline and not self.cluster.closed.is_set():
                if self.runs.exists() and len(list(self.runs.glob("*.json"))) >= self.after:
                    for worker in self.cluster.workers:
                        if worker.poll() is not None:
                            continue
                        os.kill(worker.pid, signal.SIGSTOP)
                        try:
                            busy = in_flight(read_log(self.cluster.log), worker.pid)
                            if busy:
                                stored = {p.stem for p in self.runs.glob("*.json")}
                                os.kill(worker.pid, signal.SIGKILL)
                                worker.wait()
                                self.kill = Kill(worker.pid, busy, stored)
                                return
                        finally:
                            if worker.poll() is None:
                                os.kill(worker.pid, signal.SIGCONT)
                time.sleep(0.02)
            raise TimeoutError(f"no worker had a run in flight after {self.after} records were stored")
        except BaseException as exc:  # reported by the test thread
            self.kill = Kill(error=exc)

    def result(self) -> Kill:
        self.join(timeout=60)
        if self.kill.error is not None:
            raise self.kill.error
        return self.kill


def check_runs(kill: Kill, records: list, keys: set, log: Path, survivor: int, retried: bool = False):
    """Every run stored once and ok; only work lost with the killed worker was done again. With
    ``retried``, the runs lost were retried by the executor (a second attempt: the run in flight,
    and any the scheduler had already handed to the worker), else by Dask (a first attempt)."""
    assert {r["key"] for r in records} == keys
    assert all(r["status"] == "ok" for r in records)
    second = {r["key"] for r in records if r["attempts"] == 2}
    assert all(r["attempts"] == 1 for r in records if r["key"] not in second)
    if retried:
        assert kill.lost <= second <= keys - kill.stored
    else:
        assert not second
    events = read_log(log)
    ends = Counter(k for e, k, p in events if e == "end")
    assert set(ends) == keys, "a run never finished"
    # the run in flight on the killed worker was taken over by the other one
    assert kill.lost and all((("end", k, survivor) in events) for k in kill.lost)
    # a run whose record was stored before the kill ran once: finished work is never redone
    assert all(ends[k] == 1 for k in kill.stored), {k: ends[k] for k in kill.stored if ends[k] != 1}
    # runs done twice are only those the killed worker had started and not delivered
    on_victim = {k for e, k, p in events if e == "start" and p == kill.pid}
    starts = Counter(k for e, k, p in events if e == "start")
    assert {k for k in keys if starts[k] > 1} <= on_victim - kill.stored


TASKS = [{"rig": "repose", "params": {"e_pp": 0.3 + 0.01 * (i % 5), "e_pw": 0.35, "mu_s_pw": 0.2},
          "seed": i} for i in range(16)]


@pytest.mark.timeout(120)
@pytest.mark.parametrize("dask_cluster", [None, 0], indirect=True, ids=["dask-retries", "KilledWorker"])
def test_executor_survives_a_killed_worker(dask_cluster, tmp_path, request):
    """Killed with a run in flight: Dask reruns it elsewhere, or (scheduler allowed no failure)
    the future fails with ``KilledWorker`` and the executor submits the run again."""
    retried = request.node.callspec.params["dask_cluster"] == 0
    store = RunStore(tmp_path / "runs")
    keys = {run_key(t) for t in TASKS}
    killer = Killer(dask_cluster, store.root, after=4)
    killer.start()
    out = run_all(TASKS, slow_standin_runner, store, scheduler=dask_cluster.address, progress=False)
    kill = killer.result()
    assert 4 <= len(kill.stored) < len(TASKS)
    assert (out.ran, out.reused, out.failed) == (len(TASKS), 0, 0)
    survivor = next(w.pid for w in dask_cluster.workers if w.pid != kill.pid)
    check_runs(kill, store.records(), keys, dask_cluster.log, survivor, retried)
    # results in task order, as the stand-in gives them in this process
    assert [r["result"] for r in out.records] == [standin_runner(t) for t in TASKS]
    # a rerun of the same task list runs nothing
    n_events = len(read_log(dask_cluster.log))
    again = run_all(TASKS, slow_standin_runner, store, scheduler=dask_cluster.address, progress=False)
    assert (again.ran, again.reused, again.failed) == (0, len(TASKS), 0)
    assert again.records == out.records
    assert len(read_log(dask_cluster.log)) == n_events


#: The design-expert campaign's stages and runs (the paper profile's defaults: one replicate,
#: 6 noise seeds and 6 climb levels): 12 + 6 + 6 + 17 + 3 = 44 runs.
STAGES = {"Plackett-Burman": 12, "noise": 6, "steepest climb": 6, "Box-Behnken": 17, "validation": 3}
SECTIONS = ("plackett_burman", "noise", "steepest_climb", "box_behnken", "validation")


@pytest.mark.timeout(120)
def test_calibrate_on_the_cluster_survives_a_killed_worker(dask_cluster, tmp_path, measurement,
                                                           monkeypatch, capsys):
    """``demcal calibrate --scheduler``: a worker killed midway costs only its runs in flight,
    the campaign completes with what the stand-in gives in this process, and a rerun runs
    nothing."""
    import demcal.analyse.campaign as campaign
    import demcal.measure.pipeline as pipeline
    from demcal.analyse.campaign import CampaignConfig, calibrate
    from demcal.cli import main

    # the front door as it is, with the example's measurement and the stand-in for the DEM
    monkeypatch.setattr(pipeline, "measure_workbook", lambda *args, **kwargs: measurement)
    monkeypatch.setattr(campaign, "campaign_runner", slow_standin_runner)
    out = tmp_path / "campaign"
    argv = ["calibrate", str(ROOT / "data" / "astragalus"), "--out", str(out), "--profile", "paper",
            "--scheduler", dask_cluster.address, "--no-report"]
    killer = Killer(dask_cluster, out / "runs", after=6)
    killer.start()
    assert main(argv) == 0
    kill = killer.result()
    assert 6 <= len(kill.stored) < sum(STAGES.values())

    results = json.loads((out / "results.json").read_text())
    assert results["runner"] == "tests.analyse.standin.slow_standin_runner"
    stages = {s["stage"]: s for s in results["stages"]}
    assert {name: s["runs"] for name, s in stages.items()} == STAGES
    assert all(s["failed"] == 0 and s["reused"] + s["ran"] == s["runs"] for s in stages.values())
    keys = {run["key"] for section in SECTIONS for run in results[section]["runs"]}
    assert sum(s["ran"] for s in stages.values()) == len(keys)
    survivor = next(w.pid for w in dask_cluster.workers if w.pid != kill.pid)
    check_runs(kill, RunStore(out / "runs").records(), keys, dask_cluster.log, survivor)
    # the progress bar of each stage counted each of its runs once, the lost one included
    err = capsys.readouterr().err
    for name, s in stages.items():
        assert re.search(rf"{re.escape(name)}: 100%.*\b{s['ran']}/{s['ran']}\b", err), name

    # the same campaign in this process, one run at a time: the same runs and the same answer
    local = calibrate(ROOT / "data" / "astragalus", tmp_path / "local",
                      CampaignConfig(profile="paper", workers=1, progress=False),
                      runner=standin_runner, measurement=measurement).to_dict()
    for section in SECTIONS:
        assert [r["key"] for r in results[section]["runs"]] == [r["key"] for r in local[section]["runs"]]
    assert results["box_behnken"]["response"] == local["box_behnken"]["response"]
    assert results["calibrated_parameters"] == local["calibrated_parameters"]
    assert results["validation"]["verdict"] == local["validation"]["verdict"]

    # a rerun of the campaign finds every run in the store
    n_events = len(read_log(dask_cluster.log))
    assert main(argv) == 0
    again = json.loads((out / "results.json").read_text())
    assert all(s["ran"] == 0 for s in again["stages"])
    assert len(read_log(dask_cluster.log)) == n_events
