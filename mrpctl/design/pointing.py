"""How well the delayed loop points: the H₂ norm (delay Lyapunov matrix), pointing budgets in arcsec and
H∞-optimal PD synthesis on the exact norm, certified by the bounded-real LMI
([`mrpctl.design.performance`][mrpctl.design.performance] has the margins and the H∞ norms; the methods and the
measured tables are in ``design/performance.md``)."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg
from scipy.optimize import minimize

from mrpctl._validation import finite_array, integer, positive_scalar, readonly
from mrpctl.design._common import real_matrix
from mrpctl.design.performance import HinfBound, HinfNorm, hinf_bound, hinf_norm
from mrpctl.design.spectra import characteristic_roots, delay_system
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.model import gain_matrix, plant_model
from mrpctl.spacecraft import Spacecraft, check_spacecraft

__all__ = [
    "ARCSEC",
    "H2Norm",
    "HinfPDSynthesis",
    "PointingBudget",
    "delay_lyapunov",
    "h2_norm",
    "pointing_budget",
    "synthesize_hinf_pd",
    "torque_to_attitude",
]

#: Arcseconds per radian.
ARCSEC = 180.0 / math.pi * 3600.0


# ------------------------------------------------------------------------------ H2 and pointing
@dataclass(frozen=True, eq=False)
class H2Norm:
    """Result of [`h2_norm`][mrpctl.design.pointing.h2_norm].

    Attributes
    ----------
    value : float
        ‖T‖₂ = (tr Bᵀ U(0) B)^{1/2}; ``math.inf`` when the system is not exponentially stable.
    lyapunov : numpy.ndarray or None
        U(0) = ∫₀^∞ Φ(t)ᵀ CᵀC Φ(t) dt, Φ the fundamental matrix (None when unstable).
    residual : float
        Relative residual of the delay Lyapunov equations at the solution.
    stable : bool
    time : float
    reason : str
    """

    value: float
    lyapunov: np.ndarray | None = field(repr=False)
    residual: float
    stable: bool
    time: float
    reason: str

    def __str__(self) -> str:
        if not self.stable:
            return f"H2 norm infinite: {self.reason}"
        return (
            f"H2 norm {self.value:.10g} (delay Lyapunov matrix, residual {self.residual:.1e}, {1e3 * self.time:.1f} ms)"
        )


def delay_lyapunov(a0: np.ndarray, a1: np.ndarray, tau: float, w: np.ndarray) -> tuple[np.ndarray, float]:
    """U(0) of the delay Lyapunov matrix U(θ) = ∫₀^∞ Φ(t)ᵀ W Φ(t + θ) dt of ẋ = A₀x + A₁x(t − τ).

    On θ ∈ [0, τ], X(θ) = U(θ) and Y(θ) = U(θ − τ) solve X' = XA₀ + YA₁, Y' = −A₀ᵀY − A₁ᵀX
    (Kharitonov & Plischke 2006), with X(0) = Y(τ) and the algebraic condition
    X(0)A₀ + A₀ᵀX(0) + Y(0)A₁ + A₁ᵀY(0)ᵀ = −W; in vec form a matrix exponential of size 2n². With a
    singular A₀ or A₁ (the attitude loop has both) these 2n² equations can be rank deficient, so the
    symmetry conditions U(0) = U(0)ᵀ and U(−τ) = U(τ)ᵀ, which the solution satisfies, are added and
    the overdetermined system is solved by least squares; the answer is accepted only when it has
    full column rank and satisfies every equation.

    Returns
    -------
    (U(0), residual)
        The residual is ‖equations‖ / ‖W‖ at the solution.

    Raises
    ------
    ArithmeticError
        When the equations do not determine U(0) (a root pair λ, −λ: the system is not stable) or
        are not satisfied to 1e-8.
    """
    n = a0.shape[0]
    eye = np.eye(n)
    nn = n * n
    lop = np.block([[np.kron(a0.T, eye), np.kron(a1.T, eye)], [-np.kron(eye, a1.T), -np.kron(eye, a0.T)]])
    phi = scipy.linalg.expm(lop * tau)
    perm = np.zeros((nn, nn))
    for i in range(n):
        for j in range(n):
            perm[i * n + j, j * n + i] = 1.0  # vec(Yᵀ) = perm vec(Y), column-major
    rows = np.vstack(
        (
            np.hstack((phi[nn:, :nn] - np.eye(nn), phi[nn:, nn:])),  # Y(τ) = X(0)
            np.hstack((np.kron(a0.T, eye) + np.kron(eye, a0.T), np.kron(a1.T, eye) + np.kron(eye, a1.T) @ perm)),
            np.hstack((np.eye(nn) - perm, np.zeros((nn, nn)))),  # X(0) = X(0)ᵀ
            np.hstack((np.zeros((nn, nn)), np.eye(nn))) - perm @ phi[:nn, :],  # Y(0) = X(τ)ᵀ
        )
    )
    rhs = np.concatenate((np.zeros(nn), -w.flatten(order="F"), np.zeros(2 * nn)))
    singular = np.linalg.svd(rows, compute_uv=False)
    if singular[-1] <= 1e-12 * singular[0]:
        raise ArithmeticError("the delay Lyapunov equations do not determine U(0) (is the system stable?)")
    sol = np.linalg.lstsq(rows, rhs, rcond=None)[0]
    residual = float(np.linalg.norm(rows @ sol - rhs)) / max(float(np.linalg.norm(w)), 1e-300)
    if residual > 1e-8:
        raise ArithmeticError(f"the delay Lyapunov equations are not satisfied (relative residual {residual:.1e})")
    x0 = sol[:nn].reshape((n, n), order="F")
    return 0.5 * (x0 + x0.T), residual


def h2_norm(A: Any, A_d: Any, tau: Any, B: Any, C: Any) -> H2Norm:
    """Exact H₂ norm of ẋ = A x + A_d x(t − τ) + B w, z = C x (one delay), from the delay Lyapunov matrix.

    ‖T‖₂² = ∫₀^∞ ‖C Φ(t) B‖_F² dt = tr(Bᵀ U(0) B), U the delay Lyapunov matrix for W = CᵀC
    (Jarlebring, Vanbiervliet & Michiels 2011); for white noise w of intensity I it is the stationary
    E‖z‖². Unstable systems (certified spectral abscissa >= 0) give ``value = inf``.
    """
    start = time.perf_counter()
    system = delay_system(A, [A_d], [tau])
    b, c = real_matrix("B", B, rows=system.n), real_matrix("C", C, cols=system.n)
    spectrum = characteristic_roots(system.A0, list(system.A), list(system.tau), count=4)
    if not spectrum.certified:
        raise ArithmeticError(f"the stability of the system could not be certified:\n{spectrum}")
    if not spectrum.stable:
        return H2Norm(
            value=math.inf,
            lyapunov=None,
            residual=math.nan,
            stable=False,
            time=time.perf_counter() - start,
            reason=f"not exponentially stable (spectral abscissa {spectrum.abscissa:.6g} 1/s >= 0)",
        )
    u0, residual = delay_lyapunov(system.A0, system.A[0], system.tau[0], c.T @ c)
    value = float(np.trace(b.T @ u0 @ b))
    return H2Norm(
        value=math.sqrt(max(value, 0.0)),
        lyapunov=readonly(u0),
        residual=residual,
        stable=True,
        time=time.perf_counter() - start,
        reason="delay Lyapunov matrix",
    )


def torque_to_attitude(spacecraft: Spacecraft, K: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(A, A_d, B_w, C) of the linearised loop from a body torque w (N m) to the attitude angle 4σ (rad).

    ẋ = A x + B K x(t − τ) + B w with x = [σ; ω/4]; the small-angle rotation is θ = 4σ, so C = [4I, 0].
    """
    sc = check_spacecraft(spacecraft)
    plant = plant_model(sc)
    a, a_d = plant.closed_loop_matrices(gain_matrix(K))
    c = np.hstack((4.0 * np.eye(3), np.zeros((3, 3))))
    return np.array(a), np.array(a_d), np.array(plant.B), c


