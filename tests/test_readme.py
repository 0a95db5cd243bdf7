"""The README's API example runs as written, and its two set-up commands are the Makefile's."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")


def test_api_example_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    section = README.split("## API in twenty lines", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    monkeypatch.chdir(tmp_path)
    exec(compile(code, "README.md", "exec"), {})
    out = capsys.readouterr().out
    assert "exact delay margin 1.5555" in out
    assert "switches     2" in out and "converged" in out
    assert (tmp_path / "on_delayed.png").exists()


def test_setup_commands_exist() -> None:
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    assert "make demo" in README and "make test" in README
    assert re.search(r"^demo:", makefile, re.M) and re.search(r"^test:", makefile, re.M)
    assert "make test" in (ROOT / ".ci" / "run").read_text(encoding="utf-8")


def test_gallery_images_exist() -> None:
    for name in re.findall(r"\]\((docs/gallery/[^)]+\.png)\)", README):
        assert (ROOT / name).read_bytes()[:4] == b"\x89PNG", name


def test_flown_loop_example_runs(capsys: pytest.CaptureFixture[str]) -> None:
    """The "loop as flown" block runs as written and every certificate it prints is certified."""
    section = README.split("## The loop as flown: certify it", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    exec(compile(code, "README.md", "exec"), {})
    out = capsys.readouterr().out
    heads = [line for line in out.splitlines() if not line.startswith(" ")]
    assert len(heads) == 4 and "not certified" not in out and "failed" not in out
    assert ": stable (spectral radius" in heads[1]
    assert all(line.split(":")[-1].strip().startswith("certified") for line in (heads[0], heads[2], heads[3]))


def test_flight_loop_example_runs(capsys: pytest.CaptureFixture[str]) -> None:
    """The "simulate it" block runs as written and prints what its comments say."""
    section = README.split("## The loop as flown: simulate it", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    scope: dict[str, object] = {}
    exec(compile(code, "README.md", "exec"), scope)
    out = capsys.readouterr().out
    run = scope["run"]
    assert run.switch_count == 1 and run.converged and "converged" in out  # type: ignore[attr-defined]
    assert round(100 * run.saturated_fraction, 1) == 10.4  # type: ignore[attr-defined]
    assert float(abs(run.u).max()) <= 20.0  # type: ignore[attr-defined]
