"""Scenario files of the estimated loop: the [estimator] table, its round trip, its runs and its refusals."""

from __future__ import annotations

import copy
import json
import math
import tomllib
from dataclasses import fields, replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from cli_assertions import one_line_error

from mrpctl import paper, simulate
from mrpctl.campaign.spec import parse_campaign
from mrpctl.cli import USER_ERROR, main
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.estimation import EstimatedLoop, Estimator, EstimatorTuning, Gyro, Sensors, StarTracker
from mrpctl.flight import ActuatorModel, Hysteretic
from mrpctl.scenario import load_scenario, parse_scenario, scenario_toml
from mrpctl.simulation.estimated import EstimatedResult

ARCSEC = math.pi / 648_000.0  # one arcsecond, written apart from mrpctl's constant

BASE: dict[str, Any] = {
    "name": "estimated",
    "tau": 0.5,
    "rate": 10.0,
    "t_final": 12.0,
    "substeps": 4,
    "spacecraft": {"inertia": [140.0, 100.0, 80.0]},
    "gains": {"K": np.asarray(paper.GAIN).tolist()},
    "initial": {"sigma": np.asarray(paper.INITIAL_SIGMA).tolist(), "omega": [0.46, 0.0, 0.0]},
    "rule": {"type": "hysteretic", "delta": 0.0},
    "estimator": {
        "seed": 3,
        "attitude_error": 1e-3,
        "bias_error": 2e-3,
        "star_tracker": {"noise_arcsec": 10.0, "rate": 2.0, "dropout": 0.05},
        "gyro": {"rate_noise": 1e-5, "bias_walk": 1e-7, "initial_bias": [5e-4, -3e-4, 2e-4]},
    },
}


WHEELS = {"layout": "orthogonal", "spin_inertia": 3e-5, "torque_limit": 5e-3, "speed_limit_rpm": 6000.0}


def _with(**changes: Any) -> dict[str, Any]:
    """BASE with keys of [estimator] or of its sub-tables changed ("star_tracker.rate" = ...); None removes."""
    data = copy.deepcopy(BASE)
    for dotted, value in changes.items():
        table = data["estimator"]
        *path, key = dotted.split(".")
        for part in path:
            table = table.setdefault(part, {})
        if value is None:
            table.pop(key, None)
        else:
            table[key] = value
    return data


def _same(a: Any, b: Any) -> bool:
    """Two frozen values equal field by field, arrays bit for bit (None, enums, floats, nested values)."""
    if a is None or b is None:
        return a is b
    if hasattr(a, "__dataclass_fields__"):
        return type(a) is type(b) and all(
            _same(getattr(a, f.name), getattr(b, f.name)) for f in fields(a) if f.name != "covariance" or f.init
        )
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
        return a.shape == b.shape and a.tobytes() == b.tobytes()
    return bool(a == b) and type(a) is type(b)


def _round_trip(scenario: Any) -> Any:
    return parse_scenario(tomllib.loads(scenario_toml(scenario)))


def _python_loop() -> EstimatedLoop:
    """The BASE table's loop built with the Python API (the tracker's noise converted here, not by mrpctl)."""
    tracker = StarTracker(10.0 * ARCSEC, 2.0, 0.5, dropout=0.05)
    gyro = Gyro(1e-5, 1e-7, initial_bias=(5e-4, -3e-4, 2e-4))
    return EstimatedLoop(Sensors(tracker, gyro, seed=3), Estimator(attitude_error=1e-3, bias_error=2e-3))


def test_the_table_is_the_python_api_value() -> None:
    scenario = parse_scenario(BASE)
    loop = scenario.estimated_loop
    assert _same(loop, _python_loop())
    assert loop.sensors.star_tracker.noise == 10.0 * ARCSEC
    # Farrenkopf's P0 is replaced by the diagonal of the initial errors
    assert loop.estimator.tuning is None and loop.estimator.kind.value == "mekf"
    assert "estimator: mekf on a 2 Hz star tracker of 10.0 arcsec" in str(scenario)


