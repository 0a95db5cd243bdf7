"""The sampled-data loop as flown: period h, zero-order hold, a delay of d samples.

u(t) = K x(t_{k−d}) for t ∈ [t_k, t_{k+1}), t_k = k h, on ẋ = A x + B u. Two answers:

- **exact**: the lifted discrete-time system x_{k+1} = Φ x_k + Γ K x_{k−d}, Φ = e^{Ah},
  Γ = ∫₀ʰ e^{As} ds B, is stable iff the spectral radius of its companion matrix (size n(d+1))
  is below 1 ([`sampled_stability`][mrpctl.design.sampled_stability],
  [`max_stable_delay_samples`][mrpctl.design.max_stable_delay_samples],
  [`max_stable_period`][mrpctl.design.max_stable_period]);
- **certified**: the input-delay approach, ẋ = A x + B K x(t − τ(t)) with the sawtooth
  τ(t) = d h + (t − t_k) ∈ [d h, (d+1) h), τ̇ = 1, through the interval criterion of
  `mrpctl.design.interval` ([`certify_sampled`][mrpctl.design.certify_sampled],
  [`max_certified_period`][mrpctl.design.max_certified_period]).

For a spacecraft with a gain that splits per axis, [`spacecraft_axes`][mrpctl.design.spacecraft_axes] returns the three
2×2
(A, B, K) triples, so d = 500 (τ = 0.5 s at 1 kHz) is a 1002×1002 eigenproblem per axis.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg

from mrpctl._validation import finite_array, integer, positive_scalar
from mrpctl.design._common import order_value
from mrpctl.design.interval import DelayRate, IntervalCertificate, solve_interval, solve_interval_preconditioned
from mrpctl.design.lmi import DEFAULT_MARGIN_TOL, CertificateStatus, SearchStatus, criterion_name
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.model import gain_matrix, plant_model
from mrpctl.spacecraft import Spacecraft, check_spacecraft

__all__ = [
    "MAX_LIFTED_SIZE",
    "SampledCertification",
    "SampledCriterion",
    "SampledStability",
    "certify_sampled",
    "lifted_matrices",
    "max_certified_delay_samples",
    "max_certified_period",
    "max_stable_delay_samples",
    "max_stable_period",
    "sampled_stability",
    "spacecraft_axes",
]

#: Largest companion matrix (rows) `sampled_stability` builds densely (8·N² bytes: 128 MB at 4000).
MAX_LIFTED_SIZE = 4000


def sampled_system(A: Any, B: Any, K: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Check (A, B, K) of ẋ = A x + B u, u = K x(t_k): finite, (n, n), (n, m), (m, n); float64 copies."""
    a = finite_array("A", A)
    if a.ndim != 2 or a.shape[0] != a.shape[1] or a.shape[0] == 0:
        raise DimensionError(f"A: expected a square (n, n) matrix but found shape {a.shape}")
    n = a.shape[0]
    b = finite_array("B", B)
    if b.ndim == 1:
        b = b.reshape(n, -1) if b.size % n == 0 else b
    if b.ndim != 2 or b.shape[0] != n:
        raise DimensionError(f"B: expected shape ({n}, m) but found {b.shape}")
    k = finite_array("K", K)
    if k.ndim == 1:
        k = k.reshape(1, -1)
    if k.shape != (b.shape[1], n):
        raise DimensionError(f"K: expected shape ({b.shape[1]}, {n}) but found {k.shape}")
    return np.array(a, dtype=float), np.array(b, dtype=float), np.array(k, dtype=float)


def lifted_matrices(A: Any, B: Any, period: float) -> tuple[np.ndarray, np.ndarray]:
    """(Φ, Γ) = (e^{Ah}, ∫₀ʰ e^{As} ds B) from one expm of [[A, B], [0, 0]] h.

    Parameters
    ----------
    A : array_like
        (n, n) (1/s).
    B : array_like
        (n, m).
    period : float
        Sampling period h (s).
    """
    a = finite_array("A", A)
    b = finite_array("B", B)
    h = positive_scalar("period", period)
    n, m = a.shape[0], b.shape[1]
    aug = np.zeros((n + m, n + m))
    aug[:n, :n] = a
    aug[:n, n:] = b
    e = scipy.linalg.expm(aug * h)
    return e[:n, :n].copy(), e[:n, n:].copy()


