"""The rate-limited MRP steering law on a reaction-wheel cluster: against the separately written NumPy reference
(tests/wheels_reference.py, its own steering law), the lanes against the scalar engine bit for bit, and the
design for a wheel cluster (design_for_actuator) against hand-computed numbers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_wheels import _reference_wheels, _relative
from wheels_reference import wheel_loop

from mrpctl import simulate, simulate_batch
from mrpctl.errors import SpecificationError
from mrpctl.flight import Hysteretic, SensorModel
from mrpctl.flight.steering import SteeringLaw
from mrpctl.model import gain_from_pd, state
from mrpctl.spacecraft import Spacecraft
from mrpctl.wheels import WheelCluster

CUBESAT = Spacecraft(np.diag([0.2, 0.25, 0.15]))
J_FULL = np.array([[0.2, 0.01, 0.0], [0.01, 0.25, -0.005], [0.0, -0.005, 0.15]])
SPEED_LIMIT = 6000.0 * 2.0 * math.pi / 60.0  # rad/s
SPIN_INERTIA = 0.02 / SPEED_LIMIT  # 20 mN m s at 6000 rpm


def _gain(spacecraft: Spacecraft) -> np.ndarray:
    return gain_from_pd(spacecraft, -0.3 * np.ones(3), -1.2 * np.ones(3))


_AWAY = np.array([0.9, 0.3, -0.2]) / np.linalg.norm([0.9, 0.3, -0.2])
CASES = {
    # the cubesat's cluster (5 mN m, 20 mN m s), a slew of ~150 degrees: the law's momentum limit (the wheels'
    # 0.02 N m s, 0.08 to 0.13 rad/s) acts below its rate limit, then the linear law
    "orthogonal": dict(
        inertia=np.diag([0.2, 0.25, 0.15]),
        wheels=WheelCluster.orthogonal(SPIN_INERTIA, 5e-3, SPEED_LIMIT),
        law=SteeringLaw(0.2, 0.012, 0.45, momentum_limit=0.02, spacecraft=CUBESAT),
        x0=([0.5, -0.6, 0.4], [0.01, 0.005, -0.01]),
        tau=0.2,
        rate=10.0,
        t_final=80.0,
        substeps=2,
        delta=0.0,
    ),
    # a pyramid with friction, null space, the gyroscopic term, a full inertia; a law whose rate limit the
    # wheels' speed limit cuts (the speed cut acts); 179.4 degrees from the target turning away: the set switches
    "pyramid": dict(
        inertia=J_FULL,
        wheels=WheelCluster.pyramid(
            2e-4,
            5e-3,
            60.0,
            viscous=1e-7,
            coulomb=1e-5,
            speeds=[10.0, -20.0, 30.0, 5.0],
            null_gain=0.02,
            gyroscopic=True,
        ),
        law=SteeringLaw(0.3, 0.02, 0.3),
        x0=(0.99 * _AWAY, 0.05 * _AWAY),
        tau=0.3,
        rate=10.0,
        t_final=60.0,
        substeps=1,
        delta=0.0,
    ),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_steering_law_on_wheels_matches_the_numpy_reference_at_every_sample(name: str) -> None:
    case = CASES[name]
    spacecraft = Spacecraft(case["inertia"])
    wheels, law = case["wheels"], case["law"]
    K = _gain(spacecraft)
    x0 = state(*case["x0"])
    common = dict(rate=case["rate"], t_final=case["t_final"], substeps=case["substeps"])
    result = simulate(
        spacecraft, K, x0, tau=case["tau"], rule=Hysteretic(case["delta"]), wheels=wheels, law=law, **common
    )
    reference_args = dict(d=round(case["tau"] * case["rate"]), delta=case["delta"], **common)
    inertia = None if law.spacecraft is None else np.array(case["inertia"])
    steering = (law.rate_limit, law.acceleration, law.lag, law.momentum_limit, inertia)
    reference = wheel_loop(case["inertia"], K, x0, _reference_wheels(wheels), steering=steering, **reference_args)
    assert result.wheels is not None and result.sigma.shape == reference.sigma.shape
    assert _relative(result.sigma, reference.sigma) <= 1e-12
    assert _relative(result.omega, reference.omega) <= 1e-12
    assert _relative(result.wheels.speeds, reference.speeds) <= 1e-12
    assert _relative(result.wheels.motor_torque, reference.motor) <= 1e-12
    assert _relative(result.u, reference.body) <= 1e-12
    assert _relative(result.command, reference.command) <= 1e-12
    rate = case["rate"]
    np.testing.assert_array_equal(result.wheels.torque_limited_time, reference.torque_limited.sum(axis=0) / rate)
    np.testing.assert_array_equal(result.wheels.speed_limited_time, reference.speed_limited.sum(axis=0) / rate)
    # the law acted: the PD law's request from the same run differs by far
    pd = wheel_loop(case["inertia"], K, x0, _reference_wheels(wheels), **reference_args)
    assert np.abs(pd.command - reference.command).max() > 0.5 * np.abs(reference.command).max()
    # the law's rate limit holds once the initial rate is gone (up to the loop's overshoot)
    assert np.linalg.norm(result.omega, axis=1).max() <= 1.2 * max(law.rate_limit, np.linalg.norm(x0[3:]) * 4.0)
    if name == "pyramid":
        assert np.any(reference.speed_limited) and np.any(reference.torque_limited) and result.switch_count > 0
    else:  # the momentum limit keeps the body's momentum at the wheels' 0.02 N m s: no wheel at its speed limit
        assert np.linalg.norm(result.omega @ case["inertia"], axis=1).max() <= 1.01 * law.momentum_limit
        assert not np.any(reference.speed_limited)
        assert np.any(reference.torque_limited) and result.settling_time is not None


@pytest.mark.parametrize("noisy", [False, True])
def test_simulate_batch_with_the_law_on_wheels_equals_simulate_run_by_run(noisy: bool) -> None:
    """Metrics only on the wheel lane engine with the law compiled in, and with trajectories on the scalar engine:
    each run bit for bit simulate's."""
    from mrpctl._compile import find_compiler
    from mrpctl.engines import lanes

    case = CASES["pyramid"]
    wheels, law = case["wheels"], case["law"]
    sensor = SensorModel(attitude_noise=1e-3, rate_noise=1e-4, gyro_bias=[1e-4, 0.0, 0.0], seed=3) if noisy else None
    K = _gain(CUBESAT)
    x0 = state(
        [[0.5, -0.6, 0.4], [0.1, 0.2, -0.3], [-0.8, 0.1, 0.0]], [[0.03, 0.02, -0.04], [0.0, 0.0, 0.0], [0.0, 0.05, 0.0]]
    )
    run = dict(tau=0.2, rule=Hysteretic(0.1), t_final=40.0, rate=10.0, wheels=wheels, sensor=sensor, law=law)
    singles = [simulate(CUBESAT, K, x, **run) for x in x0]
    for trajectories in (False, True):
        batch = simulate_batch(CUBESAT, K, x0, trajectories=trajectories, threads=2, **run)
        if not trajectories and find_compiler() is not None:  # the lane engine of this law ran them
            assert any(key[0] == "wheels" and key[-1] == law for key in lanes._ENGINES)
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
                np.testing.assert_array_equal(each.sigma, single.sigma)
                np.testing.assert_array_equal(each.u, single.u)


