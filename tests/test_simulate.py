"""The compiled closed-loop simulator against an independent NumPy RK4 and against scipy.

The NumPy reference below writes the attitude equations directly (σ, ω in rad/s),
σ̇ = ¼[(1 − σᵀσ) ω + 2 σ × ω + 2 σ (σᵀω)], J ω̇ = −ω × J ω + u, and the sampled loop
of the issue (rule, record, zero-order hold of u_k = K m_{k−d}, RK4), without using
mrpctl.model, mrpctl.mrp or mrpctl.switching.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from mrpctl import paper
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.simulation import (
    SimulationResult,
    closed_loop_functions,
    delay_samples,
    simulate,
    simulate_batch,
)
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import BoundaryLayer, DelayAware, NoSwitching, OnCurrent, OnDelayed

J = np.diag([140.0, 100.0, 80.0])
K = np.hstack((-70.11 * np.eye(3), -163.08 * np.eye(3)))
SIGMA0 = np.array([np.tan(np.radians(171.6913) / 4.0), 0.0, 0.0])
OMEGA0 = np.array([0.46, 0.0, 0.0])
X0 = np.concatenate((SIGMA0, OMEGA0 / 4.0))
SC = paper.SPACECRAFT
RULES = {
    "none": NoSwitching(),
    "current": OnCurrent(),
    "delayed": OnDelayed(),
    "layer": BoundaryLayer(0.005),
    "aware": DelayAware(),
}


# ------------------------------------------------------------------ NumPy reference
def cross(a, b):
    """a × b row by row for arrays (R, 3)."""
    return np.stack(
        (
            a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],
            a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
            a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0],
        ),
        axis=1,
    )


def reference_derivative(sigma, omega, u, inertia, inertia_inv):
    """σ̇, ω̇ for arrays (R, 3)."""
    ss = np.sum(sigma * sigma, axis=1, keepdims=True)
    sw = np.sum(sigma * omega, axis=1, keepdims=True)
    sigma_dot = 0.25 * ((1.0 - ss) * omega + 2.0 * cross(sigma, omega) + 2.0 * sigma * sw)
    momentum = omega @ inertia.T
    omega_dot = (u - cross(omega, momentum)) @ inertia_inv.T
    return sigma_dot, omega_dot


def reference_run(kinds, params, *, d, rate, n, gain=K, inertia=J, x0=X0, history="constant", substeps=1):
    """Run R loops at once (one rule kind each); returns sigma, omega, u (n, R, 3), switched (n, R)."""
    kinds = list(kinds)
    runs = len(kinds)
    inertia_inv = np.linalg.inv(inertia)
    h = 1.0 / rate
    dt = h / substeps
    sigma = np.tile(x0[:3], (runs, 1))
    omega = np.tile(4.0 * x0[3:], (runs, 1))
    if isinstance(history, str):
        past = np.zeros((d, 6)) if history == "zero-input" else np.tile(x0, (d, 1))
    else:
        past = np.asarray(history)
    past_sigma = np.repeat(past[None, :, :3], runs, axis=0)  # (R, d, 3) m_{-d} .. m_{-1}
    past_omega = np.repeat(4.0 * past[None, :, 3:], runs, axis=0)
    meas_sigma = np.zeros((n, runs, 3))
    meas_omega = np.zeros((n, runs, 3))
    torque = np.zeros((n, runs, 3))
    switched = np.zeros((n, runs), dtype=bool)
    last_switch = np.full(runs, -(10**9))
    kind = np.array(kinds)
    par = np.asarray(params, dtype=float)
    for k in range(n):
        if d == 0:
            seen_sigma = sigma
        elif k - d < 0:
            seen_sigma = past_sigma[:, k]
        else:
            seen_sigma = meas_sigma[k - d]
        current = np.linalg.norm(sigma, axis=1)
        delayed = np.linalg.norm(seen_sigma, axis=1)
        flip = np.where(kind == "current", current >= 1.0, False)
        flip |= np.where(kind == "delayed", delayed >= 1.0, False)
        flip |= np.where(kind == "layer", (delayed >= 1.0) & (delayed <= 1.0 + par), False)
        flip |= np.where(kind == "aware", (delayed >= par) & (k - d >= last_switch), False)
        sigma = np.where(flip[:, None], -sigma / (current**2)[:, None], sigma)
        last_switch = np.where(flip, k, last_switch)
        switched[k] = flip
        meas_sigma[k], meas_omega[k] = sigma, omega
        if d == 0:
            m_sigma, m_omega = sigma, omega
        elif k - d < 0:
            m_sigma, m_omega = past_sigma[:, k], past_omega[:, k]
        else:
            m_sigma, m_omega = meas_sigma[k - d], meas_omega[k - d]
        u = m_sigma @ gain[:, :3].T + (m_omega / 4.0) @ gain[:, 3:].T
        torque[k] = u
        for _ in range(substeps):
            a_s, a_w = reference_derivative(sigma, omega, u, inertia, inertia_inv)
            b_s, b_w = reference_derivative(sigma + dt / 2 * a_s, omega + dt / 2 * a_w, u, inertia, inertia_inv)
            c_s, c_w = reference_derivative(sigma + dt / 2 * b_s, omega + dt / 2 * b_w, u, inertia, inertia_inv)
            e_s, e_w = reference_derivative(sigma + dt * c_s, omega + dt * c_w, u, inertia, inertia_inv)
            sigma = sigma + dt / 6 * (a_s + 2 * b_s + 2 * c_s + e_s)
            omega = omega + dt / 6 * (a_w + 2 * b_w + 2 * c_w + e_w)
    return meas_sigma, meas_omega, torque, switched


def reference_metrics(sigma, omega, u, switched, rate):
    """Independent metrics of one run (arrays (n, 3), (n,))."""
    unsettled = (np.linalg.norm(sigma, axis=1) >= 1e-2) | (np.linalg.norm(omega, axis=1) >= 1e-3)
    last = np.flatnonzero(unsettled)
    settle_index = last[-1] + 1 if last.size else 0
    flips = np.sum(u[1:] * u[:-1] < 0, axis=0)
    return {
        "settling_time": settle_index / rate if settle_index < len(sigma) else None,
        "sign_flips": flips,
        "max_sigma": np.linalg.norm(sigma, axis=1).max(),
        "switch_indices": np.flatnonzero(switched),
    }


# ------------------------------------------------------------------ shared runs
@pytest.fixture(scope="module")
def paper_runs() -> dict[str, SimulationResult]:
    """The paper's case over 60 s: tau = 0.5 s for every rule, and tau = 0 with OnCurrent."""
    runs = {
        name: simulate(SC, paper.GAIN, paper.INITIAL_STATE, tau=0.5, rule=rule, t_final=60.0)
        for name, rule in RULES.items()
    }
    runs["current-tau0"] = simulate(SC, paper.GAIN, paper.INITIAL_STATE, tau=0.0, rule=OnCurrent(), t_final=60.0)
    return runs


