"""The steering law (mrpctl.flight.steering) in the compiled flight loop, and the design for the actuator
(mrpctl.design.actuator, ``mrpctl design --torque-limit``)."""

from __future__ import annotations

import json
import math

import casadi as ca
import numpy as np
import pytest
from cli_assertions import one_line_error

from mrpctl import OnCurrent, Spacecraft, simulate, simulate_batch
from mrpctl.cli import USER_ERROR, main
from mrpctl.design.actuator import ActuatorDesignStatus, design_for_actuator, slew_lower_bound
from mrpctl.errors import SpecificationError
from mrpctl.flight import ActuatorModel, Hysteretic
from mrpctl.flight.steering import SteeringLaw, steering_command_expr
from mrpctl.model import gain_from_pd

INERTIA = np.diag([0.2, 0.25, 0.15])
CUBESAT = Spacecraft(INERTIA)
K = gain_from_pd(CUBESAT, [-(2.2**2)] * 3, [-2 * 2.2] * 3)


def _numpy_command(law: SteeringLaw, gain: np.ndarray, sigma: np.ndarray, rate: np.ndarray) -> np.ndarray:
    """The steering law written again in NumPy from its definition (module docstring)."""
    k_sigma, k_omega = gain[:, 0:3], gain[:, 3:6]
    omega_lin = -4.0 * np.linalg.solve(k_omega, k_sigma @ sigma)
    angle = 4.0 * math.atan(float(np.linalg.norm(sigma)))
    a, lag = law.acceleration, law.lag
    limit = min(law.rate_limit, math.sqrt((a * lag) ** 2 + 2 * a * angle) - a * lag)
    size = float(np.linalg.norm(omega_lin))
    omega_c = omega_lin if size <= limit else omega_lin * limit / size
    return k_omega @ (rate - omega_c / 4.0)


def test_the_steering_command_equals_its_numpy_definition() -> None:
    law = SteeringLaw(0.15, 0.012, 0.4)
    gain = ca.SX.sym("K", 3, 6)
    sigma, rate = ca.SX.sym("s", 3), ca.SX.sym("w", 3)
    command = ca.Function("c", [gain, sigma, rate], [steering_command_expr(law, gain, sigma, rate)[0]])
    rng = np.random.default_rng(3)
    coupled = K + 0.3 * rng.normal(size=(3, 6))  # a full K_omega too
    for gain_value in (K, coupled):
        for size in (1e-4, 1e-3, 0.01, 0.3, 1.0):
            s = rng.normal(size=3)
            s *= size / np.linalg.norm(s)
            w = rng.normal(size=3) * 0.02
            expected = _numpy_command(law, gain_value, s, w)
            got = np.asarray(command(gain_value, s, w)).ravel()
            np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-15)


def test_without_its_limit_reached_the_law_is_the_pd_law() -> None:
    """A rate limit and deceleration no run reaches: the run is the PD run to round-off (a different sum order)."""
    x0 = np.array([0.02, -0.01, 0.015, 0.001, 0.0, -0.002])
    common = dict(tau=0.2, rule=Hysteretic(0.0), t_final=5.0, rate=100.0, actuator=ActuatorModel(1.0))
    pd = simulate(CUBESAT, K, x0, **common)
    steered = simulate(CUBESAT, K, x0, law=SteeringLaw(1e3, 1e6), **common)
    np.testing.assert_allclose(steered.sigma, pd.sigma, rtol=0, atol=1e-13)
    np.testing.assert_allclose(steered.omega, pd.omega, rtol=0, atol=1e-13)


def test_the_law_limits_the_rate_it_commands() -> None:
    """From rest at 120 deg the body turns no faster than the rate limit (plus the rate loop's overshoot)."""
    law = SteeringLaw(0.1, 0.012, 0.4)
    sigma0 = math.tan(math.radians(120) / 4) * np.array([0.0, 1.0, 0.0])
    run = simulate(
        CUBESAT,
        K,
        np.r_[sigma0, 0, 0, 0],
        tau=0.2,
        rule=Hysteretic(0.0),
        t_final=60.0,
        rate=100.0,
        actuator=ActuatorModel(5e-3),
        law=law,
    )
    peak = float(np.max(np.linalg.norm(run.omega, axis=1)))
    assert 0.09 < peak < 0.105
    assert run.settling_time is not None and run.settling_time < 40.0
    # the bang-bang bound of the slew and the law's trapezoid: 2 pi/3 / 0.1 + 0.1 / 0.012 = 29.3 s before the tail
    assert run.settling_time > slew_lower_bound(2 * math.pi / 3, 0.25, 5e-3)


