"""Fixed-order gains for performance at a delay: PD and PID per axis, and full-matrix refinement.

Per axis, θ = 4σ, θ̈ = d/J + (K₁θ + K₂θ̇ + K₃∫θ)(t − τ) (the integral is of the delayed measurement, so the
whole command is a delayed feedback of the state (σ, ω/4, ∫σ)). In λ = sτ the axis is

    T(λ) = (τ²/J) · λ / (λ³ + (d λ² + p λ + i) e^{−λ}),   p = −τ²K₁, d = −τK₂, i = −τ³K₃,

so the optimal normalised gains (p, d[, i]) are one set for every axis, inertia and delay, for each of the
objectives: the spectral abscissa (× 1/τ), the H∞ norm (× τ²/J) and the H₂ norm (× τ^{3/2}/J). They are
found by Nelder–Mead from several starts on the exact quantity
([`spectral_abscissa`][mrpctl.design.spectra.spectral_abscissa], the level-set
[`hinf_norm`][mrpctl.design.performance.hinf_norm], the delay-Lyapunov
[`h2_norm`][mrpctl.design.pointing.h2_norm]) and then evaluated on the full loop of the spacecraft.

[`refine_full_gain`][mrpctl.design.fixed_order.refine_full_gain] takes any gain matrix of a delayed loop
ẋ = A x + B K x(t − τ) + B_w w further by BFGS on the exact H∞ norm with its gradient at the peak
(∂σ_max/∂K = Re(e^{−iωτ} (uᴴ C M⁻¹ B)ᵀ (M⁻¹ B_w v)ᵀ), M = iωI − A − BKe^{−iωτ}; nonsmooth where peaks tie,
as in HIFOO): all entries free, coupled axes included.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import minimize

from mrpctl._validation import integer, positive_scalar, readonly
from mrpctl.design._common import real_matrix
from mrpctl.design.performance import HinfBound, HinfNorm, hinf_bound, hinf_norm
from mrpctl.design.pointing import H2Norm, h2_norm
from mrpctl.design.spectra import spectral_abscissa
from mrpctl.errors import SpecificationError
from mrpctl.model import plant_model
from mrpctl.spacecraft import Spacecraft, check_spacecraft

__all__ = [
    "OBJECTIVES",
    "STRUCTURES",
    "FixedOrderSynthesis",
    "FullGainRefinement",
    "hinf_gradient",
    "normalised_axis",
    "pid_loop",
    "refine_full_gain",
    "synthesize_fixed_order",
]

#: The objectives of [`synthesize_fixed_order`][mrpctl.design.fixed_order.synthesize_fixed_order].
OBJECTIVES = ("abscissa", "hinf", "h2")
#: The controller structures.
STRUCTURES = ("pd", "pid")

_STARTS: dict[str, list[tuple[float, ...]]] = {
    "pd": [(0.2, 0.6), (0.1, 0.5), (0.3, 0.9), (0.05, 0.3), (0.5, 1.2), (0.15, 0.8)],
    "pid": [(0.2, 0.6, 0.01), (0.1, 0.5, 0.005), (0.3, 0.9, 0.03), (0.05, 0.3, 0.001), (0.4, 1.0, 0.05)],
}


def normalised_axis(structure: str, gains: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(A₀, A₁, B, C) of one axis in t/τ with unit delay: gains (p, d) for "pd", (p, d, i) for "pid".

    The state is (y, y') or (y, y', ∫y), y the angle; w enters y'' and z = y.
    """
    g = [float(v) for v in gains]
    if structure == "pd":
        p, d = g
        return (
            np.array([[0.0, 1.0], [0.0, 0.0]]),
            np.array([[0.0, 0.0], [-p, -d]]),
            np.array([[0.0], [1.0]]),
            np.array([[1.0, 0.0]]),
        )
    p, d, i = g
    return (
        np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]),
        np.array([[0.0, 0.0, 0.0], [-p, -d, -i], [0.0, 0.0, 0.0]]),
        np.array([[0.0], [1.0], [0.0]]),
        np.array([[1.0, 0.0, 0.0]]),
    )


