"""The C compilation cache: reuse, atomic writes, validation and repair, leftovers, timeout, CC, VM fallback."""

from __future__ import annotations

import contextlib
import ctypes
import hashlib
import json
import os
import signal
import subprocess
import sys
import tempfile
import textwrap
import threading
import time
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
import pytest

from mrpctl import _compile, paper, simulate, simulate_batch
from mrpctl._compile import (
    TIMEOUT_VARIABLE,
    CompilerWarning,
    cache_dir,
    compile_function,
    compile_source,
    compile_timeout,
    find_compiler,
    generate_code,
)
from mrpctl.engines.scalar import clear_engines
from mrpctl.errors import CacheWarning, CodegenError, SpecificationError
from mrpctl.switching import OnDelayed


def _function(scale: float = 2.0) -> ca.Function:
    x = ca.SX.sym("x", 3)
    y = ca.SX.sym("y", 2, 2)
    return ca.Function("toy", [x, y], [scale * ca.sin(x), y @ y, ca.sum1(x)], ["x", "y"], ["s", "yy", "total"])


def test_compile_once_then_reuse(tmp_path: Path) -> None:
    function = _function()
    first = compile_function(function, directory=tmp_path)
    assert first.compiled and first.compile_seconds > 0 and first.library is not None and first.library.exists()
    second = compile_function(function, directory=tmp_path)
    assert second.library == first.library and second.compile_seconds == 0.0
    x, y = np.array([0.1, -0.2, 0.3]), np.array([[1.0, 2.0], [3.0, 4.0]])
    for got, want in zip(second.function(x, y), function(x, y), strict=True):
        np.testing.assert_array_equal(np.asarray(got), np.asarray(want))
    other = compile_function(_function(3.0), directory=tmp_path)
    assert other.library != first.library
    assert not list(tmp_path.glob("*.part"))
    assert "from cache" in str(second)


def test_generated_code_is_deterministic() -> None:
    assert generate_code(_function()) == generate_code(_function())


