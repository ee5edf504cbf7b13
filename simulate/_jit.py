"""One shared set of numba JIT flags for every simulate kernel, and the kernel cache guard.

Arithmetic is IEEE, without ``fastmath``. Its flags let LLVM fuse, reorder and approximate
across whatever code it sees at once, and that depends on how a kernel was built: compiled in
this process with its callees, or loaded from the cache. With them the same run gave other
bits in a fresh process than in the next one (spring-dashpot rolling, threaded runs); without
them it does not, at no measurable cost in speed (``tests/simulate/test_jit.py``). Leaving out
``nnan`` and ``ninf`` also keeps comparisons with NaN and infinity meaningful (the engine must
be able to see a non-finite state and stop).

Kernels are cached on disk (``cache=True``), so a second run loads machine code instead of
compiling. numba checks only the source file of each cached function, while the engine's
kernels inline evaluators from several modules; ``refresh_stale_cache`` therefore drops the
cached kernels of this package whenever any of those sources changes.

Loops over every contact or body are ``loop_kernel``s, compiled without numba's reference
counting (its private ``_nrt=False`` option). Every array an evaluator is handed inside such a
loop otherwise costs an atomic increment and decrement of its reference count per element:
about a third of the paper case's run time went to them. A loop kernel allocates nothing (numba
refuses to compile one that does) and borrows its arrays from its caller, which holds them for
the call. The arithmetic is the same, so are the bits. numba cannot lower a ``prange`` loop
without reference counting, so a threaded variant hands each thread blocks of rows of a loop
kernel.

The same counts are paid once per call of a kernel that takes arrays, so they also set a floor
under every step whatever the number of particles: in a rig of one particle (an incline, a drop)
more than half the CPU samples fall on them. The serial force kernel is therefore a loop kernel,
``serial_or_threaded`` passes the step's arrays on by name instead of packing them into a tuple
and out again, and on one thread the steps between two list rebuilds run in a loop kernel
(``engine._steps_serial``): the step loop counts its arrays once per rebuild, not once per step.
A step of a one-particle rig costs less than half what it did (``benchmarks/RESULTS.md``).

``serial_or_threaded`` pairs a serial kernel with its threaded variant, chosen when the caller
compiles, so that the threaded variants (about half of the compile time) are compiled only by
a process that runs on threads.

A process that has to compile the kernels (none in the cache) says so once on stderr; ``prefetch``
is a cache hint for kernels (``simulate.forces.PREFETCH_AHEAD``).
"""

from __future__ import annotations

import hashlib
import inspect
import sys
import types as types_module
from pathlib import Path

import numba
from llvmlite import ir
from numba import types
from numba.core import cgutils, event
from numba.core.errors import TypingError
from numba.extending import intrinsic, overload

