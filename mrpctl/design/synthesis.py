"""Gain synthesis for a given delay τ: fastest certified PD gains, and descriptor-method state feedback."""

from __future__ import annotations

import enum
import functools
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mrpctl._validation import nonnegative_scalar, positive_scalar
from mrpctl.design._common import OPTIMAL, frozen, order_value, solve
from mrpctl.design.gains import PDGains, pd_gains
from mrpctl.design.lmi import (
    DEFAULT_MARGIN_TOL,
    WIRTINGER,
    Certificate,
    CertificateStatus,
    Positivity,
    _certify,
    _legendre_rows,
    bracket_root,
    criterion_name,
)
from mrpctl.design.loop import linearized_loop
from mrpctl.design.margin import DelayMargin, delay_margin
from mrpctl.errors import SpecificationError
from mrpctl.model import gain_from_pd
from mrpctl.spacecraft import Spacecraft

__all__ = [
    "LMISynthesis",
    "PDSynthesis",
    "SynthesisStatus",
    "synthesize_lmi",
    "synthesize_pd",
]


class SynthesisStatus(enum.Enum):
    """Outcome of a synthesis."""

    #: Gains found, and re-verified by :func:`~mrpctl.design.lmi.certify` and the exact margin.
    SYNTHESIZED = "synthesized and verified"
    #: The synthesis LMI was feasible but the re-verification of the gains failed.
    NOT_VERIFIED = "synthesized but not verified"
    #: No gains found (the LMI is infeasible for every tuning tried).
    INFEASIBLE = "infeasible"
    #: The solver failed on every attempt.
    SOLVER_FAILED = "solver failed"


@dataclass(frozen=True)
class PDSynthesis:
    """Result of :func:`synthesize_pd`.

    Attributes
    ----------
    status : SynthesisStatus
    tau : float
        The delay τ (s) the gains are certified for.
    order : int
        Bessel-Legendre order N of the certificate.
    gains : PDGains or None
        The PD gains with the largest certified ωₙ at the requested ζ (None when none found).
    certificate : Certificate or None
        The LMI certificate of the loop at τ under ``gains``.
    margin : DelayMargin or None
        The exact delay margin of the loop under ``gains`` (>= τ when verified).
    solves : int
        LMI solves used.
    reason : str
    """

    status: SynthesisStatus
    tau: float
    order: int
    gains: PDGains | None = field(repr=False)
    certificate: Certificate | None = field(repr=False)
    margin: DelayMargin | None = field(repr=False)
    solves: int
    reason: str

    @property
    def synthesized(self) -> bool:
        """True when gains were found and verified."""
        return self.status is SynthesisStatus.SYNTHESIZED

    @property
    def omega_n(self) -> float:
        """The certified natural frequency ωₙ (rad/s); nan when nothing was found."""
        return float(self.gains.omega_n[0]) if self.gains is not None else math.nan

    def __str__(self) -> str:
        head = f"PD synthesis for tau = {self.tau:g} s ({criterion_name(self.order)}): {self.status.value}"
        if self.gains is None:
            return f"{head}\n  {self.reason}"
        return (
            f"{head}\n  omega_n = {self.omega_n:.6g} rad/s, zeta = {float(self.gains.zeta[0]):.4g}; "
            f"exact delay margin {self.margin.margin:.6g} s; {self.solves} LMI solves\n  {self.reason}"
        )


