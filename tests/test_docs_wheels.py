"""docs/how-to/wheels.md runs as written: its scenario, its commands' output and its sizing table."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest

from mrpctl.campaign import load_campaign, run_campaign
from mrpctl.campaign.report import report
from mrpctl.cli import main
from mrpctl.scenario import shipped_scenarios

ROOT = Path(__file__).resolve().parents[1]
PAGE = (ROOT / "docs" / "how-to" / "wheels.md").read_text(encoding="utf-8")


def _blocks(kind: str) -> list[str]:
    return re.findall(rf"```{kind}\n(.*?)```", PAGE, flags=re.DOTALL)


def test_the_page_is_in_the_site_and_shows_the_shipped_table() -> None:
    assert "how-to/wheels.md" in (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    shown = tomllib.loads(_blocks("toml")[0])
    shipped = tomllib.loads(shipped_scenarios()["cubesat_wheels"].read_text(encoding="utf-8"))
    campaign = tomllib.loads(_blocks("toml")[1])  # the page's campaign file: the scenario's cubesat and wheels
    assert shown["wheels"] == shipped["wheels"] == campaign["wheels"]
    example = ROOT / "examples" / "campaigns" / "wheels" / "cubesat.toml"
    assert tomllib.loads(example.read_text(encoding="utf-8")) == campaign  # the page's file, shipped
    for key in ("spacecraft", "gains", "rule", "tau", "rate", "t_final"):
        assert shipped[key] == campaign[key], key


def test_the_commands_print_what_the_page_shows(capsys: pytest.CaptureFixture[str]) -> None:
    texts = _blocks("text")
    assert main(["design", "--inertia", "0.2", "0.25", "0.15", "--tau", "0.2"]) == 0
    printed = capsys.readouterr().out.splitlines()
    for line in texts[0].splitlines():
        assert line == "..." or line in printed, line
    assert main(["simulate", "cubesat_wheels"]) == 0
    printed = capsys.readouterr().out.splitlines()
    for line in texts[1].splitlines():
        assert line in printed, line


def _campaign_file(folder: Path) -> Path:
    path = folder / "wheels_campaign.toml"  # saved as the page says
    path.write_text(_blocks("toml")[1], encoding="utf-8")
    return path


def test_the_campaign_reports_what_the_page_shows(tmp_path: Path) -> None:
    spec = load_campaign(_campaign_file(tmp_path))
    run_campaign(spec, tmp_path / "results", threads=1)
    text = str(report(tmp_path / "results")).splitlines()
    for line in _blocks("text")[2].splitlines():
        assert line in text, line


def test_the_sizing_table_is_what_the_code_prints(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    _campaign_file(tmp_path)
    monkeypatch.chdir(tmp_path)
    code = _blocks("python")[0]
    exec(compile(code, "docs/how-to/wheels.md", "exec"), {})
    assert capsys.readouterr().out == _blocks("text")[3]


def test_the_steering_section_prints_what_the_page_shows(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    texts = _blocks("text")
    monkeypatch.chdir(tmp_path)
    command = re.search(r"```sh\n(mrpctl design [^\n]*--wheels[^\n]*)\n```", PAGE)
    assert command is not None
    assert main(command.group(1).split()[1:]) == 0
    printed = capsys.readouterr().out.splitlines()
    for line in texts[4].splitlines():
        assert line in printed, line
    written = tomllib.loads((tmp_path / "steer.toml").read_text(encoding="utf-8"))
    assert written["steering"] == tomllib.loads(_blocks("toml")[2])["steering"]
    assert main(["simulate", "steer.toml"]) == 0
    printed = capsys.readouterr().out.splitlines()
    for line in texts[5].splitlines():
        assert line in printed, line
    example = ROOT / "examples" / "campaigns" / "wheels" / "cubesat_steering.toml"
    assert f"mrpctl campaign run {example.relative_to(ROOT)} --out results/steering --report" in PAGE
    run_campaign(load_campaign(example), tmp_path / "results", threads=1)
    text = str(report(tmp_path / "results")).splitlines()
    for line in texts[6].splitlines():
        assert line in text, line
