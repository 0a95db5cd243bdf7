"""docs/how-to/tracking.md runs as written: its Python blocks in order (their own assertions), its commands
through `mrpctl.cli.main`, its TOML block is the shipped scenario's [reference] table, and the numbers it
quotes are what the commands report."""

from __future__ import annotations

import json
import math
import re
import shlex
from pathlib import Path

import pytest

from mrpctl.cli import main

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "how-to" / "tracking.md"


def _blocks(language: str) -> list[str]:
    return re.findall(rf"```{language}\n(.*?)```", PAGE.read_text(encoding="utf-8"), flags=re.S)


def test_the_python_blocks_run_in_order(capsys: pytest.CaptureFixture[str]) -> None:
    namespace: dict[str, object] = {}
    blocks = _blocks("python")
    assert len(blocks) == 3
    for index, code in enumerate(blocks):
        exec(compile(code, f"docs/how-to/tracking.md (block {index + 1})", "exec"), namespace)
    printed = capsys.readouterr().out
    assert "initial error 51.62 deg" in printed  # the page says 51.6°
    slew = dict(re.findall(r"feedforward (False|True): peak error ([\d.]+) deg", printed))
    assert 6.0 < float(slew["False"]) < 8.0 and float(slew["True"]) < 1.0  # "about 7°, with it below 1°"
    assert "current: steady error 0.5534 mrad" in printed and "n tau = 0.5534 mrad" in printed


def test_the_toml_block_is_the_shipped_scenarios_reference_table() -> None:
    (block,) = _blocks("toml")
    shipped = (ROOT / "examples" / "scenarios" / "nadir.toml").read_text(encoding="utf-8")
    assert shipped.rstrip().endswith(block.rstrip())


def _commands() -> list[list[str]]:
    commands = []
    for block in _blocks("sh"):
        for line in block.splitlines():
            words = shlex.split(line.split("#", 1)[0])
            if words:
                assert words[0] == "mrpctl", line
                commands.append(words[1:])
    return commands


def test_the_commands_run_and_report_the_numbers_the_page_quotes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)
    page = PAGE.read_text(encoding="utf-8")
    simulate, verify, unstable = _commands()
    assert main(simulate) == 0
    out = capsys.readouterr().out
    assert (tmp_path / "results" / "pointing_nadir.png").stat().st_size > 10_000
    slew_time = float(re.search(r"slew time    ([\d.]+) s", out).group(1))
    assert "about 31 s to hold 0.05°" in page and round(slew_time) == 31
    assert main([*verify, "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    margins = [check["exact_delay_margin"] for check in report["checks"]]
    assert f"margins are {margins[0]:.7f} s\nand {margins[1]:.7f} s" in page
    assert "starts 20 deg from its reference" in report["local"]  # VERIFIED is local, as the page says
    assert "starts 20° from its\nreference" in page and "VERIFIED certifies no region of attraction" in page
    radius = report["checks"][0]["spectral_radius"]
    assert f"spectral radius at d = 10 is {radius:.9f}" in page
    assert main([*unstable, "--json"]) == 1
    report = json.loads(capsys.readouterr().out)
    assert [check["status"] for check in report["checks"]] == ["UNSTABLE", "UNSTABLE"]
    assert f"spectral radius {report['checks'][0]['spectral_radius']:.6f})" in page
    assert all(margin < 1.6 for margin in margins) and math.isclose(margins[0], margins[1], rel_tol=1e-5)
