"""Scenario files of the loop as flown: [rule] type = "hysteretic", [actuator], [sensor], [disturbance], [delay]."""

from __future__ import annotations

import copy
import tomllib

import numpy as np
import pytest

from mrpctl import paper, simulate
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.flight import ActuatorModel, DelayKind, DelayModel, Disturbance, Hysteretic, Saturation, SensorModel
from mrpctl.reproduction import flight_scenarios
from mrpctl.scenario import load_scenario, parse_scenario, scenario_toml, shipped_scenarios

FULL = {
    "tau": 0.5,
    "t_final": 3.0,
    "spacecraft": {"inertia": [140.0, 100.0, 80.0]},
    "gains": {"k_sigma": -70.11, "k_omega": -163.08},
    "initial": {"sigma": [0.93, 0.0, 0.0], "omega": [0.46, 0.0, 0.0]},
    "rule": {"type": "hysteretic", "delta": 0.1},
    "actuator": {"u_max": [30.0, 25.0, 20.0], "u_norm": 35.0, "saturation": "clip"},
    "sensor": {"attitude_noise": 0.003, "rate_noise": 2e-4, "gyro_bias": [1e-4, 0.0, -1e-4], "seed": 7},
    "disturbance": {"torque": [1e-3, -1e-3, 0.0]},
    "delay": {"tau_min": 0.48, "seed": 4},
}


def _with(table: str, **changes) -> dict:
    data = copy.deepcopy(FULL)
    data[table].update(changes)
    return data


def _without(table: str, key: str) -> dict:
    data = copy.deepcopy(FULL)
    del data[table][key]
    return data


def test_every_flight_table_is_read() -> None:
    scenario = parse_scenario(FULL)
    assert scenario.rule == Hysteretic(0.1)
    assert np.array_equal(scenario.actuator.u_max, [30.0, 25.0, 20.0])
    assert scenario.actuator.norm_max == 35.0 and scenario.actuator.mode is Saturation.CLIP
    sensor = scenario.sensor
    assert (sensor.attitude_noise, sensor.rate_noise, sensor.seed) == (0.003, 2e-4, 7)
    assert np.array_equal(sensor.gyro_bias, [1e-4, 0.0, -1e-4])
    assert np.array_equal(scenario.disturbance.torque, [1e-3, -1e-3, 0.0])
    delay = scenario.delay
    assert delay.kind is DelayKind.JITTER and (delay.tau_min, delay.tau_max, delay.seed) == (0.48, 0.5, 4)
    assert set(scenario.flight_options) == {"actuator", "sensor", "disturbance", "delay"}
    assert "ActuatorModel" in str(scenario) and "jitter" in str(scenario)


def test_alpha_gives_the_same_rule_as_its_delta_and_defaults() -> None:
    by_alpha = parse_scenario(_with("rule", delta=None) | {"rule": {"type": "hysteretic", "alpha": 1.2}})
    assert by_alpha.rule == Hysteretic.from_alpha(1.2)
    plain = parse_scenario(
        {key: value for key, value in FULL.items() if key in ("tau", "t_final", "spacecraft", "gains", "initial")}
        | {"rule": {"type": "hysteretic"}, "actuator": {"u_max": 5.0}}
    )
    assert plain.rule == Hysteretic(0.0) and plain.sensor is None and plain.delay is None
    assert np.array_equal(plain.actuator.u_max, [5.0, 5.0, 5.0]) and plain.actuator.mode is Saturation.SCALE


def test_the_scenario_runs_what_its_tables_say() -> None:
    """The file's models are those given to simulate by hand: the same run bit for bit."""
    run = parse_scenario(FULL).simulate()
    by_hand = simulate(
        paper.SPACECRAFT,
        paper.GAIN,
        np.array([0.93, 0.0, 0.0, 0.46 / 4, 0.0, 0.0]),
        tau=0.5,
        t_final=3.0,
        rule=Hysteretic(0.1),
        actuator=ActuatorModel([30.0, 25.0, 20.0], norm_max=35.0, mode=Saturation.CLIP),
        sensor=SensorModel(attitude_noise=0.003, rate_noise=2e-4, gyro_bias=[1e-4, 0.0, -1e-4], seed=7),
        disturbance=Disturbance([1e-3, -1e-3, 0.0]),
        delay=DelayModel.jitter(0.48, 0.5, seed=4),
    )
    assert np.array_equal(run.x0, by_hand.x0)
    assert np.array_equal(run.sigma, by_hand.sigma) and np.array_equal(run.u, by_hand.u)
    assert run.saturated_fraction == by_hand.saturated_fraction > 0


@pytest.mark.parametrize("data", [FULL, _with("rule", delta=0.0), {**FULL, "delay": {"tau_min": 0.5}}])
def test_scenario_toml_round_trips_the_flight_tables(data: dict) -> None:
    scenario = parse_scenario(data)
    again = parse_scenario(tomllib.loads(scenario_toml(scenario)))
    assert again.rule == scenario.rule
    for name in ("actuator", "sensor", "disturbance", "delay"):
        a, b = getattr(scenario, name), getattr(again, name)
        assert (a is None) == (b is None)
    assert np.array_equal(again.actuator.u_max, scenario.actuator.u_max)
    assert (again.actuator.norm_max, again.actuator.mode) == (scenario.actuator.norm_max, scenario.actuator.mode)
    for key in ("attitude_noise", "rate_noise", "seed"):
        assert getattr(again.sensor, key) == getattr(scenario.sensor, key)
    assert np.array_equal(again.sensor.gyro_bias, scenario.sensor.gyro_bias)
    assert np.array_equal(again.disturbance.torque, scenario.disturbance.torque)
    assert (again.delay.tau_min, again.delay.tau_max, again.delay.seed) == (
        scenario.delay.tau_min,
        scenario.delay.tau_max,
        scenario.delay.seed,
    )


