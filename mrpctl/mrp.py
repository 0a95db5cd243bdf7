"""Modified Rodrigues parameters (MRPs): shadow set, conversions, kinematics.

Conventions (see ``design/conventions.md``):

* σ = tan(Φ/4) ê for a principal rotation of angle Φ (rad) about the unit axis ê.
* Quaternions are scalar first, β = (β₀, β₁, β₂, β₃) = (cos Φ/2, ê sin Φ/2), as in
  Schaub & Junkins and Basilisk.
* The direction cosine matrix is [BN]: it maps N-frame components of a vector into
  B-frame components (passive). ``scipy.spatial.transform.Rotation.as_matrix()``
  returns its transpose.
* Every function that *returns* an attitude returns the short set, |σ| <= 1, unless its
  name says otherwise (``shadow``). Which of the two sets is returned at exactly
  |σ| = 1 is decided by rounding.

All functions are vectorised over leading axes: σ has shape (..., 3).

The kinematic matrix B(σ) is written once, as a CasADi expression
([`b_matrix_expr`][mrpctl.mrp.b_matrix_expr]); the NumPy functions [`b_matrix`][mrpctl.mrp.b_matrix] and
[`sigma_dot`][mrpctl.mrp.sigma_dot]
evaluate that expression, and [`mrpctl.model`][mrpctl.model] builds the plant from it.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

import casadi as ca
import numpy as np

from mrpctl._validation import finite_array
from mrpctl.errors import SpecificationError

__all__ = [
    "add",
    "add_expr",
    "b_matrix",
    "b_matrix_expr",
    "b_matrix_inverse",
    "dcm_expr",
    "from_dcm",
    "from_principal_rotation",
    "from_quaternion",
    "from_rotation_vector",
    "shadow",
    "shadow_expr",
    "short",
    "sigma_dot",
    "skew",
    "skew_expr",
    "subtract",
    "subtract_expr",
    "to_dcm",
    "to_principal_rotation",
    "to_quaternion",
    "to_rotation_vector",
]

_ZERO_NORM = 1e-300


def _sigma(name: str, value: Any) -> np.ndarray:
    return finite_array(name, value, (None, 3))


# --------------------------------------------------------------------------- CasADi
def skew_expr(v: Any) -> Any:
    """The cross-product matrix [v×] of a 3-vector CasADi expression."""
    return ca.vertcat(
        ca.horzcat(0, -v[2], v[1]),
        ca.horzcat(v[2], 0, -v[0]),
        ca.horzcat(-v[1], v[0], 0),
    )


def b_matrix_expr(sigma: Any) -> Any:
    """B(σ) = (1 − σᵀσ) I₃ + 2 [σ×] + 2 σ σᵀ as a CasADi expression (SX or MX).

    σ̇ = ¼ B(σ) ω (paper Eq. 3).
    """
    return (1 - ca.dot(sigma, sigma)) * ca.DM.eye(3) + 2 * skew_expr(sigma) + 2 * (sigma @ sigma.T)


def shadow_expr(sigma: Any) -> Any:
    """The shadow set σˢ = −σ / |σ|² as a CasADi expression (undefined at σ = 0)."""
    return -sigma / ca.dot(sigma, sigma)


def dcm_expr(sigma: Any) -> Any:
    """[BN] = I + (8 [σ×]² − 4 (1 − σ²) [σ×]) / (1 + σ²)² as a CasADi expression (the NumPy
    [`to_dcm`][mrpctl.mrp.to_dcm])."""
    s = skew_expr(sigma)
    sq = ca.dot(sigma, sigma)
    return ca.DM.eye(3) + (8 * (s @ s) - 4 * (1 - sq) * s) / (1 + sq) ** 2


def add_expr(sigma1: Any, sigma2: Any) -> Any:
    """σ(F/N) from σ1 = σ(B/N) and σ2 = σ(F/B) as a CasADi expression: ``[FN] = [FB][BN]``.

    Schaub & Junkins' composition formula
    σ = ((1 − |σ1|²) σ2 + (1 − |σ2|²) σ1 − 2 σ2 × σ1) / (1 + |σ1|² |σ2|² − 2 σ1·σ2);
    the set it returns is not shortened, and the denominator vanishes for the one pair whose
    composition is a rotation by exactly 2π (for short sets: σ2 = −σ1's shadow). The NumPy
    [`add`][mrpctl.mrp.add] returns the short set.
    """
    s1 = ca.dot(sigma1, sigma1)
    s2 = ca.dot(sigma2, sigma2)
    cross = ca.cross(sigma2, sigma1)
    return ((1 - s1) * sigma2 + (1 - s2) * sigma1 - 2 * cross) / (1 + s1 * s2 - 2 * ca.dot(sigma1, sigma2))


def subtract_expr(sigma: Any, sigma1: Any) -> Any:
    """σ(F/B) from σ = σ(F/N) and σ1 = σ(B/N) as a CasADi expression: ``[FB] = [FN][BN]ᵀ``.

    σ(F/B) = ((1 − |σ1|²) σ − (1 − |σ|²) σ1 + 2 σ × σ1) / (1 + |σ1|² |σ|² + 2 σ1·σ) (Schaub &
    Junkins); not shortened (the NumPy [`subtract`][mrpctl.mrp.subtract] returns the short set).
    """
    s = ca.dot(sigma, sigma)
    s1 = ca.dot(sigma1, sigma1)
    cross = ca.cross(sigma, sigma1)
    return ((1 - s1) * sigma - (1 - s) * sigma1 + 2 * cross) / (1 + s1 * s + 2 * ca.dot(sigma1, sigma))


@lru_cache(maxsize=1)
def _b_function() -> ca.Function:
    sigma = ca.SX.sym("sigma", 3)
    return ca.Function("b_matrix", [sigma], [b_matrix_expr(sigma)], ["sigma"], ["B"])


@lru_cache(maxsize=1)
def _sigma_dot_function() -> ca.Function:
    sigma = ca.SX.sym("sigma", 3)
    omega = ca.SX.sym("omega", 3)
    return ca.Function(
        "sigma_dot", [sigma, omega], [b_matrix_expr(sigma) @ omega / 4], ["sigma", "omega"], ["sigma_dot"]
    )


# --------------------------------------------------------------------------- NumPy
def skew(v: Any) -> np.ndarray:
    """The cross-product matrix [v×], shape (..., 3, 3), so that [v×] w = v × w."""
    v = finite_array("v", v, (None, 3))
    out = np.zeros((*v.shape, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def shadow(sigma: Any) -> np.ndarray:
    """The shadow set σˢ = −σ / |σ|², which describes the same attitude as σ.

    Raises
    ------
    SpecificationError
        If any σ is the zero vector (the identity attitude has no finite shadow).
    """
    sigma = _sigma("sigma", sigma)
    sq = np.sum(sigma**2, axis=-1, keepdims=True)
    if np.any(sq <= _ZERO_NORM):
        raise SpecificationError("sigma: the zero MRP (identity attitude) has no shadow set (|sigma| = 0)")
    return -sigma / sq


def short(sigma: Any) -> np.ndarray:
    """The set with |σ| <= 1 describing the same attitude (σ unchanged if already short)."""
    sigma = _sigma("sigma", sigma)
    sq = np.sum(sigma**2, axis=-1, keepdims=True)
    long_set = sq > 1.0
    safe = np.where(long_set, sq, 1.0)
    return np.where(long_set, -sigma / safe, sigma)


def _eval_mapped(function: ca.Function, *args: np.ndarray) -> np.ndarray:
    """Evaluate a CasADi Function of 3-vectors over leading axes; returns (..., rows, cols)."""
    lead = args[0].shape[:-1]
    n = int(np.prod(lead, dtype=int))
    flat = [np.ascontiguousarray(a.reshape(n, 3).T) for a in args]
    rows, cols = function.size_out(0)
    if n == 0:
        return np.zeros((*lead, rows, cols))
    out = np.asarray(function.map(n)(*flat))
    return out.reshape(rows, n, cols).transpose(1, 0, 2).reshape((*lead, rows, cols))


def b_matrix(sigma: Any) -> np.ndarray:
    """B(σ) = (1 − σᵀσ) I₃ + 2 [σ×] + 2 σ σᵀ, shape (..., 3, 3)."""
    sigma = _sigma("sigma", sigma)
    return _eval_mapped(_b_function(), sigma)


def b_matrix_inverse(sigma: Any) -> np.ndarray:
    """B(σ)⁻¹ = B(σ)ᵀ / (1 + σᵀσ)², shape (..., 3, 3)."""
    sigma = _sigma("sigma", sigma)
    scale = (1.0 + np.sum(sigma**2, axis=-1))[..., None, None] ** 2
    return np.swapaxes(b_matrix(sigma), -1, -2) / scale


def sigma_dot(sigma: Any, omega: Any) -> np.ndarray:
    """MRP kinematics σ̇ = ¼ B(σ) ω, with ω the body angular velocity in rad/s."""
    sigma = _sigma("sigma", sigma)
    omega = finite_array("omega", omega, (None, 3))
    sigma, omega = np.broadcast_arrays(sigma, omega)
    return _eval_mapped(_sigma_dot_function(), sigma, omega)[..., 0]


# --------------------------------------------------------------------- conversions
def to_quaternion(sigma: Any) -> np.ndarray:
    """Quaternion (scalar first) of σ, with β₀ >= 0 (the short-set rotation)."""
    sigma = short(_sigma("sigma", sigma))
    sq = np.sum(sigma**2, axis=-1, keepdims=True)
    return np.concatenate(((1.0 - sq) / (1.0 + sq), 2.0 * sigma / (1.0 + sq)), axis=-1)


def from_quaternion(quaternion: Any) -> np.ndarray:
    """Short-set σ of a quaternion (scalar first, any norm > 0; it is normalised)."""
    q = finite_array("quaternion", quaternion, (None, 4))
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(norm <= _ZERO_NORM):
        raise SpecificationError("quaternion: the zero quaternion does not describe an attitude")
    q = q / norm
    q = np.where(q[..., :1] < 0.0, -q, q)
    return q[..., 1:] / (1.0 + q[..., :1])


def to_dcm(sigma: Any) -> np.ndarray:
    """Direction cosine matrix [BN] = I + (8 [σ×]² − 4 (1 − σ²) [σ×]) / (1 + σ²)²."""
    sigma = _sigma("sigma", sigma)
    sq = np.sum(sigma**2, axis=-1)[..., None, None]
    s = skew(sigma)
    return np.eye(3) + (8.0 * s @ s - 4.0 * (1.0 - sq) * s) / (1.0 + sq) ** 2


def from_dcm(dcm: Any) -> np.ndarray:
    """Short-set σ of a direction cosine matrix [BN] (Shepperd's method through β).

    The matrix is checked to be a rotation to 1e-6 (orthogonal, determinant +1).
    """
    c = finite_array("dcm", dcm, (None, 3, 3))
    gram = np.swapaxes(c, -1, -2) @ c
    if np.any(np.abs(gram - np.eye(3)) > 1e-6) or np.any(np.linalg.det(c) < 0):
        raise SpecificationError("dcm must be a proper rotation matrix (C^T C = I, det C = +1) to 1e-6")
    trace = np.trace(c, axis1=-2, axis2=-1)
    squares = (
        np.stack(
            (
                1.0 + trace,
                1.0 + 2.0 * c[..., 0, 0] - trace,
                1.0 + 2.0 * c[..., 1, 1] - trace,
                1.0 + 2.0 * c[..., 2, 2] - trace,
            ),
            axis=-1,
        )
        / 4.0
    )
    pick = np.argmax(squares, axis=-1)
    # Products 4 β_i β_j from the symmetric and antisymmetric parts of [BN].
    p01 = c[..., 1, 2] - c[..., 2, 1]
    p02 = c[..., 2, 0] - c[..., 0, 2]
    p03 = c[..., 0, 1] - c[..., 1, 0]
    p12 = c[..., 0, 1] + c[..., 1, 0]
    p13 = c[..., 2, 0] + c[..., 0, 2]
    p23 = c[..., 1, 2] + c[..., 2, 1]
    products = np.stack(
        (
            np.stack((4 * squares[..., 0], p01, p02, p03), axis=-1),
            np.stack((p01, 4 * squares[..., 1], p12, p13), axis=-1),
            np.stack((p02, p12, 4 * squares[..., 2], p23), axis=-1),
            np.stack((p03, p13, p23, 4 * squares[..., 3]), axis=-1),
        ),
        axis=-2,
    )
    row = np.take_along_axis(products, pick[..., None, None], axis=-2)[..., 0, :]
    big = np.sqrt(np.take_along_axis(squares, pick[..., None], axis=-1))
    return from_quaternion(row / (4.0 * big))


def to_principal_rotation(sigma: Any) -> tuple[np.ndarray, np.ndarray]:
    """Principal axis ê (unit, shape (..., 3)) and angle Φ = 4 arctan|σ| in rad.

    σ is used as given (a long set gives Φ > π). At σ = 0 the axis is undefined and
    [1, 0, 0] is returned with Φ = 0.
    """
    sigma = _sigma("sigma", sigma)
    norm = np.linalg.norm(sigma, axis=-1, keepdims=True)
    zero = norm <= _ZERO_NORM
    axis = np.where(zero, np.array([1.0, 0.0, 0.0]), sigma / np.where(zero, 1.0, norm))
    return axis, 4.0 * np.arctan(norm[..., 0])


def from_principal_rotation(axis: Any, angle: Any) -> np.ndarray:
    """Short-set σ for a rotation of ``angle`` (rad) about ``axis`` (normalised here)."""
    axis = finite_array("axis", axis, (None, 3))
    angle = finite_array("angle", angle)
    norm = np.linalg.norm(axis, axis=-1, keepdims=True)
    if np.any(norm <= _ZERO_NORM):
        raise SpecificationError("axis must be a non-zero 3-vector")
    return from_rotation_vector((axis / norm) * angle[..., None])


def to_rotation_vector(sigma: Any) -> np.ndarray:
    """Rotation vector Φ ê (rad) of the short set of σ, so |result| <= π."""
    sigma = short(_sigma("sigma", sigma))
    norm = np.linalg.norm(sigma, axis=-1, keepdims=True)
    small = norm < 1e-4
    safe = np.where(small, 1.0, norm)
    sq = norm**2
    # 4 arctan(s)/s, with its Taylor series 4 (1 − s²/3 + s⁴/5) near s = 0.
    factor = np.where(small, 4.0 * (1.0 - sq / 3.0 + sq**2 / 5.0), 4.0 * np.arctan(norm) / safe)
    return factor * sigma


def from_rotation_vector(rotation_vector: Any) -> np.ndarray:
    """Short-set σ of a rotation vector Φ ê (rad)."""
    rv = finite_array("rotation_vector", rotation_vector, (None, 3))
    angle = np.linalg.norm(rv, axis=-1, keepdims=True)
    small = angle < 1e-4
    safe = np.where(small, 1.0, angle)
    sq = angle**2
    # tan(Φ/4)/Φ, with its Taylor series 1/4 + Φ²/192 + Φ⁴/7680 near Φ = 0.
    factor = np.where(small, 0.25 + sq / 192.0 + sq**2 / 7680.0, np.tan(angle / 4.0) / safe)
    # Angles with Φ/4 at an odd multiple of π/2 give tan = ±inf; reduce Φ into (−π, π] first.
    wrapped = np.abs(angle) > np.pi
    if np.any(wrapped):
        reduced = np.mod(angle + np.pi, 2.0 * np.pi) - np.pi
        factor = np.where(wrapped, np.tan(reduced / 4.0) / safe, factor)
    return short(factor * rv)


# --------------------------------------------------------------------- composition
def _quaternion_compose(second: np.ndarray, first: np.ndarray) -> np.ndarray:
    """β of [FN] = [FB][BN] from β' of [FB] (second) and β of [BN] (first)."""
    a0, a1, a2, a3 = np.moveaxis(second, -1, 0)
    b0, b1, b2, b3 = np.moveaxis(first, -1, 0)
    return np.stack(
        (
            a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
            a1 * b0 + a0 * b1 + a3 * b2 - a2 * b3,
            a2 * b0 - a3 * b1 + a0 * b2 + a1 * b3,
            a3 * b0 + a2 * b1 - a1 * b2 + a0 * b3,
        ),
        axis=-1,
    )


def add(sigma1: Any, sigma2: Any) -> np.ndarray:
    """Compose two attitudes: σ1 = σ(B/N), σ2 = σ(F/B) -> σ(F/N), short set.

    In DCMs: to_dcm(add(σ1, σ2)) = to_dcm(σ2) @ to_dcm(σ1).
    """
    q1 = to_quaternion(_sigma("sigma1", sigma1))
    q2 = to_quaternion(_sigma("sigma2", sigma2))
    return from_quaternion(_quaternion_compose(q2, q1))


def subtract(sigma: Any, sigma1: Any) -> np.ndarray:
    """Relative attitude: σ = σ(F/N), σ1 = σ(B/N) -> σ(F/B), short set.

    It inverts [`add`][mrpctl.mrp.add]: add(σ1, subtract(σ, σ1)) is σ (as an attitude).
    """
    q = to_quaternion(_sigma("sigma", sigma))
    q1 = to_quaternion(_sigma("sigma1", sigma1))
    q1_inverse = q1 * np.array([1.0, -1.0, -1.0, -1.0])
    return from_quaternion(_quaternion_compose(q, q1_inverse))
