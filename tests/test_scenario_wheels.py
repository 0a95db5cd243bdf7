"""Scenario files on reaction wheels: the [wheels] table, read, refused and written back."""

from __future__ import annotations

import copy
import math
import tomllib

import numpy as np
import pytest

from mrpctl import simulate
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.flight import Hysteretic
from mrpctl.scenario import load_scenario, parse_scenario, scenario_toml, shipped_scenarios
from mrpctl.spacecraft import Spacecraft
from mrpctl.wheels import WheelCluster

RPM = 2.0 * math.pi / 60.0  # written out here, not taken from the module under test

BASE = {
    "tau": 0.2,
    "rate": 50.0,
    "t_final": 4.0,
    "spacecraft": {"inertia": [0.2, 0.25, 0.15]},
    "gains": {"attitude": [3.958, 4.947, 2.968], "rate": [0.8897, 1.1121, 0.6673]},
    "initial": {"principal_angle_deg": 60.0, "axis": [1.0, 0.0, 1.0], "omega": [0.0, 0.01, 0.0]},
    "rule": {"type": "hysteretic", "delta": 0.1},
    "wheels": {"layout": "orthogonal", "spin_inertia": 3.1831e-5, "torque_limit": 5e-3, "speed_limit_rpm": 6000.0},
}


def _data(**wheels: object) -> dict:
    data = copy.deepcopy(BASE)
    data["wheels"].update(wheels)
    return data


def _without(key: str) -> dict:
    data = copy.deepcopy(BASE)
    del data["wheels"][key]
    return data


def _same_cluster(a: WheelCluster, b: WheelCluster) -> bool:
    return a.key() == b.key() and np.array_equal(a.speeds, b.speeds)


def test_the_shipped_cubesat_flies_on_its_wheels() -> None:
    scenario = load_scenario("cubesat_wheels")
    assert "cubesat_wheels" in shipped_scenarios()
    expected = WheelCluster(np.eye(3), 3.1831e-5, 5e-3, 6000.0 * RPM)
    assert scenario.wheels is not None
    assert _same_cluster(scenario.wheels, expected)
    # 6000 rpm is 200 pi rad/s, 20 mN m s of momentum per wheel with Js = 3.1831e-5 kg m^2
    np.testing.assert_allclose(scenario.wheels.speed_limit, 200.0 * math.pi, rtol=1e-15)
    np.testing.assert_allclose(scenario.wheels.momentum_capacity, 0.02, rtol=2e-5)
    assert "wheels: 3" in str(scenario) and "6000 rpm" in str(scenario)
    result = scenario.simulate()
    direct = simulate(
        Spacecraft([0.2, 0.25, 0.15]),
        scenario.K,
        scenario.x0,
        tau=0.2,
        rule=Hysteretic(0.1),
        t_final=scenario.t_final,
        rate=50.0,
        wheels=scenario.wheels,
    )
    assert result.wheels is not None and direct.wheels is not None
    assert np.array_equal(result.sigma, direct.sigma) and np.array_equal(result.u, direct.u)
    assert np.array_equal(result.wheels.speeds, direct.wheels.speeds)
    assert np.array_equal(result.wheels.peak_speed, direct.wheels.peak_speed)
    # the body torque is the motors' reaction, each motor within its limit
    assert np.max(np.abs(result.wheels.motor_torque)) <= 5e-3
    assert np.array_equal(result.u, -result.wheels.motor_torque)  # Gs = I: -Gs u_s is -u_s


