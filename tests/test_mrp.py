"""MRP kinematics against scipy's Rotation, finite differences and algebraic identities."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial.transform import Rotation

from mrpctl import mrp
from mrpctl.errors import DimensionError, SpecificationError

N_ATTITUDES = 2000
TOL = 1e-12


@pytest.fixture(scope="module")
def rotations() -> Rotation:
    return Rotation.random(N_ATTITUDES, random_state=7)


def _scalar_first(rotation: Rotation) -> np.ndarray:
    q = rotation.as_quat()  # scipy: scalar last
    q = np.concatenate((q[:, 3:], q[:, :3]), axis=1)
    return np.where(q[:, :1] < 0.0, -q, q)


def _same_attitude(sigma_a: np.ndarray, sigma_b: np.ndarray) -> float:
    return float(np.max(np.abs(mrp.to_dcm(sigma_a) - mrp.to_dcm(sigma_b))))


# ----------------------------------------------------------------------- vs scipy
def test_from_quaternion_matches_scipy(rotations: Rotation) -> None:
    sigma = mrp.from_quaternion(_scalar_first(rotations))
    assert np.max(np.abs(sigma - rotations.as_mrp())) < TOL


def test_from_quaternion_accepts_either_sign(rotations: Rotation) -> None:
    q = _scalar_first(rotations)
    assert np.max(np.abs(mrp.from_quaternion(-q) - rotations.as_mrp())) < TOL


def test_to_quaternion_matches_scipy(rotations: Rotation) -> None:
    assert np.max(np.abs(mrp.to_quaternion(rotations.as_mrp()) - _scalar_first(rotations))) < TOL


def test_scipy_from_mrp_matches_to_dcm(rotations: Rotation) -> None:
    sigma = rotations.as_mrp()
    # [BN] is passive; scipy's as_matrix() is the active matrix, its transpose.
    reference = Rotation.from_mrp(sigma).as_matrix().transpose(0, 2, 1)
    assert np.max(np.abs(mrp.to_dcm(sigma) - reference)) < TOL


def test_from_dcm_matches_scipy(rotations: Rotation) -> None:
    dcm = rotations.as_matrix().transpose(0, 2, 1)
    assert np.max(np.abs(mrp.from_dcm(dcm) - rotations.as_mrp())) < TOL


def test_rotation_vector_matches_scipy(rotations: Rotation) -> None:
    sigma = rotations.as_mrp()
    assert np.max(np.abs(mrp.to_rotation_vector(sigma) - rotations.as_rotvec())) < TOL
    assert np.max(np.abs(mrp.from_rotation_vector(rotations.as_rotvec()) - sigma)) < TOL


def test_rotation_vector_small_angles_match_scipy() -> None:
    rotvec = np.array([[1e-9, 0, 0], [0, 3e-6, -2e-6], [5e-5, 5e-5, 5e-5], [0, 0, 0]])
    sigma = mrp.from_rotation_vector(rotvec)
    assert np.max(np.abs(sigma - Rotation.from_rotvec(rotvec).as_mrp())) < 1e-15
    assert np.max(np.abs(mrp.to_rotation_vector(sigma) - rotvec)) < 1e-15


def test_principal_rotation_matches_scipy(rotations: Rotation) -> None:
    rotvec = rotations.as_rotvec()
    angle = np.linalg.norm(rotvec, axis=1)
    axis = rotvec / angle[:, None]
    sigma = mrp.from_principal_rotation(axis, angle)
    assert np.max(np.abs(sigma - rotations.as_mrp())) < TOL
    axis_back, angle_back = mrp.to_principal_rotation(sigma)
    assert np.max(np.abs(angle_back - angle)) < TOL
    assert np.max(np.abs(axis_back - axis)) < 1e-10


def test_principal_rotation_of_long_set_exceeds_pi() -> None:
    sigma = np.array([0.5, 0.0, 0.0])
    _, angle = mrp.to_principal_rotation(mrp.shadow(sigma))
    assert angle == pytest.approx(2 * np.pi - 4 * np.arctan(0.5), abs=1e-14)


def test_paper_initial_attitude() -> None:
    sigma = mrp.from_principal_rotation([1.0, 0.0, 0.0], np.radians(171.6913))
    assert sigma[0] == pytest.approx(0.9300, abs=5e-5)
    assert np.max(np.abs(sigma - Rotation.from_rotvec([np.radians(171.6913), 0, 0]).as_mrp())) < TOL


def test_add_and_subtract_match_scipy(rotations: Rotation) -> None:
    first, second = rotations[:1000], rotations[1000:]
    sigma = mrp.add(first.as_mrp(), second.as_mrp())
    # [FN] = [FB][BN] (passive) is the active product first * second in scipy.
    reference = (first * second).as_mrp()
    assert np.max(np.abs(sigma - reference)) < TOL
    assert np.all(np.linalg.norm(sigma, axis=1) <= 1.0 + 1e-15)
    relative = mrp.subtract(sigma, first.as_mrp())
    assert _same_attitude(relative, second.as_mrp()) < TOL


def test_add_uses_dcm_product(rotations: Rotation) -> None:
    s1, s2 = rotations[:500].as_mrp(), rotations[500:1000].as_mrp()
    assert np.max(np.abs(mrp.to_dcm(mrp.add(s1, s2)) - mrp.to_dcm(s2) @ mrp.to_dcm(s1))) < TOL


# ------------------------------------------------------------------ shadow, short
def test_shadow_is_same_rotation(rotations: Rotation) -> None:
    sigma = rotations.as_mrp()
    shadow = mrp.shadow(sigma)
    assert _same_attitude(shadow, sigma) < TOL
    assert np.max(np.abs(Rotation.from_mrp(shadow).as_matrix() - rotations.as_matrix())) < TOL
    assert np.max(np.abs(mrp.shadow(shadow) - sigma)) < TOL


def test_short_returns_the_set_inside_the_unit_ball(rotations: Rotation) -> None:
    sigma = rotations.as_mrp()
    long_sets = mrp.shadow(sigma)
    mixed = np.where(np.arange(len(sigma))[:, None] % 2 == 0, sigma, long_sets)
    assert np.max(np.abs(mrp.short(mixed) - sigma)) < TOL


def test_shadow_of_zero_raises() -> None:
    with pytest.raises(SpecificationError, match=r"sigma.*no shadow"):
        mrp.shadow(np.zeros(3))
    with pytest.raises(SpecificationError, match="sigma"):
        mrp.shadow([[0.1, 0.2, 0.3], [0.0, 0.0, 0.0]])


# --------------------------------------------------------------------- kinematics
def test_b_matrix_identity(rotations: Rotation) -> None:
    sigma = rotations.as_mrp() * 1.7  # not only the short set
    b = mrp.b_matrix(sigma)
    scale = (1.0 + np.sum(sigma**2, axis=1)) ** 2
    assert np.max(np.abs(b.transpose(0, 2, 1) @ b - scale[:, None, None] * np.eye(3))) < 1e-11
    assert np.max(np.abs(mrp.b_matrix_inverse(sigma) @ b - np.eye(3))) < TOL


def test_b_matrix_against_written_formula(rng: np.random.Generator) -> None:
    sigma = rng.normal(size=3)
    s = np.array([[0, -sigma[2], sigma[1]], [sigma[2], 0, -sigma[0]], [-sigma[1], sigma[0], 0]])
    expected = (1 - sigma @ sigma) * np.eye(3) + 2 * s + 2 * np.outer(sigma, sigma)
    assert np.max(np.abs(mrp.b_matrix(sigma) - expected)) < 1e-14


def test_sigma_dot_against_dcm_kinematics(rng: np.random.Generator) -> None:
    """sigma_dot must reproduce Poisson's equation dC/dt = -[omega x] C for [BN]."""
    step = 1e-6
    for _ in range(50):
        sigma = mrp.short(rng.normal(size=3) * 0.6)
        omega = rng.normal(size=3)
        rate = mrp.sigma_dot(sigma, omega)
        dcm_rate = (mrp.to_dcm(sigma + step * rate) - mrp.to_dcm(sigma - step * rate)) / (2 * step)
        expected = -mrp.skew(omega) @ mrp.to_dcm(sigma)
        assert np.max(np.abs(dcm_rate - expected)) < 1e-8


