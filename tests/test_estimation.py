"""The estimators against an independent NumPy build, the shadow-set mapping, the re-propagation, consistency."""

from __future__ import annotations

import math

import estimation_reference as ref
import numpy as np
import pytest
from scipy.stats import chi2

from mrpctl import mrp
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.estimation import (
    ARCSEC,
    Estimator,
    EstimatorTuning,
    Gyro,
    Sensors,
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


def _case(
    kind, samples, seed, *, gyro=GYRO, tuning=None, sigma0=(0.1, -0.2, 0.3), error=None, bias0=None, functions=None
):
    """A run with delayed updates: the truth from t_{−ℓ−1}, the readings r_{−ℓ} … r_{N−1} (r_k: the mean rate
    over [t_{k−1}, t_k]), the measurement of t_j arriving at j + ℓ; the filter starts at t_{−ℓ−1} on the truth
    turned by ``error`` (rad)."""
    if functions is None:
        functions = estimator_functions(kind, TRACKER, gyro, RATE, tuning=tuning)
    clock = functions.clock
    latency, h = clock.latency, clock.period
    if bias0 is not None:
        gyro = Gyro(gyro.rate_noise, gyro.bias_walk, bias0)
    streams = sensor_streams(TRACKER, gyro, clock, samples + latency, seed)
    noise = streams.gyro_error - 0.5 * (streams.bias[:-1] + streams.bias[1:])
    q_true, _, readings = ref.truth(
        samples + latency, h, lambda t: _omega(t - (latency + 1) * h), sigma0, streams.bias, noise
    )
    taken = np.array(
        [ref.compose_mrp(ref.mrp_of_q(q_true[j + latency + 1]), streams.rotation[j]) for j in range(samples)]
    )
    arriving, available = np.zeros((samples, 3)), np.zeros(samples)
    arriving[latency:], available[latency:] = taken[: samples - latency], streams.taken[: samples - latency]
    q_start = q_true[0] if error is None else ref.qmul(ref.qrot(-np.asarray(error)), q_true[0])
    sigma_start = ref.mrp_of_q(q_start if q_start[0] >= 0 else -q_start)
    return {
        "functions": functions,
        "state": functions.initial_state(sigma_start, np.zeros(3)),
        "pre": readings[:latency],
        "gyro": readings[latency:],
        "arriving": arriving,
        "available": available,
        "q_now": q_true[latency + 1 :],
        "bias_now": streams.bias[latency + 1 :],
    }


def _relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


@pytest.mark.parametrize("kind", ["mekf", "mrp_ekf"])
def test_compiled_filter_matches_the_independent_numpy_filter_over_a_run_with_delayed_updates(kind):
    case = _case(kind, 600, 1)
    functions, state = case["functions"], case["state"]
    run = filter_run(functions, state, case["gyro"], case["arriving"], case["available"], ring=case["pre"])
    size = functions.attitude_size
    start = (state[:size].copy(), np.zeros(3), state[size + 3 :].reshape(6, 6, order="F"))
    model = (ref.Mekf if kind == "mekf" else ref.MrpEkf)(
        functions.clock.period, GYRO.rate_noise, GYRO.bias_walk, TRACKER.covariance
    )
    latency = functions.clock.latency
    sigma, bias, covariance, innovation = ref.run_delayed(
        model, start, case["pre"], case["gyro"], case["arriving"], case["available"], latency
    )
    assert latency == 5 and case["available"].sum() > 100  # delayed updates, some lost
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
    # the filters' switches map P by it: the run against the reference (whose mapping is written apart)
    # crosses |σ| = 1 six times, test_compiled_filter_matches_the_independent_numpy_filter_over_a_run_...


@pytest.mark.parametrize("kind", ["mekf", "mrp_ekf"])
def test_a_delayed_update_equals_the_on_time_update_replayed_forward(kind):
    case = _case(kind, 300, 2)
    functions, state = case["functions"], case["state"]
    latency = functions.clock.latency
    on_time_tracker = StarTracker(TRACKER.noise, TRACKER.rate, 0.0, dropout=TRACKER.dropout)
    on_time = estimator_functions(kind, on_time_tracker, GYRO, RATE, tuning=EstimatorTuning.from_sensors(TRACKER, GYRO))
    gyro, arriving, available = case["gyro"], case["arriving"], case["available"]
    delayed = filter_run(functions, state, gyro, arriving, available, ring=case["pre"])
    # the on-time filter starts on the same state at t_{−ℓ−1}: its sample i is time t_{i−ℓ}, where it reads
    # r_{i−ℓ} and the measurement of t_{i−ℓ}, the one the delayed filter gets at i; its state after sample i is
    # the posterior at t_{i−ℓ}, which replayed over r_{i−ℓ+1} … r_i must be the delayed filter's estimate at i
    readings = np.vstack((case["pre"], gyro))  # readings[i] = r_{i−ℓ}
    on_run = filter_run(on_time, state, readings[: len(gyro)], arriving, available)
    size = functions.attitude_size
    worst = 0.0
    for k in range(latency, len(gyro), 7):
        x = np.array(on_run.state[k])
        for i in range(k + 1, k + latency + 1):
            x = np.array(functions.propagate(x, readings[i])).ravel()
        if kind == "mekf":
            q = x[:4] if x[0] >= 0 else -x[:4]
            sigma = q[1:] / (1 + q[0])
        else:
            sigma = x[:3]
        covariance = x[size + 3 :].reshape(6, 6, order="F")
        worst = max(worst, _relative(delayed.sigma[k], sigma), _relative(delayed.covariance[k], covariance))
    assert worst < 1e-13


def _qmul(a, b):
    """β of C(a) C(b) over rows (scalar first)."""
    scalar = a[:, 0] * b[:, 0] - np.sum(a[:, 1:] * b[:, 1:], axis=1)
    vector = a[:, :1] * b[:, 1:] + b[:, :1] * a[:, 1:] - np.cross(a[:, 1:], b[:, 1:])
    return np.column_stack((scalar, vector))


def _qrot(theta):
    angle = np.linalg.norm(theta, axis=1, keepdims=True)
    safe = np.where(angle > 0, angle, 1.0)
    return np.column_stack((np.cos(angle / 2), np.where(angle > 0, np.sin(angle / 2) / safe, 0.5) * theta))


def _q_of_mrp(sigma):
    squared = np.sum(sigma**2, axis=1, keepdims=True)
    return np.column_stack(((1 - squared) / (1 + squared), 2 * sigma / (1 + squared)))


def _rotvec(q):
    q = np.where(q[:, :1] < 0, -q, q)
    norm = np.linalg.norm(q[:, 1:], axis=1, keepdims=True)
    return np.where(norm > 0, 2 * np.arctan2(norm, q[:, :1]) / np.where(norm > 0, norm, 1.0), 2.0) * q[:, 1:]


def _nees_runs(kind: str, runs: int, samples: int):
    """Monte Carlo runs with the initial errors drawn from P₀: NEES of the estimate now, bias errors, sigmas.

    The true motion is the same in every run (the tumble of `_omega` from σ₀); each run draws its own initial
    errors, bias, gyro noise, star-tracker noise and dropouts."""
    tuning = EstimatorTuning.from_sensors(TRACKER, WALKING_GYRO, attitude_error=50 * ARCSEC, bias_error=1e-4)
    functions = estimator_functions(kind, TRACKER, WALKING_GYRO, RATE, tuning=tuning)  # built and compiled once
    clock = functions.clock
    latency, h = clock.latency, clock.period
    total = samples + latency  # periods from t_{−ℓ−1}
    omega = np.array([_omega((i - latency - 1) * h) for i in range(total)])
    q_true, _, _ = ref.truth(
        total,
        h,
        lambda t: _omega(t - (latency + 1) * h),
        (0.1, -0.2, 0.3),
        np.zeros((total + 1, 3)),
        np.zeros((total, 3)),
    )
    q_now = q_true[latency + 1 :]
    rng = np.random.default_rng(11)
    nees = np.empty((runs, samples))
    bias_error = np.empty((runs, samples, 3))
    bias_sigma = np.empty((runs, samples, 3))
    for run in range(runs):
        gyro = Gyro(WALKING_GYRO.rate_noise, WALKING_GYRO.bias_walk, rng.normal(0.0, 1e-4, 3))
        error0 = rng.normal(0.0, 50 * ARCSEC, 3)
        streams = sensor_streams(TRACKER, gyro, clock, total, 100 + run)
        readings = omega + streams.gyro_error  # r_{i−ℓ}: the mean rate over period i plus its error
        taken = _qmul(_qrot(streams.rotation[:samples]), q_now)  # the measurement of t_j
        taken = np.where(taken[:, :1] < 0, -taken, taken)
        arriving, available = np.zeros((samples, 3)), np.zeros(samples)
        arriving[latency:] = (taken[:, 1:] / (1 + taken[:, :1]))[: samples - latency]
        available[latency:] = streams.taken[: samples - latency]
        q_start = ref.qmul(ref.qrot(-error0), q_true[0])
        sigma_start = ref.mrp_of_q(q_start if q_start[0] >= 0 else -q_start)
        state = functions.initial_state(sigma_start, np.zeros(3))
        out = filter_run(functions, state, readings[latency:], arriving, available, ring=readings[:latency])
        q_hat = _q_of_mrp(out.sigma)
        dtheta = _rotvec(_qmul(q_now, q_hat * np.array([1.0, -1.0, -1.0, -1.0])))
        db = streams.bias[latency + 1 :] - out.bias
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
        (lambda: Estimator(kind="ukf"), "kind"),
        (lambda: Estimator(covariance_now=1), "covariance_now"),
        (lambda: Estimator(initial_bias=(0, 0)), "initial_bias"),
        (lambda: Estimator(attitude_error=0.0), "attitude_error"),
        (lambda: Sensors(TRACKER, GYRO, seed=-1), "seed"),
        (lambda: Sensors(GYRO, TRACKER), "star_tracker"),
        (lambda: EstimatorTuning(float("nan"), 1e-7, np.eye(3), np.eye(6)), "rate_noise"),
        (lambda: StarTracker(1e-5, 20.0, 0.5).clock(10.0), "rate"),
    ],
)
def test_bad_sensor_and_filter_input_is_refused_naming_the_parameter(build, name):
    with pytest.raises((SpecificationError, DimensionError), match=name):
        build()


