"""Shared fixtures: seeded random generators, and the paper reproduction computed once per test session."""

from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20261122)


@pytest.fixture(scope="session")
def paper_reproduction(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, object]:
    """``reproduce(out)`` of the whole paper (60 s runs), once per session (once per xdist worker).

    test_reproduction checks the numbers and files; test_cli hands the same runs to
    ``mrpctl reproduce`` instead of computing them again.
    """
    from mrpctl.reproduction import reproduce

    out = tmp_path_factory.mktemp("results")
    return out, reproduce(out)


@pytest.fixture
def blank_figures(monkeypatch: pytest.MonkeyPatch) -> None:
    """Stand-in for ``reproduction._figures``: a blank PNG per figure name.

    For tests of writing, refusing and overwriting the reproduction's files; the real figures
    (about 10 s to render) are checked once, on :func:`paper_reproduction`.
    """
    from matplotlib.figure import Figure

    from mrpctl.reproduction import FIGURE_FILES

    def figures(results: dict, out: Path) -> list[Path]:
        assert "paper_fig4_on_delayed" in results
        for name in FIGURE_FILES:
            Figure(figsize=(1, 1)).savefig(out / name)
        return [out / name for name in FIGURE_FILES]

    monkeypatch.setattr("mrpctl.reproduction._figures", figures)


@pytest.hookimpl(tryfirst=True)  # before xdist's own hook, which turns the mark into the node id's @group
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Every test that uses the paper's reproduction runs on one xdist worker (``--dist loadgroup``),
    so the 60 s runs are computed once per test session, not once per worker."""
    for item in items:
        if "paper_reproduction" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.xdist_group("paper_reproduction"))
