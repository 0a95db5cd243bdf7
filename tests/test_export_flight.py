"""mrpctl.export of the loop as flown (rule Hysteretic with actuator, disturbance, sensor, delay).

The exported Functions, loaded back from the ``.casadi`` files and through the compiled
library, run the same flight loop as :func:`mrpctl.simulate` and must give its numbers
bit for bit; the manifest lists the flight models and the memory layout; an export with
flight options is as atomic as the others.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from mrpctl import _export as export_module
from mrpctl import closed_loop_functions, paper, simulate
from mrpctl._compile import find_compiler
from mrpctl._export import C_PREFIX, FLIGHT_EXPORTED_FUNCTIONS, HEADER_NAME, LIBRARY_NAME, MANIFEST_NAME, export
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.flight import ActuatorModel, DelayModel, Disturbance, Hysteretic, Saturation, SensorModel
from mrpctl.loop import FLIGHT_MEMORY_LAYOUT
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import OnDelayed

HAS_COMPILER = find_compiler() is not None
needs_compiler = pytest.mark.skipif(not HAS_COMPILER, reason="no C compiler on this machine")

T_FINAL = 1.2
# The paper's case flown: no hysteresis and 0.01 rad attitude noise, so that the controller's set
# selection switches several times near Phi = 180 deg; a torque limit that acts from the start,
# a disturbance and a gyro bias.
PAPER_FLIGHT = dict(
    spacecraft=paper.SPACECRAFT,
    K=paper.GAIN,
    x0=paper.INITIAL_STATE,
    tau=paper.TAU,
    rate=1000.0,
    rule=Hysteretic(0.0),
    actuator=ActuatorModel(u_max=[60.0, 50.0, 40.0], norm_max=70.0),
    disturbance=Disturbance([1e-3, -2e-3, 5e-4]),
    sensor=SensorModel(attitude_noise=0.01, rate_noise=1e-4, gyro_bias=[1e-4, 0.0, -2e-4], seed=3),
)
# A second case: full inertia, a fast tumble through Phi = 180 deg, CLIP saturation, hysteresis,
# two RK4 substeps, no sensor model.
OTHER_FLIGHT = dict(
    spacecraft=Spacecraft([[12.0, 0.5, -0.3], [0.5, 9.0, 0.2], [-0.3, 0.2, 7.0]]),
    K=np.hstack((-0.2 * np.eye(3) + 0.01, -0.6 * np.eye(3))),
    x0=np.array([0.6, -0.3, 0.2, 0.5, 0.3, -0.2]),
    tau=0.02,
    rate=200.0,
    substeps=2,
    rule=Hysteretic(0.05),
    actuator=ActuatorModel(u_max=0.3, mode=Saturation.CLIP),
)


def _loop_args(case: dict) -> dict:
    return {key: value for key, value in case.items() if key not in ("spacecraft", "K", "x0")}


def _export(folder: Path, case: dict, **options):
    return export(case["spacecraft"], case["K"], folder, **_loop_args(case), **options)


def _simulate(case: dict):
    return simulate(case["spacecraft"], case["K"], case["x0"], t_final=T_FINAL, **_loop_args(case))


def _noise(case: dict, n: int) -> np.ndarray:
    sensor = case.get("sensor")
    if sensor is None:
        return np.zeros((n, 6))
    rotation, rate = sensor.noise(0, n)
    return np.hstack((rotation, rate))


@pytest.fixture(scope="module")
def paper_flight(tmp_path_factory):
    return _export(tmp_path_factory.mktemp("flight") / "paper", PAPER_FLIGHT)


@pytest.fixture(scope="module")
def other_flight(tmp_path_factory):
    return _export(tmp_path_factory.mktemp("flight") / "other", OTHER_FLIGHT)


@pytest.fixture(scope="module")
def references():
    return {"paper": _simulate(PAPER_FLIGHT), "other": _simulate(OTHER_FLIGHT)}


CASES = {"paper": ("paper_flight", PAPER_FLIGHT), "other": ("other_flight", OTHER_FLIGHT)}


def _functions(result, source: str) -> dict[str, ca.Function]:
    if source == "casadi":
        return {name: ca.Function.load(str(result.folder / f"{name}.casadi")) for name in FLIGHT_EXPORTED_FUNCTIONS}
    return {name: ca.external(C_PREFIX + name, str(result.library)) for name in FLIGHT_EXPORTED_FUNCTIONS}


def _sample_loop(sample: ca.Function, case: dict, n: int, memory0: np.ndarray):
    """Run n samples with the exported ``sample`` alone and a ring of the d past measurements."""
    d = round(case["tau"] * case["rate"])
    x = np.asarray(case["x0"], dtype=float)
    memory = memory0
    ring = [x.copy() for _ in range(d)]  # the constant history m_{-d..-1} = x0
    noise = _noise(case, n)
    states, torques, switches = [], [], []
    for k in range(n):
        delayed = ring[k % d] if d > 0 else np.zeros(6)
        x_next, memory, x_meas, u, switched, measurement = (
            np.asarray(value).ravel() for value in sample(x, memory, delayed, noise[k])
        )
        if d > 0:
            ring[k % d] = measurement
        states.append(x_meas)
        torques.append(u)
        if switched[0] > 0:
            switches.append(k)
        x = x_next
    return np.array(states), np.array(torques), switches, memory


def _chunk_loop(chunk: ca.Function, case: dict, n: int, memory0: np.ndarray):
    d = round(case["tau"] * case["rate"])
    length = max(d, 1)
    x = np.asarray(case["x0"], dtype=float)
    memory = memory0
    history = np.tile(x[:, None], (1, length))
    noise = _noise(case, n + length).T
    states, torques, flags = [], [], []
    for start in range(0, n, length):
        x, memory, chunk_states, measurements, u, switched = (
            np.asarray(value) for value in chunk(x, memory, history, noise[:, start : start + length])
        )
        history = measurements
        states.append(chunk_states)
        torques.append(u)
        flags.append(switched)
    states, torques = np.hstack(states)[:, :n].T, np.hstack(torques)[:, :n].T
    return states, torques, np.flatnonzero(np.hstack(flags)[0, :n] > 0).tolist()


def _controller_loop(functions: dict[str, ca.Function], case: dict, n: int, memory0: np.ndarray):
    """The loop of a flight computer: sensor, the delay line, flight_controller, the plant's step with u + w."""
    d = round(case["tau"] * case["rate"])
    x = np.asarray(case["x0"], dtype=float)
    memory = memory0[0:5]
    delta = case["rule"].delta
    w = np.zeros(3) if case.get("disturbance") is None else case["disturbance"].torque
    ring = [x.copy() for _ in range(d)]
    noise = _noise(case, n)
    states, torques, commands, switches = [], [], [], []
    for k in range(n):
        x_true, measurement = (np.asarray(v).ravel() for v in functions["sensor"](x, noise[k]))
        delayed = ring[k % d] if d > 0 else measurement
        u, command, memory, switched = (
            np.asarray(v).ravel() for v in functions["flight_controller"](delayed, memory, delta)
        )
        if d > 0:
            ring[k % d] = measurement
        states.append(x_true)
        torques.append(u)
        commands.append(command)
        if switched[0] > 0:
            switches.append(k)
        x = np.asarray(functions["step"](x_true, u + w)).ravel()
    return np.array(states), np.array(torques), switches, np.array(commands)