def test_sigma_dot_vectorised_over_leading_axes(rng: np.random.Generator) -> None:
    sigma = rng.normal(size=(4, 5, 3))
    omega = rng.normal(size=(4, 5, 3))
    out = mrp.sigma_dot(sigma, omega)
    assert out.shape == (4, 5, 3)
    assert np.allclose(out[2, 3], mrp.b_matrix(sigma[2, 3]) @ omega[2, 3] / 4, rtol=0, atol=1e-15)


def test_skew_is_cross_product(rng: np.random.Generator) -> None:
    v, w = rng.normal(size=(2, 10, 3))
    assert np.max(np.abs((mrp.skew(v) @ w[..., None])[..., 0] - np.cross(v, w))) < 1e-15


# ----------------------------------------------------------------------- properties
finite_sigma = arrays(np.float64, 3, elements=st.floats(-20, 20, allow_nan=False))


@settings(max_examples=200, deadline=None)
@given(finite_sigma)
def test_roundtrip_quaternion(sigma: np.ndarray) -> None:
    if np.sum(sigma**2) < 1e-12:
        return
    back = mrp.from_quaternion(mrp.to_quaternion(sigma))
    assert np.linalg.norm(back) <= 1.0 + 1e-12
    assert _same_attitude(back, sigma) < 1e-11


