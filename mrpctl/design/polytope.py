"""Inertia uncertainty: a polytope of linearised loops from a nominal Spacecraft and tolerances.

The J-set: J = J₀ + diag(δ) + E with |δᵢ| ≤ tol·J₀,ᵢᵢ (per-axis relative tolerance on the diagonal
of the nominal J₀, which must be diagonal) and symmetric off-diagonal products of inertia
|E_ij| ≤ ``product_bound`` (kg m²). The loop matrix A_d = B(J) K = [[0, 0], [J⁻¹K_σ/4, J⁻¹K_ω/4]] is
affine in J⁻¹, not in J, so the certified set is a box in the entries of J⁻¹ that contains the
image of the J-set (`inverse_box`):

- products of inertia zero: J⁻¹ = diag(1/Jᵢᵢ) and the box [1/((1+tol)J₀,ᵢᵢ), 1/((1−tol)J₀,ᵢᵢ)] is the
  image itself (exact; its 8 vertices are physical inertias);
- otherwise: J = D + E, J⁻¹ = D⁻¹ − D⁻¹ E D⁻¹ + R with ‖R‖₂ ≤ ‖D⁻¹‖³‖E‖²/(1 − ‖D⁻¹‖‖E‖); interval bounds
  of the first two terms plus ±‖R‖₂ on every entry give a box of the 6 entries (64 vertices).

Every plant of the convex hull of the vertices is certified. Constant delay, by default
(`Functional.VERTEX`): a vertex-dependent Lyapunov-Krasovskii functional V(α) = Σ αᵢ Vᵢ with
(Pᵢ, Sᵢ, Rᵢ) per vertex and one Finsler/descriptor slack M common to the vertices, which makes
every vertex LMI affine in the vertex's (A, A_d) and the convex combination valid (He, Wu, She &
Liu, IEEE TAC 49(5), 2004; see `vertex_blocks`); or (`Functional.COMMON`) one
functional for all vertices. Interval delay: one common functional. Vertices of the outer box that are not the
inverse of a physical inertia (not positive definite, or violating the triangle inequality) are
KEPT: certifying a superset is sound, only more conservative; `InertiaPolytope.nonphysical`
counts them.
"""

from __future__ import annotations

import enum
import itertools
import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mrpctl._validation import nonnegative_scalar, positive_scalar, readonly
from mrpctl.design._common import (
    NOT_GIVEN,
    OPTIMAL,
    SolveOutcome,
    balancing,
    delay_rate_argument,
    order_value,
    similarity,
    solve,
    system_matrices,
)
from mrpctl.design.interval import (
    DelayRate,
    IntervalCertificate,
    UnknownRate,
    interval_margins,
    rate_value,
    solve_interval,
    solve_interval_preconditioned,
    solve_lmi,
)
from mrpctl.design.lmi import DEFAULT_MARGIN_TOL, BlockMargin, CertificateStatus, lmi_blocks, lmi_structure
from mrpctl.design.margin import delay_margin
from mrpctl.errors import SpecificationError
from mrpctl.model import gain_matrix
from mrpctl.spacecraft import Spacecraft, check_spacecraft

__all__ = [
    "Functional",
    "InertiaPolytope",
    "PolytopeCertificate",
    "certify_polytope",
    "certify_vertices",
    "exact_polytope_margin",
    "inertia_polytope",
    "inverse_box",
    "max_certified_tolerance",
    "max_stable_tolerance",
    "vertex_blocks",
]


class Functional(enum.Enum):
    """Which Lyapunov-Krasovskii functional [`certify_polytope`][mrpctl.design.certify_polytope] searches for (constant
    delay)."""

    COMMON = "one functional common to all vertices"
    VERTEX = "vertex-dependent functional (descriptor form, common Finsler slack)"


@dataclass(frozen=True, eq=False)
class InertiaPolytope:
    """The inertia set and the J⁻¹ box that contains its image.

    Attributes
    ----------
    nominal : Spacecraft
    tolerance : float
        Relative per-axis tolerance on the principal inertias.
    product_bound : float
        Bound on |J_ij|, i ≠ j (kg m²).
    lower, upper : numpy.ndarray
        (3, 3) entrywise bounds of J⁻¹ (1/(kg m²)).
    vertices : numpy.ndarray
        (V, 3, 3) vertices of the J⁻¹ box (symmetric matrices).
    nonphysical : int
        Number of vertices that are not the inverse of a physical inertia.
    """

    nominal: Spacecraft
    tolerance: float
    product_bound: float
    lower: np.ndarray = field(repr=False)
    upper: np.ndarray = field(repr=False)
    vertices: np.ndarray = field(repr=False)
    nonphysical: int

    @property
    def diagonal(self) -> bool:
        """True when products of inertia are excluded (then the box is exact and the loop splits per axis)."""
        return self.product_bound == 0.0

    def contains_inverse(self, inertia: Any, *, rtol: float = 1e-12) -> bool:
        """True when inv(inertia) lies in the J⁻¹ box (up to ``rtol`` of the box size)."""
        inv = np.linalg.inv(np.asarray(inertia, dtype=float))
        slack = rtol * float(np.max(np.abs(self.upper)))
        return bool(np.all(inv >= self.lower - slack) and np.all(inv <= self.upper + slack))

    def __str__(self) -> str:
        return (
            f"inertia polytope around {self.nominal}: +/-{100 * self.tolerance:g} % per axis, "
            f"|J_ij| <= {self.product_bound:g} kg m^2; {len(self.vertices)} vertices of J^-1 "
            f"({self.nonphysical} not physical)"
        )