#: Flags of every compiled kernel.
JIT_FLAGS = dict(
    cache=True,
    nogil=True,
    error_model="numpy",
    boundscheck=False,
    fastmath=False,
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


class _CompileNotice(event.Listener):
    """Says once per process, on stderr, that this package's kernels are being compiled: the first
    command after installing spends half a minute or more on it, which would otherwise pass in
    silence (a campaign's progress bar standing at 0). numba emits ``numba:compile`` only for a
    kernel missing from the cache, so a process that loads them says nothing."""

    said = False

    def on_start(self, ev):
        function = getattr(ev.data.get("dispatcher"), "py_func", None)
        if not self.said and (getattr(function, "__module__", None) or "").startswith(__package__ + "."):
            self.said = True
            from tqdm import tqdm    # written above any progress bar on the terminal

            tqdm.write("demcal: compiling the DEM kernels for this installation, once (half a minute to a "
                       "minute; `demcal compile` does it ahead of time); later runs load them from the "
                       "cache", file=sys.stderr)

    def on_end(self, ev):
        pass


compile_notice = _CompileNotice()
event.register("numba:compile", compile_notice)


def kernel(fn):
    """Compile ``fn`` with the shared flags."""
    return numba.njit(**JIT_FLAGS)(fn)


def loop_kernel(fn):
    """Compile ``fn`` with the shared flags and without numba's reference counting (a loop that
    allocates nothing; see the module docstring)."""
    return numba.njit(_nrt=False, **JIT_FLAGS)(fn)


def threaded_kernel(fn):
    """Compile ``fn`` with the shared flags and ``numba.prange`` loops run on threads."""
    return numba.njit(parallel=True, **JIT_FLAGS)(fn)


def evaluator(fn):
    """Compile ``fn`` with the shared flags, inlined at numba level into its callers."""
    return numba.njit(**INLINE_FLAGS)(fn)


def serial_twin(threaded):
    """A kernel of the same source as the ``threaded_kernel`` ``threaded``, compiled without
    threads: its ``numba.prange`` loops run as plain loops (``numba.get_thread_id()`` is 0), and
    it skips the parallel passes' compile time (the list rebuild compiles in a third of it).

    The twin is named ``<name>_serial``: numba keys a function's cached machine code by its name,
    bytecode and argument types, not by its compile flags, so under the same name the two
    variants would load each other's code from the cache."""
    fn = threaded.py_func
    twin = types_module.FunctionType(fn.__code__, fn.__globals__, fn.__name__ + "_serial", fn.__defaults__,
                                     fn.__closure__)
    twin.__qualname__ = fn.__qualname__ + "_serial"
    twin.__doc__ = fn.__doc__
    twin.__module__ = fn.__module__
    return kernel(twin)


def serial_or_threaded(serial, threaded):
    """One kernel of two variants: ``f = serial_or_threaded(a, b)`` is called in a kernel as
    ``f(use_threads, *args)`` with ``use_threads`` a constant (a literal ``True`` or ``False``
    passed down from a caller) and runs ``b(*args)`` if it is true, else ``a(*args)``. Only the
    chosen variant is compiled into the caller, so a serial loop never compiles the threaded
    kernels (about half of the engine's compile time)."""

    # the arguments by name (the serial kernel's), not packed into a tuple: each array is passed
    # on as it came, instead of counted into a tuple and out of it at every call of every step
    names = ", ".join(inspect.signature(serial.py_func).parameters)

    def choose(use_threads):
        if not isinstance(use_threads, types.BooleanLiteral):
            raise TypingError(f"{serial.__name__}: 'use_threads' must be a constant True or False")
        scope = {"chosen": threaded if use_threads.literal_value else serial}
        exec(f"def call(use_threads, {names}):\n    return chosen({names})\n", scope)
        return scope["call"]

    scope = {"serial": serial, "threaded": threaded, "choose": choose}
    exec(f"def either(use_threads, {names}):\n"
         f"    return (threaded if use_threads else serial)({names})\n"
         f"def typed(use_threads, {names}):\n"
         f"    return choose(use_threads)\n", scope)
    # a function made by exec has no file to cache against; it is compiled into its caller,
    # whose cached machine code holds it
    overload(scope["either"], jit_options=dict(JIT_FLAGS, cache=False))(scope["typed"])
    return scope["either"]


@intrinsic
def prefetch(typingctx, array, row):
    """``prefetch(array, row)`` in a kernel asks the processor to bring the first cache line of
    ``array[row]`` into its caches (LLVM's ``llvm.prefetch``: a read, kept close). A hint only: it
    changes no value, and an address out of bounds does not fault."""
    if not isinstance(array, types.Array) or not isinstance(row, types.Integer):
        return None

    def codegen(context, builder, signature, args):
        array_type = signature.args[0]
        view = context.make_array(array_type)(context, builder, args[0])
        index = context.cast(builder, args[1], signature.args[1], types.intp)
        indices = [index] + [context.get_constant(types.intp, 0)] * (array_type.ndim - 1)
        address = cgutils.get_item_pointer(context, builder, array_type, view, indices)
        byte_pointer = ir.IntType(8).as_pointer()
        i32 = ir.IntType(32)
        hint = cgutils.get_or_insert_function(builder.module,
                                              ir.FunctionType(ir.VoidType(), [byte_pointer, i32, i32, i32]),
                                              "llvm.prefetch.p0")
        builder.call(hint, [builder.bitcast(address, byte_pointer), i32(0), i32(3), i32(1)])
        return context.get_dummy_value()

    return types.void(array, row), codegen
