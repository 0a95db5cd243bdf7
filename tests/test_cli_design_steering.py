"""``mrpctl design --torque-limit/--wheels --toml``: the designed steering law written as a runnable scenario."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from cli_assertions import one_line_error

from mrpctl import Spacecraft
from mrpctl.cli import USER_ERROR, main
from mrpctl.design.actuator import design_for_actuator
from mrpctl.flight import ActuatorModel, Hysteretic
from mrpctl.scenario import load_scenario

CUBESAT = ["design", "--inertia", "0.2", "0.25", "0.15", "--tau", "0.2"]
SPACECRAFT = Spacecraft([0.2, 0.25, 0.15])


def _same_law(a, b) -> bool:
    return (a.rate_limit, a.acceleration, a.lag, a.momentum_limit) == (
        b.rate_limit,
        b.acceleration,
        b.lag,
        b.momentum_limit,
    )


def test_the_design_for_a_torque_limit_is_written_and_flies(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "steer.toml"
    argv = [*CUBESAT, "--torque-limit", "5e-3", "--max-rate", "0.05", "--toml", str(path), "--rate", "50"]
    assert main([*argv, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["toml"] == str(path) and out["momentum_limit"] is None
    design = design_for_actuator(SPACECRAFT, 0.2, ActuatorModel(5e-3), max_rate=0.05, settling_time=60.0)
    scenario = load_scenario(path)
    assert scenario.law is not None and _same_law(scenario.law, design.law)
    assert np.array_equal(scenario.K, design.K)
    assert scenario.actuator is not None and np.array_equal(scenario.actuator.u_max, [5e-3] * 3)
    assert scenario.wheels is None and isinstance(scenario.rule, Hysteretic) and scenario.rate == 50.0
    # in the envelope: 170 deg, |omega0| = 0.05 rad/s
    assert 4.0 * np.arctan(np.linalg.norm(scenario.sigma0)) == pytest.approx(np.radians(170.0), rel=1e-14)
    assert np.linalg.norm(scenario.omega0) == pytest.approx(0.05, rel=1e-15)
    assert main(["simulate", str(path), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)["result"]
    assert result["settling_time"] == scenario.simulate().settling_time
    # the file exists now: refused without --overwrite
    assert main(argv) == USER_ERROR
    one_line_error(capsys, "--overwrite")


def test_the_design_for_a_scenario_s_wheels(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "wheels.toml"
    argv = [*CUBESAT, "--wheels", "cubesat_wheels", "--max-rate", "0.05", "--settling-time", "120"]
    assert main([*argv, "--toml", str(path), "--rate", "50", "--t-final", "120"]) == 0
    assert "wheels holding" in capsys.readouterr().out
    cluster = load_scenario("cubesat_wheels").wheels
    assert cluster is not None
    design = design_for_actuator(SPACECRAFT, 0.2, cluster, max_rate=0.05, settling_time=120.0)
    scenario = load_scenario(path)
    assert scenario.law is not None and _same_law(scenario.law, design.law)
    assert scenario.law.momentum_limit is not None and scenario.law.spacecraft is not None
    assert np.array_equal(scenario.law.spacecraft.inertia, SPACECRAFT.inertia)
    assert scenario.wheels is not None and scenario.wheels.key() == cluster.key() and scenario.actuator is None
    assert scenario.t_final == 120.0


@pytest.mark.parametrize(
    ("extra", "needle"),
    [
        (["--torque-limit", "5e-3", "--wheels", "cubesat_wheels"], "not both"),
        (["--wheels", "paper_fig4_on_delayed"], "has no [wheels] table"),
        (["--wheels", "no_such_file.toml"], "scenario file not found"),
        (["--torque-limit", "5e-3", "--toml", "x.toml", "--rule", "on-current"], "controller-side rule only"),
        (["--torque-limit", "5e-3", "--toml", "x.toml", "--rate", "7"], "rate"),
        (["--wheels", "cubesat_wheels", "--max-rate", "0.05"], "predicted settling time above the time asked"),
    ],
)
def test_what_the_design_refuses(
    extra: list[str], needle: str, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch
) -> None:
    monkeypatch.chdir(tmp_path)
    assert main([*CUBESAT, *extra]) == USER_ERROR
    one_line_error(capsys, needle)
    assert not (tmp_path / "x.toml").exists()
