"""The attitude estimators as CasADi Functions (pure SX): an MEKF and an MRP-based EKF with shadow sets.

Both estimate the attitude and the gyro bias β (6 error states) from the gyro, sampled at the controller
period h, and the star tracker, whose measurement of time t_m arrives ℓ periods late (``design/estimation.md``).

MEKF (multiplicative EKF, Lefferts, Markley & Shuster)
    Global attitude q̂ (unit quaternion, scalar first, of [BN]) and β̂; error state δx = (δθ, Δβ), with
    C(q) = C(δθ) C(q̂). Propagation over one period on ω̂ = ω̃ − β̂ (held): q̂⁺ = q(ω̂ h) ⊗ q̂ and
    P⁺ = Φ P Φᵀ + Q with Crassidis' closed forms of Φ and Q. Update with the star tracker's attitude:
    the residual y is the rotation vector of C(q_m) C(q̂)ᵀ, H = [I 0], a Joseph-form update, then
    the reset q̂ ← q(δθ̂) ⊗ q̂, β̂ ← β̂ + Δβ̂.
MRP-EKF (additive EKF on the MRP σ, Karlgaard & Schaub)
    State (σ̂, β̂). Propagation σ̂⁺ = σ̂ ⊕ σ(ω̂ h) (exact for a held rate) and P⁺ = Φ P Φᵀ + Q with
    Φ = I + F h + F² h²/2, F = [[A, −¼B(σ̂)], [0, 0]], A = ½(σ̂ω̂ᵀ − ω̂σ̂ᵀ − [ω̂×] + σ̂ᵀω̂ I), and
    Q = T Q_MEKF Tᵀ, T = diag(¼B(σ̂), I). Update with the measured MRP in the set nearer σ̂, R_σ = B R Bᵀ/16.
    After each propagation and each update, σ̂ switches to its shadow σ̂ˢ = −σ̂/|σ̂|² when |σ̂| > 1, and
    the covariance is mapped with the switching map's Jacobian S = (2σ̂σ̂ᵀ − |σ̂|² I)/|σ̂|⁴:
    P ← M P Mᵀ, M = diag(S, I) (Karlgaard & Schaub's shadow-set covariance mapping).

The gyro is rate-integrating: its reading ω̃_k, delivered at sample k, is the mean rate over the period
[t_{k−1}, t_k] (the attitude increment over h), and it propagates the estimate over that period.

The delayed update by buffered re-propagation (one ``sample`` per controller period): the filter's memory is
its posterior at t_{k−ℓ−1} and the ring of the ℓ gyro readings ω̃_{k−ℓ} … ω̃_{k−1}. At sample k the memory is
propagated by ω̃_{k−ℓ} to t_{k−ℓ}, updated by the measurement of t_{k−ℓ} that arrives now (the next memory),
then replayed over ω̃_{k−ℓ+1} … ω̃_k to t_k: the estimate now. It is the estimate a filter with the
measurement on time would hold, replayed forward.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field, fields
from typing import Any

import casadi as ca
import numpy as np

from mrpctl._validation import finite_array, integer, positive_scalar, readonly
from mrpctl.errors import SpecificationError
from mrpctl.estimation.sensors import Gyro, SensorClock, StarTracker
from mrpctl.flight import compose_mrp_expr, quaternion_from_mrp_expr, rotation_vector_to_mrp_expr
from mrpctl.mrp import b_matrix_expr, skew_expr

__all__ = [
    "COVARIANCE_SIZE",
    "Estimator",
    "EstimatorFunctions",
    "EstimatorKind",
    "EstimatorTuning",
    "estimator_functions",
    "farrenkopf_steady_state",
    "relative_rotation_expr",
    "shadow_jacobian_expr",
]

#: The 6 × 6 covariance, stored column-major.
COVARIANCE_SIZE = 36
#: Below this rotation per period φ = |ω̂| h the Φ coefficients are their Taylor series.
_SERIES_ANGLE = 0.1
_SMALL_MRP = 1e-4


class EstimatorKind(enum.Enum):
    """Which estimator: the multiplicative EKF on a quaternion, or the additive EKF on the MRP."""

    MEKF = "mekf"
    MRP_EKF = "mrp_ekf"


def farrenkopf_steady_state(gyro: Gyro, noise: float, period: float) -> np.ndarray:
    """Farrenkopf's single-axis steady state: the post-update covariance [[P_θθ, P_θβ], [P_θβ, P_ββ]].

    The fixed point of the single-axis Riccati recursion with updates of noise variance ``noise``² (rad²)
    every ``period`` s (the star tracker's), Φ = [[1, −T], [0, 1]] and the gyro's Q over T: the steady
    state Farrenkopf solved in closed form, reached here by doubling the recursion until it stops moving.
    """
    t = float(period)
    r = float(noise) ** 2
    sv2, su2 = gyro.rate_noise**2, gyro.bias_walk**2
    phi = np.array([[1.0, -t], [0.0, 1.0]])
    q = np.array([[sv2 * t + su2 * t**3 / 3.0, -su2 * t**2 / 2.0], [-su2 * t**2 / 2.0, su2 * t]])
    # the information form of the Riccati map P⁻ -> P⁻ is iterated by structure-preserving doubling
    a, g, h = phi.T.copy(), np.array([[1.0 / r, 0.0], [0.0, 0.0]]), q.copy()
    for _ in range(200):
        inverse = np.linalg.inv(np.eye(2) + g @ h)
        a_next = a @ inverse @ a
        g_next = g + a @ inverse @ g @ a.T
        h_next = h + a.T @ h @ inverse @ a
        done = np.allclose(h_next, h, rtol=1e-15, atol=0.0)
        a, g, h = a_next, g_next, h_next
        if done:
            break
    prior = 0.5 * (h + h.T)
    gain = prior[:, :1] / (prior[0, 0] + r)
    post = prior - gain @ prior[:1, :]
    return 0.5 * (post + post.T)


@dataclass(frozen=True)
class EstimatorTuning:
    """The noise parameters the filter is built with (by default those of the sensors).

    Parameters
    ----------
    rate_noise, bias_walk : float
        σ_v (rad/√s) and σ_u (rad/s^{3/2}) of the process noise.
    measurement_covariance : array_like
        R (3, 3), rad², symmetric positive definite: the star tracker's attitude error covariance.
    initial_covariance : array_like
        P₀ (6, 6), symmetric positive definite, on (δθ, Δβ) (rad², rad²/s): for the MRP-EKF it is mapped to
        (δσ, Δβ) at the initial estimate.
    """

    rate_noise: float
    bias_walk: float
    measurement_covariance: Any
    initial_covariance: Any

    def __post_init__(self) -> None:
        object.__setattr__(self, "rate_noise", positive_scalar("rate_noise", self.rate_noise))
        object.__setattr__(self, "bias_walk", positive_scalar("bias_walk", self.bias_walk))
        object.__setattr__(
            self, "measurement_covariance", _spd("measurement_covariance", self.measurement_covariance, 3)
        )
        object.__setattr__(self, "initial_covariance", _spd("initial_covariance", self.initial_covariance, 6))

    @classmethod
    def from_sensors(
        cls,
        star_tracker: StarTracker,
        gyro: Gyro,
        *,
        attitude_error: float | None = None,
        bias_error: float | None = None,
    ) -> EstimatorTuning:
        """Q and R of the sensors, P₀ the Farrenkopf steady state of each axis at the tracker's rate.

        ``attitude_error`` (rad) and ``bias_error`` (rad/s), when given, are the 1σ of the initial estimate's
        errors about each axis: P₀ is then diagonal with them (a filter started far from its steady state).
        """
        p0 = np.zeros((6, 6))
        for axis in range(3):
            steady = farrenkopf_steady_state(
                gyro, math.sqrt(star_tracker.covariance[axis, axis]), 1.0 / star_tracker.rate
            )
            p0[np.ix_([axis, axis + 3], [axis, axis + 3])] = steady
        if attitude_error is not None or bias_error is not None:
            diagonal = np.diag(p0).copy()
            if attitude_error is not None:
                diagonal[0:3] = positive_scalar("attitude_error", attitude_error) ** 2
            if bias_error is not None:
                diagonal[3:6] = positive_scalar("bias_error", bias_error) ** 2
            p0 = np.diag(diagonal)
        return cls(gyro.rate_noise, gyro.bias_walk, star_tracker.covariance, p0)


def _spd(name: str, value: Any, size: int) -> np.ndarray:
    matrix = finite_array(name, value, (size, size))
    if not np.allclose(matrix, matrix.T, rtol=1e-12, atol=0.0):
        raise SpecificationError(f"{name} must be symmetric, got {matrix}")
    matrix = 0.5 * (matrix + matrix.T)
    try:
        np.linalg.cholesky(matrix)
    except np.linalg.LinAlgError:
        eigenvalues = np.linalg.eigvalsh(matrix)
        raise SpecificationError(f"{name} must be positive definite (eigenvalues {eigenvalues})") from None
    return readonly(matrix)


# ------------------------------------------------------------------------------- SX building blocks
def _quaternion_product(a: Any, b: Any) -> Any:
    """β of C(a) C(b) (scalar first; a = β(F/B), b = β(B/N))."""
    return ca.vertcat(a[0] * b[0] - ca.dot(a[1:4], b[1:4]), a[0] * b[1:4] + b[0] * a[1:4] - ca.cross(a[1:4], b[1:4]))


def _rotation_quaternion(theta: Any) -> Any:
    """β of the rotation by the vector θ (rad): (cos(φ/2), sin(φ/2) θ/φ), with the series near φ = 0."""
    squared = ca.dot(theta, theta)
    angle = ca.sqrt(squared)
    small = angle < _SMALL_MRP
    safe = ca.if_else(small, 1.0, angle)
    factor = ca.if_else(small, 0.5 - squared / 48.0 + squared**2 / 3840.0, ca.sin(safe / 2.0) / safe)
    return ca.vertcat(ca.cos(angle / 2.0), factor * theta)


def _rotation_vector_of_quaternion(q: Any) -> Any:
    """The rotation vector of a unit quaternion (either sign): 4 arctan(s)/s σ of its short MRP σ, s = |σ|."""
    sign = ca.if_else(q[0] >= 0, 1.0, -1.0)
    sigma = sign * q[1:4] / (1 + sign * q[0])
    squared = ca.dot(sigma, sigma)
    norm = ca.sqrt(squared)
    small = norm < _SMALL_MRP
    safe = ca.if_else(small, 1.0, norm)
    factor = ca.if_else(small, 4.0 * (1.0 - squared / 3.0 + squared**2 / 5.0), 4.0 * ca.atan(safe) / safe)
    return factor * sigma


def _inverse3(m: Any) -> Any:
    """The inverse of a 3 × 3 SX matrix by its adjugate."""
    cofactor = ca.vertcat(
        ca.horzcat(
            m[1, 1] * m[2, 2] - m[1, 2] * m[2, 1],
            m[0, 2] * m[2, 1] - m[0, 1] * m[2, 2],
            m[0, 1] * m[1, 2] - m[0, 2] * m[1, 1],
        ),
        ca.horzcat(
            m[1, 2] * m[2, 0] - m[1, 0] * m[2, 2],
            m[0, 0] * m[2, 2] - m[0, 2] * m[2, 0],
            m[0, 2] * m[1, 0] - m[0, 0] * m[1, 2],
        ),
        ca.horzcat(
            m[1, 0] * m[2, 1] - m[1, 1] * m[2, 0],
            m[0, 1] * m[2, 0] - m[0, 0] * m[2, 1],
            m[0, 0] * m[1, 1] - m[0, 1] * m[1, 0],
        ),
    )
    determinant = m[0, 0] * cofactor[0, 0] + m[0, 1] * cofactor[1, 0] + m[0, 2] * cofactor[2, 0]
    return cofactor / determinant


def _block_propagation(f: Any, g: Any, p: Any, q: Any) -> Any:
    """Φ P Φᵀ + Q for Φ = [[F, G], [0, I]] and a symmetric P = [[A, B], [Bᵀ, C]], by blocks:
    [[M Fᵀ + N Gᵀ, N], [Nᵀ, C]] + Q with M = F A + G Bᵀ, N = F B + G C. Only the upper triangle of M Fᵀ + N Gᵀ
    is formed (the result is symmetric by construction, so it needs no symmetrising): a third of the
    arithmetic of the full products."""
    a, b, c = p[0:3, 0:3], p[0:3, 3:6], p[3:6, 3:6]
    m = f @ a + g @ b.T
    n = f @ b + g @ c
    top = _upper(m, f) + _upper(n, g)
    return ca.vertcat(ca.horzcat(top, n), ca.horzcat(n.T, c)) + q


def _upper(x: Any, y: Any) -> Any:
    """The upper triangle of x yᵀ (3 × 3 blocks), mirrored: x yᵀ where it, or the sum it enters, is symmetric
    (mirroring is linear, so the sum of mirrored terms is the mirrored sum)."""
    out = ca.SX(3, 3)
    for i in range(3):
        for j in range(i, 3):
            out[i, j] = ca.dot(x[i, :], y[j, :])
            if j != i:
                out[j, i] = out[i, j]
    return out


def _block_joseph(p: Any, gain: Any, r: Any) -> Any:
    """The Joseph form (I − K H) P (I − K H)ᵀ + K R Kᵀ for H = [I 0] and a symmetric P = [[A, B], [Bᵀ, C]], by
    blocks (K = [K₁; K₂], L = I − K₁): the same terms as the 6 × 6 products, without their zero and identity
    blocks, and the two diagonal blocks formed on their upper triangle (symmetric by construction)::

        [[L A Lᵀ + K₁ R K₁ᵀ,  L B − L A K₂ᵀ + K₁ R K₂ᵀ], [·ᵀ,  C − K₂ B − Bᵀ K₂ᵀ + K₂ A K₂ᵀ + K₂ R K₂ᵀ]]
    """
    a, b, c = p[0:3, 0:3], p[0:3, 3:6], p[3:6, 3:6]
    k1, k2 = gain[0:3, :], gain[3:6, :]
    ell = ca.DM.eye(3) - k1
    la, k1r, k2a = ell @ a, k1 @ r, k2 @ a
    top = _upper(la, ell) + _upper(k1r, k1)
    cross = ell @ b - la @ k2.T + k1r @ k2.T
    k2b = k2 @ b
    bottom = c - k2b - k2b.T + _upper(k2a, k2) + _upper(k2 @ r, k2)
    return ca.vertcat(ca.horzcat(top, cross), ca.horzcat(cross.T, bottom))


def _phi_coefficients(omega: Any, h: float) -> tuple[Any, Any, Any]:
    """(sin φ/|ω|, (1 − cos φ)/|ω|², (φ − sin φ)/|ω|³), φ = |ω| h, with their series below φ = 0.1."""
    squared = ca.dot(omega, omega)
    norm = ca.sqrt(squared)
    x = squared * h * h  # φ²
    series = ca.if_else(norm * h < _SERIES_ANGLE, 1.0, 0.0)
    safe = ca.if_else(series, 1.0, norm)
    angle = safe * h
    a = ca.if_else(series, h * (1 - x / 6 * (1 - x / 20 * (1 - x / 42 * (1 - x / 72)))), ca.sin(angle) / safe)
    b = ca.if_else(
        series, h * h * (0.5 - x / 24 * (1 - x / 30 * (1 - x / 56 * (1 - x / 90)))), (1 - ca.cos(angle)) / safe**2
    )
    c = ca.if_else(
        series,
        h**3 * (1.0 / 6 - x / 120 * (1 - x / 42 * (1 - x / 72 * (1 - x / 110)))),
        (angle - ca.sin(angle)) / safe**3,
    )
    return a, b, c


def _process_noise(tuning: EstimatorTuning, h: float) -> np.ndarray:
    """Q over one period on (δθ, Δβ) (Crassidis & Junkins)."""
    sv2, su2 = tuning.rate_noise**2, tuning.bias_walk**2
    eye = np.eye(3)
    return np.block(
        [[(sv2 * h + su2 * h**3 / 3) * eye, -(su2 * h**2 / 2) * eye], [-(su2 * h**2 / 2) * eye, su2 * h * eye]]
    )


def relative_rotation_expr(sigma_from: Any, sigma_to: Any) -> Any:
    """The rotation vector (rad) of C(σ_to) C(σ_from)ᵀ: the body's rotation from one attitude to the next (SX)."""
    q_from = quaternion_from_mrp_expr(sigma_from)
    return _rotation_vector_of_quaternion(
        _quaternion_product(quaternion_from_mrp_expr(sigma_to), ca.vertcat(q_from[0], -q_from[1:4]))
    )


def shadow_jacobian_expr(sigma: Any) -> Any:
    """S = ∂σˢ/∂σ = (2 σσᵀ − |σ|² I)/|σ|⁴ of the shadow map σˢ = −σ/|σ|² (SX; σ ≠ 0)."""
    squared = ca.dot(sigma, sigma)
    return (2 * (sigma @ sigma.T) - squared * ca.DM.eye(3)) / (squared * squared)


def _switch(sigma: Any, p: Any) -> tuple[Any, Any, Any]:
    """(σ, P, switched): the shadow set and the mapped covariance when |σ| > 1."""
    squared = ca.dot(sigma, sigma)
    long_set = squared > 1
    safe = ca.if_else(long_set, squared, 1.0)
    s = (2 * (sigma @ sigma.T) - safe * ca.DM.eye(3)) / (safe * safe)
    # M P Mᵀ for M = diag(S, I), by blocks: [[S A Sᵀ, S B], [Bᵀ Sᵀ, C]]
    a, b, c = p[0:3, 0:3], p[0:3, 3:6], p[3:6, 3:6]
    sb = s @ b
    mapped = ca.vertcat(ca.horzcat(_upper(s @ a, s), sb), ca.horzcat(sb.T, c))
    return (
        ca.if_else(long_set, -sigma / safe, sigma),
        ca.if_else(long_set, mapped, p),
        ca.if_else(long_set, 1.0, 0.0),
    )


# ------------------------------------------------------------------------------- the two filters
def _mekf_propagate(attitude: Any, bias: Any, p: Any, gyro: Any, h: float, q: np.ndarray) -> tuple[Any, Any]:
    omega = gyro - bias
    attitude_next = _quaternion_product(_rotation_quaternion(omega * h), attitude)
    attitude_next = attitude_next / ca.norm_2(attitude_next)
    if p is None:
        return attitude_next, None
    a, b, c = _phi_coefficients(omega, h)
    w = skew_expr(omega)
    w2 = w @ w
    phi11 = ca.DM.eye(3) - a * w + b * w2
    phi12 = b * w - h * ca.DM.eye(3) - c * w2
    return attitude_next, _block_propagation(phi11, phi12, p, ca.DM(q))


def _mekf_update(attitude: Any, bias: Any, p: Any, measured: Any, r: np.ndarray) -> tuple[Any, Any, Any, Any]:
    q_m = quaternion_from_mrp_expr(measured)
    conjugate = ca.vertcat(attitude[0], -attitude[1:4])
    y = _rotation_vector_of_quaternion(_quaternion_product(q_m, conjugate))
    innovation_covariance = p[0:3, 0:3] + ca.DM(r)
    gain = p[:, 0:3] @ _inverse3(innovation_covariance)
    p_next = _block_joseph(p, gain, ca.DM(r))
    dx = gain @ y
    attitude_next = _quaternion_product(_rotation_quaternion(dx[0:3]), attitude)
    attitude_next = attitude_next / ca.norm_2(attitude_next)
    return attitude_next, bias + dx[3:6], p_next, y


def _mrp_propagate(sigma: Any, bias: Any, p: Any, gyro: Any, h: float, q: np.ndarray) -> tuple[Any, Any]:
    omega = gyro - bias
    sigma_next = compose_mrp_expr(sigma, rotation_vector_to_mrp_expr(omega * h))
    if p is None:
        squared = ca.dot(sigma_next, sigma_next)
        return ca.if_else(squared > 1, -sigma_next / ca.if_else(squared > 1, squared, 1.0), sigma_next), None
    quarter_b = b_matrix_expr(sigma) / 4
    a_block = 0.5 * (sigma @ omega.T - omega @ sigma.T - skew_expr(omega) + ca.dot(sigma, omega) * ca.DM.eye(3))
    # Φ = I + F h + F² h²/2 for F = [[A, −¼B], [0, 0]]: F² = [[A², −A ¼B], [0, 0]]
    phi11 = ca.DM.eye(3) + a_block * h + (a_block @ a_block) * (h * h / 2)
    phi12 = -quarter_b * h - (a_block @ quarter_b) * (h * h / 2)
    # T Q Tᵀ for T = diag(¼B, I) and Q's blocks q_ij I
    q11, q12, q22 = q[0, 0], q[0, 3], q[3, 3]
    cross = q12 * quarter_b
    noise = ca.vertcat(ca.horzcat(q11 * _upper(quarter_b, quarter_b), cross), ca.horzcat(cross.T, q22 * ca.DM.eye(3)))
    p_next = _block_propagation(phi11, phi12, p, noise)
    sigma_next, p_next, _ = _switch(sigma_next, p_next)
    return sigma_next, p_next


def _mrp_update(sigma: Any, bias: Any, p: Any, measured: Any, r: np.ndarray) -> tuple[Any, Any, Any, Any]:
    squared = ca.dot(measured, measured)
    shadow = -measured / ca.if_else(squared > 0, squared, 1.0)
    nearer = ca.logic_and(squared > 0, ca.norm_2(shadow - sigma) < ca.norm_2(measured - sigma))
    y = ca.if_else(nearer, shadow, measured) - sigma
    b = b_matrix_expr(sigma)
    r_sigma = b @ ca.DM(r) @ b.T / 16
    gain = p[:, 0:3] @ _inverse3(p[0:3, 0:3] + r_sigma)
    p_next = _block_joseph(p, gain, r_sigma)
    dx = gain @ y
    sigma_next, p_next, _ = _switch(sigma + dx[0:3], p_next)
    return sigma_next, bias + dx[3:6], p_next, y


@dataclass(frozen=True, eq=False)
class EstimatorFunctions:
    """One estimator as CasADi Functions, with its clock and tuning.

    Attributes
    ----------
    kind : EstimatorKind
    clock : SensorClock
        The star tracker on the controller's clock (n, ℓ, h).
    tuning : EstimatorTuning
    attitude_size : int
        4 (quaternion) for the MEKF, 3 (MRP) for the MRP-EKF.
    state_size : int
        The filter state (attitude, β̂, P column-major).
    propagate : casadi.Function
        ``propagate(state, gyro) -> state_next``: one period on the gyro sample.
    update : casadi.Function
        ``update(state, measurement, available) -> (state_next, innovation)``: the star tracker's MRP;
        with ``available`` = 0 the state is returned unchanged.
    sample : casadi.Function
        ``sample(state, ring, gyro, measurement, available) -> (state_next, ring_next, sigma, omega, bias,
        covariance, innovation)``: one controller period with the delayed update and the replay; ``state`` the
        posterior at t_{k−ℓ−1}, ``ring`` the readings ω̃_{k−ℓ} … ω̃_{k−1} (3 × ℓ, left out when ℓ = 0), ``gyro``
        ω̃_k, ``sigma`` the short-set MRP of the estimate now, ``omega`` = ω̃_k − β̂, ``covariance`` the
        covariance now (replayed; 36, column-major).
    """

    kind: EstimatorKind
    clock: SensorClock
    tuning: EstimatorTuning
    attitude_size: int
    state_size: int
    propagate: ca.Function = field(repr=False)
    update: ca.Function = field(repr=False)
    sample: ca.Function = field(repr=False)

    def initial_state(self, sigma: Any, bias: Any) -> np.ndarray:
        """The filter state of the estimate (σ̂₀, β̂₀) with the tuning's P₀ (mapped to δσ for the MRP-EKF)."""
        sigma = finite_array("sigma", sigma, (3,))
        bias = finite_array("bias", bias, (3,))
        squared = float(sigma @ sigma)
        if squared > 1.0:
            sigma = -sigma / squared
            squared = 1.0 / squared
        p0 = np.array(self.tuning.initial_covariance)
        if self.kind is EstimatorKind.MEKF:
            attitude = np.concatenate((((1 - squared) / (1 + squared),), 2 * sigma / (1 + squared)))
        else:
            attitude = sigma
            skew = np.array([[0, -sigma[2], sigma[1]], [sigma[2], 0, -sigma[0]], [-sigma[1], sigma[0], 0]])
            b = (1 - squared) * np.eye(3) + 2 * skew + 2 * np.outer(sigma, sigma)
            t = np.block([[b / 4, np.zeros((3, 3))], [np.zeros((3, 3)), np.eye(3)]])
            p0 = t @ p0 @ t.T
            p0 = 0.5 * (p0 + p0.T)
        return np.concatenate((attitude, bias, p0.reshape(-1, order="F")))


def estimator_functions(
    kind: EstimatorKind | str,
    star_tracker: StarTracker,
    gyro: Gyro,
    controller_rate: float,
    *,
    tuning: EstimatorTuning | None = None,
    buffer: int | None = None,
    covariance_now: bool = True,
) -> EstimatorFunctions:
    """Build the estimator ``kind`` for the sensors on the controller's clock.

    Parameters
    ----------
    kind : EstimatorKind or str
        ``"mekf"`` or ``"mrp_ekf"``.
    star_tracker, gyro : StarTracker, Gyro
    controller_rate : float
        The controller's (and the gyro's) rate (Hz).
    tuning : EstimatorTuning, optional, keyword-only
        Default [`EstimatorTuning.from_sensors`][mrpctl.estimation.EstimatorTuning.from_sensors].
    buffer : int, optional, keyword-only
        The gyro buffer's length (samples), at least the latency; default the latency itself.
    covariance_now : bool, keyword-only
        True (default): the sample's ``covariance`` is the covariance now, replayed with the estimate (ℓ
        covariance propagations more a sample). False: the replay carries the estimate only, and
        ``covariance`` is the posterior's at the measurement time t_{k−ℓ} (in the posterior's MRP set for the
        MRP-EKF); the estimate is the same.
    """
    try:
        kind = EstimatorKind(kind)
    except ValueError:
        raise SpecificationError(f"kind: one of 'mekf', 'mrp_ekf', got {kind!r}") from None
    if not isinstance(star_tracker, StarTracker):
        raise SpecificationError(f"star_tracker must be a StarTracker, got {type(star_tracker).__name__}")
    if not isinstance(gyro, Gyro):
        raise SpecificationError(f"gyro must be a Gyro, got {type(gyro).__name__}")
    clock = star_tracker.clock(controller_rate, buffer=buffer)
    if buffer is not None:
        integer("buffer", buffer, minimum=0)
    tuning = EstimatorTuning.from_sensors(star_tracker, gyro) if tuning is None else tuning
    if not isinstance(tuning, EstimatorTuning):
        raise SpecificationError(f"tuning must be an EstimatorTuning, got {type(tuning).__name__}")
    h = clock.period
    q = _process_noise(tuning, h)
    r = np.array(tuning.measurement_covariance)
    size = 4 if kind is EstimatorKind.MEKF else 3
    prop, upd = (_mekf_propagate, _mekf_update) if kind is EstimatorKind.MEKF else (_mrp_propagate, _mrp_update)

    def unpack(state: Any) -> tuple[Any, Any, Any]:
        return state[0:size], state[size : size + 3], ca.reshape(state[size + 3 :], 6, 6)

    def pack(attitude: Any, bias: Any, p: Any) -> Any:
        return ca.vertcat(attitude, bias, ca.reshape(p, COVARIANCE_SIZE, 1))

    state = ca.SX.sym("state", size + 3 + COVARIANCE_SIZE)
    gyro_now = ca.SX.sym("gyro", 3)
    measurement = ca.SX.sym("measurement", 3)
    available = ca.SX.sym("available")

    attitude, bias, p = unpack(state)
    propagated_attitude, propagated_p = prop(attitude, bias, p, gyro_now, h, q)
    propagated = pack(propagated_attitude, bias, propagated_p)
    propagate = ca.Function("propagate", [state, gyro_now], [propagated], ["state", "gyro"], ["state_next"])

    updated_attitude, updated_bias, updated_p, innovation = upd(attitude, bias, p, measurement, r)
    on = available > 0.5
    updated = ca.if_else(on, pack(updated_attitude, updated_bias, updated_p), state)
    innovation = ca.if_else(on, innovation, ca.DM.zeros(3))
    update = ca.Function(
        "update",
        [state, measurement, available],
        [updated, innovation],
        ["state", "measurement", "available"],
        ["state_next", "innovation"],
    )

    latency = clock.latency
    ring = ca.SX.sym("ring", 3, latency)
    readings = [ring[:, j] for j in range(latency)] + [gyro_now]  # delivered at k − ℓ … k
    prior_attitude, prior_p = prop(attitude, bias, p, readings[0], h, q)
    posterior = update(pack(prior_attitude, bias, prior_p), measurement, available)
    state_next = posterior[0]
    now_attitude, now_bias, now_p = unpack(state_next)
    for reading in readings[1:]:
        now_attitude, replayed = prop(now_attitude, now_bias, now_p if covariance_now else None, reading, h, q)
        now_p = replayed if covariance_now else now_p
    if kind is EstimatorKind.MEKF:
        sign = ca.if_else(now_attitude[0] >= 0, 1.0, -1.0)
        sigma_now = sign * now_attitude[1:4] / (1 + sign * now_attitude[0])
    else:
        sigma_now = now_attitude
    inputs = [state] + ([ring] if latency else []) + [gyro_now, measurement, available]
    names = ["state"] + (["ring"] if latency else []) + ["gyro", "measurement", "available"]
    outputs = [state_next] + ([ca.horzcat(ring[:, 1:], gyro_now)] if latency else [])
    output_names = ["state_next"] + (["ring_next"] if latency else [])
    outputs += [sigma_now, gyro_now - now_bias, now_bias, ca.reshape(now_p, COVARIANCE_SIZE, 1), posterior[1]]
    output_names += ["sigma", "omega", "bias", "covariance", "innovation"]
    sample = ca.Function("estimator_sample", inputs, outputs, names, output_names)
    return EstimatorFunctions(
        kind=kind,
        clock=clock,
        tuning=tuning,
        attitude_size=size,
        state_size=size + 3 + COVARIANCE_SIZE,
        propagate=propagate,
        update=update,
        sample=sample,
    )


@dataclass(frozen=True)
class Estimator:
    """The estimator of an estimated loop (``simulate(..., sensors=..., estimator=...)``).

    Parameters
    ----------
    kind : EstimatorKind or str
        ``"mekf"`` (default) or ``"mrp_ekf"``.
    tuning : EstimatorTuning, optional
        Default [`EstimatorTuning.from_sensors`][mrpctl.estimation.EstimatorTuning.from_sensors] with the
        initial errors below.
    initial_sigma : array_like, optional
        The initial attitude estimate σ̂₀ (the true σ₀ when None: an attitude known at the start).
    initial_bias : array_like
        The initial bias estimate β̂₀ (rad/s). Default zero.
    attitude_error, bias_error : float, optional
        1σ of the initial errors (rad, rad/s) for the default tuning; None: Farrenkopf's steady state.
    covariance_now : bool
        Record the covariance now (True, default) or at the measurement time (False: a cheaper sample, see
        [`estimator_functions`][mrpctl.estimation.estimator_functions]).
    """

    kind: EstimatorKind | str = EstimatorKind.MEKF
    tuning: EstimatorTuning | None = None
    initial_sigma: Any = None
    initial_bias: Any = (0.0, 0.0, 0.0)
    attitude_error: float | None = None
    bias_error: float | None = None
    covariance_now: bool = True

    def __post_init__(self) -> None:
        if not isinstance(self.covariance_now, bool):
            raise SpecificationError(f"covariance_now must be True or False, got {self.covariance_now!r}")
        try:
            object.__setattr__(self, "kind", EstimatorKind(self.kind))
        except ValueError:
            raise SpecificationError(f"kind: one of 'mekf', 'mrp_ekf', got {self.kind!r}") from None
        if self.tuning is not None and not isinstance(self.tuning, EstimatorTuning):
            raise SpecificationError(f"tuning must be an EstimatorTuning, got {type(self.tuning).__name__}")
        if self.initial_sigma is not None:
            object.__setattr__(self, "initial_sigma", readonly(finite_array("initial_sigma", self.initial_sigma, (3,))))
        object.__setattr__(self, "initial_bias", readonly(finite_array("initial_bias", self.initial_bias, (3,))))
        for name in ("attitude_error", "bias_error"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, positive_scalar(name, value))

    def functions(self, star_tracker: StarTracker, gyro: Gyro, controller_rate: float) -> EstimatorFunctions:
        """The estimator's Functions for these sensors at the controller rate."""
        tuning = self.tuning
        if tuning is None:
            tuning = EstimatorTuning.from_sensors(
                star_tracker, gyro, attitude_error=self.attitude_error, bias_error=self.bias_error
            )
        key = (
            self.kind,
            _value_key(star_tracker),
            _value_key(gyro),
            float(controller_rate),
            tuning.rate_noise,
            tuning.bias_walk,
            np.asarray(tuning.measurement_covariance).tobytes(),
            np.asarray(tuning.initial_covariance).tobytes(),
            self.covariance_now,
        )
        found = _FUNCTIONS.get(key)
        if found is None:
            found = estimator_functions(
                self.kind, star_tracker, gyro, controller_rate, tuning=tuning, covariance_now=self.covariance_now
            )
            if len(_FUNCTIONS) >= 16:
                _FUNCTIONS.pop(next(iter(_FUNCTIONS)))
            _FUNCTIONS[key] = found
        return found


def _value_key(value: Any) -> tuple[Any, ...]:
    """A dataclass value's fields, exactly (arrays by their bytes)."""
    return tuple(
        None if getattr(value, f.name) is None else np.asarray(getattr(value, f.name), dtype=float).tobytes()
        for f in fields(value)
    )


#: Built estimators by (kind, sensors, rate, tuning): the same Functions (and so the same compiled run) again.
_FUNCTIONS: dict[tuple[Any, ...], EstimatorFunctions] = {}
