"""Scenario files of the predictor: [rule] type = "on-predicted", the [predictor] table, the shipped predictor-paper."""

from __future__ import annotations

import copy
import math
import tomllib
from typing import Any

import numpy as np
import pytest

from mrpctl import OnPredicted, Predictor, paper, simulate
from mrpctl._compile import find_compiler
from mrpctl._predictor_study import FAST_OMEGA_N, RATE, TAU, X0
from mrpctl.design import pd_gains
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.flight import ActuatorModel
from mrpctl.scenario import (
    RULE_NAMES,
    load_scenario,
    parse_scenario,
    predictor_model,
    rule_from_name,
    rule_name,
    scenario_toml,
    shipped_scenarios,
)

needs_compiler = pytest.mark.skipif(find_compiler() is None, reason="no C compiler on this machine")

J = np.diag([140.0, 100.0, 80.0])
BASE: dict[str, Any] = {
    "tau": 0.5,
    "rate": 100.0,
    "t_final": 2.0,
    "spacecraft": {"inertia": [140.0, 100.0, 80.0]},
    "gains": {"K1": -4.0, "K2": -4.0},
    "initial": {"sigma": [0.93, 0.0, 0.0], "omega": [0.46, 0.0, 0.0]},
    "rule": {"type": "on-predicted", "alpha": 1.0},
    "predictor": {},
}


def _with(table: str, **changes: object) -> dict:
    data = copy.deepcopy(BASE)
    data[table] = {**data[table], **changes}
    return data


def _round_trip(scenario):
    return parse_scenario(tomllib.loads(scenario_toml(scenario)))


def test_rule_names_include_on_predicted() -> None:
    assert RULE_NAMES["on-predicted"] is OnPredicted
    assert rule_name(OnPredicted(1.2)) == "on-predicted"
    assert rule_from_name("on-predicted") == OnPredicted(1.0)
    assert rule_from_name("on-predicted", alpha=1.3) == OnPredicted(1.3)
    assert rule_from_name("on-predicted", alpha=math.inf) == OnPredicted(None)


@pytest.mark.parametrize(
    ("table", "expected"),
    [
        ({}, J),
        ({"inertia": [150.0, 95.0, 85.0]}, np.diag([150.0, 95.0, 85.0])),
        ({"inertia": [[150.0, 1.0, 0.0], [1.0, 95.0, 0.0], [0.0, 0.0, 85.0]]}, None),
        # the plant's error against the model: J = (1 + e) J_m (the convention of perturbed_spacecraft)
        ({"inertia_error": 0.1}, J / 1.1),
        ({"inertia_error": [0.1, -0.05, 0.2]}, np.diag([140.0 / 1.1, 100.0 / 0.95, 80.0 / 1.2])),
    ],
)
def test_predictor_table_gives_the_model(table: dict, expected: np.ndarray | None) -> None:
    scenario = parse_scenario(_with("predictor", **table) | {"predictor": table})
    assert isinstance(scenario.predictor, Predictor) and isinstance(scenario.rule, OnPredicted)
    want = np.array(table["inertia"]) if expected is None else expected
    np.testing.assert_allclose(scenario.predictor.model.inertia, want, rtol=1e-15, atol=0.0)
    np.testing.assert_array_equal(scenario.spacecraft.inertia, J)  # the plant is unchanged
    assert "predictor" in scenario.run_options and "predictor" not in scenario.flight_options
    back = _round_trip(scenario)
    np.testing.assert_array_equal(back.predictor.model.inertia, scenario.predictor.model.inertia)
    assert back.rule == scenario.rule and np.array_equal(back.K, scenario.K)


def test_per_axis_error_of_a_full_inertia_is_a_congruence() -> None:
    """3 errors on a non-diagonal J: J = S J_m S with S = diag(sqrt(1 + e_i)), J_m written out element by element."""
    full = [[140.0, 5.0, -2.0], [5.0, 100.0, 3.0], [-2.0, 3.0, 80.0]]
    errors = [0.1, -0.2, 0.3]
    model = predictor_model(parse_scenario(_with("spacecraft", inertia=full)).spacecraft, inertia_error=errors)
    expected = [[full[i][j] / math.sqrt((1 + errors[i]) * (1 + errors[j])) for j in range(3)] for i in range(3)]
    np.testing.assert_allclose(model.inertia, expected, rtol=1e-14)
    # and it is the inverse of perturbed_spacecraft's per-axis plant, axis by axis
    from mrpctl.predictor import perturbed_spacecraft

    plant = model
    for i in range(3):
        plant = perturbed_spacecraft(plant, errors[i], axis=i)
    np.testing.assert_allclose(plant.inertia, full, rtol=1e-14)


@pytest.mark.parametrize("alpha", [1.0, 1.25, math.inf])
def test_alpha_round_trips_and_inf_never_switches(alpha: float) -> None:
    scenario = parse_scenario(_with("rule", alpha=alpha))
    assert scenario.rule == OnPredicted(None if math.isinf(alpha) else alpha)
    assert _round_trip(scenario).rule == scenario.rule


def test_default_alpha_is_one() -> None:
    data = copy.deepcopy(BASE)
    del data["rule"]["alpha"]
    assert parse_scenario(data).rule == OnPredicted(1.0)


