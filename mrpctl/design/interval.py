"""Interval time-varying delay: ẋ = A x + A_d x(t − τ(t)), τ(t) ∈ [τ_min, τ_max], τ̇ bounded or unknown.

One Lyapunov-Krasovskii criterion parameterised by the Bessel-Legendre order N of the integral
inequality (N = 0 Jensen, N = 1 Wirtinger, N ≥ 2 Bessel-Legendre), with the reciprocally convex
combination (Park, Ko & Jeong 2011) on the two pieces of the delay interval. See ``design/lmi.md``,
section 7, for the functional, the derivation and the references.

Every solve builds its own cvxpy problem from constants (nothing compiled is shared between calls,
so the functions are thread-safe), in time normalised by τ_max (A·τ_max, A_d·τ_max, τ/τ_max): the
answer does not depend on the time unit.
"""

from __future__ import annotations

import enum
import functools
import logging
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mrpctl._validation import finite_scalar, nonnegative_scalar, positive_scalar, readonly
from mrpctl.design._common import (
    NOT_GIVEN,
    OPTIMAL,
    SolveOutcome,
    delay_rate_argument,
    order_value,
    renamed_attribute,
    solve,
    system_matrices,
)
from mrpctl.design.lmi import DEFAULT_MARGIN_TOL, BlockMargin, CertificateStatus, SearchStatus, criterion_name
from mrpctl.design.margin import delay_margin
from mrpctl.errors import SpecificationError

__all__ = [
    "DelayRate",
    "IntervalCertificate",
    "IntervalDelayCertification",
    "RateKind",
    "certify_interval",
    "interval_blocks",
    "max_certified_interval_delay",
]

_LOG = logging.getLogger(__name__)


class RateKind(enum.Enum):
    """What is known about the delay derivative τ̇."""

    #: τ̇ ∈ [lower, upper] (e.g. |τ̇| ≤ μ, or τ̇ = 1 for the sampled-data sawtooth).
    BOUNDED = "bounded"
    #: τ(t) = d h + t − t_k of a sampled, zero-order-held loop: τ̇ = 1 and τ resets to d h at every
    #: sampling instant; admits the Fridman (2010) terms that vanish at the sampling instants.
    SAWTOOTH = "sawtooth"
    #: Nothing: τ(t) may vary arbitrarily (even discontinuously) inside [τ_min, τ_max].
    UNKNOWN = "unknown"


@dataclass(frozen=True)
class DelayRate:
    """Bounds on the delay derivative τ̇ (dimensionless).

    Build with [`bounded`][mrpctl.design.DelayRate.bounded] (|τ̇| ≤ μ), [`between`][mrpctl.design.DelayRate.between] (τ̇
    ∈ [lower, upper]), [`sawtooth`][mrpctl.design.DelayRate.sawtooth]
    (τ̇ = 1, the sampled-data input delay) or [`unknown`][mrpctl.design.DelayRate.unknown].
    """

    kind: RateKind
    lower: float = math.nan
    upper: float = math.nan

    @classmethod
    def bounded(cls, mu: float) -> DelayRate:
        """|τ̇| ≤ μ."""
        mu = nonnegative_scalar("mu", mu)
        return cls(RateKind.BOUNDED, -mu, mu)

    @classmethod
    def between(cls, lower: float, upper: float) -> DelayRate:
        """τ̇ ∈ [lower, upper]."""
        lo = finite_scalar("lower", lower)
        hi = finite_scalar("upper", upper)
        if hi < lo:
            raise SpecificationError(f"rate bounds must satisfy lower <= upper, got [{lo}, {hi}]")
        if lo > 0.0 or hi < 0.0:
            raise SpecificationError(
                f"rate bounds [{lo}, {hi}] must contain 0: a continuous delay that stays in [tau_min, tau_max] "
                "has mean rate 0 (for the sampled-data delay use DelayRate.sawtooth())"
            )
        return cls(RateKind.BOUNDED, lo, hi)

    @classmethod
    def sawtooth(cls) -> DelayRate:
        """τ̇ = 1: τ(t) = d h + t − t_k of a sampled, zero-order-held loop (τ_min = d h, τ_max = (d+1) h)."""
        return cls(RateKind.SAWTOOTH, 1.0, 1.0)

    @classmethod
    def unknown(cls) -> DelayRate:
        """No bound on τ̇ (fast-varying delay)."""
        return cls(RateKind.UNKNOWN)

    @property
    def vertices(self) -> tuple[float, ...]:
        """The values of τ̇ at which the LMI is imposed (it is affine in τ̇); empty when unknown."""
        if self.kind is RateKind.UNKNOWN:
            return ()
        return (self.lower,) if self.lower == self.upper else (self.lower, self.upper)

    def __str__(self) -> str:
        if self.kind is RateKind.UNKNOWN:
            return "rate unknown"
        if self.kind is RateKind.SAWTOOTH:
            return "sampled-data sawtooth (rate 1)"
        if self.lower == self.upper:
            return f"rate = {self.lower:g}"
        if self.lower == -self.upper:
            return f"|rate| <= {self.upper:g}"
        return f"rate in [{self.lower:g}, {self.upper:g}]"