@dataclass(frozen=True)
class SampledStability:
    """Exact stability of the lifted sampled loop.

    Attributes
    ----------
    period : float
        h (s).
    delay_samples : int
        d.
    spectral_radius : float
        Largest |eigenvalue| of the n(d+1) companion matrix.
    size : int
        n(d+1).
    """

    period: float
    delay_samples: int
    spectral_radius: float
    size: int

    @property
    def stable(self) -> bool:
        """True when the spectral radius is below 1."""
        return self.spectral_radius < 1.0

    def __str__(self) -> str:
        word = "stable" if self.stable else "unstable"
        return (
            f"sampled loop h = {self.period:.6g} s, d = {self.delay_samples}: {word} "
            f"(spectral radius {self.spectral_radius:.9f}, companion size {self.size})"
        )


def _radius(a: np.ndarray, b: np.ndarray, k: np.ndarray, h: float, d: int) -> tuple[float, int]:
    n = a.shape[0]
    size = n * (d + 1)
    if size > MAX_LIFTED_SIZE:
        raise SpecificationError(
            f"delay_samples: the lifted companion matrix would be {size}x{size} "
            f"(~{8 * size * size / 1e6:.0f} MB, an O(N^3) eigenproblem), above MAX_LIFTED_SIZE = {MAX_LIFTED_SIZE}; "
            "split the loop per axis (spacecraft_axes) or use a longer period"
        )
    phi, gam = lifted_matrices(a, b, h)
    gk = gam @ k
    if d == 0:
        return float(np.max(np.abs(np.linalg.eigvals(phi + gk)))), size
    m = np.zeros((size, size))
    m[:n, :n] = phi
    m[:n, d * n :] = gk
    m[n:, :-n] = np.eye(d * n)
    return float(np.max(np.abs(scipy.linalg.eigvals(m, overwrite_a=True, check_finite=False)))), size


