"""The run store and executor of a calibration campaign.

Every DEM run of a campaign is one JSON record in ``DIR/runs/<key>.json``; the key is the
SHA-256 of the run's canonical inputs (rig, parameters, profile, seed, extensions) and of the
DEM's model version, so the same inputs always map to the same record. Records are written atomically the moment a run ends,
so a campaign killed midway loses at most the runs that were in flight, and a rerun skips
every run whose record says ``"status": "ok"``. A failed run is recorded with its error and
retried once; a run that fails twice stays recorded as failed and the campaign reports it.

Runs execute in local worker processes (``workers``) or on a Dask distributed cluster
(``scheduler="tcp://host:port"``), with a progress bar and ETA. On a cluster, a run in flight on
a worker that dies is rerun by Dask on another worker; when Dask gives up on it
(``KilledWorker``) or the run is otherwise lost, that counts as a failed attempt and the run is
retried as above, while the other runs go on being recorded. A run's result is released on the
cluster once it is here, so a worker dying later never makes Dask run a finished run again.

Record layout::

    {"key": str, "inputs": {...}, "status": "ok" | "failed", "attempts": int,
     "result": {...} | null, "error": str | null, "wall_s": float,
     "provenance": {"code": {...}, "seed": int, "created": str}}
"""

from __future__ import annotations

import concurrent.futures as cf
import json
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable

from tqdm.auto import tqdm

from demcal.errors import InputError
from demcal.jsonio import read_json, to_jsonable, write_json
from demcal.provenance import Provenance, run_key
from demcal.simulate.threads import run_processes, threads_limited_to

#: How many times a failed run is attempted in all (the first try and one retry).
MAX_ATTEMPTS = 2


class RunStore:
    """A folder of run records, one JSON file per run, keyed by :func:`run_key`."""

    def __init__(self, root):
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)

    def path(self, key: str) -> Path:
        return self.root / f"{key}.json"

    def get(self, key: str) -> dict | None:
        p = self.path(key)
        if not p.exists():
            return None
        try:
            return read_json(p)
        except json.JSONDecodeError as exc:
            raise InputError(f"run record {p} is not valid JSON ({exc}); delete it to rerun that run") from exc

    def put(self, record: dict) -> Path:
        return write_json(self.path(record["key"]), record)

    def finished(self, key: str) -> bool:
        rec = self.get(key)
        return rec is not None and rec.get("status") == "ok"

    def records(self) -> list[dict]:
        return [read_json(p) for p in sorted(self.root.glob("*.json"))]


def _execute(runner: Callable[[dict], dict], inputs: dict,
             threads: int | None = None) -> tuple[str, dict | None, str | None, float]:
    """Run one set of inputs in a worker (its DEM on at most ``threads`` threads); never
    raises, so one failure cannot sink the pool."""
    t0 = time.perf_counter()
    try:
        with threads_limited_to(threads):
            result = runner(inputs)
        return "ok", to_jsonable(result), None, time.perf_counter() - t0
    except Exception as exc:  # recorded in the run store, reported by the campaign
        tb = traceback.format_exception_only(type(exc), exc)[-1].strip()
        return "failed", None, tb, time.perf_counter() - t0


@dataclass(frozen=True)
class RunOutcome:
    """What :func:`run_all` did: records in input order, and how many were run vs reused."""

    records: list
    ran: int
    reused: int
    failed: int


