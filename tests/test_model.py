"""The CasADi plant against the direct equations, the paper's split and its linearisation."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from mrpctl import Spacecraft, paper, plant_model
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.model import gain_from_pd, pd_from_gain, state, state_parts


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def _direct(inertia: np.ndarray, x: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Paper Eq. 3 written out in NumPy: [B(sigma) omega/4; J^-1 (-omega x J omega + u)/4]."""
    sigma, omega = x[:3], 4 * x[3:]
    b = (1 - sigma @ sigma) * np.eye(3) + 2 * _skew(sigma) + 2 * np.outer(sigma, sigma)
    omega_dot = np.linalg.solve(inertia, -np.cross(omega, inertia @ omega) + u)
    return np.concatenate((b @ omega / 4, omega_dot / 4))


def _paper_f(inertia: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Paper Eq. 7 as printed: f = [(B(x1) - I) x2; -4 J^-1 [x2 x] J x2]."""
    x1, x2 = x[:3], x[3:]
    b = (1 - x1 @ x1) * np.eye(3) + 2 * _skew(x1) + 2 * np.outer(x1, x1)
    return np.concatenate(((b - np.eye(3)) @ x2, -4 * np.linalg.solve(inertia, _skew(x2) @ inertia @ x2)))


@pytest.fixture(scope="module", params=["paper", "full"])
def spacecraft(request: pytest.FixtureRequest) -> Spacecraft:
    if request.param == "paper":
        return paper.SPACECRAFT
    q = np.linalg.qr(np.random.default_rng(3).normal(size=(3, 3)))[0]
    return Spacecraft(q @ np.diag([30.0, 45.0, 60.0]) @ q.T)


def test_dynamics_equal_direct_form_and_split(spacecraft: Spacecraft, rng: np.random.Generator) -> None:
    model = plant_model(spacecraft)
    for _ in range(200):
        x = rng.normal(size=6)
        u = rng.normal(size=3) * 50
        xdot = np.asarray(model.dynamics(x, u)).ravel()
        assert np.max(np.abs(xdot - _direct(spacecraft.inertia, x, u))) < 1e-12
        split = model.A @ x + model.B @ u + np.asarray(model.nonlinearity(x)).ravel()
        assert np.max(np.abs(split - xdot)) < 1e-12
        # The printed f(x) of the paper agrees with the direct form.
        assert np.max(np.abs(_paper_f(spacecraft.inertia, x) - np.asarray(model.nonlinearity(x)).ravel())) < 1e-12


def test_jacobian_at_origin_is_a_and_b(spacecraft: Spacecraft) -> None:
    model = plant_model(spacecraft)
    x = ca.SX.sym("x", 6)
    u = ca.SX.sym("u", 3)
    xdot = model.dynamics(x, u)
    jac = ca.Function("linearization", [x, u], [ca.jacobian(xdot, x), ca.jacobian(xdot, u)])
    a, b = (np.asarray(m) for m in jac(np.zeros(6), np.zeros(3)))
    assert np.max(np.abs(a - model.A)) < 1e-15
    assert np.max(np.abs(b - model.B)) < 1e-15
    assert np.allclose(model.B[3:], np.linalg.inv(spacecraft.inertia) / 4, rtol=0, atol=1e-15)


def test_named_ports() -> None:
    model = plant_model(paper.SPACECRAFT)
    assert model.dynamics.name() == "dynamics"
    assert model.dynamics.name_in() == ["x", "u"]
    assert model.dynamics.name_out() == ["xdot"]
    assert model.nonlinearity.name_in() == ["x"]
    assert model.nonlinearity.name_out() == ["f"]


def test_gain_convention_roundtrip_and_loop(rng: np.random.Generator) -> None:
    """K = [4 J K1, 4 J K2] makes B K = [[0, 0], [K1, K2]] (paper Eq. 19oct11)."""
    sc = paper.SPACECRAFT
    k1 = np.diag(rng.uniform(-1, -0.1, 3))
    k2 = np.diag(rng.uniform(-2, -0.1, 3))
    gain = gain_from_pd(sc, k1, k2)
    back1, back2 = pd_from_gain(sc, gain)
    assert np.allclose(back1, k1, atol=1e-15) and np.allclose(back2, k2, atol=1e-15)
    _, a_delayed = plant_model(sc).closed_loop_matrices(gain)
    assert np.allclose(a_delayed, np.block([[np.zeros((3, 6))], [k1, k2]]), atol=1e-15)


def test_paper_gain_in_loop_coordinates() -> None:
    k1, k2 = pd_from_gain(paper.SPACECRAFT, paper.GAIN)
    assert np.allclose(np.diag(k1), -70.11 / (4 * np.array([140, 100, 80])), rtol=1e-14)
    assert np.allclose(np.diag(k2), -163.08 / (4 * np.array([140, 100, 80])), rtol=1e-14)


def test_linearised_closed_loop_is_sigma_ddot(rng: np.random.Generator) -> None:
    """Small-angle check of the convention: sigma_ddot = K1 sigma + K2 sigma_dot for tau = 0."""
    sc = paper.SPACECRAFT
    model = plant_model(sc)
    k1, k2 = pd_from_gain(sc, paper.GAIN)
    x = rng.normal(size=6) * 1e-7
    xdot = np.asarray(model.dynamics(x, paper.GAIN @ x)).ravel()
    sigma_ddot = xdot[3:]  # x2 = omega/4 = sigma_dot to first order
    assert np.allclose(sigma_ddot, k1 @ x[:3] + k2 @ x[3:], rtol=1e-5, atol=1e-20)


def test_state_helpers() -> None:
    x = state([0.1, 0.2, 0.3], [4.0, 8.0, 12.0])
    assert np.array_equal(x, [0.1, 0.2, 0.3, 1.0, 2.0, 3.0])
    sigma, omega = state_parts(x)
    assert np.array_equal(sigma, [0.1, 0.2, 0.3]) and np.array_equal(omega, [4.0, 8.0, 12.0])


def test_bad_inputs() -> None:
    with pytest.raises(SpecificationError, match="spacecraft"):
        plant_model(np.eye(3))  # type: ignore[arg-type]
    model = plant_model(paper.SPACECRAFT)
    with pytest.raises(DimensionError, match=r"K: expected shape \(3, 6\) but found \(3, 3\)"):
        model.closed_loop_matrices(np.eye(3))
    with pytest.raises(SpecificationError, match="K must be finite"):
        model.closed_loop_matrices(np.full((3, 6), np.nan))
    with pytest.raises(SpecificationError, match="sigma must be finite"):
        state([np.nan, 0, 0], [0, 0, 0])
    with pytest.raises(SpecificationError, match="omega must be finite"):
        state([0, 0, 0], [np.inf, 0, 0])
    with pytest.raises(DimensionError, match="K1"):
        gain_from_pd(paper.SPACECRAFT, np.ones((2, 2)), np.eye(3))


def test_dynamics_with_a_symbolic_inertia_matches_the_direct_equations() -> None:
    from mrpctl.model import dynamics_expr

    inertia = np.array([[120.0, 5.0, -3.0], [5.0, 100.0, 2.0], [-3.0, 2.0, 90.0]])
    x = ca.SX.sym("x", 6)
    u = ca.SX.sym("u", 3)
    j = ca.SX.sym("J", 3, 3)
    j_inv = ca.SX.sym("J_inv", 3, 3)
    f = ca.Function("f", [x, u, j, j_inv], [dynamics_expr(None, x, u, inertia=j, inertia_inverse=j_inv)])
    rng = np.random.default_rng(3)
    for _ in range(5):
        xv, uv = rng.normal(size=6), rng.normal(size=3)
        got = np.asarray(f(xv, uv, inertia, np.linalg.inv(inertia))).ravel()
        np.testing.assert_allclose(got, _direct(inertia, xv, uv), rtol=1e-12, atol=1e-14)
    with pytest.raises(ValueError, match="both"):
        dynamics_expr(None, x, u, inertia=j)
