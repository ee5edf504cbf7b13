"""The calibrated parameters run in LIGGGHTS: is LIGGGHTS' angle of repose the lab's?

``demcal export DIR --to liggghts --check`` closes the loop of a calibration: the set demcal
calibrated is run in the target code, in the lab's repose rig, and LIGGGHTS' heaps are tested
against the lab's photos by the same test as demcal's own validation.

1. The case. The campaign's repose rig with its dimensions (``results.json``), the calibrated
   parameters, and the particle, materials and contact model of demcal's LIGGGHTS export
   (``Rig.liggghts_case``: the particle template, the rolling lever converted as the export
   converts it), at the time step that follows the material.
2. The schedule, as the paper's: the particles are poured over the first second, the wall is
   lifted at ``lift_time`` (default 4 s) and the run goes on ``SETTLE_S`` after the wall is
   clear (the paper's 10 s for its carton: 4 + 2.5 + 3.5). Each case says when only settling
   remains (``settling_from``): a funnel lifts nothing and pours for as long as its twin does; a
   drum turns from ``lift_time`` and is read after its spin-up.
3. Each run's final spheres are measured by the rig's own ``measure``: the side view rendered
   and read by the photo estimator, as the lab's photos and demcal's twins are; a heap the
   estimator finds no slope in is read by the rig's fallback method, and a run with no reading
   at all is replaced by the next seed (and listed); after ``MAX_TRIES_PER_RUN`` such runs in a
   row, or a failed LIGGGHTS run, the check ends ``failed`` with the runs it made.
4. The verdict: two one-sided tests of LIGGGHTS' mean angle against the lab's mean with the
   campaign's tolerance and the lab's heap-to-heap sd (``analyse.equivalence``), looked at
   after ``first`` runs and every ``step`` more up to ``cap`` (Haybittle-Peto levels, as the
   validation's sequential test): "equivalent", "different" or "undecided", with the runs it
   needed.

References
----------
Schuirmann, D. J. (1987). A comparison of the two one-sided tests procedure and the power
approach for assessing the equivalence of average bioavailability. J. Pharmacokinet.
Biopharm. 15, 657-680.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

from demcal.errors import DemcalError, InputError, SimulationError

#: Simulated time after the wall's lower edge passed its top [s] (the paper's carton:
#: 10 - 4 - 2.5 s).
SETTLE_S = 3.5
#: Time the wall starts to rise [s] (the paper's).
LIFT_TIME_S = 4.0
#: Sequential plan: runs at the first look, runs added between looks, largest number of runs.
FIRST, STEP, CAP = 5, 5, 15
#: Seeds tried per run wanted before a check gives up on runs without a reading.
MAX_TRIES_PER_RUN = 2


@dataclass(frozen=True)
class TargetRun:
    """One LIGGGHTS run of the check: its seed, angle [deg] (NaN: no reading), how it was
    read, its loop time [s], spheres, and the rig estimator's notes."""

    seed: int
    angle_deg: float
    read_by: str
    wall_s: float
    spheres: int
    lost_spheres: int
    workdir: str
    notes: list = field(default_factory=list)