def _memory0(case: dict) -> np.ndarray:
    closed = closed_loop_functions(case["spacecraft"], case["K"], **_loop_args(case))
    d = round(case["tau"] * case["rate"])
    return closed.flight.initial_memory(case["x0"], d)


def _check_equal(reference, states, torques, switches) -> None:
    assert np.array_equal(states[:, 0:3], reference.sigma)
    assert np.array_equal(4.0 * states[:, 3:6], reference.omega)
    assert np.array_equal(torques, reference.u)
    assert switches == reference.switch_indices.tolist()


# ======================================================================= the runs, bit for bit
def test_the_reference_runs_exercise_the_flight_loop(references):
    """Both runs switch the controller's set several times and saturate: the comparisons cover the logic."""
    assert references["paper"].switch_count >= 10 and references["other"].switch_count >= 1
    for run in references.values():
        assert 0.0 < run.saturated_fraction < 1.0
    assert np.max(np.abs(references["paper"].u)) <= 60.0


@pytest.mark.parametrize("source", ["casadi", pytest.param("library", marks=needs_compiler)])
@pytest.mark.parametrize("case_name", list(CASES))
def test_exported_sample_and_chunk_reproduce_simulate_bit_for_bit(case_name, source, request, references):
    fixture, case = CASES[case_name]
    functions = _functions(request.getfixturevalue(fixture), source)
    reference = references[case_name]
    n = len(reference.t)
    memory0 = _memory0(case)
    states, torques, switches, memory = _sample_loop(functions["sample"], case, n, memory0)
    _check_equal(reference, states, torques, switches)
    assert memory[5] / n == pytest.approx(reference.saturated_fraction, rel=0, abs=0)
    assert np.array_equal(memory[6:10], reference.peak_command)
    _check_equal(reference, *_chunk_loop(functions["chunk"], case, n, memory0))