def test_the_latency_defaults_to_tau_and_the_run_is_the_python_call() -> None:
    scenario = parse_scenario(BASE)
    assert scenario.estimated_loop.sensors.star_tracker.latency == 0.5
    run = scenario.simulate_estimated()
    loop = _python_loop()
    expected = simulate(
        paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, tau=0.5, rule=Hysteretic(0.0), t_final=12.0, rate=10.0,
        substeps=4, sensors=loop.sensors, estimator=loop.estimator,
    )  # fmt: skip
    assert isinstance(run, EstimatedResult)
    for name in ("sigma", "omega", "sigma_hat", "bias_hat", "covariance", "u"):
        assert getattr(run, name).tobytes() == getattr(expected, name).tobytes(), name


@pytest.mark.parametrize(
    "changes",
    [
        {},
        {"kind": "mrp_ekf", "covariance_now": False, "initial_bias": [1e-4, 0.0, -2e-4], "attitude_error": None},
        {"initial_sigma": [0.1, -0.2, 0.3], "bias_error": None, "seed": 11},
        {"star_tracker.noise_arcsec": [5.0, 7.5, 12.25], "star_tracker.dropout": 0.0},
        {
            "star_tracker.noise_arcsec": None,
            "star_tracker.noise": 1.2345678e-5,  # not a whole number of arcsec: written in rad, bit for bit
            "star_tracker.boresight": [0.0, 0.0, 1.0],
            "star_tracker.roll_noise_arcsec": 40.0,
        },
        {"gyro.scale_factor": [1e-4, -2e-4, 3e-4], "star_tracker.latency": 0.5},
        {"tuning.rate_noise": 2e-5, "tuning.initial_covariance": np.diag([1e-6] * 3 + [4e-6] * 3).tolist()},
    ],
)
def test_the_writer_reads_back_to_the_same_loop(changes: dict[str, Any]) -> None:
    scenario = parse_scenario(_with(**changes))
    back = _round_trip(scenario)
    assert _same(back.estimated_loop, scenario.estimated_loop)
    assert scenario_toml(back) == scenario_toml(scenario)


def test_a_partial_tuning_table_keeps_the_sensors_values_for_the_rest() -> None:
    loop = parse_scenario(_with(**{"tuning.bias_walk": 3e-7})).estimated_loop
    tuning = loop.estimator.tuning
    assert isinstance(tuning, EstimatorTuning)
    assert tuning.bias_walk == 3e-7 and tuning.rate_noise == 1e-5
    np.testing.assert_array_equal(tuning.measurement_covariance, np.eye(3) * (10.0 * ARCSEC) ** 2)
    # the initial errors of the table: P0 = diag(1e-3², 1e-3², 1e-3², 2e-3², 2e-3², 2e-3²)
    np.testing.assert_array_equal(tuning.initial_covariance, np.diag([1e-6] * 3 + [4e-6] * 3))


def test_the_writer_keeps_a_tuning_of_python() -> None:
    tuning = EstimatorTuning(3e-5, 2e-7, np.diag([1e-9, 2e-9, 3e-9]), np.eye(6) * 1e-6)
    scenario = parse_scenario(BASE)
    loop = scenario.estimated_loop
    scenario = replace(scenario, estimated_loop=replace(loop, estimator=replace(loop.estimator, tuning=tuning)))
    back = _round_trip(scenario).estimated_loop
    assert _same(back.estimator.tuning, tuning)