@pytest.fixture(scope="module")
def reference_tau05() -> tuple[np.ndarray, ...]:
    """The NumPy reference for all five rules at tau = 0.5 s over the first 6 s (all first switches)."""
    names = list(RULES)
    params = [0.005 if name == "layer" else 1.0 for name in names]
    return reference_run(names, params, d=500, rate=1000.0, n=6001)


# ------------------------------------------------------------------ agreement
@pytest.mark.parametrize("index,name", list(enumerate(RULES)))
def test_agrees_with_numpy_reference(paper_runs, reference_tau05, index: int, name: str) -> None:
    sigma, omega, u, switched = reference_tau05
    run = paper_runs[name]
    n = sigma.shape[0]
    np.testing.assert_array_equal(run.switch_indices[run.switch_indices < n], np.flatnonzero(switched[:, index]))
    assert np.max(np.abs(run.sigma[:n] - sigma[:, index])) < 1e-12
    assert np.max(np.abs(run.omega[:n] - omega[:, index])) < 1e-12
    assert np.max(np.abs(run.u[:n] - u[:, index])) < 1e-12 * np.max(np.abs(K))


def test_tau_zero_agrees_with_reference_and_metrics(paper_runs) -> None:
    n = 3001  # the switch is at 0.438 s; the metrics of the full run are checked below
    full = paper_runs["current-tau0"]
    run = simulate(SC, paper.GAIN, paper.INITIAL_STATE, tau=0.0, rule=OnCurrent(), t_final=3.0)
    np.testing.assert_array_equal(run.sigma, full.sigma[:n])
    sigma, omega, u, switched = reference_run(["current"], [1.0], d=0, rate=1000.0, n=n)
    assert np.max(np.abs(run.sigma - sigma[:, 0])) < 1e-12
    assert np.max(np.abs(run.omega - omega[:, 0])) < 1e-12
    expected = reference_metrics(sigma[:, 0], omega[:, 0], u[:, 0], switched[:, 0], 1000.0)
    np.testing.assert_array_equal(run.switch_indices, expected["switch_indices"])
    np.testing.assert_array_equal(run.sign_flips, expected["sign_flips"])
    assert run.settling_time is None and expected["settling_time"] is None
    assert run.max_sigma == pytest.approx(expected["max_sigma"], rel=1e-12)


