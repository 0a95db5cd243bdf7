"""mrpctl simulate / export with the predictor options, their one-line errors (exit code 2), the README example."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from cli_assertions import one_line_error as _one_line_error

from mrpctl import OnPredicted, Predictor, paper, simulate
from mrpctl._compile import find_compiler
from mrpctl.cli import USER_ERROR, main
from mrpctl.flight import ActuatorModel
from mrpctl.reproduction import paper_scenarios
from mrpctl.scenario import load_scenario
from mrpctl.spacecraft import Spacecraft

needs_compiler = pytest.mark.skipif(find_compiler() is None, reason="no C compiler on this machine")
README = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")
J = np.diag([140.0, 100.0, 80.0])


def _json(capsys: pytest.CaptureFixture[str]) -> dict:
    return json.loads(capsys.readouterr().out)


@needs_compiler
def test_simulate_shipped_predictor_scenario(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", "predictor-paper", "--t-final", "2", "--rate", "100", "--json"]) == 0
    out = _json(capsys)
    base = load_scenario("predictor-paper")
    direct = simulate(
        base.spacecraft,
        base.K,
        base.x0,
        tau=0.5,
        rule=OnPredicted(1.0),
        t_final=2.0,
        rate=100.0,
        predictor=Predictor(model=base.spacecraft),
    )
    assert out["scenario"]["rule"] == out["result"]["rule"] == "on-predicted"
    np.testing.assert_array_equal(out["scenario"]["predictor_inertia"], J)
    assert out["result"]["switch_count"] == direct.switch_count
    np.testing.assert_array_equal(out["result"]["final_sigma"], direct.sigma[-1])


@needs_compiler
@pytest.mark.parametrize(
    ("options", "model", "alpha"),
    [
        (["--predictor"], J, 1.0),
        (["--predictor-error", "0.1", "--alpha", "1.2"], J / 1.1, 1.2),  # the plant J = 1.1 J_m
        (["--predictor-error", "0.1", "-0.05", "0.2"], np.diag([140.0 / 1.1, 100.0 / 0.95, 80.0 / 1.2]), 1.0),
        (
            ["--predictor-inertia", "150", "95", "85", "--rule", "on-predicted", "--alpha", "inf"],
            np.diag([150.0, 95.0, 85.0]),
            None,
        ),
        (
            ["--predictor-inertia", *map(str, (150, 1, 0, 1, 95, 0, 0, 0, 85))],
            np.array([[150.0, 1, 0], [1, 95, 0], [0, 0, 85]]),
            1.0,
        ),
    ],
)
def test_predictor_options_reach_simulate(
    capsys: pytest.CaptureFixture[str], options: list[str], model: np.ndarray, alpha: float | None
) -> None:
    """Without a file (the paper's example, delay-aware rule), a predictor option selects 'on-predicted'."""
    argv = ["simulate", *options, "--t-final", "1.5", "--rate", "100", "--torque-limit", "20", "--json"]
    assert main(argv) == 0
    out = _json(capsys)
    np.testing.assert_allclose(out["scenario"]["predictor_inertia"], model, rtol=1e-15)
    direct = simulate(
        paper.SPACECRAFT,
        paper.GAIN,
        paper_scenarios()["delay_aware"].x0,
        tau=0.5,
        rule=OnPredicted(alpha),
        t_final=1.5,
        rate=100.0,
        actuator=ActuatorModel(u_max=20.0),
        predictor=Predictor(model=Spacecraft(model)),
    )
    assert out["result"]["rule"] == "on-predicted"
    assert out["result"]["switch_count"] == direct.switch_count
    assert out["result"]["saturated_fraction"] == direct.saturated_fraction
    np.testing.assert_array_equal(out["result"]["final_omega"], direct.omega[-1])


@pytest.mark.parametrize(
    ("argv", "needles"),
    [
        (["simulate", "--rule", "on-predicted"], ("--predictor", "on-predicted")),
        (["simulate", "--predictor", "--rule", "on-current"], ("--predictor", "on-predicted", "on-current")),
        (["simulate", "predictor-paper", "--rule", "on-current"], ("[predictor]", "on-current")),
        (["simulate", "--predictor", "--hysteresis", "0.1"], ("--hysteresis", "--predictor")),
        (["simulate", "--predictor", "--jitter", "0.45", "0.5"], ("--jitter", "predictor")),
        (["simulate", "--predictor", "--history", "zero-input"], ("--history", "constant")),
        (["simulate", "--predictor", "--eps", "0.1"], ("--eps", "on-predicted")),
        (["simulate", "--predictor", "--alpha", "0.5"], ("--alpha", ">= 1")),
        (["simulate", "--predictor-inertia", "1", "2"], ("--predictor-inertia", "3", "9")),
        (["simulate", "--predictor-inertia", "-1", "2", "2"], ("--predictor-inertia",)),
        (["simulate", "--predictor-error", "-1"], ("--predictor-error", "> -1")),
        (["simulate", "--predictor-error", "0.1", "0.2"], ("--predictor-error", "1 or 3")),
        (
            ["simulate", "--predictor-error", "0.1", "--predictor-inertia", "1", "1", "1"],
            ("--predictor-inertia", "--predictor-error", "one of them"),
        ),
        (["sweep", "tau", "--scenario", "predictor-paper", "--values", "0.5"], ("sweep", "predictor")),
        (["sweep", "tau", "--rule", "on-predicted", "--values", "0.5"], ("sweep", "predictor")),
        (["export", "predictor-paper", "--out", "never", "--rule", "delay-aware"], ("[predictor]", "delay-aware")),
        (["export", "predictor-paper", "--out", "never", "--jitter", "0.45", "0.5"], ("--jitter", "predictor")),
    ],
)
def test_predictor_errors_are_one_line(
    capsys: pytest.CaptureFixture[str],
    argv: list[str],
    needles: tuple[str, ...],
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.chdir(tmp_path)
    assert main(argv) == USER_ERROR
    _one_line_error(capsys, *needles)
    assert not (tmp_path / "never").exists()


def test_export_manifest_of_a_predictor_scenario(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    out = tmp_path / "exported"
    argv = ["export", "predictor-paper", "--out", str(out), "--no-compile", "--predictor-error", "0.05"]
    assert main([*argv, "--alpha", "1.1", "--torque-limit", "20", "--json"]) == 0
    result = _json(capsys)
    manifest = json.loads((out / "manifest.json").read_text(encoding="utf-8"))
    section = manifest["predictor"]
    np.testing.assert_allclose(section["model_inertia"], J / 1.05, rtol=1e-15)
    assert section["alpha"] == 1.1 and section["tau"] == 0.5
    assert section["actuator"]["u_max"] == [20.0, 20.0, 20.0]
    assert "predictor_controller" in " ".join(result["files"])
    # the scenario's own [predictor] (the exact model) and alpha when no option changes them
    assert main(["export", "predictor-paper", "--out", str(tmp_path / "plain"), "--no-compile", "--json"]) == 0
    capsys.readouterr()
    plain = json.loads((tmp_path / "plain" / "manifest.json").read_text(encoding="utf-8"))["predictor"]
    np.testing.assert_array_equal(plain["model_inertia"], J)
    assert plain["alpha"] == 1.0 and plain["actuator"] is None


@pytest.mark.slow  # about 8 s: the exact 1 kHz margin search of the example
@needs_compiler
def test_readme_delay_compensation_example(capsys: pytest.CaptureFixture[str]) -> None:
    """The README's "Delay compensation" block runs as written and prints what its comments say."""
    section = README.split("## Delay compensation", 1)[1]
    block = re.search(r"```python\n(.*?)```", section, re.S)
    assert block is not None
    code = block.group(1)
    scope: dict[str, object] = {}
    exec(compile(code, "README.md", "exec"), scope)
    out = capsys.readouterr().out
    assert "+/-19.9185%" in out
    run = scope["run"]
    assert run.converged and run.switch_count == 0  # type: ignore[attr-defined]
    assert f"settling time {run.settling_time:.3f} s" in out and round(run.settling_time, 3) == 3.003  # type: ignore[attr-defined]
