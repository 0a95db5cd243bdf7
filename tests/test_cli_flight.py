"""mrpctl simulate / export with the loop-as-flown options, and their one-line errors (exit code 2)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from cli_assertions import one_line_error as _one_line_error

from mrpctl import paper, simulate
from mrpctl.cli import USER_ERROR, main
from mrpctl.flight import ActuatorModel, DelayModel, Disturbance, Hysteretic, Saturation, SensorModel
from mrpctl.scenario import load_scenario


def _json(capsys: pytest.CaptureFixture[str]) -> dict:
    return json.loads(capsys.readouterr().out)


def test_every_flight_option_reaches_simulate(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["simulate", "--hysteresis", "0.1", "--torque-limit", "30", "25", "20", "--torque-norm", "35"]
    argv += ["--saturation", "clip", "--attitude-noise", "0.003", "--rate-noise", "2e-4", "--gyro-bias", "1e-4", "0"]
    argv += ["-0.0001", "--noise-seed", "7", "--disturbance", "1e-3", "-0.001", "0", "--jitter", "0.48", "0.5"]
    argv += ["--jitter-seed", "4", "--t-final", "3", "--json"]
    assert main(argv) == 0
    data = _json(capsys)
    expected = simulate(
        paper.SPACECRAFT,
        paper.GAIN,
        paper.INITIAL_STATE,
        tau=0.5,
        t_final=3.0,
        rule=Hysteretic(0.1),
        actuator=ActuatorModel([30.0, 25.0, 20.0], norm_max=35.0, mode=Saturation.CLIP),
        sensor=SensorModel(attitude_noise=0.003, rate_noise=2e-4, gyro_bias=[1e-4, 0.0, -1e-4], seed=7),
        disturbance=Disturbance([1e-3, -1e-3, 0.0]),
        delay=DelayModel.jitter(0.48, 0.5, seed=4),
    )
    result = data["result"]
    assert result["rule"] == "hysteretic" and data["scenario"]["tau"] == 0.5
    assert result["switch_count"] == expected.switch_count
    assert result["final_sigma"] == expected.sigma[-1].tolist()  # JSON floats are exact (repr)
    assert result["saturated_fraction"] == expected.saturated_fraction
    assert result["peak_command"] == expected.peak_command.tolist()
    assert set(data["scenario"]["flight_models"]) == {"actuator", "sensor", "disturbance", "delay"}


def test_options_change_a_flight_scenario_field_by_field(capsys: pytest.CaptureFixture[str]) -> None:
    """--attitude-noise replaces only that field of the scenario's sensor; --torque-norm keeps its u_max."""
    base = load_scenario("flight-paper")
    assert (
        main(["simulate", "flight-paper", "--attitude-noise", "0.0", "--torque-norm", "25", "--t-final", "2", "--json"])
        == 0
    )
    data = _json(capsys)
    sensor = SensorModel(attitude_noise=0.0, rate_noise=base.sensor.rate_noise, seed=base.sensor.seed)
    expected = simulate(
        base.spacecraft,
        base.K,
        base.x0,
        tau=base.tau,
        t_final=2.0,
        rule=base.rule,
        actuator=ActuatorModel(base.actuator.u_max, norm_max=25.0),
        sensor=sensor,
        disturbance=base.disturbance,
        delay=base.delay,
    )
    assert data["result"]["final_sigma"] == expected.sigma[-1].tolist()
    assert data["result"]["saturated_fraction"] == expected.saturated_fraction


