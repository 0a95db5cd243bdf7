"""mrpctl.export of the predictor loop: the exported Functions against the compiled engine, and the manifest.

The Functions are loaded back from the ``.casadi`` files and through the compiled library; a loop of
``sample`` alone, and one of ``sensor``, ``predictor_controller`` and ``step`` (the flight-software
pieces) with the caller's own delay line of (m_k, z_k), must give :func:`mrpctl.simulate`'s numbers
bit for bit.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
import pytest

from mrpctl import OnPredicted, Predictor, SimulationResult, paper, simulate
from mrpctl._compile import find_compiler
from mrpctl._export import C_PREFIX, MANIFEST_NAME, PREDICTOR_EXPORTED_FUNCTIONS, ExportResult, export
from mrpctl.design import pd_gains
from mrpctl.errors import SpecificationError
from mrpctl.flight import ActuatorModel, SensorModel
from mrpctl.loop import PREDICTOR_MEMORY_LAYOUT, closed_loop_functions
from mrpctl.loop.options import predictor_memory
from mrpctl.predictor import perturbed_spacecraft
from mrpctl.switching import OnDelayed

needs_compiler = pytest.mark.skipif(find_compiler() is None, reason="no C compiler on this machine")

SC = paper.SPACECRAFT
PLANT = perturbed_spacecraft(SC, 0.1)
K = pd_gains(SC, zeta=1.0, omega_n=1.0).K
X0 = np.array([0.3, -0.5, 0.2, 1.0, -0.5, 0.75])
CASE: dict[str, Any] = dict(
    tau=0.2,
    rate=100.0,
    rule=OnPredicted(1.0),
    predictor=Predictor(model=SC),
    actuator=ActuatorModel(u_max=[60.0, 50.0, 40.0]),
    disturbance=[0.2, -0.1, 0.05],
    sensor=SensorModel(attitude_noise=1e-3, rate_noise=1e-3, gyro_bias=[1e-3, 0.0, -1e-3], seed=5),
)
T_FINAL = 2.0
N = 201
D = 20


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> ExportResult:
    return export(PLANT, K, tmp_path_factory.mktemp("predictor") / "export", **CASE)


@pytest.fixture(scope="module")
def reference() -> SimulationResult:
    return simulate(PLANT, K, X0, t_final=T_FINAL, **CASE)


def _noise() -> np.ndarray:
    rotation, rate = CASE["sensor"].noise(0, N)
    return np.hstack((rotation, rate))


def _functions(result: ExportResult, source: str) -> dict[str, ca.Function]:
    if source == "casadi":
        return {name: ca.Function.load(str(result.folder / f"{name}.casadi")) for name in PREDICTOR_EXPORTED_FUNCTIONS}
    assert result.library is not None
    return {name: ca.external(C_PREFIX + name, str(result.library)) for name in PREDICTOR_EXPORTED_FUNCTIONS}


def _state(result: SimulationResult) -> np.ndarray:
    return np.hstack((result.sigma, result.omega / 4.0))


@pytest.mark.parametrize("source", ["casadi", pytest.param("library", marks=needs_compiler)])
def test_exported_sample_reproduces_simulate_bit_for_bit(
    exported: ExportResult, reference: SimulationResult, source: str
) -> None:
    f = _functions(exported, source)
    noise = _noise()
    x, memory = X0.copy(), predictor_memory(X0)
    ring: list[np.ndarray] = []
    states, torques, switches = [], [], []
    for k in range(N):
        delayed = np.concatenate((X0, X0)) if k < D else ring[k - D]
        out = [np.array(v).ravel() for v in f["sample"](x, memory, delayed, noise[k])]
        x, memory = out[0], out[1]
        states.append(out[2])
        torques.append(out[3])
        switches.append(float(out[4][0]))
        ring.append(out[5])
    assert np.array_equal(np.array(states), _state(reference))
    assert np.array_equal(np.array(torques), reference.u)
    assert np.flatnonzero(switches).tolist() == reference.switch_indices.tolist()
    assert reference.saturated_fraction is not None and reference.saturated_fraction > 0  # the limit acts


@pytest.mark.parametrize("source", ["casadi", pytest.param("library", marks=needs_compiler)])
def test_flight_software_pieces_reproduce_simulate_bit_for_bit(
    exported: ExportResult, reference: SimulationResult, source: str
) -> None:
    """sensor -> predictor_controller (prediction, K, actuator, model_step) -> step, with the caller's delay line."""
    f = _functions(exported, source)
    noise = _noise()
    w = np.array(CASE["disturbance"])
    x = X0.copy()
    z = predictor_memory(X0)[10:16]
    previous = z[0:3].copy()
    measurements, copies, states, torques, switches = [], [], [], [], []
    for k in range(N):
        x_true, measured = (np.array(v).ravel() for v in f["sensor"](x, noise[k]))
        measurements.append(measured)
        copies.append(z)
        y, z_delayed = (X0, X0) if k < D else (measurements[k - D], copies[k - D])
        u, _, x_hat, switched, z_next = (
            np.array(v).ravel() for v in f["predictor_controller"](y, z_delayed, z, previous)
        )
        x_hat_alone, switched_alone = (np.array(v).ravel() for v in f["prediction"](y, z_delayed, z, previous))
        assert np.array_equal(x_hat, x_hat_alone) and switched == switched_alone
        assert np.array_equal(z_next, np.array(f["model_step"](z, u)).ravel())
        states.append(x_true)
        torques.append(u)
        switches.append(float(switched[0]))
        previous, z = x_hat[0:3], z_next
        x = np.array(f["step"](x_true, u + w)).ravel()
    assert np.array_equal(np.array(states), _state(reference))
    assert np.array_equal(np.array(torques), reference.u)
    assert np.flatnonzero(switches).tolist() == reference.switch_indices.tolist()


