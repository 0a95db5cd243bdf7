"""H₂ and H∞ of the sampled-data loop as flown: period h, zero-order hold, d samples of delay.

ẋ = A x + B u + B_w w, z = C x, u(t) = K x(t_{k−d}) on [t_k, t_{k+1}). Lifted to the sampling instants,
the loop is x_{k+1} = Φ x_k + Γ u_k + (noise), with the commands v_k = K x_k waiting in a delay line of d
samples; the discrete state is ξ_k = (x_k, v_{k−1}, …, v_{k−d}), of size n + m d.

- [`sampled_h2_norm`][mrpctl.design.sampled_performance.sampled_h2_norm]: w continuous white noise of
  intensity W, z the continuous output; the figure is the variance of z averaged over a sample period in
  steady state (the loop is h-periodic, so the variance ripples between samples): exact, from one discrete
  Lyapunov equation at the sampling instants and the intersample integrals in closed form.
- [`sampled_hinf_norm`][mrpctl.design.sampled_performance.sampled_hinf_norm]: w held over each sample (a
  commanded torque, or the sample mean of a slow disturbance) and z sampled: the H∞ norm of the discrete
  transfer function, by the level set of its symplectic pencil (global on the unit circle).
- [`sampled_l2_gain`][mrpctl.design.sampled_performance.sampled_l2_gain]: the L₂ gain from the continuous w
  to the continuous z through the hold (the intersample behaviour included), by bisection on the
  unit-circle eigenvalues of the lifted Hamiltonian pencil of one period.

The methods, their checks and the numbers of the paper loop are in ``design/performance.md``.
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg
from scipy.optimize import minimize_scalar

from mrpctl._validation import integer, positive_scalar, readonly
from mrpctl.design._common import real_matrix
from mrpctl.design.sampled import lifted_matrices, sampled_system
from mrpctl.errors import SpecificationError

__all__ = [
    "SampledH2",
    "SampledHinf",
    "SampledL2Gain",
    "sampled_h2_norm",
    "sampled_hinf_norm",
    "sampled_l2_gain",
    "sampled_loop_matrices",
    "sampled_sigma",
]

#: Largest lifted state (n + m d) the dense solves accept.
MAX_SAMPLED_STATE = 2000


@dataclass(frozen=True)
class _Loop:
    a: np.ndarray
    b: np.ndarray
    k: np.ndarray
    bw: np.ndarray
    c: np.ndarray
    h: float
    d: int


def _loop(A: Any, B: Any, K: Any, period: Any, delay_samples: Any, B_w: Any, C: Any) -> _Loop:
    a, b, k = sampled_system(A, B, K)
    n, m = a.shape[0], b.shape[1]
    h = positive_scalar("period", period)
    d = integer("delay_samples", delay_samples, minimum=0)
    bw = b.copy() if B_w is None else real_matrix("B_w", B_w, rows=n)
    c = real_matrix("C", C, cols=n)
    if not np.any(bw) or not np.any(c):
        raise SpecificationError("B_w and C must be nonzero: the transfer function w -> z is identically zero")
    if n + m * d > MAX_SAMPLED_STATE:
        raise SpecificationError(
            f"delay_samples: the lifted state would have n + m d = {n + m * d} entries, above {MAX_SAMPLED_STATE}; "
            "split the loop per axis or use a longer period"
        )
    return _Loop(a, b, k, bw, c, h, d)


def sampled_loop_matrices(
    A: Any, B: Any, K: Any, period: Any, *, delay_samples: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(F, T, E) of the lifted loop ξ_{k+1} = F ξ_k + E x-increment, ξ = (x_k, v_{k−1}, …, v_{k−d}).

    F is the closed-loop transition over one sample; T maps ξ_k to (x_k, u_k), the state and the held command
    over [t_k, t_{k+1}); E = [I; 0] injects an increment of x (the integrated disturbance) into ξ.
    """
    a, b, k = sampled_system(A, B, K)
    h = positive_scalar("period", period)
    d = integer("delay_samples", delay_samples, minimum=0)
    return _matrices(_Loop(a, b, k, b, np.eye(a.shape[0]), h, d))


