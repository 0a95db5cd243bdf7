"""The tracking linearisation (mrpctl.design.tracking) against independent references: a
finite-difference Jacobian of the CasADi tracking-error dynamics composed from the body dynamics
(with a separately written tracking law), and the onset of instability of the delayed linear loop
simulated by a NumPy method of steps (RK4 with a history buffer)."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest

from mrpctl import paper
from mrpctl.design import delay_margin, max_stable_delay_samples
from mrpctl.design.tracking import (
    certify_orbit_rates,
    orbit_rate_vertices,
    tracking_linearization,
)
from mrpctl.errors import SpecificationError
from mrpctl.guidance import CircularOrbit, EigenaxisSlew, InertialPointing, NadirPointing
from mrpctl.model import gain_from_pd, gravity_gradient_expr, tracking_error_dynamics_expr
from mrpctl.mrp import add_expr, dcm_expr
from mrpctl.spacecraft import Spacecraft

ORBIT_500 = CircularOrbit.from_altitude(500e3, inclination=math.radians(97.4), raan=0.3, latitude=0.1)


def _slow_gain(spacecraft: Spacecraft, omega_n: float = 0.002, zeta: float = 0.7) -> np.ndarray:
    """A loop slow enough (omega_n comparable to n) that the orbital terms move the delay margin."""
    return gain_from_pd(spacecraft, -(omega_n**2) * np.ones(3), -2.0 * zeta * omega_n * np.ones(3))


# --------------------------------------------------------------------------------- finite differences
def _closed_loop(
    spacecraft: Spacecraft,
    K: np.ndarray,
    profile: InertialPointing | NadirPointing,
    t: float,
    tau: float,
    *,
    feedforward: bool,
    gravity_gradient: bool,
) -> ca.Function:
    """ẋ(t) = F(x(t), x(t − τ)) of the delayed tracking loop, from the CasADi body dynamics.

    The law is written here: the measurement at t − τ is the body state rebuilt from the error and
    the reference at t − τ, u = K x(t − τ) + ω̃ × Jω̃ + J([B̃N] ω̇_R − ω̃ × [B̃N] ω_R) (reference at t − τ).
    """
    j = ca.DM(spacecraft.inertia)
    x = ca.SX.sym("x", 6)
    xd = ca.SX.sym("xd", 6)
    now, then = profile.samples(np.array([t, t - tau]))
    u = ca.DM(K) @ xd
    if feedforward:
        sigma_meas = add_expr(ca.DM(then[0:3]), xd[0:3])
        c = dcm_expr(sigma_meas)
        omega_meas = 4 * xd[3:6] + c @ ca.DM(then[3:6])
        u = u + ca.cross(omega_meas, j @ omega_meas)
        u = u + j @ (c @ ca.DM(then[6:9]) - ca.cross(omega_meas, c @ ca.DM(then[3:6])))
    torque = None
    if gravity_gradient:
        assert isinstance(profile, NadirPointing)
        r_hat = profile.r_hat(np.array([t]))[0]
        n = profile.orbit_rate

        def torque(sigma_bn: object) -> object:
            return gravity_gradient_expr(sigma_bn, r_hat, n, spacecraft.inertia)

    xdot = tracking_error_dynamics_expr(spacecraft, x, u, now[0:3], now[3:6], now[6:9], torque=torque)
    return ca.Function("loop", [x, xd], [xdot])


def _jacobians(loop: ca.Function, step: float = 1e-6) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(F(0, 0), ∂F/∂x, ∂F/∂x_d) by central differences of the numerical Function."""
    zero = np.zeros(6)
    value = np.asarray(loop(zero, zero)).ravel()
    a0 = np.zeros((6, 6))
    a1 = np.zeros((6, 6))
    for i in range(6):
        e = np.zeros(6)
        e[i] = step
        a0[:, i] = (np.asarray(loop(e, zero)).ravel() - np.asarray(loop(-e, zero)).ravel()) / (2 * step)
        a1[:, i] = (np.asarray(loop(zero, e)).ravel() - np.asarray(loop(zero, -e)).ravel()) / (2 * step)
    return value, a0, a1


