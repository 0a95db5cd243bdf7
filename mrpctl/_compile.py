"""Compile C code to shared libraries: one compiler call, an on-disk cache that checks what it loads.

`compile_function` generates C from a CasADi Function with
`casadi.CodeGenerator`, compiles it (or reuses the cached library) and loads it with
`casadi.external`; `compile_source` does the same for C source that is not a
CasADi Function and returns the library's path (load it with `ctypes`). Both go
through `build_library`, the one place the compiler runs; [`mrpctl._export`][mrpctl._export]
builds its shared library with it too.

Flags: ``-O2 -shared -fPIC`` by default (`DEFAULT_FLAGS`); the simulator uses
`SIMULATION_FLAGS` (-O3 without FMA contraction). Never ``-ffast-math`` nor
``-march=native``: IEEE arithmetic in the order CasADi wrote it, so that the same code
gives the same bits on every machine with the same compiler.

The compiler is ``$CC`` when that variable is set (a program name or path, without
arguments; if it cannot be found a [`CodegenError`][mrpctl.errors.CodegenError] says so, and how to unset it),
else ``gcc``, else ``cc``. Without any, `compile_function` returns the Function for
CasADi's virtual machine with a [`CompilerWarning`][mrpctl.errors.CompilerWarning]. Each compiler call is bounded by a
timeout (`DEFAULT_TIMEOUT` = 600 s, ``$MRPCTL_COMPILE_TIMEOUT``, or the ``timeout``
keyword): past it the compiler and its children are killed and a [`CodegenError`][mrpctl.errors.CodegenError]
names the compiler and the limit.

The cache
---------
The directory is ``$MRPCTL_CACHE_DIR`` if set, else ``~/.cache/mrpctl``. A library is named
``<name>_<hash>.so``, the hash covering the code, the compiler and its version, the flags
and CasADi's version. Beside it, ``<name>_<hash>.so.sha256`` records its size and SHA-256;
it is written (atomically) after the library is in place. Before a library is loaded its
size and checksum are verified: a truncated one (which would kill the interpreter with a
bus error when loaded), a garbage one, or one without a checksum file is deleted and
rebuilt with a [`CacheWarning`][mrpctl.errors.CacheWarning].

Builds run in a private folder ``build-<pid>-<random>`` inside the cache directory, and the
library is written to ``<name>_<hash>.so.<pid>-<random>.part`` and renamed into place, so a
reader never sees half a library. A per-library lock file (``flock``) serialises processes
and threads compiling the same code: the second waits and then finds the library built.
Each build first removes ``.part`` files and build folders left by killed processes (their
pid is dead, or they are older than a day), and ``mrpctl-build-*`` folders of older mrpctl
versions in the temporary directory that are older than a day.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import math
import os
import re
import secrets
import shutil
import signal
import subprocess
import tempfile
import time
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from mrpctl._files import file_sha256
from mrpctl._validation import positive_scalar
from mrpctl.errors import CacheWarning, CodegenError, CompilerWarning, SpecificationError

try:  # POSIX; without it (Windows) compiles of the same code are not serialised
    import fcntl
except ImportError:  # pragma: no cover - not on Linux
    fcntl = None  # type: ignore[assignment]

__all__ = [
    "DEFAULT_FLAGS",
    "DEFAULT_TIMEOUT",
    "SIMULATION_FLAGS",
    "STALE_SECONDS",
    "TIMEOUT_VARIABLE",
    "CacheWarning",
    "CompiledFunction",
    "CompilerWarning",
    "abandoned",
    "address",
    "build_library",
    "cache_dir",
    "compile_function",
    "compile_source",
    "compile_timeout",
    "compiler_version",
    "find_compiler",
    "generate_code",
]

logger = logging.getLogger(__name__)

#: Flags used by default (and by the export): optimised, position independent,
#: IEEE-exact (no fast-math, no -march=native).
DEFAULT_FLAGS: tuple[str, ...] = ("-O2", "-shared", "-fPIC")
#: Flags of the simulator's engine: -O3 inlines the sample function into the unrolled
#: mapaccum (1.4x faster), -fno-semantic-interposition lets -fPIC code inline as well
#: (another 1.4x), -ffp-contract=off forbids fused multiply-adds so that the arithmetic
#: stays the IEEE sequence CasADi wrote on every architecture (measured on the paper's case).
SIMULATION_FLAGS: tuple[str, ...] = ("-O3", "-ffp-contract=off", "-fno-semantic-interposition", "-shared", "-fPIC")
#: Default limit of one compiler call (s).
DEFAULT_TIMEOUT = 600.0
#: Environment variable overriding `DEFAULT_TIMEOUT` (seconds).
TIMEOUT_VARIABLE = "MRPCTL_COMPILE_TIMEOUT"
#: Age (s) after which a leftover ``.part`` file or build folder is removed even if its pid lives.
STALE_SECONDS = 86400.0

_CODEGEN_OPTIONS: dict[str, Any] = {"with_header": False, "casadi_real": "double", "casadi_int": "long long int"}
_CASADI_VERSION: str = vars(ca)["__version__"]  # (CasADi's stubs do not declare it)
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_PID_TAG = re.compile(r"(?:^build-|\.)(\d+)-[0-9a-f]+(?:\.part)?$")
_CHECKSUM_SUFFIX = ".sha256"


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

    def __str__(self) -> str:
        if not self.compiled:
            return f"{self.function.name()}: CasADi virtual machine (not compiled)"
        how = f"compiled in {self.compile_seconds:.2f} s" if self.compile_seconds else "from cache"
        return f"{self.function.name()}: {self.library} ({how})"


# ================================================================ compiler and settings
def cache_dir() -> Path:
    """The directory of compiled libraries: ``$MRPCTL_CACHE_DIR`` or ``~/.cache/mrpctl``."""
    configured = os.environ.get("MRPCTL_CACHE_DIR")
    if configured:
        return Path(configured).expanduser()
    return Path.home() / ".cache" / "mrpctl"


def find_compiler() -> str | None:
    """Path of the C compiler: ``$CC`` if set, else ``gcc``, else ``cc``; None if there is none.

    Raises
    ------
    CodegenError
        If ``$CC`` is set (non-empty) but names no executable program: it is never
        silently replaced by another compiler.
    """
    configured = os.environ.get("CC", "").strip()
    if configured:
        found = shutil.which(configured)
        if found is None:
            raise CodegenError(
                f"the environment variable CC={configured!r} names no executable C compiler "
                "(not found on PATH, or not executable; CC must be one program, without arguments): "
                "set CC to an installed compiler, or unset it (`unset CC`) to use gcc or cc"
            )
        return found
    for candidate in ("gcc", "cc"):
        found = shutil.which(candidate)
        if found:
            return found
    return None


def compile_timeout(timeout: float | None = None) -> float:
    """The limit (s) of one compiler call: ``timeout``, else ``$MRPCTL_COMPILE_TIMEOUT``, else 600 s."""
    if timeout is not None:
        return positive_scalar("timeout", timeout)
    configured = os.environ.get(TIMEOUT_VARIABLE, "").strip()
    if not configured:
        return DEFAULT_TIMEOUT
    try:
        value = float(configured)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0.0):
        raise SpecificationError(
            f"the environment variable {TIMEOUT_VARIABLE} must be a positive number of seconds, got {configured!r}"
        )
    return value


def compiler_version(compiler: str, *, timeout: float | None = None) -> str | None:
    """The first line ``compiler --version`` prints (None if it prints nothing or cannot run)."""
    return _compiler_version(compiler, compile_timeout(timeout))


@lru_cache(maxsize=8)
def _compiler_version(compiler: str, timeout: float) -> str | None:
    try:
        done = _run([compiler, "--version"], cwd=None, timeout=timeout, compiler=compiler)
    except CodegenError as exc:
        if "did not finish" in str(exc):
            raise
        return None
    lines = done.stdout.splitlines()
    return lines[0] if lines else None


def _run(command: list[str], *, cwd: Path | None, timeout: float, compiler: str) -> subprocess.CompletedProcess[str]:
    """Run the compiler in its own process group; on timeout or interruption kill the whole group."""
    try:
        process = subprocess.Popen(
            command,
            cwd=cwd,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,
        )
    except OSError as exc:
        raise CodegenError(f"could not run the C compiler {compiler}: {exc}") from exc
    with process:
        try:
            stdout, stderr = process.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            _kill_group(process)
            raise CodegenError(
                f"the C compiler {compiler} did not finish within the timeout of {timeout:g} s and was "
                f"killed; raise the limit with the timeout keyword or ${TIMEOUT_VARIABLE} (seconds)"
            ) from None
        except BaseException:  # KeyboardInterrupt, SystemExit: the compiler must not outlive us
            _kill_group(process)
            raise
    return subprocess.CompletedProcess(command, process.returncode, stdout, stderr)


def _kill_group(process: subprocess.Popen[str]) -> None:
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(process.pid, signal.SIGKILL)
    with contextlib.suppress(subprocess.TimeoutExpired):
        process.communicate(timeout=10.0)


# ===================================================================== the one build
def build_library(
    source: str | os.PathLike[str],
    output: str | os.PathLike[str],
    *,
    compiler: str | None = None,
    flags: tuple[str, ...] = DEFAULT_FLAGS,
    timeout: float | None = None,
) -> float:
    """Compile the C file ``source`` into the shared library ``output``, atomically.

    The compiler runs in the folder of ``source`` (``compiler *flags source -o part -lm``),
    writes ``<output>.<pid>-<random>.part`` and that file is renamed to ``output``: a reader
    never sees half a library, and an interruption leaves ``output`` as it was.

    Parameters
    ----------
    source : path-like
        The C translation unit.
    output : path-like
        The library to write (replaced if present).
    compiler : str, optional, keyword-only
        The compiler; default `find_compiler`.
    flags : tuple of str, keyword-only
        Compiler flags; default `DEFAULT_FLAGS`.
    timeout : float, optional, keyword-only
        Limit of the compiler call (s); default `compile_timeout`.

    Returns
    -------
    float
        Wall time of the compilation (s).

    Raises
    ------
    CodegenError
        If there is no compiler, it fails, it exceeds the timeout, or the output cannot be written.
    """
    limit = compile_timeout(timeout)
    flags = _flags(flags)
    if compiler is None:
        compiler = find_compiler()
        if compiler is None:
            raise CodegenError("no C compiler found ($CC, gcc, cc): install gcc, or set CC to a C compiler")
    source, output = Path(source), Path(output)
    partial = output.with_name(f"{output.name}.{os.getpid()}-{secrets.token_hex(4)}.part")
    start = time.perf_counter()
    try:
        done = _run(
            [compiler, *flags, source.name, "-o", str(partial.absolute()), "-lm"],
            cwd=source.parent,
            timeout=limit,
            compiler=compiler,
        )
        if done.returncode != 0:
            raise CodegenError(
                f"the C compiler {compiler} failed (exit {done.returncode}) on {source}:\n" + done.stderr[-4000:]
            )
        try:
            os.replace(partial, output)
        except OSError as exc:
            raise CodegenError(f"cannot write the library {output}: {exc}") from exc
    finally:
        with contextlib.suppress(FileNotFoundError):
            partial.unlink()
    seconds = time.perf_counter() - start
    logger.debug("built %s with %s in %.2f s", output, compiler, seconds)
    return seconds


def _flags(flags: object) -> tuple[str, ...]:
    if not isinstance(flags, tuple | list) or not all(isinstance(flag, str) for flag in flags):
        raise SpecificationError(f"flags must be a tuple of strings, got {flags!r}")
    return tuple(flags)


# ======================================================================== the cache
def generate_code(function: ca.Function, *others: ca.Function) -> str:
    """The C source of ``function`` and ``others`` (and everything they call) as one string."""
    generator = ca.CodeGenerator(function.name() + ".c", _CODEGEN_OPTIONS)
    for each in (function, *others):
        generator.add(each)
    return generator.dump()


def compile_source(
    code: str,
    name: str,
    *,
    flags: tuple[str, ...] = DEFAULT_FLAGS,
    directory: str | os.PathLike[str] | None = None,
    timeout: float | None = None,
) -> Path:
    """Compile the C source ``code`` to a cached shared library and return its path.

    The same cache as `compile_function` (same hashing, validation and repair); load
    the library with `ctypes`.

    Parameters
    ----------
    code : str
        One C translation unit.
    name : str
        Stem of the library's file name (a C identifier, e.g. the main function's name).
    flags : tuple of str, keyword-only
        Compiler flags; default `DEFAULT_FLAGS`.
    directory : path-like, optional, keyword-only
        Cache directory; default `cache_dir`.
    timeout : float, optional, keyword-only
        Limit of the compiler call (s); default `compile_timeout`.

    Returns
    -------
    pathlib.Path
        The verified library ``<directory>/<name>_<hash>.so``.

    Raises
    ------
    SpecificationError
        If ``code`` is not a string or ``name`` not a C identifier.
    CodegenError
        If no compiler is found (there is no fallback for plain C), it fails or times out,
        or the cache directory cannot be written.
    """
    if not isinstance(code, str):
        raise SpecificationError(f"code must be C source as a str, got {type(code).__name__}")
    compiler = find_compiler()
    if compiler is None:
        raise CodegenError(f"no C compiler found ($CC, gcc, cc) to compile {name!r}: install gcc, or set CC")
    library, _ = _cached_library(code, name, compiler, flags, directory, timeout)
    return library


def compile_function(
    function: ca.Function,
    *,
    flags: tuple[str, ...] = DEFAULT_FLAGS,
    directory: str | os.PathLike[str] | None = None,
    appendix: str = "",
    timeout: float | None = None,
    others: tuple[ca.Function, ...] = (),
) -> CompiledFunction:
    """Compile ``function`` to a shared library (or reuse the cached one) and load it.

    Parameters
    ----------
    function : casadi.Function
        Any code-generatable CasADi Function (SX, or MX calling SX Functions).
    flags : tuple of str, keyword-only
        Compiler flags; the default is `DEFAULT_FLAGS`.
    directory : path-like, optional, keyword-only
        Cache directory; default `cache_dir`.
    appendix : str, keyword-only
        C source appended to the generated code (part of the hash), e.g. a driver loop
        that calls the generated function; load its exported symbols from
        `CompiledFunction.library` with ctypes.
    timeout : float, optional, keyword-only
        Limit of the compiler call (s); default `compile_timeout`.
    others : tuple of casadi.Function, keyword-only
        More Functions generated into the same library (for the ``appendix`` to call, under their names).

    Returns
    -------
    CompiledFunction
        The loaded Function. With no C compiler, the original Function for CasADi's
        virtual machine, and a [`CompilerWarning`][mrpctl.errors.CompilerWarning] is issued.

    Raises
    ------
    CodegenError
        If ``$CC`` names no compiler, the compiler fails or times out, or the library cannot be loaded.

    Warns
    -----
    CacheWarning
        When the cached library was truncated, corrupt or had no checksum (it is rebuilt).
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
    code = generate_code(function, *others) + appendix
    library, seconds = _cached_library(code, name, compiler, flags, directory, timeout)
    try:
        loaded = ca.external(name, str(library))
    except RuntimeError as exc:
        raise CodegenError(f"could not load the compiled library {library}: {exc}") from exc
    return CompiledFunction(function=loaded, compiled=True, library=library, compile_seconds=seconds)


