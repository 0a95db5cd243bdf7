"""The predictor loop with a per-sample disturbance torque w_k (design/predictor.md, "A per-sample disturbance").

w_k acts on the plant only: the controller's model copy is driven by the applied torque u, as with a constant
w. Checked against the independent NumPy reference loop (tests/predictor_reference.py, which adds row k of
the disturbance to u_k on the plant and never on the copy), against the constant ``Disturbance`` (rows that
are all the same constant give the same bits), through ``simulate_batch`` (shared and per run), ``export``
(the ``torque`` input of ``sample`` and ``chunk``, reloaded and compiled), scenario files and the CLI.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
import pytest

from mrpctl import OnPredicted, Predictor, SimulationResult, paper, simulate, simulate_batch
from mrpctl._compile import find_compiler
from mrpctl._export import C_PREFIX, MANIFEST_NAME, PREDICTOR_EXPORTED_FUNCTIONS, ExportResult, export
from mrpctl.cli import main
from mrpctl.design import pd_gains
from mrpctl.engines import scalar as _engine
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.flight import ActuatorModel, Disturbance, Saturation, SensorModel
from mrpctl.loop.options import predictor_memory
from mrpctl.predictor import perturbed_spacecraft
from mrpctl.scenario import load_scenario

sys.path.insert(0, str(Path(__file__).parent))
import predictor_reference as ref

needs_compiler = pytest.mark.skipif(find_compiler() is None, reason="no C compiler on this machine")
pytestmark = needs_compiler  # the predictor runs on the compiled engine only

SC = paper.SPACECRAFT
J = np.diag(SC.inertia)
PLANT = perturbed_spacecraft(SC, 0.1)
X0 = np.array([0.93, 0.0, 0.0, 0.46 / 4, 0.0, 0.0])
TUMBLE = np.array([0.3, -0.5, 0.2, 4.0 / 4, -2.0 / 4, 3.0 / 4])  # |ω| = 5.4 rad/s
TAU, RATE, T_FINAL = 0.5, 100.0, 4.0
N = 401
RTOL = 1e-12  # relative to the largest state component (torque); measured 3.9e-16 (9.1e-15), design/predictor.md
BIAS = np.array([3.0, -2.0, 1.0])  # N m


def _gain(omega_n: float) -> np.ndarray:
    return pd_gains(SC, zeta=1.0, omega_n=omega_n).K


def _rows(n: int = N, scale: float = 20.0, seed: int = 2026) -> np.ndarray:
    """A random per-sample disturbance (N m): a constant part plus white noise of ``scale`` (1σ)."""
    return BIAS + scale * np.random.default_rng(seed).standard_normal((n, 3))


def _gust(t: np.ndarray) -> np.ndarray:
    """An elementwise w(t) (N m)."""
    return np.column_stack((5.0 * np.sin(3.0 * t), -4.0 * np.cos(2.0 * t), 2.0 * (t > 1.5)))


def _state(result: SimulationResult) -> np.ndarray:
    return np.hstack((result.sigma, result.omega / 4.0))


def _assert_matches(result: SimulationResult, reference: ref.Run) -> None:
    assert result.switch_indices.tolist() == reference.switches
    x = _state(result)
    assert x.shape == reference.x.shape
    assert np.max(np.abs(x - reference.x)) <= RTOL * np.max(np.abs(reference.x))
    assert np.max(np.abs(result.u - reference.u)) <= RTOL * np.max(np.abs(reference.u))


def _same_bits(a: SimulationResult, b: SimulationResult) -> None:
    for name in ("sigma", "omega", "u", "switch_indices"):
        assert np.asarray(getattr(a, name)).tobytes() == np.asarray(getattr(b, name)).tobytes(), name
    assert a.saturated_fraction == b.saturated_fraction
    assert np.asarray(a.peak_command).tobytes() == np.asarray(b.peak_command).tobytes()


SENSOR = SensorModel(attitude_noise=1e-3, rate_noise=1e-3, gyro_bias=[1e-3, -2e-3, 0.5e-3], seed=7)

REFERENCE_CASES = [
    # (plant inertia error, x0, gain, actuator clip (N m), sensor, t_final, switches in the reference)
    pytest.param(0.1, TUMBLE, _gain(1.0), None, False, T_FINAL, 1, id="tumble-plant+10%"),
    pytest.param(0.1, TUMBLE, _gain(2.0), 50.0, False, T_FINAL, None, id="tumble-clipped"),
    pytest.param(0.1, TUMBLE, _gain(1.0), None, True, T_FINAL, None, id="tumble-sensor"),
    pytest.param(0.0, X0, paper.GAIN, None, False, 3.0, 1, id="paper-exact-model"),
]


@pytest.mark.parametrize(("e", "x0", "gain", "u_max", "noisy", "t_final", "switches"), REFERENCE_CASES)
def test_engine_equals_the_reference_loop_with_a_per_sample_torque(
    e: float, x0: np.ndarray, gain: np.ndarray, u_max: float | None, noisy: bool, t_final: float, switches: int | None
) -> None:
    """Random w_k: identical switch samples, states and torques to 1e-12 relative; w_k matters."""
    plant = perturbed_spacecraft(SC, e)
    n = int(t_final * RATE) + 1
    rows = _rows(n)
    options: dict[str, Any] = {}
    noise = None
    if u_max is not None:
        options["actuator"] = ActuatorModel(u_max=u_max, mode=Saturation.CLIP)
    if noisy:
        options["sensor"] = SENSOR
        theta, eta = SENSOR.noise(0, n)
        noise = (theta, eta, np.asarray(SENSOR.gyro_bias))
    common: dict[str, Any] = dict(tau=TAU, rule=OnPredicted(1.0), t_final=t_final, rate=RATE, predictor=Predictor(SC))
    result = simulate(plant, gain, x0, disturbance=rows, **common, **options)
    reference = ref.run(
        np.diag(plant.inertia),
        J,
        gain,
        x0,
        tau=TAU,
        rate=RATE,
        t_final=t_final,
        u_max=u_max,
        disturbance=rows,
        noise=noise,
    )
    _assert_matches(result, reference)
    if switches is not None:
        assert len(reference.switches) == switches
    if u_max is not None:
        assert result.saturated_fraction is not None and result.saturated_fraction > 0.05  # the clip acts
    # not vacuous: the per-sample part moves the run away from the run with its mean alone
    mean = simulate(plant, gain, x0, disturbance=rows.mean(axis=0), **common, **options)
    assert np.max(np.abs(_state(mean) - _state(result))) > 1e-5


@pytest.mark.parametrize(
    "options",
    [
        pytest.param({}, id="unlimited"),
        pytest.param({"actuator": ActuatorModel(u_max=[60.0, 50.0, 40.0], norm_max=70.0)}, id="limited"),
        pytest.param({"sensor": SENSOR, "actuator": ActuatorModel(u_max=50.0, mode=Saturation.CLIP)}, id="sensor"),
    ],
)
def test_constant_rows_equal_the_constant_disturbance_bit_for_bit(options: dict[str, Any]) -> None:
    w = np.array([0.3, -0.2, 0.1])
    common: dict[str, Any] = dict(tau=TAU, rule=OnPredicted(1.0), t_final=T_FINAL, rate=RATE, predictor=Predictor(SC))
    rows = simulate(PLANT, _gain(1.0), TUMBLE, disturbance=np.tile(w, (N, 1)), **common, **options)
    constant = simulate(PLANT, _gain(1.0), TUMBLE, disturbance=Disturbance(w), **common, **options)
    _same_bits(rows, constant)
    assert constant.switch_count >= 1


def test_function_of_time_equals_its_rows_slice_by_slice(monkeypatch: pytest.MonkeyPatch) -> None:
    """w(t) evaluated per slice (97 samples) equals its rows in one slice, bit for bit."""
    common: dict[str, Any] = dict(tau=TAU, rule=OnPredicted(1.0), t_final=T_FINAL, rate=RATE, predictor=Predictor(SC))
    whole = simulate(PLANT, _gain(1.0), TUMBLE, disturbance=_gust(np.arange(N) / RATE), **common)
    monkeypatch.setattr(_engine, "SLICE_SAMPLES", 97)
    function = simulate(PLANT, _gain(1.0), TUMBLE, disturbance=Disturbance(function=_gust), **common)
    rows = simulate(PLANT, _gain(1.0), TUMBLE, disturbance=_gust(np.arange(N) / RATE), **common)
    _same_bits(function, whole)
    _same_bits(rows, whole)


def test_batch_equals_simulate_shared_and_per_run() -> None:
    """simulate_batch (scalar engine, 2 threads): shared rows, a per-run list and an (N, n, 3) array."""
    states = np.array([X0, TUMBLE, -TUMBLE, TUMBLE])
    plants = [perturbed_spacecraft(SC, e) for e in (0.0, 0.1, -0.1, 0.05)]
    common: dict[str, Any] = dict(tau=TAU, rule=OnPredicted(1.0), t_final=T_FINAL, rate=RATE, predictor=Predictor(SC))
    gain = _gain(1.0)
    shared = _rows()
    per_run: list[Any] = [None, BIAS, _rows(seed=1), Disturbance(function=_gust)]
    stacked = np.stack([_rows(seed=s) for s in range(4)])
    for given, each in (
        (shared, [shared] * 4),
        (per_run, per_run),
        (stacked, list(stacked)),
    ):
        singles = [simulate(plants[i], gain, states[i], disturbance=each[i], **common) for i in range(4)]
        for trajectories in (True, False):
            batch = simulate_batch(
                plants, gain, states, disturbance=given, trajectories=trajectories, threads=2, **common
            )
            assert batch.switch_count.tolist() == [s.switch_count for s in singles]
            assert np.array_equal(batch.max_sigma, [s.max_sigma for s in singles])
            assert np.array_equal(batch.peak_torque, [s.peak_torque for s in singles])
            if trajectories:
                assert batch.runs is not None
                for run, single in zip(batch.runs, singles, strict=True):
                    _same_bits(run, single)
    assert len({simulate(PLANT, gain, TUMBLE, disturbance=w, **common).sigma[-1].tobytes() for w in per_run}) == 4


def test_bad_disturbance_is_refused_naming_it(tmp_path: Path) -> None:
    common: dict[str, Any] = dict(tau=TAU, rule=OnPredicted(1.0), t_final=T_FINAL, rate=RATE, predictor=Predictor(SC))
    gain = _gain(1.0)
    with pytest.raises(DimensionError, match=r"disturbance: torque: expected shape \(3,\) or \(n, 3\)"):
        simulate(PLANT, gain, TUMBLE, disturbance=np.zeros((N, 2)), **common)
    with pytest.raises(DimensionError, match=r"disturbance: torque: expected shape \(n, 3\) = \(401, 3\)"):
        simulate(PLANT, gain, TUMBLE, disturbance=np.zeros((N - 1, 3)), **common)
    bad = _rows()
    bad[17, 1] = np.nan
    with pytest.raises(SpecificationError, match="disturbance: torque must be finite"):
        simulate(PLANT, gain, TUMBLE, disturbance=bad, **common)
    with pytest.raises(SpecificationError, match=r"function \(the disturbance w\(t\)"):
        simulate(
            PLANT, gain, TUMBLE, disturbance=Disturbance(function=lambda t: np.full((len(t), 3), np.nan)), **common
        )
    states = np.array([TUMBLE, X0])
    with pytest.raises(DimensionError, match=r"disturbance: torque: expected shape \(n, 3\) = \(401, 3\)"):
        simulate_batch(PLANT, gain, states, disturbance=np.zeros((N + 1, 3)), **common)
    with pytest.raises(SpecificationError, match=r"disturbance\[1\] must be finite"):
        simulate_batch(PLANT, gain, states, disturbance=[None, bad], **common)
    with pytest.raises(DimensionError, match=r"disturbance\[0\]: torque: expected shape \(n, 3\) = \(401, 3\)"):
        simulate_batch(PLANT, gain, states, disturbance=[np.zeros((N - 1, 3)), None], **common)
    with pytest.raises(DimensionError, match=r"disturbance: a per-run per-sample torque has shape"):
        simulate_batch(PLANT, gain, states, disturbance=np.zeros((2, N - 1, 3)), **common)
    with pytest.raises(DimensionError, match=r"disturbance: torque: expected shape"):
        export(PLANT, gain, tmp_path / "never", disturbance=np.zeros((N, 2)), compile=False, **_export_case())
    assert not (tmp_path / "never").exists()


# ----------------------------------------------------------------------------------------- export
EXPORT_TAU, EXPORT_T_FINAL = 0.2, 2.0
EXPORT_N, EXPORT_D = 201, 20
EXPORT_X0 = np.array([0.3, -0.5, 0.2, 1.0, -0.5, 0.75])
EXPORT_ROWS = _rows(EXPORT_N, scale=15.0, seed=11)
EXPORT_SENSOR = SensorModel(attitude_noise=1e-3, rate_noise=1e-3, gyro_bias=[1e-3, 0.0, -1e-3], seed=5)


def _export_case() -> dict[str, Any]:
    return dict(
        tau=EXPORT_TAU,
        rate=RATE,
        rule=OnPredicted(1.0),
        predictor=Predictor(model=SC),
        actuator=ActuatorModel(u_max=[300.0, 250.0, 200.0]),
        sensor=EXPORT_SENSOR,
    )


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> ExportResult:
    folder = tmp_path_factory.mktemp("predictor_torque") / "export"
    return export(PLANT, _gain(1.0), folder, disturbance=EXPORT_ROWS, **_export_case())


@pytest.fixture(scope="module")
def expected() -> SimulationResult:
    return simulate(PLANT, _gain(1.0), EXPORT_X0, t_final=EXPORT_T_FINAL, disturbance=EXPORT_ROWS, **_export_case())


def _exported_functions(result: ExportResult, source: str) -> dict[str, ca.Function]:
    if source == "casadi":
        return {name: ca.Function.load(str(result.folder / f"{name}.casadi")) for name in PREDICTOR_EXPORTED_FUNCTIONS}
    assert result.library is not None
    return {name: ca.external(C_PREFIX + name, str(result.library)) for name in PREDICTOR_EXPORTED_FUNCTIONS}


def _export_noise(samples: int) -> np.ndarray:
    rotation, rate = EXPORT_SENSOR.noise(0, samples)
    return np.hstack((rotation, rate))


def _check_export(expected: SimulationResult, states: np.ndarray, torques: np.ndarray, switches: list[int]) -> None:
    assert np.array_equal(states, _state(expected))
    assert np.array_equal(torques, expected.u)
    assert switches == expected.switch_indices.tolist()


def test_the_torque_and_the_limit_act_in_the_export_case(expected: SimulationResult) -> None:
    constant = simulate(
        PLANT, _gain(1.0), EXPORT_X0, t_final=EXPORT_T_FINAL, disturbance=EXPORT_ROWS.mean(axis=0), **_export_case()
    )
    assert np.max(np.abs(_state(expected) - _state(constant))) > 1e-5
    assert expected.saturated_fraction is not None and 0.0 < expected.saturated_fraction < 1.0


@pytest.mark.parametrize("source", ["casadi", "library"])
def test_exported_sample_chunk_and_pieces_with_a_torque_input_reproduce_simulate(
    exported: ExportResult, expected: SimulationResult, source: str
) -> None:
    f = _exported_functions(exported, source)
    assert f["sample"].name_in()[-1] == "torque" and f["sample"].size_in(4) == (3, 1)
    assert f["chunk"].name_in()[-1] == "torque" and f["chunk"].size_in(4) == (3, EXPORT_D)
    n, d = EXPORT_N, EXPORT_D
    noise = _export_noise(n + d)
    start = np.concatenate((EXPORT_X0, EXPORT_X0))  # the constant history (x0; x0)

    # a loop of sample, the caller's delay line of (m_k; z_k)
    x, memory = EXPORT_X0.copy(), predictor_memory(EXPORT_X0)
    ring: list[np.ndarray] = []
    states, torques, switches = [], [], []
    for k in range(n):
        out = [
            np.array(v).ravel()
            for v in f["sample"](x, memory, start if k < d else ring[k - d], noise[k], EXPORT_ROWS[k])
        ]
        x, memory = out[0], out[1]
        states.append(out[2])
        torques.append(out[3])
        if out[4][0] > 0:
            switches.append(k)
        ring.append(out[5])
    _check_export(expected, np.array(states), np.array(torques), switches)

    # chunks of d samples; the last one runs past n (any torque and noise there)
    x, memory = EXPORT_X0.copy(), predictor_memory(EXPORT_X0)
    history = np.tile(start[:, None], (1, d))
    torque = np.vstack((EXPORT_ROWS, np.zeros((d, 3)))).T
    chunk_states, chunk_u, flags = [], [], []
    for first in range(0, n, d):
        x, memory, block, history, u, switched = (
            np.asarray(v)
            for v in f["chunk"](x, memory, history, noise[first : first + d].T, torque[:, first : first + d])
        )
        chunk_states.append(block)
        chunk_u.append(u)
        flags.append(switched)
    _check_export(
        expected,
        np.hstack(chunk_states)[:, :n].T,
        np.hstack(chunk_u)[:, :n].T,
        np.flatnonzero(np.hstack(flags)[0, :n] > 0).tolist(),
    )

    # the flight-software pieces: sensor -> predictor_controller (no w) -> step with u + w_k
    x = EXPORT_X0.copy()
    z = predictor_memory(EXPORT_X0)[10:16]
    previous = z[0:3].copy()
    measurements: list[np.ndarray] = []
    copies: list[np.ndarray] = []
    states, torques, switches = [], [], []
    for k in range(n):
        x_true, measured = (np.array(v).ravel() for v in f["sensor"](x, noise[k]))
        measurements.append(measured)
        copies.append(z)
        y, z_delayed = (EXPORT_X0, EXPORT_X0) if k < d else (measurements[k - d], copies[k - d])
        u, _, x_hat, switched, z_next = (
            np.array(v).ravel() for v in f["predictor_controller"](y, z_delayed, z, previous)
        )
        states.append(x_true)
        torques.append(u)
        if switched[0] > 0:
            switches.append(k)
        previous, z = x_hat[0:3], z_next
        x = np.array(f["step"](x_true, u + EXPORT_ROWS[k])).ravel()
    _check_export(expected, np.array(states), np.array(torques), switches)


def test_the_manifest_names_the_torque_input(exported: ExportResult) -> None:
    manifest = json.loads((exported.folder / MANIFEST_NAME).read_text(encoding="utf-8"))
    section = manifest["predictor"]
    disturbance = section["disturbance"]
    assert disturbance["per_sample"] is True and disturbance["input"] == "torque"
    assert disturbance["samples"] == EXPORT_N and disturbance["function"] is None
    assert section["constants"]["disturbance"] == [0.0, 0.0, 0.0]  # w is not bound in
    for name in ("sample", "chunk"):
        entry = manifest["functions"][name]
        assert entry["inputs"][-1]["name"] == "torque" and "torque" in entry["description"]
    assert "torque" not in [port["name"] for port in manifest["functions"]["predictor_controller"]["inputs"]]


def test_a_function_of_time_exports_the_same_sample_and_chunk(tmp_path: Path, exported: ExportResult) -> None:
    function = export(
        PLANT,
        _gain(1.0),
        tmp_path / "function",
        disturbance=Disturbance(function=_gust),
        compile=False,
        **_export_case(),
    )
    assert function.manifest["predictor"]["disturbance"]["function"] == "_gust"
    for name in ("sample", "chunk", "predictor_controller"):
        assert (tmp_path / "function" / f"{name}.casadi").read_bytes() == (
            exported.folder / f"{name}.casadi"
        ).read_bytes()


# ------------------------------------------------------------------------------- scenario and CLI
SCENARIO = f"""
tau = 0.1
rate = {RATE}
t_final = 3.0
[spacecraft]
inertia = [140.0, 100.0, 80.0]
[gains]
k_sigma = -7.011
k_omega = -16.308
[initial]
sigma = [0.6, -0.2, 0.1]
omega = [0.3, 0.1, 0.0]
[rule]
type = "on-predicted"
alpha = 1.0
[predictor]
inertia_error = 0.1
[disturbance]
torque_file = "w.npy"
"""
SCENARIO_ROWS = _rows(301, scale=2.0, seed=5)


def _scenario_expected(model: Any, rows: np.ndarray) -> SimulationResult:
    return simulate(
        SC,
        np.hstack((-7.011 * np.eye(3), -16.308 * np.eye(3))),
        np.array([0.6, -0.2, 0.1, 0.075, 0.025, 0.0]),
        tau=0.1,
        rate=RATE,
        t_final=3.0,
        rule=OnPredicted(1.0),
        predictor=Predictor(model=model),
        disturbance=rows,
    )


def test_scenario_predictor_with_a_torque_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    np.save(tmp_path / "w.npy", SCENARIO_ROWS)
    path = tmp_path / "s.toml"
    path.write_text(SCENARIO, encoding="utf-8")
    scenario = load_scenario(path)
    assert scenario.predictor is not None and scenario.disturbance is not None
    expected = _scenario_expected(scenario.predictor.model, SCENARIO_ROWS)
    _same_bits(scenario.simulate(), expected)
    assert main(["simulate", str(path), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)["result"]
    assert result["final_sigma"] == expected.sigma[-1].tolist() and result["switch_count"] == expected.switch_count


def test_cli_predictor_with_a_disturbance_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    np.save(tmp_path / "w.npy", SCENARIO_ROWS)
    path = tmp_path / "s.toml"
    path.write_text(SCENARIO.replace('[disturbance]\ntorque_file = "w.npy"\n', ""), encoding="utf-8")
    # --predictor (the exact model) replaces the file's [predictor]; --disturbance-file gives the rows
    assert main(["simulate", str(path), "--predictor", "--disturbance-file", str(tmp_path / "w.npy"), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)["result"]
    expected = _scenario_expected(SC, SCENARIO_ROWS)
    assert result["final_sigma"] == expected.sigma[-1].tolist() and result["switch_count"] == expected.switch_count
    without = _scenario_expected(SC, np.zeros((301, 3)))
    assert result["final_sigma"] != without.sigma[-1].tolist()
    out = tmp_path / "exported"
    argv = ["export", str(path), "--out", str(out), "--no-compile", "--predictor"]
    assert main([*argv, "--disturbance-file", str(tmp_path / "w.npy"), "--json"]) == 0
    capsys.readouterr()
    manifest = json.loads((out / MANIFEST_NAME).read_text(encoding="utf-8"))
    assert manifest["predictor"]["disturbance"]["input"] == "torque"
    assert manifest["functions"]["sample"]["inputs"][-1]["name"] == "torque"
