"""Compile CasADi Functions to C shared libraries, cached on disk by a hash of the code.

:func:`compile_function` generates C with :class:`casadi.CodeGenerator`, hashes the
code together with the compiler and its flags, compiles it once with
``gcc -O2 -shared -fPIC`` by default (:data:`DEFAULT_FLAGS`; the simulator uses
:data:`SIMULATION_FLAGS`, -O3 without FMA contraction). Never ``-ffast-math`` nor
``-march=native``: IEEE arithmetic in the order CasADi wrote it, the same bits on every
machine with the same compiler. and loads it with
:func:`casadi.external`. A second call with the same code compiles nothing.

The cache directory is ``$MRPCTL_CACHE_DIR`` if set, else ``~/.cache/mrpctl``. Libraries
are written to a temporary file in that directory and renamed into place, so parallel
processes (pytest-xdist workers) may compile the same code at the same time safely.

When no C compiler is found (``$CC``, then ``gcc``, then ``cc``), the Function is
returned as it is, to be evaluated by CasADi's virtual machine, with a
:class:`CompilerWarning`.
"""

from __future__ import annotations

import ctypes
import hashlib
import logging
import os
import shutil
import subprocess
import tempfile
import time
import warnings
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from mrpctl.errors import CodegenError, CompilerWarning

__all__ = [
    "DEFAULT_FLAGS",
    "SIMULATION_FLAGS",
    "CFunction",
    "CSession",
    "CompiledFunction",
    "CompilerWarning",
    "address",
    "cache_dir",
    "compile_function",
    "find_compiler",
    "generate_code",
]

logger = logging.getLogger(__name__)

#: Flags used by default (and by the export module): optimised, position independent,
#: IEEE-exact (no fast-math, no -march=native).
DEFAULT_FLAGS: tuple[str, ...] = ("-O2", "-shared", "-fPIC")
#: Flags of the simulator's engine: -O3 inlines the sample function into the unrolled
#: mapaccum (1.4x faster), -fno-semantic-interposition lets -fPIC code inline as well
#: (another 1.4x), -ffp-contract=off forbids fused multiply-adds so that the arithmetic
#: stays the IEEE sequence CasADi wrote on every architecture (measured on the paper's case).
SIMULATION_FLAGS: tuple[str, ...] = ("-O3", "-ffp-contract=off", "-fno-semantic-interposition", "-shared", "-fPIC")

_CODEGEN_OPTIONS = {"with_header": False, "casadi_real": "double", "casadi_int": "long long int"}


@dataclass(frozen=True)
class CompiledFunction:
    """A CasADi Function and how it is evaluated.

    Attributes
    ----------
    function : casadi.Function
        The loaded shared library (``casadi.external``) or the original Function.
    compiled : bool
        True when ``function`` runs compiled C code.
    library : pathlib.Path or None
        The shared library on disk (None for the virtual machine).
    compile_seconds : float
        Wall time spent compiling in this call (0.0 on a cache hit).
    """

    function: ca.Function
    compiled: bool
    library: Path | None
    compile_seconds: float

    def direct(self) -> CFunction | None:
        """A :class:`CFunction` calling the library without CasADi (None for the virtual machine)."""
        if self.library is None:
            return None
        return CFunction(self.library, self.function.name())

    def __str__(self) -> str:
        if not self.compiled:
            return f"{self.function.name()}: CasADi virtual machine (not compiled)"
        how = f"compiled in {self.compile_seconds:.2f} s" if self.compile_seconds else "from cache"
        return f"{self.function.name()}: {self.library} ({how})"


def cache_dir() -> Path:
    """The directory of compiled libraries: ``$MRPCTL_CACHE_DIR`` or ``~/.cache/mrpctl``."""
    configured = os.environ.get("MRPCTL_CACHE_DIR")
    if configured:
        return Path(configured).expanduser()
    return Path.home() / ".cache" / "mrpctl"


def find_compiler() -> str | None:
    """Path of the C compiler: ``$CC`` if set and found, else ``gcc``, else ``cc``; None if none."""
    candidates = [os.environ.get("CC"), "gcc", "cc"]
    for candidate in candidates:
        if candidate:
            found = shutil.which(candidate)
            if found:
                return found
    return None


