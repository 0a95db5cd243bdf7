"""Options that compose: plant and initial-state options override a scenario file as every other option does,
``sweep`` takes the loop-as-flown options, and what is not modelled is refused with what to use instead."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mrpctl import BoundaryLayer, DelayAware, NoSwitching, OnCurrent, OnDelayed, paper, simulate, simulate_batch
from mrpctl.cli import USER_ERROR, main
from mrpctl.errors import SpecificationError
from mrpctl.flight import ActuatorModel, DelayModel, Disturbance, Hysteretic, SensorModel
from mrpctl.scenario import load_scenario, tumbling_states
from mrpctl.spacecraft import Spacecraft


def _json(capsys: pytest.CaptureFixture[str]) -> dict:
    return json.loads(capsys.readouterr().out)


def test_plant_and_initial_state_options_override_a_scenario_file(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["simulate", "paper_fig3_on_current", "--t-final", "2", "--rate", "100", "--json"]
    argv += ["--inertia", "120", "100", "90", "--k-sigma", "-50", "--k-omega", "-150", "--omega", "0.2", "0", "0"]
    assert main(argv) == 0
    out = _json(capsys)
    file = load_scenario("paper_fig3_on_current")
    assert out["scenario"]["inertia"] == np.diag([120.0, 100.0, 90.0]).tolist()
    assert out["scenario"]["sigma0"] == file.x0[:3].tolist() and out["scenario"]["omega0"] == [0.2, 0.0, 0.0]
    gain = np.hstack((-50.0 * np.eye(3), -150.0 * np.eye(3)))
    direct = simulate(
        Spacecraft([120.0, 100.0, 90.0]),
        gain,
        np.concatenate((file.x0[:3], [0.05, 0.0, 0.0])),
        tau=0.5,
        rule=OnCurrent(),
        t_final=2.0,
        rate=100.0,
    )
    assert out["result"]["final_omega"] == direct.omega[-1].tolist()


def test_sweep_takes_the_loop_as_flown_options(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["sweep", "tumble", "--count", "3", "--t-final", "2", "--rate", "100", "--json"]
    assert main([*argv, "--torque-limit", "5", "--disturbance", "0.1", "0", "0", "--attitude-noise", "1e-3"]) == 0
    runs = _json(capsys)["runs"]
    x0 = tumbling_states(3, seed=0)
    batch = simulate_batch(
        paper.SPACECRAFT,
        paper.GAIN,
        x0,
        tau=0.5,
        rule=Hysteretic(0.1),
        t_final=2.0,
        rate=100.0,
        actuator=ActuatorModel(u_max=5.0),
        disturbance=Disturbance([0.1, 0.0, 0.0]),
        sensor=SensorModel(attitude_noise=1e-3),
    )
    assert [r["max_abs_sigma"] for r in runs] == batch.max_sigma.tolist()
    assert [r["switches"] for r in runs] == batch.switch_count.tolist()


def test_sweep_tau_with_a_jittering_delay_says_what_to_use(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sweep", "tau", "--values", "0.3", "0.5", "--jitter", "0.4", "0.5"]) == USER_ERROR
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "sweep tau with a jittering delay" in err[0] and "sweep tau without it" in err[0]


@pytest.mark.parametrize("rule", [NoSwitching(), OnCurrent(), OnDelayed(), BoundaryLayer(0.05), DelayAware()])
@pytest.mark.parametrize(
    "option",
    [
        {"actuator": ActuatorModel(u_max=5.0)},
        {"sensor": SensorModel(attitude_noise=1e-3)},
        {"disturbance": Disturbance([0.1, 0.0, 0.0])},
        {"delay": DelayModel.jitter(0.4, 0.5, seed=1)},
    ],
)
def test_a_plant_side_rule_with_a_flight_model_is_refused_naming_what_to_use(rule, option) -> None:
    with pytest.raises(SpecificationError, match=r"Hysteretic\("):
        simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, tau=0.5, t_final=1.0, rule=rule, **option)