@pytest.mark.parametrize("source", ["casadi", pytest.param("library", marks=needs_compiler)])
@pytest.mark.parametrize("case_name", list(CASES))
def test_flight_controller_sensor_and_step_reproduce_simulate_bit_for_bit(case_name, source, request, references):
    fixture, case = CASES[case_name]
    functions = _functions(request.getfixturevalue(fixture), source)
    reference = references[case_name]
    states, torques, switches, commands = _controller_loop(functions, case, len(reference.t), _memory0(case))
    _check_equal(reference, states, torques, switches)
    peak = np.concatenate((np.max(np.abs(commands), axis=0), [np.max(np.linalg.norm(commands, axis=1))]))
    assert np.allclose(peak, reference.peak_command, rtol=1e-15, atol=0)
    limits = case["actuator"].u_max
    assert np.all(np.abs(torques) <= limits) and np.any(np.abs(commands) > limits)  # the limit acted


# ================================================================================ the folder
def test_flight_folder_and_manifest(paper_flight):
    folder = paper_flight.folder
    names = {path.name for path in folder.iterdir()}
    assert {f"{name}.casadi" for name in FLIGHT_EXPORTED_FUNCTIONS} <= names
    assert "controller.casadi" not in names and "rule.casadi" not in names
    assert (LIBRARY_NAME in names) == HAS_COMPILER
    header = (folder / HEADER_NAME).read_text()
    for name in FLIGHT_EXPORTED_FUNCTIONS:
        assert f"int {C_PREFIX}{name}(const casadi_real** arg" in header
    manifest = json.loads((folder / MANIFEST_NAME).read_text())
    assert manifest == paper_flight.manifest
    assert list(manifest["functions"]) == list(FLIGHT_EXPORTED_FUNCTIONS)
    controller = manifest["functions"]["flight_controller"]
    assert controller["inputs"] == [
        {"name": "x_meas", "shape": [6, 1]},
        {"name": "memory", "shape": [5, 1]},
        {"name": "delta", "shape": [1, 1]},
    ]
    assert [port["name"] for port in controller["outputs"]] == ["u", "u_command", "memory_next", "switched"]
    sample = manifest["functions"]["sample"]
    assert [port["name"] for port in sample["inputs"]] == ["x", "memory", "x_delayed", "noise"]
    assert sample["inputs"][1]["shape"] == [10, 1] and sample["inputs"][3]["shape"] == [6, 1]
    flight = manifest["flight"]
    assert flight["rule"]["delta"] == 0.0 and flight["rule"]["alpha"] == 1.0
    assert flight["actuator"] == {"u_max": [60.0, 50.0, 40.0], "norm_max": 70.0, "saturation": "scale"}
    assert flight["disturbance"] == {"torque": [1e-3, -2e-3, 5e-4]}
    sensor = flight["sensor"]
    assert (sensor["attitude_noise"], sensor["rate_noise"], sensor["seed"]) == (0.01, 1e-4, 3)
    assert sensor["gyro_bias"] == [1e-4, 0.0, -2e-4]
    assert flight["delay"] is None
    assert flight["constants"]["u_max"] == [60.0, 50.0, 40.0] and flight["constants"]["u_norm"] == 70.0
    assert flight["memory_layout"]["sample"] == list(FLIGHT_MEMORY_LAYOUT)
    assert flight["memory_layout"]["flight_controller"] == ["h", "c", "sigma_prev_1", "sigma_prev_2", "sigma_prev_3"]
    assert manifest["parameters"]["rule"]["class"] == "Hysteretic"
    assert manifest["parameters"]["initial_memory"] is None  # it depends on x0: see flight.initial_memory
    assert "flight" in str(paper_flight) and "actuator, disturbance, sensor" in str(paper_flight)