def synthesize_pd(
    spacecraft: Spacecraft,
    tau: float,
    *,
    zeta: float = 1.0,
    order: int = 3,
    allow_underdamped: bool = False,
    rtol: float = 1e-4,
    positivity: Positivity = Positivity.RELAXED,
) -> PDSynthesis:
    """The fastest PD gains (largest ωₙ at the given ζ) whose LMI certifies the delay τ.

    The gains are those of :func:`~mrpctl.design.gains.pd_gains` (same ζ, ωₙ on every axis,
    K₁ = −ωₙ² I, K₂ = −2ζωₙ I). The certified set in ωₙ is searched from the exact bound
    (the loop's exact delay margin scales as 1/ωₙ, so ωₙ above it is never certifiable) with the
    same safeguarded root search on the solver margin as
    :func:`~mrpctl.design.lmi.max_certified_delay`, to relative width ``rtol``.

    Parameters
    ----------
    spacecraft : Spacecraft
    tau : float
        Delay τ > 0 (s).
    zeta : float, optional
        Damping ratio ζ (default 1, critically damped; < 1 needs ``allow_underdamped``).
    order : int, optional
        Bessel-Legendre order N of the certificate (default 3).
    allow_underdamped : bool, optional
        Accept ζ < 1.
    rtol : float, optional
        Relative width of the final ωₙ bracket.
    positivity : Positivity, optional
        Positivity condition of the certificate.

    Returns
    -------
    PDSynthesis

    Raises
    ------
    SpecificationError
        If τ <= 0 or NaN, ζ <= 0 (or < 1 without ``allow_underdamped``), or an option is invalid.
    """
    if not isinstance(spacecraft, Spacecraft):
        raise TypeError(f"spacecraft must be a mrpctl.Spacecraft, got {type(spacecraft).__name__}")
    tau = positive_scalar("tau", tau)
    zeta = positive_scalar("zeta", zeta)
    order = order_value(order)
    rtol = positive_scalar("rtol", rtol)
    pd_gains(spacecraft, zeta=zeta, omega_n=1.0, allow_underdamped=allow_underdamped)  # checks ζ
    # Exact bound: the per-axis loop at ωₙ = 1 has margin τ₁; at ωₙ its margin is τ₁/ωₙ.
    unit = delay_margin([[0.0, 1.0], [0.0, 0.0]], [[0.0, 0.0], [-1.0, -2.0 * zeta]]).margin
    omega_bound = unit / tau
    solves = 0

    def test(omega_n: float) -> Certificate:
        nonlocal solves
        solves += 1
        gains = pd_gains(spacecraft, zeta=zeta, omega_n=omega_n, allow_underdamped=allow_underdamped)
        return linearized_loop(spacecraft, gains.K).certify(tau, order=order, positivity=positivity)

    good = None
    for fraction in (0.5, 0.1, 0.01):
        cert = test(fraction * omega_bound)
        if cert.certified:
            good, good_cert = fraction * omega_bound, cert
            break
    if good is None:
        return PDSynthesis(
            SynthesisStatus.INFEASIBLE,
            tau,
            order,
            None,
            None,
            None,
            solves,
            f"no omega_n down to 1% of the exact bound {omega_bound:.6g} rad/s is certified",
        )
    bad_cert = test(omega_bound)
    if bad_cert.certified:  # would contradict the exact margin: report, do not hide
        omega_n, cert = omega_bound, bad_cert
        reason = "certified at the exact bound itself (soundness check failed)"
    else:
        omega_n, cert = bracket_root(test, good, good_cert, omega_bound, rtol)
        reason = f"largest certified omega_n to rtol {rtol:g}; exact bound {omega_bound:.6g} rad/s"
    gains = pd_gains(spacecraft, zeta=zeta, omega_n=omega_n, allow_underdamped=allow_underdamped)
    margin = linearized_loop(spacecraft, gains.K).delay_margin()
    verified = cert.certified and margin.margin > tau
    return PDSynthesis(
        SynthesisStatus.SYNTHESIZED if verified else SynthesisStatus.NOT_VERIFIED,
        tau,
        order,
        gains,
        cert,
        margin,
        solves,
        reason,
    )


@dataclass(frozen=True)
class LMISynthesis:
    """Result of :func:`synthesize_lmi`: a delayed state feedback u = K x(t − τ).

    Attributes
    ----------
    status : SynthesisStatus
    tau : float
        The delay τ (s).
    decay_rate : float
        The decay rate α (1/s) imposed through z = e^{αt} x.
    order : int
        Bessel-Legendre order N of the synthesis LMI (0 Jensen, 1 Wirtinger).
    K : numpy.ndarray or None
        (3, 6) gain on x = [σ; ω/4] (N m); None when nothing was found.
    epsilon : float
        The descriptor tuning scalar ε (s) of P₃ = εP₂ that was kept (nan when none).
    certificate : Certificate or None
        :func:`~mrpctl.design.lmi.certify` of ẋ = A x + B K x(t − τ) at τ (same order).
    decay_certificate : Certificate or None
        :func:`~mrpctl.design.lmi.certify` of the shifted system ż = (A + αI) z + e^{ατ} B K z(t − τ).
    margin : DelayMargin or None
        Exact delay margin of the loop under K.
    solves : int
        Synthesis LMI solves (ε line search).
    reason : str
    """

    status: SynthesisStatus
    tau: float
    decay_rate: float
    order: int
    K: np.ndarray | None = field(repr=False)
    epsilon: float
    certificate: Certificate | None = field(repr=False)
    decay_certificate: Certificate | None = field(repr=False)
    margin: DelayMargin | None = field(repr=False)
    solves: int
    reason: str

    @property
    def synthesized(self) -> bool:
        """True when K was found and verified."""
        return self.status is SynthesisStatus.SYNTHESIZED

    def __str__(self) -> str:
        head = (
            f"LMI synthesis for tau = {self.tau:g} s, decay rate {self.decay_rate:g} 1/s "
            f"({criterion_name(self.order)}, descriptor method): {self.status.value}"
        )
        lines = [head, f"  {self.reason}"]
        if self.K is not None:
            lines.append(f"  epsilon = {self.epsilon:.4g} s; exact delay margin {self.margin.margin:.6g} s")
            lines.append(f"  K = {np.array2string(self.K, precision=5, max_line_width=200)}")
        return "\n".join(lines)


