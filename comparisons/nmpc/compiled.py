"""casadi Functions compiled to C once per machine and called through ``ctypes``.

:func:`compile_function` writes the C code of a casadi Function (casadi's code
generator: the whole ``sqpmethod`` solver with its derivatives and its QP solver),
compiles it into a shared library and loads it. The library is cached under a hash
of the generated source, the compiler command and the casadi installation, so each
problem compiles once per machine (``$DFCOA_NMPC_CACHE``, default
``$XDG_CACHE_HOME/dfcoa_opt/nmpc`` or ``~/.cache/dfcoa_opt/nmpc``). Without a C
compiler (``$CC``, ``cc`` or ``gcc``), or when compiling or loading fails, it warns
and returns None: the caller keeps the interpreted casadi Function, which computes
the same numbers.

The compiled function is called through casadi's C API (``<name>_work``,
``<name>_checkout``, ...) with ``ctypes``: one dense input vector and one dense
output vector, with no casadi Python wrapper in between (that wrapper alone costs
about 35 us per call, measured in ``docs/methods/nmpc.md``). A small C loop
appended to the generated source, ``<name>_batch``, evaluates the function on
every row of an ``(N, n_in)`` array in one ``ctypes`` call (:meth:`CompiledFunction.batch`),
timing each row with ``CLOCK_MONOTONIC``: the same calls, in the same order, as
``N`` single calls.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import tempfile
import threading
import warnings
from functools import lru_cache
from pathlib import Path

import casadi as ca
import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
#: Optimisation flags: -O2 (-O3 measured no faster); no -ffast-math, so the compiled
#: code evaluates the same floating-point operations as casadi's interpreter.
CFLAGS = ("-O2", "-fPIC", "-shared")
#: casadi's shared libraries, linkable by name (``-l``), e.g. ``daqp``.
CASADI_DIR = Path(ca.__file__).resolve().parent
#: The row loop appended to the generated source (``{name}``: the function's name). It
#: points ``arg[0]``/``res[0]`` at row ``i`` and calls the function, as a single call
#: does, then points them back at the single call's buffers.
BATCH_SOURCE = """
#include <time.h>
CASADI_SYMBOL_EXPORT int {name}_batch(const casadi_real** arg, casadi_real** res,
    casadi_int* iw, casadi_real* w, int mem, casadi_int n, casadi_int n_in,
    casadi_int n_out, const casadi_real* z, casadi_real* out, int* flags,
    casadi_real* seconds) {{
  casadi_int i;
  struct timespec t0, t1;
  const casadi_real* arg0 = arg[0];
  casadi_real* res0 = res[0];
  for (i = 0; i < n; ++i) {{
    arg[0] = z + i * n_in;
    res[0] = out + i * n_out;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    flags[i] = {name}(arg, res, iw, w, mem);
    clock_gettime(CLOCK_MONOTONIC, &t1);
    seconds[i] = (casadi_real)(t1.tv_sec - t0.tv_sec)
                 + 1e-9 * (casadi_real)(t1.tv_nsec - t0.tv_nsec);
  }}
  arg[0] = arg0;
  res[0] = res0;
  return 0;
}}
"""


def cache_dir() -> Path:
    """Where compiled libraries are kept (``$DFCOA_NMPC_CACHE`` or the user cache)."""
    env = os.environ.get("DFCOA_NMPC_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "dfcoa_opt" / "nmpc"


def compiler() -> str | None:
    """The C compiler: ``$CC``, else ``cc`` or ``gcc`` on the path; None without one."""
    cc = os.environ.get("CC")
    if cc:
        return shutil.which(cc)
    return shutil.which("cc") or shutil.which("gcc")


class CompiledFunction:
    """A compiled one-input, one-output casadi Function, called with numpy vectors.

    Not re-entrant: calls on one object are serialised by a lock (ctypes releases the
    GIL); objects of the same library share it (one casadi memory per library).

    Args:
        path: The shared library.
        name: The function's name in it.
        n_in: Length of the dense input vector.
        n_out: Length of the dense output vector.
    """

    def __init__(self, path: Path, name: str, n_in: int, n_out: int) -> None:
        self.path, self.name, self.n_in, self.n_out = path, name, n_in, n_out
        lib = ctypes.CDLL(str(path))
        sizes = [ctypes.c_longlong() for _ in range(4)]
        fn = getattr(lib, name)
        getattr(lib, f"{name}_work")(*(ctypes.byref(s) for s in sizes))
        n_arg, n_res, n_iw, n_w = (max(int(s.value), 1) for s in sizes)
        getattr(lib, f"{name}_incref")()
        self._mem = int(getattr(lib, f"{name}_checkout")())
        if self._mem < 0:
            raise RuntimeError(f"{path}: no free casadi memory for {name}")
        self._in, self._out = np.zeros(n_in), np.zeros(n_out)
        self._iw, self._w = np.zeros(n_iw, dtype=np.int64), np.zeros(n_w)
        ptr = ctypes.POINTER(ctypes.c_double)
        self._arg, self._res = (ptr * n_arg)(), (ptr * n_res)()
        self._arg[0], self._res[0] = self._in.ctypes.data_as(ptr), self._out.ctypes.data_as(ptr)
        fn.argtypes = [ctypes.c_void_p] * 4 + [ctypes.c_int]
        fn.restype = ctypes.c_int
        self._fn = fn
        self._batch = getattr(lib, f"{name}_batch", None)
        if self._batch is not None:
            self._batch.argtypes = ([ctypes.c_void_p] * 4 + [ctypes.c_int]
                                    + [ctypes.c_longlong] * 3 + [ctypes.c_void_p] * 4)
            self._batch.restype = ctypes.c_int
        self._call = (ctypes.addressof(self._arg), ctypes.addressof(self._res),
                      self._iw.ctypes.data, self._w.ctypes.data, self._mem)
        self._lib, self._lock = lib, threading.Lock()

    def __call__(self, x: FloatArray) -> FloatArray:
        """Evaluate at the ``(n_in,)`` input; returns a new ``(n_out,)`` array.

        Raises:
            RuntimeError: The compiled function returned an error flag.
        """
        with self._lock:
            self._in[:] = x
            flag = self._fn(*self._call)
            out = self._out.copy()
        if flag:
            raise RuntimeError(f"{self.name} (compiled) returned {flag}")
        return out

    def batch(self, z: FloatArray) -> tuple[FloatArray, NDArray[np.intc], FloatArray]:
        """Evaluate every row of ``z`` ``(N, n_in)`` in one call (``<name>_batch``).

        Row ``i`` gives the numbers of ``self(z[i])``: the same compiled function,
        called in row order on the same memory.

        Returns:
            ``(out (N, n_out), flags (N,), seconds (N,))``: the outputs, each row's
            error flag (0 = success; a row with a flag has undefined outputs) and its
            wall time in s.

        Raises:
            RuntimeError: The library has no ``<name>_batch`` (built before it existed).
        """
        if self._batch is None:
            raise RuntimeError(f"{self.path}: no {self.name}_batch")
        z = np.ascontiguousarray(z, dtype=np.float64)
        n = z.shape[0]
        out, seconds = np.empty((n, self.n_out)), np.empty(n)
        flags = np.zeros(n, dtype=np.intc)
        arg, res, iw, w, mem = self._call
        with self._lock:
            self._batch(arg, res, iw, w, mem, n, self.n_in, self.n_out, z.ctypes.data,
                        out.ctypes.data, flags.ctypes.data, seconds.ctypes.data)
        return out, flags, seconds


def _source(fn: ca.Function, name: str) -> str:
    """C source of ``fn`` and its dependencies (casadi code generator) and its row loop."""
    gen = ca.CodeGenerator(f"{name}.c", {"with_header": False})
    gen.add(fn)
    return gen.dump() + BATCH_SOURCE.format(name=name)


def library_path(source: str, cc: str, libs: tuple[str, ...]) -> Path:
    """Cache path of the library of ``source`` built by ``cc`` against ``libs``."""
    key = "\n".join((source, cc, " ".join(CFLAGS), " ".join(libs), ca.__version__,
                     str(CASADI_DIR)))
    return cache_dir() / f"{hashlib.sha256(key.encode()).hexdigest()[:24]}.so"


def _build(source: str, cc: str, libs: tuple[str, ...], target: Path) -> None:
    """Compile ``source`` into ``target`` (atomically: concurrent builders are safe)."""
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=target.parent) as tmp:
        c_file, so_file = Path(tmp) / "f.c", Path(tmp) / "f.so"
        c_file.write_text(source)
        cmd = [cc, *CFLAGS, str(c_file), f"-I{CASADI_DIR / 'include'}", f"-L{CASADI_DIR}",
               *(f"-l{lib}" for lib in libs), f"-Wl,-rpath,{CASADI_DIR}", "-lm", "-o",
               str(so_file)]
        run = subprocess.run(cmd, capture_output=True, text=True, check=False)
        if run.returncode != 0:
            raise RuntimeError(f"{' '.join(cmd)}: {run.stderr.strip()[:2000]}")
        os.replace(so_file, target)


@lru_cache(maxsize=32)
def _load(path: Path, name: str, n_in: int, n_out: int) -> CompiledFunction:
    """One loaded object per library and process (casadi's generated code has one memory)."""
    return CompiledFunction(path, name, n_in, n_out)


def compile_function(fn: ca.Function, libs: tuple[str, ...] = ()) -> CompiledFunction | None:
    """``fn`` (one dense input, one dense output) compiled and loaded, or None.

    Compiles only when the cache has no library for this exact source; the first
    call for a problem takes a few seconds (gcc), later ones (any process) a few ms.

    Args:
        fn: A casadi Function with one dense column input and one dense column output.
        libs: casadi libraries to link (``"daqp"`` for the daqp QP solver).

    Returns:
        The compiled function, or None (with a warning) without a compiler or when
        the build fails; the caller then uses ``fn`` itself.
    """
    cc = compiler()
    if cc is None:
        warnings.warn("nmpc: no C compiler found ($CC, cc, gcc): using casadi's interpreted "
                      "solver (same results, slower)", RuntimeWarning, stacklevel=2)
        return None
    name = fn.name()
    source = _source(fn, name)
    path = library_path(source, cc, libs)
    try:
        if not path.exists():
            _build(source, cc, libs, path)
        return _load(path, name, fn.nnz_in(), fn.nnz_out())
    except (OSError, RuntimeError, AttributeError) as exc:
        warnings.warn(f"nmpc: compiling the solver failed, using casadi's interpreted solver "
                      f"(same results, slower): {exc}", RuntimeWarning, stacklevel=2)
        return None
