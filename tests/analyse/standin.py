"""An analytic stand-in for the repose rig, for fast tests of everything around the DEM.

The angle depends on e_pp, e_pw and mu_s_pw only (factors B, E and F of the screening), plus
a seed-dependent noise of sd ``NOISE_SD``; the heap profile is a single flank at that angle,
shaped like the repose rig's (a plateau inside the carton, one slope to the floor)."""

import math

import numpy as np

NOISE_SD = 0.15


def standin_angle(p: dict) -> float:
    zb = (p["e_pp"] - 0.3) / 0.1
    ze = (p["e_pw"] - 0.35) / 0.05
    zf = (p["mu_s_pw"] - 0.2) / 0.1
    return 34.0 - 1.5 * zb - 1.2 * ze + 2.0 * zf + 0.5 * zb * ze - 0.4 * zf**2


def standin_runner(inputs: dict) -> dict:
    noise = np.random.default_rng(inputs["seed"]).normal(0.0, NOISE_SD)
    angle = standin_angle(inputs["params"]) + noise
    height = 0.08
    run = height / math.tan(math.radians(angle))
    x = [0.0, 0.12, 0.12 + run, 0.12 + run + 0.05]
    z = [height, height, 0.0, 0.0]
    return {"rig": "repose", "observable": {"angle_deg": angle, "angle_profile_deg": angle},
            "record": {"profile": {"x": x, "z": z}},
            "wall_s": 0.0, "steps": 0, "spheres": 0, "sphere_steps_per_s": 0.0,
            "seed": inputs["seed"]}


#: Seed-to-seed sd of the noisy stand-in, about the DEM heap's [deg].
HEAP_NOISE_SD = 2.5


def heap_standin_angle(p: dict) -> float:
    """Mean angle of the noisy stand-in: steep in mu_s_pw and mu_r_pp, mild in mu_s_pp and e_pp,
    flat in the rest (the heap cannot identify those)."""
    return (36.0 + 25.0 * (p["mu_s_pw"] - 0.2) - 60.0 * (p["mu_s_pw"] - 0.2) ** 2
            + 30.0 * (p["mu_r_pp"] - 0.53) + 20.0 * (p["mu_s_pp"] - 0.65) - 4.0 * (p["e_pp"] - 0.3))


def drum_standin_angle(p: dict) -> float:
    """Mean angle of the noisy stand-in drum: equal to the heap's at the default truth, steep
    in mu_r_pp and mu_s_pp in another combination than the heap (the drum's bed slides on
    itself where the heap's rolls), flat in the rest."""
    return 36.0 + 30.0 * (p["mu_r_pp"] - 0.53) - 20.0 * (p["mu_s_pp"] - 0.65) + 5.0 * (p["mu_s_pw"] - 0.2)


#: Apparent over contact restitution of the stand-in's drop twin (a segment turning part of its
#: energy into rotation rebounds lower than its contact restitution).
DROP_RATIO = 0.5


def heap_standin_runner(inputs: dict) -> dict:
    """A heap whose noise is a fresh draw for every (parameters, seed), as the chaotic DEM's
    is: runs sharing a seed at different points are independent; a drum task's mean angle is
    :func:`drum_standin_angle`. Drop and incline tasks (the
    joint calibration's twins) get an apparent restitution of ``DROP_RATIO`` times the contact
    one, with a little orientation scatter, and an incline reading equal to the friction."""
    import hashlib
    import json

    key = json.dumps(inputs, sort_keys=True)
    rng = np.random.default_rng(int.from_bytes(hashlib.sha256(key.encode()).digest()[:8], "little"))
    p = inputs["params"]
    if inputs.get("rig") == "drop":
        e = p["e_pp"] if inputs["pair"] == "particle-particle" else p["e_pw"]
        return {"rig": "drop", "observable": {"apparent_restitution": DROP_RATIO * e + rng.normal(0.0, 0.01)}}
    if inputs.get("rig") == "incline":
        on = "pp" if inputs["surface"] == "particle" else "pw"
        key = f"mu_s_{on}" if inputs["mode"] == "slide" else f"mu_r_{on}"
        name = "static_friction_apparent" if inputs["mode"] == "slide" else "rolling_friction_apparent"
        return {"rig": "incline", "observable": {name: p[key]}}
    mean = drum_standin_angle if inputs.get("rig") == "drum" else heap_standin_angle
    angle = mean(inputs["params"]) + rng.normal(0.0, HEAP_NOISE_SD)
    return {"rig": inputs.get("rig", "repose"), "observable": {"angle_deg": angle, "angle_profile_deg": angle},
            "record": {}, "wall_s": 0.0, "steps": 0, "spheres": 0, "sphere_steps_per_s": 0.0,
            "seed": inputs["seed"]}


