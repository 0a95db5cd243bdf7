"""mrpctl.data with predictor runs: save/load keeps the rule OnPredicted, the model inertia and the flight metrics."""

from __future__ import annotations

import numpy as np
import pytest

from mrpctl import OnPredicted, Predictor, data, paper, simulate
from mrpctl._compile import find_compiler
from mrpctl.design import pd_gains
from mrpctl.flight import ActuatorModel
from mrpctl.predictor import perturbed_spacecraft

pytestmark = pytest.mark.skipif(find_compiler() is None, reason="no C compiler on this machine")

X0 = np.array([0.93, 0.0, 0.0, 0.46 / 4, 0.0, 0.0])
MODEL = perturbed_spacecraft(paper.SPACECRAFT, 0.05)


def _run(alpha: float | None):
    return simulate(
        paper.SPACECRAFT,
        pd_gains(paper.SPACECRAFT, zeta=1.0, omega_n=2.0).K,
        X0,
        tau=0.5,
        rule=OnPredicted(alpha),
        t_final=3.0,
        rate=100.0,
        actuator=ActuatorModel(u_max=5.0),
        predictor=Predictor(model=MODEL),
    )


@pytest.mark.parametrize("alpha", [1.0, 1.2, None])
def test_predictor_run_round_trip(alpha: float | None, tmp_path) -> None:
    run = _run(alpha)
    assert run.saturated_fraction is not None and run.saturated_fraction > 0.0  # the limit acted
    back = data.load(data.save(run, tmp_path / "predicted.nc", seed=3))
    assert back.rule == OnPredicted(alpha) and data.metadata(tmp_path / "predicted.nc")["rule"] == str(run.rule)
    assert isinstance(back.predictor, Predictor)
    np.testing.assert_array_equal(back.predictor.model.inertia, MODEL.inertia)
    assert back.spacecraft == paper.SPACECRAFT
    for name in ("t", "sigma", "omega", "u", "switch_indices", "K", "x0", "peak_command"):
        np.testing.assert_array_equal(getattr(back, name), getattr(run, name), err_msg=name)
    for name in ("switch_count", "settling_time", "saturated_fraction", "peak_torque", "tau", "rate"):
        assert getattr(back, name) == getattr(run, name), name
    assert "predictor" in str(back) and str(back) == str(run)


def test_plain_runs_keep_no_predictor_fields(tmp_path) -> None:
    from mrpctl import DelayAware

    run = simulate(paper.SPACECRAFT, paper.GAIN, X0, tau=0.5, rule=DelayAware(), t_final=1.0, rate=100.0)
    dataset = data.to_xarray(run)
    assert "predictor_inertia" not in dataset and "saturated_fraction" not in dataset
    back = data.load(data.save(run, tmp_path / "plain.nc"))
    assert back.predictor is None and back.saturated_fraction is None and back.peak_command is None
