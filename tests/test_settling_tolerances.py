"""Settling tolerances as parameters (attitude as a principal angle in degrees, rate in rad/s): run-time constants
of the compiled sample, in simulate, simulate_batch (scalar engine and lanes), results, scenarios, campaigns and
the command line; the defaults give the compiled-in bounds of before (|σ| < 1e-2, |ω| < 1e-3) bit for bit."""

from __future__ import annotations

import json
import math
import tomllib

import numpy as np
import pytest

from mrpctl import OnCurrent, OnDelayed, OnPredicted, Predictor, paper, simulate, simulate_batch
from mrpctl.cli import USER_ERROR, main
from mrpctl.errors import SpecificationError
from mrpctl.flight import Hysteretic
from mrpctl.scenario import parse_scenario, scenario_toml
from mrpctl.simulation import SETTLING_ATTITUDE_DEG, SETTLING_OMEGA, SETTLING_SIGMA

SC = paper.SPACECRAFT
X0 = paper.INITIAL_STATE
COMMON = dict(tau=0.5, t_final=60.0, rate=100.0)
LOOSE = dict(settling_attitude=10.0, settling_rate=1e-2)  # deg, rad/s


def _settling(
    sigma: np.ndarray, omega: np.ndarray, rate: float, attitude_deg: float, omega_bound: float
) -> float | None:
    """The settling time from a kept trajectory (every sample), written again here."""
    bound = math.tan(math.radians(attitude_deg) / 4.0)
    unsettled = (np.sum(sigma * sigma, axis=1) >= bound**2) | (np.sum(omega * omega, axis=1) >= omega_bound**2)
    last = int(np.flatnonzero(unsettled)[-1])
    return (last + 1) / rate if last + 1 < len(sigma) else None


def test_the_default_angle_is_the_old_bound_exactly() -> None:
    assert math.tan(math.radians(SETTLING_ATTITUDE_DEG) / 4.0) == SETTLING_SIGMA == 1e-2
    assert pytest.approx(2.2917547907) == SETTLING_ATTITUDE_DEG and SETTLING_OMEGA == 1e-3


@pytest.mark.parametrize("rule", [OnCurrent(), Hysteretic(0.1)])
def test_simulate_settles_on_the_given_tolerances(rule) -> None:
    default = simulate(SC, paper.GAIN, X0, rule=rule, **COMMON)
    explicit = simulate(
        SC, paper.GAIN, X0, rule=rule, settling_attitude=SETTLING_ATTITUDE_DEG, settling_rate=1e-3, **COMMON
    )
    assert explicit.settling_time == default.settling_time
    assert default.settling_time == _settling(default.sigma, default.omega, 100.0, SETTLING_ATTITUDE_DEG, 1e-3)
    loose = simulate(SC, paper.GAIN, X0, rule=rule, **LOOSE, **COMMON)
    assert (loose.settling_attitude, loose.settling_rate) == (10.0, 1e-2)
    assert loose.settling_time == _settling(loose.sigma, loose.omega, 100.0, 10.0, 1e-2)
    assert default.settling_time is not None and loose.settling_time is not None
    assert loose.settling_time < default.settling_time
    assert np.array_equal(loose.sigma, default.sigma)  # only the metric moves


def test_batches_on_both_engines_and_the_predictor_take_them() -> None:
    x0 = np.stack([X0, 0.5 * X0])
    rules = [OnCurrent(), Hysteretic(0.1)]
    lanes = simulate_batch(SC, paper.GAIN, x0, rule=rules, **LOOSE, **COMMON)  # metrics only: the lane engine
    scalar = simulate_batch(SC, paper.GAIN, x0, rule=rules, trajectories=True, **LOOSE, **COMMON)
    assert np.array_equal(lanes.settling_time, scalar.settling_time)
    assert (lanes.settling_attitude, lanes.settling_rate) == (10.0, 1e-2)
    for i, run in enumerate(scalar.runs or ()):
        assert run.settling_time == scalar.settling_time[i] == _settling(run.sigma, run.omega, 100.0, 10.0, 1e-2)
    default = simulate_batch(SC, paper.GAIN, x0, rule=rules, **COMMON)
    assert np.all(default.settling_time > lanes.settling_time)
    pred = simulate(SC, paper.GAIN, X0, rule=OnPredicted(), predictor=Predictor(model=SC), **LOOSE, **COMMON)
    assert pred.settling_time == _settling(pred.sigma, pred.omega, 100.0, 10.0, 1e-2)


@pytest.mark.parametrize(
    ("keywords", "name"),
    [
        ({"settling_attitude": 0.0}, "settling_attitude"),
        ({"settling_attitude": -1.0}, "settling_attitude"),
        ({"settling_attitude": 181.0}, "settling_attitude"),
        ({"settling_attitude": math.nan}, "settling_attitude"),
        ({"settling_attitude": math.inf}, "settling_attitude"),
        ({"settling_rate": 0.0}, "settling_rate"),
        ({"settling_rate": -1e-3}, "settling_rate"),
        ({"settling_rate": math.nan}, "settling_rate"),
        ({"settling_rate": math.inf}, "settling_rate"),
    ],
)
def test_bad_tolerances_are_refused_naming_the_parameter(keywords, name) -> None:
    with pytest.raises(SpecificationError, match=name):
        simulate(SC, paper.GAIN, X0, rule=OnDelayed(), tau=0.5, t_final=1.0, **keywords)
    with pytest.raises(SpecificationError, match=name):
        simulate_batch(SC, paper.GAIN, X0, rule=OnDelayed(), tau=0.5, t_final=1.0, **keywords)


