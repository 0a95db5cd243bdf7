"""The Makefile's set-up: `make demo` installs the runtime only, `make test` the test extras and compares images."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.skipif(shutil.which("make") is None, reason="no make on this machine")


def _dry_run(target: str, tmp_path: Path) -> str:
    venv = tmp_path / "fresh-venv"  # does not exist: every set-up step is printed
    done = subprocess.run(
        ["make", "-n", "-C", str(ROOT), target, f"VENV={venv}"], capture_output=True, text=True, check=True
    )
    return done.stdout


def test_demo_installs_only_the_runtime(tmp_path: Path) -> None:
    out = _dry_run("demo", tmp_path)
    assert "pip install" in out and "-e ." in out and "[test]" not in out
    assert "mrpctl example" in out
    # the shipped nadir-pointing scenario, by its name (installed as package data, no checkout path needed)
    assert "mrpctl simulate nadir --pointing-plot results/pointing_nadir.png" in out


def test_test_installs_the_test_extras_and_compares_images(tmp_path: Path) -> None:
    out = _dry_run("test", tmp_path)
    assert "-e '.[test]'" in out
    pytest_line = next(line for line in out.splitlines() if "-m pytest" in line)
    assert "--mpl" in pytest_line.split()