@pytest.mark.parametrize("name", ["none", "aware", "delayed", "current-tau0"])
def test_in_code_metrics_match_the_trajectory(paper_runs, name: str) -> None:
    run = paper_runs[name]
    u_flips = np.sum(run.u[1:] * run.u[:-1] < 0, axis=0)
    np.testing.assert_array_equal(run.sign_flips, u_flips)
    expected = reference_metrics(run.sigma, run.omega, run.u, np.isin(np.arange(len(run.t)), run.switch_indices), 1e3)
    assert run.settling_time == expected["settling_time"]
    assert run.max_sigma == pytest.approx(expected["max_sigma"], rel=1e-14)


def test_history_zero_input_and_array_and_substeps() -> None:
    d, rate, n = 20, 1000.0, 301
    rng = np.random.default_rng(4)
    history = np.tile(X0, (d, 1)) + 0.01 * rng.normal(size=(d, 6))
    history[3:6, 0] = 1.02  # three delayed measurements outside the unit sphere: three switches
    for hist in ("zero-input", history):
        run = simulate(SC, K, X0, tau=d / rate, rule=OnDelayed(), t_final=0.3, history=hist, substeps=2)
        sigma, omega, u, switched = reference_run(["delayed"], [1.0], d=d, rate=rate, n=n, history=hist, substeps=2)
        np.testing.assert_array_equal(run.switch_indices, np.flatnonzero(switched[:, 0]))
        assert np.max(np.abs(run.sigma - sigma[:, 0])) < 1e-13
        assert np.max(np.abs(run.omega - omega[:, 0])) < 1e-13
        assert np.max(np.abs(run.u - u[:, 0])) < 1e-10
    assert run.switch_count >= 3
    zero = simulate(SC, K, X0, tau=d / rate, rule=OnDelayed(), t_final=0.3, history="zero-input", substeps=2)
    zeros = simulate(SC, K, X0, tau=d / rate, rule=OnDelayed(), t_final=0.3, history=np.zeros((d, 6)), substeps=2)
    np.testing.assert_array_equal(zero.sigma, zeros.sigma)
    assert np.all(zero.u[:d] == 0.0) and np.any(zero.u[d:] != 0.0)


