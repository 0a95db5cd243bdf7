"""The example scripts run from start to end and print what they promise."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _run(*args: str) -> str:
    completed = subprocess.run(
        [sys.executable, *args], capture_output=True, text=True, check=False, timeout=300, cwd=EXAMPLES.parent
    )
    assert completed.returncode == 0, completed.stderr
    return completed.stdout


def test_monte_carlo_compares_every_rule() -> None:
    out = _run(str(EXAMPLES / "monte_carlo_rules.py"), "6")
    for rule in ("NoSwitching", "OnCurrent", "OnDelayed", "BoundaryLayer", "DelayAware"):
        assert rule in out
    on_delayed = next(line for line in out.splitlines() if line.startswith("OnDelayed"))
    aware = next(line for line in out.splitlines() if line.startswith("DelayAware (switch when |sigma(t - tau)| >= 1 "))
    # "still switching" column: the delay-aware rule never is.
    assert aware.split()[-3] == "0%"
    assert on_delayed.split()[-3] != "0%"


def test_design_for_a_new_spacecraft() -> None:
    out = _run(str(EXAMPLES / "design_new_spacecraft.py"))
    assert "synthesized and verified" in out
    assert "certified" in out and "exact delay margin" in out
    assert "status       converged" in out


def test_reproduce_paper_script(
    tmp_path: Path,
    paper_reproduction: tuple[Path, object],
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """The script's own steps run as written; its call of reproduce() writes the session's runs.

    The whole reproduction is computed once per test session (conftest), not again here.
    """
    import runpy

    from mrpctl import reproduction

    _, computed = paper_reproduction
    monkeypatch.setattr(reproduction, "reproduce", lambda out_dir: reproduction.write_reproduction(computed, out_dir))
    script = runpy.run_path(str(EXAMPLES / "reproduce_paper.py"), run_name="example")
    script["main"](tmp_path)
    out = capsys.readouterr().out
    assert (tmp_path / "claims.md").exists() and (tmp_path / "on_delayed_zoom.png").exists()
    assert "Reproduction of Samiei & Butcher" in out
