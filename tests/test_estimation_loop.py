"""The estimated closed loop: its parts against the standalone filter and plant, and its options."""

from __future__ import annotations

import numpy as np
import pytest

from mrpctl import mrp, paper, simulate
from mrpctl.errors import SpecificationError
from mrpctl.estimation import Estimator, Gyro, Sensors, StarTracker, filter_run
from mrpctl.flight import Hysteretic, SensorModel
from mrpctl.loop import step_function
from mrpctl.model import STATE_SIZE
from mrpctl.simulation.estimated import EstimatedResult, simulate_estimated
from mrpctl.switching import OnDelayed

TRACKER = StarTracker.from_arcsec(10.0, 2.0, 0.5, dropout=0.05)
GYRO = Gyro(1e-5, 1e-7, (1e-3, -5e-4, 2e-4))
SENSORS = Sensors(TRACKER, GYRO, seed=4)
ESTIMATOR = Estimator(attitude_error=1e-3, bias_error=2e-3)
RATE = 10.0


ESTIMATORS = {
    "mekf": ESTIMATOR,
    "mrp_ekf": Estimator(kind="mrp_ekf", attitude_error=1e-3, bias_error=2e-3),
}


@pytest.fixture(scope="module", params=sorted(ESTIMATORS))
def kind(request) -> str:
    return request.param


@pytest.fixture(scope="module")
def run(kind) -> EstimatedResult:
    return simulate(
        paper.SPACECRAFT,
        paper.GAIN,
        paper.INITIAL_STATE,
        tau=0.5,
        rule=Hysteretic(),
        t_final=120.0,
        rate=RATE,
        substeps=2,
        sensors=SENSORS,
        estimator=ESTIMATORS[kind],
    )


def _check_against_standalone(run, estimator, tracker):
    functions = estimator.functions(tracker, GYRO, RATE)
    latency = functions.clock.latency
    n = len(run.t)
    arriving, available = np.zeros((n, 3)), np.zeros(n)
    arriving[latency:], available[latency:] = run.measurement[: n - latency], run.taken[: n - latency]
    rate0 = paper.INITIAL_OMEGA
    back = mrp.from_rotation_vector(-rate0 * (latency + 1) * functions.clock.period)
    state = functions.initial_state(mrp.add(paper.INITIAL_SIGMA, back), np.zeros(3))
    alone = filter_run(functions, state, run.gyro, arriving, available, ring=np.tile(rate0, (latency, 1)))
    assert run.taken.sum() > 0.9 * n / functions.clock.every
    assert np.max(np.abs(alone.sigma - run.sigma_hat)) < 1e-12
    assert np.max(np.abs(alone.covariance - run.covariance)) < 1e-12 * np.max(np.abs(run.covariance))
    assert np.max(np.abs(alone.omega - run.omega_hat)) < 1e-12


def test_the_loops_estimator_is_the_standalone_filter_on_the_recorded_sensors(run, kind):
    _check_against_standalone(run, ESTIMATORS[kind], TRACKER)


@pytest.mark.parametrize("mode", ["estimator", "pd", "predictor"])
def test_a_loop_without_latency(mode):
    tracker = StarTracker.from_arcsec(10.0, 2.0, 0.0, dropout=0.05)
    result = simulate_estimated(
        paper.SPACECRAFT,
        paper.GAIN,
        paper.INITIAL_STATE,
        sensors=Sensors(tracker, GYRO, seed=4),
        t_final=30.0,
        rate=RATE,
        estimator=ESTIMATOR,
        mode=mode,
    )
    assert np.all(np.isfinite(result.sigma)) and result.pointing_error[-1] < result.pointing_error[0]
    if mode == "estimator":
        _check_against_standalone(result, ESTIMATOR, tracker)