def test_law_far_inside_its_limit_is_the_pd_law_on_wheels() -> None:
    """A rate limit and deceleration far above what the run asks: s = 1 at every sample, the PD run to
    round-off (the sum is ordered differently)."""
    wheels = WheelCluster.orthogonal(SPIN_INERTIA, 5e-3, SPEED_LIMIT)
    K = _gain(CUBESAT)
    x0 = state([0.05, -0.02, 0.03], [0.0, 0.0, 0.0])
    run = dict(tau=0.2, rule=Hysteretic(0.0), t_final=30.0, rate=10.0, wheels=wheels)
    pd = simulate(CUBESAT, K, x0, **run)
    steered = simulate(CUBESAT, K, x0, law=SteeringLaw(10.0, 100.0, 0.0), **run)
    assert _relative(steered.sigma, pd.sigma) <= 1e-13
    assert _relative(steered.command, pd.command) <= 1e-13


def test_law_on_wheels_needs_an_invertible_rate_block() -> None:
    wheels = WheelCluster.orthogonal(SPIN_INERTIA, 5e-3, SPEED_LIMIT)
    K = _gain(CUBESAT)
    K[:, 3:6] = 0.0
    with pytest.raises(SpecificationError, match="rate block"):
        simulate(CUBESAT, K, state([0.1, 0, 0], [0, 0, 0]), tau=0.2, rule=Hysteretic(0.0), t_final=1.0, rate=10.0,
                 wheels=wheels, law=SteeringLaw(0.1, 0.01, 0.4))  # fmt: skip