@pytest.mark.parametrize(
    ("data", "needles"),
    [
        (_with(foo=1), ["unknown key 'foo' in [estimator]"]),
        (_with(**{"star_tracker.bogus": 1}), ["unknown key 'bogus' in [estimator.star_tracker]"]),
        (_with(**{"gyro.drift": 1}), ["unknown key 'drift' in [estimator.gyro]"]),
        (_with(**{"tuning.q": 1}), ["unknown key 'q' in [estimator.tuning]"]),
        (_with(star_tracker=None), ["[estimator] needs a [estimator.star_tracker] table"]),
        (_with(gyro=None), ["[estimator] needs a [estimator.gyro] table"]),
        (_with(star_tracker=3), ["[estimator.star_tracker] must be a table"]),
        (_with(**{"star_tracker.noise_arcsec": -1.0}), ["[estimator.star_tracker]", "noise_arcsec must be > 0"]),
        (_with(**{"star_tracker.noise_arcsec": math.nan}), ["[estimator.star_tracker]", "noise_arcsec"]),
        (_with(**{"star_tracker.noise": 1e-5}), ["[estimator.star_tracker]", "noise (rad) or noise_arcsec"]),
        (_with(**{"star_tracker.noise_arcsec": None}), ["[estimator.star_tracker] needs noise_arcsec"]),
        (_with(**{"star_tracker.rate": None}), ["[estimator.star_tracker] needs rate"]),
        (_with(**{"star_tracker.rate": 3.0}), ["[estimator.star_tracker]", "rate", "divide the controller rate 10"]),
        (_with(**{"star_tracker.rate": 0.0}), ["[estimator.star_tracker]", "rate must be > 0"]),
        (_with(**{"star_tracker.latency": 0.3}), ["[estimator.star_tracker]", "latency", "tau = 0.5"]),
        (_with(**{"star_tracker.dropout": 1.0}), ["[estimator.star_tracker]", "dropout"]),
        (_with(**{"star_tracker.roll_noise_arcsec": 4.0}), ["[estimator.star_tracker]", "roll_noise", "boresight"]),
        (_with(**{"gyro.rate_noise": 0.0}), ["[estimator.gyro]", "rate_noise must be > 0"]),
        (_with(**{"gyro.bias_walk": None}), ["[estimator.gyro] needs bias_walk"]),
        (_with(**{"gyro.initial_bias": [1.0, 2.0]}), ["[estimator.gyro]", "initial_bias"]),
        (_with(kind="ukf"), ["[estimator]", "kind: one of 'mekf', 'mrp_ekf'"]),
        (_with(covariance_now="yes"), ["[estimator]", "covariance_now must be true or false"]),
        (_with(seed=-1), ["[estimator]", "seed must be >= 0"]),
        (_with(attitude_error=0.0), ["[estimator]", "attitude_error must be > 0"]),
        (_with(**{"tuning.initial_covariance": (-np.eye(6)).tolist()}), ["[estimator.tuning]", "initial_covariance"]),
        (_with(**{"tuning.measurement_covariance": [[1.0, 2.0], [2.0, 1.0]]}), ["[estimator.tuning]"]),
        ({**_with(), "rule": {"type": "on-delayed"}}, ["[estimator] needs [rule] type = 'hysteretic'"]),
        ({**_with(), "history": "zero-input"}, ["[estimator] needs history = 'constant'"]),
        ({**_with(), "actuator": {"u_max": 1.0}}, ["[estimator]", "without [actuator]"]),
        ({**_with(), "wheels": WHEELS}, ["[estimator]", "without [wheels]"]),
        ({**_with(), "reference": {"type": "inertial", "sigma": [0.0, 0.0, 0.1]}}, ["without [reference]"]),
        (
            {**_with(), "spacecraft": {"inertia": [[140.0, 1.0, 0.0], [1.0, 100.0, 0.0], [0.0, 0.0, 80.0]]}},
            ["[estimator] needs a diagonal [spacecraft] inertia"],
        ),
        ({**_with(), "estimator": [1, 2]}, ["[estimator] must be a table"]),
    ],
)
def test_bad_tables_name_their_key(data: dict[str, Any], needles: list[str]) -> None:
    with pytest.raises((SpecificationError, DimensionError)) as error:  # a wrong shape: a DimensionError
        parse_scenario(data)
    for needle in needles:
        assert needle in str(error.value), str(error.value)