def _full_inertia() -> Spacecraft:
    return Spacecraft([[140.0, 4.0, -3.0], [4.0, 100.0, 2.5], [-3.0, 2.5, 80.0]])


@pytest.mark.parametrize("feedforward", [True, False])
@pytest.mark.parametrize("gravity_gradient", [True, False])
@pytest.mark.parametrize("spacecraft", [paper.SPACECRAFT, _full_inertia()], ids=["diagonal", "full"])
def test_nadir_linearisation_equals_the_finite_difference_jacobian(
    feedforward: bool, gravity_gradient: bool, spacecraft: Spacecraft
) -> None:
    # a fast (unphysical) orbit makes the orbital terms large enough to be checked to many digits
    profile = NadirPointing(CircularOrbit(0.05, inclination=0.9, raan=-0.4, latitude=1.3))
    K = np.asarray(paper.GAIN)
    lin = tracking_linearization(spacecraft, K, profile, feedforward=feedforward, gravity_gradient=gravity_gradient)
    for t in (0.0, 37.0):  # the error dynamics about a constant-rate reference do not depend on t
        loop = _closed_loop(spacecraft, K, profile, t, 0.5, feedforward=feedforward, gravity_gradient=gravity_gradient)
        value, a0, a1 = _jacobians(loop)
        scale = max(np.abs(lin.A[3:]).max(), 1e-3)
        np.testing.assert_allclose(a0, lin.A, rtol=0, atol=1e-7 * scale)
        np.testing.assert_allclose(a1, lin.A_d, rtol=0, atol=1e-7 * np.abs(lin.A_d).max())
        # at x = 0 the loop moves only by the torque the law leaves unsupplied
        expected = np.concatenate((np.zeros(3), -0.25 * spacecraft.inertia_inverse @ lin.unbalanced_torque))
        np.testing.assert_allclose(value, expected, rtol=0, atol=1e-12)
    # the orbital terms are really there: the coupling entries are far above the tolerance
    assert abs(lin.A[3, 4]) > 1e-3 and abs(lin.A[4, 3]) > 1e-3
    if spacecraft is paper.SPACECRAFT:
        np.testing.assert_array_equal(lin.unbalanced_torque, 0.0)
    elif gravity_gradient or not feedforward:
        assert np.linalg.norm(lin.unbalanced_torque) > 0.0


@pytest.mark.parametrize("feedforward", [True, False])
def test_inertial_linearisation_is_todays_plant_and_matches_the_jacobian(feedforward: bool) -> None:
    sc = _full_inertia()
    profile = InertialPointing([0.2, -0.1, 0.3])
    lin = tracking_linearization(sc, paper.GAIN, profile, feedforward=feedforward)
    _, a0, a1 = _jacobians(
        _closed_loop(sc, paper.GAIN, profile, 3.0, 0.5, feedforward=feedforward, gravity_gradient=False)
    )
    expected_a = np.block([[np.zeros((3, 3)), np.eye(3)], [np.zeros((3, 3)), np.zeros((3, 3))]])
    np.testing.assert_array_equal(lin.A, expected_a)
    np.testing.assert_allclose(lin.A_d, np.vstack((np.zeros((3, 6)), 0.25 * sc.inertia_inverse @ paper.GAIN)))
    np.testing.assert_allclose(a0, lin.A, atol=1e-9)
    np.testing.assert_allclose(a1, lin.A_d, atol=1e-9)
    assert lin.orbit_rate == 0.0 and "inertial pointing" in str(lin)


def test_linearisation_refuses_what_it_does_not_cover() -> None:
    slew = EigenaxisSlew(start=[0.0, 0.0, 0.0], axis=[1.0, 0.0, 0.0], angle=1.0, rate_limit=0.1, acceleration_limit=0.1)
    with pytest.raises(SpecificationError, match=r"reference.*time-varying"):
        tracking_linearization(paper.SPACECRAFT, paper.GAIN, slew)  # type: ignore[arg-type]
    with pytest.raises(SpecificationError, match="feedforward"):
        tracking_linearization(paper.SPACECRAFT, paper.GAIN, feedforward=1)  # type: ignore[arg-type]
    with pytest.raises(SpecificationError, match="rates"):
        orbit_rate_vertices(paper.SPACECRAFT, paper.GAIN, (2e-3, 1e-3))