@dataclass(frozen=True, eq=False)
class PointingBudget:
    """Result of [`pointing_budget`][mrpctl.design.pointing.pointing_budget]: stationary pointing error.

    Attributes
    ----------
    covariance : numpy.ndarray
        (3, 3) covariance of the attitude error angle θ = 4σ (rad²).
    three_sigma : numpy.ndarray
        (3,) 3σ per body axis (arcsec).
    total_three_sigma : float
        3 (tr covariance)^{1/2} (arcsec): three times the RMS of the pointing error angle.
    contributions : dict of str to numpy.ndarray
        3σ per axis (arcsec) of each source alone ("torque", "attitude noise", "rate noise").
    residual : float
        Largest relative residual of the delay Lyapunov solves.
    time : float
    """

    covariance: np.ndarray = field(repr=False)
    three_sigma: np.ndarray = field(repr=False)
    total_three_sigma: float
    contributions: dict[str, np.ndarray] = field(repr=False)
    residual: float
    time: float

    def __str__(self) -> str:
        axes = ", ".join(f"{v:.4g}" for v in self.three_sigma)
        parts = "; ".join(f"{k} " + ", ".join(f"{v:.3g}" for v in vals) for k, vals in self.contributions.items())
        return f"pointing 3-sigma per axis {axes} arcsec, total {self.total_three_sigma:.4g} arcsec ({parts})"


