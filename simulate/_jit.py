"""One shared set of numba JIT flags for every simulate kernel.

``fastmath`` is restricted to the flags that only reorder or contract arithmetic; ``nnan`` and
``ninf`` are left out on purpose, because the engine must be able to see a non-finite state and
stop (that check runs in numpy on the returned arrays, but a kernel compiled under ``nnan`` may
also drop the guards against zero-length vectors).
"""

from __future__ import annotations

import numba

#: Flags of every compiled kernel (``cache=True``: the second run loads machine code from disk).
JIT_FLAGS = dict(
    cache=True,
    nogil=True,
    error_model="numpy",
    boundscheck=False,
    fastmath={"nsz", "arcp", "contract", "afn", "reassoc"},
)

#: Small evaluators inlined into the kernels that call them.
INLINE_FLAGS = dict(JIT_FLAGS, inline="always")


def kernel(fn):
    """Compile ``fn`` with the shared flags."""
    return numba.njit(**JIT_FLAGS)(fn)


def evaluator(fn):
    """Compile ``fn`` with the shared flags, inlined at numba level into its callers."""
    return numba.njit(**INLINE_FLAGS)(fn)
