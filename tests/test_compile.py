"""The C compilation cache: hashing, reuse, atomic writes, errors and the VM fallback."""

from __future__ import annotations

import threading
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from mrpctl import _compile, paper, simulate, simulate_batch
from mrpctl._compile import CompilerWarning, cache_dir, compile_function, generate_code
from mrpctl.errors import CodegenError
from mrpctl.simulation._engine import clear_engines
from mrpctl.switching import OnDelayed


def _function(scale: float = 2.0) -> ca.Function:
    x = ca.SX.sym("x", 3)
    y = ca.SX.sym("y", 2, 2)
    return ca.Function("toy", [x, y], [scale * ca.sin(x), y @ y, ca.sum1(x)], ["x", "y"], ["s", "yy", "total"])


def test_compile_once_then_reuse(tmp_path: Path) -> None:
    function = _function()
    first = compile_function(function, directory=tmp_path)
    assert first.compiled and first.compile_seconds > 0 and first.library.exists()
    second = compile_function(function, directory=tmp_path)
    assert second.library == first.library and second.compile_seconds == 0.0
    x, y = np.array([0.1, -0.2, 0.3]), np.array([[1.0, 2.0], [3.0, 4.0]])
    for got, want in zip(second.function(x, y), function(x, y), strict=True):
        np.testing.assert_array_equal(np.asarray(got), np.asarray(want))
    other = compile_function(_function(3.0), directory=tmp_path)
    assert other.library != first.library
    assert not list(tmp_path.glob("*.part"))
    assert "from cache" in str(second)


def test_direct_call_writes_into_numpy_buffers(tmp_path: Path) -> None:
    function = _function()
    direct = compile_function(function, directory=tmp_path).direct()
    assert (direct.n_in, direct.n_out) == (2, 3)
    x = np.array([0.1, -0.2, 0.3])
    y = np.array([[1.0, 2.0], [3.0, 4.0]])
    s, yy = np.empty(3), np.empty((2, 2))
    direct([x, np.ascontiguousarray(y.T)], [s, yy, None])  # column-major in, total not written
    np.testing.assert_array_equal(s, 2.0 * np.sin(x))
    np.testing.assert_allclose(yy.T, y @ y, rtol=1e-15)


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
    assert not fallback.compiled and fallback.direct() is None and fallback.function is function
    assert not list(tmp_path.iterdir())


def test_simulation_in_the_virtual_machine_matches_compiled(monkeypatch: pytest.MonkeyPatch) -> None:
    arguments = dict(tau=0.02, rule=OnDelayed(), t_final=0.9, substeps=2)  # the structure of test_simulate
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
    np.testing.assert_array_equal(batch.runs[0].switch_indices, compiled.switch_indices)
    np.testing.assert_allclose(batch.runs[0].sigma, compiled.sigma, rtol=0, atol=1e-13)
