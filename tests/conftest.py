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
