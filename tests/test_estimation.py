"""The estimators against an independent NumPy build, the shadow-set mapping, the re-propagation, consistency."""

from __future__ import annotations

import math

import estimation_reference as ref
import numpy as np
import pytest
from scipy.stats import chi2

from mrpctl import mrp
from mrpctl.errors import SpecificationError
from mrpctl.estimation import (
    ARCSEC,
    EstimatorTuning,
    Gyro,
    StarTracker,
    estimator_functions,
    farrenkopf_steady_state,
    filter_run,
    sensor_streams,
    shadow_jacobian_expr,
)

RATE = 10.0
TRACKER = StarTracker.from_arcsec(10.0, 2.0, 0.5, dropout=0.1)
GYRO = Gyro(1e-5, 1e-7, (2e-3, -1e-3, 5e-4))
#: The consistency runs' gyro: a bias walk whose steady-state estimation error decorrelates in about 2.6 s
#: (P_ββ/σ_u²), so that 100 runs of 60 s average it (with σ_u = 1e-7 it stays correlated for 100 s and the
#: grand mean of 100 runs scatters by 4 % of the state dimension; with 1e-6, 13 s and 2 %)
WALKING_GYRO = Gyro(1e-5, 1e-5)


def _omega(t: float) -> np.ndarray:
    # a tumble about y (about 0.3 rad/s): the attitude crosses |σ| = 1 every 21 s
    return np.array([0.05 * math.sin(0.1 * t), 0.3, -0.02])


def _case(kind: str, samples: int, seed: int, tuning: EstimatorTuning | None = None):
    functions = estimator_functions(kind, TRACKER, GYRO, RATE, tuning=tuning)
    clock = functions.clock
    streams = sensor_streams(TRACKER, GYRO, clock, samples, seed)
    noise = streams.gyro_error - 0.5 * (streams.bias[:-1] + streams.bias[1:])
    q_true, _, gyro = ref.truth(samples, clock.period, _omega, [0.1, -0.2, 0.3], streams.bias, noise)
    taken = np.array([ref.compose_mrp(ref.mrp_of_q(q_true[k]), streams.rotation[k]) for k in range(samples)])
    latency = clock.latency
    arriving, available = np.zeros((samples, 3)), np.zeros(samples)
    arriving[latency:], available[latency:] = taken[: samples - latency], streams.taken[: samples - latency]
    return functions, streams, q_true, gyro, arriving, available


def _relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


@pytest.mark.parametrize("kind", ["mekf", "mrp_ekf"])
def test_compiled_filter_matches_the_independent_numpy_filter_over_a_run_with_delayed_updates(kind):
    functions, streams, _, gyro, arriving, available = _case(kind, 600, 1)
    state = functions.initial_state([0.1, -0.2, 0.3], [0.0, 0.0, 0.0])
    run = filter_run(functions, state, gyro, arriving, available)
    size = functions.attitude_size
    start = (state[:size].copy(), np.zeros(3), state[size + 3 :].reshape(6, 6, order="F"))
    model = (ref.Mekf if kind == "mekf" else ref.MrpEkf)(
        functions.clock.period, GYRO.rate_noise, GYRO.bias_walk, TRACKER.covariance
    )
    latency = functions.clock.latency
    sigma, bias, covariance, innovation = ref.run_delayed(
        model, start, np.zeros((latency, 3)), gyro, arriving, streams.taken, latency
    )
    assert latency == 5 and available.sum() > 100  # delayed updates, some lost
    assert np.sum(np.sum(sigma**2, axis=1) > 0.9) > 0  # the run passes near |σ| = 1 (and switches)
    if kind == "mrp_ekf":
        assert np.sum(np.abs(np.diff(sigma, axis=0)) > 0.5) > 0  # shadow switches happened
    assert _relative(run.sigma, sigma) < 1e-12
    assert _relative(run.bias, bias) < 1e-12
    assert _relative(run.covariance, covariance) < 1e-12
    assert _relative(run.innovation, innovation) < 1e-12


