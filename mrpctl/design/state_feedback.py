"""State-feedback synthesis by LMI: a delayed u = K x(t − τ) certified at a decay rate (descriptor LMI),
nominal or over the loop as flown (inertia box, delay interval, sampling); `synthesize_lmi`.

PD synthesis is in `mrpctl.design.synthesis`, which re-exports this module's names.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mrpctl._validation import nonnegative_scalar, positive_scalar, readonly
from mrpctl.design._common import NOT_GIVEN, OPTIMAL, SynthesisStatus, axis_a, delay_rate_argument, order_value, solve
from mrpctl.design.interval import (
    DelayRate,
    UnknownRate,
    descriptor_interval_blocks,
    interval_unknowns,
    solve_lmi,
)
from mrpctl.design.lmi import (
    DEFAULT_MARGIN_TOL,
    WIRTINGER,
    Certificate,
    CertificateStatus,
    PerThread,
    Positivity,
    certify_checked,
    criterion_name,
    legendre_rows,
)
from mrpctl.design.loop import linearized_loop
from mrpctl.design.margin import DelayMargin, delay_margin
from mrpctl.design.polytope import (
    VERTEX_LIMIT,
    Functional,
    InertiaPolytope,
    PolytopeCertificate,
    certify_polytope,
    inertia_polytope,
    vertex_blocks,
)
from mrpctl.design.robust import (
    DelayModel,
    DelaySet,
    delay_set,
    exact_check_of_set,
)
from mrpctl.errors import SpecificationError
from mrpctl.model import gain_from_pd, plant_model
from mrpctl.spacecraft import Spacecraft, check_spacecraft

__all__ = ["LMISynthesis", "shifted_certificate", "synthesize_lmi"]

#: Largest α τ_max of synthesize_lmi: e^{ατ} scales the delayed term; e^36 = 4.3e15 is 1/eps of float64, beyond
#: which the shifted LMI cannot resolve the other terms (and e^{ατ} overflows from α τ = 709).
_MAX_DECAY_DELAY = 36.0


@dataclass(frozen=True, eq=False)
class LMISynthesis:
    """Result of [`synthesize_lmi`][mrpctl.design.synthesize_lmi]: a delayed state feedback u = K x(t − τ).

    With the robust options, ``certificate`` and ``decay_certificate`` are
    [`PolytopeCertificate`][mrpctl.design.PolytopeCertificate] objects of the whole set (the independent
    analysis of K and of its α-shifted loops).

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
        [`certify`][mrpctl.design.certify] of ẋ = A x + B K x(t − τ) at τ (same order).
    decay_certificate : Certificate or None
        [`certify`][mrpctl.design.certify] of the shifted system ż = (A + αI) z + e^{ατ} B K z(t − τ).
    margin : DelayMargin or None
        Exact delay margin of the loop under K (at the nominal inertia).
    solves : int
        Synthesis LMI solves (ε line search).
    reason : str
    model : DelayModel
        The delay covered (robust synthesis; CONSTANT for the nominal one).
    tau_min, tau_max : float
        The delay interval covered (s): [τ, τ] for a constant delay, [d·h, d·h + h] = [τ, τ + h] for
        the sampled loop, [tau_min, τ] for the jitter.
    tolerance, product_bound : float
        The inertia set covered (0, 0: the nominal spacecraft).
    exact_check : str
        Robust synthesis: what the exact reference said about K over the set (empty otherwise).
    """

    status: SynthesisStatus
    tau: float
    decay_rate: float
    order: int
    K: np.ndarray | None = field(repr=False)
    epsilon: float
    certificate: Certificate | PolytopeCertificate | None = field(repr=False)
    decay_certificate: Certificate | PolytopeCertificate | None = field(repr=False)
    margin: DelayMargin | None = field(repr=False)
    solves: int
    reason: str
    model: DelayModel = DelayModel.CONSTANT
    tau_min: float = math.nan
    tau_max: float = math.nan
    tolerance: float = 0.0
    product_bound: float = 0.0
    exact_check: str = ""

    @property
    def synthesized(self) -> bool:
        """True when K was found and verified."""
        return self.status is SynthesisStatus.SYNTHESIZED

    @property
    def robust(self) -> bool:
        """True when the synthesis covered a delay interval, a sampled loop or an inertia set."""
        return self.model is not DelayModel.CONSTANT or self.tolerance > 0.0 or self.product_bound > 0.0

    def __str__(self) -> str:
        head = (
            f"LMI synthesis for tau = {self.tau:g} s, decay rate {self.decay_rate:g} 1/s "
            f"({criterion_name(self.order)}, descriptor method): {self.status.value}"
        )
        lines = [head]
        if self.robust:
            span = f"{self.model.value}, tau in [{self.tau_min:.6g}, {self.tau_max:.6g}] s"
            lines.append(
                f"  robust: {span}, "
                + (
                    "nominal inertia"
                    if self.tolerance == 0.0 and self.product_bound == 0.0
                    else f"inertia +/-{100 * self.tolerance:g} %, |J_ij| <= {self.product_bound:g} kg m^2"
                )
            )
            if self.exact_check:
                lines.append(f"  {self.exact_check}")
        lines.append(f"  {self.reason}")
        if self.K is not None:
            margin = self.margin.margin if self.margin is not None else math.nan
            lines.append(f"  epsilon = {self.epsilon:.4g} s; exact delay margin {margin:.6g} s")
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
        # deferred: cvxpy (about 1 s to import), only when an LMI is solved
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

        rows = legendre_rows(order)  # Δ_k over [x, x_d, Ω_0..Ω_{N−1}]
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


#: ``_synthesis_problem(n, m, order)``: compiled once per shape and per thread (thread-safe).
_synthesis_problem = PerThread(_SynthesisProblem)


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
    tolerance: float | None = None,
    product_bound: float | None = None,
    period: float | None = None,
    tau_min: float | None = None,
    delay_rate: DelayRate | float | None = None,
    rate: Any = NOT_GIVEN,
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

    Every K found is re-verified: [`certify`][mrpctl.design.certify] of the loop at τ and of the
    shifted loop (decay rate α), and [`delay_margin`][mrpctl.design.delay_margin] > τ.

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
    tolerance, product_bound : float, optional
        Robust synthesis over the inertia set of [`inertia_polytope`][mrpctl.design.inertia_polytope]
        (relative per-axis tolerance 0 <= tol < 1 of a diagonal nominal J; |J_ij| bound, kg m²).
    period : float, optional
        Robust synthesis for the sampled loop at period h (s), ZOH: the sawtooth τ(t) ∈ [τ, τ + h],
        τ̇ = 1 (τ/h must be whole).
    tau_min : float, optional
        Robust synthesis for the jitter τ(t) ∈ [tau_min, τ] (s); ``tau_min`` = τ is the constant delay.
    delay_rate : DelayRate or float, optional
        With ``tau_min``: bound on τ̇ (a number μ means |τ̇| <= μ; None: unknown); ``rate`` is its
        deprecated name.

    Returns
    -------
    LMISynthesis

    Notes
    -----
    **Robust synthesis** (any of ``tolerance``, ``product_bound``, ``period``, ``tau_min``,
    ``rate``; design/lmi.md section 7.8). The multipliers X = P₂⁻¹ and Y = K X are common to every
    vertex of the plant polytope, so the congruenced LMI is affine in the plant matrices (A, B) and
    the vertex LMIs cover the convex hull. Diagonal set: per axis the normalised loop has the input
    gain b = J₀/J ∈ [1/(1+tol), 1/(1−tol)] (2 vertices, one 2×2 synthesis shared by the axes);
    with products of inertia the 6×6 loop at the (deduplicated) vertices of the J⁻¹ box. Constant
    delay: the order-N functional of this function, vertex-dependent up to
    `VERTEX_LIMIT` vertices (common above). Jitter and sampled loop:
    the interval criterion of `interval` (order-N Bessel-Legendre with the
    reciprocally convex combination, N = 1: Wirtinger) in descriptor form
    (`descriptor_interval_blocks`), one functional common to the
    vertices; the decay rate enters as z = e^{αt} x, whose delayed gain e^{ατ(t)} varies in
    [e^{ατ_min}, e^{ατ_max}] (two more vertices). Every K found is re-verified by
    [`certify_polytope`][mrpctl.design.certify_polytope] (the analysis, at α = 0 and at the decay rate)
    and by the exact reference (the grid of exact constant-delay margins over the set, or the
    lifted spectral radius of the sampled loop at the box ends). The set equal to the nominal one
    (tolerance 0, no products, constant delay) runs the nominal synthesis above, number for number.

    Raises
    ------
    SpecificationError
        If τ <= 0 or NaN, α < 0 or NaN, ε values are not positive, or a robust option is invalid
        (tolerance < 0 or >= 1, τ/period not whole, both ``period`` and ``tau_min``, ``rate``
        without ``tau_min``, a coupled nominal J with a robust option).
    """
    spacecraft = check_spacecraft(spacecraft)
    tau = positive_scalar("tau", tau)
    alpha = nonnegative_scalar("decay_rate", decay_rate)
    order = order_value(order)
    margin_tol = positive_scalar("margin_tol", margin_tol)
    rate = delay_rate_argument(delay_rate, rate)
    robust = any(v is not None for v in (tolerance, product_bound, period, tau_min, rate))
    delays = delay_set(tau, period=period, tau_min=tau_min, delay_rate=rate)
    if alpha * delays.tau_max > _MAX_DECAY_DELAY:
        raise SpecificationError(
            f"decay_rate: alpha * tau_max = {alpha * delays.tau_max:g} is above {_MAX_DECAY_DELAY:g}: the shifted "
            f"loop's delayed term is scaled by e^(alpha tau) = {math.exp(min(alpha * delays.tau_max, 709.0)):.3g}"
            f"{'' if alpha * delays.tau_max < 709.0 else ' or more (overflow)'}, beyond float64's precision "
            "(1/eps = 4.5e15) against the other terms; ask for a smaller decay_rate"
        )
    poly = None
    if robust:
        poly = inertia_polytope(
            spacecraft,
            0.0 if tolerance is None else tolerance,
            product_bound=0.0 if product_bound is None else product_bound,
        )
    scale = delays.tau_max
    if epsilons is None:
        eps_grid = scale * np.logspace(-1.5, 1.5, 9)
    else:
        eps_grid = np.atleast_1d(np.asarray(epsilons, dtype=float))
        if eps_grid.ndim != 1 or eps_grid.size == 0 or not np.all(np.isfinite(eps_grid)) or np.any(eps_grid <= 0):
            raise SpecificationError(f"epsilons must be a non-empty list of finite values > 0, got {epsilons!r}")
    nominal_set = poly is None or (poly.tolerance == 0.0 and poly.product_bound == 0.0)
    if poly is not None and not (nominal_set and delays.model is DelayModel.CONSTANT):
        return _synthesize_lmi_robust(spacecraft, poly, delays, alpha, order, eps_grid, margin_tol)
    gain = math.exp(alpha * tau)
    if spacecraft.is_diagonal:
        # Per axis, in (σᵢ, ωᵢ/4): ẋ = [[0, 1], [0, 0]] x + [0; 1] v with v = uᵢ / (4Jᵢ), and
        # v = [K₁, K₂] x(t − τ) is the same loop for every axis, so it is synthesized once and
        # scaled: K = [4 J K₁, 4 J K₂].
        a_s = axis_a() + alpha * np.eye(2)
        b_s = gain * np.array([[0.0], [1.0]])
        where = "the per-axis loop"
    else:
        plant = plant_model(spacecraft)
        a_s = plant.A + alpha * np.eye(6)
        b_s = gain * plant.B
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
            tau_min=tau,
            tau_max=tau,
        )
    if spacecraft.is_diagonal:
        k = gain_from_pd(spacecraft, np.full(3, k_part[0, 0]), np.full(3, k_part[0, 1]))
    else:
        k = k_part
    loop = linearized_loop(spacecraft, k)
    cert = loop.certify(tau, order=order, margin_tol=margin_tol)
    decay_cert = shifted_certificate(loop, alpha, tau, order, margin_tol, Positivity.RELAXED)
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
        readonly(k),
        eps,
        cert,
        decay_cert,
        margin,
        solves,
        reason,
        tau_min=tau,
        tau_max=tau,
    )