@dataclass(frozen=True, eq=False)
class IntervalCertificate:
    """Result of [`certify_interval`][mrpctl.design.certify_interval] at one delay interval.

    Attributes
    ----------
    status : CertificateStatus
        CERTIFIED only when Clarabel reports ``optimal`` and every block recomputed in float64 from
        the returned matrices keeps a relative margin of at least ``margin_tol``.
    order : int
        Bessel-Legendre order N of the integral inequality.
    tau_min, tau_max : float
        The delay interval (s).
    rate : DelayRate
    plants : int
        Number of (A, A_d) pairs certified by the one common functional.
    matrices : dict of str to numpy.ndarray
        Decision matrices (read-only) in time normalised by τ_max; empty when the solver failed.
    margins : tuple of BlockMargin
    solver_status : str
    solve_time : float
        Wall time (s) of the build and solve.
    solver_margin : float
        Optimal common margin t of the normalised problem (positive means feasible).
    reason : str
    """

    status: CertificateStatus
    order: int
    tau_min: float
    tau_max: float
    delay_rate: DelayRate
    plants: int
    matrices: dict[str, np.ndarray] = field(repr=False)
    margins: tuple[BlockMargin, ...]
    solver_status: str
    solve_time: float
    solver_margin: float
    reason: str

    @property
    def certified(self) -> bool:
        """True when the LMI proves exponential stability for every admissible τ(t)."""
        return self.status is CertificateStatus.CERTIFIED

    @property
    def rate(self) -> DelayRate:
        """Deprecated name of ``delay_rate`` (``rate`` is a measurement rate in Hz elsewhere in mrpctl)."""
        return renamed_attribute(self, "rate", "delay_rate")

    @property
    def min_margin(self) -> float:
        """The smallest relative block margin (nan when nothing was recomputed)."""
        return min((m.relative for m in self.margins), default=math.nan)

    def __str__(self) -> str:
        return (
            f"{criterion_name(self.order)} + RCC, tau(t) in [{self.tau_min:.6g}, {self.tau_max:.6g}] s, "
            f"{self.delay_rate}: {self.status.value} (CLARABEL {self.solver_status}, {1e3 * self.solve_time:.1f} ms)"
            f"\n  {self.reason}"
        )


@dataclass(frozen=True, eq=False)
class IntervalDelayCertification:
    """Result of [`max_certified_interval_delay`][mrpctl.design.max_certified_interval_delay]: the largest certified
    τ_max for a fixed τ_min.

    Attributes
    ----------
    status : SearchStatus
    order : int
    tau_min : float
    upper : float
        The largest certified τ_max (s), to ``rtol``; nan when nothing was certified.
    delay_rate : DelayRate
        The bound on the delay's rate dτ/dt.
    certificate : IntervalCertificate or None
        The certificate at ``upper``.
    solves : int
    solve_time : float
    reason : str
    """

    status: SearchStatus
    order: int
    tau_min: float
    upper: float
    delay_rate: DelayRate
    certificate: IntervalCertificate | None = field(repr=False)
    solves: int
    solve_time: float
    reason: str

    @property
    def certified(self) -> bool:
        return self.status is not SearchStatus.NOT_CERTIFIED

    @property
    def rate(self) -> DelayRate:
        """Deprecated name of ``delay_rate`` (``rate`` is a measurement rate in Hz elsewhere in mrpctl)."""
        return renamed_attribute(self, "rate", "delay_rate")

    def __str__(self) -> str:
        if not self.certified:
            return f"{criterion_name(self.order)} + RCC ({self.delay_rate}): {self.status.value} ({self.reason})"
        return (
            f"{criterion_name(self.order)} + RCC ({self.delay_rate}): certified for tau(t) in "
            f"[{self.tau_min:.6g}, {self.upper:.6g}] s ({self.solves} solves, {self.solve_time:.3f} s; {self.reason})"
        )


# --------------------------------------------------------------------------------------------
# Structure. Time is normalised so that h2 = τ_max = 1; h1 = τ_min/τ_max ∈ [0, 1).
# ζ = [x0 = x(t); x1 = x(t − h1) (h1 > 0 only); xτ = x(t − τ); x2 = x(t − h2);
#      Ω⁰_k (k < N, on [t − h1, t], h1 > 0 only); Ωᵃ_k on [t − τ, t − h1]; Ωᵇ_k on [t − h2, t − τ]].
# --------------------------------------------------------------------------------------------


class _Layout:
    def __init__(self, n: int, order: int, has0: bool, descriptor: bool = False) -> None:
        self.n, self.order, self.has0 = n, order, has0
        names = ["x0"] + (["x1"] if has0 else []) + ["xt", "x2"]
        for seg in (["0"] if has0 else []) + ["a", "b"]:
            names += [f"O{seg}{k}" for k in range(order)]
        if descriptor:
            names.append("dx")  # ẋ(t) as a free block (descriptor form, used by the synthesis)
        self.index = {name: i for i, name in enumerate(names)}
        self.m = len(names) * n
        # Built eagerly and read-only: a cached layout is shared safely between threads.
        self._sel: dict[str, np.ndarray] = {}
        for name, i in self.index.items():
            out = np.zeros((n, self.m))
            out[:, i * n : (i + 1) * n] = np.eye(n)
            out.setflags(write=False)
            self._sel[name] = out

    def e(self, name: str) -> np.ndarray:
        if name == "x1" and not self.has0:
            name = "x0"
        return self._sel[name]

    def bessel(self, upper: str, lower: str, seg: str) -> list[np.ndarray]:
        """Δ_k = ∫ L_k ẋ over one segment, k = 0..N (L_k(1) = 1 at the recent end)."""
        rows = []
        for k in range(self.order + 1):
            row = self.e(upper) - (-1.0) ** k * self.e(lower)
            for j in range(k):
                if (k + j) % 2 == 1:
                    row = row - 2.0 * (2 * j + 1) * self.e(f"O{seg}{j}")
            rows.append(row)
        return rows


@functools.lru_cache(maxsize=64)
def _layout(n: int, order: int, has0: bool, descriptor: bool = False) -> _Layout:
    return _Layout(n, order, has0, descriptor)