@settings(max_examples=200, deadline=None)
@given(finite_sigma)
def test_roundtrip_dcm(sigma: np.ndarray) -> None:
    back = mrp.from_dcm(mrp.to_dcm(sigma))
    assert np.linalg.norm(back) <= 1.0 + 1e-12
    assert _same_attitude(back, sigma) < 1e-11


@settings(max_examples=200, deadline=None)
@given(arrays(np.float64, 3, elements=st.floats(-3, 3, allow_nan=False)))
def test_roundtrip_rotation_vector(rotvec: np.ndarray) -> None:
    if np.linalg.norm(rotvec) > np.pi - 1e-6:
        return  # at pi the two sets tie; which one comes back is rounding
    assert np.max(np.abs(mrp.to_rotation_vector(mrp.from_rotation_vector(rotvec)) - rotvec)) < 1e-12


@settings(max_examples=200, deadline=None)
@given(finite_sigma, finite_sigma)
def test_add_subtract_roundtrip(sigma1: np.ndarray, sigma2: np.ndarray) -> None:
    total = mrp.add(sigma1, sigma2)
    assert _same_attitude(mrp.subtract(total, sigma1), sigma2) < 1e-10


# ------------------------------------------------------------------------ bad input
@pytest.mark.parametrize(
    "function", [mrp.shadow, mrp.short, mrp.b_matrix, mrp.to_dcm, mrp.to_quaternion, mrp.to_rotation_vector]
)
def test_nan_and_inf_rejected(function) -> None:
    for bad in (np.nan, np.inf):
        with pytest.raises(SpecificationError, match="sigma must be finite"):
            function([0.1, bad, 0.2])


@pytest.mark.parametrize("function", [mrp.shadow, mrp.short, mrp.b_matrix, mrp.to_dcm])
def test_wrong_shape_rejected(function) -> None:
    with pytest.raises(DimensionError, match=r"sigma: expected shape \(\.\.\., 3\) but found \(4,\)"):
        function(np.zeros(4))


def test_sigma_dot_checks_omega() -> None:
    with pytest.raises(SpecificationError, match="omega must be finite"):
        mrp.sigma_dot([0.1, 0.2, 0.3], [np.nan, 0, 0])
    with pytest.raises(DimensionError, match="omega"):
        mrp.sigma_dot([0.1, 0.2, 0.3], [1.0, 0.0])


def test_bad_conversion_inputs() -> None:
    with pytest.raises(SpecificationError, match="quaternion"):
        mrp.from_quaternion(np.zeros(4))
    with pytest.raises(DimensionError, match="quaternion"):
        mrp.from_quaternion(np.ones(3))
    with pytest.raises(SpecificationError, match="dcm must be a proper rotation"):
        mrp.from_dcm(2 * np.eye(3))
    with pytest.raises(SpecificationError, match="dcm must be a proper rotation"):
        mrp.from_dcm(-np.eye(3))
    with pytest.raises(SpecificationError, match="axis"):
        mrp.from_principal_rotation(np.zeros(3), 1.0)
    with pytest.raises(SpecificationError, match="angle must be finite"):
        mrp.from_principal_rotation([1, 0, 0], np.nan)