def test_law_option_errors_name_the_parameter() -> None:
    x0 = np.zeros(6)
    with pytest.raises(SpecificationError, match="law: the steering law runs in the flight loop only"):
        simulate(CUBESAT, K, x0, tau=0.0, rule=OnCurrent(), t_final=1.0, law=SteeringLaw(0.1, 0.01))
    with pytest.raises(SpecificationError, match="law must be"):
        simulate(CUBESAT, K, x0, tau=0.0, rule=Hysteretic(0.0), t_final=1.0, law=(0.1, 0.01))
    singular = K.copy()
    singular[:, 3:6] = 0.0
    with pytest.raises(SpecificationError, match=r"K: the steering law needs an invertible rate block"):
        simulate(CUBESAT, singular, x0, tau=0.0, rule=Hysteretic(0.0), t_final=1.0, law=SteeringLaw(0.1, 0.01))
    with pytest.raises(SpecificationError, match="rate_limit must be > 0"):
        SteeringLaw(0.0, 0.01)
    with pytest.raises(SpecificationError, match="acceleration must be > 0"):
        SteeringLaw(0.1, -1.0)
    with pytest.raises(SpecificationError, match="lag must be >= 0"):
        SteeringLaw(0.1, 0.01, -0.1)
    with pytest.raises(SpecificationError, match="rate_limit"):
        SteeringLaw(math.nan, 0.01)


@pytest.fixture(scope="module")
def cubesat_design() -> object:
    return design_for_actuator(CUBESAT, 0.2, ActuatorModel(5e-3), max_rate=0.05)


def test_the_cubesat_design_and_its_numbers(cubesat_design: object) -> None:
    design = cubesat_design
    assert design.status is ActuatorDesignStatus.DESIGNED and design.designed
    assert design.law.acceleration == pytest.approx(0.6 * 5e-3 / 0.25)
    assert design.law.rate_limit == pytest.approx(math.sqrt(math.pi * 0.012))  # below the gyroscopic limit 0.2
    assert design.lower_bound == pytest.approx(2 * math.sqrt(math.pi * 0.15 / (5e-3 * math.sqrt(3))))
    assert design.lower_bound < design.predicted_time < 60.0
    text = str(design)
    assert "designed" in text and "rate limit 0.1942 rad/s" in text and "lower bound of any law 14.75 s" in text


