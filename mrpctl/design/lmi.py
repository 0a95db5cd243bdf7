"""Delay-dependent Lyapunov-Krasovskii LMIs (Jensen, Wirtinger, Bessel-Legendre N): certify τ, search τ."""

from __future__ import annotations

import enum
import logging
import math
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mrpctl._validation import positive_scalar, readonly
from mrpctl.design._common import OPTIMAL, balancing, order_value, similarity, solve, system_matrices
from mrpctl.design.margin import delay_margin
from mrpctl.errors import SpecificationError

__all__ = [
    "JENSEN",
    "WIRTINGER",
    "BlockMargin",
    "Certificate",
    "CertificateStatus",
    "DelayCertification",
    "Positivity",
    "SearchStatus",
    "certify",
    "criterion_name",
    "lmi_blocks",
    "max_certified_delay",
]

_LOG = logging.getLogger(__name__)

#: Order of the Jensen-based criterion (Bessel-Legendre N = 0).
JENSEN = 0
#: Order of the Wirtinger-based criterion (Seuret & Gouaisbaut 2013; Bessel-Legendre N = 1).
WIRTINGER = 1

#: Default relative eigenvalue margin an LMI block must keep in the float64 recomputation.
DEFAULT_MARGIN_TOL = 1e-9


def criterion_name(order: int) -> str:
    """Human name of the criterion of Bessel-Legendre order N."""
    if order == JENSEN:
        return "Jensen (N=0)"
    if order == WIRTINGER:
        return "Wirtinger (N=1)"
    return f"Bessel-Legendre N={order}"


class Positivity(enum.Enum):
    """Which positivity condition makes V_N(x_t) >= ε|x(t)|²."""

    #: P ≻ 0, as in Seuret & Gouaisbaut (2013, 2015).
    STRICT = "P > 0"
    #: τP + diag(0, S, 3S, ..., (2N−1)S) ≻ 0: Bessel's inequality applied to ∫xᵀSx (sound, less conservative).
    RELAXED = "tau P + diag(0, S, 3S, ...) > 0"


class CertificateStatus(enum.Enum):
    """Outcome of one LMI test at a fixed delay."""

    CERTIFIED = "certified"
    NOT_CERTIFIED = "not certified"
    SOLVER_FAILED = "solver failed"


@dataclass(frozen=True, eq=False)
class BlockMargin:
    """Smallest eigenvalue of one LMI block, sign chosen so that positive means satisfied.

    Attributes
    ----------
    name : str
        ``"S"``, ``"R"``, ``"positivity"`` (τP + diag(0, S, 3S, ...)) or ``"derivative"`` (−Φ_N(τ)).
    eigenvalue : float
        λ_min of the block, recomputed in float64 from the returned decision matrices.
    relative : float
        ``eigenvalue`` divided by the 2-norm of the block.
    """

    name: str
    eigenvalue: float
    relative: float


@dataclass(frozen=True, eq=False)
class Certificate:
    """Result of [`certify`][mrpctl.design.certify]: an LMI test of ẋ = A x + A_d x(t − τ) at one delay τ.

    Attributes
    ----------
    status : CertificateStatus
        CERTIFIED only when the solver reported ``optimal`` and every block of the float64
        recomputation keeps a relative margin of at least ``margin_tol``.
    order : int
        Bessel-Legendre order N (0 Jensen, 1 Wirtinger).
    tau : float
        The delay τ (s).
    P, S, R : numpy.ndarray or None
        Decision matrices of the functional V_N (read-only); None when the solver failed.
        P is ((N+1)n, (N+1)n) and acts on ξ = [x(t); τΩ₀; ...; τΩ_{N−1}].
    margins : tuple of BlockMargin
        The recomputed smallest eigenvalues, one per block.
    solver : str
        Solver name.
    solver_status : str
        The status string reported through cvxpy (or the error caught).
    solve_time : float
        Wall time of the solve call (s), compilation included.
    solver_margin : float
        The optimal common margin t of the normalised problem (positive means feasible); nan when
        the solver failed.
    positivity : Positivity
        The positivity condition used.
    reason : str
        One line explaining the status.
    """

    status: CertificateStatus
    order: int
    tau: float
    P: np.ndarray | None = field(repr=False)
    S: np.ndarray | None = field(repr=False)
    R: np.ndarray | None = field(repr=False)
    margins: tuple[BlockMargin, ...]
    solver: str
    solver_status: str
    solve_time: float
    solver_margin: float
    positivity: Positivity
    reason: str

    @property
    def certified(self) -> bool:
        """True when the LMI proves exponential stability at this τ."""
        return self.status is CertificateStatus.CERTIFIED

    @property
    def min_margin(self) -> float:
        """The smallest relative block margin (nan when nothing was recomputed)."""
        return min((m.relative for m in self.margins), default=math.nan)

    def __str__(self) -> str:
        head = (
            f"{criterion_name(self.order)} at tau = {self.tau:.6g} s: {self.status.value} "
            f"({self.solver} {self.solver_status}, {1e3 * self.solve_time:.1f} ms)"
        )
        lines = [head, f"  {self.reason}"]
        if self.margins:
            lines.append(
                "  lambda_min: "
                + ", ".join(f"{m.name} {m.eigenvalue:.3g} (rel {m.relative:.2g})" for m in self.margins)
            )
        return "\n".join(lines)


