"""``mrpctl simulate`` (and sweep, export, verify, analyze) of a scenario on reaction wheels."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from cli_assertions import one_line_error

from mrpctl import export_wheel_controller, simulate
from mrpctl.cli import USER_ERROR, main
from mrpctl.flight import Hysteretic
from mrpctl.scenario import load_scenario, scenario_toml, tumbling_states

RPM = 2.0 * math.pi / 60.0


def test_simulate_prints_the_wheel_metrics(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    plot = tmp_path / "wheels.png"
    assert main(["simulate", "cubesat_wheels", "--t-final", "40", "--json", "--wheels-plot", str(plot)]) == 0
    data = json.loads(capsys.readouterr().out)
    wheels = data["result"]["wheels"]
    assert data["scenario"]["wheels"]["speed_limit_rpm"] == [6000.0] * 3
    assert data["scenario"]["wheels"]["spin_axes"] == np.eye(3).tolist()
    assert data["files"]["wheels_plot"] == str(plot) and plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # the same run from Python, its trajectory kept at every sample: the metrics rebuilt from it
    scenario = load_scenario("cubesat_wheels")
    run = simulate(
        scenario.spacecraft,
        scenario.K,
        scenario.x0,
        tau=scenario.tau,
        rule=scenario.rule,
        t_final=40.0,
        rate=scenario.rate,
        wheels=scenario.wheels,
    )
    assert run.wheels is not None and scenario.wheels is not None
    speeds, motor = np.asarray(run.wheels.speeds), np.asarray(run.wheels.motor_torque)
    limit, torque = scenario.wheels.speed_limit, scenario.wheels.torque_limit
    np.testing.assert_allclose(wheels["peak_speed_rpm"], np.max(np.abs(speeds), axis=0) / RPM, rtol=1e-14)
    cut = (np.abs(speeds) >= limit) & (motor == 0.0)  # at the limit, the speeding torque cut to 0
    np.testing.assert_allclose(wheels["speed_limited_time_s"], cut.sum(axis=0) / scenario.rate, rtol=1e-14)
    clipped = np.abs(motor) == torque
    counted = np.asarray(wheels["torque_limited_time_s"]) * scenario.rate
    assert np.all(clipped.sum(axis=0) <= counted + 1e-9) and np.all(counted <= (clipped | cut).sum(axis=0) + 1e-9)
    capacity = scenario.wheels.spin_inertia * limit
    momentum = np.max(np.linalg.norm(speeds * scenario.wheels.spin_inertia, axis=1))
    assert wheels["peak_momentum_Nms"] == pytest.approx(momentum, rel=1e-14)
    assert wheels["momentum_capacity_Nms"] == pytest.approx(capacity.tolist(), rel=1e-15)
    ratio = np.max(np.abs(speeds), axis=0) / limit
    assert wheels["worst_wheel_index"] == int(np.argmax(ratio))
    assert wheels["count"] == 3 and wheels["speed_limit_rpm"] == [6000.0] * 3
    # the two wheels of the slew's axes reach the speed limit, the third does not
    assert sorted(np.asarray(wheels["speed_limited_time_s"]) > 0) == [False, True, True]
    assert main(["simulate", "cubesat_wheels", "--t-final", "40"]) == 0
    text = capsys.readouterr().out
    assert "wheels (3): peak stored momentum" in text and "wheels: 3, Js = 3.183e-05 kg m^2" in text
    rows = [line.split() for line in text.splitlines() if line.strip()[:1].isdigit() and len(line.split()) == 6]
    assert [int(row[0]) for row in rows] == [1, 2, 3]
    for row, peak in zip(rows, np.max(np.abs(speeds), axis=0) / RPM, strict=True):
        assert float(row[1]) == pytest.approx(peak, abs=0.05) and float(row[2]) == 6000.0


def _bad_file(tmp_path: Path) -> str:
    path = tmp_path / "bad.toml"
    text = scenario_toml(load_scenario("cubesat_wheels"))
    assert "spin_inertia = 3.1831e-05" in text
    path.write_text(text.replace("spin_inertia = 3.1831e-05", "spin_inertia = 0.0"), encoding="utf-8")
    return str(path)


@pytest.mark.parametrize(
    ("argv", "needles"),
    [
        (["simulate", "paper_fig4_on_delayed", "--wheels-plot", "w.png"], ["--wheels-plot needs", "[wheels]"]),
        (["simulate", "cubesat_wheels", "--wheels-plot", "w.xyz"], ["--wheels-plot", "unknown image format"]),
        (["simulate", "cubesat_wheels", "--torque-limit", "0.005"], ["[wheels] and [actuator]", "--torque-limit"]),
        (["simulate", "cubesat_wheels", "--rule", "on-delayed"], ["rule only", "'on-delayed'", "--hysteresis"]),
        (["simulate", "cubesat_wheels", "--predictor"], ["predictor is not modelled", "--hysteresis"]),
        (["verify", "cubesat_wheels"], ["[wheels]: verify", "M = J - Gs diag(Js) Gs^T", "remove [wheels]"]),
        (["analyze", "cubesat_wheels"], ["[wheels]: analyze", "remove [wheels]"]),
        (["sweep", "eps", "--scenario", "cubesat_wheels"], ["rule only", "'boundary-layer'"]),
        (["export", "cubesat_wheels", "--out", "OUT", "--physical"], ["--physical", "wheel controller"]),
        (["export", "cubesat_wheels", "--out", "OUT", "--disturbance", "0", "0", "1e-4"], ["disturbance model"]),
    ],
    ids=[
        "plot-without-wheels",
        "plot-format",
        "torque-limit",
        "paper-rule",
        "predictor",
        "verify",
        "analyze",
        "sweep-eps",
        "export-physical",
        "export-models",
    ],
)
def test_what_a_wheel_scenario_does_not_take(
    argv: list[str], needles: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch
) -> None:
    monkeypatch.chdir(tmp_path)
    assert main(argv) == USER_ERROR
    one_line_error(capsys, *needles)
    assert not (tmp_path / "w.png").exists() and not (tmp_path / "OUT").exists()


def test_a_bad_wheels_table_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", _bad_file(tmp_path)]) == USER_ERROR
    one_line_error(capsys, "[wheels] spin_inertia must be > 0")


def test_sweep_tumble_flies_the_wheels(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["sweep", "tumble", "--scenario", "cubesat_wheels", "--count", "2", "--t-final", "6", "--json"]
    argv += ["--rate-range", "0.01", "0.05", "--angle-range", "20", "60"]
    assert main(argv) == 0
    runs = json.loads(capsys.readouterr().out)["runs"]
    scenario = load_scenario("cubesat_wheels")
    states = tumbling_states(2, seed=0, angle_deg=(20.0, 60.0), body_rate=(0.01, 0.05), cross_rate=0.05)
    for row, x0 in zip(runs, states, strict=True):
        one = simulate(
            scenario.spacecraft,
            scenario.K,
            x0,
            tau=scenario.tau,
            rule=scenario.rule,
            t_final=6.0,
            rate=scenario.rate,
            wheels=scenario.wheels,
        )
        assert row["max_abs_sigma"] == one.max_sigma and row["switches"] == one.switch_count
        assert row["settling_s"] == one.settling_time or (
            math.isnan(row["settling_s"]) and math.isnan(one.settling_time)
        )


def test_export_writes_the_wheel_controller(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "export"
    assert main(["export", "cubesat_wheels", "--out", str(out), "--no-compile", "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert any(name.endswith("wheel_controller.casadi") for name in printed["files"])
    manifest = json.loads((out / "manifest.json").read_text(encoding="utf-8"))
    assert manifest["wheels"]["count"] == 3 and manifest["wheels"]["torque_limit"] == [5e-3] * 3
    # the same files as the Python call on the scenario's values
    scenario = load_scenario("cubesat_wheels")
    assert scenario.wheels is not None and isinstance(scenario.rule, Hysteretic)
    direct = export_wheel_controller(
        scenario.spacecraft,
        scenario.K,
        scenario.wheels,
        tmp_path / "direct",
        tau=scenario.tau,
        rule=scenario.rule,
        rate=scenario.rate,
        compile=False,
    )
    assert direct.content_hash == printed["content_hash"]


def test_sweep_tumble_says_which_runs_the_wheels_cannot_hold(capsys: pytest.CaptureFixture[str]) -> None:
    # The default tumble (0.5-1.2 rad/s) carries up to 0.3 N m s; the cubesat's wheels hold 0.02 N m s per axis.
    argv = ["sweep", "tumble", "--scenario", "cubesat_wheels", "--count", "3", "--t-final", "2"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "3 of 3 runs start with more angular momentum than the wheels hold at rest" in out
    states = tumbling_states(3, seed=0, angle_deg=(160.0, 179.0), body_rate=(0.5, 1.2), cross_rate=0.05)
    scenario = load_scenario("cubesat_wheels")
    # independent of the linear program: three orthogonal wheels hold at most Js Ω_max about each body axis
    from mrpctl.mrp import to_dcm

    loads = []
    for x0 in states:
        h_n = to_dcm(x0[:3]).T @ (scenario.spacecraft.inertia @ (4.0 * x0[3:]))
        loads.append(np.max(np.abs(h_n) / scenario.wheels.momentum_capacity))
    assert f"up to {max(loads):.3g}x their capacity" in out
    argv = ["sweep", "tumble", "--scenario", "cubesat_wheels", "--count", "3", "--t-final", "2", "--json"]
    argv += ["--rate-range", "0.01", "0.05", "--cross-rate", "0.01"]
    assert main(argv) == 0
    document = json.loads(capsys.readouterr().out)
    assert all(0.0 < v < 1.0 for v in document["wheel_momentum_load"])