def test_cache_dir_from_environment(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("MRPCTL_CACHE_DIR", str(tmp_path / "c"))
    assert cache_dir() == tmp_path / "c"
    monkeypatch.delenv("MRPCTL_CACHE_DIR")
    assert cache_dir() == Path.home() / ".cache" / "mrpctl"


def test_parallel_compiles_of_the_same_code_do_not_race(tmp_path: Path) -> None:
    function = _function(5.0)
    results, errors = [], []

    def work() -> None:
        try:
            results.append(compile_function(function, directory=tmp_path))
        except Exception as exc:  # pragma: no cover - reported below
            errors.append(exc)

    threads = [threading.Thread(target=work) for _ in range(3)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert not errors
    assert len({result.library for result in results}) == 1
    assert len(list(tmp_path.glob("*.so"))) == 1 and not list(tmp_path.glob("*.part"))


def test_compiler_failure_is_a_codegen_error(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("CC", "false")
    with pytest.raises(CodegenError, match="failed"):
        compile_function(_function(7.0), directory=tmp_path)


def test_no_compiler_falls_back_to_the_virtual_machine(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    function = _function()
    monkeypatch.setattr(_compile, "find_compiler", lambda: None)
    with pytest.warns(CompilerWarning, match="virtual machine"):
        fallback = compile_function(function, directory=tmp_path)
    assert not fallback.compiled and fallback.library is None and fallback.function is function
    assert not list(tmp_path.iterdir())


def test_simulation_in_the_virtual_machine_matches_compiled(monkeypatch: pytest.MonkeyPatch) -> None:
    # The structure of test_simulate.
    arguments: dict[str, Any] = dict(tau=0.02, rule=OnDelayed(), t_final=0.9, substeps=2)
    x0 = np.array([0.98, 0.05, 0.0, 0.12, 0.01, 0.0])
    compiled = simulate(paper.SPACECRAFT, paper.GAIN, x0, **arguments)
    compiled_batch = simulate_batch(paper.SPACECRAFT, paper.GAIN, [x0, -x0], **arguments)
    clear_engines()
    try:
        monkeypatch.setattr(_compile, "find_compiler", lambda: None)
        with pytest.warns(CompilerWarning):
            interpreted = simulate(paper.SPACECRAFT, paper.GAIN, x0, **arguments)
            batch = simulate_batch(paper.SPACECRAFT, paper.GAIN, [x0, -x0], trajectories=True, **arguments)
    finally:
        clear_engines()
    assert compiled.switch_count > 0
    np.testing.assert_array_equal(interpreted.switch_indices, compiled.switch_indices)
    np.testing.assert_allclose(interpreted.sigma, compiled.sigma, rtol=0, atol=1e-13)
    np.testing.assert_array_equal(interpreted.sign_flips, compiled.sign_flips)
    np.testing.assert_array_equal(batch.switch_count, compiled_batch.switch_count)
    assert batch.runs is not None
    np.testing.assert_array_equal(batch.runs[0].switch_indices, compiled.switch_indices)
    np.testing.assert_allclose(batch.runs[0].sigma, compiled.sigma, rtol=0, atol=1e-13)


# ====================================================== validation and repair of the cache
def _checksum_matches(library: Path) -> bool:
    record = json.loads(library.with_name(library.name + ".sha256").read_text())
    data = library.read_bytes()
    return record["size"] == len(data) and record["sha256"] == hashlib.sha256(data).hexdigest()


def _plant(function: ca.Function, folder: Path) -> Path:
    """Build the library compile_function would load, without loading it into this process."""
    library = compile_source(generate_code(function), function.name(), directory=folder)
    assert _checksum_matches(library)
    return library


_CHILD = textwrap.dedent(
    """
    import sys, warnings
    import casadi as ca, numpy as np
    from mrpctl._compile import compile_function
    x = ca.SX.sym("x", 3)
    y = ca.SX.sym("y", 2, 2)
    f = ca.Function("toy", [x, y], [SCALE * ca.sin(x), y @ y, ca.sum1(x)], ["x", "y"], ["s", "yy", "total"])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        compiled = compile_function(f, directory=sys.argv[1])
    print(repr(float(compiled.function(np.array([0.1, -0.2, 0.4]), np.eye(2))[2])))
    print(str(compiled.library))
    for warning in caught:
        print(warning.category.__name__, str(warning.message).replace(chr(10), " "))
    """
)


def test_truncated_library_is_rebuilt_instead_of_crashing(tmp_path: Path) -> None:
    # On main, loading the truncated library killed the interpreter with SIGBUS: run it in a child.
    library = _plant(_function(13.0), tmp_path)
    data = library.read_bytes()
    library.write_bytes(data[: len(data) // 2])
    child = subprocess.run(
        [sys.executable, "-c", _CHILD.replace("SCALE", "13.0"), str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "CC": ""},
    )
    assert child.returncode == 0, (child.returncode, child.stderr[-2000:])
    total, path, *warned = child.stdout.splitlines()
    assert float(total) == 0.1 + -0.2 + 0.4  # the same sum, in CasADi's order (left to right)
    assert Path(path) == library and library.read_bytes() == data  # rebuilt, same bytes as before
    assert len(warned) == 1 and warned[0].startswith("CacheWarning") and "truncated" in warned[0]
    assert _checksum_matches(library)


def test_garbage_library_is_rebuilt_with_a_warning(tmp_path: Path, rng: np.random.Generator) -> None:
    function = _function(17.0)
    library = _plant(function, tmp_path)
    size = library.stat().st_size
    library.write_bytes(rng.integers(0, 256, size=size, dtype=np.uint8).tobytes())  # same size, wrong bytes
    with pytest.warns(CacheWarning, match="SHA-256 differs"):
        compiled = compile_function(function, directory=tmp_path)
    assert compiled.library == library and compiled.compile_seconds > 0 and _checksum_matches(library)
    x = np.array([0.3, 0.2, -0.1])
    np.testing.assert_array_equal(np.asarray(compiled.function(x, np.eye(2))[0]).ravel(), 17.0 * np.sin(x))


def test_library_without_checksum_is_rebuilt(tmp_path: Path) -> None:
    function = _function(19.0)
    library = _plant(function, tmp_path)
    library.with_name(library.name + ".sha256").unlink()
    with pytest.warns(CacheWarning, match="no checksum file"):
        compiled = compile_function(function, directory=tmp_path)
    assert compiled.compile_seconds > 0 and _checksum_matches(library)
    again = compile_function(function, directory=tmp_path)  # verified: a hit, no warning
    assert again.compile_seconds == 0.0


def test_two_libraries_swapped_with_their_checksum_files_are_rebuilt(tmp_path: Path) -> None:
    """A second audit: each swapped library matched the checksum file swapped with it, so the wrong code loaded
    (for ever); the checksum file also names its library."""
    first, second = _function(23.0), _function(29.0)
    one, two = _plant(first, tmp_path), _plant(second, tmp_path)
    assert one != two
    for suffix in ("", ".sha256"):
        a, b = one.with_name(one.name + suffix), two.with_name(two.name + suffix)
        data = a.read_bytes()
        a.write_bytes(b.read_bytes())
        b.write_bytes(data)
    with pytest.warns(CacheWarning, match="records the library"):
        compiled = compile_function(first, directory=tmp_path)
    assert compiled.library == one and compiled.compile_seconds > 0 and _checksum_matches(one)
    x = np.array([0.3, 0.2, -0.1])
    np.testing.assert_array_equal(np.asarray(compiled.function(x, np.eye(2))[0]).ravel(), 23.0 * np.sin(x))


def test_compile_source_builds_plain_c_in_the_same_cache(tmp_path: Path) -> None:
    code = "double mrpctl_axpy(double a, double x, double y) { return a * x + y; }\n"
    library = compile_source(code, "axpy", directory=tmp_path)
    assert library.parent == tmp_path and library.name.startswith("axpy_") and _checksum_matches(library)
    assert compile_source(code, "axpy", directory=tmp_path) == library
    axpy = ctypes.CDLL(str(library)).mrpctl_axpy
    axpy.restype, axpy.argtypes = ctypes.c_double, [ctypes.c_double] * 3
    assert axpy(0.1, 3.0, 0.7) == 0.1 * 3.0 + 0.7
    with pytest.raises(SpecificationError, match="name must be a C identifier"):
        compile_source(code, "../evil", directory=tmp_path)
    with pytest.raises(SpecificationError, match="code must be C source"):
        compile_source(b"int x;", "bytes", directory=tmp_path)  # type: ignore[arg-type]


# ============================================================================ leftovers
def _dead_pid() -> int:
    done = subprocess.Popen([sys.executable, "-c", "pass"])
    done.wait()
    return done.pid


def test_leftovers_of_killed_builds_are_removed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    cache, temporary = tmp_path / "cache", tmp_path / "tmp"
    cache.mkdir()
    temporary.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temporary))
    dead, alive, old = _dead_pid(), os.getpid(), time.time() - 2 * 86400

    def plant(folder: Path, name: str, age: float | None = None, directory: bool = False) -> Path:
        path = folder / name
        if directory:
            path.mkdir()
            (path / "toy.c").write_text("int x;")
        else:
            path.write_bytes(b"half a library")
        if age is not None:
            os.utime(path, (age, age))
        return path

    removed = [
        plant(cache, f"build-{dead}-0a1b2c3d", directory=True),
        plant(cache, f"toy_0123.so.{dead}-0a1b2c3d.part"),
        plant(cache, f"build-{alive}-beef0001", age=old, directory=True),  # alive pid but a day old
        plant(cache, "toy_0123.k2j3h4.so.part", age=old),  # older mrpctl: no pid in the name
        plant(temporary, "mrpctl-build-x8y7z6", age=old, directory=True),  # older mrpctl: in /tmp
    ]
    kept = [
        plant(cache, f"build-{alive}-beef0002", directory=True),  # another thread building now
        plant(cache, f"toy_4567.so.{alive}-beef0003.part"),
        plant(cache, "toy_4567.m5n6b7.so.part"),  # no pid, recent: may be in use
        plant(temporary, "mrpctl-build-q1w2e3", directory=True),
        plant(cache, "notes.txt"),
    ]
    compile_function(_function(23.0), directory=cache)
    assert [path for path in removed if path.exists()] == []
    assert [path for path in kept if not path.exists()] == []


def test_a_compile_killed_by_sigterm_is_cleaned_up_by_the_next(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    cache, started = tmp_path / "cache", tmp_path / "started"
    hanging = _script(
        tmp_path / "hanging_cc",
        f"""\
        if [ "$1" = "--version" ]; then echo "hanging-cc 1.0"; exit 0; fi
        echo $$ > {started}.tmp && mv {started}.tmp {started}
        exec sleep 120
        """,
    )
    code = "from mrpctl._compile import compile_source; compile_source('int answer = 42;', 'killed', directory=DIR)"
    child = subprocess.Popen(
        [sys.executable, "-c", code.replace("DIR", repr(str(cache)))], env={**os.environ, "CC": str(hanging)}
    )
    try:
        for _ in range(1200):  # the child is compiling once the fake compiler has started (at most 60 s)
            if started.exists() or child.poll() is not None:
                break
            time.sleep(0.05)
        assert started.exists(), "the fake compiler never started"
        child.send_signal(signal.SIGTERM)
        assert child.wait(timeout=60) == -signal.SIGTERM
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
        if started.exists():  # the fake compiler runs in its own session: end it
            with contextlib.suppress(ProcessLookupError):
                os.killpg(int(started.read_text()), signal.SIGKILL)
    left = [path.name for path in cache.iterdir() if path.name.startswith("build-")]
    assert left == [f"build-{child.pid}-" + left[0].rsplit("-", 1)[1]]  # what SIGTERM left behind
    monkeypatch.delenv("CC", raising=False)
    library = compile_source("int answer = 42;", "killed", directory=cache)
    assert ctypes.c_int.in_dll(ctypes.CDLL(str(library)), "answer").value == 42
    assert not [path for path in cache.iterdir() if path.name.startswith("build-") or path.name.endswith(".part")]


# ================================================================== timeout and $CC
def _script(path: Path, body: str) -> Path:
    path.write_text("#!/bin/sh\n" + textwrap.dedent(body))
    path.chmod(0o755)
    return path


def _gone(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0] in ("Z", "X")
    except FileNotFoundError:
        return True


@pytest.mark.parametrize("how", ["keyword", "environment"])
def test_hanging_compiler_is_killed_after_the_timeout(
    how: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    pids = tmp_path / "pids"
    hanging = _script(
        tmp_path / "hanging_cc",
        f"""\
        if [ "$1" = "--version" ]; then echo "hanging-cc 1.0"; exit 0; fi
        sleep 120 &
        echo $! >> {pids}
        wait
        """,
    )
    monkeypatch.setenv("CC", str(hanging))
    cache = tmp_path / "cache"
    if how == "keyword":
        context = pytest.raises(CodegenError, match=r"hanging_cc did not finish within the timeout of 0.8 s")
        with context:
            compile_function(_function(29.0), directory=cache, timeout=0.8)
    else:
        monkeypatch.setenv(TIMEOUT_VARIABLE, "0.8")
        with pytest.raises(CodegenError, match=rf"timeout of 0.8 s.*{TIMEOUT_VARIABLE}"):
            compile_function(_function(29.0), directory=cache)
    (pid,) = (int(line) for line in pids.read_text().split())
    assert _gone(pid)  # the compiler's children are killed too (its whole process group)
    assert sorted(path.name for path in cache.iterdir() if not path.name.endswith(".lock")) == []


@pytest.mark.parametrize("value", ["abc", "0", "-5", "nan", "inf"])
def test_timeout_variable_is_checked(value: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(TIMEOUT_VARIABLE, value)
    with pytest.raises(SpecificationError, match=rf"{TIMEOUT_VARIABLE} must be a positive number of seconds"):
        compile_timeout()
    with pytest.raises(SpecificationError, match="timeout"):
        compile_timeout(-1.0)
    assert compile_timeout(2.5) == 2.5


def test_cc_that_does_not_exist_is_refused(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("CC", "/nonexistent/mrpctl-cc")
    with pytest.raises(CodegenError, match=r"CC='/nonexistent/mrpctl-cc' names no executable.*unset CC"):
        compile_function(_function(31.0), directory=tmp_path)
    monkeypatch.setenv("CC", "")  # empty means unset
    assert find_compiler() is not None


def test_cc_is_the_compiler_used(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    gcc = find_compiler()
    log = tmp_path / "calls"
    wrapper = _script(tmp_path / "logging_cc", f'echo "$@" >> {log}\nexec {gcc} "$@"\n')
    monkeypatch.setenv("CC", str(wrapper))
    compiled = compile_function(_function(37.0), directory=tmp_path / "cache")
    assert compiled.compiled
    calls = log.read_text().splitlines()
    assert calls[0] == "--version" and calls[1].startswith("-O2 -shared -fPIC toy_") and calls[1].endswith(" -lm")