class SearchStatus(enum.Enum):
    """Outcome of [`max_certified_delay`][mrpctl.design.max_certified_delay]."""

    CERTIFIED = "certified interval found"
    SEARCH_LIMIT = "certified up to the search limit tau_max"
    NOT_CERTIFIED = "no delay certified"


@dataclass(frozen=True, eq=False)
class DelayCertification:
    """Result of [`max_certified_delay`][mrpctl.design.max_certified_delay]: the certified delay interval of one
    criterion.

    Attributes
    ----------
    status : SearchStatus
    order : int
        Bessel-Legendre order N.
    lower, upper : float
        Ends (s) of the certified interval [lower, upper] found by bisection to ``rtol``; 0.0 for
        ``lower`` when the certificate extends down to τ → 0; nan when nothing was certified.
    certificate : Certificate or None
        The certificate at ``upper`` (None when nothing was certified).
    solves : int
        Number of LMI solves.
    solve_time : float
        Total wall time of those solves (s).
    reason : str
    """

    status: SearchStatus
    order: int
    lower: float
    upper: float
    certificate: Certificate | None = field(repr=False)
    solves: int
    solve_time: float
    reason: str

    @property
    def certified(self) -> bool:
        """True when some delay interval was certified."""
        return self.status is not SearchStatus.NOT_CERTIFIED

    @property
    def tau(self) -> float:
        """The largest certified delay (s); nan when nothing was certified."""
        return self.upper

    def __str__(self) -> str:
        if not self.certified:
            return f"{criterion_name(self.order)}: {self.status.value} ({self.reason})"
        span = f"tau <= {self.upper:.6g} s" if self.lower == 0.0 else f"tau in [{self.lower:.6g}, {self.upper:.6g}] s"
        return (
            f"{criterion_name(self.order)}: certified for {span} "
            f"({self.solves} solves, {self.solve_time:.3f} s; {self.reason})"
        )


# --------------------------------------------------------------------------------------------
# The criterion, written once for every order N.
#
# ζ = [x(t); x(t − τ); Ω₀; ...; Ω_{N−1}],  Ω_k = (1/τ) ∫_{t−τ}^{t} L_k((s − t + τ)/τ) x(s) ds,
# L_k the Legendre polynomials shifted to [0, 1] (L_k(1) = 1, L_k(0) = (−1)^k).
# Δ_k = ∫ L_k ẋ ds = x(t) − (−1)^k x(t − τ) − Σ_{j<k, k+j odd} 2(2j+1) Ω_j = E_k ζ, and τ Ω̇_k = Δ_k.
# V_N = ξᵀ P ξ + ∫ xᵀ S x ds + τ ∫∫ ẋᵀ R ẋ,  ξ = [x; τΩ₀; ...; τΩ_{N−1}] = G(τ) ζ,  ξ̇ = H ζ.
# --------------------------------------------------------------------------------------------


def legendre_rows(order: int) -> np.ndarray:
    """Coefficients c_k (k = 0..N) with Δ_k = Σ_i c_k[i] ζ_i on the N+2 blocks of ζ."""
    rows = np.zeros((order + 1, order + 2))
    for k in range(order + 1):
        rows[k, 0] = 1.0
        rows[k, 1] = -((-1.0) ** k)
        for j in range(k):
            if (k + j) % 2 == 1:
                rows[k, 2 + j] = -2.0 * (2 * j + 1)
    return rows


def lmi_structure(n: int, order: int) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """(E_0..E_N as (n, m) arrays, G0 = [I 0 0], G1 = [0 0 I_{Nn}]) for ζ of size m = (N+2)n."""
    rows = legendre_rows(order)
    eye = np.eye(n)
    e_mats = [np.kron(rows[k], eye) for k in range(order + 1)]
    m = (order + 2) * n
    g0 = np.zeros((n, m))
    g0[:, :n] = eye
    g1 = np.zeros((order * n, m))
    g1[:, 2 * n :] = np.eye(order * n)
    return e_mats, g0, g1