@dataclass(frozen=True)
class TargetCheck:
    """The verdict on a calibrated set run in LIGGGHTS (``DIR/export/liggghts_check.json``).

    Attributes
    ----------
    verdict : str
        ``equivalent``, ``different`` or ``undecided``; ``failed`` when LIGGGHTS failed or kept
        giving heaps with no reading before the test could be made (``failure`` says why; the
        runs it made are kept).
    code : str
        The LIGGGHTS version that ran (from its log).
    rig : str
        The repose rig (the workbook's ``repose_rig``).
    schedule : dict
        ``lift_time_s``, ``duration_s``.
    runs : list of TargetRun
        Every run, those without a reading included.
    test : dict
        The sequential equivalence test (``analyse.equivalence.SequentialResult.to_dict``).
    demcal : dict
        demcal's own validation in the campaign (verdict, mean, runs), to read beside it.
    source : dict
        The campaign's ``results.json`` (path, SHA-256) and the code version.
    case : dict
        The LIGGGHTS case (dimensions, particle, contact parameters, time step).
    failure : str
        Why there is no test (``failed``), else empty.
    """

    verdict: str
    code: str
    rig: str
    schedule: dict
    runs: list
    test: dict | None
    demcal: dict
    source: dict
    case: dict
    failure: str = ""

    def to_dict(self) -> dict:
        out = asdict(self)
        out["runs"] = [asdict(r) for r in self.runs]
        return out

    def summary(self) -> str:
        t = self.test
        used = [r for r in self.runs if math.isfinite(r.angle_deg)]
        if t is None:
            return (f"LIGGGHTS check ({self.code}, {self.rig} rig): {self.verdict} after {len(self.runs)} run(s): "
                    f"{self.failure}")
        lines = [f"LIGGGHTS check ({self.code}, {self.rig} rig): {self.verdict}",
                 f"  LIGGGHTS {t['mean_deg']:.2f} deg [{t['ci95'][0]:.2f}, {t['ci95'][1]:.2f}] over "
                 f"{len(used)} runs against the lab's {t['target_deg']:.2f} deg, tolerance "
                 f"{t['tolerance_deg']:.2f} deg; difference {t['difference_deg']:+.2f} deg, 90 % interval "
                 f"[{t['difference_ci90'][0]:+.2f}, {t['difference_ci90'][1]:+.2f}]",
                 f"  demcal's validation: {self.demcal.get('verdict')}, {self.demcal.get('mean_deg', math.nan):.2f} deg "
                 f"over {self.demcal.get('n_runs')} runs"]
        missing = len(self.runs) - len(used)
        if missing:
            lines.append(f"  {missing} run(s) gave no reading and were replaced by the next seed")
        return "\n".join(lines)


def schedule_for(case, duration: float | None = None) -> dict:
    """The run's schedule: the case's wall lifted at its ``plate_lift_start``, the run ending
    ``SETTLE_S`` after only the heap's settling remains (``case.settling_from()``), or at
    ``duration``."""
    if not case.plate_lift_start >= case.fill_time:
        raise InputError(f"--lift-time must be at least {case.fill_time:g} s (the fill takes that long), "
                         f"got {case.plate_lift_start!r}")
    settling = float(case.settling_from())
    end = settling + SETTLE_S if duration is None else float(duration)
    if not (math.isfinite(end) and end > case.plate_lift_start):
        raise InputError(f"--duration must be after the lift starts ({case.plate_lift_start:g} s), got {duration!r}")
    return {"lift_time_s": float(case.plate_lift_start), "settling_from_s": settling, "duration_s": float(end)}


def read_angle(rig, heap: dict) -> tuple[float, str]:
    """The rig's reading of a heap: its compared observable, or its fallbacks in order."""
    for name in (rig.compared, *rig.fallbacks):
        value = heap.get(name)
        if value is not None and math.isfinite(value):
            return float(value), name
    return math.nan, ""