def inverse_box(nominal: np.ndarray, tolerance: float, product_bound: float) -> tuple[np.ndarray, np.ndarray]:
    """Entrywise bounds (lower, upper) of J⁻¹ over the J-set (see the module docstring)."""
    j0 = np.diag(nominal)
    dmin, dmax = (1.0 - tolerance) * j0, (1.0 + tolerance) * j0
    lower = np.zeros((3, 3))
    upper = np.zeros((3, 3))
    np.fill_diagonal(lower, 1.0 / dmax)
    np.fill_diagonal(upper, 1.0 / dmin)
    if product_bound > 0.0:
        inv_norm = 1.0 / float(np.min(dmin))
        e_norm = product_bound * math.sqrt(6.0)  # ‖E‖₂ <= ‖E‖_F
        if inv_norm * e_norm >= 1.0:
            raise SpecificationError(
                f"product_bound = {product_bound:g} kg m^2 is too large for the Neumann bound "
                f"(need sqrt(6) p < min J_ii (1 - tolerance) = {np.min(dmin):.6g})"
            )
        r = inv_norm**3 * e_norm**2 / (1.0 - inv_norm * e_norm)
        first = product_bound / np.outer(dmin, dmin)
        np.fill_diagonal(first, 0.0)
        lower = lower - first - r
        upper = upper + first + r
    return lower, upper


def inertia_polytope(spacecraft: Spacecraft, tolerance: float, *, product_bound: float = 0.0) -> InertiaPolytope:
    """Build the J⁻¹ polytope around a diagonal nominal inertia.

    Parameters
    ----------
    spacecraft : Spacecraft
        Nominal; its J must be diagonal.
    tolerance : float
        Relative per-axis tolerance on Jᵢᵢ, 0 <= tol < 1.
    product_bound : float, optional
        |J_ij| bound (kg m²), default 0.
    """
    sc = check_spacecraft(spacecraft)
    if not sc.is_diagonal:
        raise SpecificationError("spacecraft: the nominal inertia must be diagonal (principal axes)")
    tol = nonnegative_scalar("tolerance", tolerance)
    if tol >= 1.0:
        raise SpecificationError(f"tolerance must be < 1 (a relative tolerance), got {tol}")
    p = nonnegative_scalar("product_bound", product_bound)
    lower, upper = inverse_box(np.array(sc.inertia), tol, p)
    if p == 0.0:
        corners = [np.diag(c) for c in itertools.product(*[(lower[i, i], upper[i, i]) for i in range(3)])]
    else:
        idx = [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)]
        corners = []
        for choice in itertools.product(*[(lower[i, j], upper[i, j]) for i, j in idx]):
            m = np.zeros((3, 3))
            for (i, j), v in zip(idx, choice, strict=True):
                m[i, j] = m[j, i] = v
            corners.append(m)
    bad = 0
    for m in corners:
        eig = np.linalg.eigvalsh(m)
        if eig[0] <= 0.0:
            bad += 1
            continue
        inertias = np.sort(1.0 / eig)
        if inertias[2] > inertias[0] + inertias[1]:
            bad += 1
    return InertiaPolytope(sc, tol, p, readonly(lower), readonly(upper), readonly(np.array(corners)), bad)


#: ``functional=None`` uses the vertex-dependent functional up to this many vertices per sub-problem and
#: the common one above (measured, products of inertia, 64 vertices of the 6×6 loop, N = 0: common 10 s,
#: vertex-dependent 200 s, most of it inside Clarabel).
VERTEX_LIMIT = 8


def _vertex_loops(poly: InertiaPolytope, K: Any) -> list[tuple[np.ndarray, np.ndarray]]:
    k = gain_matrix(K)
    a = np.block([[np.zeros((3, 3)), np.eye(3)], [np.zeros((3, 3)), np.zeros((3, 3))]])
    out = []
    seen: set[bytes] = set()
    for jinv in poly.vertices:
        if jinv.tobytes() in seen:
            continue
        seen.add(jinv.tobytes())
        b = np.vstack((np.zeros((3, 3)), jinv / 4.0))
        out.append((a, b @ k))
    return out


