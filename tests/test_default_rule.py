"""The default rule (the command line without a file, ``design --toml``, the ``init`` starter, the example
campaigns) is the controller-side hysteresis the docs call sound, not ``DelayAware``; the paper keeps its rules."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import pytest

from mrpctl.campaign import load_campaign
from mrpctl.cli import main
from mrpctl.cli.overrides import paper_base
from mrpctl.flight import Hysteretic
from mrpctl.rules import DEFAULT_DELTA, DEFAULT_RULE
from mrpctl.scenario import STARTER_SCENARIO, load_scenario, parse_scenario, shipped_scenarios
from mrpctl.switching import BoundaryLayer, DelayAware, NoSwitching, OnCurrent, OnDelayed

ROOT = Path(__file__).resolve().parents[1]


def _json(capsys: pytest.CaptureFixture[str]) -> dict:
    return json.loads(capsys.readouterr().out)


def test_the_default_rule_is_the_documented_hysteresis() -> None:
    assert Hysteretic(DEFAULT_DELTA) == DEFAULT_RULE and DEFAULT_DELTA == 0.1
    assert 1.05 <= DEFAULT_RULE.alpha <= 1.2  # the band design/flight.md recommends
    flight_doc = (ROOT / "design" / "flight.md").read_text(encoding="utf-8")
    assert "Recommendation: use the controller-side rule with α ≈ 1.05–1.2" in flight_doc
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert "**not sound in general**" in readme and "`Hysteretic(0.1)`" in readme
    assert paper_base().rule == DEFAULT_RULE


def test_simulate_and_sweep_without_a_file_use_it(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", "--t-final", "1", "--rate", "100", "--json"]) == 0
    out = _json(capsys)
    assert out["scenario"]["rule"] == "hysteretic" and "0.1" in out["scenario"]["rule_repr"]
    assert main(["sweep", "tumble", "--count", "2", "--t-final", "1", "--rate", "100", "--json"]) == 0
    assert _json(capsys)["rule"] == str(DEFAULT_RULE)
    # the loop-as-flown options apply to the default rule without --hysteresis
    assert main(["simulate", "--torque-limit", "20", "--t-final", "1", "--rate", "100", "--json"]) == 0
    assert _json(capsys)["result"]["saturated_fraction"] > 0.0


def test_design_toml_and_the_starter_write_it(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "s.toml"
    argv = ["design", "--inertia", "12", "15", "9", "--tau", "0.05", "--order", "1", "--rate", "100"]
    assert main([*argv, "--toml", str(path), "--json"]) == 0
    capsys.readouterr()
    assert load_scenario(path).rule == DEFAULT_RULE
    assert parse_scenario(tomllib.loads(STARTER_SCENARIO)).rule == DEFAULT_RULE
    start = tmp_path / "start.toml"
    assert main(["init", str(start)]) == 0
    assert load_scenario(start).rule == DEFAULT_RULE


def test_no_shipped_file_defaults_to_delay_aware() -> None:
    # the shipped scenarios: the paper's rules, the flight and predictor cases, and the one demonstration of
    # DelayAware that the reproduction draws (delay_aware.png), named after it
    rules = {name: load_scenario(path).rule for name, path in shipped_scenarios().items()}
    assert [name for name, rule in rules.items() if isinstance(rule, DelayAware)] == ["delay_aware"]
    assert rules["paper_fig2_tau0_on_current"] == OnCurrent() and rules["paper_fig3_on_current"] == OnCurrent()
    assert rules["paper_fig4_on_delayed"] == OnDelayed() and rules["paper_fig6_no_switching"] == NoSwitching()
    assert isinstance(rules["paper_fig7_boundary_layer"], BoundaryLayer)
    for path in sorted((ROOT / "examples" / "campaigns").glob("*.toml")):
        spec = load_campaign(path)
        assert not isinstance(spec.base.rule, DelayAware), path.name  # a rule list may still compare it