def _stable_by_winding(a: np.ndarray, b: np.ndarray, k: np.ndarray, h: float, d: int) -> bool:
    """Stability of the lifted loop by the argument principle (O(n³ M) for M circle points, any d).

    det(zI − M) = p(z) = z^{nd} q(z), q(z) = det(M(θ)), M(θ) = zI − Φ − z^{−d} Γ K at z = e^{iθ}, of degree
    n(d+1): every zero is inside the unit circle iff the winding number of q about 0 is n. The count is
    certified arc by arc, not read off a grid that merely looks fine (a zero a distance δ inside the circle turns
    the phase by about 2π over an arc of width δ, which a coarse grid aliases to a small step):
    ‖dM/dθ‖ ≤ L = 1 + d ‖ΓK‖, so on an arc of width Δθ from θ_i, σ_min(M) ≥ σ_i − L Δθ with σ_i = σ_min(M(θ_i)),
    and |d arg q/dθ| = |tr(M⁻¹ dM/dθ)| ≤ n L / (σ_i − L Δθ). An arc is accepted when that bound times Δθ is
    below π/2: then q has no zero on it and its phase change is the principal argument of q_{i+1}/q_i. Arcs
    that fail are halved (only next to a zero); with more than 2²⁰ points (a zero on or within round-off of
    the circle) the dense eigenvalues decide (which refuses companions above MAX_LIFTED_SIZE).
    """
    n = a.shape[0]
    phi, gam = lifted_matrices(a, b, h)
    gk = gam @ k
    lipschitz = 1.0 + d * float(np.linalg.norm(gk, 2))

    def evaluate(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        z = np.exp(1j * theta)
        mats = z[:, None, None] * np.eye(n) - phi[None] - np.exp(-1j * d * theta)[:, None, None] * gk[None]
        return np.linalg.det(mats), np.linalg.svd(mats, compute_uv=False)[:, -1]

    theta = np.linspace(0.0, 2.0 * np.pi, max(4096, 32 * (d + 1)) + 1)
    q, smallest = evaluate(theta)
    while True:
        width = np.diff(theta)
        room = smallest[:-1] - lipschitz * width
        bad = (room <= 0.0) | (n * lipschitz * width >= 0.5 * np.pi * np.maximum(room, 0.0))
        if not np.any(bad):
            break
        if theta.size + int(np.count_nonzero(bad)) > 2**20:
            return _radius(a, b, k, h, d)[0] < 1.0
        middle = 0.5 * (theta[:-1][bad] + theta[1:][bad])
        q_mid, s_mid = evaluate(middle)
        order = np.argsort(np.concatenate((theta, middle)), kind="stable")
        theta = np.concatenate((theta, middle))[order]
        q = np.concatenate((q, q_mid))[order]
        smallest = np.concatenate((smallest, s_mid))[order]
    steps = np.angle(q[1:] / q[:-1])
    winding = round(float(np.sum(steps)) / (2.0 * np.pi))
    return winding == n


def sampled_stability(A: Any, B: Any, K: Any, period: float, *, delay_samples: int = 0) -> SampledStability:
    """Exact stability of u(t) = K x(t_{k−d}) held over [t_k, t_{k+1}) on ẋ = A x + B u.

    Parameters
    ----------
    A, B, K : array_like
        (n, n), (n, m) and (m, n).
    period : float
        Sampling period h (s).
    delay_samples : int, optional
        d >= 0 (keyword-only; default 0).

    Raises
    ------
    SpecificationError
        If n(d+1) > MAX_LIFTED_SIZE (the estimate and the way out are in the message).
    """
    a, b, k = sampled_system(A, B, K)
    h = positive_scalar("period", period)
    d = integer("delay_samples", delay_samples, minimum=0)
    rho, size = _radius(a, b, k, h, d)
    return SampledStability(h, d, rho, size)


@dataclass(frozen=True)
class _Scan:
    value: float
    evaluations: int


def max_stable_delay_samples(A: Any, B: Any, K: Any, period: float, *, d_limit: int = 2000) -> int:
    """The largest d such that the lifted loop is stable for every delay 0, 1, ..., d samples.

    Stability in d is located by doubling then bisection on the first unstable d (each test by the
    argument principle, `_stable_by_winding`, so d in the thousands is cheap), and the answer
    is verified (stable at d, unstable at d + 1). Returns -1 when d = 0 is already unstable and
    ``d_limit`` when every d up to the limit is stable (checked at the limit only).
    """
    a, b, k = sampled_system(A, B, K)
    h = positive_scalar("period", period)
    d_limit = integer("d_limit", d_limit, minimum=1)

    def stable(d: int) -> bool:
        return _stable_by_winding(a, b, k, h, d)

    if not stable(0):
        return -1
    good, bad = 0, 1
    while stable(bad):
        good = bad
        if bad >= d_limit:
            return d_limit
        bad = min(2 * bad, d_limit)
    while bad - good > 1:
        mid = (good + bad) // 2
        if stable(mid):
            good = mid
        else:
            bad = mid
    return good


def max_stable_period(
    A: Any, B: Any, K: Any, *, delay_samples: int = 0, period_limit: float = 100.0, rtol: float = 1e-6, grid: int = 400
) -> float:
    """The largest h such that the lifted loop is stable for every period in (0, h] (s).

    A geometric grid of ``grid`` periods from period_limit·1e-6 up to ``period_limit`` finds the first
    unstable period, then bisection to ``rtol``. Returns nan when no grid period is stable, and
    ``period_limit`` when every grid period is.
    """
    a, b, k = sampled_system(A, B, K)
    d = integer("delay_samples", delay_samples, minimum=0)
    limit = positive_scalar("period_limit", period_limit)
    rtol = positive_scalar("rtol", rtol)
    grid = integer("grid", grid, minimum=2)
    periods = np.geomspace(limit * 1e-6, limit, grid)
    good = math.nan
    bad = math.nan
    for h in periods:
        if _radius(a, b, k, float(h), d)[0] < 1.0:
            good = float(h)
        else:
            bad = float(h)
            break
    if math.isnan(good):
        return math.nan
    if math.isnan(bad):
        return limit
    for _ in range(200):
        if bad - good <= rtol * good:
            break
        mid = 0.5 * (good + bad)
        if _radius(a, b, k, mid, d)[0] < 1.0:
            good = mid
        else:
            bad = mid
    return good


#: Largest delay (d + 1) h (s) of the sawtooth criterion: its blocks hold (d + 1)² h², finite up to 1.3e154 s.
_MAX_DELAY = 1e150


def _solve_sawtooth(
    a: np.ndarray, a_d: np.ndarray, h: float, d: int, order: int, margin_tol: float, *, precondition: bool = True
) -> IntervalCertificate:
    """The plain sawtooth problem; when it does not certify, the preconditioned ones (each certificate is sound).

    The retries are (1) difference coordinates + block scaling, (2) the same with the integral weights
    R1, R2, X, U, Z in units of 1/ε; at most three solves, the first certificate wins.
    """
    plain = solve_interval([(a, a_d)], d * h, (d + 1) * h, DelayRate.sawtooth(), order, margin_tol)
    if plain.certified or not precondition:
        return plain
    for scale_variables in (False, True):
        retry = solve_interval_preconditioned(
            [(a, a_d)], d * h, (d + 1) * h, DelayRate.sawtooth(), order, margin_tol, scale_variables=scale_variables
        )
        if retry.certified:
            return retry
    return plain


def certify_sampled(
    A: Any,
    B: Any,
    K: Any,
    period: float,
    *,
    delay_samples: int = 0,
    order: int = 1,
    margin_tol: float = DEFAULT_MARGIN_TOL,
    precondition: bool = True,
) -> IntervalCertificate:
    """Certify the sampled loop by the input-delay approach (interval delay with τ̇ = 1).

    ẋ = A x + B K x(t − τ(t)), τ(t) = d h + t − t_k ∈ [d h, (d+1) h], τ̇ = 1; see
    [`certify_interval`][mrpctl.design.certify_interval]. When the problem as written does not certify
    (typically Clarabel ``optimal_inaccurate`` for N >= 1 at 1 kHz), it is solved again in difference
    coordinates with power-of-two block scaling (an equivalent LMI, design/lmi.md 7.3); the returned
    certificate says which one certified. ``precondition=False`` (keyword-only) skips the retry.
    """
    a, b, k = sampled_system(A, B, K)
    h = positive_scalar("period", period)
    d = integer("delay_samples", delay_samples, minimum=0)
    if (d + 1) * h > _MAX_DELAY:
        raise SpecificationError(
            f"period: (delay_samples + 1) * period = {(d + 1) * h:g} s is above {_MAX_DELAY:g} s: the criterion's "
            "blocks hold the squared delay, which overflows float64 (NaN in the solver's data) beyond 1.3e154 s"
        )
    return _solve_sawtooth(
        a, b @ k, h, d, order_value(order), positive_scalar("margin_tol", margin_tol), precondition=precondition
    )


class SampledCriterion(enum.Enum):
    """Which sampled-data certificate a [`SampledCertification`][mrpctl.design.SampledCertification] comes from."""

    #: Input-delay approach: the interval criterion with the sawtooth τ(t) ∈ [d h, (d+1) h] (any d).
    INPUT_DELAY = "input-delay"
    #: Looped functional with Wirtinger's inequality (`mrpctl.design.looped`; d = 0, periodic).
    LOOPED = "looped"


@dataclass(frozen=True, eq=False)
class SampledCertification:
    """Result of [`max_certified_period`][mrpctl.design.max_certified_period] and
    [`max_looped_period`][mrpctl.design.max_looped_period].

    Attributes
    ----------
    status : SearchStatus
    order : int
        Bessel-Legendre order of the integral inequality (1 for the looped criterion).
    delay_samples : int
    period : float
        Largest certified sampling period h (s); nan when none. The input-delay criterion
        certifies every sampling sequence with intervals in (0, h]; the looped criterion
        certifies the *periodic* loop at this one h only (not smaller or mixed intervals: a
        system certified at 0.8259 s periodic is unstable when 0.5893 s and 0.8259 s alternate,
        design/lmi.md section 7.2).
    certificate : IntervalCertificate, LoopedCertificate or None
    solves : int
    reason : str
    criterion : SampledCriterion
    """

    status: SearchStatus
    order: int
    delay_samples: int
    period: float
    certificate: Any = field(repr=False)
    solves: int
    reason: str
    criterion: SampledCriterion = SampledCriterion.INPUT_DELAY

    @property
    def certified(self) -> bool:
        return self.status is not SearchStatus.NOT_CERTIFIED

    def __str__(self) -> str:
        if self.criterion is SampledCriterion.LOOPED:
            head = "looped functional + Wirtinger, sampled (d = 0)"
        else:
            head = f"{criterion_name(self.order)} + RCC, sampled (d = {self.delay_samples})"
        if not self.certified:
            return f"{head}: {self.status.value} ({self.reason})"
        if self.criterion is SampledCriterion.LOOPED:
            return f"{head}: periodic h = {self.period:.6g} s certified ({self.solves} solves; {self.reason})"
        return f"{head}: certified for h <= {self.period:.6g} s ({self.solves} solves; {self.reason})"


def bisect_period(
    a: np.ndarray,
    b: np.ndarray,
    k: np.ndarray,
    d: int,
    test: Callable[[float], Any],
    *,
    rtol: float,
    period_limit: float | None,
    criterion: SampledCriterion,
    order: int,
) -> SampledCertification:
    """Bisection of the certified period below the exact one (which is tested too); <= 206 solves."""
    scale = max(float(np.linalg.norm(a, 2)), float(np.linalg.norm(b @ k, 2)), 1e-12)
    limit = 1e3 / scale if period_limit is None else positive_scalar("period_limit", period_limit)
    exact = max_stable_period(a, b, k, delay_samples=d, period_limit=limit)
    solves = 0

    def run(h: float) -> Any:
        nonlocal solves
        solves += 1
        return test(h)

    def result(status: SearchStatus, period: float, cert: Any, reason: str) -> SampledCertification:
        return SampledCertification(status, order, d, period, cert, solves, reason, criterion)

    if math.isnan(exact):
        return result(SearchStatus.NOT_CERTIFIED, math.nan, None, "no stable period")
    bad = exact
    good, cert = math.nan, None
    for f in (1.0, 0.5, 0.2, 0.05, 0.01, 1e-3):
        trial = run(f * exact)
        if trial.certified:
            good, cert = f * exact, trial
            break
        bad = f * exact
    if cert is None:
        return result(SearchStatus.NOT_CERTIFIED, math.nan, None, "nothing certified")
    if good >= exact:
        return result(SearchStatus.CERTIFIED, good, cert, f"certified at the exact bound {exact:.6g} s")
    for _ in range(200):
        if bad - good <= rtol * good:
            break
        mid = 0.5 * (good + bad)
        trial = run(mid)
        if trial.certified:
            good, cert = mid, trial
        else:
            bad = mid
    return result(SearchStatus.CERTIFIED, good, cert, f"exact period {exact:.6g} s")


def max_certified_period(
    A: Any,
    B: Any,
    K: Any,
    *,
    delay_samples: int = 0,
    order: int = 1,
    rtol: float = 1e-3,
    period_limit: float | None = None,
    margin_tol: float = DEFAULT_MARGIN_TOL,
) -> SampledCertification:
    """The largest sampling period h certified by [`certify_sampled`][mrpctl.design.certify_sampled] (bisection, ≤ 206
    solves).

    The exact period ([`max_stable_period`][mrpctl.design.max_stable_period]) bounds the search from above: a sound
    certificate
    cannot exceed it. The bound itself is tested too.
    """
    a, b, k = sampled_system(A, B, K)
    d = integer("delay_samples", delay_samples, minimum=0)
    order = order_value(order)
    rtol = positive_scalar("rtol", rtol)
    margin_tol = positive_scalar("margin_tol", margin_tol)

    def test(h: float) -> IntervalCertificate:
        return _solve_sawtooth(a, b @ k, h, d, order, margin_tol)

    return bisect_period(
        a, b, k, d, test, rtol=rtol, period_limit=period_limit, criterion=SampledCriterion.INPUT_DELAY, order=order
    )


def spacecraft_axes(spacecraft: Spacecraft, K: Any) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], ...]:
    """(A, B, K) of the linearised spacecraft loop: three 2×2 per-axis triples when it splits, else one 6×6.

    Per axis i on (σᵢ, ωᵢ/4): A = [[0, 1], [0, 0]], B = [0; 1/(4 Jᵢ)], K = [K_σ,ii, K_ω,ii]; the split
    needs a diagonal J and diagonal gain blocks.
    """
    sc = check_spacecraft(spacecraft)
    k = gain_matrix(K)
    plant = plant_model(sc)
    ks, kw = k[:, :3], k[:, 3:]
    if sc.is_diagonal and _diag(ks) and _diag(kw):
        a = np.array([[0.0, 1.0], [0.0, 0.0]])
        jd = np.diag(sc.inertia)
        return tuple((a, np.array([[0.0], [0.25 / jd[i]]]), np.array([[ks[i, i], kw[i, i]]])) for i in range(3))
    return ((np.array(plant.A), np.array(plant.B), np.array(k)),)


