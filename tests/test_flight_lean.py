"""The leaner compiled flight sample (design/flight.md, phase 8b): same numbers, bit for bit.

The compiled engine's flight sample reads its delayed measurement as it is (``short_measurements``);
the engine hands the driver a history already in the short set. Checked here against the virtual
machine, which runs the sample as before (the controller takes the short set of every measurement it
reads) on the history as given, and the claim behind it: every measurement the sample writes is a
fixed point of the short-set map.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from mrpctl import OnCurrent, paper, simulate
from mrpctl.engines import scalar as _engine
from mrpctl.engines.stats import S_K
from mrpctl.engines.vm import VirtualMachineEngine
from mrpctl.flight import (
    ActuatorModel,
    Hysteretic,
    Saturation,
    SensorModel,
    actuator_function,
    selection_function,
    short_expr,
)
from mrpctl.loop.options import NO_FLIGHT_OPTIONS

_ULP = 2.0**-52  # the spacing of doubles in [1, 2)


def _near_the_sphere(count: int, seed: int) -> np.ndarray:
    """σ (count, 3) whose computed |σ|² (CasADi's order, no FMA) is in [1 − 8 ulp, 1 + 40 ulp]: the shadow's edge."""
    rng = np.random.default_rng(seed)
    sigma = rng.normal(size=(count, 3))
    sigma /= np.sqrt(np.sum(sigma**2, axis=1, keepdims=True))
    sigma *= (1.0 + rng.integers(-4, 20, count) * _ULP)[:, None]
    sigma *= 1.0 + rng.integers(-3, 4, (count, 3)) * (_ULP / 2)  # a few last bits of each component
    return sigma


def _bits(array: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(array, dtype=float).view(np.uint64)


def test_every_measurement_the_ideal_sample_writes_is_its_own_short_set():
    sigma = _near_the_sphere(200_000, 8)
    squared = (sigma[:, 0] * sigma[:, 0] + sigma[:, 1] * sigma[:, 1]) + sigma[:, 2] * sigma[:, 2]
    assert np.sum(squared > 1.0) > 100_000 and np.sum(squared == 1.0) > 1_000  # the edge is covered
    x = ca.SX.sym("x", 6)
    # without a sensor m_k is x_meas, bookkept by OnCurrent (−σ/|σ|² when |σ|² >= 1)
    bookkept = OnCurrent().expressions(x, x, ca.SX.zeros(1), delay_samples=0)[0]
    states = np.hstack((sigma, np.zeros_like(sigma)))
    measured = ca.Function("m", [x], [bookkept]).map(len(states))
    reread = ca.Function("r", [x], [short_expr(bookkept[0:3])]).map(len(states))
    m = np.asarray(measured(states.T))[0:3]
    assert np.max(np.sum(m**2, axis=0)) <= 1.0 + 4 * _ULP  # short (what the test is about)
    assert np.array_equal(_bits(np.asarray(reread(states.T))), _bits(m))  # a fixed point, bit for bit
    # and never a −0 (the short-set map makes it +0): if_else(c, a, b) is (c ? a : 0) + (!c ? b : 0)
    negative_zero = np.array([[-0.0, -0.0, -0.0, 0.0, 0.0, 0.0], [2.0, -0.0, -0.0, 0.0, 0.0, 0.0]])
    m = np.asarray(ca.Function("m", [x], [bookkept]).map(2)(negative_zero.T))[0:3]
    assert not np.any(np.signbit(m) & (m == 0.0))


def _former_selection() -> ca.Function:
    """selection_function as written before phase 8b (if_else flips and a selected shadow): the reference."""
    h, c, delta = ca.SX.sym("h"), ca.SX.sym("c"), ca.SX.sym("delta")
    sigma, previous = ca.SX.sym("sigma", 3), ca.SX.sym("previous", 3)
    s_now, s_prev = ca.dot(sigma, sigma), ca.dot(previous, previous)
    flipped = (1 - s_now) * (1 - s_prev) + 4 * ca.dot(sigma, previous) < 0
    c_next = ca.if_else(flipped, -c, c)
    switched = ca.if_else(ca.logic_and(h * c_next < 0, (1 + delta) * s_now < 1 - delta), 1.0, 0.0)
    h_next = ca.if_else(switched, -h, h)
    shadow = sigma * (-1 / ca.if_else(s_now > 0, s_now, 1.0))
    sigma_c = ca.if_else(h_next * c_next > 0, sigma, shadow)
    return ca.Function("former", [h, c, sigma, previous, delta], [h_next, c_next, sigma_c, switched])


def test_the_selection_function_gives_the_former_bits_for_every_h_and_c():
    rng = np.random.default_rng(5)
    n = 20_000
    sigma = np.vstack((_near_the_sphere(n // 2, 6), rng.normal(size=(n // 2, 3)) * rng.uniform(0, 2, (n // 2, 1))))
    sigma[::7, rng.integers(0, 3)] = -0.0  # zeros of both signs, and σ = 0 itself
    sigma[::11, :] = 0.0
    sigma[::13, 1] = -0.0
    previous = np.roll(sigma, 1, axis=0) * rng.choice([-1.0, 1.0], (n, 1))  # same and opposite hemispheres
    h = rng.choice([-1.0, 1.0], n)
    c = rng.choice([-1.0, 1.0], n)
    delta = rng.choice([0.0, 0.05, 0.5], n)
    inputs = (h, c, sigma.T, previous.T, delta)
    ours = selection_function().map(n)(*inputs)
    former = _former_selection().map(n)(*inputs)
    assert np.sum(np.asarray(former[3])) > 500 and np.sum(np.asarray(former[1]) != c) > 500  # flips of h and c
    for new, old in zip(ours, former, strict=True):
        assert np.array_equal(_bits(np.asarray(new)), _bits(np.asarray(old)))


def _former_actuator(mode: Saturation) -> ca.Function:
    """actuator_function as written before phase 8b (three selected quotients): the reference."""
    u, u_max, norm_max, w = ca.SX.sym("u", 3), ca.SX.sym("u_max", 3), ca.SX.sym("norm_max"), ca.SX.sym("w", 3)
    if mode is Saturation.SCALE:
        ratio = ca.fmax(ca.mmax(ca.fabs(u) / u_max), ca.norm_2(u) / norm_max)
        saturated = ratio > 1
        applied = ca.fmin(ca.fmax(ca.if_else(saturated, u / ratio, u), -u_max), u_max)
    else:
        clipped = ca.fmin(ca.fmax(u, -u_max), u_max)
        ratio = ca.norm_2(clipped) / norm_max
        applied = ca.if_else(ratio > 1, clipped / ratio, clipped)
        saturated = ca.logic_or(ca.mmax(ca.fabs(u) - u_max) > 0, ratio > 1)
    return ca.Function("former", [u, u_max, norm_max, w], [applied, applied + w, ca.if_else(saturated, 1.0, 0.0)])


@pytest.mark.parametrize("mode", list(Saturation))
def test_the_actuator_function_gives_the_former_bits(mode):
    rng = np.random.default_rng(7)
    n = 20_000
    u = rng.normal(size=(n, 3)) * rng.choice([0.1, 1.0, 10.0, 1e200], (n, 1))
    u[::5, rng.integers(0, 3)] = -0.0
    u[::9, :] = -0.0
    u[::17, 0] = np.inf
    u[::19, 1] = -np.inf
    u_max = rng.uniform(0.5, 3.0, (n, 3))
    u_max[::3, :] = np.inf  # no per-axis limit
    norm_max = rng.choice([1.5, 4.0, np.inf], n)
    w = rng.normal(size=(n, 3)) * 0.1
    w[::4] = 0.0
    inputs = (u.T, u_max.T, norm_max, w.T)
    ours = actuator_function(mode).map(n)(*inputs)
    former = _former_actuator(mode).map(n)(*inputs)
    assert 1_000 < np.sum(np.asarray(former[2])) < n - 1_000  # limited and free samples
    for new, old in zip(ours, former, strict=True):
        assert np.array_equal(_bits(np.asarray(new)), _bits(np.asarray(old)))


def test_short_history_is_the_controllers_short_set_and_keeps_the_rates():
    rows = np.array([[2.0, -1.0, 0.5, 0.1, -0.2, 0.3], [-0.0, 0.0, -0.0, -0.0, 1.0, 2.0], [0.1, 0.2, -0.3, 0, 0, 0]])
    short = _engine.short_history(rows)
    assert np.array_equal(short[:, 3:6], rows[:, 3:6]) and np.signbit(short[1, 3])  # ω/4 as given, −0 kept
    assert np.allclose(short[0, 0:3], -rows[0, 0:3] / 5.25, rtol=1e-15, atol=0)  # the shadow −σ/|σ|²
    assert np.array_equal(short[2], rows[2])
    assert not np.any(np.signbit(short[1, 0:3]))  # −0 → +0, as the sample's if_else did
    assert short is not rows and rows[0, 0] == 2.0  # a copy


@pytest.mark.parametrize(("delta", "noisy"), [(0.0, False), (0.15, False), (0.15, True)])
def test_a_long_history_gives_the_virtual_machines_numbers_bit_for_bit(delta, noisy):
    # The virtual machine runs the flight sample as before: the controller takes the short set of every
    # measurement it reads, here the history as given (rows in the long set, a −0, a row on the sphere).
    d, n = 5, 300
    rng = np.random.default_rng(3)
    sigma = rng.normal(size=(d, 3))
    sigma *= (rng.uniform(1.2, 4.0, d) / np.linalg.norm(sigma, axis=1))[:, None]  # |σ| > 1
    sigma[1] = [-0.0, 0.6, -0.8]  # |σ|² = 1 within rounding; a −0
    sigma[3] = [0.0, -0.0, 0.0]
    history = np.hstack((sigma, rng.normal(scale=0.5, size=(d, 3))))
    x0 = np.array([1.5, -0.7, 0.9, 0.4, -0.3, 0.2])  # long: the plant bookkeeping swaps it at k = 0
    gains = 0.05 * paper.GAIN
    rule = Hysteretic(delta)
    bias = [1e-3, -2e-3, 5e-4]
    sensor = SensorModel(attitude_noise=0.01, rate_noise=1e-3, gyro_bias=bias, seed=4) if noisy else None
    options = NO_FLIGHT_OPTIONS.copy()
    options[7:10] = bias if noisy else 0.0
    compiled = _engine.engine(paper.SPACECRAFT, rule, d, 0.01, 1, sensor=noisy)  # with limits (inf): squared_peak
    assert compiled.compiled_code
    machine = VirtualMachineEngine(compiled.virtual_machine_sample(), d, compiled.inertia, flight=True)
    outputs = []
    for found, given in ((compiled, history), (machine, history), (compiled, x0[None]), (machine, x0[None])):
        before = given.copy()
        outputs.append(
            found.run(
                x0,
                0.0,
                given,
                gains,
                np.array(rule.parameters()),
                n,
                spacecraft=paper.SPACECRAFT,
                keep_every=1,
                workspace=found.workspace(n, switches=True),
                switch_limit=n,
                flight_options=options,
                sensor=sensor,
            )
        )
        assert np.array_equal(_bits(given), _bits(before))  # the caller's history is not touched
    for ours, theirs in (outputs[0:2], outputs[2:4]):
        assert ours.samples == theirs.samples == n
        assert np.array_equal(_bits(ours.measurements), _bits(theirs.measurements))
        assert np.array_equal(_bits(ours.u), _bits(theirs.u))
        # the statistics but the sample counter (the machine runs whole chunks, its padding uncounted)
        assert np.array_equal(_bits(ours.stats[S_K + 1 :]), _bits(theirs.stats[S_K + 1 :])) and S_K == 0
        assert ours.switch_indices.tolist() == theirs.switch_indices.tolist()
    # the long rows were read: the history decides the first d commands (not the same in the two histories)
    assert not np.array_equal(outputs[0].u[:d], outputs[2].u[:d])


@pytest.mark.parametrize("actuator", [None, ActuatorModel([0.2, 0.25, 0.3], norm_max=0.35)])
def test_the_peak_command_is_the_max_of_the_recorded_commands_bit_for_bit(actuator):
    # The compiled sample keeps max |u_c|² and the engine takes one square root at the end; the
    # reference is max over the recorded u_c,k of their norms, each rounded (NumPy, CasADi's order).
    x0 = np.array([0.4, -0.8, 0.3, 0.2, -0.1, 0.15])
    run = simulate(
        paper.SPACECRAFT,
        0.05 * paper.GAIN,
        x0,
        tau=0.05,
        rate=100.0,
        rule=Hysteretic(0.15),
        t_final=6.0,
        actuator=actuator,
    )
    u = run.command
    norms = np.sqrt((u[:, 0] * u[:, 0] + u[:, 1] * u[:, 1]) + u[:, 2] * u[:, 2])
    assert np.array_equal(_bits(run.peak_command), _bits(np.append(np.max(np.abs(u), axis=0), np.max(norms))))
    assert actuator is None or run.saturated_fraction > 0.1  # the limits acted: u_c is not u