@lru_cache(maxsize=8)
def _compiler_identity(compiler: str) -> str:
    try:
        done = subprocess.run([compiler, "--version"], capture_output=True, text=True, check=False, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return compiler
    return compiler + "\n" + done.stdout.splitlines()[0] if done.stdout else compiler


def generate_code(function: ca.Function) -> str:
    """The C source of ``function`` (and everything it calls) as one string."""
    generator = ca.CodeGenerator(function.name() + ".c", _CODEGEN_OPTIONS)
    generator.add(function)
    return generator.dump()


def compile_function(
    function: ca.Function,
    *,
    flags: tuple[str, ...] = DEFAULT_FLAGS,
    directory: str | os.PathLike[str] | None = None,
    appendix: str = "",
) -> CompiledFunction:
    """Compile ``function`` to a shared library (or reuse the cached one) and load it.

    Parameters
    ----------
    function : casadi.Function
        Any code-generatable CasADi Function (SX, or MX calling SX Functions).
    flags : tuple of str, keyword-only
        Compiler flags; the default is :data:`DEFAULT_FLAGS`.
    directory : path-like, optional, keyword-only
        Cache directory; default :func:`cache_dir`.
    appendix : str, keyword-only
        C source appended to the generated code (part of the hash), e.g. a driver loop
        that calls the generated function; load its exported symbols from
        :attr:`CompiledFunction.library` with ctypes.

    Returns
    -------
    CompiledFunction
        The loaded Function. With no C compiler, the original Function for CasADi's
        virtual machine, and a :class:`CompilerWarning` is issued.

    Raises
    ------
    CodegenError
        If the compiler is present but fails, or the library cannot be loaded.
    """
    name = function.name()
    compiler = find_compiler()
    if compiler is None:
        warnings.warn(
            f"no C compiler found ($CC, gcc, cc): {name} runs in CasADi's virtual machine, "
            "which is several times slower; install gcc to compile it",
            CompilerWarning,
            stacklevel=2,
        )
        return CompiledFunction(function=function, compiled=False, library=None, compile_seconds=0.0)
    code = generate_code(function) + appendix
    digest = hashlib.sha256(
        "\n".join((code, _compiler_identity(compiler), " ".join(flags), ca.__version__)).encode()
    ).hexdigest()[:20]
    folder = Path(directory) if directory is not None else cache_dir()
    library = folder / f"{name}_{digest}.so"
    seconds = 0.0
    if library.exists():
        logger.debug("cache hit for %s: %s", name, library)
    else:
        seconds = _build(code, library, compiler, flags)
        logger.info("compiled %s in %.2f s -> %s", name, seconds, library)
    try:
        loaded = ca.external(name, str(library))
    except RuntimeError as exc:
        raise CodegenError(f"could not load the compiled library {library}: {exc}") from exc
    return CompiledFunction(function=loaded, compiled=True, library=library, compile_seconds=seconds)


def _build(code: str, library: Path, compiler: str, flags: tuple[str, ...]) -> float:
    try:
        library.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise CodegenError(f"cannot create the cache directory {library.parent}: {exc}") from exc
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="mrpctl-build-") as build:
        source = Path(build) / (library.stem + ".c")
        source.write_text(code)
        handle, partial = tempfile.mkstemp(prefix=library.stem + ".", suffix=".so.part", dir=library.parent)
        os.close(handle)
        try:
            done = subprocess.run(
                [compiler, *flags, str(source), "-o", partial, "-lm"],
                capture_output=True,
                text=True,
                check=False,
            )
            if done.returncode != 0:
                raise CodegenError(
                    f"{Path(compiler).name} failed (exit {done.returncode}) on {source.name}:\n" + done.stderr[-4000:]
                )
            os.replace(partial, library)
        finally:
            if os.path.exists(partial):
                os.unlink(partial)
    return time.perf_counter() - start


_INT = ctypes.c_longlong  # matches the "casadi_int" code-generation option


def address(array: np.ndarray) -> int:
    """The address of a contiguous NumPy array's data (for :class:`CFunction` calls)."""
    return int(array.__array_interface__["data"][0])


class CFunction:
    """Call a generated CasADi function through ctypes on NumPy buffers (no copies).

    Inputs and outputs are NumPy float64 arrays holding the dense nonzeros in
    column-major order (a C-ordered (n, m) array is an m × n CasADi matrix); ``None``
    passes a null pointer (input: zeros; output: not written). The GIL is released
    during the call, so several threads may call one CFunction at once, each through its
    own :meth:`session` (work arrays).
    """

    def __init__(self, library: Path, name: str) -> None:
        self.name = name
        self._library = ctypes.CDLL(str(library))
        self._eval = getattr(self._library, name)
        self._eval.restype = ctypes.c_int
        self._eval.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int]
        work = getattr(self._library, name + "_work")
        sizes = [_INT() for _ in range(4)]
        if work(*[ctypes.byref(size) for size in sizes]) != 0:
            raise CodegenError(f"{name}_work failed in {library}")
        self.sz_arg, self.sz_res, self.sz_iw, self.sz_w = (int(size.value) for size in sizes)
        count = getattr(self._library, name + "_n_in")
        count.restype = _INT
        self.n_in = int(count())
        count = getattr(self._library, name + "_n_out")
        count.restype = _INT
        self.n_out = int(count())

    def session(self) -> CSession:
        """Work arrays for a sequence of calls from one thread."""
        return CSession(self)

    def __call__(self, inputs: list[Any], outputs: list[Any]) -> None:
        """Evaluate once; ``inputs``/``outputs`` are lists of contiguous float64 arrays or None."""
        self.session()(
            [None if value is None else address(value) for value in inputs],
            [None if value is None else address(value) for value in outputs],
        )


class CSession:
    """Pointer and work arrays of one :class:`CFunction`, reused across calls (one thread)."""

    def __init__(self, function: CFunction) -> None:
        self._function = function
        self._eval = function._eval
        self._arg = (ctypes.c_void_p * max(function.sz_arg, 1))()
        self._res = (ctypes.c_void_p * max(function.sz_res, 1))()
        self._iw = (_INT * max(function.sz_iw, 1))()
        self._w = (ctypes.c_double * max(function.sz_w, 1))()

    def __call__(self, inputs: list[int | None], outputs: list[int | None]) -> None:
        """Evaluate on data addresses (see :func:`address`); None is a null pointer."""
        arg, res = self._arg, self._res
        for i, value in enumerate(inputs):
            arg[i] = value
        for i, value in enumerate(outputs):
            res[i] = value
        if self._eval(arg, res, self._iw, self._w, 0) != 0:
            raise CodegenError(f"evaluation of the compiled function {self._function.name} failed")
