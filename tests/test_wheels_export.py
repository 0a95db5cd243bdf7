"""The exported wheel controller (CasADi Function and C library): the wheel torques of the simulated loop."""

from __future__ import annotations

import json

import casadi as ca
import numpy as np
import pytest
from wheels_reference import Wheels, allocate

from mrpctl import WheelCluster, export_wheel_controller, simulate
from mrpctl._compile import find_compiler
from mrpctl._export import C_PREFIX, MANIFEST_NAME, WHEEL_EXPORTED_FUNCTIONS, content_hash
from mrpctl.errors import SpecificationError
from mrpctl.flight import Hysteretic
from mrpctl.model import gain_from_pd, state
from mrpctl.spacecraft import Spacecraft

CRAFT = Spacecraft(np.array([[0.2, 0.01, 0.0], [0.01, 0.25, -0.005], [0.0, -0.005, 0.15]]))
WHEELS = WheelCluster.pyramid(
    2e-4, 5e-3, 300.0, speeds=[10.0, -20.0, 30.0, 5.0], null_gain=0.05, bias_speeds=[50.0, -50.0, 50.0, -50.0],
    gyroscopic=True,
)  # fmt: skip
K = gain_from_pd(CRAFT, -0.04 * np.ones(3), -0.4 * np.ones(3))


def _short(sigma: np.ndarray) -> np.ndarray:
    s2 = sigma @ sigma
    return -sigma / s2 if s2 > 1.0 else sigma


def test_exported_controller_gives_the_wheel_torques_of_the_simulated_loop(tmp_path) -> None:
    """d = 0, an ideal sensor: the controller sees x_meas = the recorded state; threaded through its memory it
    gives the run's motor torques at every sample, in the .casadi Function and in the C library."""
    x0 = state([0.5, -0.6, 0.4], [0.03, 0.02, -0.04])
    run = simulate(CRAFT, K, x0, tau=0.0, rule=Hysteretic(0.1), t_final=30.0, rate=10.0, wheels=WHEELS)
    assert run.wheels is not None
    result = export_wheel_controller(CRAFT, K, WHEELS, tmp_path / "out", tau=0.0, rule=Hysteretic(0.1), rate=10.0)
    manifest = json.loads((tmp_path / "out" / MANIFEST_NAME).read_text())
    assert tuple(manifest["functions"]) == WHEEL_EXPORTED_FUNCTIONS
    assert manifest["wheels"]["count"] == 4 and manifest["wheels"]["gyroscopic"] is True
    names = [path.name for path in result.files if path.name != MANIFEST_NAME]
    assert manifest["content_hash"]["value"] == content_hash(tmp_path / "out", names)
    controller = ca.Function.load(str(tmp_path / "out" / "wheel_controller.casadi"))
    functions = [controller]
    if find_compiler() is not None:
        assert result.library is not None
        functions.append(ca.external(C_PREFIX + "wheel_controller", str(result.library)))
    for function in functions:
        sigma0 = _short(run.sigma[0])
        memory = np.array([1.0, 1.0, *sigma0])
        motors = []
        for sigma, omega, speeds in zip(run.sigma, run.omega, run.wheels.speeds, strict=True):
            x_meas = np.concatenate((sigma, omega / 4.0))
            out = function(x_meas, memory, speeds)
            motors.append(np.asarray(out[0]).ravel())
            memory = np.asarray(out[2]).ravel()
        motors = np.array(motors)
        assert np.abs(motors - run.wheels.motor_torque).max() <= 1e-15 * np.abs(run.wheels.motor_torque).max()
    assert np.any(np.abs(run.wheels.motor_torque) == WHEELS.torque_limit)  # the clip is part of what was checked


def test_exported_controller_allocation_matches_the_reference(tmp_path) -> None:
    rng = np.random.default_rng(3)
    export_wheel_controller(CRAFT, K, WHEELS, tmp_path / "out", tau=0.0, compile=False)
    controller = ca.Function.load(str(tmp_path / "out" / "wheel_controller.casadi"))
    reference = Wheels(
        axes=np.array(WHEELS.spin_axes), js=np.array(WHEELS.spin_inertia), u_max=np.array(WHEELS.torque_limit),
        omega_max=np.array(WHEELS.speed_limit), viscous=np.zeros(4), coulomb=np.zeros(4), cycle=np.ones(4),
        speeds=np.zeros(4), null_gain=WHEELS.null_gain, bias=np.array(WHEELS.bias_speeds), gyroscopic=True,
    )  # fmt: skip
    for _ in range(20):
        sigma = rng.uniform(-0.5, 0.5, 3)
        omega = rng.normal(scale=0.05, size=3)
        speeds = rng.uniform(-320.0, 320.0, 4)
        out = controller(np.concatenate((sigma, omega / 4.0)), np.array([1.0, 1.0, *sigma]), speeds)
        command = K @ np.concatenate((sigma, omega / 4.0))  # h = c = +1, no flip: σ_c = σ
        motor, _, _ = allocate(reference, command, omega, speeds, CRAFT.inertia)
        np.testing.assert_allclose(np.asarray(out[3]).ravel(), command, rtol=1e-14, atol=1e-18)
        np.testing.assert_allclose(np.asarray(out[0]).ravel(), motor, rtol=1e-12, atol=1e-17)


def test_export_wheel_controller_refuses_bad_input(tmp_path) -> None:
    with pytest.raises(SpecificationError, match="WheelCluster"):
        export_wheel_controller(CRAFT, K, np.eye(3), tmp_path / "a", tau=0.0, compile=False)
    with pytest.raises(SpecificationError, match="Hysteretic"):
        export_wheel_controller(CRAFT, K, WHEELS, tmp_path / "b", tau=0.0, rule="OnCurrent", compile=False)