def _g_matrix(lay: _Layout, h1: float, tau: float, rate: DelayRate) -> np.ndarray:
    """ξ = G(τ) ζ, ξ = [x; ∫ x over the segments] (N ≥ 1) or [x] (N = 0)."""
    rows = [lay.e("x0")]
    if lay.order == 0:
        return rows[0]
    if lay.has0:
        rows += [h1 * lay.e(f"O0{k}") for k in range(lay.order)]
    ia = (tau - h1) * lay.e("Oa0")
    ib = (1.0 - tau) * lay.e("Ob0")
    rows += [ia + ib] if _merged(rate) else [ia, ib]
    return np.vstack(rows)


def _h_matrix(lay: _Layout, f0: np.ndarray, rate: DelayRate, d: float) -> np.ndarray:
    """ξ̇ = H(τ̇) ζ."""
    rows = [f0]
    if lay.order == 0:
        return f0
    if lay.has0:
        rows += lay.bessel("x0", "x1", "0")[: lay.order]
    if _merged(rate):
        rows.append(lay.e("x1") - lay.e("x2"))
    else:
        rows += [lay.e("x1") - (1.0 - d) * lay.e("xt"), (1.0 - d) * lay.e("xt") - lay.e("x2")]
    return np.vstack(rows)


def _merged(rate: DelayRate) -> bool:
    """ξ holds ∫_{t−h2}^{t−h1} x whole (not split at t − τ(t)) when τ is unknown or jumps.

    The split integrals are continuous in t only for a continuous τ(t). The sampled-data sawtooth
    resets τ at every sampling instant, where they would jump and ξᵀPξ could jump up: so the
    sawtooth uses the merged integral, whose derivative does not involve τ̇ (and no Q term).
    """
    return rate.kind is not RateKind.BOUNDED


def _xi_size(n: int, order: int, has0: bool, rate: DelayRate) -> int:
    if order == 0:
        return n
    return n * (1 + order * int(has0) + (1 if _merged(rate) else 2))


def _vertex_points(h1: float, rate: DelayRate) -> list[tuple[float, float]]:
    """(τ, τ̇) at which Φ is imposed: Φ is affine in τ for fixed τ̇ and affine in τ̇ for fixed τ."""
    rates = rate.vertices or (0.0,)
    return [(tau, d) for tau in (h1, 1.0) for d in rates]


def _phi(
    lay: _Layout,
    a: np.ndarray,
    a_d: np.ndarray,
    h1: float,
    tau: float,
    rate: DelayRate,
    d: float,
    mats: Any,
    mm: Any,
    f0: np.ndarray | None = None,
) -> Any:
    """Φ(τ, τ̇) for one plant; ``mats`` holds numbers or cvxpy expressions, ``mm`` is the matmul.

    ``f0``: the row that ẋ(t) is in ζ; default A x(t) + A_d x(t − τ) (the plant substituted). The
    descriptor form of the synthesis passes the selector of a free ẋ block instead (then ``a`` and
    ``a_d`` are unused and the plant enters through the descriptor term only).
    """
    n, order = lay.n, lay.order
    if f0 is None:
        f0 = a @ lay.e("x0") + a_d @ lay.e("xt")
    g = _g_matrix(lay, h1, tau, rate)
    h = _h_matrix(lay, f0, rate, d)
    P, S1, S2, Q, R1, R2 = (mats[k] for k in ("P", "S1", "S2", "Q", "R1", "R2"))
    he = mm(g.T, mm(P, h))
    phi = he + he.T
    e0, e1, et, e2 = lay.e("x0"), lay.e("x1"), lay.e("xt"), lay.e("x2")
    if lay.has0:
        phi = phi + mm(e0.T, mm(S1, e0)) - mm(e1.T, mm(S1, e1))
    phi = phi + mm(e1.T, mm(S2, e1)) - mm(e2.T, mm(S2, e2))
    if rate.kind is RateKind.BOUNDED:
        phi = phi + mm(e1.T, mm(Q, e1)) - (1.0 - d) * mm(et.T, mm(Q, et))
    if _fridman(rate, lay.has0):
        # d = 0 only: W = (t_{k+1} − t)[∫_{t_k}^t ẋᵀUẋ + (x − x_k)ᵀ Z (x − x_k)], zero at t_k⁺ and t_{k+1}⁻
        # (Fridman 2010), x_k = x(t − τ); t_{k+1} − t = 1 − τ; −∫_{t_k}^t ẋᵀUẋ <= −(Bessel terms on
        # [t − τ, t])/τ <= −(Bessel terms)/h with h = 1.
        dk = e0 - et
        U, Z = mats["U"], mats["Z"]
        for k, row in enumerate(lay.bessel("x1", "xt", "a")):
            phi = phi - (2 * k + 1) * mm(row.T, mm(U, row))
        phi = phi - mm(dk.T, mm(Z, dk))
        cross = mm(dk.T, mm(Z, f0))
        phi = phi + (1.0 - tau) * (mm(f0.T, mm(U, f0)) + cross + cross.T)
    # Functional terms h1∫_{−h1}^{0}∫ ẋᵀR1ẋ and h12∫_{−h2}^{−h1}∫ ẋᵀR2ẋ: derivative h²ẋᵀRẋ − h∫ẋᵀRẋ.
    h12 = 1.0 - h1
    w = h12**2 * R2
    if lay.has0:
        w = w + h1**2 * R1
        for k, row in enumerate(lay.bessel("x0", "x1", "0")):
            phi = phi - (2 * k + 1) * mm(row.T, mm(R1, row))
    phi = phi + mm(f0.T, mm(w, f0))
    gamma = np.vstack(lay.bessel("x1", "xt", "a") + lay.bessel("xt", "x2", "b"))
    phi = phi - mm(gamma.T, mm(_rcc(mats, order, n), gamma))
    return phi