def test_export_with_flight_options(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "flown"
    assert (
        main(["export", "flight-paper", "--out", str(out), "--no-compile", "--disturbance", "0", "2e-3", "0", "--json"])
        == 0
    )
    data = _json(capsys)
    manifest = json.loads((out / "manifest.json").read_text())
    assert data["content_hash"] == manifest["content_hash"]["value"]
    flight = manifest["flight"]
    assert flight["disturbance"] == {"torque": [0.0, 2e-3, 0.0]}
    assert flight["actuator"]["u_max"] == [20.0, 20.0, 20.0] and flight["sensor"]["seed"] == 1
    assert flight["delay"]["samples"] == [450, 500]
    assert (out / "flight_controller.casadi").exists()


@pytest.mark.parametrize(
    ("argv", "needles"),
    [
        (["simulate", "paper_fig4_on_delayed", "--torque-limit", "20"], ("actuator", "--hysteresis", "on-delayed")),
        (["simulate", "--hysteresis", "1.5"], ("--hysteresis", "delta", "[0, 1)")),
        (["simulate", "--hysteresis", "0.1", "--rule", "on-delayed"], ("--hysteresis", "on-delayed")),
        (["simulate", "--hysteresis", "0.1", "--alpha", "1.2"], ("--alpha", "--rule")),
        (["simulate", "--rule", "hysteretic", "--hysteresis", "0.1", "--alpha", "1.2"], ("--hysteresis", "--alpha")),
        (["simulate", "--hysteresis", "0.1", "--torque-limit", "1", "2"], ("--torque-limit", "1 or 3 values")),
        (["simulate", "--hysteresis", "0.1", "--torque-limit", "-1"], ("--torque-limit", "u_max", "> 0")),
        (["simulate", "--hysteresis", "0.1", "--torque-norm", "5"], ("--torque-norm", "needs --torque-limit")),
        (["simulate", "--hysteresis", "0.1", "--attitude-noise", "-0.1"], ("--attitude-noise", "attitude_noise")),
        (["simulate", "--hysteresis", "0.1", "--rate-noise", "nan"], ("--rate-noise", "rate_noise")),
        (["simulate", "--hysteresis", "0.1", "--noise-seed", "-3"], ("--noise-seed", "seed")),
        (["simulate", "--hysteresis", "0.1", "--disturbance", "inf", "0", "0"], ("--disturbance", "torque")),
        (["simulate", "--hysteresis", "0.1", "--jitter", "0.4", "0.5", "--tau", "0.3"], ("--jitter", "--tau")),
        (["simulate", "--hysteresis", "0.1", "--jitter", "0.5", "0.4"], ("--jitter", "tau_max must be >= tau_min")),
        (["simulate", "--hysteresis", "0.1", "--jitter", "0", "0.5"], ("--jitter", "1/rate")),
        (["simulate", "--hysteresis", "0.1", "--jitter-seed", "2"], ("--jitter-seed", "--jitter")),
        (["simulate", "flight-paper", "--tau", "0.4"], ("tau_max", "--jitter")),
        (["simulate", "flight-paper", "--rule", "on-current"], ("only to the loop as flown", "on-current")),
    ],
)
def test_bad_flight_options_exit_2_with_one_line(argv: list[str], needles: tuple[str, ...], capsys) -> None:
    assert main([*argv, "--t-final", "0.01"]) == USER_ERROR
    _one_line_error(capsys, *needles)


def test_flight_options_are_in_the_help(capsys: pytest.CaptureFixture[str]) -> None:
    for command in ("simulate", "export"):
        with pytest.raises(SystemExit):
            main([command, "--help"])
        out = capsys.readouterr().out
        for option in ("--hysteresis", "--torque-limit", "--attitude-noise", "--rate-noise", "--gyro-bias"):
            assert option in out
        assert "--noise-seed" in out and "--disturbance" in out and "--jitter" in out
    assert np.isfinite(load_scenario("flight-paper").tau)


def test_a_tumble_sweep_of_a_flight_scenario_keeps_its_models(tmp_path: Path, capsys) -> None:
    """The sweep hands the scenario's actuator, sensor, disturbance and delay to every run (never drops them)."""
    out = tmp_path / "sweep.csv"
    argv = ["sweep", "tumble", "--scenario", "flight-paper", "--count", "2", "--seed", "3", "--t-final", "1.5"]
    assert main([*argv, "--csv", str(out)]) == 0
    capsys.readouterr()
    rows = out.read_text().splitlines()
    header, first = rows[0].split(","), rows[1].split(",")
    base = load_scenario("flight-paper")
    x0 = np.array([float(v) for v in first[1:7]])
    x0[3:] /= 4.0
    expected = simulate(base.spacecraft, base.K, x0, tau=base.tau, rule=base.rule, t_final=1.5, **base.flight_options)
    assert int(first[header.index("switches")]) == expected.switch_count
    assert float(first[header.index("max_abs_sigma")]) == expected.max_sigma