def test_the_layouts_and_the_axes_are_the_clusters() -> None:
    parsed = parse_scenario(_data(layout="pyramid", elevation_deg=30.0, speed_limit_rpm=[5000.0, 5000, 6000, 6000]))
    expected = WheelCluster.pyramid(3.1831e-5, 5e-3, [5000.0 * RPM] * 2 + [6000.0 * RPM] * 2, elevation=math.pi / 6)
    assert parsed.wheels is not None
    np.testing.assert_allclose(parsed.wheels.spin_axes, expected.spin_axes, rtol=0, atol=1e-15)
    np.testing.assert_allclose(parsed.wheels.speed_limit, expected.speed_limit, rtol=1e-15)
    # the default elevation gives equal capacity on every axis: atan(1/sqrt 2)
    beta = math.atan(1.0 / math.sqrt(2.0))
    pyramid = parse_scenario(_data(layout="pyramid")).wheels
    assert pyramid is not None
    np.testing.assert_allclose(pyramid.spin_axes[2], np.full(4, math.sin(beta)), rtol=0, atol=1e-15)
    rows = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.6, 0.0, 0.8]]
    data = _data(spin_axes=rows, torque_limit=[1e-3, 2e-3, 3e-3, 4e-3])
    del data["wheels"]["layout"]
    wheels = parse_scenario(data).wheels
    assert wheels is not None and wheels.count == 4
    assert np.array_equal(wheels.spin_axes, np.array(rows).T)  # one row per wheel: the columns of Gs
    assert np.array_equal(wheels.torque_limit, [1e-3, 2e-3, 3e-3, 4e-3])


def _round_trip(data: dict) -> tuple[object, object, str]:
    scenario = parse_scenario(data)
    text = scenario_toml(scenario)
    return scenario, parse_scenario(tomllib.loads(text)), text


@pytest.mark.parametrize(
    "wheels",
    [
        {},
        {"layout": "pyramid", "null_gain": 0.05, "bias_speed_rpm": [100.0, -100.0, 100.0, -100.0]},
        {
            "layout": "pyramid",
            "elevation_deg": 40.0,
            "viscous": [1e-7, 2e-7, 3e-7, 4e-7],
            "coulomb": 1e-5,
            "limit_cycle_speed_rad_s": 1e-3,
            "initial_speed_rad_s": [1.0, 2.0, 3.0, 4.0],
            "gyroscopic": True,
            "spin_inertia": [3e-5, 3.1e-5, 3.2e-5, 3.3e-5],
        },
        {"control_axes": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], "speed_limit_rpm": [4000.0, 5000.0, 6100.0]},
    ],
    ids=["orthogonal", "pyramid-null-space", "friction-per-wheel", "two-control-axes"],
)
def test_the_writer_reads_back_to_the_same_cluster(wheels: dict) -> None:
    scenario, back, text = _round_trip(_data(**wheels))
    assert scenario.wheels is not None and back.wheels is not None  # type: ignore[attr-defined]
    for field in (
        "spin_axes",
        "spin_inertia",
        "torque_limit",
        "speed_limit",
        "viscous",
        "coulomb",
        "limit_cycle_speed",
        "speeds",
        "control_axes",
        "bias_speeds",
    ):
        a, b = getattr(scenario.wheels, field), getattr(back.wheels, field)  # type: ignore[attr-defined]
        assert a.tobytes() == b.tobytes(), field
    assert scenario.wheels.null_gain == back.wheels.null_gain  # type: ignore[attr-defined]
    assert scenario.wheels.gyroscopic == back.wheels.gyroscopic  # type: ignore[attr-defined]
    assert "[wheels]" in text


def test_the_writer_gives_the_speeds_as_they_were_written() -> None:
    text = _round_trip(_data())[2]
    assert "speed_limit_rpm = 6000.0\n" in text
    # speeds given in rad/s come back to the bit, in rpm where an rpm value reads back exactly, else in rad/s
    data = _without("speed_limit_rpm")
    data["wheels"]["speed_limit_rad_s"] = [1.0 / 3.0, 600.0, 700.0]
    scenario, back, text = _round_trip(data)
    assert back.wheels.speed_limit.tobytes() == scenario.wheels.speed_limit.tobytes()  # type: ignore[attr-defined]
    assert ("speed_limit_rpm" in text) != ("speed_limit_rad_s" in text)