def test_no_limit_and_a_delay_model_in_the_manifest(tmp_path):
    """Without an actuator the limits are null (JSON has no inf); a jitter model is recorded."""
    result = export(
        paper.SPACECRAFT,
        paper.GAIN,
        tmp_path / "jitter",
        tau=0.5,
        rule=Hysteretic.from_alpha(1.2),
        delay=DelayModel.jitter(0.45, 0.5, seed=2),
        compile=False,
    )
    text = (result.folder / MANIFEST_NAME).read_text()
    assert "Infinity" not in text and "NaN" not in text
    flight = json.loads(text)["flight"]
    assert flight["actuator"] is None and flight["constants"]["u_max"] == [None, None, None]
    assert flight["constants"]["u_norm"] is None
    assert flight["delay"]["kind"] == "jitter" and flight["delay"]["samples"] == [450, 500]
    assert flight["delay"]["seed"] == 2
    assert flight["rule"]["delta"] == pytest.approx((1.2**2 - 1) / (1.2**2 + 1), rel=1e-15)


def test_an_interrupted_flight_overwrite_keeps_the_old_export(paper_flight, tmp_path, monkeypatch):
    folder = tmp_path / "previous"
    shutil.copytree(paper_flight.folder, folder)
    (folder / "notes.txt").write_text("mine")
    before = {path.name: path.read_bytes() for path in folder.iterdir()}
    monkeypatch.setattr(export_module, "_manifest", lambda *args, **kwargs: (_ for _ in ()).throw(KeyboardInterrupt()))
    with pytest.raises(KeyboardInterrupt):
        _export(folder, OTHER_FLIGHT, overwrite=True, compile=False)
    assert {path.name: path.read_bytes() for path in folder.iterdir()} == before
    assert sorted(path.name for path in tmp_path.iterdir()) == ["previous"]


def test_a_flight_export_replaces_a_paper_export_whole(tmp_path):
    folder = tmp_path / "out"
    export(paper.SPACECRAFT, paper.GAIN, folder, tau=0.5, rule=OnDelayed(), compile=False)
    (folder / "notes.txt").write_text("mine")
    result = _export(folder, OTHER_FLIGHT, overwrite=True, compile=False)
    names = {path.name for path in folder.iterdir()}
    assert names == {path.name for path in result.files} | {"notes.txt"}
    assert "rule.casadi" not in names and "controller.casadi" not in names  # no stale paper Functions


# ================================================================================ bad input
def test_flight_options_are_refused_before_writing(tmp_path):
    folder = tmp_path / "never"
    limit = ActuatorModel(u_max=1.0)
    with pytest.raises(SpecificationError, match="Hysteretic"):
        export(paper.SPACECRAFT, paper.GAIN, folder, tau=0.5, rule=OnDelayed(), actuator=limit)
    with pytest.raises(SpecificationError, match=r"actuator must be a mrpctl\.flight\.ActuatorModel"):
        export(paper.SPACECRAFT, paper.GAIN, folder, tau=0.5, rule=Hysteretic(0.1), actuator=1.0)
    with pytest.raises(DimensionError, match="torque: expected shape"):  # (n, 3) rows are a torque input
        export(paper.SPACECRAFT, paper.GAIN, folder, tau=0.5, rule=Hysteretic(0.1), disturbance=np.zeros((5, 2)))
    with pytest.raises(SpecificationError, match="sensor must be"):
        export(paper.SPACECRAFT, paper.GAIN, folder, tau=0.5, rule=Hysteretic(0.1), sensor="noisy")
    with pytest.raises(SpecificationError, match="tau_max"):
        export(paper.SPACECRAFT, paper.GAIN, folder, tau=0.4, rule=Hysteretic(0.1), delay=DelayModel.jitter(0.3, 0.5))
    assert not folder.exists()


def test_zero_delay_flight_export_reproduces_simulate(tmp_path):
    """d = 0: the sample's controller acts on its own measurement (no delay line); the logic switch is the crossing."""
    case = dict(
        spacecraft=paper.SPACECRAFT,
        K=paper.GAIN,
        x0=paper.INITIAL_STATE,
        tau=0.0,
        rate=1000.0,
        rule=Hysteretic(0.0),
        sensor=SensorModel(attitude_noise=0.002, seed=9),
        disturbance=Disturbance([0.0, 1e-3, 0.0]),
    )
    result = _export(tmp_path / "zero", case, compile=False)
    reference = simulate(case["spacecraft"], case["K"], case["x0"], t_final=0.7, **_loop_args(case))
    assert reference.switch_count >= 1
    functions = _functions(result, "casadi")
    n = len(reference.t)
    states, torques, switches, _ = _sample_loop(functions["sample"], case, n, _memory0(case))
    _check_equal(reference, states, torques, switches)
    _check_equal(reference, *_controller_loop(functions, case, n, _memory0(case))[:3])