def _cached_library(
    code: str,
    name: str,
    compiler: str,
    flags: tuple[str, ...],
    directory: str | os.PathLike[str] | None,
    timeout: float | None,
) -> tuple[Path, float]:
    """The verified cached library of ``code`` (built if missing or bad) and the seconds spent building."""
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise SpecificationError(f"name must be a C identifier (letters, digits, _), got {name!r}")
    flags = _flags(flags)
    limit = compile_timeout(timeout)
    identity = compiler + ("\n" + version if (version := _compiler_version(compiler, limit)) else "")
    key = "\n".join((code, identity, " ".join(flags), _CASADI_VERSION))
    digest = hashlib.sha256(key.encode()).hexdigest()[:20]
    folder = Path(directory) if directory is not None else cache_dir()
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise CodegenError(f"cannot create the cache directory {folder}: {exc}") from exc
    library = folder / f"{name}_{digest}.so"
    with _locked(folder / f"{name}_{digest}.lock"):
        problem = _verify(library)
        if problem is None:
            logger.debug("cache hit for %s: %s", name, library)
            return library, 0.0
        if problem:
            warnings.warn(
                f"the cached library {library} is unusable ({problem}); it was deleted and is being rebuilt",
                CacheWarning,
                stacklevel=3,
            )
        for stale in (library, _checksum_path(library)):
            try:
                stale.unlink(missing_ok=True)
            except OSError as exc:
                raise CodegenError(
                    f"cannot delete {stale} to rebuild it: {exc}; delete it by hand, or set MRPCTL_CACHE_DIR "
                    "to a writable folder"
                ) from exc
        _clean(folder)
        build = folder / f"build-{os.getpid()}-{secrets.token_hex(4)}"
        try:
            build.mkdir()
            source = build / f"{library.stem}.c"
            source.write_text(code)
            seconds = build_library(source, library, compiler=compiler, flags=flags, timeout=limit)
            _write_checksum(library, build)
        except OSError as exc:
            raise CodegenError(f"cannot build {library.name} in the cache directory {folder}: {exc}") from exc
        finally:
            shutil.rmtree(build, ignore_errors=True)
    logger.info("compiled %s in %.2f s -> %s", name, seconds, library)
    return library, seconds