def lmi_blocks(
    A: Any,
    A_d: Any,
    tau: float,
    P: Any,
    S: Any,
    R: Any,
    *,
    order: int,
    positivity: Positivity = Positivity.RELAXED,
) -> dict[str, np.ndarray]:
    """The LMI blocks of the order-N criterion in float64, written directly (no Schur complement).

    Used to re-verify every solver answer independently of the cvxpy model. Each returned block
    must be positive definite for a certificate:

    - ``"S"``: S, ``"R"``: R;
    - ``"positivity"``: τP + diag(0, S, 3S, ..., (2N−1)S)  (V_N >= ε|x|², Bessel on ∫xᵀSx), or τP
      for ``Positivity.STRICT``;
    - ``"derivative"``: −Φ_N(τ) with
      Φ_N(τ) = He(G(τ)ᵀ P H) + diag(S, −S, 0) + τ² F₀ᵀ R F₀ − Σ_{k=0}^{N} (2k+1) E_kᵀ R E_k,
      F₀ = [A, A_d, 0].

    Parameters
    ----------
    A, A_d : array_like
        (n, n) system matrices.
    tau : float
        Delay τ (s).
    P, S, R : array_like
        Decision matrices, ((N+1)n)² and n² symmetric.
    order : int
        Bessel-Legendre order N.
    """
    a, a_d = system_matrices(A, A_d)
    n = a.shape[0]
    p = np.asarray(P, dtype=float)
    s = np.asarray(S, dtype=float)
    r = np.asarray(R, dtype=float)
    e_mats, g0, g1 = lmi_structure(n, order)
    m = (order + 2) * n
    f0 = np.zeros((n, m))
    f0[:, :n] = a
    f0[:, n : 2 * n] = a_d
    g = np.vstack((g0, tau * g1))
    h = np.vstack([f0, *e_mats[:order]]) if order else f0
    he = g.T @ p @ h
    phi = he + he.T
    phi[:n, :n] += s
    phi[n : 2 * n, n : 2 * n] -= s
    phi += tau**2 * f0.T @ r @ f0
    for k, e in enumerate(e_mats):
        phi -= (2 * k + 1) * e.T @ r @ e
    pos = tau * p
    for k in range(order if positivity is Positivity.RELAXED else 0):
        sl = slice((k + 1) * n, (k + 2) * n)
        pos[sl, sl] += (2 * k + 1) * s
    return {"S": _sym(s), "R": _sym(r), "positivity": _sym(pos), "derivative": _sym(-phi)}


def _sym(m: np.ndarray) -> np.ndarray:
    return 0.5 * (m + m.T)


def block_margins(blocks: dict[str, np.ndarray]) -> tuple[BlockMargin, ...]:
    """λ_min and λ_min/‖block‖₂ of every block of [`lmi_blocks`][mrpctl.design.lmi_blocks] (positive means
    satisfied)."""
    out = []
    for name, block in blocks.items():
        eig = float(np.linalg.eigvalsh(block)[0])
        norm = float(np.linalg.norm(block, 2))
        out.append(BlockMargin(name, eig, eig / norm if norm > 0 else -math.inf))
    return tuple(out)