def _fridman(rate: DelayRate, has0: bool) -> bool:
    """The sampling-instant terms are used for the sawtooth with d = 0 (τ_min = 0) only.

    With d > 0, x(t_k) is not a point of ζ; as a free extra block it made Clarabel return
    ``optimal_inaccurate`` on the paper's loop, so it is left out (the criterion is then the interval
    criterion with τ̇ = 1).
    """
    return rate.kind is RateKind.SAWTOOTH and not has0


def _weights(order: int) -> list[float]:
    return [float(2 * k + 1) for k in range(order + 1)]


def _rcc(mats: dict[str, Any], order: int, n: int) -> Any:
    """[[R_N, X], [Xᵀ, R_N]], R_N = diag(R2, 3R2, ..., (2N+1)R2)."""
    return mats["RCC"]


def _assemble_rcc(R2: Any, X: Any, order: int, n: int, *, numeric: bool) -> Any:
    w = _weights(order)
    size = (order + 1) * n
    if numeric:
        r_n = np.kron(np.diag(w), R2)
        return np.block([[r_n, X], [X.T, r_n]])
    # deferred: cvxpy (about 1 s to import), only when an LMI is solved
    import cvxpy as cp

    zero = np.zeros((n, n))
    r_n = cp.bmat([[w[i] * R2 if i == j else zero for j in range(order + 1)] for i in range(order + 1)])
    del size
    return cp.bmat([[r_n, X], [X.T, r_n]])


def _sym(m: np.ndarray) -> np.ndarray:
    return 0.5 * (m + m.T)


def interval_blocks(
    plants: Sequence[tuple[np.ndarray, np.ndarray]],
    h1: float,
    rate: DelayRate,
    matrices: dict[str, Any],
    *,
    order: int,
) -> dict[str, np.ndarray]:
    """Every LMI block of the interval criterion in float64, in time normalised by τ_max (h2 = 1).

    Each block must be positive definite for a certificate: P, S1 (h1 > 0), S2, Q (bounded rate),
    R1 (h1 > 0), R2, the reciprocally convex block [[R_N, X], [Xᵀ, R_N]], and −Φ(τ, τ̇) at every
    vertex (τ ∈ {h1, 1}, τ̇ at its bounds) of every plant (A·τ_max, A_d·τ_max).
    """
    n = plants[0][0].shape[0]
    has0 = h1 > 0.0
    lay = _layout(n, order, has0)
    mats, blocks = _functional_blocks(matrices, has0, rate, order, n)
    for p, (a, a_d) in enumerate(plants):
        for tau, d in _vertex_points(h1, rate):
            phi = _phi(lay, a, a_d, h1, tau, rate, d, mats, np.matmul)
            blocks[f"derivative[plant {p}, tau {tau:.3g}, rate {d:g}]"] = _sym(-phi)
    return blocks