def _diag(m: np.ndarray) -> bool:
    return bool(np.all(m == np.diag(np.diag(m))))


def max_certified_delay_samples(
    A: Any,
    B: Any,
    K: Any,
    period: float,
    *,
    order: int = 1,
    d_max: int,
    margin_tol: float = DEFAULT_MARGIN_TOL,
) -> tuple[int, IntervalCertificate | None, int]:
    """The largest d <= d_max such that [`certify_sampled`][mrpctl.design.certify_sampled] certifies delays d' = d
    (bisection on d).

    Certified d means the sawtooth τ(t) ∈ [d h, (d+1) h] is certified; the search assumes the
    certified set in d is an interval starting at 0 (the certificate at the answer is returned and
    the answer + 1 was tested and failed, unless it is ``d_max``). A test that ends in a solver
    failure (``optimal_inaccurate``) rather than a negative margin is retried at d ± 1, d + 2 before
    it counts as failed. Returns (d, certificate, solves); d = -1 when d = 0 is not certified.
    """
    a, b, k = sampled_system(A, B, K)
    h = positive_scalar("period", period)
    order = order_value(order)
    d_max = integer("d_max", d_max, minimum=0)
    margin_tol = positive_scalar("margin_tol", margin_tol)
    solves = 0

    def test(d: int) -> IntervalCertificate:
        nonlocal solves
        solves += 1
        return _solve_sawtooth(a, b @ k, h, d, order, margin_tol)

    top = test(d_max)
    if top.certified:
        return d_max, top, solves
    first = test(0)
    if not first.certified:
        return -1, None, solves
    good, cert, bad = 0, first, d_max
    while bad - good > 1:
        mid = (good + bad) // 2
        trial = test(mid)
        if not trial.certified and trial.status is CertificateStatus.SOLVER_FAILED:
            # A solver failure is no evidence of infeasibility: probe the neighbours before giving mid up.
            for probe in (mid + 1, mid - 1, mid + 2):
                if good < probe < bad:
                    again = test(probe)
                    if again.certified:
                        mid, trial = probe, again
                        break
        if trial.certified:
            good, cert = mid, trial
        else:
            bad = mid
    return good, cert, solves
