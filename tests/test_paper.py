"""The paper's constants agree with the paper's own statements."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from mrpctl import paper
from mrpctl.cli import main


def test_initial_sigma_is_0_93() -> None:
    # "Initial conditions in terms of MRPs can be obtained as sigma = [0.93, 0, 0]".
    assert round(float(paper.INITIAL_SIGMA[0]), 4) == 0.9300
    reference = Rotation.from_rotvec(paper.INITIAL_PRINCIPAL_ANGLE * np.array([1.0, 0, 0])).as_mrp()
    assert np.max(np.abs(paper.INITIAL_SIGMA - reference)) < 1e-15


def test_initial_state_layout() -> None:
    assert np.array_equal(paper.INITIAL_STATE[3:], paper.INITIAL_OMEGA / 4)
    assert paper.GAIN.shape == (3, 6)
    assert not paper.GAIN.flags.writeable


def test_delay_is_whole_number_of_samples() -> None:
    assert (paper.TAU * paper.MEASUREMENT_RATE).is_integer()


def test_example_command_prints_summary(capsys) -> None:
    assert main(["example"]) == 0
    out = capsys.readouterr().out
    assert "diag(140, 100, 80)" in out and "tau = 0.5 s" in out and "0.93" in out