# --------------------------------------------------------------------------------------------
# Robust descriptor synthesis: common X = P₂⁻¹ and Y = K X over the vertices of the plant polytope.
# Time is normalised by τ_max (A·τ_max, B·τ_max, ε/τ_max); K is unchanged by the normalisation.
# --------------------------------------------------------------------------------------------


def _robust_plants(
    spacecraft: Spacecraft, poly: InertiaPolytope, delays: DelaySet, alpha: float
) -> tuple[np.ndarray, list[np.ndarray], list[float], bool]:
    """(A + αI, the vertex input matrices B_i, the delayed gains g, per-axis?) of the shifted loop."""
    if poly.diagonal:
        a = axis_a() + alpha * np.eye(2)
        ends = sorted({1.0 / (1.0 + poly.tolerance), 1.0 / (1.0 - poly.tolerance)})
        bs = [np.array([[0.0], [b]]) for b in ends]
        split = True
    else:
        a = plant_model(spacecraft).A + alpha * np.eye(6)
        bs = []
        seen: set[bytes] = set()
        for jinv in poly.vertices:
            if jinv.tobytes() not in seen:
                seen.add(jinv.tobytes())
                bs.append(np.vstack((np.zeros((3, 3)), jinv / 4.0)))
        split = False
    ends_t = (delays.tau_max,) if delays.model is DelayModel.CONSTANT else (delays.tau_min, delays.tau_max)
    gains = sorted({math.exp(alpha * t) for t in ends_t})
    return a, bs, gains, split


