"""One shared set of numba JIT flags for every simulate kernel, and the kernel cache guard.

``fastmath`` is restricted to the flags that only reorder or contract arithmetic; ``nnan`` and
``ninf`` are left out on purpose, so that comparisons with NaN and infinity keep their meaning
(the engine must be able to see a non-finite state and stop).

Kernels are cached on disk (``cache=True``), so a second run loads machine code instead of
compiling. numba checks only the source file of each cached function, while the engine's
kernels inline evaluators from several modules; ``refresh_stale_cache`` therefore drops the
cached kernels of this package whenever any of those sources changes.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numba

#: Flags of every compiled kernel.
JIT_FLAGS = dict(
    cache=True,
    nogil=True,
    error_model="numpy",
    boundscheck=False,
    fastmath={"nsz", "arcp", "contract", "afn", "reassoc"},
)

#: Small evaluators inlined into the kernels that call them.
INLINE_FLAGS = dict(JIT_FLAGS, inline="always")

#: Source files whose code ends up in the cached kernels.
KERNEL_SOURCES = ("_jit.py", "contact/hertz_mindlin.py", "contact/rolling.py", "integrate.py",
                  "walls.py", "neighbours.py", "forces.py", "engine.py")


def refresh_stale_cache() -> None:
    """Delete this package's cached kernels if any kernel source changed since they were made."""
    root = Path(__file__).resolve().parent
    try:
        digest = hashlib.sha256(b"".join((root / name).read_bytes() for name in KERNEL_SOURCES)).hexdigest()
        stamp = root / "__pycache__" / "kernel-sources.sha256"
        if stamp.is_file() and stamp.read_text().strip() == digest:
            return
        for folder in (root / "__pycache__", root / "contact" / "__pycache__"):
            if folder.is_dir():
                for cached in list(folder.glob("*.nbi")) + list(folder.glob("*.nbc")):
                    cached.unlink(missing_ok=True)
        stamp.parent.mkdir(exist_ok=True)
        stamp.write_text(digest + "\n")
    except OSError:
        pass  # a read-only installation keeps whatever cache it has


refresh_stale_cache()


def kernel(fn):
    """Compile ``fn`` with the shared flags."""
    return numba.njit(**JIT_FLAGS)(fn)


def threaded_kernel(fn):
    """Compile ``fn`` with the shared flags and ``numba.prange`` loops run on threads."""
    return numba.njit(parallel=True, **JIT_FLAGS)(fn)


def evaluator(fn):
    """Compile ``fn`` with the shared flags, inlined at numba level into its callers."""
    return numba.njit(**INLINE_FLAGS)(fn)