def test_shadow_set_covariance_mapping_is_the_jacobian_of_the_switching_map():
    import casadi as ca

    symbol = ca.SX.sym("s", 3)
    jacobian = ca.Function("S", [symbol], [shadow_jacobian_expr(symbol)])
    rng = np.random.default_rng(3)
    for _ in range(20):
        sigma = rng.normal(size=3)
        sigma *= rng.uniform(0.8, 1.3) / np.linalg.norm(sigma)
        step = 1e-6
        numeric = np.column_stack(
            [(mrp.shadow(sigma + step * e) - mrp.shadow(sigma - step * e)) / (2 * step) for e in np.eye(3)]
        )
        analytic = np.array(jacobian(sigma))
        assert np.max(np.abs(analytic - numeric)) < 1e-8 * np.max(np.abs(numeric))
    # and the filter's switch maps P by it: a covariance propagated through a crossing stays the one
    # the linearised shadow map gives (checked by the reference filter, whose mapping is written apart)


@pytest.mark.parametrize("kind", ["mekf", "mrp_ekf"])
def test_a_delayed_update_equals_the_on_time_update_replayed_forward(kind):
    functions, _, _, gyro, arriving, available = _case(kind, 300, 2)
    latency = functions.clock.latency
    on_time_tracker = StarTracker(TRACKER.noise, TRACKER.rate, 0.0, dropout=TRACKER.dropout)
    on_time = estimator_functions(kind, on_time_tracker, GYRO, RATE, tuning=EstimatorTuning.from_sensors(TRACKER, GYRO))
    state = functions.initial_state([0.1, -0.2, 0.3], [0.0, 0.0, 0.0])
    delayed = filter_run(functions, state, gyro, arriving, available)
    # the on-time filter starts at t_{−ℓ} on the same state: its sample i is time t_{i−ℓ}, where it reads
    # ω̃_{i−ℓ} (the pre-start samples first) and the measurement of t_{i−ℓ}, the one the delayed filter gets at i
    on_gyro = np.vstack((np.zeros((latency, 3)), gyro))[: len(gyro)]
    on_run = filter_run(on_time, state, on_gyro, arriving, available)
    # on_run.state[i] is the on-time prior at t_{i+1−ℓ}; sample k's estimate is on-time posterior at t_{k−ℓ}
    # (= the prior at t_{k−ℓ} updated, i.e. on_run's row k − 1 updated) propagated over ω̃_{k−ℓ} … ω̃_{k−1}
    propagate = functions.propagate
    worst = 0.0
    size = functions.attitude_size
    for k in range(latency + 1, len(gyro), 7):
        x = np.array(on_run.state[k - 1])  # prior at t_{k−ℓ} after the update of t_{k−1−ℓ}: re-apply k's update
        x = np.array(on_time.update(x, arriving[k], available[k])[0]).ravel()
        for j in range(k - latency, k):
            x = np.array(propagate(x, gyro[j])).ravel()
        if kind == "mekf":
            q = x[:4] if x[0] >= 0 else -x[:4]
            sigma = q[1:] / (1 + q[0])
        else:
            sigma = x[:3]
        covariance = x[size + 3 :].reshape(6, 6, order="F")
        worst = max(worst, _relative(delayed.sigma[k], sigma), _relative(delayed.covariance[k], covariance))
    assert worst < 1e-13