def _matrices(loop: _Loop) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n, m, d = loop.a.shape[0], loop.b.shape[1], loop.d
    size = n + m * d
    phi, gam = lifted_matrices(loop.a, loop.b, loop.h)
    t = np.zeros((n + m, size))
    t[:n, :n] = np.eye(n)
    if d == 0:
        t[n:, :n] = loop.k
    else:
        t[n:, n + m * (d - 1) :] = np.eye(m)  # u_k = v_{k−d}, the oldest command in the line
    f = np.zeros((size, size))
    f[:n] = np.hstack((phi, gam)) @ t
    if d > 0:
        f[n : n + m, :n] = loop.k  # the newest command v_k = K x_k
        f[n + m :, n : n + m * (d - 1)] = np.eye(m * (d - 1))
    e = np.zeros((size, n))
    e[:n] = np.eye(n)
    return f, t, e


def _double_integrals(a: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """(∫₀ʰ e^{Gs} ds, ∫₀ʰ (h − s) e^{Gs} ds) for G = A ⊕ A, the vec-operator of X ↦ AX + XAᵀ.

    vec(e^{As} M e^{Aᵀs}) = e^{Gs} vec(M); both integrals are blocks of one exponential of
    [[G, I, 0], [0, 0, I], [0, 0, 0]] h.
    """
    n = a.shape[0]
    g = np.kron(np.eye(n), a) + np.kron(a, np.eye(n))
    q = n * n
    big = np.zeros((3 * q, 3 * q))
    big[:q, :q] = g
    big[:q, q : 2 * q] = np.eye(q)
    big[q : 2 * q, 2 * q :] = np.eye(q)
    e = scipy.linalg.expm(big * h)
    return e[:q, q : 2 * q], e[:q, 2 * q :]


def _vec(m: np.ndarray) -> np.ndarray:
    return m.reshape(-1, order="F")


def _mat(v: np.ndarray, n: int) -> np.ndarray:
    out = v.reshape((n, n), order="F")
    return 0.5 * (out + out.T)


@dataclass(frozen=True, eq=False)
class SampledH2:
    """Result of [`sampled_h2_norm`][mrpctl.design.sampled_performance.sampled_h2_norm].

    Attributes
    ----------
    value : float
        (tr of the period-averaged covariance of z)^{1/2} for W = the given intensity; ``inf`` when unstable.
    covariance : numpy.ndarray or None
        (p, p) covariance of z averaged over a sample period.
    sample_covariance : numpy.ndarray or None
        (p, p) covariance of z at the sampling instants.
    spectral_radius : float
        Of the lifted transition F (the loop is stable iff below 1).
    time : float
    reason : str
    """

    value: float
    covariance: np.ndarray | None = field(repr=False)
    sample_covariance: np.ndarray | None = field(repr=False)
    spectral_radius: float
    time: float
    reason: str

    @property
    def finite(self) -> bool:
        """True when the loop is stable and the value a number."""
        return math.isfinite(self.value)

    def __str__(self) -> str:
        if not self.finite or self.sample_covariance is None:
            return f"sampled-data H2 norm infinite: {self.reason}"
        return (
            f"sampled-data H2 norm {self.value:.10g} (period-averaged; at the samples "
            f"{math.sqrt(float(np.trace(self.sample_covariance))):.10g}; spectral radius "
            f"{self.spectral_radius:.9f}, {1e3 * self.time:.0f} ms)"
        )


def sampled_h2_norm(
    A: Any,
    B: Any,
    K: Any,
    period: Any,
    *,
    delay_samples: int = 0,
    B_w: Any = None,
    C: Any,
    intensity: Any = None,
) -> SampledH2:
    """Exact H₂ figure of the sampled loop for continuous white noise w: the period-averaged variance of z.

    With E[w(t)w(s)ᵀ] = W δ(t − s) (``intensity``, default I), Q(s) = ∫₀ˢ e^{Ar}B_wWB_wᵀe^{Aᵀr} dr and
    ξ_k's stationary covariance Σ = F Σ Fᵀ + E Q(h) Eᵀ (discrete Lyapunov equation), the state between
    samples is x(t_k + s) = [I 0] e^{Ās} T ξ_k + noise with Ā = [[A, B], [0, 0]] on (x, u), so

        (1/h) ∫₀ʰ E[x xᵀ] ds = (1/h) ([I 0] ∫₀ʰ e^{Ās} TΣTᵀ e^{Āᵀs} ds [I 0]ᵀ + ∫₀ʰ (h − r) e^{Ar}B_wWB_wᵀe^{Aᵀr} dr),

    both integrals from one matrix exponential each (Van Loan's block form on the Kronecker operator).
    The value is (tr C ⋯ Cᵀ)^{1/2}: for W = I it is the H₂ norm of the h-periodic system as Chen & Francis
    define it (the impulse responses' energy averaged over the impulse time).

    Parameters
    ----------
    A, B, K : array_like
        (n, n), (n, m), (m, n): ẋ = A x + B u, u = K x(t_{k−d}) held.
    period : float
        h (s).
    delay_samples : int, optional
        d >= 0.
    B_w : array_like, optional
        (n, q) disturbance input (default B: a torque on the actuator's channels).
    C : array_like
        (p, n) output.
    intensity : array_like, optional
        (q, q) symmetric positive semidefinite W (default I).
    """
    start = time.perf_counter()
    loop = _loop(A, B, K, period, delay_samples, B_w, C)
    n, m = loop.a.shape[0], loop.b.shape[1]
    q = loop.bw.shape[1]
    w = np.eye(q) if intensity is None else real_matrix("intensity", intensity, rows=q, cols=q)
    if not np.allclose(w, w.T, rtol=0.0, atol=1e-12 * (1.0 + float(np.abs(w).max()))) or np.min(
        np.linalg.eigvalsh(0.5 * (w + w.T))
    ) < -1e-12 * (1.0 + float(np.abs(w).max())):
        raise SpecificationError("intensity must be a symmetric positive semidefinite (q, q) matrix")
    f, t, e = _matrices(loop)
    rho = float(np.max(np.abs(np.linalg.eigvals(f))))
    if rho >= 1.0:
        return SampledH2(
            value=math.inf,
            covariance=None,
            sample_covariance=None,
            spectral_radius=rho,
            time=time.perf_counter() - start,
            reason=f"the sampled loop is unstable (spectral radius {rho:.9f} >= 1): the variance grows without bound",
        )
    noise = loop.bw @ w @ loop.bw.T
    first, second = _double_integrals(loop.a, loop.h)
    q_h = _mat(first @ _vec(noise), n)
    sigma = scipy.linalg.solve_discrete_lyapunov(f, e @ q_h @ e.T)
    sigma = 0.5 * (sigma + sigma.T)
    abar = np.zeros((n + m, n + m))
    abar[:n, :n] = loop.a
    abar[:n, n:] = loop.b
    first_bar, _ = _double_integrals(abar, loop.h)
    held = _mat(first_bar @ _vec(t @ sigma @ t.T), n + m)[:n, :n]
    average = (held + _mat(second @ _vec(noise), n)) / loop.h
    z_avg = loop.c @ average @ loop.c.T
    z_samp = loop.c @ sigma[:n, :n] @ loop.c.T
    return SampledH2(
        value=math.sqrt(max(float(np.trace(z_avg)), 0.0)),
        covariance=readonly(0.5 * (z_avg + z_avg.T)),
        sample_covariance=readonly(0.5 * (z_samp + z_samp.T)),
        spectral_radius=rho,
        time=time.perf_counter() - start,
        reason="discrete Lyapunov equation at the samples, intersample integrals in closed form",
    )


@dataclass(frozen=True, eq=False)
class SampledHinf:
    """Result of [`sampled_hinf_norm`][mrpctl.design.sampled_performance.sampled_hinf_norm].

    Attributes
    ----------
    value : float
        sup_θ σ_max(T(e^{iθ})) of the discrete loop (held w, sampled z); ``inf`` when unstable.
    frequency : float
        ω = θ/h (rad/s) of the peak, in [0, π/h]; nan when infinite.
    spectral_radius : float
    levels : int
        Level-set iterations.
    time : float
    reason : str
    """

    value: float
    frequency: float
    spectral_radius: float
    levels: int
    time: float
    reason: str

    @property
    def finite(self) -> bool:
        """True when the loop is stable and the value a number."""
        return math.isfinite(self.value)

    def __str__(self) -> str:
        if not self.finite:
            return f"sampled-loop H-infinity norm infinite: {self.reason}"
        return (
            f"sampled-loop H-infinity norm {self.value:.10g} at omega = {self.frequency:.6g} rad/s "
            f"({self.levels} levels, spectral radius {self.spectral_radius:.9f}, {1e3 * self.time:.0f} ms)"
        )


def sampled_hinf_norm(
    A: Any,
    B: Any,
    K: Any,
    period: Any,
    *,
    delay_samples: int = 0,
    B_w: Any = None,
    C: Any,
    rtol: float = 1e-10,
) -> SampledHinf:
    """Exact H∞ norm of the sampled loop from a held disturbance w_k (constant on [t_k, t_{k+1})) to z_k = C x_k.

    T(z) = C_ξ (zI − F)⁻¹ E Γ_w, Γ_w = ∫₀ʰ e^{As} ds B_w. γ is a singular value of T(e^{iθ}) exactly when
    e^{iθ} is an eigenvalue of the pencil

        [[F, G Gᵀ/γ²], [0, −I]] − z [[I, 0], [−HᵀH, −Fᵀ]],   G = EΓ_w, H = C_ξ,

    (from z x = F x + G w, w = GᵀΛ/γ², Λ = z(FᵀΛ + HᵀH x)). The level set (Boyd–Balakrishnan) raises γ to
    the largest σ_max between consecutive unit-circle eigenvalues and stops when none is left at γ(1 + 2 rtol).
    As h → 0 with d h = τ it tends to the H∞ norm of the continuous delayed loop (a held w is then a
    continuous one); it does not see the intersample ripple of z.
    """
    start = time.perf_counter()
    loop = _loop(A, B, K, period, delay_samples, B_w, C)
    rtol = positive_scalar("rtol", rtol)
    f, _, e = _matrices(loop)
    rho = float(np.max(np.abs(np.linalg.eigvals(f))))
    if rho >= 1.0:
        return SampledHinf(
            value=math.inf,
            frequency=math.nan,
            spectral_radius=rho,
            levels=0,
            time=time.perf_counter() - start,
            reason=f"the sampled loop is unstable (spectral radius {rho:.9f} >= 1): the L2 gain is infinite",
        )
    _, gam_w = lifted_matrices(loop.a, loop.bw, loop.h)
    g = e @ gam_w
    hm = np.hstack((loop.c, np.zeros((loop.c.shape[0], f.shape[0] - loop.a.shape[0]))))
    size = f.shape[0]
    eye = np.eye(size)

    def sigma(theta: float) -> float:
        tf = hm @ np.linalg.solve(np.exp(1j * theta) * eye - f, g)
        return float(np.linalg.svd(tf, compute_uv=False)[0])

    def crossings(gamma: float) -> list[float]:
        left = np.block([[f, g @ g.T / gamma**2], [np.zeros((size, size)), -eye]])
        right = np.block([[eye, np.zeros((size, size))], [-hm.T @ hm, -f.T]])
        values = scipy.linalg.eigvals(left, right)
        values = values[np.isfinite(values)]
        near = values[np.abs(np.abs(values) - 1.0) <= 1e-6]  # extra edges only split the intervals further
        return sorted({round(abs(float(np.angle(z))), 12) for z in near})

    grid = np.linspace(0.0, math.pi, 257)
    values = [sigma(th) for th in grid]
    best = int(np.argmax(values))
    gamma, theta_peak = _peak(sigma, float(grid[best]), values[best], 0.0, math.pi)
    levels = 0
    for _ in range(60):
        levels += 1
        level = gamma * (1.0 + 2.0 * rtol)
        edges = [0.0, *crossings(level), math.pi]
        improved = False
        for lo, hi in itertools.pairwise(edges):
            if hi <= lo:
                continue
            mid = 0.5 * (lo + hi)
            if sigma(mid) <= level:
                continue
            value, where = _peak(sigma, mid, sigma(mid), lo, hi)
            if value > gamma:
                gamma, theta_peak, improved = value, where, True
        if not improved:
            break
    return SampledHinf(
        value=gamma,
        frequency=theta_peak / loop.h,
        spectral_radius=rho,
        levels=levels,
        time=time.perf_counter() - start,
        reason=f"no unit-circle eigenvalue of the pencil at gamma (1 + {2.0 * rtol:.0e})",
    )


def _peak(sigma: Any, theta: float, value: float, lo: float, hi: float) -> tuple[float, float]:
    """The largest σ_max on [lo, hi] near θ: a bounded scalar search on the whole interval and one around θ."""
    best, where = value, theta
    width = 0.05 * (hi - lo) + 1e-9
    for a, b in ((lo, hi), (max(lo, theta - width), min(hi, theta + width))):
        if b <= a:
            continue
        res = minimize_scalar(lambda x: -sigma(x), bounds=(a, b), method="bounded", options={"xatol": 1e-13})
        if -float(res.fun) > best:
            best, where = -float(res.fun), float(res.x)
    return best, where


def sampled_sigma(
    A: Any, B: Any, K: Any, period: Any, omega: Any, *, delay_samples: int = 0, B_w: Any = None, C: Any
) -> np.ndarray:
    """σ_max(T(e^{iωh})) of the held-disturbance loop of
    [`sampled_hinf_norm`][mrpctl.design.sampled_performance.sampled_hinf_norm] at the frequencies ω (rad/s)."""
    loop = _loop(A, B, K, period, delay_samples, B_w, C)
    w = np.atleast_1d(np.asarray(omega, dtype=float))
    if w.ndim != 1 or not np.all(np.isfinite(w)) or np.any(w < 0.0):
        raise SpecificationError("omega must be a 1-D array of finite frequencies >= 0 (rad/s)")
    f, _, e = _matrices(loop)
    _, gam_w = lifted_matrices(loop.a, loop.bw, loop.h)
    g = e @ gam_w
    hm = np.hstack((loop.c, np.zeros((loop.c.shape[0], f.shape[0] - loop.a.shape[0]))))
    z = np.exp(1j * w * loop.h)
    m = z[:, None, None] * np.eye(f.shape[0]) - f
    tf = hm @ np.linalg.solve(m, np.broadcast_to(g, (len(w), *g.shape)))
    return np.asarray(np.linalg.svd(tf, compute_uv=False)[:, 0], dtype=float)


# ------------------------------------------------------------------------------ the intersample L2 gain
@dataclass(frozen=True)
class _Period:
    """One period of the loop as a continuous system on Y = (x(s), ξ_k): Y(0) = E ξ_k, ξ_{k+1} = J Y(h)."""

    f: np.ndarray
    abar: np.ndarray
    bbar: np.ndarray
    cbar: np.ndarray
    e: np.ndarray
    j: np.ndarray


def _period(loop: _Loop) -> _Period:
    f, t, _ = _matrices(loop)
    n, size = loop.a.shape[0], f.shape[0]
    q = n + size
    abar = np.zeros((q, q))
    abar[:n, :n] = loop.a
    abar[:n, n:] = loop.b @ t[n:]  # the held command u_k, a row selection of ξ_k
    bbar = np.vstack((loop.bw, np.zeros((size, loop.bw.shape[1]))))
    cbar = np.hstack((loop.c, np.zeros((loop.c.shape[0], size))))
    e = np.zeros((q, size))
    e[:n, :n] = np.eye(n)
    e[n:] = np.eye(size)
    j = np.zeros((size, q))
    j[:n, :n] = np.eye(n)
    j[n:, n:] = f[n:]  # the command line moves on; x_{k+1} = x(h)
    return _Period(f, abar, bbar, cbar, e, j)


def _unit_circle_angles(loop: _Loop, per: _Period, gamma: float) -> np.ndarray:
    """Angles θ in [0, π] where γ is a singular value of the lifted frequency response at e^{iθ}.

    With the Hamiltonian H = [[Ā, B̄B̄ᵀ/γ²], [−C̄ᵀC̄, −Āᵀ]] of one period and Φ = e^{hH}, the worst
    disturbance w = B̄ᵀΛ/γ² and the Floquet ansatz ξ_k = zᵏξ, ν_k = zᵏν give
    J(Φ₁₁Eξ + Φ₁₂Λ₀) = zξ, Φ₂₁Eξ + Φ₂₂Λ₀ = zJᵀν, EᵀΛ₀ = ν: a pencil in z of size 2N + q.
    """
    size, q = per.f.shape[0], per.abar.shape[0]
    ham = np.block([[per.abar, per.bbar @ per.bbar.T / gamma**2], [-per.cbar.T @ per.cbar, -per.abar.T]])
    phi = scipy.linalg.expm(loop.h * ham)
    p11, p12, p21, p22 = phi[:q, :q], phi[:q, q:], phi[q:, :q], phi[q:, q:]
    zn, zq = np.zeros((size, size)), np.zeros((size, q))
    left = np.block([[per.j @ p11 @ per.e, per.j @ p12, zn], [p21 @ per.e, p22, zq.T], [zn, per.e.T, -np.eye(size)]])
    right = np.block([[np.eye(size), zq, zn], [zq.T, np.zeros((q, q)), per.j.T], [zn, zq, zn]])
    values = scipy.linalg.eigvals(left, right)
    values = values[np.isfinite(values)]
    near = values[np.abs(np.abs(values) - 1.0) <= 1e-7]
    return np.sort(np.abs(np.angle(near)))


def _psd_root(m: np.ndarray) -> np.ndarray:
    val, vec = np.linalg.eigh(0.5 * (m + m.T))
    return np.asarray((vec * np.sqrt(np.maximum(val, 0.0))) @ vec.T)


def _gramian(a: np.ndarray, m: np.ndarray, h: float) -> np.ndarray:
    """∫₀ʰ e^{As} M e^{Aᵀs} ds (Van Loan: E₂₂ᵀE₁₂ of the exponential of [[−A, M], [0, Aᵀ]] h)."""
    q = a.shape[0]
    big = np.zeros((2 * q, 2 * q))
    big[:q, :q], big[:q, q:], big[q:, q:] = -a, m, a.T
    ex = scipy.linalg.expm(big * h)
    out = ex[q:, q:].T @ ex[:q, q:]
    return np.asarray(0.5 * (out + out.T))


def _held_lower_bound(loop: _Loop, per: _Period, pieces: int, thetas: np.ndarray) -> tuple[float, float]:
    """(γ, θ): the largest gain over w constant on ``pieces`` sub-intervals of each period (a lower bound of the
    L2 gain: a subset of inputs, the output energy integrated exactly), on the grid of θ."""
    size, q, p = per.f.shape[0], per.abar.shape[0], per.bbar.shape[1]
    hs = loop.h / pieces
    aug = np.zeros((q + p, q + p))
    aug[:q, :q], aug[:q, q:] = per.abar, per.bbar
    ex = scipy.linalg.expm(aug * hs)
    ad, bd = ex[:q, :q], ex[:q, q:]
    weight = np.zeros((q + p, q + p))
    weight[:q, :q] = per.cbar.T @ per.cbar
    energy = _gramian(aug.T, weight, hs)  # ∫ e^{augᵀs} W e^{aug s} ds: the substep's output energy form
    val, vec = np.linalg.eigh(energy)
    root = (vec * np.sqrt(np.maximum(val, 0.0))).T
    cols = size + pieces * p
    y = np.hstack((per.e, np.zeros((q, pieces * p))))
    rows = []
    for k in range(pieces):
        sel = np.zeros((p, cols))
        sel[:, size + k * p : size + (k + 1) * p] = np.eye(p)
        rows.append(root @ np.vstack((y, sel)))
        y = ad @ y + bd @ sel
    nxt = per.j @ y
    cz, dz = np.vstack([r[:, :size] for r in rows]), np.vstack([r[:, size:] for r in rows])
    best, where = -1.0, 0.0
    for theta in thetas:
        tf = cz @ np.linalg.solve(np.exp(1j * theta) * np.eye(size) - nxt[:, :size], nxt[:, size:]) + dz
        value = float(np.linalg.svd(tf, compute_uv=False)[0]) / math.sqrt(hs)
        if value > best:
            best, where = value, float(theta)
    return best, where


@dataclass(frozen=True)
class SampledL2Gain:
    """Result of [`sampled_l2_gain`][mrpctl.design.sampled_performance.sampled_l2_gain].

    Attributes
    ----------
    value : float
        The L₂ gain from the continuous w to the continuous z (``inf`` when unstable).
    frequency : float
        ω (rad/s) of the peak in [0, π/h] (nan when infinite).
    lower_bound : float
        The held-input lower bound the bisection started from.
    bracket_certified : bool
        True when the resolvent bound shows σ_max < the lower bound somewhere on the circle, so that every γ of
        the bisection below the gain has a crossing (the bisection is then exact to ``rtol``).
    spectral_radius : float
    time : float
    reason : str
    """

    value: float
    frequency: float
    lower_bound: float
    bracket_certified: bool
    spectral_radius: float
    time: float
    reason: str

    @property
    def finite(self) -> bool:
        """True when the loop is stable and the value a number."""
        return math.isfinite(self.value)

    def __str__(self) -> str:
        if not self.finite:
            return f"sampled-data L2 gain infinite: {self.reason}"
        return (
            f"sampled-data L2 gain {self.value:.10g} at omega = {self.frequency:.6g} rad/s "
            f"({'certified bracket' if self.bracket_certified else 'bracket NOT certified'}; held-input lower bound "
            f"{self.lower_bound:.10g}; {1e3 * self.time:.0f} ms)"
        )


def sampled_l2_gain(
    A: Any,
    B: Any,
    K: Any,
    period: Any,
    *,
    delay_samples: int = 0,
    B_w: Any = None,
    C: Any,
    rtol: float = 1e-9,
) -> SampledL2Gain:
    """The L₂ gain of the sampled loop from the continuous disturbance w to the continuous output z.

    The intersample behaviour included (Bamieh & Pearson's lifting): γ is a singular value of the lifted
    frequency response Ĝ(e^{iθ}) (an operator on L₂[0, h]) exactly when e^{iθ} is an eigenvalue of a finite
    pencil built from the Hamiltonian exponential of one period (``_unit_circle_angles``). The gain is found
    by bisection on γ between a lower bound (the gain over inputs constant on 8 sub-intervals of each
    period, with the output energy integrated exactly) and the first γ above it without a crossing; each γ
    below the gain has a crossing as soon as σ_max is below the lower bound somewhere, which a resolvent
    bound ‖D̂‖_HS + ‖(Ĉ*Ĉ)^{1/2}(zI − F)⁻¹(B̂B̂*)^{1/2}‖ checks (``bracket_certified``).
    """
    start = time.perf_counter()
    loop = _loop(A, B, K, period, delay_samples, B_w, C)
    rtol = positive_scalar("rtol", rtol)
    per = _period(loop)
    rho = float(np.max(np.abs(np.linalg.eigvals(per.f))))
    if rho >= 1.0:
        return SampledL2Gain(
            value=math.inf,
            frequency=math.nan,
            lower_bound=math.nan,
            bracket_certified=False,
            spectral_radius=rho,
            time=time.perf_counter() - start,
            reason=f"the sampled loop is unstable (spectral radius {rho:.9f} >= 1): the L2 gain is infinite",
        )
    grid = np.linspace(0.0, math.pi, 129)
    low, theta0 = _held_lower_bound(loop, per, 8, grid)
    step = grid[1] - grid[0]
    res = minimize_scalar(
        lambda th: -_held_lower_bound(loop, per, 8, np.array([th]))[0],
        bounds=(max(0.0, theta0 - step), min(math.pi, theta0 + step)),
        method="bounded",
        options={"xatol": 1e-10},
    )
    if -float(res.fun) > low:
        low, theta0 = -float(res.fun), float(res.x)
    # the resolvent bound, at the grid's θ where it is smallest
    n = loop.a.shape[0]
    _, second = _double_integrals(loop.a, loop.h)
    d_hs = math.sqrt(max(float(np.trace(loop.c @ _mat(second @ _vec(loop.bw @ loop.bw.T), n) @ loop.c.T)), 0.0))
    w_o = per.e.T @ _gramian(per.abar.T, per.cbar.T @ per.cbar, loop.h) @ per.e  # Ĉ*Ĉ
    w_c = per.j @ _gramian(per.abar, per.bbar @ per.bbar.T, loop.h) @ per.j.T  # B̂B̂*
    root_o, root_c = _psd_root(w_o), _psd_root(w_c)
    eye = np.eye(per.f.shape[0])
    # ‖Ĝ(z)‖ <= ‖D̂‖ + ‖Ĉ(zI − F)⁻¹B̂‖ and the second norm is exactly ‖(Ĉ*Ĉ)^{1/2}(zI − F)⁻¹(B̂B̂*)^{1/2}‖
    resolvent = min(
        float(np.linalg.svd(root_o @ np.linalg.solve(np.exp(1j * th) * eye - per.f, root_c), compute_uv=False)[0])
        for th in grid[::8]
    )
    certified = d_hs + resolvent < low
    lo, hi = low, low * 1.01
    while _unit_circle_angles(loop, per, hi).size:
        lo, hi = hi, hi * 1.1
    while hi - lo > rtol * hi:
        mid = 0.5 * (lo + hi)
        if _unit_circle_angles(loop, per, mid).size:
            lo = mid
        else:
            hi = mid
    angles = _unit_circle_angles(loop, per, lo)
    theta = float(np.mean(angles)) if angles.size else theta0
    return SampledL2Gain(
        value=hi,
        frequency=theta / loop.h,
        lower_bound=low,
        bracket_certified=bool(certified),
        spectral_radius=rho,
        time=time.perf_counter() - start,
        reason="bisection on the unit-circle eigenvalues of the lifted Hamiltonian pencil",
    )