@contextlib.contextmanager
def _locked(path: Path) -> Iterator[None]:
    """An exclusive ``flock`` on ``path`` (released by the kernel if the process dies).

    In a read-only cache no lock can be taken and none is needed to load a verified library
    (a build there fails with its own error)."""
    try:
        handle = os.open(path, os.O_RDWR | os.O_CREAT, 0o644) if fcntl is not None else -1
    except OSError as exc:
        logger.debug("no lock %s (%s): reading the cache without it", path, exc)
        handle = -1
    if handle < 0:
        yield
        return
    try:
        fcntl.flock(handle, fcntl.LOCK_EX)
        yield
    finally:
        os.close(handle)  # closing releases the lock


def _checksum_path(library: Path) -> Path:
    return library.with_name(library.name + _CHECKSUM_SUFFIX)


def _write_checksum(library: Path, build: Path) -> None:
    """Write ``<library>.sha256`` (size and SHA-256) atomically, after the library is in place."""
    record = {"library": library.name, "size": library.stat().st_size, "sha256": file_sha256(library)}
    partial = build / (library.name + _CHECKSUM_SUFFIX)
    partial.write_text(json.dumps(record) + "\n")
    os.replace(partial, _checksum_path(library))


def _verify(library: Path) -> str | None:
    """None if ``library`` matches its checksum file; "" if neither exists; else what is wrong."""
    checksum = _checksum_path(library)
    if not library.exists():
        return ""  # not built yet (a lone checksum file is removed before the build)
    try:
        record = json.loads(checksum.read_text())
        size, expected, named = int(record["size"]), str(record["sha256"]), str(record["library"])
    except FileNotFoundError:
        return f"no checksum file {checksum.name}"
    except (OSError, ValueError, TypeError, KeyError) as exc:
        return f"unreadable checksum file {checksum.name}: {exc}"
    if named != library.name:  # another library's checksum beside it (both swapped: each matches its own record)
        return f"its checksum file records the library {named}"
    try:
        found = library.stat().st_size
        if found != size:
            return f"{found} bytes where {size} were written: truncated or replaced"
        if file_sha256(library) != expected:
            return "its SHA-256 differs from the one recorded when it was built"
    except OSError as exc:
        return f"cannot be read: {exc}"
    return None