def test_boresight_noise_and_clock():
    tracker = StarTracker.from_arcsec(5.0, 2.0, 0.5, boresight=(0, 0, 2), roll_noise=40.0)
    assert np.allclose(np.diag(tracker.covariance), (np.array([5.0, 5.0, 40.0]) * ARCSEC) ** 2)
    clock = tracker.clock(10.0)
    assert (clock.every, clock.latency) == (5, 5)
    assert math.isclose(clock.period, 0.1)


@pytest.mark.parametrize("kind", ["mekf", "mrp_ekf"])
def test_without_the_covariance_now_the_estimate_is_the_same_and_the_covariance_the_posteriors(kind):
    case = _case(kind, 200, 5)
    lean = estimator_functions(kind, TRACKER, GYRO, RATE, covariance_now=False)
    inputs = (case["state"], case["gyro"], case["arriving"], case["available"])
    full = filter_run(case["functions"], *inputs, ring=case["pre"])
    cheap = filter_run(lean, *inputs, ring=case["pre"])
    assert np.array_equal(full.sigma, cheap.sigma)
    assert np.array_equal(full.bias, cheap.bias)
    size = lean.attitude_size
    posterior = cheap.state[:, size + 3 :].reshape(-1, 6, 6).transpose(0, 2, 1)
    assert np.array_equal(cheap.covariance, posterior)
    assert lean.sample.n_instructions() < 0.5 * case["functions"].sample.n_instructions()