def pointing_budget(
    spacecraft: Spacecraft,
    K: Any,
    tau: Any,
    *,
    torque_psd: Any = 0.0,
    attitude_noise: Any = 0.0,
    rate_noise: Any = 0.0,
) -> PointingBudget:
    """3σ pointing error of the delayed loop from white torque disturbance and white sensor noise.

    The linearised loop with measured state x + n: ẋ = A x + B K (x + n)(t − τ) + B d. All sources
    are white, given as one-sided densities (a one-sided PSD G corresponds to the intensity G/2 of
    E[d(t)d(s)ᵀ] = (G/2) δ(t − s)), independent per axis:

    * ``torque_psd``: PSD of the body torque d (N² m²/Hz), scalar or per axis;
    * ``attitude_noise``: amplitude spectral density of the attitude measurement error angle
      (rad/√Hz); on σ it is a quarter of that;
    * ``rate_noise``: amplitude spectral density of the rate measurement (rad/s/√Hz); on ω/4 a quarter.

    The stationary state covariance Σ = ∫ Φ(t) B_n Q B_nᵀ Φ(t)ᵀ dt is U(0) of the delay Lyapunov
    matrix of the transposed system (A₀ᵀ, A₁ᵀ) with W = B_n Q B_nᵀ (the delayed noise n(t − τ) is
    white with the same intensity); the attitude error is θ = 4σ.
    """
    start = time.perf_counter()
    a, a_d, b, _ = torque_to_attitude(spacecraft, K)
    tau = positive_scalar("tau", tau)
    k = gain_matrix(K)
    q_d = _per_axis_density("torque_psd", torque_psd) / 2.0
    q_att = (_per_axis_density("attitude_noise", attitude_noise) / 4.0) ** 2 / 2.0
    q_rate = (_per_axis_density("rate_noise", rate_noise) / 4.0) ** 2 / 2.0
    spectrum = characteristic_roots(a, a_d, tau, count=4)
    if not (spectrum.certified and spectrum.stable):
        raise SpecificationError(
            f"the loop is not exponentially stable at tau = {tau:g} s (spectral abscissa {spectrum.abscissa:.6g} 1/s): "
            "its pointing error grows without bound"
        )
    sources = {
        "torque": b @ np.diag(q_d) @ b.T,
        "attitude noise": (b @ k[:, :3]) @ np.diag(q_att) @ (b @ k[:, :3]).T,
        "rate noise": (b @ k[:, 3:]) @ np.diag(q_rate) @ (b @ k[:, 3:]).T,
    }
    total = np.zeros((3, 3))
    contributions = {}
    residual = 0.0
    for name, w in sources.items():
        if not np.any(w):
            contributions[name] = readonly(np.zeros(3))
            continue
        sigma_x, res = delay_lyapunov(a.T, a_d.T, tau, w)
        residual = max(residual, res)
        cov = 16.0 * sigma_x[:3, :3]
        total += cov
        contributions[name] = readonly(3.0 * np.sqrt(np.clip(np.diag(cov), 0.0, None)) * ARCSEC)
    return PointingBudget(
        covariance=readonly(total),
        three_sigma=readonly(3.0 * np.sqrt(np.clip(np.diag(total), 0.0, None)) * ARCSEC),
        total_three_sigma=float(3.0 * math.sqrt(max(float(np.trace(total)), 0.0)) * ARCSEC),
        contributions=contributions,
        residual=residual,
        time=time.perf_counter() - start,
    )


def _per_axis_density(name: str, value: Any) -> np.ndarray:
    array = finite_array(name, value)
    if array.ndim == 0:
        array = np.full(3, float(array))
    if array.shape != (3,):
        raise DimensionError(f"{name}: expected a scalar or shape (3,) but found {array.shape}")
    if np.any(array < 0.0):
        raise SpecificationError(f"{name} must be >= 0 (a spectral density), got {array}")
    return array


