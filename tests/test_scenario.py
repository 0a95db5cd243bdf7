"""Scenario files: the shipped TOML files, their validation, and random tumbling states."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from mrpctl import mrp, paper
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.flight import Hysteretic
from mrpctl.reproduction import flight_scenarios, paper_scenarios
from mrpctl.scenario import (
    STARTER_SCENARIO,
    load_scenario,
    parse_scenario,
    resolve_scenario,
    rule_from_name,
    scenario_toml,
    shipped_scenarios,
    tumbling_states,
)
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import BoundaryLayer, DelayAware, NoSwitching, OnCurrent, OnDelayed

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples" / "scenarios"
PACKAGE = ROOT / "mrpctl" / "scenarios"


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


def test_examples_are_the_package_data_files() -> None:
    """One copy: examples/scenarios is the package-data folder mrpctl/scenarios (shipped in the wheel)."""
    assert EXAMPLES.resolve() == PACKAGE.resolve()
    shipped = shipped_scenarios()
    # predictor-paper: checked against mrpctl._predictor_study in tests/test_scenario_predictor.py;
    # nadir: checked in tests/test_scenario_tracking.py;
    # cubesat_wheels: in tests/test_scenario_wheels.py and by the how-to that sizes its wheels (test_docs_wheels.py)
    expected = set(paper_scenarios()) | set(flight_scenarios()) | {"predictor-paper", "nadir", "cubesat_wheels"}
    assert set(shipped) == expected == {p.stem for p in PACKAGE.glob("*.toml")}
    assert all(path.resolve().parent == PACKAGE.resolve() for path in shipped.values())


def test_shipped_names_resolve(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    assert resolve_scenario("paper_fig4_on_delayed") == shipped_scenarios()["paper_fig4_on_delayed"]
    assert resolve_scenario("paper_fig4_on_delayed.toml") == shipped_scenarios()["paper_fig4_on_delayed"]
    (tmp_path / "paper_fig4_on_delayed.toml").write_text("x = 1\n", encoding="utf-8")
    assert resolve_scenario("paper_fig4_on_delayed.toml") == Path("paper_fig4_on_delayed.toml")  # a file wins
    with pytest.raises(
        SpecificationError, match=r"not found: nope.*shipped scenario names: cubesat_wheels, delay_aware"
    ):
        load_scenario("nope")


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


def test_per_axis_and_scalar_gains() -> None:
    """k_sigma/k_omega per axis, and K1/K2 as scalars, per axis or matrices, against K built by hand."""
    inertia = np.array([12.0, 15.0, 9.0])
    base = {**_minimal(), "spacecraft": {"inertia": inertia.tolist()}}
    per_axis = parse_scenario({**base, "gains": {"k_sigma": [-1.0, -2.0, -3.0], "k_omega": [-4.0, -5.0, -6.0]}}).K
    expected = np.zeros((3, 6))
    for i in range(3):
        expected[i, i], expected[i, 3 + i] = -(i + 1.0), -(i + 4.0)
    assert np.array_equal(per_axis, expected)
    scalar = parse_scenario({**base, "gains": {"K1": -0.64, "K2": -1.6}}).K
    by_hand = np.zeros((3, 6))
    for i in range(3):
        by_hand[i, i], by_hand[i, 3 + i] = 4.0 * inertia[i] * -0.64, 4.0 * inertia[i] * -1.6
    assert np.max(np.abs(scalar - by_hand)) <= 1e-15 * np.max(np.abs(by_hand))
    vector = parse_scenario({**base, "gains": {"K1": [-0.64] * 3, "K2": (-1.6 * np.eye(3)).tolist()}}).K
    assert np.array_equal(vector, scalar)
    with pytest.raises(DimensionError, match="k_sigma: expected a scalar or 3 per-axis values"):
        parse_scenario({**base, "gains": {"k_sigma": [-1.0, -2.0], "k_omega": -1.0}})


def test_written_scenario_reads_back_bit_for_bit() -> None:
    """scenario_toml -> parse: J (full 3x3), K, x0 and the rule come back exactly."""
    rng = np.random.default_rng(5)
    rotation = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    inertia = rotation @ np.diag([12.0, 15.0, 9.0]) @ rotation.T
    inertia = (inertia + inertia.T) / 2
    scenario = paper_scenarios()["paper_fig7_boundary_layer"]
    from dataclasses import replace

    scenario = replace(
        scenario,
        name="random",
        spacecraft=Spacecraft(inertia),
        K=rng.normal(size=(3, 6)) * 100,
        x0=rng.normal(size=6) / 3,
        tau=0.2,
        substeps=2,
    )
    text = scenario_toml(scenario, comment="line one\nline two")
    assert text.startswith("# line one\n# line two\n")
    back = parse_scenario(tomllib.loads(text), name="other")
    assert back.name == "random" and back.spacecraft == scenario.spacecraft
    assert np.array_equal(back.K, scenario.K) and np.array_equal(back.x0[:3], scenario.x0[:3])
    assert np.max(np.abs(back.x0 - scenario.x0)) <= 1e-16
    assert back.rule == BoundaryLayer(eps=paper.BOUNDARY_LAYER_EPS)
    assert (back.tau, back.rate, back.t_final, back.substeps) == (0.2, 1000.0, 60.0, 2)


def test_starter_scenario_loads() -> None:
    starter = parse_scenario(tomllib.loads(STARTER_SCENARIO))
    k = np.diag(4.0 * np.array([12.0, 15.0, 9.0]))
    assert np.max(np.abs(starter.K - np.hstack((-0.64 * k, -1.6 * k)))) < 1e-12
    assert starter.rule == Hysteretic(0.1) and starter.tau == 0.2  # the command line's default rule


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
        ({"substeps": 0}, "substeps must be >= 1"),
        ({"substeps": True}, "substeps must be an integer"),
        ({"tau": True}, "tau must be a real number, got the boolean"),
        ({"t_final": False}, "t_final must be a real number, got the boolean"),
        ({"rate": True}, "rate must be a real number, got the boolean"),
        ({"tau": 0.0005}, r"tau \* rate must be a whole number"),
        ({"gains": {"k_sigma": True, "k_omega": -1.0}}, "k_sigma must be numeric, got booleans"),
        ({"rule": {"type": "boundary-layer", "eps": True}}, "eps must be a real number, got the boolean"),
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
    latin1 = tmp_path / "latin1.toml"
    latin1.write_bytes('description = "J = 140 kg m\u00b2"\n'.encode("latin-1"))
    with pytest.raises(SpecificationError, match=r"latin1.toml is not UTF-8 text .*b'\\xb2'"):
        load_scenario(latin1)
    with pytest.raises(SpecificationError, match="is a folder"):
        load_scenario(tmp_path)


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
    with pytest.raises(SpecificationError, match="seed must be >= 0, got -1"):
        tumbling_states(3, seed=-1)


def test_tumbling_ranges_are_settable() -> None:
    states = tumbling_states(100, seed=1, angle_deg=(90.0, 100.0), body_rate=(2.0, 3.0), cross_rate=0.0)
    sigma, omega = states[:, :3], 4 * states[:, 3:]
    angle = np.degrees(4 * np.arctan(np.linalg.norm(sigma, axis=1)))
    assert np.all((angle >= 90.0 - 1e-9) & (angle <= 100.0 + 1e-9))
    axis = sigma / np.linalg.norm(sigma, axis=1, keepdims=True)
    assert np.allclose(np.cross(omega, axis), 0.0, atol=1e-12)  # no cross rate
    assert np.all((np.linalg.norm(omega, axis=1) >= 2.0) & (np.linalg.norm(omega, axis=1) <= 3.0))
