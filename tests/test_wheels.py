"""The wheel cluster in the compiled plant against an independent NumPy reference, momentum, allocation, bad input."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from wheels_reference import Wheels, wheel_loop

from mrpctl import simulate
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.flight import ActuatorModel, Hysteretic
from mrpctl.loop.wheels import wheel_allocation_function, wheel_step_function
from mrpctl.model import gain_from_pd, state
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import OnDelayed
from mrpctl.wheels import WheelCluster, allocation_matrix, null_space_projector

J_FULL = np.array([[0.2, 0.01, 0.0], [0.01, 0.25, -0.005], [0.0, -0.005, 0.15]])
CUBESAT = Spacecraft(np.diag([0.2, 0.25, 0.15]))


def _reference_wheels(w: WheelCluster) -> Wheels:
    return Wheels(
        axes=np.array(w.spin_axes),
        js=np.array(w.spin_inertia),
        u_max=np.array(w.torque_limit),
        omega_max=np.array(w.speed_limit),
        viscous=np.array(w.viscous),
        coulomb=np.array(w.coulomb),
        cycle=np.array(w.limit_cycle_speed),
        speeds=np.array(w.speeds),
        control=np.array(w.control_axes),
        null_gain=w.null_gain,
        bias=np.array(w.bias_speeds),
        gyroscopic=w.gyroscopic,
    )


def _relative(a: np.ndarray, b: np.ndarray) -> float:
    scale = float(np.abs(b).max())
    return float(np.abs(a - b).max()) / scale if scale > 0 else float(np.abs(a - b).max())


CASES = {
    # a pyramid with friction, null-space management, the gyroscopic term, a disturbance, 3 samples of delay
    "pyramid": dict(
        inertia=J_FULL,
        wheels=WheelCluster.pyramid(
            2e-4,
            5e-3,
            300.0,
            viscous=1e-7,
            coulomb=1e-5,
            speeds=[10.0, -20.0, 30.0, 5.0],
            null_gain=0.05,
            bias_speeds=[50.0, -50.0, 50.0, -50.0],
            gyroscopic=True,
        ),
        pd=(-0.04, -0.4),
        x0=([0.5, -0.6, 0.4], [0.03, 0.02, -0.04]),
        tau=0.3,
        rate=10.0,
        t_final=80.0,
        substeps=2,
        delta=0.1,
        disturbance=[1e-5, 0.0, -2e-5],
    ),
    # the same pyramid without friction (its RK4 stages take h_s at the stage times, three substeps, a full J)
    "pyramid_frictionless": dict(
        inertia=J_FULL,
        wheels=WheelCluster.pyramid(
            2e-4,
            5e-3,
            300.0,
            speeds=[10.0, -20.0, 30.0, 5.0],
            null_gain=0.05,
            bias_speeds=[50.0, -50.0, 50.0, -50.0],
            gyroscopic=True,
        ),
        pd=(-0.04, -0.4),
        x0=([0.5, -0.6, 0.4], [0.03, 0.02, -0.04]),
        tau=0.3,
        rate=10.0,
        t_final=80.0,
        substeps=3,
        delta=0.1,
        disturbance=[1e-5, 0.0, -2e-5],
    ),
    # three orthogonal wheels that reach their speed limit, a slew through 180 degrees (a shadow switch), d = 0
    "speed_limit": dict(
        inertia=np.diag([0.2, 0.25, 0.15]),
        wheels=WheelCluster.orthogonal(1e-4, [4e-3, 5e-3, 6e-3], [60.0, 80.0, 70.0], speeds=[50.0, -70.0, 0.0]),
        pd=(-0.05, -0.5),
        x0=([0.9, 0.3, -0.2], [0.08, 0.03, -0.02]),
        tau=0.0,
        rate=20.0,
        t_final=60.0,
        substeps=1,
        delta=0.2,
        disturbance=None,
    ),
    # one wheel about x with Coulomb friction inside its limit cycle, controlling the x axis only
    "one_wheel": dict(
        inertia=np.diag([0.2, 0.25, 0.15]),
        wheels=WheelCluster(
            np.array([[1.0], [0.0], [0.0]]),
            1e-4,
            2e-3,
            500.0,
            coulomb=2e-5,
            viscous=1e-7,
            limit_cycle_speed=0.5,
            speeds=0.2,
            control_axes=[[1.0, 0.0, 0.0]],
        ),
        pd=(-0.02, -0.3),
        x0=([0.2, 0.0, 0.0], [0.01, 0.0, 0.0]),
        tau=0.1,
        rate=10.0,
        t_final=40.0,
        substeps=4,
        delta=0.0,
        disturbance=None,
    ),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_compiled_wheel_loop_matches_the_numpy_reference_at_every_sample(name: str) -> None:
    case = CASES[name]
    spacecraft = Spacecraft(case["inertia"])
    wheels = case["wheels"]
    k1, k2 = case["pd"]
    K = gain_from_pd(spacecraft, k1 * np.ones(3), k2 * np.ones(3))
    x0 = state(*case["x0"])
    result = simulate(
        spacecraft,
        K,
        x0,
        tau=case["tau"],
        rule=Hysteretic(case["delta"]),
        t_final=case["t_final"],
        rate=case["rate"],
        substeps=case["substeps"],
        wheels=wheels,
        disturbance=case["disturbance"],
    )
    reference = wheel_loop(
        case["inertia"],
        K,
        x0,
        _reference_wheels(wheels),
        rate=case["rate"],
        t_final=case["t_final"],
        d=round(case["tau"] * case["rate"]),
        delta=case["delta"],
        substeps=case["substeps"],
        disturbance=case["disturbance"],
    )
    assert result.wheels is not None
    assert result.sigma.shape == reference.sigma.shape
    assert _relative(result.sigma, reference.sigma) <= 1e-12
    assert _relative(result.omega, reference.omega) <= 1e-12
    assert _relative(result.wheels.speeds, reference.speeds) <= 1e-12
    assert _relative(result.wheels.motor_torque, reference.motor) <= 1e-12
    assert _relative(result.u, reference.body) <= 1e-12
    assert _relative(result.command, reference.command) <= 1e-12
    rate = case["rate"]
    np.testing.assert_array_equal(result.wheels.torque_limited_time, reference.torque_limited.sum(axis=0) / rate)
    np.testing.assert_array_equal(result.wheels.speed_limited_time, reference.speed_limited.sum(axis=0) / rate)
    np.testing.assert_allclose(result.wheels.peak_speed, np.abs(reference.speeds).max(axis=0), rtol=1e-12)
    np.testing.assert_allclose(result.wheels.final_speeds, reference.final_speeds, rtol=1e-12, atol=1e-12)
    momentum = np.linalg.norm(reference.speeds * wheels.spin_inertia @ wheels.spin_axes.T, axis=1).max()
    assert result.wheels.peak_momentum == pytest.approx(momentum, rel=1e-12)
    assert result.saturated_fraction == pytest.approx(np.any(reference.torque_limited, axis=1).mean(), abs=0)
    # each case exercises what it is there for
    if name == "speed_limit":
        assert np.any(reference.speed_limited) and result.switch_count > 0
    if name.startswith("pyramid"):
        assert np.any(reference.torque_limited)
    if name == "one_wheel":
        assert np.any(np.abs(reference.speeds) < wheels.limit_cycle_speed)
        assert np.any(np.abs(reference.speeds) > wheels.limit_cycle_speed)


def _dcm(sigma: np.ndarray) -> np.ndarray:
    s2 = sigma @ sigma
    skew = np.array([[0.0, -sigma[2], sigma[1]], [sigma[2], 0.0, -sigma[0]], [-sigma[1], sigma[0], 0.0]])
    return np.eye(3) + (8.0 * skew @ skew - 4.0 * (1.0 - s2) * skew) / (1.0 + s2) ** 2


@pytest.mark.parametrize(("control", "friction"), [(False, False), (True, True)])
def test_total_angular_momentum_is_conserved_without_external_torque(control: bool, friction: bool) -> None:
    """H_N = [NB] (J ω + Gs diag(Js) Ω): the motor torques and friction are internal; 600 s at 100 Hz."""
    spacecraft = Spacecraft(J_FULL)
    options = dict(viscous=1e-7, coulomb=1e-5) if friction else {}
    wheels = WheelCluster.pyramid(2e-4, 5e-3, 600.0, speeds=[100.0, -200.0, 300.0, 50.0], **options)
    K = gain_from_pd(spacecraft, -0.04 * np.ones(3), -0.4 * np.ones(3)) * (1.0 if control else 0.0)
    x0 = state([0.2, -0.3, 0.1], [0.03, 0.02, -0.04])
    result = simulate(spacecraft, K, x0, tau=0.2, rule=Hysteretic(0.1), t_final=600.0, rate=100.0, wheels=wheels)
    assert result.wheels is not None and result.samples == 60001
    body = result.omega @ J_FULL.T + wheels.momentum(result.wheels.speeds)
    inertial = np.einsum("kji,kj->ki", np.array([_dcm(s) for s in result.sigma]), body)
    drift = np.abs(inertial - inertial[0]).max() / np.linalg.norm(inertial[0])
    assert drift <= 1e-12
    if control:  # the wheels did exchange momentum with the body
        assert np.abs(result.wheels.speeds[-1] - wheels.speeds).max() > 1.0


def test_allocation_is_the_minimum_norm_pseudo_inverse() -> None:
    rng = np.random.default_rng(7)
    for count in (3, 4, 5, 6):
        axes = rng.normal(size=(3, count))
        axes /= np.linalg.norm(axes, axis=0)
        wheels = WheelCluster(axes, 1e-4, 1.0, 1e3)
        allocation = allocation_matrix(wheels)
        np.testing.assert_allclose(allocation, -np.linalg.pinv(axes), rtol=0, atol=1e-13)
        u = rng.normal(size=3)
        np.testing.assert_allclose(-axes @ (allocation @ u), u, rtol=0, atol=1e-14)
    # two control axes of a pyramid: the torque about them only, minimum norm
    control = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    wheels = WheelCluster.pyramid(1e-4, 1.0, 1e3, control_axes=control)
    expected = -np.linalg.pinv(control @ wheels.spin_axes) @ control
    np.testing.assert_allclose(allocation_matrix(wheels), expected, rtol=0, atol=1e-14)


def test_null_space_management_makes_no_body_torque() -> None:
    wheels = WheelCluster.pyramid(2e-4, 1.0, 1e4, speeds=0.0, null_gain=0.3, bias_speeds=[100.0, -100.0, 100.0, -100.0])
    projector = null_space_projector(wheels)
    assert np.abs(wheels.spin_axes @ projector).max() <= 1e-15
    allocation = wheel_allocation_function(CUBESAT, wheels)
    speeds = np.array([300.0, 10.0, -250.0, 40.0])
    motor, body, limited, cut = (np.asarray(v).ravel() for v in allocation(np.zeros(3), np.zeros(3), speeds))
    assert np.abs(motor).max() > 1e-3  # the null-space term acts
    # and gives no body torque: zero to round-off, bounded relative to the terms that cancel (|Gs| |motor|, times
    # 16 eps for the projector's and the sum's roundings); an absolute 1e-17 held on one CPU and not on another
    assert np.all(np.abs(body) <= 16 * np.finfo(float).eps * (np.abs(wheels.spin_axes) @ np.abs(motor)))
    assert not limited.any() and not cut.any()
    # toward the bias: d/dt of Js (Ω − Ω_bias) along the null space is −k P Js (Ω − Ω_bias)
    error = wheels.spin_inertia * (speeds - wheels.bias_speeds)
    assert float(motor @ (projector @ error)) < 0.0


def test_each_wheel_is_clipped_on_its_own_and_cut_at_its_speed_limit() -> None:
    wheels = WheelCluster.orthogonal(1e-4, [1e-3, 2e-3, 3e-3], 100.0)
    allocation = wheel_allocation_function(CUBESAT, wheels)
    command = np.array([5e-3, -1e-3, 1e-2])  # body torque request; the motors take minus it
    motor, body, limited, cut = (np.asarray(v).ravel() for v in allocation(command, np.zeros(3), np.zeros(3)))
    np.testing.assert_array_equal(motor, [-1e-3, 1e-3, -3e-3])
    np.testing.assert_array_equal(limited, [1.0, 0.0, 1.0])
    np.testing.assert_array_equal(body, -motor)
    # at Ω_max: no torque that would spin a wheel faster; a torque that slows it passes
    speeds = np.array([-100.0, -100.0, -100.5])
    motor, body, limited, cut = (np.asarray(v).ravel() for v in allocation(command, np.zeros(3), speeds))
    np.testing.assert_array_equal(motor, [0.0, 1e-3, 0.0])
    np.testing.assert_array_equal(cut, [1.0, 0.0, 1.0])


def test_gyroscopic_term_is_mrp_feedbacks() -> None:
    wheels = WheelCluster.orthogonal(1e-3, 10.0, 1e4, gyroscopic=True)
    allocation = wheel_allocation_function(CUBESAT, wheels)
    omega = np.array([0.1, -0.2, 0.3])
    speeds = np.array([100.0, 50.0, -20.0])
    body = np.asarray(allocation(np.zeros(3), omega, speeds)[1]).ravel()
    spin = 1e-3 * (omega + speeds)
    expected = np.cross(omega, CUBESAT.inertia @ omega + spin)
    np.testing.assert_allclose(body, expected, rtol=1e-14, atol=0)


def test_the_allocation_sample_is_pure_sx() -> None:
    allocation = wheel_allocation_function(CUBESAT, WheelCluster.pyramid(1e-4, 1e-3, 100.0))
    assert isinstance(allocation.sx_in(0), ca.SX)


# ---------------------------------------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    ("arguments", "error", "words"),
    [
        (
            dict(spin_axes=np.eye(3), spin_inertia=np.nan, torque_limit=1.0, speed_limit=1.0),
            SpecificationError,
            "spin_inertia",
        ),
        (
            dict(spin_axes=np.eye(3), spin_inertia=0.0, torque_limit=1.0, speed_limit=1.0),
            SpecificationError,
            "spin_inertia",
        ),
        (
            dict(spin_axes=np.eye(3), spin_inertia=1e-4, torque_limit=-1.0, speed_limit=1.0),
            SpecificationError,
            "torque_limit",
        ),
        (
            dict(spin_axes=np.eye(3), spin_inertia=1e-4, torque_limit=1.0, speed_limit=0.0),
            SpecificationError,
            "speed_limit",
        ),
        (
            dict(spin_axes=np.eye(3), spin_inertia=1e-4, torque_limit=[1.0, 1.0], speed_limit=1.0),
            DimensionError,
            "torque_limit",
        ),
        (
            dict(spin_axes=np.eye(3), spin_inertia=1e-4, torque_limit=1.0, speed_limit=1.0, viscous=-1.0),
            SpecificationError,
            "viscous",
        ),
        (
            dict(spin_axes=np.eye(3), spin_inertia=1e-4, torque_limit=1.0, speed_limit=1.0, speeds=[0.0, np.inf, 0.0]),
            SpecificationError,
            "speeds",
        ),
        (
            dict(spin_axes=np.ones((3, 2)) / np.sqrt(3), spin_inertia=1e-4, torque_limit=1.0, speed_limit=1.0),
            SpecificationError,
            "rank",
        ),
        (
            dict(spin_axes=np.eye(3)[:, :2], spin_inertia=1e-4, torque_limit=1.0, speed_limit=1.0),
            SpecificationError,
            "spin_axes",
        ),
        (
            dict(spin_axes=2 * np.eye(3), spin_inertia=1e-4, torque_limit=1.0, speed_limit=1.0),
            SpecificationError,
            "unit",
        ),
        (dict(spin_axes=np.eye(4), spin_inertia=1e-4, torque_limit=1.0, speed_limit=1.0), DimensionError, "spin_axes"),
        (
            dict(spin_axes=np.full((3, 3), np.nan), spin_inertia=1e-4, torque_limit=1.0, speed_limit=1.0),
            SpecificationError,
            "spin_axes",
        ),
        (
            dict(spin_axes=np.eye(3), spin_inertia=1e-4, torque_limit=1.0, speed_limit=1.0, null_gain=0.1),
            SpecificationError,
            "null space",
        ),
        (
            dict(spin_axes=np.eye(3), spin_inertia=1e-4, torque_limit=1.0, speed_limit=1.0, control_axes=[[2.0, 0, 0]]),
            SpecificationError,
            "control_axes",
        ),
        (
            dict(spin_axes=np.eye(3), spin_inertia=1e-4, torque_limit=1.0, speed_limit=1.0, gyroscopic=1),
            SpecificationError,
            "gyroscopic",
        ),
    ],
)
def test_bad_wheel_cluster_is_refused_naming_the_parameter(arguments: dict, error: type, words: str) -> None:
    with pytest.raises(error, match=words):
        WheelCluster(**arguments)


def test_bad_combinations_say_what_to_use() -> None:
    wheels = WheelCluster.orthogonal(1e-4, 5e-3, 600.0)
    K = gain_from_pd(CUBESAT, -0.04 * np.ones(3), -0.4 * np.ones(3))
    x0 = state([0.1, 0.0, 0.0], [0.0, 0.0, 0.0])
    run = dict(tau=0.2, t_final=1.0, rate=10.0)
    with pytest.raises(SpecificationError, match="Hysteretic"):
        simulate(CUBESAT, K, x0, rule=OnDelayed(), wheels=wheels, **run)
    with pytest.raises(SpecificationError, match="actuator"):
        simulate(CUBESAT, K, x0, rule=Hysteretic(0.1), wheels=wheels, actuator=ActuatorModel(u_max=1e-3), **run)
    with pytest.raises(SpecificationError, match="WheelCluster"):
        simulate(CUBESAT, K, x0, rule=Hysteretic(0.1), wheels=np.eye(3), **run)
    heavy = WheelCluster.orthogonal(0.2, 5e-3, 600.0)  # spin inertia as large as J
    with pytest.raises(SpecificationError, match="spin_inertia"):
        simulate(CUBESAT, K, x0, rule=Hysteretic(0.1), wheels=heavy, **run)
    reference = np.zeros((11, 9))
    with pytest.raises(SpecificationError, match="tracking a reference on a wheel cluster is not modelled"):
        simulate(CUBESAT, K, x0, rule=Hysteretic(0.1), wheels=wheels, reference=reference, **run)
    from mrpctl import simulate_batch

    with pytest.raises(SpecificationError, match="tracking a reference on a wheel cluster is not modelled"):
        simulate_batch(CUBESAT, K, [x0, x0], rule=Hysteretic(0.1), wheels=wheels, reference=reference, **run)


def test_predictor_with_wheels_is_refused() -> None:
    from mrpctl.predictor import OnPredicted, Predictor

    wheels = WheelCluster.orthogonal(1e-4, 5e-3, 600.0)
    K = gain_from_pd(CUBESAT, -0.04 * np.ones(3), -0.4 * np.ones(3))
    x0 = state([0.1, 0.0, 0.0], [0.0, 0.0, 0.0])
    with pytest.raises(SpecificationError, match="predictor"):
        simulate(
            CUBESAT,
            K,
            x0,
            tau=0.2,
            t_final=1.0,
            rate=10.0,
            rule=OnPredicted(1.0),
            predictor=Predictor(CUBESAT),
            wheels=wheels,
        )


@pytest.mark.parametrize("noisy", [False, True])
def test_simulate_batch_on_wheels_equals_simulate_run_by_run(noisy: bool) -> None:
    """Metrics only (the lane engine, W runs per C call) and with trajectories (the scalar engine's thread pool):
    each run bit for bit simulate's."""
    from mrpctl import simulate_batch
    from mrpctl._compile import find_compiler
    from mrpctl.engines import lanes
    from mrpctl.flight import SensorModel

    wheels = WheelCluster.pyramid(
        2e-4, 5e-3, 300.0, speeds=[10.0, -20.0, 30.0, 5.0], viscous=1e-7, coulomb=1e-5, null_gain=0.02,
        gyroscopic=True,
    )  # fmt: skip
    sensor = SensorModel(attitude_noise=1e-3, rate_noise=1e-4, gyro_bias=[1e-4, 0.0, 0.0], seed=3) if noisy else None
    K = gain_from_pd(CUBESAT, -0.04 * np.ones(3), -0.4 * np.ones(3))
    x0 = state(
        [[0.5, -0.6, 0.4], [0.1, 0.2, -0.3], [-0.8, 0.1, 0.0]], [[0.03, 0.02, -0.04], [0.0, 0.0, 0.0], [0.0, 0.05, 0.0]]
    )
    run = dict(tau=0.2, rule=Hysteretic(0.1), t_final=40.0, rate=10.0, wheels=wheels, sensor=sensor)
    singles = [simulate(CUBESAT, K, x, **run) for x in x0]
    for trajectories in (False, True):
        batch = simulate_batch(CUBESAT, K, x0, trajectories=trajectories, threads=2, **run)
        if not trajectories and find_compiler() is not None:
            assert any(key[0] == "wheels" for key in lanes._ENGINES)  # the lane engine ran them
        assert batch.wheels is not None and len(batch.wheels) == 3
        for single, record, settled in zip(singles, batch.wheels, batch.settling_time, strict=True):
            assert single.wheels is not None
            np.testing.assert_array_equal(record.peak_speed, single.wheels.peak_speed)
            np.testing.assert_array_equal(record.final_speeds, single.wheels.final_speeds)
            np.testing.assert_array_equal(record.torque_limited_time, single.wheels.torque_limited_time)
            np.testing.assert_array_equal(record.speed_limited_time, single.wheels.speed_limited_time)
            assert record.peak_momentum == single.wheels.peak_momentum
            assert (settled == single.settling_time) or (np.isnan(settled) and single.settling_time is None)
        np.testing.assert_array_equal(batch.saturated_fraction, [s.saturated_fraction for s in singles])
        np.testing.assert_array_equal(batch.max_sigma, [s.max_sigma for s in singles])
        if trajectories:
            assert batch.runs is not None
            for single, each in zip(singles, batch.runs, strict=True):
                assert each.wheels is not None and single.wheels is not None
                np.testing.assert_array_equal(each.wheels.speeds, single.wheels.speeds)
                np.testing.assert_array_equal(each.sigma, single.sigma)
    with pytest.raises(SpecificationError, match="Hysteretic"):
        simulate_batch(CUBESAT, K, x0, tau=0.2, rule=OnDelayed(), t_final=1.0, rate=10.0, wheels=wheels)


def test_wheel_loop_with_a_sensor_and_a_per_sample_disturbance_matches_the_reference() -> None:
    """Attitude and rate noise, a gyro bias (the noise samples are data for the reference) and a torque per sample."""
    from mrpctl.flight import SensorModel

    spacecraft = Spacecraft(J_FULL)
    wheels = WheelCluster.pyramid(2e-4, 5e-3, 300.0, speeds=[10.0, -20.0, 30.0, 5.0], gyroscopic=True)
    K = gain_from_pd(spacecraft, -0.04 * np.ones(3), -0.4 * np.ones(3))
    x0 = state([0.5, -0.6, 0.4], [0.03, 0.02, -0.04])
    rate, t_final, n = 10.0, 50.0, 501
    sensor = SensorModel(attitude_noise=0.01, rate_noise=1e-3, gyro_bias=[1e-3, -2e-3, 5e-4], seed=4)
    torque = 1e-5 * np.sin(np.arange(n)[:, None] * np.array([0.1, 0.2, 0.3]))
    result = simulate(
        spacecraft, K, x0, tau=0.2, rule=Hysteretic(0.1), t_final=t_final, rate=rate, wheels=wheels,
        sensor=sensor, disturbance=torque,
    )  # fmt: skip
    reference = wheel_loop(
        J_FULL, K, x0, _reference_wheels(wheels), rate=rate, t_final=t_final, d=2, delta=0.1,
        disturbance=torque, noise=sensor.noise(0, n), bias=sensor.gyro_bias,
    )  # fmt: skip
    assert result.wheels is not None
    for ours, theirs in (
        (result.sigma, reference.sigma),
        (result.omega, reference.omega),
        (result.wheels.speeds, reference.speeds),
        (result.wheels.motor_torque, reference.motor),
        (result.command, reference.command),
    ):
        assert _relative(ours, theirs) <= 1e-12
    assert np.any(reference.torque_limited)


def test_progress_is_called_and_its_exception_stops_the_wheel_run() -> None:
    wheels = WheelCluster.orthogonal(1e-4, 5e-3, 600.0)
    K = gain_from_pd(CUBESAT, -0.04 * np.ones(3), -0.4 * np.ones(3))
    x0 = state([0.1, 0.0, 0.0], [0.0, 0.0, 0.0])
    seen: list[tuple[int, int]] = []
    simulate(CUBESAT, K, x0, tau=0.2, rule=Hysteretic(0.1), t_final=2.0, rate=10.0, wheels=wheels,
             progress=lambda done, total: seen.append((done, total)))  # fmt: skip
    assert seen == [(21, 21)]

    def interrupt(done: int, total: int) -> None:
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        simulate(CUBESAT, K, x0, tau=0.2, rule=Hysteretic(0.1), t_final=2.0, rate=10.0, wheels=wheels,
                 progress=interrupt)  # fmt: skip


@pytest.mark.parametrize("combination", ["zero-input", "jitter", "torque rows", "torque function"])
def test_wheels_with_the_flight_options_batch_equals_single(combination: str) -> None:
    """A zero-input history, a seeded jitter, a per-sample torque (rows or a function): the lanes' metrics-only
    batch gives each run's wheel metrics and settling as simulate does, bit for bit."""
    from mrpctl import simulate_batch
    from mrpctl.flight import DelayModel, Disturbance

    wheels = WheelCluster.orthogonal(1e-4, 5e-3, 300.0)
    K = gain_from_pd(CUBESAT, -0.04 * np.ones(3), -0.4 * np.ones(3))
    x0 = state([[0.3, 0.1, -0.2], [0.1, -0.4, 0.2]], [[0.01, 0.0, 0.0], [0.0, 0.02, 0.0]])
    options: dict = {
        "zero-input": dict(history="zero-input"),
        "jitter": dict(delay=DelayModel.jitter(0.1, 0.2, seed=1)),
        "torque rows": dict(disturbance=np.full((401, 3), 1e-5)),
        "torque function": dict(disturbance=Disturbance(function=lambda t: np.outer(np.sin(t), [1e-5, 0.0, 0.0]))),
    }[combination]
    run = dict(tau=0.2, rule=Hysteretic(0.1), t_final=40.0, rate=10.0, wheels=wheels, **options)
    singles = [simulate(CUBESAT, K, x, **run) for x in x0]
    batch = simulate_batch(CUBESAT, K, x0, **run)
    assert batch.wheels is not None
    for single, record in zip(singles, batch.wheels, strict=True):
        assert single.wheels is not None
        np.testing.assert_array_equal(record.final_speeds, single.wheels.final_speeds)
        np.testing.assert_array_equal(record.peak_speed, single.wheels.peak_speed)
    np.testing.assert_array_equal(
        batch.settling_time, [np.nan if s.settling_time is None else s.settling_time for s in singles]
    )
    if combination == "jitter":
        assert singles[0].delay_used is not None and len(set(singles[0].delay_used.tolist())) == 2


@pytest.mark.parametrize("substeps", [1, 4])
def test_one_step_from_rest_is_the_closed_form_of_the_wheel_equations(substeps: int) -> None:
    """From rest (ω = 0, Ω = 0), no friction, constant motor torques u_i on wheels along the principal axes:
    H = J ω + Js Ω stays 0, so ω × H = 0 and (J_ii − Js,i) ω̇_i = −u_i, Ω̇_i = u_i/Js,i − ω̇_i. Both are linear
    in t (RK4 integrates them exactly), ω_i(h) = −u_i h/(J_ii − Js,i), Ω_i(h) = u_i h J_ii/(Js,i (J_ii − Js,i)).
    The body turns about the fixed axis of ω by θ(t) = |ω̇| t²/2: σ(h) = tan(θ/4) ω̂, where RK4 is not exact
    (its truncation, 4.3e-11 relative with one substep, falls as substeps⁻⁴: 1.7e-13 with four)."""
    inertia = np.array([0.2, 0.25, 0.15])
    js = np.array([3e-5, 5e-5, 2e-5])
    wheels = WheelCluster.orthogonal(js, 1.0, 1e4)
    motor = np.array([3e-3, -2e-3, 1e-3])
    period = 0.1
    step = wheel_step_function(Spacecraft(np.diag(inertia)), wheels, period, substeps)
    x_next, speeds_next = (np.asarray(v).ravel() for v in step(np.zeros(6), np.zeros(3), motor, np.zeros(3)))
    omega = 4.0 * x_next[3:6]
    hub = inertia - js
    expected_omega = -motor * period / hub
    expected_speeds = motor * period * inertia / (js * hub)
    assert np.abs(omega - expected_omega).max() <= 1e-14 * np.abs(expected_omega).max()
    assert np.abs(speeds_next - expected_speeds).max() <= 1e-14 * np.abs(expected_speeds).max()
    momentum = inertia * omega + js * speeds_next  # zero: the motor torques are internal
    assert np.abs(momentum).max() <= 1e-14 * np.abs(inertia * omega).max()
    acceleration = np.linalg.norm(motor / hub)
    sigma = np.tan(acceleration * period**2 / 8.0) * expected_omega / np.linalg.norm(expected_omega)
    assert np.abs(x_next[0:3] - sigma).max() <= 1e-10 * np.abs(sigma).max()


def test_momentum_load_against_the_closed_forms() -> None:
    from mrpctl.wheels import WheelCluster, rest_momentum_load

    speed_limit = 6000.0 * 2.0 * np.pi / 60.0
    orthogonal = WheelCluster.orthogonal([3e-5, 4e-5, 5e-5], 5e-3, speed_limit)
    capacity = np.array([3e-5, 4e-5, 5e-5]) * speed_limit
    rng = np.random.default_rng(3)
    for h in rng.normal(scale=0.02, size=(5, 3)):
        # three wheels along the axes: each axis' momentum is its own wheel's, so the load is the largest ratio
        assert orthogonal.momentum_load(h) == pytest.approx(np.max(np.abs(h) / capacity), rel=1e-7)
    pyramid = WheelCluster.pyramid(3e-5, 5e-3, speed_limit)
    beta = np.arctan(1.0 / np.sqrt(2.0))
    # along the pyramid's axis the four wheels share the momentum equally: h = 4 sin(beta) Js Omega
    assert pyramid.momentum_load([0.0, 0.0, 0.01]) == pytest.approx(0.01 / (4 * np.sin(beta) * 3e-5 * speed_limit))
    # any cluster against a linear program written here: minimise t with Gs diag(Js) Omega = h, |Omega_i| <= t Omega_max
    from scipy.optimize import linprog

    axes = rng.normal(size=(3, 5))
    skewed = WheelCluster(
        axes / np.linalg.norm(axes, axis=0), rng.uniform(2e-5, 6e-5, 5), 5e-3, rng.uniform(300.0, 700.0, 5)
    )
    h = rng.normal(scale=0.01, size=(6, 3))
    n = skewed.count
    limits = skewed.speed_limit[:, None]
    bound = np.vstack((np.hstack((np.eye(n), -limits)), np.hstack((-np.eye(n), -limits))))
    columns = np.hstack((skewed.spin_axes * skewed.spin_inertia, np.zeros((3, 1))))
    cost = np.r_[np.zeros(n), 1.0]
    free = [(None, None)] * n + [(0.0, None)]
    expected = [linprog(cost, bound, np.zeros(2 * n), columns, row, bounds=free).fun for row in h]
    np.testing.assert_allclose(skewed.momentum_load(h), expected, rtol=1e-7)
    planar = WheelCluster(np.eye(3)[:, :2], [3e-5, 3e-5], 5e-3, speed_limit, control_axes=np.eye(3)[:2])
    assert planar.momentum_load([0.0, 0.0, 1e-3]) == np.inf  # no wheel spins about z
    assert planar.momentum_load([1e-3, 0.0, 0.0]) == pytest.approx(1e-3 / (3e-5 * speed_limit), rel=1e-7)
    # at rest at the origin: H_N = [BN]^T (J omega) with the body turned 90 deg about z
    sigma = np.array([0.0, 0.0, np.tan(np.pi / 8)])
    load = rest_momentum_load(orthogonal, np.diag([0.2, 0.25, 0.15]), sigma, [0.05, 0.0, 0.0])
    # the body's x axis is N's y axis: the x-momentum 0.01 N m s lands on the y wheel
    assert load == pytest.approx(0.2 * 0.05 / capacity[1], rel=1e-7)


@pytest.mark.parametrize("cluster", ["orthogonal", "pyramid"])
def test_a_sample_that_does_not_count_leaves_the_wheel_memory_as_it_was(cluster: str) -> None:
    """The lanes' wheel sample freezes its memory itself (the core's ``counted`` input): past the horizon and after
    a divergence the memory comes back bit for bit; a counted sample's memory is the unguarded sample's (the
    scalar engine's form, ``frozen_memory=False``) bit for bit."""
    from mrpctl.engines.scalar import engine_sample
    from mrpctl.engines.stats import S_DIVERGED, S_K, initial_stats
    from mrpctl.loop.wheels import wheel_core_function

    if cluster == "orthogonal":
        wheels = WheelCluster.orthogonal(3e-5, 5e-3, 600.0)
    else:
        wheels = WheelCluster.pyramid(2e-4, 5e-3, 300.0, viscous=1e-7, coulomb=1e-5, null_gain=0.05, gyroscopic=True)
    d = 2
    core = wheel_core_function(CUBESAT, wheels, d, 0.1, 1, sensor=False, disturbed=True)
    frozen, free = engine_sample(core, d, "frozen"), engine_sample(core, d, "free", frozen_memory=False)
    rng = np.random.default_rng(3)
    count = wheels.count
    memory = np.concatenate(
        (
            [1.0, 0.0],
            rng.uniform(-0.3, 0.3, 3),
            [4.0],
            rng.uniform(0.0, 1e-2, 4),  # the flight accumulators: a count, the peaks (the last one squared)
            rng.uniform(-500.0, 500.0, count),  # Ω, some past their speed limit
            rng.uniform(0.0, 600.0, count),
            rng.integers(0, 50, 2 * count).astype(float),
            [rng.uniform(0.0, 1e-3)],
        )
    )
    x = np.concatenate((rng.uniform(-0.3, 0.3, 3), rng.uniform(-0.01, 0.01, 3)))
    K = gain_from_pd(CUBESAT, -0.04 * np.ones(3), -0.4 * np.ones(3))
    flight = np.concatenate((np.full(4, np.inf), [1e-4, 0.0, -2e-4], np.zeros(3)))
    arguments = dict(x_delayed=np.concatenate((x[:3] * 1.01, x[3:])), K=K, parameters=[0.1], flight=flight)
    counted = initial_stats(100)
    counted[S_K] = 7.0
    past_horizon = counted.copy()
    past_horizon[S_K] = 100.0
    diverged = counted.copy()
    diverged[S_DIVERGED] = 5.0
    expected = np.asarray(free(x=x, memory=memory, stats=counted, **arguments)["memory_next"]).ravel()
    got = np.asarray(frozen(x=x, memory=memory, stats=counted, **arguments)["memory_next"]).ravel()
    np.testing.assert_array_equal(got, expected)
    assert np.any(got != memory)
    for stats in (past_horizon, diverged):
        still = np.asarray(frozen(x=x, memory=memory, stats=stats, **arguments)["memory_next"]).ravel()
        np.testing.assert_array_equal(still, memory)
        assert np.all(np.signbit(still) == np.signbit(memory))