# ------------------------------------------------------------------------------ synthesis
@dataclass(frozen=True, eq=False)
class HinfPDSynthesis:
    """Result of [`synthesize_hinf_pd`][mrpctl.design.pointing.synthesize_hinf_pd].

    Attributes
    ----------
    K : numpy.ndarray
        (3, 6) gain [4J K₁, 4J K₂] with K₁ = −ωₙ² I, K₂ = −2ζωₙ I.
    omega_n, zeta : float
        The optimal natural frequency (rad/s) and damping of every axis.
    exact : HinfNorm
        Exact H∞ norm torque → attitude angle 4σ of the 6×6 loop at τ with K.
    certified : HinfBound
        The bounded-real LMI bound at K.
    evaluations : int
        Exact H∞ evaluations of the search.
    time : float
    """

    K: np.ndarray = field(repr=False)
    omega_n: float
    zeta: float
    exact: HinfNorm = field(repr=False)
    certified: HinfBound = field(repr=False)
    evaluations: int
    time: float

    def __str__(self) -> str:
        return (
            f"H-infinity-optimal PD at the delay: omega_n = {self.omega_n:.6g} rad/s, zeta = {self.zeta:.4g}; "
            f"exact {self.exact.value:.6g}, certified < {self.certified.value:.6g} rad/(N m)"
        )


_AXIS_A = np.array([[0.0, 1.0], [0.0, 0.0]])
_AXIS_B = np.array([[0.0], [1.0]])
_AXIS_C = np.array([[1.0, 0.0]])


def _axis_hinf(w: float, zeta: float) -> float:
    """H∞ of 1/(λ² + (2ζwλ + w²)e^{−λ}) (the normalised axis, unit delay); inf when unstable."""
    a_d = np.array([[0.0, 0.0], [-w * w, -2.0 * zeta * w]])
    return hinf_norm(_AXIS_A, a_d, 1.0, _AXIS_B, _AXIS_C, rtol=1e-9).value


def synthesize_hinf_pd(spacecraft: Spacecraft, tau: Any, *, starts: int = 3, order: int = 2) -> HinfPDSynthesis:
    """Decoupled PD gains minimising the exact H∞ norm from body torque to attitude angle at the delay τ.

    Per axis θ̈ = d/J + (K₁θ + K₂θ̇)(t − τ) in small angles; with K₁ = −ωₙ², K₂ = −2ζωₙ and λ = sτ,
    T(s) = (τ²/J) / (λ² + (2ζwλ + w²)e^{−λ}), w = ωₙτ, so the optimal (w, ζ) is the same for every
    axis, inertia and delay, and the loop's norm is τ²/J_min times the normalised one. The normalised
    norm is minimised by Nelder-Mead over (w, ζ) from ``starts`` points (it is nonsmooth where two
    peaks are equal), each evaluation the exact level-set norm; the gains are then checked on the
    6×6 loop by the exact norm and certified by the bounded-real LMI of order ``order``.
    """
    start = time.perf_counter()
    sc = check_spacecraft(spacecraft)
    tau = positive_scalar("tau", tau)
    starts = integer("starts", starts, minimum=1)
    evaluations = 0

    def objective(v: np.ndarray) -> float:
        nonlocal evaluations
        w, z = float(v[0]), float(v[1])
        if w <= 1e-3 or z <= 0.05 or z > 5.0:
            return 1e6 + abs(w) + abs(z)
        evaluations += 1
        value = _axis_hinf(w, z)
        return value if math.isfinite(value) else 1e6 + w

    best: tuple[float, float, float] | None = None
    for w0, z0 in [(0.2, 0.7), (0.3, 1.0), (0.4, 0.8), (0.25, 1.5), (0.5, 0.6), (0.15, 0.5)][:starts]:
        res = minimize(
            objective, np.array([w0, z0]), method="Nelder-Mead", options={"xatol": 1e-5, "fatol": 1e-9, "maxfev": 120}
        )
        if best is None or res.fun < best[0]:
            best = (float(res.fun), float(res.x[0]), float(res.x[1]))
    assert best is not None
    _, w, zeta = best
    omega_n = w / tau
    k1 = -(omega_n**2) * np.eye(3)
    k2 = -2.0 * zeta * omega_n * np.eye(3)
    k = 4.0 * sc.inertia @ np.hstack((k1, k2))
    a, a_d, b, c = torque_to_attitude(sc, k)
    exact = hinf_norm(a, a_d, tau, b, c)
    bound = hinf_bound(a, a_d, tau, b, c, order=order)
    return HinfPDSynthesis(
        K=readonly(k),
        omega_n=omega_n,
        zeta=zeta,
        exact=exact,
        certified=bound,
        evaluations=evaluations,
        time=time.perf_counter() - start,
    )
