"""Looped-functional certificate of a sampled-data loop (zero-order hold, no extra delay).

u(t) = K x(t_k) on [t_k, t_k + h), ẋ = A x + B u. With τ = t − t_k ∈ [0, h) and
ζ = [x(t); x(t_k); v], v = (1/τ)∫_{t_k}^{t} x, the criterion is Seuret's looped functional
(Seuret, Automatica 48(1), 2012) extended by the Wirtinger-based free-matrix inequality
(Zeng, He, Wu & She, IEEE TAC 60(10), 2015): V(x) = xᵀPx and

    W(τ) = (h − τ)[zᵀ S̄ z + ∫_{t_k}^{t} ẋᵀRẋ] + τ(h − τ) ζᵀXζ,   z = [x − x_k; ∫_{t_k}^t x; x_k],
    S̄ = [[S, S1], [S1ᵀ, 0]],

with W = 0 at τ = 0 and at τ = h (the functional is *looped*: no sign condition on W). If
d(V + W)/dt < 0 on every sampling interval then V(x(t_{k+1})) < V(x(t_k)): the sampled loop is
stable. −∫ẋᵀRẋ is bounded by Wirtinger's inequality in free-matrix form
(−∫ẋᵀRẋ ≤ τζᵀ(N1R⁻¹N1ᵀ + N2(3R)⁻¹N2ᵀ)ζ + 2ζᵀ(N1(x − x_k) + N2(x + x_k − 2v))), so the derivative
bound f(τ) is a matrix polynomial of degree 2 in τ; f ≺ 0 on [0, h] follows from f(0) ≺ 0,
f(h) ≺ 0 (Schur complement) and f(0) − h²f₂ ≺ 0 (f₂ the τ² coefficient): vertices bound a convex
f, the tangent at τ = h bounds a concave one (the quadratic negative-determination lemma, Kim,
Automatica 64, 2016, cited from memory; the two-line proof is in design/lmi.md, section 7.2).

The certificate is for the *periodic* loop of period h (the loop mrpctl simulates and the exact
lifted reference tests). The problem is solved in time normalised by h (A·h, BK·h), so it is
well scaled at 1 kHz; CERTIFIED only on Clarabel ``optimal`` and a positive relative margin of
every block recomputed in float64 from the returned matrices.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mrpctl._validation import integer, positive_scalar, readonly
from mrpctl.design.interval import UnknownRate, interval_margins, solve_lmi
from mrpctl.design.lmi import DEFAULT_MARGIN_TOL, BlockMargin, CertificateStatus
from mrpctl.design.sampled import SampledCertification, SampledCriterion, bisect_period, sampled_system
from mrpctl.errors import SpecificationError

__all__ = [
    "LoopedCertificate",
    "certify_looped",
    "looped_blocks",
    "max_looped_period",
]


@dataclass(frozen=True, eq=False)
class LoopedCertificate:
    """Result of [`certify_looped`][mrpctl.design.certify_looped] at one sampling period.

    Attributes
    ----------
    status : CertificateStatus
        CERTIFIED only when Clarabel reports ``optimal`` and every block recomputed in float64 keeps
        a relative margin of at least ``margin_tol``.
    period : float
        Sampling period h (s).
    matrices : dict of str to numpy.ndarray
        Decision matrices (read-only) in time normalised by h; empty when the solver failed.
    margins : tuple of BlockMargin
    solver_status : str
    solve_time : float
        Wall time (s) of the build and solve.
    solver_margin : float
        Optimal common margin t of the normalised problem.
    reason : str
    """

    status: CertificateStatus
    period: float
    matrices: dict[str, np.ndarray] = field(repr=False)
    margins: tuple[BlockMargin, ...]
    solver_status: str
    solve_time: float
    solver_margin: float
    reason: str

    @property
    def certified(self) -> bool:
        """True when the LMI proves stability of the periodic sampled loop."""
        return self.status is CertificateStatus.CERTIFIED

    @property
    def min_margin(self) -> float:
        """The smallest relative block margin (nan when nothing was recomputed)."""
        return min((m.relative for m in self.margins), default=math.nan)

    def __str__(self) -> str:
        return (
            f"looped functional + Wirtinger, sampled h = {self.period:.6g} s: {self.status.value} "
            f"(CLARABEL {self.solver_status}, {1e3 * self.solve_time:.1f} ms)\n  {self.reason}"
        )


def _selectors(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    eye = np.eye(3 * n)
    return eye[:n], eye[n : 2 * n], eye[2 * n :]


def _sym(m: np.ndarray) -> np.ndarray:
    return m + m.T


def _phi0(a: np.ndarray, a_d: np.ndarray, tau: float, mats: dict[str, np.ndarray]) -> np.ndarray:
    """d(V + W)/dt without the −∫ẋᵀRẋ term, as a 3n×3n matrix on ζ (h = 1)."""
    n = a.shape[0]
    ex, ek, ev = _selectors(n)
    f = a @ ex + a_d @ ek
    P, S, S1, X, R = (mats[k] for k in ("P", "S", "S1", "X", "R"))
    sbar = np.block([[S, S1], [S1.T, np.zeros((n, n))]])
    z = np.vstack([ex - ek, tau * ev, ek])
    zdot = np.vstack([f, ex, np.zeros((n, 3 * n))])
    ztau = np.vstack([tau * f, np.zeros((n, 3 * n)), ex - ev])
    out = _sym(ex.T @ P @ f)
    out = out - z.T @ sbar @ z + (1.0 - tau) * _sym(z.T @ sbar @ zdot)
    out = out + (1.0 - 2.0 * tau) * X + (1.0 - tau) * _sym(X @ ztau)
    return out + (1.0 - tau) * (f.T @ R @ f)


def looped_blocks(a: np.ndarray, a_d: np.ndarray, matrices: dict[str, Any]) -> dict[str, np.ndarray]:
    """Every LMI block of the looped criterion in float64, in time normalised by h (A·h, A_d·h = BK·h).

    Each block must be positive definite: P, R, and −f(0), −[[f(1), N], [Nᵀ, −diag(R, 3R)]] (Schur
    form of f(1)), −(f(0) − f₂) (f₂ the τ² coefficient of f), with f(τ) the derivative bound.
    """
    n = a.shape[0]
    mats = {k: np.asarray(v, dtype=float) for k, v in matrices.items()}
    ex, ek, ev = _selectors(n)
    nn = mats["N"]
    free = _sym(nn @ np.vstack([ex - ek, ex + ek - 2.0 * ev]))
    p0, ph, p1 = (_phi0(a, a_d, tau, mats) for tau in (0.0, 0.5, 1.0))
    r = mats["R"]
    rr = np.block([[r, np.zeros((n, n))], [np.zeros((n, n)), 3.0 * r]])
    end = np.block([[p1 + free, nn], [nn.T, -rr]])
    curv = -p0 - 2.0 * p1 + 4.0 * ph + free
    blocks = {
        "P": 0.5 * _sym(mats["P"]),
        "R": 0.5 * _sym(r),
        "derivative[tau 0]": -0.5 * _sym(p0 + free),
        "derivative[tau h]": -0.5 * _sym(end),
        "derivative[curvature]": -0.5 * _sym(curv),
    }
    return blocks


def _unknowns(n: int) -> list[UnknownRate]:
    return [
        UnknownRate("P", n, n, True),
        UnknownRate("R", n, n, True),
        UnknownRate("S", 2 * n, 2 * n, True),
        UnknownRate("S1", 2 * n, n, False),
        UnknownRate("X", 3 * n, 3 * n, True),
        UnknownRate("N", 3 * n, 2 * n, False),
    ]


def solve_looped(a: np.ndarray, a_d: np.ndarray, period: float, margin_tol: float) -> LoopedCertificate:
    """Build and solve the normalised looped problem for ẋ = A x + A_d x(t_k); the re-check decides."""
    n = a.shape[0]
    sa, sad = period * a, period * a_d

    def blocks(mats: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        return looped_blocks(sa, sad, mats)

    start = time.perf_counter()
    outcome, values, t_opt = solve_lmi(_unknowns(n), blocks, {}, ["P", "R"])
    elapsed = time.perf_counter() - start
    if values is None:
        reason = outcome.error or f"solver status {outcome.status!r} is not 'optimal': no certificate"
        return LoopedCertificate(
            CertificateStatus.SOLVER_FAILED, period, {}, (), outcome.status, elapsed, math.nan, reason
        )
    margins = interval_margins(blocks(values))
    worst = min(margins, key=lambda m: m.relative)
    ok = worst.relative >= margin_tol
    reason = (
        f"every block positive definite; smallest relative margin {worst.relative:.3g} ({worst.name})"
        if ok
        else f"block {worst.name!r} has relative margin {worst.relative:.3g} < {margin_tol:g} (t = {t_opt:.3g})"
    )
    return LoopedCertificate(
        CertificateStatus.CERTIFIED if ok else CertificateStatus.NOT_CERTIFIED,
        period,
        {k: readonly(v) for k, v in values.items()},
        margins,
        outcome.status,
        elapsed,
        t_opt,
        reason,
    )


def certify_looped(
    A: Any, B: Any, K: Any, period: float, *, margin_tol: float = DEFAULT_MARGIN_TOL
) -> LoopedCertificate:
    """Certify the periodic sampled loop u(t) = K x(t_k) on ẋ = A x + B u by the looped functional.

    Parameters
    ----------
    A, B, K : array_like
        (n, n) (1/s), (n, m) and (m, n).
    period : float
        Sampling period h (s).
    margin_tol : float, optional
        Relative eigenvalue margin each recomputed block must keep (default 1e-9).

    Returns
    -------
    LoopedCertificate

    Examples
    --------
    >>> certify_looped([[0, 1], [0, -0.1]], [[0], [0.1]], [[-3.75, -11.5]], 1.6).certified
    True
    """
    a, b, k = sampled_system(A, B, K)
    h = positive_scalar("period", period)
    return solve_looped(a, b @ k, h, positive_scalar("margin_tol", margin_tol))


def max_looped_period(
    A: Any,
    B: Any,
    K: Any,
    *,
    rtol: float = 1e-3,
    period_limit: float | None = None,
    margin_tol: float = DEFAULT_MARGIN_TOL,
    delay_samples: int = 0,
) -> SampledCertification:
    """The largest sampling period certified by [`certify_looped`][mrpctl.design.certify_looped] (bisection below the
    exact period).

    Returns a [`SampledCertification`][mrpctl.design.SampledCertification] whose ``criterion`` is
    ``SampledCriterion.LOOPED``. Only ``delay_samples = 0`` is supported (for d > 0 use
    [`max_certified_period`][mrpctl.design.max_certified_period]).
    """
    a, b, k = sampled_system(A, B, K)
    if integer("delay_samples", delay_samples, minimum=0) != 0:
        raise SpecificationError(
            "delay_samples: the looped-functional criterion covers d = 0 only; "
            "for a delay of d > 0 samples use sampled.max_certified_period (input-delay approach)"
        )
    rtol = positive_scalar("rtol", rtol)
    margin_tol = positive_scalar("margin_tol", margin_tol)
    return bisect_period(
        a,
        b,
        k,
        0,
        lambda h: solve_looped(a, b @ k, h, margin_tol),
        rtol=rtol,
        period_limit=period_limit,
        criterion=SampledCriterion.LOOPED,
        order=1,
    )
