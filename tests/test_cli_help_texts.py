"""The exit-code epilogs of the command line say what the commands do: an option they name exists on the commands
they name it for, and verify's exit 0 for a tracking scenario does not claim more than its checks cover."""

from __future__ import annotations

import argparse
import json
import re

import pytest

from mrpctl.cli import EXIT_CODES, VERIFY_EXIT_CODES, build_parser, main


def _subcommands() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    (action,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(action.choices)


def _options(parser: argparse.ArgumentParser) -> set[str]:
    return {flag for action in parser._actions for flag in action.option_strings}


def test_the_divergence_exit_code_names_exactly_the_commands_that_take_the_option() -> None:
    (line,) = [line for line in EXIT_CODES.splitlines() if line.lstrip().startswith("1 ")]
    named = set(re.match(r"\s*1\s+([\w, ]+):", line).group(1).replace(" ", "").split(","))  # type: ignore[union-attr]
    commands = _subcommands()
    having = {name for name, sub in commands.items() if "--fail-on-divergence" in _options(sub)}
    assert named == having == {"simulate", "sweep"}
    shown = {name for name, sub in commands.items() if sub.epilog == EXIT_CODES}
    assert "export" in shown and "export" not in having  # so the shared epilog must say whose option it is


def test_verify_exit_zero_of_a_tracking_scenario_is_called_local(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["verify", "nadir", "--orders", "0", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["verified"] and report["not_covered"] == []
    assert "no region of attraction is certified" in report["local"]  # VERIFIED, yet the nonlinear loop is not
    text = " ".join(VERIFY_EXIT_CODES.split())
    assert "nothing is listed as not covered (a local verdict" in text
    assert "no region of attraction is certified" in text
