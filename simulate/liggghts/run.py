"""Run the repose deck with the LIGGGHTS-PUBLIC 3.8 binary on one core and read its results.

``python -m benchmarks.liggghts.run`` runs the paper's case from the command line and stores
what the side-by-side benchmark needs; ``demcal export --to liggghts --check`` runs a
calibrated set in the lab's repose rig.

The binary is the Debian package ``liggghts`` (``/usr/bin/liggghts``), an MPI build that runs
as a single process without ``mpirun``. Set ``DEMCAL_LIGGGHTS`` to use another binary. When
no binary is found, :func:`run_liggghts` raises :class:`LiggghtsUnavailable`, which says how
to install it.

Throughput is counted as LIGGGHTS' own "Loop time" (wall clock of the time-step loops, summed
over the ``run`` commands of the deck; setup and the template's Monte Carlo are excluded) and
sphere-steps per second = final number of spheres x time steps / loop time.
"""

from __future__ import annotations

import math
import os
import re
import resource
import shutil
import subprocess
import time
from pathlib import Path

import numpy as np

from demcal.simulate.liggghts.deck import LOG_NAME, POSITION_COLUMNS, SPHERE_POSITION_COLUMNS, ReposeCase, write_deck
from demcal.errors import InputError, SimulationError
from demcal.provenance import Provenance, sha256_file

#: Binary names tried in order when ``DEMCAL_LIGGGHTS`` is not set.
BINARY_NAMES = ("liggghts", "lmp_auto", "lmp_ubuntu", "lmp_fedora", "lmp_mpi", "lmp_serial")
SCREEN_NAME = "screen.liggghts"

_LOOP = re.compile(r"^Loop time of ([0-9.eE+-]+) on (\d+) procs for (\d+) steps with (\d+) atoms")
_VERSION = re.compile(r"LIGGGHTS \(Version ([^,)]+)")


class LiggghtsUnavailable(SimulationError):
    """No LIGGGHTS binary on this machine."""


def find_liggghts(binary=None) -> str | None:
    """Path of the LIGGGHTS executable: ``binary``, else ``$DEMCAL_LIGGGHTS``, else the first of
    ``BINARY_NAMES`` on ``PATH``; None when there is none."""
    candidate = binary or os.environ.get("DEMCAL_LIGGGHTS")
    if candidate:
        return shutil.which(candidate)
    for name in BINARY_NAMES:
        found = shutil.which(name)
        if found:
            return found
    return None