def test_actuator_table_applies_with_the_predictor() -> None:
    scenario = parse_scenario(BASE | {"actuator": {"u_max": 20.0}})
    assert isinstance(scenario.actuator, ActuatorModel)
    np.testing.assert_array_equal(scenario.actuator.u_max, [20.0, 20.0, 20.0])
    back = _round_trip(scenario)
    np.testing.assert_array_equal(back.actuator.u_max, scenario.actuator.u_max)
    assert back.actuator.mode is scenario.actuator.mode and back.predictor is not None


@pytest.mark.parametrize(
    ("data", "error", "needles"),
    [
        ({k: v for k, v in BASE.items() if k != "predictor"}, SpecificationError, ("[predictor]", "on-predicted")),
        (
            _with("rule", type="on-current", alpha=None) | {"rule": {"type": "on-current"}},
            SpecificationError,
            ("[predictor]", "on-predicted", "on-current"),
        ),
        (
            _with("predictor", inertia=[1.0, 2.0, 2.0], inertia_error=0.1),
            SpecificationError,
            ("[predictor]", "inertia_error", "not both"),
        ),
        (_with("predictor", inertia_error=-1.0), SpecificationError, ("[predictor]", "inertia_error", "> -1")),
        (_with("predictor", inertia_error=[0.1, 0.2]), DimensionError, ("[predictor]", "inertia_error", "(2,)")),
        (_with("predictor", inertia_error="big"), SpecificationError, ("[predictor]", "inertia_error")),
        (_with("predictor", inertia=[1.0, 2.0]), DimensionError, ("[predictor]",)),
        (_with("predictor", inertia=[-1.0, 2.0, 2.0]), SpecificationError, ("[predictor]",)),
        (_with("predictor", J=[1.0, 2.0, 2.0]), SpecificationError, ("'J'", "[predictor]")),
        (BASE | {"predictor": 3.0}, SpecificationError, ("[predictor]", "table")),
        (_with("rule", alpha=0.9), SpecificationError, ("[rule]", "alpha", ">= 1")),
        (_with("rule", alpha="x"), SpecificationError, ("[rule]", "alpha")),
        (_with("rule", eps=0.1), SpecificationError, ("[rule]", "eps", "on-predicted")),
        (BASE | {"history": "zero-input"}, SpecificationError, ("[predictor]", "history", "constant")),
        (BASE | {"delay": {"tau_min": 0.45}}, SpecificationError, ("[delay]", "on-predicted", "constant")),
    ],
)
def test_bad_predictor_scenarios_name_the_key(data: dict, error: type, needles: tuple[str, ...]) -> None:
    with pytest.raises(error) as info:
        parse_scenario(data)
    for needle in needles:
        assert needle in str(info.value), str(info.value)


def test_shipped_predictor_paper_is_the_study_case() -> None:
    """predictor-paper.toml is the case of mrpctl._predictor_study: paper plant, x0, tau, rate, fast gains."""
    assert "predictor-paper" in shipped_scenarios()
    scenario = load_scenario("predictor-paper")
    fast = pd_gains(paper.SPACECRAFT, zeta=1.0, omega_n=FAST_OMEGA_N).K
    np.testing.assert_allclose(scenario.K, fast, rtol=1e-14, atol=0.0)
    np.testing.assert_allclose(scenario.x0, X0, rtol=0.0, atol=1e-6)  # x0 from Phi = 171.6913 deg
    assert (scenario.tau, scenario.rate, scenario.t_final) == (TAU, RATE, 60.0)
    assert scenario.predictor is not None and scenario.predictor.model == paper.SPACECRAFT
    assert scenario.spacecraft == paper.SPACECRAFT
    assert scenario.rule == OnPredicted(1.0) and scenario.history == "constant"
    assert "predictor" in str(scenario).lower()


@needs_compiler
def test_scenario_simulate_is_simulate_with_the_predictor() -> None:
    """Scenario.simulate passes the predictor: identical to a direct simulate(..., predictor=) call."""
    scenario = parse_scenario(_with("predictor", inertia_error=0.05) | {"actuator": {"u_max": 3.0}})
    run = scenario.simulate()
    direct = simulate(
        scenario.spacecraft,
        scenario.K,
        scenario.x0,
        tau=0.5,
        rule=OnPredicted(1.0),
        t_final=2.0,
        rate=100.0,
        actuator=ActuatorModel(u_max=3.0),
        predictor=Predictor(model=scenario.spacecraft.__class__(1.05 * J)),
    )
    assert run.predictor is not None and run.saturated_fraction is not None and run.saturated_fraction > 0.0
    np.testing.assert_array_equal(run.sigma, direct.sigma)
    np.testing.assert_array_equal(run.u, direct.u)
    assert run.switch_count == direct.switch_count


@needs_compiler
def test_shipped_predictor_paper_runs_and_settles() -> None:
    """The full 60 s paper case with the predictor settles in 0.995 s without a switch (the fast gains brake
    before |sigma| reaches 1), as the independent NumPy reference loop found (design/predictor.md, 1 kHz row)."""
    result = load_scenario("predictor-paper").simulate()
    assert not result.diverged and result.converged
    assert result.switch_count == 0 and result.max_sigma < 1.0
    assert result.settling_time == pytest.approx(0.995, abs=1.5e-3)


def test_scenario_toml_refuses_on_predicted_without_a_model() -> None:
    """A file it could not read back is never written (mrpctl design --rule on-predicted --toml goes through here)."""
    from dataclasses import replace

    scenario = replace(parse_scenario(BASE), predictor=None)
    with pytest.raises(SpecificationError, match=r"on-predicted.*\[predictor\]"):
        scenario_toml(scenario)