class _AnalysisProblem:
    """The order-N analysis LMI as a cvxpy problem, parameterised in (A, A_d, τ, τA, τA_d).

    Every product is parameter × variable (DPP), so the problem compiles once per (n, N):
    τ G₁ᵀ P H needs τA and τA_d as their own Parameters, and the τ² F₀ᵀ R F₀ term becomes the
    Schur complement [[Φ₀, (τF₀)ᵀ R], [R τF₀, −R]] ≺ 0 (R ≻ 0), in which τ only multiplies
    variables. With ``parametric=False`` the same LMI is built from constants (for benchmarks).
    Decision variables are normalised (tr(τP + D_S) + tr S + tr R = 1) and the common
    eigenvalue margin t is maximised: the problem is always feasible and bounded, and t > 0
    means certified.
    """

    def __init__(self, n: int, order: int, positivity: Positivity, values: dict[str, Any] | None = None) -> None:
        # deferred: cvxpy (about 1 s to import), only when an LMI is solved
        import cvxpy as cp

        self.n, self.order = n, order
        m = (order + 2) * n
        if values is None:
            self.params = {
                "tau": cp.Parameter(nonneg=True, name="tau"),
                "A": cp.Parameter((n, n), name="A"),
                "A_d": cp.Parameter((n, n), name="A_d"),
                "tauA": cp.Parameter((n, n), name="tauA"),
                "tauA_d": cp.Parameter((n, n), name="tauA_d"),
            }
            sym = self.params
        else:
            self.params = {}
            sym = values
        tau, a, a_d, tau_a, tau_a_d = sym["tau"], sym["A"], sym["A_d"], sym["tauA"], sym["tauA_d"]
        self.P = cp.Variable(((order + 1) * n, (order + 1) * n), symmetric=True, name="P")
        self.S = cp.Variable((n, n), symmetric=True, name="S")
        self.R = cp.Variable((n, n), symmetric=True, name="R")
        self.t = cp.Variable(name="t")
        P, S, R, t = self.P, self.S, self.R, self.t
        e_mats, g0, g1 = lmi_structure(n, order)
        zeros_n = np.zeros((n, n))
        z_rest = np.zeros((n, order * n))
        # G(τ)ᵀ P H = G0ᵀ (P[0,:] H) + G1ᵀ (τ P[1:,:] H); H = [F₀; E_0..E_{N−1}].
        f0 = cp.hstack([a, a_d, z_rest]) if order else cp.hstack([a, a_d])
        tf0 = cp.hstack([tau_a, tau_a_d, z_rest]) if order else cp.hstack([tau_a, tau_a_d])
        e_stack = np.vstack(e_mats[:order]) if order else None
        top = P[:n, :n] @ f0
        if order:
            top = top + P[:n, n:] @ e_stack
        he = g0.T @ top
        if order:
            lower = P[n:, :n] @ tf0 + tau * (P[n:, n:] @ e_stack)
            he = he + g1.T @ lower
        s_tilde = (
            cp.bmat(
                [
                    [S, zeros_n, np.zeros((n, order * n))],
                    [zeros_n, -S, np.zeros((n, order * n))],
                    [np.zeros((order * n, n)), np.zeros((order * n, n)), np.zeros((order * n, order * n))],
                ]
            )
            if order
            else cp.bmat([[S, zeros_n], [zeros_n, -S]])
        )
        phi0 = he + he.T + s_tilde
        for k, e in enumerate(e_mats):
            phi0 = phi0 - (2 * k + 1) * (e.T @ R @ e)
        rtf0 = R @ tf0
        lmi = cp.bmat([[phi0, rtf0.T], [rtf0, -R]])
        lmi = 0.5 * (lmi + lmi.T)
        size = m + n
        if order and positivity is Positivity.RELAXED:
            d_s = cp.bmat(
                [
                    [np.zeros((n, n)), np.zeros((n, order * n))],
                    [np.zeros((order * n, n)), _diag_blocks(S, order)],
                ]
            )
            pos = tau * P + d_s
        else:
            pos = tau * P
        pos = 0.5 * (pos + pos.T)
        self.constraints = [
            -lmi >> t * np.eye(size),
            pos >> t * np.eye((order + 1) * n),
            S >> t * np.eye(n),
            R >> t * np.eye(n),
            cp.trace(pos) + cp.trace(S) + cp.trace(R) == 1.0,
        ]
        self.problem = cp.Problem(cp.Maximize(t), self.constraints)

    def set(self, a: np.ndarray, a_d: np.ndarray, tau: float) -> None:
        self.params["tau"].value = tau
        self.params["A"].value = a
        self.params["A_d"].value = a_d
        self.params["tauA"].value = tau * a
        self.params["tauA_d"].value = tau * a_d


def _diag_blocks(S: Any, order: int) -> Any:
    # deferred: cvxpy (about 1 s to import), only when an LMI is solved
    import cvxpy as cp

    n = S.shape[0]
    rows = []
    for i in range(order):
        row = []
        for j in range(order):
            row.append((2 * i + 1) * S if i == j else np.zeros((n, n)))
        rows.append(row)
    return cp.bmat(rows)


class PerThread:
    """Compiled problems, one set per thread: a cvxpy Problem holds its Parameter values and its
    solution in place, so two threads sharing one would read each other's answers."""

    def __init__(self, build: Callable[..., Any]) -> None:
        self._build = build
        self._local = threading.local()
        self._generation = 0

    def __call__(self, *key: Any) -> Any:
        store = getattr(self._local, "store", None)
        if store is None or self._local.generation != self._generation:
            store = self._local.store = {}
            self._local.generation = self._generation
        if key not in store:
            store[key] = self._build(*key)
        return store[key]

    def cache_clear(self) -> None:
        """Forget the compiled problems of every thread (they are rebuilt on the next call)."""
        self._generation += 1