def test_the_designed_law_settles_a_slice_of_the_envelope(cubesat_design: object) -> None:
    """24 runs of the envelope (the measurement, bench/actuator_design.py, has 300 and 1000): all within 60 s,
    against the PD law alone, which settles none of the same runs in 60 s."""
    rng = np.random.default_rng(11)
    q = rng.normal(size=(24, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    q[q[:, 0] < 0] *= -1
    axis = rng.normal(size=(24, 3))
    axis /= np.linalg.norm(axis, axis=1)[:, None]
    x0 = np.hstack((q[:, 1:] / (1 + q[:, 0:1]), rng.uniform(0, 0.05, (24, 1)) * axis / 4))
    common = dict(tau=0.2, rule=Hysteretic(0.0), t_final=70.0, rate=100.0, actuator=ActuatorModel(5e-3))
    steered = simulate_batch(CUBESAT, cubesat_design.K, x0, law=cubesat_design.law, **common)
    times = np.asarray(steered.settling_time)
    assert np.all(np.isfinite(times)) and np.all(times <= 60.0), times
    assert np.all(times <= cubesat_design.predicted_time)
    pd = simulate_batch(CUBESAT, cubesat_design.K, x0, **common)
    assert np.sum(np.asarray(pd.settling_time) <= 60.0) < 6


def test_an_envelope_no_law_can_recover_is_a_result(cubesat_design: object) -> None:
    infeasible = design_for_actuator(CUBESAT, 0.2, ActuatorModel(5e-3), max_rate=0.05, settling_time=10.0)
    assert infeasible.status is ActuatorDesignStatus.INFEASIBLE and not infeasible.designed
    assert "no law settles the envelope in 10 s" in infeasible.reason and "14.75 s" in infeasible.reason
    not_met = design_for_actuator(CUBESAT, 0.2, ActuatorModel(5e-3), max_rate=0.05, settling_time=20.0)
    assert not_met.status is ActuatorDesignStatus.NOT_MET
    # a spin the gyroscopic torque alone exceeds the torque at: the prediction is infinite, not a crash
    spin = design_for_actuator(CUBESAT, 0.2, ActuatorModel(5e-3), max_rate=1.0)
    assert spin.status is ActuatorDesignStatus.NOT_MET and math.isinf(spin.predicted_time)


@pytest.mark.parametrize(
    ("keywords", "match"),
    [
        ({"tau": 0.0}, "tau must be > 0"),
        ({"max_rate": -0.1}, "max_rate must be >= 0"),
        ({"max_rate": math.nan}, "max_rate"),
        ({"settling_time": 0.0}, "settling_time must be > 0"),
        ({"braking": 1.0}, "braking"),
        ({"actuator": 5e-3}, "actuator must be a mrpctl.flight.ActuatorModel"),
    ],
)
def test_bad_design_input_names_the_parameter(keywords: dict, match: str) -> None:
    arguments = {"tau": 0.2, "actuator": ActuatorModel(5e-3), "max_rate": 0.05} | keywords
    tau, actuator = arguments.pop("tau"), arguments.pop("actuator")
    with pytest.raises(SpecificationError, match=match):
        design_for_actuator(CUBESAT, tau, actuator, **arguments)


def test_a_non_positive_torque_limit_is_refused() -> None:
    with pytest.raises(SpecificationError, match=r"u_max \(per-axis torque limit, N m\) must be > 0"):
        ActuatorModel(0.0)


def test_cli_designs_for_the_actuator(capsys: pytest.CaptureFixture[str]) -> None:
    cubesat = ["design", "--inertia", "0.2", "0.25", "0.15", "--tau", "0.2"]
    assert main([*cubesat, "--torque-limit", "5e-3", "--max-rate", "0.05"]) == 0
    out = capsys.readouterr().out
    assert "designed" in out and "SteeringLaw (rate limit 0.1942 rad/s" in out
    for extra, needle in (
        (["--torque-limit", "5e-3", "--settling-time", "10"], "infeasible for any law"),
        (["--torque-limit", "0"], "--torque-limit must be > 0"),
        (["--torque-limit", "5e-3", "--max-rate", "-1"], "--max-rate must be >= 0"),
        (["--max-rate", "0.05"], "apply only with --torque-limit"),
        (["--torque-limit", "5e-3", "--sampled", "100"], "does not take --sampled"),
    ):
        assert main([*cubesat, *extra]) == USER_ERROR
        one_line_error(capsys, needle)


def test_a_batch_with_the_law_equals_its_single_runs() -> None:
    law = SteeringLaw(0.15, 0.012, 0.4)
    x0 = np.array([[0.3, -0.2, 0.1, 0.005, 0.0, -0.002], [-0.5, 0.4, 0.2, 0.0, 0.01, 0.0]])
    common = dict(tau=0.2, rule=Hysteretic(0.0), t_final=20.0, rate=100.0, actuator=ActuatorModel(5e-3), law=law)
    batch = simulate_batch(CUBESAT, K, x0, trajectories=True, **common)
    metrics = simulate_batch(CUBESAT, K, x0, **common)
    for i in range(2):
        single = simulate(CUBESAT, K, x0[i], **common)
        np.testing.assert_array_equal(batch.runs[i].sigma, single.sigma)
        np.testing.assert_array_equal(batch.runs[i].u, single.u)
        assert metrics.max_sigma[i] == batch.max_sigma[i]


def test_cli_json_of_the_actuator_design(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["design", "--inertia", "0.2", "0.25", "0.15", "--tau", "0.2", "--torque-limit", "5e-3", "--json"]
    assert main(argv) == 0
    payload = json.loads(capsys.readouterr().out)
    assert payload["status"] == "DESIGNED" and payload["rate_limit"] == pytest.approx(math.sqrt(math.pi * 0.012))
    assert np.shape(payload["K"]) == (3, 6)