def test_the_loops_plant_and_control_law(run):
    # the control law on the estimate (δ = 0: the short set) and the plant integrated on it
    u = np.column_stack((run.sigma_hat, run.omega_hat / 4)) @ np.asarray(paper.GAIN).T
    assert np.allclose(u, run.u, rtol=0, atol=1e-12 * np.max(np.abs(run.u)))
    step = step_function(paper.SPACECRAFT, 1.0 / RATE, 2)
    x = np.column_stack((run.sigma, run.omega / 4))
    worst = 0.0
    for k in range(0, len(run.t) - 1, 13):
        nxt = np.array(step(x[k], run.u[k])).ravel()
        sq = nxt[:3] @ nxt[:3]
        if sq > 1:
            nxt[:3] = -nxt[:3] / sq
        worst = max(worst, float(np.max(np.abs(nxt - x[k + 1]))))
    assert worst < 1e-12
    # the gyro reads the mean rate of the rotation over the period before the sample, plus its error
    assert np.max(np.abs(run.gyro - run.omega)) < 0.1  # a mean rate, not the rate at the sample


def test_the_estimation_error_is_the_rotation_from_the_estimate_to_the_truth(run):
    expected = mrp.to_rotation_vector(mrp.subtract(run.sigma, run.sigma_hat))  # σ(true / estimate)
    assert np.max(np.abs(run.estimation_error - expected)) < 1e-12
    assert np.max(np.abs(run.estimation_error[:100])) > 1e-5  # compared in the tumble, not only near 0


def test_the_estimate_stays_within_its_three_sigma_after_convergence(run, kind):
    after = run.t >= 20.0
    error = run.estimation_error[after]
    covariance = np.array(run.covariance[after])
    if kind == "mrp_ekf":  # on δσ: δθ = 4 B(σ̂)⁻¹ δσ
        t = 4 * np.linalg.inv(mrp.b_matrix(run.sigma_hat[after]))
        covariance = t @ covariance[:, :3, :3] @ np.swapaxes(t, 1, 2)
    sigma = np.sqrt(np.diagonal(covariance, axis1=1, axis2=2)[:, :3])
    assert np.mean(np.abs(error) <= 3 * sigma) >= 0.99
    bias_sigma = np.sqrt(np.diagonal(run.covariance[after], axis1=1, axis2=2)[:, 3:])
    assert np.mean(np.abs(run.bias_hat[after] - run.bias[after]) <= 3 * bias_sigma) >= 0.99


def test_the_estimator_loop_points_better_than_pd_on_the_biased_gyro():
    common = dict(sensors=SENSORS, t_final=120.0, rate=RATE, estimator=ESTIMATOR, substeps=2)
    estimated = simulate_estimated(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, **common)
    pd = simulate_estimated(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, mode="pd", **common)
    last = slice(-200, None)
    assert np.sqrt(np.mean(estimated.pointing_error[last] ** 2)) < 0.5 * np.sqrt(np.mean(pd.pointing_error[last] ** 2))


@pytest.mark.parametrize(
    ("options", "name"),
    [
        ({"tau": 0.3}, "tau"),
        ({"rule": OnDelayed()}, "rule"),
        ({"sensors": None}, "sensors"),
        ({"sensor": SensorModel(attitude_noise=1e-5)}, "sensor"),
        ({"history": "zero"}, "history"),
    ],
)
def test_options_of_the_estimated_loop_are_checked(options, name):
    arguments = dict(tau=0.5, rule=Hysteretic(), t_final=1.0, rate=RATE, sensors=SENSORS, estimator=ESTIMATOR)
    arguments.update(options)
    with pytest.raises(SpecificationError, match=name):
        simulate(paper.SPACECRAFT, paper.GAIN, np.zeros(STATE_SIZE), **arguments)


def test_the_how_to_runs_as_written(capsys):
    from pathlib import Path

    page = (Path(__file__).resolve().parents[1] / "docs" / "how-to" / "estimation.md").read_text(encoding="utf-8")
    code = page.split("```python\n", 1)[1].split("```", 1)[0]
    exec(compile(code, "docs/how-to/estimation.md", "exec"), {})
    printed = capsys.readouterr().out
    assert "pointing at the end" in printed and "within 3 sigma" in printed
    share = float(printed.split("within 3 sigma: ")[1].split("%")[0])
    assert share > 95.0