SCENARIO = """
tau = 0.5
rate = 100.0
t_final = 60.0
settling_attitude_deg = 10.0
settling_rate = 0.01
[spacecraft]
inertia = [140.0, 100.0, 80.0]
[gains]
k_sigma = -70.11
k_omega = -163.08
[initial]
sigma = [0.93, 0.0, 0.0]
omega = [0.46, 0.0, 0.0]
[rule]
type = "on-current"
"""


def test_scenarios_keep_them_and_write_them_back() -> None:
    scenario = parse_scenario(tomllib.loads(SCENARIO))
    assert (scenario.settling_attitude, scenario.settling_rate) == (10.0, 0.01)
    run = scenario.simulate()
    direct = simulate(SC, scenario.K, scenario.x0, rule=OnCurrent(), **LOOSE, **COMMON)
    assert run.settling_time == direct.settling_time and run.settling_attitude == 10.0
    back = parse_scenario(tomllib.loads(scenario_toml(scenario)))
    assert (back.settling_attitude, back.settling_rate) == (10.0, 0.01)
    with pytest.raises(SpecificationError, match="settling_attitude"):
        parse_scenario(tomllib.loads(SCENARIO.replace("settling_attitude_deg = 10.0", "settling_attitude_deg = 0")))


def test_the_command_line_takes_them(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["simulate", "paper_fig3_on_current", "--rate", "100", "--json"]
    assert main([*argv, "--settling-attitude", "10", "--settling-rate", "0.01"]) == 0
    result = json.loads(capsys.readouterr().out)["result"]
    direct = simulate(SC, paper.GAIN, X0, rule=OnCurrent(), **LOOSE, **COMMON)
    assert direct.settling_time is not None
    assert result["settling_time"] == direct.settling_time and result["settling_attitude_deg"] == 10.0
    assert main(["sweep", "tau", "--values", "0.5", "--rule", "on-current", "--rate", "100", "--json",
                 "--settling-attitude", "10", "--settling-rate", "0.01"]) == 0  # fmt: skip
    assert json.loads(capsys.readouterr().out)["runs"][0]["settling_s"] == direct.settling_time
    assert main([*argv, "--settling-attitude", "-2"]) == USER_ERROR
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--settling-attitude" in err[0]
    assert main([*argv, "--settling-rate", "nan"]) == USER_ERROR
    assert "--settling-rate" in capsys.readouterr().err


def test_a_campaign_takes_them() -> None:
    from mrpctl.campaign._task import simulate_chunk
    from mrpctl.campaign.spec import parse_campaign

    data = tomllib.loads(SCENARIO)
    data.update(count=2, seed=1, rule={"type": "on-current"})
    data["dispersions"] = {"omega": {"magnitude": [0.0, 0.3]}}
    spec = parse_campaign(data)
    assert (spec.base.settling_attitude, spec.base.settling_rate) == (10.0, 0.01)
    chunk = simulate_chunk(spec, 0, 2, threads=1)
    x0 = np.hstack((chunk["sigma0"], chunk["omega0"] / 4.0))
    batch = simulate_batch(SC, paper.GAIN, x0, rule=OnCurrent(), **LOOSE, **COMMON)
    assert np.all(np.isfinite(batch.settling_time))
    assert np.array_equal(chunk["settling_time"], batch.settling_time)


def test_saved_runs_keep_them(tmp_path) -> None:
    from mrpctl import data

    run = simulate(SC, paper.GAIN, X0, rule=OnCurrent(), **LOOSE, **COMMON)
    back = data.load(data.save(run, tmp_path / "run.nc"))
    assert (back.settling_attitude, back.settling_rate, back.settling_time) == (10.0, 1e-2, run.settling_time)
    plain = data.load(data.save(simulate(SC, paper.GAIN, X0, rule=OnCurrent(), **COMMON), tmp_path / "plain.nc"))
    assert (plain.settling_attitude, plain.settling_rate) == (SETTLING_ATTITUDE_DEG, SETTLING_OMEGA)


def test_the_virtual_machine_takes_them(monkeypatch: pytest.MonkeyPatch) -> None:
    from mrpctl import _compile
    from mrpctl._compile import CompilerWarning
    from mrpctl.engines.scalar import clear_engines

    arguments = dict(rule=OnCurrent(), **COMMON, **LOOSE)
    compiled = simulate(SC, paper.GAIN, X0, **arguments)
    clear_engines()
    try:
        monkeypatch.setattr(_compile, "find_compiler", lambda: None)
        with pytest.warns(CompilerWarning):
            interpreted = simulate(SC, paper.GAIN, X0, **arguments)
    finally:
        clear_engines()
    assert compiled.settling_time is not None
    assert interpreted.settling_time == compiled.settling_time
    assert interpreted.settling_time == _settling(interpreted.sigma, interpreted.omega, 100.0, 10.0, 1e-2)
    assert interpreted.plant_set_changes == compiled.plant_set_changes == compiled.switch_count