class _SynthesisProblem:
    """The descriptor-method synthesis LMI of order N, parameterised in (τ, τ², ε, A, εA, B, εB).

    ζ̄ = [x; ẋ; x(t−τ); Ω₀; ...; Ω_{N−1}] after the congruence diag(X, ..., X), X = P₂⁻¹:
    Ψ = He(G(τ)ᵀ P̄ H) + diag(S̄, 0, −S̄, 0) + τ² e₂ᵀ R̄ e₂ − Σₖ (2k+1) E_kᵀ R̄ E_k
        + He([I, εI, 0, ...]ᵀ [A X, −X, B Y, 0, ...]) ≺ 0,
    with S̄, R̄ ≻ 0, τP̄ + diag(0, S̄, 3S̄, ...) ≻ 0, and K = Y X⁻¹. All products are parameter ×
    variable (DPP); decision variables are normalised and the margin t maximised.
    """

    def __init__(self, n: int, m: int, order: int) -> None:
        import cvxpy as cp

        blocks = order + 3
        size = blocks * n
        par = {
            "tau": cp.Parameter(nonneg=True),
            "tau2": cp.Parameter(nonneg=True),
            "eps": cp.Parameter(nonneg=True),
            "A": cp.Parameter((n, n)),
            "epsA": cp.Parameter((n, n)),
            "B": cp.Parameter((n, m)),
            "epsB": cp.Parameter((n, m)),
        }
        self.params = par
        self.P = cp.Variable(((order + 1) * n, (order + 1) * n), symmetric=True)
        self.S = cp.Variable((n, n), symmetric=True)
        self.R = cp.Variable((n, n), symmetric=True)
        self.X = cp.Variable((n, n))
        self.Y = cp.Variable((m, n))
        self.t = cp.Variable()
        P, S, R, X, Y, t = self.P, self.S, self.R, self.X, self.Y, self.t
        eye = np.eye(n)

        def sel(block: int) -> np.ndarray:
            out = np.zeros((n, size))
            out[:, block * n : (block + 1) * n] = eye
            return out

        rows = _legendre_rows(order)  # Δ_k over [x, x_d, Ω_0..Ω_{N−1}]
        cols = [0, 2, *range(3, 3 + order)]  # their places in ζ̄ (ẋ is block 1)
        e_mats = [sum(rows[k, i] * sel(c) for i, c in enumerate(cols)) for k in range(order + 1)]
        # G(τ)ᵀ P̄ H with ξ = [x; τΩ₀; ...] and ξ̇ = [ẋ; Δ₀; ...; Δ_{N−1}].
        h_mat = np.vstack([sel(1), *e_mats[:order]])
        g0 = np.vstack([sel(0)] + [np.zeros((n, size))] * order)
        g1 = np.vstack([np.zeros((n, size))] + [sel(3 + k) for k in range(order)])
        he = g0.T @ (P @ h_mat) + par["tau"] * (g1.T @ (P @ h_mat))
        psi = he + he.T
        psi = psi + sel(0).T @ S @ sel(0) - sel(2).T @ S @ sel(2)
        psi = psi + par["tau2"] * (sel(1).T @ R @ sel(1))
        for k, e in enumerate(e_mats):
            psi = psi - (2 * k + 1) * (e.T @ R @ e)
        w0 = par["A"] @ X @ sel(0) - X @ sel(1) + par["B"] @ Y @ sel(2)
        w1 = par["epsA"] @ X @ sel(0) - par["eps"] * (X @ sel(1)) + par["epsB"] @ Y @ sel(2)
        desc = sel(0).T @ w0 + sel(1).T @ w1
        psi = psi + desc + desc.T
        psi = 0.5 * (psi + psi.T)
        pos = par["tau"] * P
        for k in range(order):
            block = np.zeros(((order + 1) * n, n))
            block[(k + 1) * n : (k + 2) * n, :] = eye
            pos = pos + (2 * k + 1) * (block @ S @ block.T)
        pos = 0.5 * (pos + pos.T)
        self.problem = cp.Problem(
            cp.Maximize(t),
            [
                -psi >> t * np.eye(size),
                pos >> t * np.eye((order + 1) * n),
                S >> t * np.eye(n),
                R >> t * np.eye(n),
                cp.trace(pos) + cp.trace(S) + cp.trace(R) == 1.0,
            ],
        )

    def set(self, a: np.ndarray, b: np.ndarray, tau: float, eps: float) -> None:
        p = self.params
        p["tau"].value = tau
        p["tau2"].value = tau * tau
        p["eps"].value = eps
        p["A"].value = a
        p["epsA"].value = eps * a
        p["B"].value = b
        p["epsB"].value = eps * b