# ---------------------------------------------------------------------------------------------- the design
def test_guaranteed_torque_and_momentum_of_a_cluster_by_hand() -> None:
    from mrpctl.design.actuator import guaranteed_momentum, guaranteed_torque

    orthogonal = WheelCluster.orthogonal(SPIN_INERTIA, 5e-3, SPEED_LIMIT, speeds=[100.0, -200.0, 0.0])
    low, high = guaranteed_torque(orthogonal)
    assert low == pytest.approx(5e-3, rel=1e-15) and high == pytest.approx(math.sqrt(3.0) * 5e-3, rel=1e-15)
    # the wheel at -200 rad/s has the least to spare
    assert guaranteed_momentum(orthogonal) == pytest.approx(SPIN_INERTIA * (SPEED_LIMIT - 200.0), rel=1e-14)
    # pyramid at atan(1/√2): Gs Gsᵀ = (4/3) I, so pinv(Gs) = (3/4) Gsᵀ, rows of norm 3/4; the largest body torque
    # is 4 sin(β) u = (4/√3) u (all motors alike, or two pairs opposed)
    pyramid = WheelCluster.pyramid(SPIN_INERTIA, 5e-3, SPEED_LIMIT)
    low, high = guaranteed_torque(pyramid)
    assert low == pytest.approx(5e-3 / 0.75, rel=1e-14) and high == pytest.approx(
        4.0 / math.sqrt(3.0) * 5e-3, rel=1e-14
    )
    assert guaranteed_momentum(pyramid) == pytest.approx(0.02 / 0.75, rel=1e-14)


def test_design_for_a_wheel_cluster_bounds_the_commanded_momentum() -> None:
    from mrpctl.design.actuator import ActuatorDesignStatus, design_for_actuator
    from mrpctl.flight import ActuatorModel

    wheels = WheelCluster.orthogonal(SPIN_INERTIA, 5e-3, SPEED_LIMIT)
    ideal = design_for_actuator(CUBESAT, 0.2, ActuatorModel(5e-3), max_rate=0.05)
    design = design_for_actuator(CUBESAT, 0.2, wheels, max_rate=0.05)
    assert design.torque == ideal.torque and design.lower_bound == ideal.lower_bound
    np.testing.assert_array_equal(design.K, ideal.K)
    law = design.law
    assert (law.rate_limit, law.acceleration, law.lag) == (ideal.law.rate_limit, ideal.law.acceleration, ideal.law.lag)
    assert law.momentum_limit == pytest.approx(0.02, rel=1e-14) and law.spacecraft == CUBESAT
    assert design.momentum == law.momentum_limit and ideal.momentum is None
    # the prediction's worst cruise: the 0.02 N m s less the envelope's 0.25 * 0.05, over J_max; only the slew
    # of π changes against the ideal design's (stop, lag and tail are the same)
    cruise = (0.02 - 0.25 * 0.05) / 0.25
    a, w = law.acceleration, ideal.law.rate_limit
    slew = (math.pi / cruise + cruise / a) - (math.pi / w + w / a)
    assert design.predicted_time - ideal.predicted_time == pytest.approx(slew, rel=1e-9)
    assert design.status is ActuatorDesignStatus.NOT_MET and "0.0075 N m s" in design.reason
    assert "momentum limit 0.02 N m s" in str(design)
    # an envelope whose initial momentum alone fills the wheels: no cruise left
    full = design_for_actuator(CUBESAT, 0.2, wheels, max_rate=0.1, settling_time=300.0)
    assert full.predicted_time == math.inf and full.status is ActuatorDesignStatus.NOT_MET