# ------------------------------------------------------------------------ simulated onset of instability
def _growth_rates(
    cases: list[tuple[np.ndarray, np.ndarray]], taus: np.ndarray, *, steps: int = 16, horizon: float = 240.0
) -> np.ndarray:
    """Growth rate (per delay) of ẋ = A x + A_d x(t − τ) for each case and τ, by simulation.

    Time is scaled by τ (t' = t/τ, delay 1, step 1/steps): RK4 whose delayed values at the stage
    times come from the stored solution (grid points and the cubic Hermite midpoint from the stored
    values and derivatives); history x = x0 (constant) before t = 0. The rate is the slope of
    log max‖x‖ over windows of 10 delays, fitted on the second half of the run.
    """
    a = np.concatenate([tau[:, None, None] * case[0] for case, tau in zip(cases, taus, strict=True)])
    ad = np.concatenate([tau[:, None, None] * case[1] for case, tau in zip(cases, taus, strict=True)])
    batch, n = a.shape[0], a.shape[1]
    m, h = steps, 1.0 / steps
    total = round(horizon * m)
    y = np.zeros((total + m + 1, batch, n))  # grid index i is row i + m; rows 0..m hold the history
    f = np.zeros_like(y)
    y[: m + 1] = np.ones(n) / math.sqrt(n)

    def rhs(now: np.ndarray, delayed: np.ndarray) -> np.ndarray:
        return np.einsum("bij,bj->bi", a, now) + np.einsum("bij,bj->bi", ad, delayed)

    for k in range(total):
        i = k + m
        right = f[k + 1] if k + 1 > m else 0.0 * f[k + 1]  # the history's derivative (0) up to t = 0
        middle = 0.5 * (y[k] + y[k + 1]) + h * (f[k] - right) / 8.0
        f[i] = rhs(y[i], y[k])
        k2 = rhs(y[i] + 0.5 * h * f[i], middle)
        k3 = rhs(y[i] + 0.5 * h * k2, middle)
        k4 = rhs(y[i] + h * k3, y[k + 1])
        y[i + 1] = y[i] + h * (f[i] + 2 * k2 + 2 * k3 + k4) / 6.0
    norms = np.linalg.norm(y[m:], axis=2)
    width = 10 * m
    windows = total // width
    peaks = np.log(norms[: windows * width].reshape(windows, width, batch).max(axis=1))
    second = np.arange(windows // 2, windows)
    slopes = np.polyfit(second, peaks[windows // 2 :], 1)[0]
    return slopes.reshape(len(cases), -1)


def _onset_brackets(cases: list[tuple[np.ndarray, np.ndarray]], lows: list[float], highs: list[float], rounds: int):
    """Bracket the smallest simulated unstable τ of each case by repeated 8-section (bisection in 3 bits a round)."""
    lo = np.array(lows, dtype=float)
    hi = np.array(highs, dtype=float)
    ends = _growth_rates(cases, np.stack((lo, hi), axis=1))
    assert np.all(ends[:, 0] < 0.0) and np.all(ends[:, 1] > 0.0), ends  # the starting brackets are brackets
    for _ in range(rounds):
        grid = lo[:, None] + (hi - lo)[:, None] * np.arange(1, 8)[None, :] / 8.0
        rates = _growth_rates(cases, grid)
        for c in range(len(cases)):
            unstable = np.flatnonzero(rates[c] > 0.0)
            first = int(unstable[0]) if unstable.size else 7
            lo[c], hi[c] = (grid[c, first - 1] if first > 0 else lo[c]), (grid[c, first] if first < 7 else hi[c])
    return lo, hi


def test_exact_margin_of_nadir_pointing_equals_the_simulated_onset_of_instability() -> None:
    slow_k = _slow_gain(paper.SPACECRAFT)
    nadir = NadirPointing(ORBIT_500)
    loops = [
        tracking_linearization(paper.SPACECRAFT, paper.GAIN, nadir),  # the paper's spacecraft and gains, 500 km
        tracking_linearization(paper.SPACECRAFT, slow_k, nadir, feedforward=True),
        tracking_linearization(paper.SPACECRAFT, slow_k, nadir, feedforward=False),
    ]
    margins = [loop.delay_margin().margin for loop in loops]
    lo, hi = _onset_brackets([(loop.A, loop.A_d) for loop in loops], [1.0, 200.0, 200.0], [2.0, 400.0, 400.0], 4)
    for margin, low, high in zip(margins, lo, hi, strict=True):
        assert high - low <= 1.01 * (2.0 if high < 10 else 200.0) / 8**4  # the bisection step
        assert low < margin <= high, (low, margin, high)
    # the slow loop's brackets separate nadir pointing with and without feedforward and inertial pointing
    inertial = tracking_linearization(paper.SPACECRAFT, slow_k).delay_margin().margin
    assert hi[1] < inertial and hi[2] < lo[1]
    assert margins[1] / margins[2] > 1.04


# ----------------------------------------------------------------------- LMI, sampled data, orbit range
def test_lmi_certifies_the_nadir_loop_only_below_its_exact_margin() -> None:
    lin = tracking_linearization(paper.SPACECRAFT, paper.GAIN, NadirPointing(ORBIT_500))
    margin = lin.delay_margin().margin
    assert lin.certify(0.9 * margin, order=2).certified
    assert not lin.certify(1.01 * margin, order=2).certified


def test_sampled_nadir_loop_at_20_hz_loses_stability_near_the_continuous_margin() -> None:
    lin = tracking_linearization(paper.SPACECRAFT, paper.GAIN, NadirPointing(ORBIT_500))
    margin = lin.delay_margin().margin
    h = 0.05
    d = lin.max_stable_delay_samples(h)
    # the zero-order hold adds about h/2 of delay: the last stable d h lies within 2 h below the margin
    assert margin - 2 * h <= d * h <= margin
    assert lin.sampled_stability(h, delay_samples=d).stable
    assert not lin.sampled_stability(h, delay_samples=d + 1).stable


def test_orbit_rate_vertices_hold_the_loops_and_certify_the_range() -> None:
    sc = paper.SPACECRAFT
    slow_k = _slow_gain(sc, omega_n=0.004)
    rates = (0.6e-3, 1.2e-3)
    vertices = orbit_rate_vertices(sc, slow_k, rates)
    for vertex, n in zip(vertices[:2], rates, strict=False):  # the two ends are the loops at n_lo and n_hi
        lin = tracking_linearization(sc, slow_k, NadirPointing(CircularOrbit(n)))
        np.testing.assert_allclose(vertex[0], lin.A, rtol=1e-13, atol=1e-20)
        np.testing.assert_allclose(vertex[1], lin.A_d, rtol=1e-13, atol=1e-20)
    grid = np.linspace(*rates, 9)
    exact = [tracking_linearization(sc, slow_k, NadirPointing(CircularOrbit(n))).delay_margin().margin for n in grid]
    tau = 0.8 * min(exact)
    cert = certify_orbit_rates(sc, slow_k, tau, rates, order=1)
    assert cert.certified, cert.reason
    # soundness at a delay no loop of the range survives: the certificate must fail there
    assert not certify_orbit_rates(sc, slow_k, 1.05 * max(exact), rates, order=1).certified
    assert delay_margin(*vertices[2]).margin > tau


def test_blocks_split_the_loop_as_the_physics_does() -> None:
    inertial = tracking_linearization(paper.SPACECRAFT, paper.GAIN)
    nadir = tracking_linearization(paper.SPACECRAFT, paper.GAIN, NadirPointing(ORBIT_500))
    assert inertial.blocks == ((0, 3), (1, 4), (2, 5))
    assert nadir.blocks == ((0, 1, 3, 4), (2, 5))  # roll-yaw coupled, pitch alone
    assert tracking_linearization(_full_inertia(), paper.GAIN, NadirPointing(ORBIT_500)).blocks == (tuple(range(6)),)
    # the blocks' answer equals the whole loop's where the whole-loop test is sound (20 Hz)
    whole = max_stable_delay_samples(nadir.A, nadir.B, nadir.loop_gain, 0.05)
    assert nadir.max_stable_delay_samples(0.05) == whole