def _axis_loops(poly: InertiaPolytope, K: Any) -> list[list[tuple[np.ndarray, np.ndarray]]] | None:
    """Per-axis 2×2 vertex loops when the set and the gain split per axis, else None."""
    k = gain_matrix(K)
    ks, kw = k[:, :3], k[:, 3:]
    if not (poly.diagonal and np.all(ks == np.diag(np.diag(ks))) and np.all(kw == np.diag(np.diag(kw)))):
        return None
    a = np.array([[0.0, 1.0], [0.0, 0.0]])
    axes = []
    for i in range(3):
        loops = []
        # Equal ends (tolerance 0) give one vertex: duplicated LMIs made Clarabel inaccurate.
        for jinv in sorted({float(poly.lower[i, i]), float(poly.upper[i, i])}):
            loops.append((a, np.array([[0.0, 0.0], [jinv * ks[i, i] / 4.0, jinv * kw[i, i] / 4.0]])))
        axes.append(loops)
    return axes


@dataclass(frozen=True, eq=False)
class PolytopeCertificate:
    """One certificate over every vertex of a polytope of plants (an inertia polytope).

    Attributes
    ----------
    status : CertificateStatus
        CERTIFIED only when every sub-problem (one per axis when the loop splits) was solved
        ``optimal`` and re-verified in float64 at every vertex; SOLVER_FAILED when the solver gave
        no usable answer after the retries (plain, balanced, bounded slack; see ``reason``).
    order : int
    tau : float
        The constant delay τ (s), or the upper end of the interval.
    vertices : int
        Number of vertex plants certified (per axis, when split).
    margins : tuple of BlockMargin
    solve_time : float
    reason : str
    interval : tuple of IntervalCertificate
        The interval-delay sub-certificates (empty for a constant delay).
    functional : Functional
        The functional searched for (interval delays: always COMMON).
    """

    status: CertificateStatus
    order: int
    tau: float
    vertices: int
    margins: tuple[BlockMargin, ...]
    solve_time: float
    reason: str
    interval: tuple[IntervalCertificate, ...] = field(default=(), repr=False)
    functional: Functional = Functional.COMMON

    @property
    def certified(self) -> bool:
        return self.status is CertificateStatus.CERTIFIED

    def __str__(self) -> str:
        return (
            f"polytope certificate ({self.vertices} vertices, order {self.order}, {self.functional.value}) "
            f"at tau = {self.tau:.6g} s: "
            f"{self.status.value} ({1e3 * self.solve_time:.1f} ms)\n  {self.reason}"
        )