def _functional_blocks(
    matrices: dict[str, Any], has0: bool, rate: DelayRate, order: int, n: int
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """(the matrices with the RCC block assembled, the positivity blocks of the functional)."""
    mats = {k: np.asarray(v, dtype=float) for k, v in matrices.items()}
    mats["RCC"] = _assemble_rcc(mats["R2"], mats["X"], order, n, numeric=True)
    blocks: dict[str, np.ndarray] = {"P": _sym(mats["P"]), "S2": _sym(mats["S2"]), "R2": _sym(mats["R2"])}
    if has0:
        blocks["S1"] = _sym(mats["S1"])
        blocks["R1"] = _sym(mats["R1"])
    if rate.kind is RateKind.BOUNDED:
        blocks["Q"] = _sym(mats["Q"])
    if _fridman(rate, has0):
        blocks["U"] = _sym(mats["U"])
        blocks["Z"] = _sym(mats["Z"])
    blocks["RCC"] = _sym(mats["RCC"])
    return mats, blocks


def interval_unknowns(n: int, order: int, has0: bool, rate: DelayRate) -> list[UnknownRate]:
    """The decision matrices of the interval criterion (P, S2, R2, [S1, R1], [Q], [U, Z], X)."""
    nx = _xi_size(n, order, has0, rate)
    unknowns = [UnknownRate("P", nx, nx, True), UnknownRate("S2", n, n, True), UnknownRate("R2", n, n, True)]
    if has0:
        unknowns += [UnknownRate("S1", n, n, True), UnknownRate("R1", n, n, True)]
    if rate.kind is RateKind.BOUNDED:
        unknowns.append(UnknownRate("Q", n, n, True))
    if _fridman(rate, has0):
        unknowns += [UnknownRate("U", n, n, True), UnknownRate("Z", n, n, True)]
    unknowns.append(UnknownRate("X", (order + 1) * n, (order + 1) * n, False))
    return unknowns


def descriptor_interval_blocks(
    plants: Sequence[tuple[np.ndarray, np.ndarray]],
    h1: float,
    rate: DelayRate,
    matrices: dict[str, Any],
    *,
    order: int,
    epsilon: float,
) -> dict[str, np.ndarray]:
    """The interval criterion in descriptor form, after the synthesis congruence (time normalised by τ_max).

    ``plants`` are (A, B) pairs of ẋ = A x + B u, u = K x(t − τ(t)). ζ gets a free block ẋ(t); every
    occurrence of A x + A_d x(t − τ) in `interval_blocks` becomes that block, and the descriptor
    identity 2(xᵀP₂ᵀ + ε ẋᵀP₂ᵀ)(A x + B K x(t − τ) − ẋ) = 0 (Fridman 2001) is added. After the
    congruence diag(G, …, G), G = P₂⁻¹ (every other selector of ζ is a scalar combination of
    blocks, so it commutes), with Y = K G and the functional's matrices read as G-transformed:

        −Φ̄(τ, τ̇) = −Φ_ẋ(τ, τ̇) − He((e₀ + ε e_ẋ)ᵀ (A G e₀ + B Y e_τ − G e_ẋ)),

    linear in (P̄, S̄, R̄, X̄, …, G, Y) for fixed ε and affine in the plant (A, B): the blocks at the
    vertices of a polytope of plants certify its convex hull, and K = Y G⁻¹. ``matrices`` holds the
    interval unknowns (see `interval_unknowns`) and ``G`` (n, n), ``Y`` (m, n).
    """
    n = plants[0][0].shape[0]
    has0 = h1 > 0.0
    lay = _layout(n, order, has0, True)
    mats, blocks = _functional_blocks({k: v for k, v in matrices.items() if k not in ("G", "Y")}, has0, rate, order, n)
    g = np.asarray(matrices["G"], dtype=float)
    y = np.asarray(matrices["Y"], dtype=float)
    zero = np.zeros((n, n))
    e0, et, edx = lay.e("x0"), lay.e("xt"), lay.e("dx")
    left = e0 + epsilon * edx
    for p, (a, b) in enumerate(plants):
        desc = left.T @ (a @ g @ e0 + b @ y @ et - g @ edx)
        for tau, d in _vertex_points(h1, rate):
            phi = _phi(lay, zero, zero, h1, tau, rate, d, mats, np.matmul, f0=edx) + desc + desc.T
            blocks[f"derivative[plant {p}, tau {tau:.3g}, rate {d:g}]"] = _sym(-phi)
    return blocks


def interval_margins(blocks: dict[str, np.ndarray]) -> tuple[BlockMargin, ...]:
    out = []
    for name, block in blocks.items():
        eig = float(np.linalg.eigvalsh(block)[0])
        norm = float(np.linalg.norm(block, 2))
        out.append(BlockMargin(name, eig, eig / norm if norm > 0 else -math.inf))
    return tuple(out)


@dataclass(frozen=True)
class UnknownRate:
    """One matrix of decision variables: name, shape, symmetric or not."""

    name: str
    rows: int
    cols: int
    symmetric: bool

    def basis(self) -> list[np.ndarray]:
        out = []
        for i in range(self.rows):
            for j in range(i if self.symmetric else 0, self.cols):
                b = np.zeros((self.rows, self.cols))
                b[i, j] = 1.0
                if self.symmetric:
                    b[j, i] = 1.0
                out.append(b)
        return out


def solve_lmi(
    unknowns: Sequence[UnknownRate],
    blocks: Callable[[dict[str, np.ndarray]], dict[str, np.ndarray]],
    fixed: dict[str, np.ndarray],
    normalise: Sequence[str],
) -> tuple[SolveOutcome, dict[str, np.ndarray] | None, float]:
    """Maximise t s.t. every block(mats) ≽ t I and the traces of the ``normalise`` blocks sum to 1.

    The normalised blocks must bound every unknown (e.g. P ≻ 0 itself, or τP + diag(0, S, ...)),
    else t is unbounded.

    ``blocks`` must be linear in the unknowns. It is evaluated once per basis matrix, so the cvxpy
    problem is a few dense affine maps of one variable vector: fast to build, and built per call
    (nothing shared between threads).
    """
    # deferred: cvxpy (about 1 s to import), only when an LMI is solved
    import cvxpy as cp

    bases: list[tuple[str, np.ndarray]] = []
    for u in unknowns:
        bases += [(u.name, b) for b in u.basis()]
    zero = {u.name: np.zeros((u.rows, u.cols)) for u in unknowns}
    columns: dict[str, list[np.ndarray]] = {}
    trace_row = np.zeros(len(bases))
    for idx, (name, b) in enumerate(bases):
        mats = {**fixed, **zero, name: b}
        for key, block in blocks(mats).items():
            columns.setdefault(key, []).append(block.reshape(-1))
            if key in normalise:
                trace_row[idx] += float(np.trace(block))
    v = cp.Variable(len(bases), name="v")
    t = cp.Variable(name="t")
    cons = []
    shapes = {key: block.shape for key, block in blocks({**fixed, **zero}).items()}
    for key, cols in columns.items():
        k = shapes[key][0]
        expr = cp.reshape(np.column_stack(cols) @ v, (k, k), order="C")
        cons.append(0.5 * (expr + expr.T) >> t * np.eye(k))
    cons.append(trace_row @ v == 1.0)
    problem = cp.Problem(cp.Maximize(t), cons)
    outcome = solve(problem)
    if outcome.error or outcome.status != OPTIMAL or v.value is None or t.value is None:
        return outcome, None, math.nan
    values = {u.name: np.zeros((u.rows, u.cols)) for u in unknowns}
    for coef, (name, b) in zip(np.asarray(v.value, dtype=float), bases, strict=True):
        values[name] = values[name] + coef * b
    return outcome, values, float(t.value)


def solve_interval(
    plants: Sequence[tuple[np.ndarray, np.ndarray]],
    tau_min: float,
    tau_max: float,
    rate: DelayRate,
    order: int,
    margin_tol: float,
) -> IntervalCertificate:
    """Build and solve the normalised problem; the float64 re-check decides the status."""
    n = plants[0][0].shape[0]
    h1 = tau_min / tau_max
    has0 = h1 > 0.0
    scaled = [(tau_max * a, tau_max * a_d) for a, a_d in plants]
    unknowns = interval_unknowns(n, order, has0, rate)
    fixed = {k: np.zeros((n, n)) for k in ("S1", "R1", "Q", "U", "Z")}

    def blocks(mats: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        return interval_blocks(scaled, h1, rate, mats, order=order)

    meta = {"order": order, "tau_min": tau_min, "tau_max": tau_max, "delay_rate": rate, "plants": len(plants)}
    return _solve_and_recheck(unknowns, blocks, fixed, meta, margin_tol, preconditioned=None)


def _solve_and_recheck(
    unknowns: Sequence[UnknownRate],
    blocks: Callable[[dict[str, np.ndarray]], dict[str, np.ndarray]],
    fixed: dict[str, np.ndarray],
    meta: dict[str, Any],
    margin_tol: float,
    *,
    preconditioned: dict[str, float] | None,
) -> IntervalCertificate:
    """Solve, then let the float64 re-check of ``blocks`` decide the status (shared by both solvers).

    ``preconditioned``: the scale of each unknown in the difference-coordinate problem (the
    matrices are reported unscaled), or None for the plain problem.
    """
    start = time.perf_counter()
    outcome, values, t_opt = solve_lmi(unknowns, blocks, fixed, [u.name for u in unknowns if u.symmetric])
    base: dict[str, Any] = {**meta, "solver_status": outcome.status, "solve_time": time.perf_counter() - start}
    if values is None:
        where = "" if preconditioned is None else " (preconditioned)"
        reason = outcome.error or f"solver status {outcome.status!r} is not 'optimal'{where}: no certificate"
        return IntervalCertificate(
            status=CertificateStatus.SOLVER_FAILED,
            matrices={},
            margins=(),
            solver_margin=math.nan,
            reason=reason,
            **base,
        )
    solution = {**fixed, **values}
    margins = interval_margins(blocks(solution))
    worst = min(margins, key=lambda m: m.relative)
    ok = worst.relative >= margin_tol
    if preconditioned is None:
        mats = solution
        reason = (
            f"every block positive definite; smallest relative margin {worst.relative:.3g} ({worst.name})"
            if ok
            else f"block {worst.name!r} has relative margin {worst.relative:.3g} < {margin_tol:g} (t = {t_opt:.3g})"
        )
    else:
        mats = {k: preconditioned.get(k, 1.0) * v for k, v in solution.items()}
        reason = (
            f"every block positive definite (difference coordinates, power-of-two scaling); smallest relative "
            f"margin {worst.relative:.3g} ({worst.name})"
            if ok
            else f"block {worst.name!r} has relative margin {worst.relative:.3g} < {margin_tol:g} (preconditioned)"
        )
    return IntervalCertificate(
        status=CertificateStatus.CERTIFIED if ok else CertificateStatus.NOT_CERTIFIED,
        matrices={k: readonly(v) for k, v in mats.items()},
        margins=margins,
        solver_margin=t_opt,
        reason=reason,
        **base,
    )


def rate_value(rate: Any) -> DelayRate:
    if rate is None:
        return DelayRate.unknown()
    if isinstance(rate, DelayRate):
        return rate
    if isinstance(rate, (int, float, np.floating, np.integer)) and not isinstance(rate, bool):
        return DelayRate.bounded(float(rate))
    raise SpecificationError(
        f"rate must be a DelayRate, a bound mu >= 0 on |d tau/dt|, or None (unknown); got {rate!r}"
    )


def _plants(A: Any, A_d: Any) -> list[tuple[np.ndarray, np.ndarray]]:
    return [system_matrices(A, A_d)]


def _interval(tau_min: Any, tau_max: Any) -> tuple[float, float]:
    lo = nonnegative_scalar("tau_min", tau_min)
    hi = positive_scalar("tau_max", tau_max)
    if not hi > lo:
        raise SpecificationError(f"tau_max must exceed tau_min: got [{lo}, {hi}] (a constant delay is lmi.certify)")
    return lo, hi


def certify_interval(
    A: Any,
    A_d: Any,
    tau_max: float,
    *,
    tau_min: float = 0.0,
    delay_rate: DelayRate | float | None = None,
    rate: Any = NOT_GIVEN,
    order: int = 1,
    margin_tol: float = DEFAULT_MARGIN_TOL,
) -> IntervalCertificate:
    """Test the interval-delay LMI for ẋ = A x + A_d x(t − τ(t)), τ(t) ∈ [τ_min, τ_max].

    Parameters
    ----------
    A, A_d : array_like
        (n, n) system matrices (1/s).
    tau_max : float
        Upper end of the delay interval (s).
    tau_min : float, optional
        Lower end (s), default 0.
    delay_rate : DelayRate, float or None, optional
        Bound on τ̇: a DelayRate, a number μ meaning |τ̇| ≤ μ, or None (default) for an unknown,
        arbitrarily fast-varying delay.
    rate : optional
        Deprecated name of ``delay_rate`` (DeprecationWarning).
    order : int, optional
        Bessel-Legendre order N of the integral inequality (0 Jensen, 1 Wirtinger; default 1).
    margin_tol : float, optional
        Relative eigenvalue margin each recomputed block must keep (default 1e-9).

    Returns
    -------
    IntervalCertificate

    Examples
    --------
    >>> certify_interval([[-2, 0], [0, -0.9]], [[-1, 0], [-1, -1]], 2.0, delay_rate=0.5).certified
    True
    """
    rate = delay_rate_argument(delay_rate, rate)
    plants = _plants(A, A_d)
    lo, hi = _interval(tau_min, tau_max)
    return solve_interval(
        plants, lo, hi, rate_value(rate), order_value(order), positive_scalar("margin_tol", margin_tol)
    )


def max_certified_interval_delay(
    A: Any,
    A_d: Any,
    *,
    tau_min: float = 0.0,
    delay_rate: DelayRate | float | None = None,
    rate: Any = NOT_GIVEN,
    order: int = 1,
    rtol: float = 1e-3,
    tau_limit: float | None = None,
    margin_tol: float = DEFAULT_MARGIN_TOL,
) -> IntervalDelayCertification:
    """The largest τ_max such that the criterion certifies every τ(t) ∈ [τ_min, τ_max] (s).

    The exact constant-delay analysis bounds the search: every constant delay in the interval must
    be stable, so τ_max cannot exceed the end of the exact stable interval that contains τ_min. The
    end itself is tested too (a certificate there would expose an unsound criterion). Then
    bisection to relative width ``rtol``; at most 200 solves, so it terminates on every input.

    Parameters
    ----------
    A, A_d : array_like
    tau_min : float, optional
    delay_rate : DelayRate, float or None, optional
        As in [`certify_interval`][mrpctl.design.certify_interval] (``rate``: its deprecated name).
    order : int, optional
    rtol : float, optional
        Relative width of the final bracket (default 1e-3).
    tau_limit : float, optional
        Search limit (s) for systems stable at every constant delay; default 1e3 / max(‖A‖, ‖A_d‖).
    margin_tol : float, optional
    """

    (a, a_d) = _plants(A, A_d)[0]
    lo = nonnegative_scalar("tau_min", tau_min)
    rate_v = rate_value(delay_rate_argument(delay_rate, rate))
    order = order_value(order)
    rtol = positive_scalar("rtol", rtol)
    if rtol >= 0.5:
        raise SpecificationError(f"rtol must be < 0.5, got {rtol}")
    margin_tol = positive_scalar("margin_tol", margin_tol)
    scale = max(float(np.linalg.norm(a, 2)), float(np.linalg.norm(a_d, 2)), 1e-12)
    limit = 1e3 / scale if tau_limit is None else positive_scalar("tau_limit", tau_limit)
    exact = delay_margin(a, a_d)
    solves, total = 0, 0.0

    def test(hi: float) -> IntervalCertificate:
        nonlocal solves, total
        cert = solve_interval([(a, a_d)], lo, hi, rate_v, order, margin_tol)
        solves += 1
        total += cert.solve_time
        return cert

    def result(
        status: SearchStatus, upper: float, cert: IntervalCertificate | None, reason: str
    ) -> IntervalDelayCertification:
        return IntervalDelayCertification(status, order, lo, upper, rate_v, cert, solves, total, reason)

    top = math.nan
    for s_lo, s_hi in exact.stable_intervals:
        if s_lo <= lo < s_hi or (lo == 0.0 and s_lo == 0.0):
            top = s_hi
            break
    if math.isnan(top):
        return result(
            SearchStatus.NOT_CERTIFIED, math.nan, None, f"tau_min = {lo:g} s is not in an exact stable interval"
        )
    bad = min(top, limit) if math.isfinite(top) else limit
    good, good_cert = math.nan, None
    span = bad - lo
    for f in (1.0, 0.5, 0.2, 0.05, 0.01, 1e-3):
        trial = test(lo + f * span)
        if trial.certified:
            good, good_cert = lo + f * span, trial
            break
        bad = lo + f * span
    if good_cert is None:
        return result(SearchStatus.NOT_CERTIFIED, math.nan, None, "no interval certified (criterion too conservative)")
    if good >= (min(top, limit) if math.isfinite(top) else limit):
        if math.isfinite(top) and top <= limit:
            return result(
                SearchStatus.CERTIFIED, good, good_cert, f"certified up to the exact constant-delay bound {top:.6g} s"
            )
        return result(SearchStatus.SEARCH_LIMIT, good, good_cert, f"still certified at tau_limit = {limit:.6g} s")
    for _ in range(200):
        if bad - good <= rtol * good:
            break
        mid = 0.5 * (good + bad)
        trial = test(mid)
        if trial.certified:
            good, good_cert = mid, trial
        else:
            bad = mid
    reason = f"exact constant-delay bound {top:.6g} s" if math.isfinite(top) else "stable for every constant delay"
    return result(SearchStatus.CERTIFIED, good, good_cert, reason)


# --------------------------------------------------------------------------------------------
# Preconditioning (the sampled loop at 1 kHz). In time normalised by τ_max the points and moments of
# ζ (x(t), x(t − h1), x(t − τ), x(t − h2), Legendre moments) are nearly equal when the dynamics are
# slow over a segment (‖A‖·h ≪ 1 at 1 kHz, or the 1/(d+1)-wide varying segment for d > 0): Φ ≺ 0
# must then hold in directions of size ε = ‖A‖·(segment length) next to directions of size 1, and
# Clarabel returns "optimal_inaccurate" for the Wirtinger/Bessel-Legendre problems. The retry
# writes ζ in difference coordinates ζ = T ζ' (x1 = x0 + ε0 x1', xτ = x1 + εab xτ', moments of
# order 0 about the segment's recent end, every difference scaled by the power of two nearest ε)
# and scales every block by a diagonal power-of-two congruence D (from the diagonal magnitudes of
# its coefficient matrices). T and D are invertible, so T'ΦT ≺ 0 ⇔ Φ ≺ 0, and with power-of-two
# entries the selectors and the scaling are exact in floating point: the float64 re-check of the
# transformed blocks is as strict as the plain one.
# --------------------------------------------------------------------------------------------


def _pow2(x: float) -> float:
    return float(2.0 ** round(math.log2(x)))


class _DifferenceLayout(_Layout):
    """The interval layout with every selector composed with T (ζ = T ζ')."""

    def __init__(self, base: _Layout, t: np.ndarray) -> None:
        self.n, self.order, self.has0 = base.n, base.order, base.has0
        self.index, self.m = base.index, base.m
        self._sel = {}
        for name, sel in base._sel.items():
            out = sel @ t
            out.setflags(write=False)
            self._sel[name] = out


def _difference_coordinates(lay: _Layout, eps0: float, eps_ab: float) -> np.ndarray:
    n = lay.n
    t = np.zeros((lay.m, lay.m))

    def col(name: str) -> slice:
        i = lay.index[name]
        return slice(i * n, (i + 1) * n)

    eye = np.eye(n)
    t[col("x0"), col("x0")] = eye
    ref_ab = "x1" if lay.has0 else "x0"
    if lay.has0:
        t[col("x1"), col("x0")] = eye
        t[col("x1"), col("x1")] = eps0 * eye
    for name in ("xt", "x2"):
        t[col(name), :] += t[col(ref_ab), :]
        t[col(name), col(name)] += eps_ab * eye
    for seg in (["0"] if lay.has0 else []) + ["a", "b"]:
        eps, ref = (eps0, "x0") if seg == "0" else (eps_ab, ref_ab)
        for k in range(lay.order):
            name = f"O{seg}{k}"
            if k == 0:
                t[col(name), :] += t[col(ref), :]
            t[col(name), col(name)] += eps * eye
    return t


def solve_interval_preconditioned(
    plants: Sequence[tuple[np.ndarray, np.ndarray]],
    tau_min: float,
    tau_max: float,
    rate: DelayRate,
    order: int,
    margin_tol: float,
    *,
    scale_variables: bool = False,
) -> IntervalCertificate:
    """`solve_interval` in difference coordinates with power-of-two block scaling (an equivalent LMI).

    For problems that come back ``optimal_inaccurate`` because the dynamics are slow over a segment
    (see the comment above). ``scale_variables`` also measures R1, R2, X, U, Z in units of 1/ε.
    The float64 re-check is made on the transformed blocks (exact congruences of the plain ones).
    """
    n = plants[0][0].shape[0]
    h1 = tau_min / tau_max
    has0 = h1 > 0.0
    scaled = [(tau_max * a, tau_max * a_d) for a, a_d in plants]
    c = max(max(float(np.linalg.norm(a, 2)), float(np.linalg.norm(a_d, 2))) for a, a_d in scaled)
    c = max(c, 1e-300)
    eps0 = _pow2(min(1.0, c * h1)) if has0 else 1.0
    eps_ab = _pow2(min(1.0, c * (1.0 - h1)))
    lay = _DifferenceLayout(_layout(n, order, has0), _difference_coordinates(_layout(n, order, has0), eps0, eps_ab))
    unknowns = interval_unknowns(n, order, has0, rate)
    fixed = {k: np.zeros((n, n)) for k in ("S1", "R1", "Q", "U", "Z")}
    # Optionally the integral weights in units of 1/ε (their natural size when the dynamics are slow).
    var_scale = (
        {"R1": 1.0 / eps0, "R2": 1.0 / eps_ab, "X": 1.0 / eps_ab, "U": 1.0 / eps_ab, "Z": 1.0 / eps_ab}
        if scale_variables
        else {}
    )

    def raw(matrices: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        mats = {k: var_scale.get(k, 1.0) * v for k, v in matrices.items()}
        mats["RCC"] = _assemble_rcc(mats["R2"], mats["X"], order, n, numeric=True)
        out = {"P": _sym(mats["P"]), "S2": _sym(mats["S2"]), "R2": _sym(mats["R2"])}
        if has0:
            out["S1"], out["R1"] = _sym(mats["S1"]), _sym(mats["R1"])
        if rate.kind is RateKind.BOUNDED:
            out["Q"] = _sym(mats["Q"])
        if _fridman(rate, has0):
            out["U"], out["Z"] = _sym(mats["U"]), _sym(mats["Z"])
        out["RCC"] = _sym(mats["RCC"])
        for p, (a, a_d) in enumerate(scaled):
            for tau, rate_d in _vertex_points(h1, rate):
                phi = _phi(lay, a, a_d, h1, tau, rate, rate_d, mats, np.matmul)
                out[f"derivative[difference coordinates, plant {p}, tau {tau:.3g}, rate {rate_d:g}]"] = _sym(-phi)
        return out

    zero = {u.name: np.zeros((u.rows, u.cols)) for u in unknowns}
    magnitude: dict[str, np.ndarray] = {}
    for u in unknowns:
        for basis in u.basis():
            for key, block in raw({**fixed, **zero, u.name: basis}).items():
                magnitude[key] = magnitude.get(key, 0.0) + np.abs(np.diag(block))
    scale = {
        key: np.array([_pow2(1.0 / math.sqrt(v)) if v > 0 else 1.0 for v in mag]) for key, mag in magnitude.items()
    }

    def blocks(matrices: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {key: scale[key][:, None] * b * scale[key][None, :] for key, b in raw(matrices).items()}

    meta = {"order": order, "tau_min": tau_min, "tau_max": tau_max, "delay_rate": rate, "plants": len(plants)}
    return _solve_and_recheck(unknowns, blocks, fixed, meta, margin_tol, preconditioned=var_scale)