def _nees_runs(kind: str, runs: int, samples: int):
    """Monte Carlo runs with the initial error drawn from P₀: NEES of the estimate now, bias errors, sigmas."""
    tuning = EstimatorTuning.from_sensors(TRACKER, WALKING_GYRO, attitude_error=50 * ARCSEC, bias_error=1e-4)
    functions = estimator_functions(kind, TRACKER, WALKING_GYRO, RATE, tuning=tuning)
    clock = functions.clock
    h, latency = clock.period, clock.latency
    rng = np.random.default_rng(11)
    nees = np.empty((runs, samples))
    bias_error = np.empty((runs, samples, 3))
    bias_sigma = np.empty((runs, samples, 3))
    for run in range(runs):
        gyro_model = Gyro(WALKING_GYRO.rate_noise, WALKING_GYRO.bias_walk, rng.normal(0.0, 1e-4, 3))
        streams = sensor_streams(TRACKER, gyro_model, clock, samples + latency, 100 + run)
        omega = np.array([_omega((k - latency) * h) for k in range(samples + latency)])
        noise = streams.gyro_error - 0.5 * (streams.bias[:-1] + streams.bias[1:])
        # truth from t_{−ℓ}: q_true[i] at t_{i−ℓ}, vectorised over the run
        q = [ref.q_of_mrp(np.array([0.1, -0.2, 0.3]))]
        for k in range(samples + latency):
            qn = ref.qmul(ref.qrot(omega[k] * h), q[-1])
            q.append(qn / np.linalg.norm(qn))
        q_true = np.array(q)
        readings = omega + 0.5 * (streams.bias[:-1] + streams.bias[1:]) + noise
        error0 = rng.normal(0.0, 50 * ARCSEC, 3)
        q_hat0 = ref.qmul(ref.qrot(-error0), q_true[0])
        sigma0 = ref.mrp_of_q(q_hat0 if q_hat0[0] >= 0 else -q_hat0)
        state = functions.initial_state(sigma0, np.zeros(3))
        taken = np.array(
            [ref.compose_mrp(ref.mrp_of_q(q_true[k]), streams.rotation[k]) for k in range(samples + latency)]
        )
        # the run's sample k (k = 0 … N−1) is time t_k: gyro row k + ℓ, the measurement of t_{k−ℓ} arrives
        gyro = readings[latency:]
        arriving = taken[:samples]
        available = streams.taken[:samples].copy()
        out = filter_run(functions, state, gyro, arriving, available, ring=readings[:latency])
        q_hat = np.array([ref.q_of_mrp(sigma) for sigma in out.sigma])
        dtheta = np.array([ref.rotvec_of_q(ref.qmul(q_true[k + latency], ref.qconj(q_hat[k]))) for k in range(samples)])
        db = streams.bias[latency : samples + latency] - out.bias
        p = np.array(out.covariance)
        if kind == "mrp_ekf":  # its covariance is on δσ: map to δθ = 4 B(σ)⁻¹ δσ
            t = np.tile(np.eye(6), (samples, 1, 1))
            t[:, :3, :3] = 4 * np.linalg.inv(mrp.b_matrix(out.sigma))
            p = t @ p @ np.swapaxes(t, 1, 2)
        e = np.concatenate((dtheta, db), axis=1)
        nees[run] = np.einsum("ki,ki->k", e, np.linalg.solve(p, e[:, :, None])[:, :, 0])
        bias_error[run] = db
        bias_sigma[run] = np.sqrt(np.diagonal(p, axis1=1, axis2=2)[:, 3:])
    return nees, bias_error, bias_sigma


@pytest.mark.parametrize("kind", ["mekf", "mrp_ekf"])
def test_filter_is_consistent_over_100_monte_carlo_runs(kind):
    runs, samples = 100, 700
    nees, bias_error, bias_sigma = _nees_runs(kind, runs, samples)
    after = slice(100, None)  # after convergence: 10 s, 20 tracker updates
    average = nees[:, after].mean(axis=0)
    low, high = chi2.ppf([0.025, 0.975], 6 * runs) / runs
    inside = np.mean((average >= low) & (average <= high))
    grand = float(nees[:, after].mean())
    bias_inside = np.mean(np.abs(bias_error[:, after]) <= 3 * bias_sigma[:, after])
    print(
        f"{kind}: NEES inside its 95% band on {inside:.1%}, grand mean {grand:.3f}, bias in 3 sigma {bias_inside:.2%}"
    )
    assert inside >= 0.90
    assert abs(grand - 6.0) <= 0.05 * 6.0
    assert bias_inside >= 0.99


