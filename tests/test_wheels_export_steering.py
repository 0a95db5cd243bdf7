"""The exported wheel controller with the steering law: its command against a NumPy steering law, and the
motor torques of the simulated loop."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from wheels_reference import Wheels, _steering, allocate

from mrpctl import WheelCluster, export_wheel_controller, simulate
from mrpctl._compile import find_compiler
from mrpctl._export import C_PREFIX, MANIFEST_NAME
from mrpctl.cli import main
from mrpctl.errors import SpecificationError
from mrpctl.flight import Hysteretic
from mrpctl.flight.steering import SteeringLaw
from mrpctl.model import gain_from_pd, state
from mrpctl.scenario import parse_scenario, scenario_toml
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import OnCurrent

CRAFT = Spacecraft(np.array([[0.2, 0.01, 0.0], [0.01, 0.25, -0.005], [0.0, -0.005, 0.15]]))
WHEELS = WheelCluster.pyramid(
    2e-4, 5e-3, 300.0, speeds=[10.0, -20.0, 30.0, 5.0], null_gain=0.05, bias_speeds=[50.0, -50.0, 50.0, -50.0],
    gyroscopic=True,
)  # fmt: skip
K = gain_from_pd(CRAFT, -0.04 * np.ones(3), -0.4 * np.ones(3))
LAW = SteeringLaw(0.05, 0.01, 0.4, momentum_limit=0.009, spacecraft=CRAFT)


def _functions(out: Path, library: Path | None) -> list[ca.Function]:
    functions = [ca.Function.load(str(out / "wheel_controller.casadi"))]
    if find_compiler() is not None:
        assert library is not None
        functions.append(ca.external(C_PREFIX + "wheel_controller", str(library)))
    return functions


def _quaternion(sigma: np.ndarray) -> np.ndarray:
    """The quaternion of |sigma| < 1 (q0 > 0), written out here."""
    s2 = sigma @ sigma
    return np.concatenate((((1.0 - s2) / (1.0 + s2),), 2.0 * sigma / (1.0 + s2)))


def test_the_exported_command_is_the_steering_law(tmp_path: Path) -> None:
    result = export_wheel_controller(CRAFT, K, WHEELS, tmp_path / "out", tau=0.0, rule=Hysteretic(0.1), law=LAW)
    manifest = json.loads((tmp_path / "out" / MANIFEST_NAME).read_text())
    steering = manifest["parameters"]["steering"]
    assert (steering["rate_limit"], steering["acceleration"], steering["lag"]) == (0.05, 0.01, 0.4)
    assert steering["momentum_limit"] == 0.009 and steering["momentum_inertia"] == CRAFT.inertia.tolist()
    reference = Wheels(
        axes=np.array(WHEELS.spin_axes), js=np.array(WHEELS.spin_inertia), u_max=np.array(WHEELS.torque_limit),
        omega_max=np.array(WHEELS.speed_limit), viscous=np.zeros(4), coulomb=np.zeros(4), cycle=np.ones(4),
        speeds=np.zeros(4), null_gain=WHEELS.null_gain, bias=np.array(WHEELS.bias_speeds), gyroscopic=True,
    )  # fmt: skip
    numpy_law = (LAW.rate_limit, LAW.acceleration, LAW.lag, LAW.momentum_limit, CRAFT.inertia)
    rng = np.random.default_rng(7)
    cases = []
    for _ in range(40):
        axis = rng.normal(size=3)
        sigma = np.tan(rng.uniform(0.0, np.pi) / 4.0) * axis / np.linalg.norm(axis)  # |sigma| < 1
        cases.append((sigma, rng.normal(scale=0.03, size=3), rng.uniform(-320.0, 320.0, 4)))
    cases.append((np.array([1e-4, -2e-4, 5e-5]), np.array([1e-4, 0.0, -1e-4]), np.zeros(4)))  # s = 1: the PD law
    limited = 0
    for function in _functions(tmp_path / "out", result.library):
        for sigma, omega, speeds in cases:
            x_meas = np.concatenate((sigma, omega / 4.0))
            out = function(x_meas, np.array([1.0, 1.0, *sigma]), speeds)  # h = c = +1, no flip: sigma_c = sigma
            command = np.asarray(out[3]).ravel()
            expected = _steering(K, numpy_law, sigma, _quaternion(sigma), omega)
            assert np.abs(command - expected).max() <= 1e-12 * np.abs(expected).max(), (sigma, omega)
            motor, _, _ = allocate(reference, expected, omega, speeds, CRAFT.inertia)
            np.testing.assert_allclose(np.asarray(out[0]).ravel(), motor, rtol=1e-12, atol=1e-17)
            limited += not np.allclose(expected, K @ x_meas, rtol=1e-9, atol=0.0)
    assert limited >= 30  # most cases are far enough out for the rate or momentum limit to act
    pd = K @ np.concatenate((cases[-1][0], cases[-1][1] / 4.0))
    np.testing.assert_allclose(np.asarray(out[3]).ravel(), pd, rtol=1e-13)  # near the target the law is K


def test_the_exported_controller_gives_the_motor_torques_of_the_simulated_loop(tmp_path: Path) -> None:
    """d = 0, an ideal sensor: threaded through its memory the controller gives the run's motor torques."""
    x0 = state([0.5, -0.6, 0.4], [0.03, 0.02, -0.04])
    run = simulate(CRAFT, K, x0, tau=0.0, rule=Hysteretic(0.1), t_final=30.0, rate=10.0, wheels=WHEELS, law=LAW)
    pd = simulate(CRAFT, K, x0, tau=0.0, rule=Hysteretic(0.1), t_final=30.0, rate=10.0, wheels=WHEELS)
    assert run.wheels is not None and pd.wheels is not None
    assert not np.array_equal(run.wheels.motor_torque, pd.wheels.motor_torque)
    result = export_wheel_controller(
        CRAFT, K, WHEELS, tmp_path / "out", tau=0.0, rule=Hysteretic(0.1), rate=10.0, law=LAW
    )
    for function in _functions(tmp_path / "out", result.library):
        s2 = run.sigma[0] @ run.sigma[0]
        memory = np.array([1.0, 1.0, *(-run.sigma[0] / s2 if s2 > 1.0 else run.sigma[0])])
        motors = []
        for sigma, omega, speeds in zip(run.sigma, run.omega, run.wheels.speeds, strict=True):
            out = function(np.concatenate((sigma, omega / 4.0)), memory, speeds)
            motors.append(np.asarray(out[0]).ravel())
            memory = np.asarray(out[2]).ravel()
        motors = np.array(motors)
        scale = np.abs(run.wheels.motor_torque).max()
        assert np.abs(motors - run.wheels.motor_torque).max() <= 1e-15 * scale