@functools.lru_cache(maxsize=16)
def _synthesis_problem(n: int, m: int, order: int) -> _SynthesisProblem:
    return _SynthesisProblem(n, m, order)


def _synthesize_pair(
    a: np.ndarray, b: np.ndarray, tau: float, order: int, epsilons: np.ndarray
) -> tuple[np.ndarray | None, float, int, str]:
    """Line search on ε; returns (K, ε, solves, status text) for the best margin t > 0."""
    lmi = _synthesis_problem(a.shape[0], b.shape[1], order)
    best: tuple[float, np.ndarray, float] | None = None
    statuses = []
    for eps in epsilons:
        lmi.set(a, b, tau, float(eps))
        outcome = solve(lmi.problem)
        statuses.append(outcome.status)
        if not outcome.optimal or lmi.t.value is None or lmi.X.value is None:
            continue
        t_opt = float(lmi.t.value)
        if t_opt <= 0.0 or (best is not None and t_opt <= best[0]):
            continue
        x = np.asarray(lmi.X.value, dtype=float)
        if np.linalg.cond(x) > 1e12:
            continue
        best = (t_opt, np.asarray(lmi.Y.value, dtype=float) @ np.linalg.inv(x), float(eps))
    if best is None:
        failed = all(s != OPTIMAL for s in statuses)
        return None, math.nan, len(epsilons), "solver failed" if failed else "infeasible"
    return best[1], best[2], len(epsilons), "optimal"