#: Flat-landing apparent over contact restitution of the stand-in's drop twin without shared
#: damping (the DEM's five-sphere segment: 0.05 at e = 0.36); 1 with it.
FLAT_DROP_RATIO = 0.14
#: Outflow fraction of the stand-in heap: OUTFLOW_BASE + OUTFLOW_SLOPE (e_pw - 0.5), plus noise.
OUTFLOW_BASE, OUTFLOW_SLOPE, OUTFLOW_NOISE = 0.10, 0.2, 0.01


def extension_standin_runner(inputs: dict) -> dict:
    """The noisy heap stand-in with flat drops whose rebound depends on ``contact_effective_mass``
    (``FLAT_DROP_RATIO`` times the contact restitution without it, the contact restitution with
    it), and heaps that record an outflow fraction depending on e_pw, an outside pile angle and a
    crest height: what a recalibration with the extension changes is known in closed form."""
    import hashlib
    import json

    p = inputs["params"]
    rng = np.random.default_rng(int.from_bytes(hashlib.sha256(json.dumps(inputs, sort_keys=True).encode())
                                               .digest()[:8], "little"))
    if inputs.get("rig") == "drop":
        e = p["e_pp"] if inputs["pair"] == "particle-particle" else p["e_pw"]
        ratio = 1.0 if p.get("contact_effective_mass") else FLAT_DROP_RATIO
        return {"rig": "drop", "observable": {"apparent_restitution": ratio * e + rng.normal(0.0, 0.005)}}
    if inputs.get("rig") == "incline":
        return heap_standin_runner(inputs)
    angle = heap_standin_angle(p) + rng.normal(0.0, HEAP_NOISE_SD)
    outflow = OUTFLOW_BASE + OUTFLOW_SLOPE * (p["e_pw"] - 0.5) + rng.normal(0.0, OUTFLOW_NOISE)
    return {"rig": "repose",
            "observable": {"angle_deg": angle, "angle_profile_deg": angle, "outside_fraction": outflow,
                           "angle_outside_deg": 25.0 + rng.normal(0.0, 1.0),
                           "crest_height_m": 0.08 + rng.normal(0.0, 0.002)},
            "record": {}, "wall_s": 0.0, "steps": 0, "spheres": 0,
            "sphere_steps_per_s": 0.0, "seed": inputs["seed"]}


#: Seconds one slow stand-in run takes: long enough that a Dask worker killed midway has a run
#: in flight.
SLOW_STANDIN_S = 0.25
#: Environment variable naming the file the slow stand-in logs its runs to (unset: no log).
SLOW_STANDIN_LOG = "DEMCAL_STANDIN_LOG"


def slow_standin_runner(inputs: dict) -> dict:
    """:func:`standin_runner` taking ``SLOW_STANDIN_S`` seconds, for tests on a real Dask cluster
    (a module function, so that worker processes can import it). With ``DEMCAL_STANDIN_LOG`` set
    in the worker's environment it appends ``start <run key> <pid>`` and ``end <run key> <pid>``
    lines to that file, so a test can tell which worker has a run in flight and which runs
    finished, where and how often."""
    import os
    import time

    from demcal.analyse.runs import run_key

    log = os.environ.get(SLOW_STANDIN_LOG)

    def note(event):
        if log:
            # one short O_APPEND write per line: lines from several workers do not interleave
            with open(log, "a") as f:
                f.write(f"{event} {run_key(inputs)} {os.getpid()}\n")

    note("start")
    time.sleep(SLOW_STANDIN_S)
    result = standin_runner(inputs)
    note("end")
    return result
