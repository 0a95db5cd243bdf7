"""Scenario files with the steering law: the [steering] table, read, refused, written back and flown."""

from __future__ import annotations

import copy
import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from cli_assertions import one_line_error

from mrpctl import simulate
from mrpctl.cli import USER_ERROR, main
from mrpctl.errors import SpecificationError
from mrpctl.flight import ActuatorModel, Hysteretic
from mrpctl.flight.steering import SteeringLaw
from mrpctl.scenario import parse_scenario, scenario_toml
from mrpctl.spacecraft import Spacecraft
from mrpctl.wheels import WheelCluster

RPM = 2.0 * math.pi / 60.0  # written out here, not taken from the module under test
INERTIA = [0.2, 0.25, 0.15]
WHEELS = {"layout": "orthogonal", "spin_inertia": 3.1831e-5, "torque_limit": 5e-3, "speed_limit_rpm": 6000.0}
BASE = {
    "tau": 0.2,
    "rate": 50.0,
    "t_final": 20.0,
    "spacecraft": {"inertia": INERTIA},
    "gains": {"attitude": [3.958, 4.947, 2.968], "rate": [0.8897, 1.1121, 0.6673]},
    "initial": {"principal_angle_deg": 120.0, "axis": [1.0, 1.0, 0.0], "omega": [0.0, 0.01, 0.0]},
    "rule": {"type": "hysteretic", "delta": 0.0},
    "steering": {"rate_limit": 0.1942, "acceleration": 0.012, "lag": 0.4248},
}


def _data(**steering: object) -> dict:
    data = copy.deepcopy(BASE)
    data["steering"].update(steering)
    return data


def test_the_table_is_the_law() -> None:
    scenario = parse_scenario(_data(momentum_limit=0.02))
    law = scenario.law
    assert isinstance(law, SteeringLaw)
    assert (law.rate_limit, law.acceleration, law.lag, law.momentum_limit) == (0.1942, 0.012, 0.4248, 0.02)
    assert law.spacecraft is not None and np.array_equal(law.spacecraft.inertia, np.diag(INERTIA))
    assert "steering: SteeringLaw (rate limit 0.1942 rad/s" in str(scenario)
    # lag and momentum_limit are optional: T = 0, no momentum limit
    data = _data()
    del data["steering"]["lag"]
    bare = parse_scenario(data).law
    assert bare is not None and bare.lag == 0.0 and bare.momentum_limit is None and bare.spacecraft is None
    assert parse_scenario({k: v for k, v in BASE.items() if k != "steering"}).law is None


@pytest.mark.parametrize(
    ("change", "needle"),
    [
        ({"rate": 0.1}, "unknown key 'rate' in [steering]"),
        ({"acceleration": -0.01}, "[steering] acceleration"),
        ({"rate_limit": 0.0}, "[steering] rate_limit"),
        ({"lag": -1.0}, "[steering] lag"),
        ({"momentum_limit": 0.0}, "[steering] momentum_limit"),
        ({"rate_limit": float("nan")}, "[steering] rate_limit"),
        ({"rate_limit": "fast"}, "[steering] rate_limit must be a number"),
        ({"lag": True}, "[steering] lag must be a number"),
    ],
)
def test_bad_values_name_the_key(change: dict, needle: str) -> None:
    with pytest.raises(SpecificationError) as error:
        parse_scenario(_data(**change))
    assert needle in str(error.value)


def test_a_missing_key_and_a_non_table() -> None:
    data = _data()
    del data["steering"]["acceleration"]
    with pytest.raises(SpecificationError, match=r"\[steering\] needs acceleration"):
        parse_scenario(data)
    data["steering"] = 0.1
    with pytest.raises(SpecificationError, match=r"\[steering\] must be a table"):
        parse_scenario(data)


def test_what_the_law_does_not_take() -> None:
    cases = []
    data = _data()
    data["rule"] = {"type": "on-current"}
    cases.append((data, "controller-side rule only, got the rule 'on-current'"))
    data = _data()
    data["rule"] = {"type": "on-predicted"}
    data["predictor"] = {}
    cases.append((data, "[steering] and [predictor]"))
    data = _data()
    data["reference"] = {"type": "inertial", "sigma": [0.1, 0.0, 0.0]}
    cases.append((data, "[steering] and [reference]"))
    data = _data()
    row = [0.0] * 6
    data["gains"] = {"K": [[-4.0, 0, 0, *row[:3]], [0, -5.0, 0, *row[:3]], [0, 0, -3.0, *row[:3]]]}
    cases.append((data, "invertible rate block"))
    for case, needle in cases:
        with pytest.raises(SpecificationError) as error:
            parse_scenario(case)
        assert needle in str(error.value) and "[steering]" in str(error.value)


@pytest.mark.parametrize("momentum", [None, 0.1 + 0.2])
def test_written_back_bit_for_bit(momentum: float | None) -> None:
    # awkward floats: repr must carry every bit
    data = _data(rate_limit=1.0 / 3.0, acceleration=0.012000000000000002, lag=math.pi / 10.0)
    if momentum is not None:
        data["steering"]["momentum_limit"] = momentum
    data["wheels"] = WHEELS
    scenario = parse_scenario(data)
    again = parse_scenario(tomllib.loads(scenario_toml(scenario)))
    assert again.law is not None and scenario.law is not None
    for name in ("rate_limit", "acceleration", "lag", "momentum_limit"):
        a, b = getattr(scenario.law, name), getattr(again.law, name)
        assert a == b and (a is None or a.hex() == b.hex()), name
    assert again.law.label() == scenario.law.label()  # the compiled library's name: the same law
    assert scenario_toml(again) == scenario_toml(scenario)