def synthesize_lmi(
    spacecraft: Spacecraft,
    tau: float,
    *,
    decay_rate: float,
    order: int = WIRTINGER,
    epsilons: Any = None,
    margin_tol: float = DEFAULT_MARGIN_TOL,
) -> LMISynthesis:
    """Delayed state feedback u = K x(t − τ) with decay rate α by the descriptor method.

    With z = e^{αt} x the loop becomes ż = (A + αI) z + e^{ατ} B K z(t − τ); its order-N
    functional (N = 0 Jensen, N = 1 Wirtinger, higher N Bessel-Legendre) is combined with the
    descriptor identity 2(xᵀP₂ᵀ + ẋᵀP₃ᵀ)(−ẋ + A x + B K x(t − τ)) = 0 (Fridman 2001), P₃ = εP₂, and
    the congruence X = P₂⁻¹, Y = K X makes the condition an LMI in (P̄, S̄, R̄, X, Y) for each ε.
    ε is line-searched on a logarithmic grid and the feasible point with the largest normalised
    margin is kept; K = Y X⁻¹. Without a decay rate the LMI accepts arbitrarily small gains, so α
    is the design objective. When J is diagonal the three axes share one 2×2 synthesis of the
    loop gains (K₁, K₂), and K = [4 J K₁, 4 J K₂].

    Every K found is re-verified: :func:`~mrpctl.design.lmi.certify` of the loop at τ and of the
    shifted loop (decay rate α), and :func:`~mrpctl.design.margin.delay_margin` > τ.

    Parameters
    ----------
    spacecraft : Spacecraft
    tau : float
        Delay τ > 0 (s).
    decay_rate : float
        α >= 0 (1/s); keyword-only and required.
    order : int, optional
        Bessel-Legendre order N (default 1, Wirtinger).
    epsilons : array_like, optional
        Values of ε (s) to try; default τ × logspace(−1.5, 1.5, 9).
    margin_tol : float, optional
        Relative eigenvalue margin for the re-verification certificates.

    Returns
    -------
    LMISynthesis

    Raises
    ------
    SpecificationError
        If τ <= 0 or NaN, α < 0 or NaN, or ε values are not positive.
    """
    if not isinstance(spacecraft, Spacecraft):
        raise TypeError(f"spacecraft must be a mrpctl.Spacecraft, got {type(spacecraft).__name__}")
    tau = positive_scalar("tau", tau)
    alpha = nonnegative_scalar("decay_rate", decay_rate)
    order = order_value(order)
    margin_tol = positive_scalar("margin_tol", margin_tol)
    if epsilons is None:
        eps_grid = tau * np.logspace(-1.5, 1.5, 9)
    else:
        eps_grid = np.atleast_1d(np.asarray(epsilons, dtype=float))
        if eps_grid.ndim != 1 or eps_grid.size == 0 or not np.all(np.isfinite(eps_grid)) or np.any(eps_grid <= 0):
            raise SpecificationError(f"epsilons must be a non-empty list of finite values > 0, got {epsilons!r}")
    gain = math.exp(alpha * tau)
    if spacecraft.is_diagonal:
        # Per axis, in (σᵢ, ωᵢ/4): ẋ = [[0, 1], [0, 0]] x + [0; 1] v with v = uᵢ / (4Jᵢ), and
        # v = [K₁, K₂] x(t − τ) is the same loop for every axis, so it is synthesized once and
        # scaled: K = [4 J K₁, 4 J K₂].
        a_s = np.array([[alpha, 1.0], [0.0, alpha]])
        b_s = gain * np.array([[0.0], [1.0]])
        where = "the per-axis loop"
    else:
        a_s = np.block([[np.zeros((3, 3)), np.eye(3)], [np.zeros((3, 3)), np.zeros((3, 3))]]) + alpha * np.eye(6)
        b_s = gain * np.vstack((np.zeros((3, 3)), spacecraft.inertia_inverse / 4.0))
        where = "the 6x6 loop"
    k_part, eps, solves, text = _synthesize_pair(a_s, b_s, tau, order, eps_grid)
    if k_part is None:
        status = SynthesisStatus.SOLVER_FAILED if text == "solver failed" else SynthesisStatus.INFEASIBLE
        return LMISynthesis(
            status,
            tau,
            alpha,
            order,
            None,
            math.nan,
            None,
            None,
            None,
            solves,
            f"synthesis LMI {text} for {where} at every epsilon tried",
        )
    if spacecraft.is_diagonal:
        k = gain_from_pd(spacecraft, np.full(3, k_part[0, 0]), np.full(3, k_part[0, 1]))
    else:
        k = k_part
    loop = linearized_loop(spacecraft, k)
    cert = loop.certify(tau, order=order, margin_tol=margin_tol)
    decay_cert = _shifted_certificate(loop, alpha, tau, order, margin_tol)
    margin = delay_margin(loop.A, loop.A_d)
    verified = cert.certified and decay_cert.certified and margin.margin > tau
    if verified:
        reason = f"K certified at tau and for decay rate {alpha:g} 1/s; exact margin {margin.margin:.6g} s"
    else:
        reason = "re-verification failed: " + "; ".join(
            text
            for ok, text in (
                (cert.certified, f"certificate at tau: {cert.status.value}"),
                (decay_cert.certified, f"decay certificate: {decay_cert.status.value}"),
                (margin.margin > tau, f"exact margin {margin.margin:.6g} s"),
            )
            if not ok
        )
    return LMISynthesis(
        SynthesisStatus.SYNTHESIZED if verified else SynthesisStatus.NOT_VERIFIED,
        tau,
        alpha,
        order,
        frozen(k),
        eps,
        cert,
        decay_cert,
        margin,
        solves,
        reason,
    )


def _shifted_certificate(loop: Any, alpha: float, tau: float, order: int, margin_tol: float) -> Certificate:
    """certify ż = (A + αI) z + e^{ατ} A_d z(t − τ): exponential decay at rate α, per axis when split."""
    gain = math.exp(alpha * tau)
    pairs = loop.axes if loop.split else ((loop.A, loop.A_d),)
    certs = [
        _certify(a + alpha * np.eye(a.shape[0]), gain * a_d, tau, order, margin_tol, True, Positivity.RELAXED)
        for a, a_d in pairs
    ]
    worst = min(certs, key=lambda c: (c.certified, c.min_margin if c.margins else -math.inf))
    if all(c.certified for c in certs):
        return worst
    if any(c.status is CertificateStatus.SOLVER_FAILED for c in certs):
        return next(c for c in certs if c.status is CertificateStatus.SOLVER_FAILED)
    return worst