@pytest.mark.parametrize(
    ("actuator", "words"),
    [
        (WheelCluster.pyramid(2e-4, 5e-3, 300.0, control_axes=[[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]), "control_axes"),
        (WheelCluster.orthogonal(2e-4, 5e-3, 300.0, speeds=[300.0, 0.0, 0.0]), "speed limit"),
        (np.eye(3), "WheelCluster"),
    ],
)
def test_design_refuses_a_cluster_it_cannot_use(actuator: object, words: str) -> None:
    from mrpctl.design.actuator import design_for_actuator

    with pytest.raises(SpecificationError, match=words):
        design_for_actuator(CUBESAT, 0.2, actuator, max_rate=0.05)  # type: ignore[arg-type]


def test_momentum_limit_needs_its_spacecraft() -> None:
    with pytest.raises(SpecificationError, match="momentum_limit"):
        SteeringLaw(0.1, 0.01, 0.4, momentum_limit=0.02)
    with pytest.raises(SpecificationError, match="momentum_limit"):
        SteeringLaw(0.1, 0.01, 0.4, momentum_limit=-1.0, spacecraft=CUBESAT)
    with pytest.raises(SpecificationError, match="spacecraft"):
        SteeringLaw(0.1, 0.01, 0.4, momentum_limit=0.02, spacecraft=np.eye(3))  # type: ignore[arg-type]
    law = SteeringLaw(0.1, 0.01, 0.4, momentum_limit=0.02, spacecraft=CUBESAT)
    assert law.label() != SteeringLaw(0.1, 0.01, 0.4).label()
    assert SteeringLaw(0.1, 0.01, 0.4).label() == SteeringLaw(0.1, 0.01, 0.4, None, None).label()


def test_linear_radius_counts_the_momentum_limit() -> None:
    """s_K with a momentum limit h that binds first: h / ‖J 4 K_ω⁻¹ K_σ‖ (to the bisection's 1e-6)."""
    from mrpctl.design.attraction import linear_radius

    K = _gain(CUBESAT)
    free = linear_radius(SteeringLaw(0.2, 0.012, 0.4), K)
    bound = linear_radius(SteeringLaw(0.2, 0.012, 0.4, momentum_limit=1e-4, spacecraft=CUBESAT), K)
    expected = 1e-4 / np.linalg.norm(CUBESAT.inertia @ (4.0 * np.linalg.solve(K[:, 3:6], K[:, 0:3])), 2)
    assert expected < free and bound == pytest.approx(expected, rel=2e-6) and bound <= expected


def test_momentum_limit_on_an_ideal_torque_bounds_the_body_momentum() -> None:
    """The flight sample takes the same law: on a 5 mN m ideal torque the body's momentum follows the command's
    bound (0.01 N m s here, well below what the rate limit alone allows) to the rate loop's overshoot."""
    from mrpctl.flight import ActuatorModel

    K = _gain(CUBESAT)
    x0 = state([0.5, -0.6, 0.4], [0.0, 0.0, 0.0])
    run = dict(tau=0.2, rule=Hysteretic(0.0), t_final=120.0, rate=20.0, actuator=ActuatorModel(5e-3))
    free = simulate(CUBESAT, K, x0, law=SteeringLaw(0.2, 0.012, 0.45), **run)
    bound = simulate(CUBESAT, K, x0, law=SteeringLaw(0.2, 0.012, 0.45, momentum_limit=0.01, spacecraft=CUBESAT), **run)
    assert np.linalg.norm(free.omega @ CUBESAT.inertia, axis=1).max() > 0.02
    assert np.linalg.norm(bound.omega @ CUBESAT.inertia, axis=1).max() <= 1.05 * 0.01
    assert bound.settling_time is not None and free.settling_time is not None
    assert bound.settling_time > free.settling_time