def check_calibration(results, workdir, *, source: dict | None = None, lift_time: float = LIFT_TIME_S,
                      duration: float | None = None, first: int = FIRST, step: int = STEP, cap: int = CAP,
                      case=None, binary=None, progress=None) -> TargetCheck:
    """Run a campaign's calibrated set in LIGGGHTS in its repose rig and test the angle.

    Parameters
    ----------
    results : analyse.results.CampaignResult
        The finished calibration.
    workdir : path-like
        Folder of the LIGGGHTS runs (one ``seed<N>`` folder each).
    source : dict, optional
        Where ``results`` came from (path, SHA-256), recorded.
    lift_time, duration : float
        The schedule (:func:`schedule_for`).
    first, step, cap : int
        The sequential plan (:data:`FIRST`, :data:`STEP`, :data:`CAP`).
    case : optional
        The LIGGGHTS case; default the rig's (``Rig.liggghts_case``) of the calibrated set.
    binary : str, optional
        LIGGGHTS executable (default ``simulate.liggghts.run.find_liggghts``).
    progress : callable, optional
        ``progress(run)`` after each run (a :class:`TargetRun`).

    Raises
    ------
    simulate.liggghts.run.LiggghtsUnavailable
        No LIGGGHTS binary.
    SimulationError
        Runs failed, or too many gave no reading.
    """
    from demcal.analyse.equivalence import sequential_equivalence
    from demcal.provenance import code_version
    from demcal.simulate.liggghts.run import LiggghtsUnavailable, run_liggghts
    from demcal.simulate.params import DEMParameters
    from demcal.simulate.rigs import repose_rig_named

    rig = repose_rig_named(results.repose_rig)
    if rig.liggghts_case is None:
        raise InputError(f"the {results.repose_rig} rig has no LIGGGHTS case yet")
    params = DEMParameters.from_names(results.calibrated_parameters)
    geometry = rig.geometry(**results.geometry)
    if case is None:
        case = rig.liggghts_case(params, geometry, lift_time)
    plan = schedule_for(case, duration)
    test = results.validation.test or {}
    target = float(results.validation.target_deg)
    lab_sd, lab_n = test.get("target_sd_deg"), test.get("target_n")
    tolerance = float(results.validation.tolerance_deg)
    alpha = float(test.get("alpha") or 0.05)
    workdir = Path(workdir)
    runs: list = []
    seeds = iter(range(1, 10 ** 6))
    version = {"code": ""}

    def one_run() -> float:
        for _ in range(MAX_TRIES_PER_RUN):
            seed = next(seeds)
            res = run_liggghts(seed, workdir / f"seed{seed}", duration=plan["duration_s"], case=case,
                               binary=binary, nice=0)
            version["code"] = res["version"] or version["code"]
            try:
                heap = rig.measure(res["positions"], res["radii"], res["deck"]["case"])
            except DemcalError as exc:          # nothing the rig can read: no reading
                heap = {"notes": [str(exc)]}
            angle, how = read_angle(rig, heap)
            notes = [str(n) for n in heap.get("notes", [])]
            if res["lost_spheres"]:
                notes.append(f"{res['lost_spheres']} spheres left LIGGGHTS' box")
            run = TargetRun(seed, angle, how, float(res["wall_s"]), int(res["spheres"]), int(res["lost_spheres"]),
                            str(workdir / f"seed{seed}"), notes)
            runs.append(run)
            if progress is not None:
                progress(run)
            if math.isfinite(angle):
                return angle
        raise SimulationError(f"{MAX_TRIES_PER_RUN} LIGGGHTS runs in a row gave no angle of repose "
                              f"(seeds up to {seed}, in {workdir}): {'; '.join(runs[-1].notes) or 'no heap found'}")

    v = results.validation
    demcal = {"verdict": v.verdict, "mean_deg": float(v.mean_deg), "ci95": list(v.ci95), "n_runs": int(v.n_runs)}
    made = {"rig": rig.workbook_name, "schedule": plan, "runs": runs, "demcal": demcal,
            "source": {**(source or {}), "code": code_version()}, "case": case.to_dict()}
    try:
        seq = sequential_equivalence(lambda k: [one_run() for _ in range(k)], target, lab_sd, lab_n, tolerance,
                                     first=first, step=step, cap=cap, alpha=alpha)
    except LiggghtsUnavailable:
        raise
    except SimulationError as exc:          # the runs made so far are kept, with why it stopped
        return TargetCheck("failed", version["code"] or "LIGGGHTS", test=None, failure=str(exc), **made)
    return TargetCheck(seq.verdict, version["code"] or "LIGGGHTS", test=seq.to_dict(), **made)