# ==================================================================== stale leftovers
def _pid_alive(pid: int) -> bool:
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's live process
        return True
    except OSError:
        return True
    return True


def abandoned(path: Path, pid: int | None, *, now: float | None = None) -> bool:
    """True if ``path``, written by process ``pid`` (None: unknown), is a leftover.

    A leftover's writer is dead, or it is older than `STALE_SECONDS` (a day: the pid
    may have been reused, or belong to another machine sharing the folder).
    """
    try:
        age = (time.time() if now is None else now) - path.lstat().st_mtime
    except OSError:
        return False
    if age > STALE_SECONDS:
        return True
    return pid is not None and not _pid_alive(pid)


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        with contextlib.suppress(OSError):
            path.unlink()
    logger.info("removed the leftover %s", path)


def _clean(folder: Path) -> None:
    """Remove ``.part`` files and build folders of dead processes (or older than a day)."""
    try:
        entries = list(folder.iterdir())
    except OSError:
        return
    for entry in entries:
        if not (entry.name.endswith(".part") or entry.name.startswith("build-")):
            continue
        match = _PID_TAG.search(entry.name)
        if abandoned(entry, int(match.group(1)) if match else None):
            _remove(entry)
    # Build folders of mrpctl versions that compiled in the temporary directory.
    with contextlib.suppress(OSError):
        for entry in Path(tempfile.gettempdir()).glob("mrpctl-build-*"):
            if entry.is_dir() and entry.lstat().st_uid == os.getuid() and abandoned(entry, None):
                _remove(entry)


# ========================================================================= ctypes help
def address(array: np.ndarray) -> int:
    """The address of a contiguous NumPy array's data (to pass as a pointer through ctypes)."""
    return int(array.__array_interface__["data"][0])