def _constant_blocks(
    plants: list[tuple[np.ndarray, np.ndarray]], order: int, eps: float, vertex: bool
) -> tuple[list[UnknownRate], Any, list[str]]:
    """Unknowns, block function and normalised blocks of the constant-delay descriptor synthesis (τ = 1).

    ζ̃ = [x; x(t − 1); Ω₀ … Ω_{N−1}; ẋ] as in `vertex_blocks`, whose
    plant-free part Ψ (A = A_d = 0, M = 0) is reused; the descriptor term after the congruence is
    He((e_x + ε e_ẋ)ᵀ (A X e_x + B Y e_d − X e_ẋ)).
    """
    n, m = plants[0][0].shape[0], plants[0][1].shape[1]
    size = (order + 1) * n
    k = (order + 3) * n
    zero_n = np.zeros((n, n))
    zero_m = np.zeros((k, n))
    ex = np.zeros((n, k))
    ex[:, :n] = np.eye(n)
    ed = np.zeros((n, k))
    ed[:, n : 2 * n] = np.eye(n)
    edx = np.zeros((n, k))
    edx[:, k - n :] = np.eye(n)
    left = ex + eps * edx
    tags = [str(i) for i in range(len(plants))] if vertex else [""]
    unknowns = []
    for tag in tags:
        unknowns += [UnknownRate(f"P{tag}", size, size, True), UnknownRate(f"S{tag}", n, n, True)]
        unknowns.append(UnknownRate(f"R{tag}", n, n, True))
    unknowns += [UnknownRate("G", n, n, False), UnknownRate("Y", m, n, False)]

    def blocks(mats: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        out: dict[str, np.ndarray] = {}
        g, y = mats["G"], mats["Y"]
        for i, (a, b) in enumerate(plants):
            tag = tags[i] if vertex else ""
            base = vertex_blocks(zero_n, zero_n, mats[f"P{tag}"], mats[f"S{tag}"], mats[f"R{tag}"], zero_m, order=order)
            desc = left.T @ (a @ g @ ex + b @ y @ ed - g @ edx)
            out[f"derivative[vertex {i}]"] = base["derivative"] - (desc + desc.T)
            if vertex or i == 0:
                for name in ("S", "R", "positivity"):
                    out[f"{name}[vertex {i}]"] = base[name]
        return out

    count = len(plants) if vertex else 1
    normalise = [f"{name}[vertex {i}]" for i in range(count) for name in ("S", "R", "positivity")]
    return unknowns, blocks, normalise


def _interval_problem(
    plants: list[tuple[np.ndarray, np.ndarray]], h1: float, rate: DelayRate, order: int, eps: float
) -> tuple[list[UnknownRate], Any, list[str]]:
    """Unknowns, block function and normalised blocks of the interval descriptor synthesis (τ_max = 1)."""
    n, m = plants[0][0].shape[0], plants[0][1].shape[1]
    unknowns = interval_unknowns(n, order, h1 > 0.0, rate)
    normalise = [u.name for u in unknowns if u.symmetric]
    unknowns += [UnknownRate("G", n, n, False), UnknownRate("Y", m, n, False)]
    fixed = {key: np.zeros((n, n)) for key in ("S1", "R1", "Q", "U", "Z")}

    def blocks(mats: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        return descriptor_interval_blocks(plants, h1, rate, {**fixed, **mats}, order=order, epsilon=eps)

    return unknowns, blocks, normalise


def _robust_gain(
    plants: list[tuple[np.ndarray, np.ndarray]],
    delays: DelaySet,
    order: int,
    eps_grid: np.ndarray,
    vertex: bool,
) -> tuple[np.ndarray | None, float, int, str]:
    """Line search on ε of the robust synthesis LMI; (K, ε (s), solves, status text) for the best t > 0."""
    hi = delays.tau_max
    scaled = [(hi * a, hi * b) for a, b in plants]
    best: tuple[float, np.ndarray, float] | None = None
    statuses = []
    for eps in eps_grid:
        if delays.model is DelayModel.CONSTANT:
            unknowns, blocks, normalise = _constant_blocks(scaled, order, float(eps) / hi, vertex)
        else:
            unknowns, blocks, normalise = _interval_problem(
                scaled, delays.tau_min / hi, delays.delay_rate, order, float(eps) / hi
            )
        outcome, values, t_opt = solve_lmi(unknowns, blocks, {}, normalise)
        statuses.append(outcome.status)
        if values is None or not t_opt > 0.0 or (best is not None and t_opt <= best[0]):
            continue
        g = values["G"]
        if np.linalg.cond(g) > 1e12:
            continue
        best = (t_opt, values["Y"] @ np.linalg.inv(g), float(eps))
    if best is None:
        failed = all(st != OPTIMAL for st in statuses)
        return None, math.nan, len(eps_grid), "solver failed" if failed else "infeasible"
    return best[1], best[2], len(eps_grid), "optimal"


def _synthesize_lmi_robust(
    spacecraft: Spacecraft,
    poly: InertiaPolytope,
    delays: DelaySet,
    alpha: float,
    order: int,
    eps_grid: np.ndarray,
    margin_tol: float,
) -> LMISynthesis:
    a, bs, gains, split = _robust_plants(spacecraft, poly, delays, alpha)
    plants = [(a, g * b) for b in bs for g in gains]
    vertex = delays.model is DelayModel.CONSTANT and len(plants) <= VERTEX_LIMIT
    functional = Functional.VERTEX if vertex else Functional.COMMON
    where = (
        f"{'the per-axis loop' if split else 'the 6x6 loop'} at {len(plants)} vertices "
        f"({functional.value}), {delays.model.value}"
    )
    k_part, eps, solves, text = _robust_gain(plants, delays, order, eps_grid, vertex)
    lo, hi = delays.tau_min, delays.tau_max
    base: dict[str, Any] = {
        "model": delays.model,
        "tau_min": lo,
        "tau_max": hi,
        "tolerance": poly.tolerance,
        "product_bound": poly.product_bound,
    }
    tau = hi if delays.model is not DelayModel.SAMPLED else lo
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
            f"robust synthesis LMI {text} for {where} at every epsilon tried",
            **base,
        )
    k = gain_from_pd(spacecraft, np.full(3, k_part[0, 0]), np.full(3, k_part[0, 1])) if split else k_part
    interval = delays.model is not DelayModel.CONSTANT
    extra: dict[str, Any] = {"tau_min": lo, "delay_rate": delays.delay_rate} if interval else {}
    cert = certify_polytope(poly, k, hi, order=order, margin_tol=margin_tol, **extra)
    decay_cert = certify_polytope(poly, k, hi, order=order, margin_tol=margin_tol, decay_rate=alpha, **extra)
    exact_ok, exact_text = exact_check_of_set(poly, k, delays.model, lo, hi, delays.period, delays.samples)
    loop = linearized_loop(spacecraft, k)
    margin = delay_margin(loop.A, loop.A_d)
    checks = (
        (cert.certified, f"certificate of the set: {cert.status.value}"),
        (decay_cert.certified, f"decay certificate of the set: {decay_cert.status.value}"),
        (exact_ok, exact_text),
    )
    failed = [why for ok, why in checks if not ok]
    if failed:
        status, reason = SynthesisStatus.NOT_VERIFIED, "re-verification failed: " + "; ".join(failed)
    else:
        status = SynthesisStatus.SYNTHESIZED
        reason = (
            f"K synthesized for {where}; certified for the set at alpha = 0 and {alpha:g} 1/s "
            f"({cert.solve_time + decay_cert.solve_time:.2f} s of analysis)"
        )
    return LMISynthesis(
        status,
        tau,
        alpha,
        order,
        readonly(k),
        eps,
        cert,
        decay_cert,
        margin,
        solves,
        reason,
        exact_check=exact_text,
        **base,
    )


def shifted_certificate(
    loop: Any, alpha: float, tau: float, order: int, margin_tol: float, positivity: Positivity
) -> Certificate:
    """certify ż = (A + αI) z + e^{ατ} A_d z(t − τ): exponential decay at rate α, per axis when split."""
    gain = math.exp(alpha * tau)
    pairs = loop.axes if loop.split else ((loop.A, loop.A_d),)
    cache: dict[bytes, Certificate] = {}
    certs = []
    for a, a_d in pairs:
        key = a_d.tobytes()
        if key not in cache:
            cache[key] = certify_checked(
                a + alpha * np.eye(a.shape[0]), gain * a_d, tau, order, margin_tol, True, positivity
            )
        certs.append(cache[key])
    worst = min(certs, key=lambda c: (c.certified, c.min_margin if c.margins else -math.inf))
    if all(c.certified for c in certs):
        return worst
    if any(c.status is CertificateStatus.SOLVER_FAILED for c in certs):
        return next(c for c in certs if c.status is CertificateStatus.SOLVER_FAILED)
    return worst