def test_each_loop_runs_with_its_own_method() -> None:
    estimated = parse_scenario(BASE)
    with pytest.raises(SpecificationError, match=r"simulate_estimated\(\)"):
        estimated.simulate()
    plain = replace(estimated, estimated_loop=None)
    with pytest.raises(SpecificationError, match=r"no \[estimator\] table"):
        plain.simulate_estimated()
    # a scenario built in Python with another loop's model: refused by simulate, naming it
    with pytest.raises(SpecificationError, match="actuator: not options of the estimated loop"):
        replace(estimated, actuator=ActuatorModel(u_max=10.0)).simulate_estimated()


def test_the_result_metrics_against_the_trajectory() -> None:
    run = parse_scenario(BASE).simulate_estimated()
    error = 4 * np.arctan(np.sqrt(np.sum(run.sigma**2, axis=1)))  # the principal angle, written apart
    above = [i for i in range(len(error)) if error[i] > 1.0]  # the tumble's first descent through 1 rad
    assert 0 < len(above) < len(error) - 1
    assert run.settling_time(1.0) == pytest.approx(0.1 * (above[-1] + 1), abs=1e-12)
    assert math.isnan(run.settling_time(1e-9))  # never that close in 12 s
    assert run.settling_time(4.0) == 0.0  # the principal angle never exceeds 4 rad
    start = 6.0
    kept = error[np.arange(len(error)) * 0.1 >= start - 1e-9]
    assert run.pointing_rms(start) == pytest.approx(math.sqrt(sum(e * e for e in kept) / len(kept)), rel=1e-12)
    with pytest.raises(SpecificationError, match="start"):
        run.pointing_rms(20.0)


def _write(tmp_path: Path, data: dict[str, Any]) -> Path:
    path = tmp_path / "estimated.toml"
    path.write_text(scenario_toml(parse_scenario(data)), encoding="utf-8")
    return path


