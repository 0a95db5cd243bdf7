"""mrpctl.export of the loop as flown with a per-sample disturbance torque (issue 10).

The exported ``sample`` and ``chunk`` take w_k as an input ``torque`` (named in the manifest);
loaded back from the ``.casadi`` files and through the compiled library they reproduce
:func:`mrpctl.simulate` with the same per-sample torque bit for bit.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
import pytest

from mrpctl import closed_loop_functions, paper, simulate
from mrpctl._compile import find_compiler
from mrpctl._export import C_PREFIX, FLIGHT_EXPORTED_FUNCTIONS, MANIFEST_NAME, export
from mrpctl.flight import ActuatorModel, Disturbance, Hysteretic, SensorModel

needs_compiler = pytest.mark.skipif(find_compiler() is None, reason="no C compiler on this machine")

RATE, T_FINAL = 1000.0, 1.2
N = 1201
D = 500
TIMES = np.arange(N) / RATE


def _gust(t: np.ndarray) -> np.ndarray:
    return np.stack((2.0 * np.sin(5.0 * t), -1.5 * np.cos(3.0 * t), 0.5 * t), axis=1)


CASE: dict[str, Any] = dict(
    tau=paper.TAU,
    rate=RATE,
    rule=Hysteretic(0.0),
    actuator=ActuatorModel(u_max=[60.0, 50.0, 40.0], norm_max=70.0),
    sensor=SensorModel(attitude_noise=0.01, rate_noise=1e-4, gyro_bias=[1e-4, 0.0, -2e-4], seed=3),
)
ROWS = _gust(TIMES)


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> Any:
    return export(paper.SPACECRAFT, paper.GAIN, tmp_path_factory.mktemp("torque") / "rows", disturbance=ROWS, **CASE)


@pytest.fixture(scope="module")
def reference() -> Any:
    return simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, t_final=T_FINAL, disturbance=ROWS, **CASE)


def _functions(result: Any, source: str) -> dict[str, ca.Function]:
    if source == "casadi":
        return {name: ca.Function.load(str(result.folder / f"{name}.casadi")) for name in FLIGHT_EXPORTED_FUNCTIONS}
    return {name: ca.external(C_PREFIX + name, str(result.library)) for name in FLIGHT_EXPORTED_FUNCTIONS}


def _noise() -> np.ndarray:
    rotation, rate = CASE["sensor"].noise(0, N + D)
    return np.hstack((rotation, rate))


def _memory0() -> np.ndarray:
    closed = closed_loop_functions(paper.SPACECRAFT, paper.GAIN, disturbance=ROWS, **CASE)
    assert closed.flight is not None
    return closed.flight.initial_memory(paper.INITIAL_STATE, D)


def _sample_loop(sample: ca.Function) -> tuple[np.ndarray, np.ndarray, list[int]]:
    x = np.asarray(paper.INITIAL_STATE, dtype=float)
    memory = _memory0()
    ring = [x.copy() for _ in range(D)]
    noise = _noise()
    states, torques, switches = [], [], []
    for k in range(N):
        x_next, memory, x_meas, u, switched, measurement = (
            np.asarray(value).ravel() for value in sample(x, memory, ring[k % D], noise[k], ROWS[k])
        )
        ring[k % D] = measurement
        states.append(x_meas)
        torques.append(u)
        if switched[0] > 0:
            switches.append(k)
        x = x_next
    return np.array(states), np.array(torques), switches


def _chunk_loop(chunk: ca.Function) -> tuple[np.ndarray, np.ndarray, list[int]]:
    x = np.asarray(paper.INITIAL_STATE, dtype=float)
    memory = _memory0()
    history = np.tile(x[:, None], (1, D))
    noise = _noise().T
    torque = np.vstack((ROWS, np.zeros((D, 3)))).T  # the last chunk runs past n: any torque there
    states, torques, flags = [], [], []
    for start in range(0, N, D):
        x, memory, chunk_states, measurements, u, switched = (
            np.asarray(value)
            for value in chunk(x, memory, history, noise[:, start : start + D], torque[:, start : start + D])
        )
        history = measurements
        states.append(chunk_states)
        torques.append(u)
        flags.append(switched)
    return np.hstack(states)[:, :N].T, np.hstack(torques)[:, :N].T, np.flatnonzero(np.hstack(flags)[0, :N] > 0).tolist()


def _check(reference: Any, states: np.ndarray, torques: np.ndarray, switches: list[int]) -> None:
    assert np.array_equal(states[:, 0:3], reference.sigma)
    assert np.array_equal(4.0 * states[:, 3:6], reference.omega)
    assert np.array_equal(torques, reference.u)
    assert switches == reference.switch_indices.tolist()


def test_the_torque_changes_the_run(reference: Any) -> None:
    constant = simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, t_final=T_FINAL, **CASE)
    assert np.max(np.abs(reference.sigma - constant.sigma)) > 1e-6
    assert reference.switch_count >= 10 and 0.0 < reference.saturated_fraction < 1.0


@pytest.mark.parametrize("source", ["casadi", pytest.param("library", marks=needs_compiler)])
def test_exported_sample_and_chunk_with_a_torque_input_reproduce_simulate(
    exported: Any, reference: Any, source: str
) -> None:
    functions = _functions(exported, source)
    assert functions["sample"].name_in()[-1] == "torque" and functions["chunk"].name_in()[-1] == "torque"
    assert functions["chunk"].size_in(4) == (3, D)
    _check(reference, *_sample_loop(functions["sample"]))
    _check(reference, *_chunk_loop(functions["chunk"]))


def test_the_manifest_names_the_torque_input(exported: Any) -> None:
    manifest = json.loads((exported.folder / MANIFEST_NAME).read_text())
    disturbance = manifest["flight"]["disturbance"]
    assert disturbance["per_sample"] is True and disturbance["input"] == "torque" and disturbance["samples"] == N
    assert manifest["flight"]["constants"]["disturbance"] == [0.0, 0.0, 0.0]  # w is not bound in
    ports = [port["name"] for port in manifest["functions"]["sample"]["inputs"]]
    assert ports[-1] == "torque" and "torque" in manifest["functions"]["sample"]["description"]


def test_a_function_of_time_exports_the_same_functions(tmp_path: Path, exported: Any) -> None:
    function = export(
        paper.SPACECRAFT,
        paper.GAIN,
        tmp_path / "function",
        disturbance=Disturbance(function=_gust),
        compile=False,
        **CASE,
    )
    manifest = function.manifest["flight"]["disturbance"]
    assert manifest["samples"] is None and manifest["function"] == "_gust"
    for name in ("sample", "chunk"):
        assert (tmp_path / "function" / f"{name}.casadi").read_bytes() == (
            exported.folder / f"{name}.casadi"
        ).read_bytes()