def _common_constant(
    plants: list[tuple[np.ndarray, np.ndarray]], tau: float, order: int, margin_tol: float
) -> tuple[CertificateStatus, tuple[BlockMargin, ...], float, str]:
    """Seuret-Gouaisbaut order-N LMI with common (P, S, R) at every plant, in time normalised by τ.

    The blocks are those of [`lmi_blocks`][mrpctl.design.lmi_blocks] (linear in P, S, R) at every
    vertex (τA, τA_d) with τ = 1; the same function re-checks the solution in float64.
    """
    n = plants[0][0].shape[0]
    scaled = [(tau * a, tau * a_d) for a, a_d in plants]
    size = (order + 1) * n
    unknowns = [UnknownRate("P", size, size, True), UnknownRate("S", n, n, True), UnknownRate("R", n, n, True)]

    def blocks(mats: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        out: dict[str, np.ndarray] = {}
        for i, (a, a_d) in enumerate(scaled):
            for name, block in lmi_blocks(a, a_d, 1.0, mats["P"], mats["S"], mats["R"], order=order).items():
                if name == "derivative" or i == 0:
                    out[f"{name}[vertex {i}]"] = block
        return out

    start = time.perf_counter()
    outcome, values, _ = solve_lmi(unknowns, blocks, {}, ["positivity[vertex 0]", "S[vertex 0]", "R[vertex 0]"])
    elapsed = time.perf_counter() - start
    if values is None:
        return CertificateStatus.SOLVER_FAILED, (), elapsed, outcome.error or f"solver status {outcome.status!r}"
    margins = interval_margins(blocks(values))
    worst = min(margins, key=lambda m: m.relative)
    ok = worst.relative >= margin_tol
    status = CertificateStatus.CERTIFIED if ok else CertificateStatus.NOT_CERTIFIED
    return status, margins, elapsed, f"smallest relative margin {worst.relative:.3g} ({worst.name})"


# --------------------------------------------------------------------------------------------
# Vertex-dependent functional (descriptor / Finsler form), constant delay, time normalised by τ.
#
# ζ̃ = [x(t); x(t − 1); Ω₀ … Ω_{N−1}; ẋ(t)] (m + n entries, m = (N+2)n). At vertex i,
#   Ψᵢ = He(G̃ᵀ Pᵢ H̃) + diag(Sᵢ, −Sᵢ, 0, 0) + e_ẋᵀ Rᵢ e_ẋ − Σₖ (2k+1) Ẽₖᵀ Rᵢ Ẽₖ,
#   Φ̃ᵢ = Ψᵢ + He(M Cᵢ),  Cᵢ = [Aᵢ, A_d,ᵢ, 0, −I]  (M common to all vertices),
# where H̃ = [e_ẋ; Ẽ₀ … Ẽ_{N−1}] no longer contains the plant. Ψ is linear in (Pᵢ, Sᵢ, Rᵢ) and
# independent of the plant, He(M C) is affine in the plant: Σ αᵢ Φ̃ᵢ = Ψ(α) + He(M C(α)), so
# Φ̃ᵢ ≺ 0 at every vertex gives, for every convex combination α of the vertices, the functional
# V(α) = Σ αᵢ Vᵢ (constant α: no α̇ term) whose derivative is ζ̃ᵀ Ψ(α) ζ̃ < 0 on C(α) ζ̃ = 0, i.e.
# along ẋ = A(α) x + A_d(α) x(t − 1). At a single vertex Finsler's lemma makes this equivalent to
# the Seuret-Gouaisbaut LMI of lmi_blocks (the restriction of Ψ to ẋ = F₀ζ is Φ_N, tested).
# Source of the construction: Y. He, M. Wu, J.-H. She, G.-P. Liu, "Parameter-dependent Lyapunov
# functional for stability of time-delay systems with polytopic-type uncertainties", IEEE TAC
# 49(5), 828-832, 2004 (free-weighting matrices); E. Fridman, U. Shaked, "An improved
# stabilization method for linear time-delay systems", IEEE TAC 47(11), 2002 (descriptor form).
# --------------------------------------------------------------------------------------------


def vertex_blocks(A: Any, A_d: Any, P: Any, S: Any, R: Any, M: Any, *, order: int) -> dict[str, np.ndarray]:
    """The float64 blocks of the vertex-dependent criterion at one vertex, delay normalised to 1.

    Every block must be positive definite: ``"S"`` (Sᵢ), ``"R"`` (Rᵢ), ``"positivity"``
    (Pᵢ + diag(0, Sᵢ, 3Sᵢ, …)) and ``"derivative"`` (−Φ̃ᵢ, see the comment above this function).

    Parameters
    ----------
    A, A_d : array_like
        (n, n) vertex matrices in time normalised by τ (τA, τA_d).
    P, S, R : array_like
        The vertex's decision matrices, ((N+1)n)² and n² symmetric.
    M : array_like
        ((N+3)n, n) slack common to the vertices.
    order : int
        Bessel-Legendre order N.
    """
    a = np.asarray(A, dtype=float)
    a_d = np.asarray(A_d, dtype=float)
    n = a.shape[0]
    p = np.asarray(P, dtype=float)
    s = np.asarray(S, dtype=float)
    r = np.asarray(R, dtype=float)
    mm = np.asarray(M, dtype=float)
    e_mats, g0, g1 = lmi_structure(n, order)
    m = (order + 2) * n
    k = m + n
    pad = np.zeros((n, n))
    ext = [np.hstack((e, pad)) for e in e_mats]
    e_dx = np.zeros((n, k))
    e_dx[:, m:] = np.eye(n)
    g = np.hstack((np.vstack((g0, g1)), np.zeros((g0.shape[0] + g1.shape[0], n))))
    h = np.vstack([e_dx, *ext[:order]])
    he = g.T @ p @ h
    phi = he + he.T
    phi[:n, :n] += s
    phi[n : 2 * n, n : 2 * n] -= s
    phi += e_dx.T @ r @ e_dx
    for j, e in enumerate(ext):
        phi -= (2 * j + 1) * e.T @ r @ e
    c = np.zeros((n, k))
    c[:, :n] = a
    c[:, n : 2 * n] = a_d
    c[:, m:] = -np.eye(n)
    slack = mm @ c
    phi += slack + slack.T
    pos = p.copy()
    for j in range(order):
        sl = slice((j + 1) * n, (j + 2) * n)
        pos[sl, sl] += (2 * j + 1) * s
    return {"S": _sym(s), "R": _sym(r), "positivity": _sym(pos), "derivative": _sym(-phi)}


def _sym(m: np.ndarray) -> np.ndarray:
    return 0.5 * (m + m.T)


def _sym_basis(size: int) -> list[np.ndarray]:
    out = []
    for i in range(size):
        for j in range(i, size):
            b = np.zeros((size, size))
            b[i, j] = b[j, i] = 1.0
            out.append(b)
    return out


@dataclass(frozen=True)
class _Attempt:
    balanced: bool
    slack_bound: float | None


#: The retries after a solver failure: balanced coordinates, then a bound on the slack M (an
#: unbounded optimal face in M is what made Clarabel stall), then both.
_ATTEMPTS = (
    _Attempt(False, None),
    _Attempt(True, None),
    _Attempt(False, 1e3),
    _Attempt(True, 1e3),
)


def _solve_vertex(
    plants: list[tuple[np.ndarray, np.ndarray]],
    order: int,
    slack_bound: float | None,
) -> tuple[SolveOutcome, list[dict[str, np.ndarray]] | None, float]:
    """Maximise t: every block of every vertex ≽ t I, the traces of the S, R, positivity blocks sum to 1."""
    # deferred: cvxpy (about 1 s to import), only when an LMI is solved
    import cvxpy as cp

    n = plants[0][0].shape[0]
    size = (order + 1) * n
    k = (order + 3) * n
    zero_a = np.zeros((n, n))
    zeros = {"P": np.zeros((size, size)), "S": np.zeros((n, n)), "R": np.zeros((n, n)), "M": np.zeros((k, n))}
    bases = [("P", b) for b in _sym_basis(size)] + [("S", b) for b in _sym_basis(n)] + [("R", b) for b in _sym_basis(n)]
    names = ("S", "R", "positivity", "derivative")
    # Ψ does not depend on the plant: one linear map for all vertices.
    cols: dict[str, list[np.ndarray]] = {name: [] for name in names}
    trace = np.zeros(len(bases))
    for idx, (name, b) in enumerate(bases):
        mats = {**zeros, name: b}
        blocks = vertex_blocks(zero_a, zero_a, mats["P"], mats["S"], mats["R"], mats["M"], order=order)
        for key in names:
            cols[key].append(blocks[key].reshape(-1))
        trace[idx] = sum(float(np.trace(blocks[key])) for key in ("S", "R", "positivity"))
    psi = {key: np.column_stack(c) for key, c in cols.items()}
    m_bases = []
    for i in range(k):
        for j in range(n):
            b = np.zeros((k, n))
            b[i, j] = 1.0
            m_bases.append(b)
    v = cp.Variable((len(plants), len(bases)), name="v")
    w = cp.Variable(len(m_bases), name="m")
    t = cp.Variable(name="t")
    cons = []
    for i, (a, a_d) in enumerate(plants):
        slack_cols = np.column_stack(
            [
                vertex_blocks(a, a_d, zeros["P"], zeros["S"], zeros["R"], b, order=order)["derivative"].reshape(-1)
                for b in m_bases
            ]
        )
        for key in names:
            dim = n if key in ("S", "R") else (size if key == "positivity" else k)
            flat = psi[key] @ v[i] + (slack_cols @ w if key == "derivative" else 0)
            expr = cp.reshape(flat, (dim, dim), order="C")
            cons.append(0.5 * (expr + expr.T) >> t * np.eye(dim))
    cons.append(cp.sum(v @ trace) == 1.0)
    if slack_bound is not None:
        cons.append(cp.norm(w, "inf") <= slack_bound)
    problem = cp.Problem(cp.Maximize(t), cons)
    outcome = solve(problem)
    if outcome.error or outcome.status != OPTIMAL or v.value is None or w.value is None or t.value is None:
        return outcome, None, math.nan
    m_val = sum((c * b for c, b in zip(np.asarray(w.value, dtype=float), m_bases, strict=True)), zeros["M"])
    out = []
    for i in range(len(plants)):
        mats = {key: zeros[key].copy() for key in ("P", "S", "R")}
        for c, (name, b) in zip(np.asarray(v.value[i], dtype=float), bases, strict=True):
            mats[name] = mats[name] + c * b
        mats["M"] = np.asarray(m_val)
        out.append(mats)
    return outcome, out, float(t.value)


def _vertex_constant(
    plants: list[tuple[np.ndarray, np.ndarray]],
    tau: float,
    order: int,
    margin_tol: float,
) -> tuple[CertificateStatus, tuple[BlockMargin, ...], float, str]:
    """The vertex-dependent criterion at delay τ, retried on solver failure (see ``_ATTEMPTS``)."""
    scaled = [(tau * a, tau * a_d) for a, a_d in plants]
    mag = sum((np.abs(a) + np.abs(a_d) for a, a_d in scaled), np.zeros_like(scaled[0][0]))
    scale = balancing(mag, np.zeros_like(mag))
    start = time.perf_counter()
    failures = []
    for attempt in _ATTEMPTS:
        if attempt.balanced and np.all(scale == 1.0):
            continue
        use = [(similarity(a, scale), similarity(a_d, scale)) for a, a_d in scaled] if attempt.balanced else scaled
        outcome, values, _ = _solve_vertex(use, order, attempt.slack_bound)
        label = f"{'balanced' if attempt.balanced else 'plain'}{'' if attempt.slack_bound is None else ', |M| bounded'}"
        if values is None:
            failures.append(f"{label}: {outcome.error or outcome.status}")
            continue
        margins: list[BlockMargin] = []
        for i, ((a, a_d), mats) in enumerate(zip(use, values, strict=True)):
            blocks = vertex_blocks(a, a_d, mats["P"], mats["S"], mats["R"], mats["M"], order=order)
            margins += [
                BlockMargin(f"{m.name}[vertex {i}]", m.eigenvalue, m.relative) for m in interval_margins(blocks)
            ]
        worst = min(margins, key=lambda m: m.relative)
        elapsed = time.perf_counter() - start
        ok = worst.relative >= margin_tol
        retry = f" after {len(failures)} solver failure(s) ({'; '.join(failures)})" if failures else ""
        why = f"vertex-dependent ({label}){retry}: smallest relative margin {worst.relative:.3g} ({worst.name})"
        return (CertificateStatus.CERTIFIED if ok else CertificateStatus.NOT_CERTIFIED), tuple(margins), elapsed, why
    elapsed = time.perf_counter() - start
    return (
        CertificateStatus.SOLVER_FAILED,
        (),
        elapsed,
        "vertex-dependent: every attempt failed: " + "; ".join(failures),
    )


def _interval_with_retry(
    plants: list[tuple[np.ndarray, np.ndarray]], lo: float, tau: float, rate: DelayRate, order: int, margin_tol: float
) -> tuple[IntervalCertificate, str]:
    """solve_interval; after SOLVER_FAILED once more in balanced coordinates (exact power-of-two similarity),
    then the preconditioned problems of the sampled loop (difference coordinates, design/lmi.md 7.3).

    Each retry is an equivalent LMI re-checked in float64, so the first one that certifies is sound.
    """
    cert = solve_interval(plants, lo, tau, rate, order, margin_tol)
    if cert.status is not CertificateStatus.SOLVER_FAILED:
        return cert, ""
    mag = sum((np.abs(a) + np.abs(a_d) for a, a_d in plants), np.zeros_like(plants[0][0]))
    scale = balancing(mag, np.zeros_like(mag))
    last, prefix = cert, ""
    if not np.all(scale == 1.0):
        balanced = [(similarity(a, scale), similarity(a_d, scale)) for a, a_d in plants]
        last = solve_interval(balanced, lo, tau, rate, order, margin_tol)
        prefix = f"balanced retry after solver failure ({cert.reason}): "
        if last.certified:
            return last, prefix
    for scale_variables in (False, True):
        retry = solve_interval_preconditioned(plants, lo, tau, rate, order, margin_tol, scale_variables=scale_variables)
        if retry.certified:
            return retry, f"preconditioned retry after solver failure ({cert.reason}): "
    return last, prefix


def _check_functional(functional: Any) -> None:
    if functional is not None and not isinstance(functional, Functional):
        raise SpecificationError(f"functional must be a Functional or None, got {functional!r}")


def _use_vertex(functional: Functional | None, vertices: int) -> bool:
    if functional is None:
        return vertices <= VERTEX_LIMIT
    return functional is Functional.VERTEX


def certify_polytope(
    polytope: InertiaPolytope,
    K: Any,
    tau: float,
    *,
    order: int = 2,
    tau_min: float | None = None,
    delay_rate: DelayRate | float | None = None,
    rate: Any = NOT_GIVEN,
    margin_tol: float = DEFAULT_MARGIN_TOL,
    functional: Functional | None = None,
    decay_rate: float = 0.0,
) -> PolytopeCertificate:
    """Certify u = K x(t − τ) for every inertia of the polytope (per axis when the loop splits, else 6×6).

    With ``tau_min=None`` the delay is constant τ and the criterion is the order-N Bessel-Legendre
    LMI (Seuret & Gouaisbaut 2015): with ``Functional.VERTEX`` (default up to 8 vertices) in descriptor
    form with (Pᵢ, Sᵢ, Rᵢ) per vertex and a common slack (re-checked by `vertex_blocks` at
    every vertex); with ``Functional.COMMON`` as in [`certify`][mrpctl.design.certify] with (P, S, R)
    common to the vertices (re-checked by [`lmi_blocks`][mrpctl.design.lmi_blocks]). Otherwise the delay
    varies in [tau_min, tau] with ``delay_rate`` and the interval criterion is used with common matrices
    (``functional`` is then ignored).

    Parameters
    ----------
    polytope : InertiaPolytope
    K : array_like
        (3, 6) gain on x = [σ; ω/4] (N m).
    tau : float
        Constant delay, or the upper end of the interval (s).
    order : int, optional
        Bessel-Legendre order N (default 2).
    tau_min : float, optional
        Lower end of a time-varying delay interval (s).
    delay_rate : DelayRate or float, optional
        Bound on the interval delay's rate dτ/dt (None: unknown); ``rate`` is its deprecated name.
    margin_tol : float, optional
        Relative eigenvalue margin every re-computed block must keep.
    functional : Functional, optional
        Which functional (constant delay only); None (default): VERTEX for sub-problems of at most
        `VERTEX_LIMIT` vertices (every diagonal box: 2 per axis), COMMON above.
    decay_rate : float, optional
        α >= 0 (1/s): certify the shifted loops ż = (A + αI) z + g A_d z(t − τ(t)) instead, with
        g = e^{ατ} (constant delay) or g ∈ {e^{ατ_min}, e^{ατ_max}} as extra vertices (interval:
        z = e^{αt} x sees the time-varying gain e^{ατ(t)}); then every solution decays like e^{−αt}.
        Default 0 (the plain loops).
    """
    if not isinstance(polytope, InertiaPolytope):
        raise SpecificationError(f"polytope must be an InertiaPolytope, got {type(polytope).__name__}")
    rate = delay_rate_argument(delay_rate, rate)
    tau = positive_scalar("tau", tau)
    order = order_value(order)
    margin_tol = positive_scalar("margin_tol", margin_tol)
    _check_functional(functional)
    alpha = nonnegative_scalar("decay_rate", decay_rate)
    axes = _axis_loops(polytope, K)
    groups = axes if axes is not None else [_vertex_loops(polytope, K)]
    if alpha > 0.0:
        ends = (tau,) if tau_min is None else (nonnegative_scalar("tau_min", tau_min), tau)
        gains = sorted({math.exp(alpha * end) for end in ends})
        groups = [[(a + alpha * np.eye(a.shape[0]), g * a_d) for a, a_d in plants for g in gains] for plants in groups]
    status = CertificateStatus.CERTIFIED
    margins: list[BlockMargin] = []
    total = 0.0
    reasons = []
    intervals: list[IntervalCertificate] = []
    for gi, plants in enumerate(groups):
        if tau_min is None:
            if _use_vertex(functional, len(plants)):
                st, mg, tm, why = _vertex_constant(plants, tau, order, margin_tol)
            else:
                st, mg, tm, why = _common_constant(plants, tau, order, margin_tol)
        else:
            lo = nonnegative_scalar("tau_min", tau_min)
            if not tau > lo:
                raise SpecificationError(f"tau must exceed tau_min, got [{lo}, {tau}]")
            cert, retried = _interval_with_retry(plants, lo, tau, rate_value(rate), order, margin_tol)
            intervals.append(cert)
            st, mg, tm, why = cert.status, cert.margins, cert.solve_time, retried + cert.reason
        total += tm
        margins += list(mg)
        reasons.append(f"{'axis ' + str(gi + 1) if axes is not None else '6x6'}: {st.value}, {why}")
        if st is CertificateStatus.SOLVER_FAILED:
            status = CertificateStatus.SOLVER_FAILED
        elif st is CertificateStatus.NOT_CERTIFIED and status is CertificateStatus.CERTIFIED:
            status = CertificateStatus.NOT_CERTIFIED
    return PolytopeCertificate(
        status=status,
        order=order,
        tau=tau,
        vertices=sum(len(g) for g in groups),
        margins=tuple(margins),
        solve_time=total,
        reason="; ".join(reasons),
        interval=tuple(intervals),
        functional=(
            Functional.VERTEX
            if tau_min is None and all(_use_vertex(functional, len(g)) for g in groups)
            else Functional.COMMON
        ),
    )


def certify_vertices(
    plants: Any,
    tau: float,
    *,
    order: int = 2,
    margin_tol: float = DEFAULT_MARGIN_TOL,
    functional: Functional | None = None,
) -> PolytopeCertificate:
    """Certify ẋ = A x + A_d x(t − τ) for every (A, A_d) in the convex hull of the given vertices.

    The general form of [`certify_polytope`][mrpctl.design.certify_polytope] (constant delay), for any polytope of
    plants with
    a constant uncertain parameter.

    Parameters
    ----------
    plants : sequence of (A, A_d)
        The vertices, (n, n) matrices each (1/s).
    tau : float
        Constant delay τ (s).
    order : int, optional
        Bessel-Legendre order N (default 2).
    margin_tol : float, optional
        Relative eigenvalue margin every re-computed block must keep.
    functional : Functional, optional
        VERTEX: vertex-dependent functional with a common Finsler slack; COMMON: one functional for
        all vertices; None (default): VERTEX up to `VERTEX_LIMIT` vertices, else COMMON.
    """

    checked = [system_matrices(a, a_d) for a, a_d in plants]
    if not checked:
        raise SpecificationError("plants: need at least one vertex (A, A_d)")
    if len({a.shape for a, _ in checked}) != 1:
        raise SpecificationError("plants: every vertex must have the same state dimension")
    tau = positive_scalar("tau", tau)
    order = order_value(order)
    margin_tol = positive_scalar("margin_tol", margin_tol)
    _check_functional(functional)
    used = Functional.VERTEX if _use_vertex(functional, len(checked)) else Functional.COMMON
    solver = _vertex_constant if used is Functional.VERTEX else _common_constant
    st, mg, tm, why = solver(checked, tau, order, margin_tol)
    return PolytopeCertificate(
        status=st,
        order=order,
        tau=tau,
        vertices=len(checked),
        margins=mg,
        solve_time=tm,
        reason=why,
        functional=used,
    )


def exact_polytope_margin(polytope: InertiaPolytope, K: Any, *, points: int = 41) -> float:
    """The smallest exact constant-delay margin (s) over a grid of the J-set (the reference).

    Diagonal sets: per axis, ``points`` values of Jᵢᵢ across the interval (the loop splits, the
    margin of the 6×6 loop is the smallest axis margin). With products of inertia: a grid of
    min(points, 3) values per each of the 6 entries (3⁶ = 729 full 6×6 margins); grid points that
    are not physical inertias are skipped.
    """

    k = gain_matrix(K)
    j0 = np.diag(polytope.nominal.inertia)
    tol = polytope.tolerance
    worst = math.inf
    a6 = np.block([[np.zeros((3, 3)), np.eye(3)], [np.zeros((3, 3)), np.zeros((3, 3))]])
    axes = _axis_loops(polytope, k)
    if axes is not None:
        a2 = np.array([[0.0, 1.0], [0.0, 0.0]])
        for i in range(3):
            for j in np.linspace((1 - tol) * j0[i], (1 + tol) * j0[i], points):
                a_d = np.array([[0.0, 0.0], [k[i, i] / (4 * j), k[i, 3 + i] / (4 * j)]])
                worst = min(worst, delay_margin(a2, a_d).margin)
        return worst
    q = min(points, 3)
    p = polytope.product_bound
    grids = [np.linspace((1 - tol) * j0[i], (1 + tol) * j0[i], q) for i in range(3)]
    off = np.linspace(-p, p, q)
    for d0, d1, d2, e01, e02, e12 in itertools.product(*grids, off, off, off):
        j = np.array([[d0, e01, e02], [e01, d1, e12], [e02, e12, d2]])
        eig = np.linalg.eigvalsh(j)
        if eig[0] <= 0 or eig[2] > eig[0] + eig[1]:
            continue
        b = np.vstack((np.zeros((3, 3)), np.linalg.inv(j) / 4.0))
        worst = min(worst, delay_margin(a6, b @ k).margin)
    return worst


def max_stable_tolerance(spacecraft: Spacecraft, K: Any, tau: float, *, points: int = 41, rtol: float = 1e-4) -> float:
    """The largest relative tolerance tol such that every grid inertia of the diagonal box is stable at τ.

    Bisection on tol ∈ [0, 1) with [`exact_polytope_margin`][mrpctl.design.exact_polytope_margin] (products of inertia
    zero).
    Returns nan when the nominal loop is unstable at τ.
    """
    tau = positive_scalar("tau", tau)

    def ok(tol: float) -> bool:
        return exact_polytope_margin(inertia_polytope(spacecraft, tol), K, points=points) > tau

    if not ok(0.0):
        return math.nan
    good, bad = 0.0, 0.999
    if ok(bad):
        return bad
    for _ in range(100):
        if bad - good <= rtol * max(good, 1e-6):
            break
        mid = 0.5 * (good + bad)
        if ok(mid):
            good = mid
        else:
            bad = mid
    return good


def max_certified_tolerance(
    spacecraft: Spacecraft,
    K: Any,
    tau: float,
    *,
    order: int = 2,
    product_bound: float = 0.0,
    rtol: float = 1e-3,
) -> tuple[float, PolytopeCertificate | None]:
    """The largest relative tolerance certified at τ by [`certify_polytope`][mrpctl.design.certify_polytope] (bisection,
    terminates).

    Returns (tol, certificate at tol); (nan, None) when the nominal loop is not certified.
    """
    tau = positive_scalar("tau", tau)

    def test(tol: float) -> PolytopeCertificate:
        return certify_polytope(inertia_polytope(spacecraft, tol, product_bound=product_bound), K, tau, order=order)

    first = test(0.0)
    if not first.certified:
        return math.nan, None
    good, cert = 0.0, first
    bad = 0.999
    for _ in range(60):
        if bad - good <= rtol * max(good, 1e-3):
            break
        mid = 0.5 * (good + bad)
        trial = test(mid)
        if trial.certified:
            good, cert = mid, trial
        else:
            bad = mid
    return good, cert
