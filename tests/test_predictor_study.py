"""The predictor study of ``mrpctl reproduce`` (mrpctl._predictor_study), on a short horizon."""

from __future__ import annotations

import numpy as np
import pytest

from mrpctl import paper, simulate
from mrpctl._predictor_study import FAST_OMEGA_N, X0, predictor_study
from mrpctl.design import pd_gains
from mrpctl.errors import SpecificationError
from mrpctl.switching import OnCurrent


@pytest.mark.slow  # synthesize_pd (LMI solves) takes about 6 s
def test_study_rows_sweep_and_figure() -> None:
    study = predictor_study(t_final=8.0, errors=(-0.1, 0.0, 0.1), margins=False)
    assert len(study.rows) == 8 and study.pd_margin is None and study.predictor_margin is None
    assert study.errors.tolist() == [-0.1, 0.0, 0.1]
    # Exact model: the predictor loop is the undelayed loop (bit for bit in the engine), so its settling
    # time is that of the undelayed OnCurrent run with the same fast gain.
    fast = pd_gains(paper.SPACECRAFT, zeta=1.0, omega_n=FAST_OMEGA_N).K
    undelayed = simulate(paper.SPACECRAFT, fast, np.array(X0), tau=0.0, rule=OnCurrent(), t_final=8.0)
    at_zero = [row for row in study.rows if row.controller.startswith("predictor") and row.e == 0.0]
    assert at_zero[0].settling_time == undelayed.settling_time == study.predictor_settling[1]
    # The sweep and the rows are the same runs.
    pd_rows = {row.e: row.settling_time for row in study.rows if row.controller.startswith("certified")}
    assert study.pd_settling[1] == pd_rows[0.0] or (np.isnan(study.pd_settling[1]) and pd_rows[0.0] is None)
    assert "| predictor, fast gains |" in study.table()
    assert len(study.claims()) == 8
    fig = study.figure()
    assert len(fig.axes) == 1 and len(fig.axes[0].lines) >= 2
    assert study.summary()["errors"] == [-0.1, 0.0, 0.1]


def test_study_bad_input_names_the_parameter() -> None:
    with pytest.raises(SpecificationError, match="errors"):
        predictor_study(errors=(-1.0, 0.0), margins=False)
    with pytest.raises(SpecificationError, match="margins"):
        predictor_study(margins="yes")  # type: ignore[arg-type]
    with pytest.raises(SpecificationError, match="t_final"):
        predictor_study(t_final=-1.0)