def test_the_exported_sample_is_the_sample_and_its_c_compiles(tmp_path):
    import json

    import casadi as ca

    from mrpctl._compile import compile_source
    from mrpctl.estimation.export import export_estimator

    functions = estimator_functions("mekf", TRACKER, GYRO, RATE)
    folder = export_estimator(functions, tmp_path / "estimator")
    loaded = ca.Function.load(str(folder / "estimator_sample.casadi"))
    rng = np.random.default_rng(0)
    state = functions.initial_state([0.2, -0.1, 0.3], [1e-4, 0, 0])
    args = [state, rng.normal(size=(3, 5)) * 0.1, rng.normal(size=3) * 0.1, [0.2, -0.1, 0.31], 1.0]
    for mine, theirs in zip(functions.sample(*args), loaded(*args), strict=True):
        assert np.array_equal(np.asarray(mine), np.asarray(theirs))
    manifest = json.loads((folder / "manifest.json").read_text())
    assert [port["name"] for port in manifest["inputs"]] == functions.sample.name_in()
    assert [port["name"] for port in manifest["outputs"]] == functions.sample.name_out()
    assert manifest["clock"] == {"period_s": 0.1, "tracker_every_samples": 5, "latency_samples": 5}
    assert compile_source((folder / "estimator_sample.c").read_text(), "estimator_export_check").exists()
    assert np.array_equal(np.loadtxt(folder / "initial_state.txt"), functions.initial_state([0, 0, 0], [0, 0, 0]))
    export_estimator(functions, folder)  # replaced whole
    assert sorted(p.name for p in tmp_path.iterdir()) == ["estimator"]