def test_horizon_not_a_multiple_of_the_delay_and_general_inertia() -> None:
    inertia = np.array([[120.0, 5.0, -3.0], [5.0, 100.0, 2.0], [-3.0, 2.0, 90.0]])
    craft = Spacecraft(inertia)
    d, rate = 7, 500.0
    x0 = np.array([0.3, -0.5, 0.7, 0.05, 0.02, -0.03])
    run = simulate(craft, K, x0, tau=d / rate, rule=OnCurrent(), t_final=1.237, rate=rate)
    n = int(np.floor(1.237 * rate + 1e-9)) + 1
    assert len(run.t) == n and run.t[-1] == pytest.approx((n - 1) / rate)
    sigma, omega, _, switched = reference_run(["current"], [1.0], d=d, rate=rate, n=n, inertia=inertia, x0=x0)
    assert np.max(np.abs(run.sigma - sigma[:, 0])) < 1e-12
    assert np.max(np.abs(run.omega - omega[:, 0])) < 1e-12
    np.testing.assert_array_equal(run.switch_indices, np.flatnonzero(switched[:, 0]))


def test_closed_loop_functions_agree_with_simulate() -> None:
    loop = closed_loop_functions(SC, paper.GAIN, tau=0.02, rule=OnDelayed(), substeps=2)
    assert loop.delay_samples == 20
    assert loop.sample.name_in() == ["x", "memory", "x_delayed"]
    assert loop.sample.name_out() == ["x_next", "memory_next", "x_meas", "u", "switched"]
    assert loop.step.name_in() == ["x", "u"] and loop.controller.name_in() == ["x_meas"]
    assert loop.switching.name_out() == ["x_next", "memory_next", "switched"]
    assert loop.chunk.name_in() == ["x", "memory", "history"]
    for function in (loop.dynamics, loop.controller, loop.switching, loop.step, loop.sample):
        assert function.is_a("SXFunction")
    x0 = np.array([0.99, 0.0, 0.0, 0.2, 0.0, 0.0])
    run = simulate(SC, paper.GAIN, x0, tau=0.02, rule=OnDelayed(), t_final=0.079, substeps=2)
    assert run.switch_count > 0
    x, memory, history = x0, loop.initial_memory, np.tile(x0[:, None], (1, 20))
    measured = []
    for _ in range(4):
        x, memory, history, _, _ = (np.asarray(v) for v in loop.chunk(x, memory, history))
        measured.append(history.T)
    np.testing.assert_allclose(np.vstack(measured), run.x, rtol=0, atol=1e-15)
    assert "rule" in str(loop) and "20 samples" in str(loop)


# ------------------------------------------------------------------ continuous time
def dde_solution(t_end: float, tau: float, times: np.ndarray) -> np.ndarray:
    """Continuous DDE ẋ = A x + B K x(t − τ) + f(x) with φ = x0, by the method of steps."""
    inertia_inv = np.linalg.inv(J)

    def rhs(delayed):
        def f(t, y):
            m = delayed(t - tau)
            u = K @ m
            sd, wd = reference_derivative(y[None, :3], 4.0 * y[None, 3:], u[None], J, inertia_inv)
            return np.concatenate((sd[0], wd[0] / 4.0))

        return f

    pieces = []

    def history(t):
        for start, end, solution in pieces:
            if start - 1e-12 <= t <= end + 1e-12:
                return solution(t)
        return X0

    start, y = 0.0, X0
    while start < t_end - 1e-12:
        end = min(start + tau, t_end)
        sol = solve_ivp(rhs(history), (start, end), y, method="DOP853", rtol=1e-12, atol=1e-14, dense_output=True)
        pieces.append((start, end, sol.sol))
        start, y = end, sol.y[:, -1]
    return np.array([history(t) for t in times])


@pytest.mark.slow
def test_zero_order_hold_error_is_first_order() -> None:
    t_end, tau = 3.0, 0.5
    times = np.arange(0.0, t_end + 1e-9, 0.01)
    exact = dde_solution(t_end, tau, times)
    errors = []
    for rate in (500.0, 1000.0, 2000.0):
        run = simulate(SC, K, X0, tau=tau, rule=NoSwitching(), t_final=t_end, rate=rate)
        picks = np.rint(times * rate).astype(int)
        errors.append(np.max(np.abs(run.x[picks] - exact)))
    ratios = [errors[0] / errors[1], errors[1] / errors[2]]
    assert all(1.8 < r < 2.2 for r in ratios), (errors, ratios)