#: ``_compiled(n, order, positivity)``: the analysis problem compiled once per (n, N) and per thread.
_compiled = PerThread(_AnalysisProblem)


def unit_delay_system(a: np.ndarray, a_d: np.ndarray, tau: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(τ T⁻¹AT, τ T⁻¹A_dT, diag of T): the system in normalised time t/τ (unit delay), balanced.

    With y = T⁻¹x and t' = t/τ, ẋ = A x + A_d x(t − τ) becomes y' = τT⁻¹AT y + τT⁻¹A_dT y(t' − 1).
    T is the diagonal power-of-two balancing of |τA| + |τA_d| (exact in floating point), so the
    normalised problem is the same for c·(A, A_d) at τ/c and is well scaled for τ from 1e-4 to 1e3 s.
    """
    scale = balancing(tau * a, tau * a_d)
    return tau * similarity(a, scale), tau * similarity(a_d, scale), scale


def _xi_scaling(scale: np.ndarray, tau: float, order: int) -> np.ndarray:
    """Diagonal of D T_b: ξ = [x; τΩ₀; ...] = D T_b ξ̃ with ξ̃ = [y; Ω̃₀; ...] of the unit-delay system."""
    return np.concatenate([scale] + [tau * scale] * order)


def from_unit_delay(
    p: np.ndarray, s: np.ndarray, r: np.ndarray, scale: np.ndarray, tau: float, order: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Map a certificate (P̃, S̃, R̃) of `unit_delay_system` back to (P, S, R) of (A, A_d) at τ.

    V(x_t) = τ Ṽ(y_t'): P = τ (DT_b)⁻¹ P̃ (DT_b)⁻¹, S = T⁻¹ S̃ T⁻¹, R = T⁻¹ R̃ T⁻¹ (``design/lmi.md``).
    """
    d = 1.0 / _xi_scaling(scale, tau, order)
    inv = 1.0 / scale
    return tau * (d[:, None] * p * d[None, :]), inv[:, None] * s * inv[None, :], inv[:, None] * r * inv[None, :]


def to_unit_delay(
    p: np.ndarray, s: np.ndarray, r: np.ndarray, scale: np.ndarray, tau: float, order: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The inverse of `from_unit_delay`."""
    d = _xi_scaling(scale, tau, order)
    return (d[:, None] * p * d[None, :]) / tau, scale[:, None] * s * scale[None, :], scale[:, None] * r * scale[None, :]


def verified_margins(
    a: np.ndarray,
    a_d: np.ndarray,
    tau: float,
    p: np.ndarray,
    s: np.ndarray,
    r: np.ndarray,
    *,
    order: int,
    positivity: Positivity,
) -> tuple[BlockMargin, ...]:
    """Block margins of (P, S, R) for (A, A_d) at τ, recomputed in float64 on the unit-delay system.

    The blocks of the unit-delay system are congruent to those of the original one (the derivative
    block is identical, the positivity block is (1/τ²)(DT_b)ᵀ(τP + D_S)(DT_b)), so positive
    definiteness is the same; the unit-delay blocks are the well-scaled ones to test.
    """
    a_u, a_d_u, scale = unit_delay_system(a, a_d, tau)
    p_u, s_u, r_u = to_unit_delay(p, s, r, scale, tau, order)
    return block_margins(lmi_blocks(a_u, a_d_u, 1.0, p_u, s_u, r_u, order=order, positivity=positivity))


def certify(
    A: Any,
    A_d: Any,
    tau: float,
    *,
    order: int = 3,
    positivity: Positivity = Positivity.RELAXED,
    margin_tol: float = DEFAULT_MARGIN_TOL,
    parametric: bool = True,
) -> Certificate:
    """Test the order-N Bessel-Legendre Lyapunov-Krasovskii LMI for ẋ = A x + A_d x(t − τ).

    The criterion (Seuret & Gouaisbaut, Systems & Control Letters 81, 2015; N = 0 is the
    Jensen-based and N = 1 the Wirtinger-based criterion of Seuret & Gouaisbaut, Automatica 49,
    2013): find P ∈ S^{(N+1)n}, S, R ∈ Sⁿ with S ≻ 0, R ≻ 0, a positivity condition (P ≻ 0, or
    the relaxed τP + diag(0, S, 3S, ..., (2N−1)S) ≻ 0) and Φ_N(τ) ≺ 0 (see [`lmi_blocks`][mrpctl.design.lmi_blocks]
    and ``design/lmi.md``). Exponential stability at τ follows.

    The result is CERTIFIED only when Clarabel reports ``optimal`` and an independent float64
    recomputation of every block from the returned P, S, R is positive definite with relative
    margin (λ_min / ‖block‖₂) of at least ``margin_tol``. ``optimal_inaccurate`` never certifies.
    Solver errors and Rust panics become SOLVER_FAILED, never exceptions.

    Parameters
    ----------
    A, A_d : array_like
        (n, n) system matrices (1/s).
    tau : float
        The delay τ > 0 (s).
    order : int, optional
        Bessel-Legendre order N >= 0 (keyword-only; 0 Jensen, 1 Wirtinger). Default 3.
    positivity : Positivity, optional
        RELAXED (default) or STRICT (P ≻ 0, the literature's condition).
    margin_tol : float, optional
        Required relative eigenvalue margin of each block (default 1e-9).
    parametric : bool, optional
        True (default) reuses the problem compiled once per (n, N) with cvxpy Parameters;
        False builds it from constants at every call (slower; for benchmarks).

    Returns
    -------
    Certificate

    Raises
    ------
    DimensionError
        If A is not square or A_d does not match it.
    SpecificationError
        If τ is not a finite positive number, or ``order`` or ``margin_tol`` is invalid.

    Examples
    --------
    >>> certify([[-2, 0], [0, -0.9]], [[-1, 0], [-1, -1]], 4.0, order=0).certified
    True
    """
    a, a_d = system_matrices(A, A_d)
    tau = positive_scalar("tau", tau)
    order = order_value(order)
    positivity = check_positivity(positivity)
    margin_tol = positive_scalar("margin_tol", margin_tol)
    return certify_checked(a, a_d, tau, order, margin_tol, parametric, positivity)


def check_positivity(value: Any) -> Positivity:
    """Return ``value`` if it is a [`Positivity`][mrpctl.design.Positivity] member, else raise SpecificationError."""
    if not isinstance(value, Positivity):
        raise SpecificationError(f"positivity must be a Positivity member, got {value!r}")
    return value


def certify_checked(
    a: np.ndarray,
    a_d: np.ndarray,
    tau: float,
    order: int,
    margin_tol: float,
    parametric: bool,
    positivity: Positivity,
) -> Certificate:
    """[`certify`][mrpctl.design.certify] on checked inputs: solved on `unit_delay_system`, mapped back, re-verified."""
    n = a.shape[0]
    a_u, a_d_u, scale = unit_delay_system(a, a_d, tau)
    if parametric:
        lmi = _compiled(n, order, positivity)
        lmi.set(a_u, a_d_u, 1.0)
    else:
        values = {"tau": 1.0, "A": a_u, "A_d": a_d_u, "tauA": a_u, "tauA_d": a_d_u}
        lmi = _AnalysisProblem(n, order, positivity, values)
    outcome = solve(lmi.problem)
    base: dict[str, Any] = {
        "order": order,
        "tau": tau,
        "solver": "CLARABEL",
        "solve_time": outcome.time,
        "solver_status": outcome.status,
        "positivity": positivity,
    }
    failed: dict[str, Any] = {"status": CertificateStatus.SOLVER_FAILED, "P": None, "S": None, "R": None, "margins": ()}
    if outcome.error:
        return Certificate(**failed, solver_margin=math.nan, reason=outcome.error, **base)
    solution = [lmi.P.value, lmi.S.value, lmi.R.value, lmi.t.value]
    if outcome.status != OPTIMAL or any(v is None for v in solution):
        reason = f"solver status {outcome.status!r} is not 'optimal': no certificate"
        return Certificate(**failed, solver_margin=math.nan, reason=reason, **base)
    p_u, s_u, r_u = (_sym(np.asarray(v, dtype=float)) for v in solution[:3])
    t_opt = float(solution[3])
    margins = block_margins(lmi_blocks(a_u, a_d_u, 1.0, p_u, s_u, r_u, order=order, positivity=positivity))
    p, s, r = (_sym(m) for m in from_unit_delay(p_u, s_u, r_u, scale, tau, order))
    worst = min(margins, key=lambda m: m.relative)
    if worst.relative >= margin_tol:
        status = CertificateStatus.CERTIFIED
        reason = f"every block positive definite; smallest relative margin {worst.relative:.3g} ({worst.name})"
    else:
        status = CertificateStatus.NOT_CERTIFIED
        reason = (
            f"block {worst.name!r} has relative margin {worst.relative:.3g} < {margin_tol:g} "
            f"(solver margin t = {t_opt:.3g})"
        )
    return Certificate(
        status=status,
        P=readonly(p),
        S=readonly(s),
        R=readonly(r),
        margins=margins,
        solver_margin=t_opt,
        reason=reason,
        **base,
    )


def max_certified_delay(
    A: Any,
    A_d: Any,
    *,
    order: int = 3,
    rtol: float = 1e-4,
    positivity: Positivity = Positivity.RELAXED,
    tau_max: float | None = None,
    margin_tol: float = DEFAULT_MARGIN_TOL,
    parametric: bool = True,
) -> DelayCertification:
    """The largest delay τ (s) the order-N criterion certifies for ẋ = A x + A_d x(t − τ).

    The exact analysis ([`delay_margin`][mrpctl.design.delay_margin]) only chooses where to look: its
    stable intervals are the only places a sound criterion can certify, so the search starts inside
    them, and a system stable at no delay returns NOT_CERTIFIED without a solve. The brackets are
    LMI answers only (the exact margin is tested, never assumed), so a certified delay above the
    exact margin would be reported as such. When A + A_d is not Hurwitz the certified set can still
    be an interval [lower, upper] with lower > 0; both ends are searched.

    Each end is found by a safeguarded secant search on the solver margin t(τ) (alternating with
    bisection, see `bracket_root`) until the bracket [certified, not certified] is narrower
    than ``rtol`` relative. τ enters the compiled problem as cvxpy
    Parameters, so the problem is compiled once per (n, N).

    Parameters
    ----------
    A, A_d : array_like
        (n, n) system matrices (1/s).
    order : int, optional
        Bessel-Legendre order N (keyword-only). Default 3.
    rtol : float, optional
        Relative width of the final brackets (default 1e-4).
    positivity : Positivity, optional
        Passed to [`certify`][mrpctl.design.certify].
    tau_max : float, optional
        Search limit (s) for systems stable for every delay; default 1e3 / max(‖A‖₂, ‖A_d‖₂).
    margin_tol : float, optional
        Relative eigenvalue margin passed to [`certify`][mrpctl.design.certify].
    parametric : bool, optional
        False rebuilds the cvxpy problem at every delay (for benchmarks).

    Returns
    -------
    DelayCertification

    Raises
    ------
    DimensionError, SpecificationError
        On malformed A, A_d or options.
    """

    a, a_d = system_matrices(A, A_d)
    order = order_value(order)
    positivity = check_positivity(positivity)
    rtol = positive_scalar("rtol", rtol)
    if rtol >= 0.5:
        raise SpecificationError(f"rtol must be < 0.5, got {rtol}")
    margin_tol = positive_scalar("margin_tol", margin_tol)
    scale = max(float(np.linalg.norm(a, 2)), float(np.linalg.norm(a_d, 2)), 1e-12)
    limit = 1e3 / scale if tau_max is None else positive_scalar("tau_max", tau_max)
    exact = delay_margin(a, a_d)
    search = _Search(a, a_d, order, margin_tol, parametric, positivity)
    if not exact.stable_intervals:
        return search.result(SearchStatus.NOT_CERTIFIED, math.nan, math.nan, None, f"exact analysis: {exact.reason}")
    for lo_exact, hi_exact in exact.stable_intervals:
        if lo_exact >= limit:
            break
        seed = search.seed(lo_exact, min(hi_exact, limit))
        if seed is None:
            continue
        tau_seed, cert_seed = seed
        upper, cert_upper, capped = search.upper(tau_seed, cert_seed, hi_exact, limit, rtol)
        lower = 0.0 if lo_exact == 0.0 else search.lower(tau_seed, cert_seed, lo_exact, rtol)
        status = SearchStatus.SEARCH_LIMIT if capped else SearchStatus.CERTIFIED
        if lo_exact == 0.0:
            reason = f"exact margin {exact.margin:.6g} s"
        else:
            reason = f"exact stable interval ({lo_exact:.6g}, {hi_exact:.6g}) s"
        if capped:
            reason += f"; still certified at tau_max = {limit:.6g} s"
        return search.result(status, lower, upper, cert_upper, reason)
    return search.result(
        SearchStatus.NOT_CERTIFIED,
        math.nan,
        math.nan,
        None,
        "no delay certified inside the exact stable intervals "
        + ", ".join(f"({lo:.6g}, {hi:.6g})" for lo, hi in exact.stable_intervals)
        + f" s: the {criterion_name(order)} criterion is too conservative here",
    )


def bracket_root(
    test: Callable[[float], Certificate],
    good: float,
    good_cert: Certificate,
    bad: float,
    rtol: float,
    *,
    max_steps: int = 200,
) -> tuple[float, Certificate]:
    """Shrink a bracket [good (certified), bad (not certified)] to ``rtol`` relative width.

    On the certified side the solver margin t decreases to 0 at the boundary; on the other side
    it is ≈ 0 and carries no information. So the step is a secant extrapolation of t through the
    last two certified points, aimed ``rtol/2`` past the predicted boundary so that one step can
    close the bracket, and a bisection step after every secant step that failed to certify (or
    when no two certified points exist yet). Works with ``bad`` on either side of ``good``.
    Returns the last certified point and its certificate.
    """
    points = [(good, good_cert.solver_margin)]
    bisect_next = True
    for _ in range(max_steps):
        width = bad - good
        tol = rtol * abs(good)
        if abs(width) <= tol or tol == 0.0:
            break
        x = good + 0.5 * width
        if not bisect_next and len(points) >= 2:
            (x0, t0), (x1, t1) = points[-2], points[-1]
            if t0 > t1 > 0.0 and x1 != x0:
                x = x1 + t1 * (x1 - x0) / (t0 - t1) + math.copysign(0.5 * tol, width)
        step = math.copysign(0.5 * tol, width)
        lo, hi = sorted((good + step, bad - step))
        x = min(max(x, lo), hi)
        cert = test(x)
        if cert.certified:
            good, good_cert = x, cert
            points.append((x, cert.solver_margin))
            bisect_next = False
        else:
            bad = x
            bisect_next = not bisect_next
    return good, good_cert


class _Search:
    """Bookkeeping of the LMI solves of one search, and the bracketing root finder."""

    def __init__(
        self,
        a: np.ndarray,
        a_d: np.ndarray,
        order: int,
        margin_tol: float,
        parametric: bool,
        positivity: Positivity,
    ) -> None:
        self.a, self.a_d, self.order = a, a_d, order
        self.margin_tol, self.parametric, self.positivity = margin_tol, parametric, positivity
        self.solves = 0
        self.time = 0.0

    def test(self, tau: float) -> Certificate:
        cert = certify_checked(self.a, self.a_d, tau, self.order, self.margin_tol, self.parametric, self.positivity)
        self.solves += 1
        self.time += cert.solve_time
        if cert.status is CertificateStatus.SOLVER_FAILED:
            _LOG.info("solver failed at tau = %g (%s): treated as not certified", tau, cert.reason)
        return cert

    def seed(self, lo: float, hi: float) -> tuple[float, Certificate] | None:
        """A certified delay inside the exact stable interval (lo, hi), or None."""
        if lo == 0.0:
            top = hi if math.isfinite(hi) else 1.0 / max(float(np.linalg.norm(self.a_d, 2)), 1e-12)
            candidates = [top * f for f in (0.5, 0.1, 0.01, 1e-3)]
        else:
            top = hi if math.isfinite(hi) else 2.0 * lo
            candidates = [lo + (top - lo) * f for f in (0.5, 0.3, 0.7, 0.15, 0.85, 0.05, 0.95)]
        for tau in candidates:
            cert = self.test(tau)
            if cert.certified:
                return tau, cert
        return None

    def upper(
        self, tau: float, cert: Certificate, hi_exact: float, limit: float, rtol: float
    ) -> tuple[float, Certificate, bool]:
        good, good_cert = tau, cert
        probe = hi_exact if math.isfinite(hi_exact) else 2.0 * tau
        while True:
            probe = min(probe, limit)
            trial = self.test(probe)
            if not trial.certified:
                break
            good, good_cert = probe, trial
            if probe >= limit:
                return good, good_cert, True
            probe *= 2.0
        good, good_cert = bracket_root(self.test, good, good_cert, probe, rtol)
        return good, good_cert, False

    def lower(self, tau: float, cert: Certificate, lo_exact: float, rtol: float) -> float:
        good, good_cert = tau, cert
        bad = lo_exact
        while True:
            trial = self.test(bad)
            if not trial.certified:
                break
            good, good_cert = bad, trial
            bad *= 0.5
            if bad < 1e-12:
                return 0.0
        good, _ = bracket_root(self.test, good, good_cert, bad, rtol)
        return good

    def result(
        self, status: SearchStatus, lower: float, upper: float, cert: Certificate | None, reason: str
    ) -> DelayCertification:
        return DelayCertification(
            status=status,
            order=self.order,
            lower=lower,
            upper=upper,
            certificate=cert,
            solves=self.solves,
            solve_time=self.time,
            reason=reason,
        )
