"""Provenance: what produced a number (code version, git sha, input hashes, seeds, options)."""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import platform
import subprocess
from dataclasses import asdict, dataclass, field
from functools import lru_cache
from pathlib import Path

from demcal import __version__
from demcal.jsonio import to_jsonable

#: Revision of what the DEM computes. Raise it with any change that alters the result of a run
#: with unchanged inputs: it is part of every run-store key, so a store or cache never serves a
#: record computed by other physics (``run_key``). Revision 2: shared normal
#: damping (``contact_effective_mass``, then named ``multi_contact_damping``) damps the
#: effective mass at each contact. Revision 3: the drop rig reads the rebound to the first apex
#: in free flight after the whole impact sequence (a tilted body's centre of mass descending
#: between its end impacts no longer ends it). Revision 4: a run's parameters carry the particle's
#: shape (``simulate.shapes``) and time step, so runs of revision 3 and earlier no longer replay.
#: Revision 5: a size distribution is of any shape (``particle_sizes``, formerly the segments'
#: ``segment_sizes``); the physics is unchanged, the keys are not. Revision 6: particle factories
#: insert in batches (every 50 steps) with a gap of a Verlet skin to the other spheres, and the
#: neighbour lists are rebuilt on per-sphere allowances (``simulate.neighbours``): the same
#: physics, but heaps are filled differently and their arithmetic runs in another order.
#: Revision 7: a simulation of 4,096 spheres or more is sorted in memory every 1,000 steps, and
#: one of 8,192 or more sums its contacts in fixed ranges run on threads (``simulate.forces``):
#: the same physics with the additions in another order. Smaller runs are the same to the bit.
#: Revision 8: IEEE arithmetic in every kernel (no ``fastmath``), so that a run gives the same
#: bits whether its kernels were compiled in the process or loaded from the cache.
#: Revision 9: a heap's flank is fitted between its crest and its toe only
#: (``measure.repose``), so a heap whose first line through the band was shallow (a low tail)
#: reads another angle; and a stated time step above the damped stability limit of the run's
#: lowest restitution runs in sub-steps (``simulate.timestep``), so runs at restitution below
#: 0.1 at the paper's step differ.
#: Revision 10: the calibration's sliding incline runs start tilted at 0.8 atan(mu_s)
#: (``simulate.rigs.incline.start_angle``) instead of flat: the onsets agree within about the
#: tilt's 0.01 deg chunk at a fifth of the steps, but their last bits and the runs' keys differ.
#: And under the spring-dashpot rolling model the incline twin counts a roll beyond the rolling
#: spring's elastic windup (a soft seed read 0.79 deg for atan(mu_r) = 2.86 deg before).
#: Revision 11: the incline twin adds up the rolled arc piece by piece
#: (``simulate.rigs.incline._run_adding_up_rotation``); taken from the whole rotation it wrapped
#: at half a turn, and a sphere that only rolled read a slide (a 6.6 mm sphere at 3.66 deg).
#: Revision 12: the incline twin reads a slide only when the slip keeps growing
#: (``simulate.rigs.incline.CONFIRM_SLIP``); a kernel that rolled onto its next sphere and
#: slipped 0.01-0.05 mm in the knock read a slide at the tilt of its roll, whatever its friction.
MODEL_VERSION = 12


def run_key(inputs: dict) -> str:
    """SHA-256 of the canonical JSON (sorted keys, no whitespace) of a DEM run's inputs and
    ``MODEL_VERSION``: the key of its record in a run store or cache, never shared with a run
    computed by other physics."""
    text = json.dumps({"model_version": MODEL_VERSION, "run": to_jsonable(inputs)},
                      sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def sha256_file(path, chunk: int = 1 << 20) -> str:
    """SHA-256 hex digest of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


@lru_cache(maxsize=1)
def git_sha() -> str | None:
    """The commit of the source tree demcal runs from, or None outside a git checkout."""
    here = Path(__file__).resolve().parent
    try:
        out = subprocess.run(["git", "-C", str(here), "rev-parse", "HEAD"],
                             capture_output=True, text=True, timeout=5)
    except (OSError, subprocess.SubprocessError):
        return None
    if out.returncode != 0:
        return None
    sha = out.stdout.strip()
    dirty = subprocess.run(["git", "-C", str(here), "status", "--porcelain", "--untracked-files=no"],
                           capture_output=True, text=True, timeout=5)
    return sha + ("-dirty" if dirty.returncode == 0 and dirty.stdout.strip() else "")


def code_version() -> dict:
    """demcal version, git sha, Python and platform: enough to find the code again."""
    return {"demcal": __version__, "git_sha": git_sha(), "model_version": MODEL_VERSION,
            "python": platform.python_version(), "platform": platform.platform()}


@dataclass(frozen=True)
class Provenance:
    """Where a result came from. ``inputs`` maps a file path to its SHA-256."""

    code: dict = field(default_factory=code_version)
    inputs: dict = field(default_factory=dict)
    seed: int | None = None
    options: dict = field(default_factory=dict)
    created: str = field(default_factory=lambda: _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"))

    def to_dict(self) -> dict:
        return asdict(self)