# ------------------------------------------------------------------ the paper's claims
def test_tau_zero_on_current_switches_once_near_the_paper_time(paper_runs) -> None:
    run = paper_runs["current-tau0"]
    assert run.switch_count == 1
    assert abs(run.first_switch_time - paper.PAPER_FIRST_SWITCH_TIME) < 0.02  # 0.438 s here, 0.449 s in the paper
    assert run.converged and not run.diverged


def test_on_delayed_chatters_to_the_end(paper_runs) -> None:
    run = paper_runs["delayed"]
    assert run.last_switch_time > 59.0
    assert not run.converged
    last_10 = run.t >= 50.0
    assert np.max(np.abs(run.sigma[last_10, 0])) > 0.5  # sigma_1 keeps jumping between the sets


def test_no_switching_converges_slightly_above_one(paper_runs) -> None:
    run = paper_runs["none"]
    assert run.switch_count == 0 and run.converged
    assert 1.0 < run.max_sigma < 1.05


def test_delay_aware_switches_at_most_twice_and_converges(paper_runs) -> None:
    run = paper_runs["aware"]
    assert run.switch_count <= 2 and run.converged


def test_boundary_layer_toggles_then_settles(paper_runs) -> None:
    run = paper_runs["layer"]
    assert run.switch_count > 2  # the literal layer still toggles while stale measurements sit in it
    assert run.converged