def test_the_law_is_checked(tmp_path: Path) -> None:
    with pytest.raises(SpecificationError, match=r"law must be a mrpctl\.flight\.steering\.SteeringLaw"):
        export_wheel_controller(CRAFT, K, WHEELS, tmp_path / "a", tau=0.0, law=(0.1, 0.01), compile=False)
    singular = np.array(K)
    singular[:, 3:6] = 0.0
    with pytest.raises(SpecificationError, match="invertible rate block"):
        export_wheel_controller(CRAFT, singular, WHEELS, tmp_path / "b", tau=0.0, law=LAW, compile=False)
    with pytest.raises(SpecificationError, match="Hysteretic"):
        export_wheel_controller(CRAFT, K, WHEELS, tmp_path / "c", tau=0.0, rule=OnCurrent(), law=LAW, compile=False)
    assert not any((tmp_path / name).exists() for name in ("a", "b", "c"))


def test_cli_exports_a_wheel_scenario_s_law(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = {
        "tau": 0.2,
        "rate": 50.0,
        "t_final": 20.0,
        "spacecraft": {"inertia": [0.2, 0.25, 0.15]},
        "gains": {"attitude": [3.958, 4.947, 2.968], "rate": [0.8897, 1.1121, 0.6673]},
        "initial": {"sigma": [0.1, 0.2, 0.3], "omega": [0.0, 0.0, 0.0]},
        "rule": {"type": "hysteretic", "delta": 0.0},
        "wheels": {"layout": "orthogonal", "spin_inertia": 3.1831e-5, "torque_limit": 5e-3, "speed_limit_rpm": 6e3},
        "steering": {"rate_limit": 0.1942, "acceleration": 0.012, "lag": 0.4248, "momentum_limit": 0.02},
    }
    path = tmp_path / "s.toml"
    path.write_text(scenario_toml(parse_scenario(copy.deepcopy(data))))
    assert main(["export", str(path), "--out", str(tmp_path / "out"), "--no-compile"]) == 0
    capsys.readouterr()
    manifest = json.loads((tmp_path / "out" / MANIFEST_NAME).read_text())
    assert manifest["parameters"]["steering"]["momentum_limit"] == 0.02
    assert manifest["parameters"]["steering"]["rate_limit"] == 0.1942