@pytest.mark.parametrize(
    ("data", "error", "needles"),
    [
        (
            _data(layout=None, spin_axes=[[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),
            SpecificationError,
            ["[wheels]", "spin_axes", "rank 2"],
        ),
        (_data(spin_inertia=0.0), SpecificationError, ["[wheels] spin_inertia must be > 0"]),
        (_data(spin_inertia=[3e-5, -1e-6, 3e-5]), SpecificationError, ["[wheels] spin_inertia must be > 0"]),
        (_data(torque_limit=-5e-3), SpecificationError, ["[wheels] torque_limit must be > 0"]),
        (_data(speed_limit_rpm=0.0), SpecificationError, ["[wheels] speed_limit_rpm must be > 0"]),
        (_data(speed_limit_rpm=math.nan), SpecificationError, ["[wheels]", "speed_limit_rpm"]),
        (_data(spin_inertia=math.inf), SpecificationError, ["[wheels]", "spin_inertia"]),
        (_data(torque_limit=[5e-3, 5e-3]), DimensionError, ["[wheels] torque_limit", "3 wheels"]),
        (_data(viscous=[0.0] * 4), DimensionError, ["[wheels] viscous", "3 wheels"]),
        (_data(coulomb=-1e-5), SpecificationError, ["[wheels] coulomb must be >= 0"]),
        (
            _data(layout=None, spin_axes=[[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.0]]),
            SpecificationError,
            ["[wheels] spin_axes", "unit"],
        ),
        (
            _data(layout=None, spin_axes=[[1.0, 0.0, 0.0, 0.6], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.8]]),
            DimensionError,
            ["[wheels] spin_axes", "one row of 3 numbers per wheel"],
        ),
        (_data(spin_axes=np.eye(3).tolist()), SpecificationError, ["[wheels]", "layout", "spin_axes", "one of them"]),
        (_data(layout="tetrahedron"), SpecificationError, ["[wheels] layout must be one of"]),
        (_data(elevation_deg=30.0), SpecificationError, ["[wheels] elevation_deg applies to layout = 'pyramid'"]),
        (_data(speed_limit_rad_s=600.0), SpecificationError, ["[wheels]", "speed_limit_rpm or speed_limit_rad_s"]),
        (_without("speed_limit_rpm"), SpecificationError, ["[wheels] needs speed_limit_rpm"]),
        (_without("spin_inertia"), SpecificationError, ["[wheels] needs spin_inertia"]),
        (_without("torque_limit"), SpecificationError, ["[wheels] needs torque_limit"]),
        (_data(u_max=5e-3), SpecificationError, ["unknown key 'u_max' in [wheels]"]),
        (_data(spin_inertia=0.2), SpecificationError, ["[wheels] spin_inertia", "not positive definite"]),
        (_data(null_gain=0.1), SpecificationError, ["[wheels] null_gain", "no null space"]),
        (_data(gyroscopic=1), SpecificationError, ["[wheels] gyroscopic must be true or false"]),
        (_data(control_axes=[[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]), SpecificationError, ["[wheels]", "rank 1 < 2"]),
    ],
)
def test_bad_wheels_name_the_key(data: dict, error: type[Exception], needles: list[str]) -> None:
    data["wheels"] = {key: value for key, value in data["wheels"].items() if value is not None}
    with pytest.raises(error) as caught:
        parse_scenario(data)
    for needle in needles:
        assert needle in str(caught.value), str(caught.value)


def test_a_table_that_is_not_a_table() -> None:
    data = copy.deepcopy(BASE)
    data["wheels"] = 3
    with pytest.raises(SpecificationError, match=r"\[wheels\] must be a table"):
        parse_scenario(data)


@pytest.mark.parametrize(
    ("changes", "needles"),
    [
        ({"rule": {"type": "on-delayed"}}, ["rule only", "'on-delayed'", "type = 'hysteretic'"]),
        ({"rule": {"type": "none"}}, ["rule only", "'none'", "--hysteresis"]),
        ({"actuator": {"u_max": 5e-3}}, ["[wheels] and [actuator]", "remove [actuator]"]),
        ({"rule": {"type": "on-predicted"}, "predictor": {}}, ["predictor is not modelled", "'hysteretic'"]),
        ({"reference": {"type": "inertial", "sigma": [0.1, 0.0, 0.0]}}, ["[wheels] and [reference]", "remove"]),
    ],
    ids=["paper-rule", "no-switching", "actuator", "predictor", "reference"],
)
def test_what_the_wheels_do_not_take_is_refused_when_read(changes: dict, needles: list[str]) -> None:
    data = copy.deepcopy(BASE) | changes
    with pytest.raises(SpecificationError) as caught:
        parse_scenario(data)
    for needle in needles:
        assert needle in str(caught.value), str(caught.value)
    # the same file without [wheels] is a scenario
    del data["wheels"]
    assert parse_scenario(data).wheels is None