@pytest.mark.slow
def test_delay_aware_monte_carlo_stops_switching() -> None:
    rng = np.random.default_rng(20261122)
    count = 100
    axes = rng.normal(size=(count, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.radians(rng.uniform(160.0, 179.0, count))
    rates = rng.uniform(0.3, 1.0, count)
    x0 = np.hstack((np.tan(angles / 4.0)[:, None] * axes, rates[:, None] * axes / 4.0))
    tumbling = simulate_batch(SC, paper.GAIN, x0, tau=0.5, rule=NoSwitching(), t_final=60.0)
    through = tumbling.max_sigma > 1.0  # these runs do pass Phi = 180 deg
    assert through.sum() >= 50
    aware = simulate_batch(SC, paper.GAIN, x0[through], tau=0.5, rule=DelayAware(), t_final=60.0)
    assert np.all(aware.switch_count >= 1)
    assert not np.any(aware.last_switch_time >= 50.0)
    assert np.all(aware.converged)


def test_batch_matches_single_runs() -> None:
    x0 = np.array([X0, [0.5, 0.2, -0.1, 0.05, 0.0, 0.02]])
    batch = simulate_batch(
        SC,
        K,
        x0,
        tau=[0.02, 0.0],
        rule=[BoundaryLayer(0.05), BoundaryLayer(0.2)],
        t_final=2.0,
        trajectories=True,
    )
    for i, (tau, rule) in enumerate([(0.02, BoundaryLayer(0.05)), (0.0, BoundaryLayer(0.2))]):
        single = simulate(SC, K, x0[i], tau=tau, rule=rule, t_final=2.0)
        np.testing.assert_array_equal(batch.runs[i].sigma, single.sigma)
        np.testing.assert_array_equal(batch.sign_flips[i], single.sign_flips)
        assert batch.switch_count[i] == single.switch_count
        assert batch.max_sigma[i] == single.max_sigma
    assert "2 runs" in str(batch)


# ------------------------------------------------------------------ bad input, divergence
def test_divergence_is_flagged_and_stops() -> None:
    unstable = np.hstack((np.zeros((3, 3)), 2000.0 * np.eye(3)))  # positive rate feedback: omega explodes
    run = simulate(SC, unstable, X0, tau=0.0, rule=OnCurrent(), t_final=30.0)
    assert run.diverged and not run.converged
    assert np.all(np.isfinite(run.sigma)) and np.all(np.isfinite(run.omega))
    assert run.t[-1] < 30.0 and "DIVERGED" in str(run)
    batch = simulate_batch(SC, unstable, X0, tau=0.0, rule=OnCurrent(), t_final=30.0)
    assert batch.diverged[0] and not batch.converged[0]


@pytest.mark.parametrize(
    "change,error,match",
    [
        ({"x0": np.array([np.nan, 0, 0, 0, 0, 0])}, SpecificationError, "x0"),
        ({"x0": np.zeros(5)}, DimensionError, "x0"),
        ({"tau": -0.1}, SpecificationError, "tau"),
        ({"tau": 0.0005}, SpecificationError, "tau \\* rate"),
        ({"rate": 0.0}, SpecificationError, "rate"),
        ({"rate": -5.0}, SpecificationError, "rate"),
        ({"t_final": 0.0}, SpecificationError, "t_final"),
        ({"K": np.zeros((6, 3))}, DimensionError, "K"),
        ({"history": "linear"}, SpecificationError, "history"),
        ({"history": np.zeros((3, 6))}, DimensionError, "history"),
        ({"rule": "OnDelayed"}, SpecificationError, "rule"),
        ({"substeps": 0}, SpecificationError, "substeps"),
    ],
)
def test_bad_input(change: dict, error: type, match: str) -> None:
    arguments = dict(x0=X0, K=K, tau=0.01, rule=OnDelayed(), t_final=1.0, rate=1000.0)
    arguments.update(change)
    with pytest.raises(error, match=match):
        simulate(SC, arguments.pop("K"), arguments.pop("x0"), **arguments)


def test_delay_samples() -> None:
    assert delay_samples(0.5, 1000) == 500
    assert delay_samples(0.003, 1000) == 3
    assert delay_samples(0.0, 1000) == 0
    with pytest.raises(SpecificationError, match=r"tau = 0\.0015.*rate = 1000"):
        delay_samples(0.0015, 1000)


def test_result_is_frozen_and_readable(paper_runs) -> None:
    run = paper_runs["aware"]
    with pytest.raises(dataclasses.FrozenInstanceError):
        run.tau = 1.0  # type: ignore[misc]
    for array in (run.t, run.sigma, run.omega, run.u, run.switch_times, run.switch_indices, run.sign_flips):
        assert not array.flags.writeable
    np.testing.assert_array_equal(run.switch_times, run.switch_indices / 1000.0)
    text = str(run)
    assert "DelayAware" in text and "switches" in text and "settling" in text
    assert run.rule == DelayAware() and run.tau == 0.5 and run.rate == 1000.0 and run.delay_samples == 500


def test_runs_are_bit_reproducible(paper_runs) -> None:
    again = simulate(SC, paper.GAIN, paper.INITIAL_STATE, tau=0.5, rule=OnDelayed(), t_final=60.0)
    np.testing.assert_array_equal(again.sigma, paper_runs["delayed"].sigma)


def test_run_time_inertia_follows_each_spacecraft() -> None:
    """One compiled engine per inertia layout: a second diagonal spacecraft still gets its own J."""
    small = np.diag([30.0, 25.0, 20.0])
    x0 = np.array([0.3, -0.5, 0.7, 0.05, 0.02, -0.03])
    simulate(SC, K, x0, tau=0.007, rule=OnDelayed(), t_final=0.5)  # the engine, built for the paper's J
    run = simulate(Spacecraft(np.diag(small)), K, x0, tau=0.007, rule=OnDelayed(), t_final=0.5)
    sigma, omega, u, switched = reference_run(["delayed"], [1.0], d=7, rate=1000.0, n=501, inertia=small, x0=x0)
    assert np.max(np.abs(run.sigma - sigma[:, 0])) < 1e-12
    assert np.max(np.abs(run.omega - omega[:, 0])) < 1e-12
    assert np.max(np.abs(run.u - u[:, 0])) < 1e-12 * np.max(np.abs(K))
    np.testing.assert_array_equal(run.switch_indices, np.flatnonzero(switched[:, 0]))