def test_the_writer_refuses_a_momentum_limit_of_another_inertia() -> None:
    scenario = parse_scenario(BASE)
    other = SteeringLaw(0.19, 0.012, 0.4, momentum_limit=0.02, spacecraft=Spacecraft([1.0, 1.0, 1.0]))
    from dataclasses import replace

    with pytest.raises(SpecificationError, match="momentum limit with the scenario's"):
        scenario_toml(replace(scenario, law=other))


def _direct(scenario, law, **options):
    return simulate(
        Spacecraft(INERTIA),
        scenario.K,
        scenario.x0,
        tau=0.2,
        rule=Hysteretic(0.0),
        t_final=BASE["t_final"],
        rate=50.0,
        law=law,
        **options,
    )


def test_the_scenario_flies_its_law_on_a_torque_limit() -> None:
    data = _data(momentum_limit=0.02)
    data["actuator"] = {"u_max": 5e-3}
    scenario = parse_scenario(data)
    run = scenario.simulate()
    law = SteeringLaw(0.1942, 0.012, 0.4248, momentum_limit=0.02, spacecraft=Spacecraft(INERTIA))
    direct = _direct(scenario, law, actuator=ActuatorModel(5e-3))
    pd = _direct(scenario, None, actuator=ActuatorModel(5e-3))
    assert np.array_equal(run.sigma, direct.sigma) and np.array_equal(run.u, direct.u)
    assert not np.array_equal(run.u, pd.u)  # the law, not the PD law, flew


def test_the_scenario_flies_its_law_on_the_wheels() -> None:
    data = _data(momentum_limit=0.02)
    data["wheels"] = WHEELS  # [wheels] with [steering]: the wheels take the law now
    scenario = parse_scenario(data)
    run = scenario.simulate()
    cluster = WheelCluster.orthogonal(3.1831e-5, 5e-3, 6000.0 * RPM)
    law = SteeringLaw(0.1942, 0.012, 0.4248, momentum_limit=0.02, spacecraft=Spacecraft(INERTIA))
    direct = _direct(scenario, law, wheels=cluster)
    pd = _direct(scenario, None, wheels=cluster)
    assert run.wheels is not None and direct.wheels is not None
    assert np.array_equal(run.sigma, direct.sigma) and np.array_equal(run.wheels.speeds, direct.wheels.speeds)
    assert not np.array_equal(run.u, pd.u)


def _file(tmp_path: Path, data: dict) -> str:
    scenario = parse_scenario(data, name="steer")
    path = tmp_path / "steer.toml"
    path.write_text(scenario_toml(scenario))
    return str(path)


def test_cli_simulate_flies_the_law(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = _data(momentum_limit=0.02)
    data["wheels"] = WHEELS
    path = _file(tmp_path, data)
    assert main(["simulate", path, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["scenario"]["steering"] == {
        "rate_limit": 0.1942,
        "acceleration": 0.012,
        "lag": 0.4248,
        "momentum_limit": 0.02,
    }
    scenario = parse_scenario(data)
    direct = _direct(
        scenario,
        scenario.law,
        wheels=WheelCluster.orthogonal(3.1831e-5, 5e-3, 6000.0 * RPM),
    )
    assert out["result"]["max_sigma"] == direct.max_sigma


def test_cli_sweep_flies_the_law(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _file(tmp_path, _data())
    argv = ["sweep", "tau", "--scenario", path, "--values", "0.2", "0.4", "--t-final", "10", "--json"]
    assert main(argv) == 0
    runs = json.loads(capsys.readouterr().out)["runs"]
    scenario = parse_scenario(_data())
    for row, tau in zip(runs, (0.2, 0.4), strict=True):
        one = simulate(
            scenario.spacecraft, scenario.K, scenario.x0, tau=tau, rule=scenario.rule, t_final=10.0, rate=50.0,
            law=scenario.law,
        )  # fmt: skip
        assert row["max_abs_sigma"] == one.max_sigma


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["verify"], "[steering]: verify analyses the linear law"),
        (["analyze"], "[steering]: analyze analyses the linear law"),
        (["export", "--out", "OUT", "--no-compile"], "[steering]: export writes the PD law's controller"),
        (["simulate", "--rule", "on-current"], "controller-side rule only"),
        (["sweep-eps"], "controller-side rule only"),
    ],
)
def test_what_the_cli_refuses(
    argv: list[str], needle: str, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch
) -> None:
    monkeypatch.chdir(tmp_path)
    path = _file(tmp_path, _data())
    if argv == ["sweep-eps"]:
        full = ["sweep", "eps", "--scenario", path, "--values", "0.1"]
    else:
        full = [argv[0], path, *argv[1:]]
    assert main(full) == USER_ERROR
    one_line_error(capsys, needle)
    assert not (tmp_path / "OUT").exists()