def run_all(tasks: Iterable[dict], runner: Callable[[dict], dict], store: RunStore, *,
            workers: int = 1, scheduler: str | None = None, desc: str = "DEM runs",
            progress: bool = True, prepare: Callable[[], object] | None = None,
            executor: Workers | None = None) -> RunOutcome:
    """Run every task not yet finished in ``store``; return all records in task order.

    Parameters
    ----------
    tasks : iterable of dict
        Canonical inputs of each run (must be JSON-serialisable; ``seed`` should be among them).
    runner : callable
        A picklable top-level function ``runner(inputs) -> dict`` that performs one run.
    store : RunStore
    workers : int
        Local worker processes (1 runs in this process). Ignored when ``scheduler`` is given.
    scheduler : str, optional
        Address of a Dask distributed scheduler (e.g. ``tcp://127.0.0.1:8786``).
    prepare : callable, optional
        Called here once before local worker processes start, when there are runs to make
        (``simulate.scenes.compile_kernels``: the workers then load the compiled DEM instead
        of each compiling it at the same time).
    executor : Workers, optional
        Where to run, kept open by the caller across calls (a campaign's stages then share
        one set of worker processes); ``workers``, ``scheduler`` and ``prepare`` are then its
        own. Without it the runs get workers of their own for this call.
    """
    tasks = [to_jsonable(t) for t in tasks]
    keys = [run_key(t) for t in tasks]
    pending, seen = [], set()
    for key, task in zip(keys, tasks):
        if key in seen or store.finished(key):
            continue
        seen.add(key)
        pending.append((key, task))
    reused = len(set(keys)) - len(pending)

    def record(key, task, status, result, error, wall, attempts):
        rec = {"key": key, "inputs": task, "status": status, "attempts": attempts,
               "result": result, "error": error, "wall_s": wall,
               "provenance": Provenance(seed=task.get("seed")).to_dict()}
        store.put(rec)
        return rec

    failed = 0
    attempts = {key: 0 for key, _ in pending}
    queue = list(pending)
    own = executor is None and bool(pending)
    if own:
        executor = Workers(workers, scheduler, prepare=prepare)
    bar = None
    try:
        if pending:
            executor.ready()    # before the bar: its rate and time left count runs, not compiling
        bar = tqdm(total=len(pending), desc=desc, unit="run", disable=not progress or not pending)
        while queue:
            futures = {executor.submit(_execute, runner, task): (key, task) for key, task in queue}
            queue = []
            for fut in _as_completed(futures):
                key, task = futures.pop(fut)
                try:
                    status, result, error, wall = fut.result()
                except Exception as exc:  # _execute never raises: the executor lost the run
                    status, result, wall = "failed", None, 0.0
                    error = f"run lost by the executor: {type(exc).__name__}: {exc}"
                _release(fut)
                attempts[key] += 1
                if status == "failed" and attempts[key] < MAX_ATTEMPTS:
                    record(key, task, status, result, error, wall, attempts[key])
                    queue.append((key, task))  # retried once, in the next round
                    continue
                record(key, task, status, result, error, wall, attempts[key])
                failed += status == "failed"
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
        if own:
            executor.close()
    records = [store.get(k) for k in keys]
    return RunOutcome(records=records, ran=len(pending), reused=reused, failed=failed)


class Workers:
    """Where runs execute, open until :meth:`close`: in this process (``workers`` 1), in
    ``workers`` local processes started at the first run and kept for every later batch, or on
    the Dask scheduler at ``scheduler``, connected once. A campaign opens one for all its
    stages, so its workers start, import the DEM and load its compiled kernels once, not once
    per stage. ``prepare`` is called here once, before local worker processes first start.
    A pool a crashed worker broke is replaced at the next run submitted."""

    def __init__(self, workers: int = 1, scheduler: str | None = None,
                 prepare: Callable[[], object] | None = None):
        self.workers, self.scheduler, self.prepare = workers, scheduler, prepare
        self._pool = self._client = None

    def __enter__(self) -> Workers:
        return self

    def __exit__(self, *exc) -> bool:
        self.close()
        return False

    def ready(self) -> None:
        """Call ``prepare`` now, once, if the runs are to go to local worker processes (a
        campaign's first compile of the DEM kernels takes half a minute or more)."""
        if self.prepare is not None and not self.scheduler and self.workers > 1:
            self.prepare()
            self.prepare = None

    def submit(self, fn, *args):
        """A future of ``fn(*args)``."""
        if self.scheduler:
            # a Dask worker runs tasks on threads of its own: each run's DEM on one
            return self._dask().submit(fn, *args, 1, pure=False)
        if self.workers <= 1:
            return _LazyResult(fn, args)  # one run at a time: a large one may use every core
        if self._pool is None:
            self.ready()
            self._pool = run_processes(self.workers)
        try:
            return self._pool.submit(fn, *args)
        except cf.process.BrokenProcessPool:
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = run_processes(self.workers)
            return self._pool.submit(fn, *args)

    def _dask(self):
        if self._client is None:
            try:
                from dask.distributed import Client
            except ImportError as exc:  # pragma: no cover - dask is a dependency
                raise InputError("--scheduler needs dask[distributed] installed") from exc
            try:
                self._client = Client(self.scheduler, timeout="10s")
            except OSError as exc:
                raise InputError(f"cannot reach the Dask scheduler at {self.scheduler}: {exc}") from exc
        return self._client

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
        if self._client is not None:
            self._client.close()
            self._client = None


class _LazyResult:
    """A run in this process, executed when its result is asked for, so that each record is
    stored as soon as that run ends (not after the whole batch)."""

    def __init__(self, fn, args):
        self.fn, self.args = fn, args

    def result(self):
        return self.fn(*self.args)


def _release(fut) -> None:
    """Let a Dask cluster forget a run whose result is here: while the future is held, the
    scheduler recomputes its result if the worker holding it dies, so a finished run would run
    again."""
    release = getattr(fut, "release", None)
    if release is not None:
        release()


def _as_completed(futures):
    """``as_completed`` for in-process, concurrent.futures or Dask futures."""
    first = next(iter(futures), None)
    if isinstance(first, _LazyResult):
        return list(futures)
    if first is not None and type(first).__module__.startswith("distributed"):
        from dask.distributed import as_completed
        return as_completed(list(futures))
    return cf.as_completed(futures)
