"""Scenario files: the shipped TOML files, their validation, and random tumbling states."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mrpctl import mrp, paper
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.reproduction import paper_scenarios
from mrpctl.scenario import load_scenario, parse_scenario, rule_from_name, tumbling_states
from mrpctl.switching import BoundaryLayer, DelayAware, NoSwitching, OnCurrent, OnDelayed

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "scenarios"


def _minimal() -> dict:
    return {
        "tau": 0.5,
        "t_final": 10.0,
        "spacecraft": {"inertia": [140.0, 100.0, 80.0]},
        "gains": {"k_sigma": -70.11, "k_omega": -163.08},
        "initial": {"sigma": [0.93, 0.0, 0.0], "omega": [0.46, 0.0, 0.0]},
        "rule": {"type": "on-delayed"},
    }


@pytest.mark.parametrize("name", sorted(paper_scenarios()))
def test_shipped_files_equal_builtin_scenarios(name: str) -> None:
    """examples/scenarios/*.toml and reproduction.paper_scenarios() describe the same runs."""
    from_file = load_scenario(EXAMPLES / f"{name}.toml")
    builtin = paper_scenarios()[name]
    assert from_file.name == builtin.name
    assert from_file.spacecraft == builtin.spacecraft
    assert np.array_equal(from_file.K, builtin.K)
    assert np.max(np.abs(from_file.x0 - builtin.x0)) < 1e-15
    assert (from_file.tau, from_file.rate, from_file.t_final) == (builtin.tau, builtin.rate, builtin.t_final)
    assert from_file.rule == builtin.rule
    assert from_file.history == builtin.history == "constant"


def test_initial_attitude_forms_agree() -> None:
    by_angle = parse_scenario(
        {
            **_minimal(),
            "initial": {"principal_angle_deg": 171.6913, "axis": [2.0, 0, 0], "omega": [0.46, 0, 0]},
        }
    )
    expected = mrp.from_principal_rotation([1.0, 0, 0], np.radians(171.6913))
    assert np.max(np.abs(by_angle.x0[:3] - expected)) < 1e-15
    assert np.max(np.abs(by_angle.x0 - paper.INITIAL_STATE)) < 1e-15


def test_gain_forms_agree() -> None:
    k_full = parse_scenario({**_minimal(), "gains": {"K": paper.GAIN.tolist()}}).K
    k_scalar = parse_scenario(_minimal()).K
    k1 = (-70.11 / (4 * np.array([140.0, 100.0, 80.0]))).tolist()
    k2 = (-163.08 / (4 * np.array([140.0, 100.0, 80.0]))).tolist()
    k_loop = parse_scenario({**_minimal(), "gains": {"K1": k1, "K2": k2}}).K
    assert np.array_equal(k_full, k_scalar)
    assert np.max(np.abs(k_loop - k_full)) < 1e-12


def test_rule_names() -> None:
    assert rule_from_name("none") == NoSwitching()
    assert rule_from_name("on-current") == OnCurrent()
    assert rule_from_name("on-delayed") == OnDelayed()
    assert rule_from_name("boundary-layer", eps=0.01) == BoundaryLayer(eps=0.01)
    assert rule_from_name("delay-aware") == DelayAware()
    assert rule_from_name("delay-aware", alpha=1.1) == DelayAware(alpha=1.1)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"colour": "red"}, "unknown key 'colour' in top level"),
        ({"rule": {"type": "on-delayed", "epsilon": 0.1}}, r"unknown key 'epsilon' in \[rule\]"),
        ({"spacecraft": {"inertia": [1, 2, 2], "mass": 3}}, r"unknown key 'mass' in \[spacecraft\]"),
        ({"rule": {"type": "sometimes"}}, "rule type must be one of"),
        ({"rule": {"type": "boundary-layer"}}, "needs eps"),
        ({"rule": {"type": "on-delayed", "eps": 0.1}}, "eps applies only to 'boundary-layer'"),
        ({"rule": {"type": "boundary-layer", "eps": -1.0}}, "eps .* must be > 0"),
        ({"rule": {"type": "delay-aware", "alpha": 0.5}}, "alpha .* must be >= 1"),
        ({"tau": -0.5}, "tau must be >= 0"),
        ({"tau": float("nan")}, "tau must be finite"),
        ({"t_final": 0.0}, "t_final must be > 0"),
        ({"history": "sometimes"}, "history must be"),
        ({"substeps": 0}, "substeps must be an integer >= 1"),
        ({"gains": {"k_sigma": -1.0}}, r"\[gains\] must give exactly one of"),
        ({"gains": {"k_sigma": -1.0, "k_omega": -1.0, "K": np.zeros((3, 6)).tolist()}}, "exactly one"),
        ({"initial": {"omega": [0, 0, 0]}}, "either sigma or"),
        ({"initial": {"sigma": [0.1, 0, 0]}}, "needs omega"),
        ({"initial": {"principal_angle_deg": 10.0, "omega": [0, 0, 0]}}, "needs both"),
        ({"spacecraft": {"inertia": [1.0, -1.0, 1.0]}}, "inertia must be positive definite"),
    ],
)
def test_bad_scenarios_name_the_problem(change: dict, message: str) -> None:
    with pytest.raises(SpecificationError, match=message):
        parse_scenario({**_minimal(), **change})


def test_bad_shapes() -> None:
    with pytest.raises(DimensionError, match=r"K: expected shape \(3, 6\)"):
        parse_scenario({**_minimal(), "gains": {"K": [[1.0, 2.0]]}})
    with pytest.raises(DimensionError, match="sigma"):
        parse_scenario({**_minimal(), "initial": {"sigma": [0.1, 0.2], "omega": [0, 0, 0]}})


def test_missing_and_invalid_files(tmp_path: Path) -> None:
    with pytest.raises(SpecificationError, match="not found"):
        load_scenario(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("tau = [", encoding="utf-8")
    with pytest.raises(SpecificationError, match="not valid TOML"):
        load_scenario(bad)


def test_tumbling_states_are_reproducible_and_tumble() -> None:
    states = tumbling_states(200, seed=3)
    assert states.shape == (200, 6)
    assert np.array_equal(states, tumbling_states(200, seed=3))
    sigma, omega = states[:, :3], 4 * states[:, 3:]
    angle = np.degrees(4 * np.arctan(np.linalg.norm(sigma, axis=1)))
    assert np.all((angle >= 160.0) & (angle <= 179.0))
    axis = sigma / np.linalg.norm(sigma, axis=1, keepdims=True)
    along = np.sum(omega * axis, axis=1)
    assert np.all((along >= 0.5) & (along <= 1.2))  # rotating towards 180 deg
    across = np.linalg.norm(omega - along[:, None] * axis, axis=1)
    assert np.all(across <= 0.05 + 1e-12)
    with pytest.raises(SpecificationError, match="count"):
        tumbling_states(0)