def _normalised_value(structure: str, objective: str, gains: np.ndarray) -> float:
    a0, a1, b, c = normalised_axis(structure, gains)
    if objective == "abscissa":
        return spectral_abscissa(a0, a1, 1.0)
    if objective == "hinf":
        return hinf_norm(a0, a1, 1.0, b, c, rtol=1e-9).value
    return h2_norm(a0, a1, 1.0, b, c).value


def pid_loop(
    spacecraft: Spacecraft, K: Any, K_i: Any
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(A, B, B_w, C, K_aug) of the PID loop on (σ, ω/4, ∫σ): ẋ = A x + B K_aug x(t − τ) + B_w w, z = 4σ.

    K is the (3, 6) gain on (σ, ω/4) (N m) and K_i the (3, 3) gain on ∫σ (N m/s); K_aug = [K, K_i].
    """
    sc = check_spacecraft(spacecraft)
    plant = plant_model(sc)
    k = real_matrix("K", K, rows=3, cols=6)
    k_i = real_matrix("K_i", K_i, rows=3, cols=3)
    a = np.zeros((9, 9))
    a[:6, :6] = plant.A
    a[6:, :3] = np.eye(3)
    b = np.vstack((np.array(plant.B), np.zeros((3, 3))))
    c = np.hstack((4.0 * np.eye(3), np.zeros((3, 6))))
    return a, b, b.copy(), c, np.hstack((k, k_i))


@dataclass(frozen=True, eq=False)
class FixedOrderSynthesis:
    """Result of [`synthesize_fixed_order`][mrpctl.design.fixed_order.synthesize_fixed_order].

    Attributes
    ----------
    structure, objective : str
    tau : float
    normalised : tuple of float
        (p, d) or (p, d, i): the optimal normalised gains of every axis.
    normalised_value : float
        The objective of the normalised axis at them.
    K : numpy.ndarray
        (3, 6) gain on (σ, ω/4) (N m) of the spacecraft.
    K_i : numpy.ndarray or None
        (3, 3) integral gain on ∫σ (N m/s) for "pid".
    A, B, B_w, C : numpy.ndarray
        The loop ẋ = A x + B [K, K_i] x(t − τ) + B_w w, z = C x (torque → 4σ).
    abscissa : float
        Spectral abscissa (1/s) of the loop.
    hinf : HinfNorm
        Exact H∞ norm torque → attitude angle of the loop.
    certified : HinfBound or None
        Bounded-real LMI bound (None when not asked).
    h2 : H2Norm
    evaluations : int
        Exact evaluations of the normalised objective in the search.
    time : float
    """

    structure: str
    objective: str
    tau: float
    normalised: tuple[float, ...]
    normalised_value: float
    K: np.ndarray = field(repr=False)
    K_i: np.ndarray | None = field(repr=False)
    A: np.ndarray = field(repr=False)
    B: np.ndarray = field(repr=False)
    B_w: np.ndarray = field(repr=False)
    C: np.ndarray = field(repr=False)
    abscissa: float
    hinf: HinfNorm = field(repr=False)
    certified: HinfBound | None = field(repr=False)
    h2: H2Norm = field(repr=False)
    evaluations: int
    time: float

    @property
    def gain(self) -> np.ndarray:
        """The feedback matrix on the loop's state: K, or [K, K_i] for "pid"."""
        return self.K if self.K_i is None else np.hstack((self.K, self.K_i))

    def __str__(self) -> str:
        names = ("p", "d", "i")
        gains = ", ".join(f"{n} = {v:.6g}" for n, v in zip(names, self.normalised, strict=False))
        cert = "" if self.certified is None else f", certified < {self.certified.value:.6g}"
        return (
            f"{self.structure.upper()} optimal for {self.objective} at tau = {self.tau:g} s: normalised {gains}; "
            f"abscissa {self.abscissa:.6g} 1/s, H-infinity {self.hinf.value:.6g}{cert} rad/(N m), "
            f"H2 {self.h2.value:.6g} ({self.evaluations} evaluations, {self.time:.1f} s)"
        )


def synthesize_fixed_order(
    spacecraft: Spacecraft,
    tau: Any,
    *,
    structure: str = "pd",
    objective: str = "hinf",
    starts: int = 3,
    order: int | None = 2,
) -> FixedOrderSynthesis:
    """The per-axis PD or PID gains minimising the spectral abscissa, the H∞ or the H₂ norm at the delay τ.

    The normalised axis (module docstring) is searched by Nelder–Mead from ``starts`` points on the exact
    objective (unstable points are rejected); the gains are scaled to every axis of ``spacecraft`` (the
    same normalised gains are optimal for all of them) and the loop is evaluated: spectral abscissa, exact
    H∞ and H₂ norms from torque to attitude angle, and the bounded-real LMI of ``order`` (None: skipped).

    Raises
    ------
    SpecificationError
        For an unknown structure or objective, τ <= 0, starts < 1, or when no start gives a stable loop.
    """
    start = time.perf_counter()
    sc = check_spacecraft(spacecraft)
    tau = positive_scalar("tau", tau)
    if structure not in STRUCTURES:
        raise SpecificationError(f"structure must be one of {', '.join(STRUCTURES)}, got {structure!r}")
    if objective not in OBJECTIVES:
        raise SpecificationError(f"objective must be one of {', '.join(OBJECTIVES)}, got {objective!r}")
    candidates = _STARTS[structure]
    starts = integer("starts", starts, minimum=1)
    if starts > len(candidates):
        raise SpecificationError(f"starts must be at most {len(candidates)}, got {starts}")
    evaluations = 0

    def penalised(v: np.ndarray) -> float:
        """The normalised objective; 1e12 outside the positive box or where the axis is unstable (the exact
        H∞ and H₂ norms are infinite there, the abscissa is its own penalty)."""
        nonlocal evaluations
        if np.any(v <= 0.0) or np.any(v > 50.0):
            return 1e12
        evaluations += 1
        try:
            out = _normalised_value(structure, objective, v)
        except ArithmeticError:  # the delay Lyapunov equations degenerate (a root at the origin): rejected
            return 1e12
        return out if math.isfinite(out) else 1e12

    best: tuple[float, np.ndarray] | None = None
    for x0 in candidates[:starts]:
        res = minimize(
            penalised,
            np.array(x0, dtype=float),
            method="Nelder-Mead",
            options={"xatol": 1e-7, "fatol": 1e-11, "maxfev": 400},
        )
        if best is None or res.fun < best[0]:
            best = (float(res.fun), np.array(res.x, dtype=float))
    if best is None or best[0] >= 1e12:
        raise SpecificationError(f"no start gave a stable {structure.upper()} axis (starts = {starts})")
    normalised_value, x = best
    k1, k2 = -x[0] / tau**2, -x[1] / tau
    inertia = np.array(sc.inertia, dtype=float)
    k = 4.0 * inertia @ np.hstack((k1 * np.eye(3), k2 * np.eye(3)))
    if structure == "pid":
        k_i = 4.0 * inertia @ (-x[2] / tau**3 * np.eye(3))
        a, b, b_w, c, k_aug = pid_loop(sc, k, k_i)
    else:
        k_i = None
        plant = plant_model(sc)
        a, b = np.array(plant.A), np.array(plant.B)
        b_w, c, k_aug = b.copy(), np.hstack((4.0 * np.eye(3), np.zeros((3, 3)))), k
    a_d = b @ k_aug
    exact = hinf_norm(a, a_d, tau, b_w, c)
    bound = None if order is None else hinf_bound(a, a_d, tau, b_w, c, order=order)
    return FixedOrderSynthesis(
        structure=structure,
        objective=objective,
        tau=tau,
        normalised=tuple(float(v) for v in x),
        normalised_value=normalised_value,
        K=readonly(k),
        K_i=None if k_i is None else readonly(k_i),
        A=readonly(a),
        B=readonly(b),
        B_w=readonly(b_w),
        C=readonly(c),
        abscissa=spectral_abscissa(a, a_d, tau),
        hinf=exact,
        certified=bound,
        h2=h2_norm(a, a_d, tau, b_w, c),
        evaluations=evaluations,
        time=time.perf_counter() - start,
    )


# ------------------------------------------------------------------------------ full-matrix refinement
@dataclass(frozen=True, eq=False)
class FullGainRefinement:
    """Result of [`refine_full_gain`][mrpctl.design.fixed_order.refine_full_gain].

    Attributes
    ----------
    K : numpy.ndarray
        The refined gain (same shape as the start).
    start_value, value : float
        Exact H∞ norm at the start and at K.
    hinf : HinfNorm
        The exact norm at K.
    iterations, evaluations : int
    time : float
    """

    K: np.ndarray = field(repr=False)
    start_value: float
    value: float
    hinf: HinfNorm = field(repr=False)
    iterations: int
    evaluations: int
    time: float

    def __str__(self) -> str:
        return (
            f"full-matrix refinement: H-infinity {self.start_value:.8g} -> {self.value:.8g} "
            f"({self.iterations} BFGS iterations, {self.evaluations} exact evaluations, {self.time:.1f} s)"
        )


def hinf_gradient(
    a: np.ndarray, b: np.ndarray, k: np.ndarray, tau: float, b_w: np.ndarray, c: np.ndarray, result: HinfNorm
) -> np.ndarray:
    """∂‖T‖∞/∂K at the peak of ``result`` (valid where the peak is unique and σ_max simple)."""
    w = result.frequency
    n = a.shape[0]
    phase = np.exp(-1j * w * tau)
    m = 1j * w * np.eye(n) - a - phase * (b @ k)
    m_b = np.linalg.solve(m, b)
    m_bw = np.linalg.solve(m, b_w)
    u, _, vh = np.linalg.svd(c @ m_bw)
    left = u[:, 0].conj() @ c @ m_b
    right = m_bw @ vh[0].conj()
    return np.asarray(np.real(phase * np.outer(left, right)), dtype=float)


def refine_full_gain(
    A: Any, B: Any, K: Any, tau: Any, B_w: Any, C: Any, *, iterations: int = 60, restarts: int = 4
) -> FullGainRefinement:
    """Every entry of K free: BFGS on the exact H∞ norm of ẋ = A x + B K x(t − τ) + B_w w, z = C x.

    Starts at K (which must give a stable loop), steps only to stable points (an unstable trial point has
    an infinite norm and is rejected by the line search), restarts BFGS from the best point up to
    ``restarts`` times while it improves (``iterations`` each), and returns the best gain met. A local
    method on a nonsmooth function: the result is a stationary point at best, not a global optimum.
    """
    start = time.perf_counter()
    a = real_matrix("A", A)
    n = a.shape[0]
    if a.shape != (n, n):
        raise SpecificationError(f"A must be square, got shape {a.shape}")
    b = real_matrix("B", B, rows=n)
    k0 = real_matrix("K", K, rows=b.shape[1], cols=n)
    b_w = real_matrix("B_w", B_w, rows=n)
    c = real_matrix("C", C, cols=n)
    tau = positive_scalar("tau", tau)
    iterations = integer("iterations", iterations, minimum=1)
    restarts = integer("restarts", restarts, minimum=1)
    first = hinf_norm(a, b @ k0, tau, b_w, c)
    if not first.finite:
        raise SpecificationError(f"K: the starting loop is not stable ({first.reason})")
    scale = np.maximum(np.abs(k0), 1e-3 * float(np.abs(k0).max()))
    evaluations = 0
    best: list[Any] = [first.value, k0, first]

    def fun(v: np.ndarray) -> tuple[float, np.ndarray]:
        nonlocal evaluations
        evaluations += 1
        k = v.reshape(k0.shape) * scale
        try:
            res = hinf_norm(a, b @ k, tau, b_w, c, rtol=1e-11)
        except ArithmeticError:  # stability not certified at the trial point (clustered roots): rejected
            return 1e3 * first.value, np.zeros_like(v)
        if not res.finite:
            return 1e3 * first.value, np.zeros_like(v)
        if res.value < best[0]:
            best[:] = [res.value, k, res]
        grad = hinf_gradient(a, b, k, tau, b_w, c, res) * scale
        return res.value, grad.reshape(-1)

    nit = 0
    for _ in range(restarts):  # BFGS stalls where peaks tie; a restart from the best point resets its Hessian
        before = float(best[0])
        out = minimize(
            fun, (best[1] / scale).reshape(-1), jac=True, method="BFGS", options={"maxiter": iterations, "gtol": 1e-9}
        )
        nit += int(out.nit)
        if float(best[0]) >= before * (1.0 - 1e-9):
            break
    return FullGainRefinement(
        K=readonly(best[1]),
        start_value=first.value,
        value=float(best[0]),
        hinf=best[2],
        iterations=nit,
        evaluations=evaluations,
        time=time.perf_counter() - start,
    )
