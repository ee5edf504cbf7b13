"""How the kernels are compiled (``simulate._jit``): a run gives the same bits whether its
kernels were compiled in the process or loaded from numba's cache, and a kernel of two variants
compiles only the one its caller chose."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numba
import pytest
from numba.core.errors import TypingError

from demcal.simulate._jit import serial_or_threaded

# Three short pours whose arithmetic differs most between models: the default, the
# spring-dashpot rolling with e(v) and effective mass (exp, log, pow), and the threaded loop.
_POURS = textwrap.dedent("""
    import hashlib, numpy as np
    from demcal.simulate.params import DEMParameters
    from demcal.simulate.scenes import build_paper_repose_case
    hooks = dict(rolling_model="epsd", e_pp_exponent=0.05, e_pw_exponent=0.05, contact_effective_mass=True)
    for kw, threads in (({}, None), (hooks, None), ({}, 2)):
        sim = build_paper_repose_case(DEMParameters().with_(**kw), seed=3, n_clumps=200)
        sim.threads = threads
        sim.run(duration=0.4)
        h = hashlib.sha256(np.ascontiguousarray(sim.positions()).tobytes())
        h.update(np.ascontiguousarray(sim.velocities()).tobytes())
        print(h.hexdigest())
""")


@pytest.mark.validation
def test_a_run_is_the_same_compiled_or_loaded_from_the_cache(tmp_path):
    # opt-in: compiling every kernel in an empty cache takes a core for over a minute; the
    # default suite checks the flags whose absence it guards (below)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"), NUMBA_NUM_THREADS="2")

    def pours():
        done = subprocess.run([sys.executable, "-c", _POURS], env=env, capture_output=True, text=True,
                              timeout=900)
        assert done.returncode == 0, done.stderr[-3000:]
        return done.stdout.split()

    compiled = pours()       # an empty cache: every kernel compiled in this process
    loaded = pours()         # the same kernels loaded from the cache
    assert len(compiled) == 3
    assert compiled == loaded


def test_every_kernel_is_compiled_in_ieee_arithmetic():
    """``fastmath`` is what made a run's bits depend on whether its kernels were compiled or
    loaded from the cache (``simulate._jit``); no kernel of the package may set it."""
    import importlib
    import pkgutil

    import demcal.simulate
    from numba.core.dispatcher import Dispatcher

    kernels = {}
    for module in pkgutil.walk_packages(demcal.simulate.__path__, "demcal.simulate."):
        for value in vars(importlib.import_module(module.name)).values():
            if isinstance(value, Dispatcher) and value.__module__.startswith("demcal."):
                kernels[f"{value.__module__}.{value.__name__}"] = value.targetoptions
    assert len(kernels) > 40 and "demcal.simulate.engine._advance_serial" in kernels
    assert {name for name, options in kernels.items() if options.get("fastmath") is not False} == set()


def _twice(x):
    return 2.0 * x


def _thrice(x):
    return 3.0 * x


def test_serial_or_threaded_compiles_only_the_chosen_variant():
    serial, threaded = numba.njit(_twice), numba.njit(_thrice)
    either = serial_or_threaded(serial, threaded)

    @numba.njit
    def on_one(x):
        return either(False, x)

    @numba.njit
    def on_many(x):
        return either(True, x)

    @numba.njit
    def undecided(flag, x):
        return either(flag, x)

    assert on_one(5.0) == 10.0
    assert threaded.signatures == []     # the serial caller never compiled the other variant
    assert on_many(5.0) == 15.0
    with pytest.raises(TypingError, match="constant True or False"):
        undecided(True, 5.0)


def test_demcal_compile_readies_the_serial_and_the_threaded_step_loop():
    # a process of its own: in this one another test may already have loaded either variant
    check = textwrap.dedent("""
        from demcal.cli import main
        from demcal.simulate import engine
        assert not engine._advance_serial.signatures and not engine._advance_ranged.signatures
        assert main(["compile"]) == 0
        print(bool(engine._advance_serial.signatures), bool(engine._advance_ranged.signatures))
    """)
    done = subprocess.run([sys.executable, "-c", check], capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "DEM kernels ready" in done.stdout
    assert done.stdout.split()[-2:] == ["True", "True"]


_COMPILE_ONE = textwrap.dedent("""
    import sys, numba, numpy as np
    from demcal.simulate.engine import _copy_rows
    numba.njit(lambda x: x + 1)(1)          # not the engine's
    if sys.argv[1] == "engine":
        _copy_rows(np.zeros((2, 3)), np.zeros((2, 3)), 2)
        _copy_rows(np.zeros((2, 3), np.float32), np.zeros((2, 3), np.float32), 2)
""")


def test_compiling_the_engine_says_so_once_and_loading_it_says_nothing(tmp_path):
    """The first command of an installation compiles for half a minute or more: it says so on
    stderr, once per process however many kernels it compiles, and only for the engine's (a
    user's own numba function compiles in silence); loading them from the cache is silent."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"))
    said = []
    for what in ("other", "engine", "engine"):
        done = subprocess.run([sys.executable, "-c", _COMPILE_ONE, what], env=env, capture_output=True, text=True,
                              timeout=300)
        assert done.returncode == 0, done.stderr
        said.append(done.stderr.count("demcal: compiling the DEM kernels"))
    assert said == [0, 1, 0]