def package_version() -> str | None:
    """Version of the Debian package ``liggghts`` (e.g. ``3.8.0+repack1-9+b2``), if installed."""
    try:
        out = subprocess.run(["dpkg-query", "-W", "-f=${Version}", "liggghts"],
                             capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    if out.returncode != 0:
        return None
    return out.stdout.strip() or None


def parse_log(text: str) -> dict:
    """What the benchmark needs from a LIGGGHTS log.

    Returns
    -------
    dict
        ``version`` (e.g. ``LIGGGHTS-PUBLIC 3.8.0``); ``loops``: one dict per ``run`` with
        ``loop_s`` [s], ``procs``, ``steps``, ``atoms``; ``thermo``: array (n, 5) of step,
        atoms, translational and rotational kinetic energy of the bodies [J], cpu [s];
        ``warnings`` and ``errors``: the lines starting with WARNING / ERROR.
    """
    version = None
    loops, rows, warnings, errors = [], [], [], []
    in_thermo = False
    for line in text.splitlines():
        if version is None and (m := _VERSION.search(line)):
            version = m.group(1).strip()
        if m := _LOOP.match(line):
            loops.append({"loop_s": float(m.group(1)), "procs": int(m.group(2)),
                          "steps": int(m.group(3)), "atoms": int(m.group(4))})
            in_thermo = False
            continue
        if line.startswith("WARNING"):
            warnings.append(line.strip())
        elif line.startswith("ERROR"):
            errors.append(line.strip())
        fields = line.split()
        if fields[:2] == ["Step", "Atoms"]:
            in_thermo = True
            continue
        if in_thermo and len(fields) == 5:
            try:
                row = [float(f) for f in fields]
            except ValueError:
                continue  # an INFO line of the insertion fix between thermo lines
            if not rows or row[0] != rows[-1][0]:  # a new run repeats its first step
                rows.append(row)
    thermo = np.array(rows, dtype=float).reshape(-1, 5)
    return {"version": version, "loops": loops, "thermo": thermo,
            "warnings": warnings, "errors": errors}


def read_positions(path):
    """Spheres of a ``write_dump ... custom id mol x y z radius`` file (``id id ...`` for
    single spheres, each its own body), sorted by atom id.

    Returns
    -------
    tuple
        (atom ids (N,) int, body ids (N,) int, positions (N, 3) [m], radii (N,) [m]).
    """
    path = Path(path)
    lines = path.read_text().splitlines()
    try:
        start = next(i for i, line in enumerate(lines) if line.startswith("ITEM: ATOMS"))
    except StopIteration:
        raise SimulationError(f"{path}: no 'ITEM: ATOMS' section; not a LIGGGHTS dump") from None
    columns = lines[start].split()[2:]
    if tuple(columns) not in (POSITION_COLUMNS, SPHERE_POSITION_COLUMNS):
        raise SimulationError(f"{path}: columns {columns}, expected {list(POSITION_COLUMNS)} "
                              f"or {list(SPHERE_POSITION_COLUMNS)}")
    data = np.loadtxt(lines[start + 1:], ndmin=2).reshape(-1, len(POSITION_COLUMNS))
    data = data[np.argsort(data[:, 0], kind="stable")]
    return (data[:, 0].astype(np.int64), data[:, 1].astype(np.int64),
            np.ascontiguousarray(data[:, 2:5]), np.ascontiguousarray(data[:, 5]))


def liggghts_command(exe: str, deck) -> list[str]:
    """The command line that runs ``deck`` (``write_deck``) in its folder, its log and screen
    output to files there."""
    # "-screen none" crashes LIGGGHTS 3.8 (the STL reader prints to a NULL screen), so the
    # screen goes to a file.
    return [exe, "-in", deck.script.name, "-log", LOG_NAME, "-screen", SCREEN_NAME]


def run_liggghts(seed: int, workdir, duration: float = 10.0, case: ReposeCase | None = None,
                 binary=None, nice: int = 10, timeout: float | None = None,
                 dump_interval: float | None = None) -> dict:
    """Write the repose deck into ``workdir``, run LIGGGHTS on one core, read the results.

    Parameters
    ----------
    seed : int
        Run seed (insertion positions and orientations).
    workdir : path-like
        Run folder; the deck, meshes, log and final positions are left there.
    duration : float
        Simulated time [s]; the paper's run is 10 s (134 467 steps).
    case : ReposeCase, optional
        The case; default the paper's, with its calibrated contact parameters.
    binary : str, optional
        LIGGGHTS executable; default from :func:`find_liggghts`.
    nice : int
        Niceness of the LIGGGHTS process (0 = normal priority).
    timeout : float, optional
        Kill LIGGGHTS after this many seconds of wall time.
    dump_interval : float, optional
        Also dump all spheres every this many seconds into ``workdir/post``.

    Returns
    -------
    dict
        ``wall_s`` LIGGGHTS loop time [s]; ``cpu_s`` user+system CPU of the process [s];
        ``elapsed_s`` wall time of the whole process [s]; ``steps``; ``spheres`` (at the end);
        ``bodies``; ``lost_spheres`` (spheres expected minus present); ``sphere_steps_per_s``;
        ``positions`` (N, 3) [m], ``radii`` (N,) [m], ``body_id`` (N,), ``atom_id`` (N,);
        ``version`` (from the log) and ``package_version`` (dpkg); ``loops`` (per ``run``);
        ``thermo`` (n, 5) array of step, atoms, KE_trans, KE_rot [J], cpu [s]; ``warnings``;
        ``deck`` (:meth:`Deck.to_dict`); ``provenance``.

    Raises
    ------
    LiggghtsUnavailable
        No LIGGGHTS binary found.
    SimulationError
        LIGGGHTS failed, or its results are incomplete or non-finite.
    """
    exe = find_liggghts(binary)
    if exe is None:
        raise LiggghtsUnavailable(
            "LIGGGHTS not found (tried $DEMCAL_LIGGGHTS and " + ", ".join(BINARY_NAMES)
            + "); install the Debian package: apt-get install liggghts")
    if int(nice) != nice or not 0 <= nice <= 19:
        raise InputError(f"nice must be an integer 0..19, got {nice!r}")
    deck = write_deck(workdir, seed, duration, case, dump_interval)
    for stale in (deck.positions_file, deck.log_file):
        stale.unlink(missing_ok=True)

    cmd = liggghts_command(exe, deck)
    env = dict(os.environ, OMP_NUM_THREADS="1")
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(cmd, cwd=deck.workdir, env=env, capture_output=True, text=True,
                              timeout=timeout, preexec_fn=(lambda: os.nice(nice)) if nice else None)
    except subprocess.TimeoutExpired:
        raise SimulationError(f"LIGGGHTS exceeded the timeout of {timeout} s in {deck.workdir}") from None
    elapsed = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)

    log_text = deck.log_file.read_text(errors="replace") if deck.log_file.exists() else ""
    log = parse_log(log_text)
    if proc.returncode != 0 or log["errors"]:
        reason = (log["errors"] or [line for line in (proc.stdout + proc.stderr).splitlines() if line.strip()][-3:]
                  or ["no message"])
        raise SimulationError(f"LIGGGHTS failed (exit code {proc.returncode}) in {deck.workdir}: "
                              + " | ".join(reason))
    if [lp["steps"] for lp in log["loops"]] != [n for _, n in deck.phases]:
        raise SimulationError(f"{deck.log_file}: runs of {[lp['steps'] for lp in log['loops']]} steps, "
                              f"the deck asked for {[n for _, n in deck.phases]}")
    if not deck.positions_file.exists():
        raise SimulationError(f"LIGGGHTS wrote no final positions ({deck.positions_file})")
    atom_id, body_id, positions, radii = read_positions(deck.positions_file)
    if not (np.isfinite(positions).all() and np.isfinite(log["thermo"]).all()):
        raise SimulationError(f"non-finite positions or energies in {deck.workdir}")

    expected = _inserted_bodies(log_text) * deck.case.spheres_per_particle
    wall = sum(lp["loop_s"] for lp in log["loops"])
    steps = sum(lp["steps"] for lp in log["loops"])
    spheres = int(len(atom_id))
    return {
        "seed": int(seed), "duration": float(duration),
        "wall_s": wall, "cpu_s": cpu, "elapsed_s": elapsed, "steps": steps,
        "spheres": spheres, "bodies": int(len(np.unique(body_id))),
        "lost_spheres": int(expected - spheres),
        "sphere_steps_per_s": spheres * steps / wall if wall > 0 else math.nan,
        "positions": positions, "radii": radii, "body_id": body_id, "atom_id": atom_id,
        "version": log["version"], "package_version": package_version(),
        "binary": exe, "command": cmd, "nice": int(nice),
        "loops": [dict(lp, phase=label) for lp, (label, _) in zip(log["loops"], deck.phases)],
        "thermo": log["thermo"], "warnings": sorted(set(log["warnings"])),
        "deck": deck.to_dict(),
        "provenance": Provenance(inputs={str(deck.script): sha256_file(deck.script)},
                                 seed=int(seed), options={"duration": duration, "nice": nice}).to_dict(),
    }


def _inserted_bodies(log_text: str) -> int:
    """Bodies inserted so far, from the insertion fix's last report."""
    counts = re.findall(r"a total of (\d+) particle templates", log_text)
    return int(counts[-1]) if counts else 0


def heap_summary(result: dict) -> dict:
    """Where the bodies ended up: the share that left the carton and how far they ran out.

    Returns
    -------
    dict
        ``bodies``; ``outside_fraction``: bodies whose centre is beyond the end plate
        (x > L) [-]; ``runout_max``: largest sphere x beyond the plate [m]; ``z_max`` [m].
    """
    L = result["deck"]["case"]["box_length"]
    pos, body = result["positions"], result["body_id"]
    ids, inverse = np.unique(body, return_inverse=True)
    centres = np.zeros((len(ids), 3))
    np.add.at(centres, inverse, pos)
    centres /= np.bincount(inverse)[:, None]
    return {"bodies": int(len(ids)),
            "outside_fraction": float(np.mean(centres[:, 0] > L)) if len(ids) else math.nan,
            "runout_max": float(pos[:, 0].max() - L) if len(pos) else math.nan,
            "z_max": float(pos[:, 2].max()) if len(pos) else math.nan}