def test_a_scenario_without_flight_tables_writes_none() -> None:
    text = scenario_toml(load_scenario("paper_fig4_on_delayed"))
    assert "[actuator]" not in text and "[sensor]" not in text and "[delay]" not in text


@pytest.mark.parametrize(
    ("data", "error", "pattern"),
    [
        (_with("rule", delta=1.0), SpecificationError, r"\[rule\] delta .* must be in \[0, 1\)"),
        (_with("rule", delta=-0.1), SpecificationError, r"\[rule\] delta"),
        (_with("rule", alpha=1.2), SpecificationError, r"\[rule\] .*delta or alpha.*not both"),
        (
            _with("rule", alpha=0.9) | {"rule": {"type": "hysteretic", "alpha": 0.9}},
            SpecificationError,
            r"alpha .* >= 1",
        ),
        ({**FULL, "rule": {"type": "on-delayed", "delta": 0.1}}, SpecificationError, r"delta applies only"),
        ({**FULL, "rule": {"type": "on-delayed"}}, SpecificationError, r"\[actuator\] applies only .*hysteretic"),
        (_with("actuator", u_max=0.0), SpecificationError, r"\[actuator\] u_max .* > 0"),
        (_with("actuator", u_max=[1.0, 2.0]), DimensionError, r"\[actuator\] u_max"),
        (_with("actuator", u_norm=-1.0), SpecificationError, r"\[actuator\] u_norm"),
        (_with("actuator", saturation="soft"), SpecificationError, r"\[actuator\] saturation must be one of"),
        (_without("actuator", "u_max"), SpecificationError, r"\[actuator\] needs u_max"),
        (_with("actuator", limit=3.0), SpecificationError, r"unknown key 'limit' in \[actuator\]"),
        (_with("sensor", attitude_noise=-0.01), SpecificationError, r"\[sensor\] attitude_noise"),
        (_with("sensor", rate_noise=float("nan")), SpecificationError, r"\[sensor\] rate_noise"),
        (_with("sensor", gyro_bias=[0.0, 1.0]), DimensionError, r"\[sensor\] gyro_bias"),
        (_with("sensor", seed=-1), SpecificationError, r"\[sensor\] seed"),
        (_with("sensor", seed=1.5), SpecificationError, r"\[sensor\] seed"),
        (_with("disturbance", torque=[[0.0, 0.0, 0.0]]), DimensionError, r"\[disturbance\] torque"),
        (_without("disturbance", "torque"), SpecificationError, r"\[disturbance\] needs torque"),
        (_with("delay", tau_max=0.4), SpecificationError, r"\[delay\] tau_max must equal .*tau"),
        (_with("delay", tau_min=0.6), SpecificationError, r"\[delay\] tau_max must be >= tau_min"),
        (_with("delay", tau_min=0.0), SpecificationError, r"\[delay\] tau_min must be >= 1/rate"),
        (_with("delay", tau_min=0.4805), SpecificationError, r"\[delay\] .*whole numbers of measurement periods"),
        (_without("delay", "tau_min"), SpecificationError, r"\[delay\] needs tau_min"),
        ({**FULL, "sensor": 3.0}, SpecificationError, r"\[sensor\] must be a table"),
    ],
)
def test_bad_flight_tables_are_refused_naming_the_key(data: dict, error: type, pattern: str) -> None:
    with pytest.raises(error, match=pattern):
        parse_scenario(data)


def test_the_shipped_flight_scenario_equals_the_builtin_one_and_runs() -> None:
    assert "flight-paper" in shipped_scenarios()
    from_file = load_scenario("flight-paper")
    builtin = flight_scenarios()["flight-paper"]
    assert from_file.rule == builtin.rule == Hysteretic.from_alpha(1.2)
    assert np.max(np.abs(from_file.x0 - builtin.x0)) < 1e-15
    assert np.array_equal(from_file.actuator.u_max, builtin.actuator.u_max)
    assert from_file.sensor.attitude_noise == builtin.sensor.attitude_noise and from_file.sensor.seed == 1
    assert np.array_equal(from_file.disturbance.torque, builtin.disturbance.torque)
    assert (from_file.delay.tau_min, from_file.delay.tau_max) == (builtin.delay.tau_min, builtin.delay.tau_max)
    run = from_file.simulate()
    assert run.converged and run.switch_count <= 2  # alpha = 1.2: at most a logic switch or two under the noise
    assert np.max(np.abs(run.u)) <= 20.0 and 0.0 < run.saturated_fraction < 0.5


def test_a_campaign_refuses_the_flight_tables_instead_of_dropping_them() -> None:
    from mrpctl.campaign.spec import parse_campaign

    with pytest.raises(SpecificationError, match=r"\[actuator\]: a campaign gives .* in its \[flight\] table"):
        parse_campaign({**copy.deepcopy(FULL), "count": 2, "seed": 1})


def test_a_saved_hysteretic_run_loads_back_with_its_delta(tmp_path) -> None:
    from mrpctl import data

    run = simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, tau=0.5, t_final=0.2, rule=Hysteretic(0.3))
    path = tmp_path / "run.nc"
    data.save(run, path)
    assert data.load(path).rule == Hysteretic(0.3)