def test_cli_simulates_an_estimator_scenario(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _write(tmp_path, BASE)
    assert main(["simulate", str(path), "--json", "--csv", str(tmp_path / "run.csv")]) == 0
    payload = json.loads(capsys.readouterr().out)
    run = load_scenario(path).simulate_estimated()
    result = payload["result"]
    assert result["estimator"] == "mekf" and result["switches"] == run.switches
    assert result["settling_time"] is None  # 12 s: still turning (JSON null for NaN)
    assert result["final_sigma"] == run.sigma[-1].tolist()
    assert result["final_pointing_arcsec"] == pytest.approx(run.pointing_error[-1] / ARCSEC, rel=1e-12)
    rows = np.loadtxt(tmp_path / "run.csv", delimiter=",", skiprows=1)
    np.testing.assert_array_equal(rows[:, 1:4], run.sigma)
    np.testing.assert_array_equal(rows[:, 16:19], run.bias_hat)
    # the options: the other estimator and another noise seed
    assert main(["simulate", str(path), "--estimator", "mrp_ekf", "--noise-seed", "7", "--hysteresis", "0.1"]) == 0
    text = capsys.readouterr().out
    assert "estimated loop (mrp_ekf)" in text and "noise seed 7" in text
    assert "rule Hysteretic (h flips when h q0 < -0.1;" in text  # the rule the loop flew
    assert "pointing: not settled within 0.01 rad; final" in text


def test_cli_mrp_ekf_sigma_is_the_mekf_sigma_in_rotation_units(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """The MRP-EKF's covariance is on δσ; mapped to δθ it is the MEKF's 1σ (unmapped it would be a quarter of it;
    the filters differ by their linearisation and truncated Φ, 0.25 % here)."""
    path = _write(tmp_path, BASE)
    values = {}
    for kind in ("mekf", "mrp_ekf"):
        assert main(["simulate", str(path), "--json", "--estimator", kind]) == 0
        values[kind] = json.loads(capsys.readouterr().out)["result"]["filter_sigma_rms_arcsec"]
    assert values["mrp_ekf"] == pytest.approx(values["mekf"], rel=1e-2)


@pytest.mark.parametrize(
    ("arguments", "needle"),
    [
        (["--torque-limit", "1"], "--torque-limit does not apply to a scenario with an [estimator] table"),
        (["--predictor"], "--predictor does not apply"),
        (["--predictor-form", "linear"], "--predictor-form does not apply"),
        (["--wheels-plot", "w.png"], "--wheels-plot does not apply"),
        (["--noise-seed", "-1"], "--noise-seed must be >= 0"),
        (["--hysteresis", "1.5"], "--hysteresis"),
        (["--tau", "0.3"], "tau"),
    ],
)
def test_cli_refuses_options_of_other_loops(tmp_path, capsys, arguments: list[str], needle: str) -> None:
    path = _write(tmp_path, BASE)
    assert main(["simulate", str(path), *arguments]) == USER_ERROR
    one_line_error(capsys, needle)


def test_cli_refusals_name_what_to_use(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _write(tmp_path, BASE)
    assert main(["simulate", "--estimator", "mekf"]) == USER_ERROR
    one_line_error(capsys, "--estimator applies to a scenario with an [estimator] table")
    assert main(["sweep", "tumble", "--scenario", str(path), "--count", "2"]) == USER_ERROR
    one_line_error(capsys, "sweep does not fly the estimated loop", "simulate_estimated")
    assert main(["export", str(path), "--out", str(tmp_path / "out")]) == USER_ERROR
    one_line_error(capsys, "[estimator]", "export_estimator")
    bad = tmp_path / "bad.toml"
    bad.write_text(path.read_text().replace("rate = 2.0  # Hz", "rate = 3.0  # Hz"), encoding="utf-8")
    assert main(["simulate", str(bad)]) == USER_ERROR
    one_line_error(capsys, "[estimator.star_tracker]", "rate")


def test_a_campaign_of_the_estimated_loop_is_refused() -> None:
    data = {**copy.deepcopy(BASE), "count": 4, "seed": 1}
    with pytest.raises(SpecificationError, match=r"\[estimator\]: campaigns of the estimated loop.*simulate_estimated"):
        parse_campaign(data)


def test_the_how_to_file_is_the_how_to_python_loop() -> None:
    page = (Path(__file__).resolve().parents[1] / "docs" / "how-to" / "estimation.md").read_text(encoding="utf-8")
    scenario = parse_scenario(tomllib.loads(page.split("```toml\n", 1)[1].split("```", 1)[0]))
    # the Python block's values: StarTracker.from_arcsec(10.0, rate=2.0, latency=0.5, dropout=0.05), ...
    tracker = StarTracker(10.0 * ARCSEC, 2.0, 0.5, dropout=0.05)
    gyro = Gyro(rate_noise=1e-5, bias_walk=1e-7, initial_bias=(5e-4, -3e-4, 2e-4))
    expected = EstimatedLoop(Sensors(tracker, gyro, seed=1), Estimator(attitude_error=1e-3, bias_error=2e-3))
    assert _same(scenario.estimated_loop, expected)
    assert scenario.rate == 10.0 and scenario.substeps == 4 and scenario.t_final == 120.0
    np.testing.assert_array_equal(scenario.K, paper.GAIN)


def test_simulate_batch_refuses_the_estimated_loop_naming_what_to_use() -> None:
    from mrpctl import simulate_batch

    loop = _python_loop()
    with pytest.raises(SpecificationError, match=r"sensors, estimator: simulate_batch does not fly.*once per run"):
        simulate_batch(
            paper.SPACECRAFT, paper.GAIN, np.array([paper.INITIAL_STATE] * 2), tau=0.5, rule=Hysteretic(0.0),
            t_final=1.0, rate=10.0, sensors=loop.sensors, estimator=loop.estimator,
        )  # fmt: skip