def test_farrenkopf_steady_state_is_the_filters_own_steady_state():
    # the compiled filter at rest (ω = 0, no noise in the readings), on time: its covariance just after the
    # updates converges to the single-axis steady state of each axis
    tracker = StarTracker.from_arcsec(10.0, 2.0, 0.0)
    functions = estimator_functions("mekf", tracker, GYRO, RATE)
    n = 20000  # 2000 s: twenty times the bias error's time constant P_ββ/σ_u² of about 100 s
    gyro = np.zeros((n, 3))
    available = (np.arange(n) % functions.clock.every == 0).astype(float)
    state = functions.initial_state([0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    state[7:] = np.diag([1e-6] * 3 + [1e-8] * 3).reshape(-1, order="F")  # far from the steady state
    run = filter_run(functions, state, gyro, np.zeros((n, 3)), available)
    steady = farrenkopf_steady_state(GYRO, 10 * ARCSEC, 0.5)
    last = run.covariance[n - functions.clock.every]  # just after an update
    assert np.allclose(last[np.ix_([0, 3], [0, 3])], steady, rtol=1e-8, atol=0.0)


@pytest.mark.parametrize(
    ("build", "name"),
    [
        (lambda: StarTracker(-1.0, 2.0, 0.5), "noise"),
        (lambda: StarTracker(float("nan"), 2.0, 0.5), "noise"),
        (lambda: StarTracker(1e-5, 0.0, 0.5), "rate"),
        (lambda: StarTracker(1e-5, 2.0, -0.1), "latency"),
        (lambda: StarTracker(1e-5, 2.0, 0.5, dropout=1.0), "dropout"),
        (lambda: StarTracker(1e-5, 2.0, 0.5, roll_noise=1e-4), "roll_noise"),
        (lambda: StarTracker(1e-5, 2.0, 0.5, boresight=(0, 0, 0)), "boresight"),
        (lambda: StarTracker(1e-5, 3.0, 0.5).clock(10.0), "rate"),
        (lambda: StarTracker(1e-5, 2.0, 0.55).clock(10.0), "latency"),
        (lambda: StarTracker(1e-5, 2.0, 0.5).clock(10.0, buffer=3), "latency"),
        (lambda: Gyro(0.0, 1e-7), "rate_noise"),
        (lambda: Gyro(1e-5, -1e-7), "bias_walk"),
        (lambda: Gyro(1e-5, float("nan")), "bias_walk"),
        (lambda: Gyro(1e-5, 1e-7, (0, float("nan"), 0)), "initial_bias"),
        (lambda: Gyro(1e-5, 1e-7, scale_factor=(1.0, 0, 0)), "scale_factor"),
        (lambda: EstimatorTuning(1e-5, 1e-7, np.eye(3), -np.eye(6)), "initial_covariance"),
        (lambda: EstimatorTuning(1e-5, 1e-7, np.triu(np.ones((3, 3))), np.eye(6)), "measurement_covariance"),
        (lambda: estimator_functions("ukf", TRACKER, GYRO, RATE), "kind"),
    ],
)
def test_bad_sensor_and_filter_input_is_refused_naming_the_parameter(build, name):
    with pytest.raises(SpecificationError, match=name):
        build()


def test_boresight_noise_and_clock():
    tracker = StarTracker.from_arcsec(5.0, 2.0, 0.5, boresight=(0, 0, 2), roll_noise=40.0)
    assert np.allclose(np.diag(tracker.covariance), (np.array([5.0, 5.0, 40.0]) * ARCSEC) ** 2)
    clock = tracker.clock(10.0)
    assert (clock.every, clock.latency) == (5, 5)
    assert math.isclose(clock.period, 0.1)