def test_chunk_is_d_samples(exported: ExportResult, reference: SimulationResult) -> None:
    chunk = ca.Function.load(str(exported.folder / "chunk.casadi"))
    history = np.tile(np.concatenate((X0, X0))[:, None], (1, D))
    out = chunk(X0, predictor_memory(X0), history, _noise()[0:D].T)
    assert np.array_equal(np.array(out[2]).T, _state(reference)[0:D])
    second = chunk(out[0], out[1], out[3], _noise()[D : 2 * D].T)
    assert np.array_equal(np.array(second[2]).T, _state(reference)[D : 2 * D])


def test_manifest_predictor_section(exported: ExportResult) -> None:
    manifest = json.loads(Path(exported.folder / MANIFEST_NAME).read_text())
    assert list(manifest["functions"]) == list(PREDICTOR_EXPORTED_FUNCTIONS)
    section = manifest["predictor"]
    assert section["model_inertia"] == SC.inertia.tolist() and section["tau"] == 0.2 and section["alpha"] == 1.0
    assert section["memory_layout"]["sample"] == list(PREDICTOR_MEMORY_LAYOUT)
    assert section["actuator"]["u_max"] == [60.0, 50.0, 40.0] and section["constants"]["u_norm"] is None
    assert "flight" not in manifest
    assert manifest["functions"]["sample"]["inputs"][2] == {"name": "x_delayed", "shape": [12, 1]}


def test_bad_input_is_refused_before_writing(tmp_path: Path) -> None:
    folder = tmp_path / "out"
    with pytest.raises(SpecificationError, match="rule"):
        export(SC, K, folder, tau=0.2, rate=100.0, rule=OnDelayed(), predictor=Predictor(SC), compile=False)
    with pytest.raises(SpecificationError, match="predictor="):
        export(SC, K, folder, tau=0.2, rate=100.0, rule=OnPredicted(), compile=False)
    with pytest.raises(SpecificationError, match="predictor"):
        closed_loop_functions(SC, K, tau=0.2, rate=100.0, rule=OnPredicted(), predictor="model")
    assert not folder.exists()
