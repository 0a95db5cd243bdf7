"""Exact delay margin of ẋ = A x + A_d x(t − τ) from the imaginary-axis crossings of its roots."""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg

from mrpctl._validation import integer
from mrpctl.design._common import balancing, similarity, system_matrices

__all__ = ["Crossing", "DelayMargin", "delay_margin"]

# Every tolerance is relative to the normalised system (A, A_d)/c, c = max(‖A‖₂, ‖A_d‖₂).
#: |z| may miss 1 by this much for a unit-circle candidate (accepted only after refinement).
_UNIT_CIRCLE_CANDIDATE = 1e-3
#: |Re λ| of a candidate eigenvalue of A + A_d z relative to |λ| + ‖A‖ + ‖A_d‖.
_AXIS_CANDIDATE = 1e-3
#: Backward error σ_min(M(iω, τ₀)) / (ω + ‖A‖ + ‖A_d‖) below which a refined crossing is accepted.
_BACKWARD_ERROR = 1e-10
#: Crossings with ω/c below this are rejected (their periods exceed 1e12 time units).
_MIN_FREQUENCY = 1e-12
#: σ_min(A + A_d) / (‖A‖ + ‖A_d‖) at or below this: s = 0 is a root for every delay.
_SINGULAR_RTOL = 1e-12
#: |Re λ| / (‖A‖ + ‖A_d‖) at or below this for an eigenvalue of A + A_d: on the imaginary axis.
_AXIS_RTOL = 1e-13
#: Newton steps of the crossing refinement.
_NEWTON_STEPS = 30
#: Default cap on the number of crossing events swept.
DEFAULT_MAX_EVENTS = 100_000


@dataclass(frozen=True, eq=False)
class Crossing:
    """One family of imaginary-axis crossings s = ±iω at τ = τ₀ + k 2π/ω, k = 0, 1, 2, ...

    Attributes
    ----------
    frequency : float
        ω > 0 (rad/s).
    delay : float
        τ₀, the smallest delay (s) at which the pair ±iω are characteristic roots.
    period : float
        2π/ω (s): the crossing repeats at τ₀ + k·period.
    direction : int
        +1 when the pair moves into the right half-plane as τ increases, −1 when it moves out
        (the sign of Re ds/dτ, the same for every k).
    multiplicity : int
        How many root pairs cross together (the dimension of the null space of
        iωI − A − A_d e^{−iωτ₀}; e.g. 3 for three identical decoupled axes).
    """

    frequency: float
    delay: float
    period: float
    direction: int
    multiplicity: int = 1

    def __str__(self) -> str:
        way = "destabilising" if self.direction > 0 else "stabilising"
        return f"omega = {self.frequency:.6g} rad/s at tau = {self.delay:.6g} s (+k {self.period:.6g} s), {way}"


@dataclass(frozen=True, eq=False)
class DelayMargin:
    """The exact delay margin of ẋ = A x + A_d x(t − τ) and its stability intervals.

    Attributes
    ----------
    margin : float
        The largest τ̄ (s) such that the system is exponentially stable for every τ ∈ [0, τ̄);
        ``math.inf`` when stable for all delays, 0.0 when unstable at τ = 0.
    stable_without_delay : bool
        True when A + A_d is Hurwitz (τ = 0).
    crossings : tuple of Crossing
        Every crossing family, sorted by τ₀.
    stable_intervals : tuple of (float, float)
        The delay intervals (s) on which the system is exponentially stable, open at crossing
        delays, listed up to the delay after which no further stability switch can happen.
    reason : str
        One line on how the answer was reached (or why no delay stabilises the system).
    resolved_to : float
        The intervals are exact for τ below this (s); ``math.inf`` when the sweep proved that no
        later stability switch exists, finite when it stopped at ``max_events`` crossings.
    """

    margin: float
    stable_without_delay: bool
    crossings: tuple[Crossing, ...]
    stable_intervals: tuple[tuple[float, float], ...]
    reason: str
    resolved_to: float = math.inf

    @property
    def complete(self) -> bool:
        """True when every stability switch was determined (``resolved_to`` is infinite)."""
        return math.isinf(self.resolved_to)

    @property
    def delay_independent(self) -> bool:
        """True when the system is stable for every delay τ >= 0."""
        return math.isinf(self.margin)

    @property
    def stable_for_some_delay(self) -> bool:
        """True when at least one delay interval is stable."""
        return bool(self.stable_intervals)

    def is_stable(self, tau: float) -> bool:
        """True when τ (s) lies strictly inside a stable interval."""
        return any(lo < tau < hi or (lo == 0.0 and tau == 0.0) for lo, hi in self.stable_intervals)

    def __str__(self) -> str:
        lines = [f"exact delay margin {self.margin:.6g} s ({self.reason})"]
        if self.stable_intervals and not (len(self.stable_intervals) == 1 and self.stable_intervals[0][0] == 0.0):
            spans = ", ".join(f"({lo:.6g}, {hi:.6g})" for lo, hi in self.stable_intervals)
            lines.append(f"  stable for tau in {spans} s")
        lines.extend(f"  crossing {c}" for c in self.crossings)
        return "\n".join(lines)


def delay_margin(A: Any, A_d: Any, *, max_events: int = DEFAULT_MAX_EVENTS) -> DelayMargin:
    """Exact delay margin of ẋ = A x + A_d x(t − τ) by the frequency-domain crossing method.

    A characteristic root s = iω of det(sI − A − A_d e^{−sτ}) = 0 means iω is an eigenvalue of
    A + A_d z with z = e^{−iωτ} on the unit circle; then −iω is an eigenvalue of A + A_d z⁻¹ and
    the Kronecker sum (A + A_d z) ⊕ (A + A_d z⁻¹) is singular, i.e.

        det(z² (A_d ⊗ I) + z (A ⊗ I + I ⊗ A) + I ⊗ A_d) = 0                (Chen, Gu & Nett 1995)

    a quadratic eigenvalue problem of size n², solved as a generalized eigenvalue problem that
    accepts a singular A_d (its infinite eigenvalues are discarded). Each unit-circle z gives ω
    (the imaginary eigenvalue of A + A_d z) and τ₀ = −arg(z)/ω mod 2π/ω. The crossing direction
    is the sign of Re ds/dτ = −Re(uᴴ ∂M/∂τ v / uᴴ ∂M/∂s v) with M(s, τ) = sI − A − A_d e^{−sτ} and
    u, v its left and right null vectors. Counting unstable roots from τ = 0 (the eigenvalues of
    A + A_d) across the sorted crossings gives the stable intervals.

    Scale: the analysis runs on the balanced (T⁻¹AT, T⁻¹A_dT)/c (T a power-of-two diagonal
    similarity, c = max(‖T⁻¹AT‖₂, ‖T⁻¹A_dT‖₂)) (the delays of c·(A, A_d)
    are those of (A, A_d) divided by c), and every tolerance is relative: a crossing is accepted
    when the backward error σ_min(M(iω, τ₀)) / (ω + ‖A‖₂ + ‖A_d‖₂) is below 1e-10 after Newton
    refinement and ω/c > 1e-12; s = 0 is a root for every delay when
    σ_min(A + A_d) <= 1e-12 (‖A‖₂ + ‖A_d‖₂).

    Termination: the crossings are swept in τ lazily and the sweep stops as soon as the number of
    right-half-plane roots exceeds 2 × (the root pairs of all crossing families, with multiplicity);
    then it can never return to zero, because from any τ on the destabilising families add at least
    2((τ' − τ)/T − 1) roots and
    the stabilising ones remove at most 2((τ' − τ)/T + 1), and Σ_up ω >= Σ_down ω. At most
    ``max_events`` crossings are swept: if that limit is reached first the intervals are exact
    only up to ``resolved_to`` and ``complete`` is False (the margin itself is always exact).

    Parameters
    ----------
    A, A_d : array_like
        (n, n) system matrices (1/s). A scalar is read as a 1×1 matrix.
    max_events : int, optional
        Largest number of crossing events swept (default 100 000; memory is O(number of families)).

    Returns
    -------
    DelayMargin

    Raises
    ------
    DimensionError
        If A is not square or A_d does not match it.
    SpecificationError
        If an entry is NaN or inf, or ``max_events`` is not a positive integer.

    Examples
    --------
    >>> round(delay_margin(0.0, -1.0).margin, 6)  # ẋ = −x(t − τ): π/2
    1.570796
    """
    a, a_d = system_matrices(A, A_d)
    max_events = integer("max_events", max_events, minimum=1)
    n = a.shape[0]
    scale = balancing(a, a_d)  # a similarity: same roots, better conditioned (e.g. huge inertia)
    a, a_d = similarity(a, scale), similarity(a_d, scale)
    c = max(float(np.linalg.norm(a, 2)), float(np.linalg.norm(a_d, 2)))
    singular = c == 0.0
    if not singular:
        an, adn = a / c, a_d / c
        norm_sum = float(np.linalg.norm(an, 2) + np.linalg.norm(adn, 2))
        singular = float(np.linalg.svd(an + adn, compute_uv=False)[-1]) <= _SINGULAR_RTOL * norm_sum
    if singular:
        return DelayMargin(
            margin=0.0,
            stable_without_delay=False,
            crossings=(),
            stable_intervals=(),
            reason="A + A_d is singular: s = 0 is a characteristic root for every delay",
        )
    eig0 = np.linalg.eigvals(an + adn)
    axis_tol = _AXIS_RTOL * norm_sum
    unstable0 = int(np.sum(eig0.real > axis_tol))
    on_axis = bool(np.any(np.abs(eig0.real) <= axis_tol))
    stable0 = unstable0 == 0 and not on_axis
    crossings = [
        Crossing(frequency=c * w, delay=theta / (c * w), period=2.0 * math.pi / (c * w), direction=d, multiplicity=m)
        for w, theta, d, m in _crossings(an, adn, n, norm_sum)
    ]
    crossings.sort(key=lambda x: x.delay)
    sweep = _stable_intervals(unstable0 + (2 if on_axis else 0), crossings, max_events)
    intervals = sweep.intervals
    if not crossings:
        margin = math.inf if stable0 else 0.0
        reason = (
            "no imaginary-axis crossing: stable for every delay"
            if stable0
            else "no imaginary-axis crossing and A + A_d is not Hurwitz: unstable for every delay"
        )
    elif stable0:
        margin = intervals[0][1] if intervals and intervals[0][0] == 0.0 else 0.0
        reason = f"first destabilising crossing at omega = {_frequency_at(crossings, margin):.6g} rad/s"
    else:
        margin = 0.0
        reason = (
            "A + A_d is not Hurwitz; stable only on the listed intervals"
            if intervals
            else "A + A_d is not Hurwitz and no delay stabilises the system"
        )
    if not sweep.complete:
        reason += (
            f"; stability switches could not be determined beyond tau = {sweep.resolved_to:.6g} s "
            f"(max_events = {max_events} crossings swept)"
        )
    return DelayMargin(
        margin=float(margin),
        stable_without_delay=stable0,
        crossings=tuple(crossings),
        stable_intervals=tuple(intervals),
        reason=reason,
        resolved_to=sweep.resolved_to,
    )


def _frequency_at(crossings: list[Crossing], tau: float) -> float:
    for c in crossings:
        k = round((tau - c.delay) / c.period) if c.period > 0 else 0
        if abs(c.delay + k * c.period - tau) <= 1e-9 * max(abs(tau), c.period):
            return c.frequency
    return math.nan


def _crossings(a: np.ndarray, a_d: np.ndarray, n: int, norm_sum: float) -> list[tuple[float, float, int, int]]:
    """(ω, θ = ωτ₀ ∈ [0, 2π), direction, multiplicity) of every crossing family of the normalised system."""
    eye = np.eye(n)
    m2 = np.kron(a_d, eye)
    m1 = np.kron(a, eye) + np.kron(eye, a)
    m0 = np.kron(eye, a_d)
    size = n * n
    zero = np.zeros((size, size))
    ident = np.eye(size)
    pencil_a = np.block([[zero, ident], [-m0, -m1]])
    pencil_b = np.block([[ident, zero], [zero, m2]])
    alpha, beta = scipy.linalg.eig(pencil_a, pencil_b, right=False, homogeneous_eigvals=True)
    finite = np.abs(beta) > 1e-12 * np.abs(alpha)
    z_values = alpha[finite] / beta[finite]
    found: list[tuple[float, float, int, int]] = []
    for z in z_values:
        if not np.isfinite(z) or abs(abs(z) - 1.0) > _UNIT_CIRCLE_CANDIDATE:
            continue
        z_unit = z / abs(z)
        for lam in np.linalg.eigvals(a + a_d * z_unit):
            if abs(lam.real) > _AXIS_CANDIDATE * (abs(lam) + norm_sum) or lam.imag <= 0.0:
                continue
            refined = _refine(a, a_d, float(lam.imag), float(-np.angle(z_unit)), norm_sum)
            if refined is None:
                continue
            omega, theta = refined
            if omega <= _MIN_FREQUENCY:
                continue
            theta = math.fmod(theta, 2.0 * math.pi)
            if theta < 0.0:
                theta += 2.0 * math.pi
            if any(_same(omega, theta, w, t) for w, t, _, _ in found):
                continue
            found.append((omega, theta, _direction(a, a_d, omega, theta / omega), _multiplicity(a, a_d, omega, theta)))
    return found


def _multiplicity(a: np.ndarray, a_d: np.ndarray, omega: float, theta: float) -> int:
    """Root pairs on the axis at (ω, θ): singular values of iωI − A − A_d e^{−iθ} at the level of the smallest."""
    m = 1j * omega * np.eye(a.shape[0]) - a - a_d * np.exp(-1j * theta)
    singular = np.linalg.svd(m, compute_uv=False)
    level = max(1e3 * float(singular[-1]), 1e-9 * (omega + float(np.linalg.norm(a, 2)) + float(np.linalg.norm(a_d, 2))))
    return max(1, int(np.sum(singular <= level)))


def _same(omega: float, theta: float, w: float, t: float) -> bool:
    gap = abs(theta - t) % (2.0 * math.pi)
    return abs(omega - w) <= 1e-7 * max(omega, w) and min(gap, 2.0 * math.pi - gap) <= 1e-7


def _residual(a: np.ndarray, a_d: np.ndarray, omega: float, theta: float) -> tuple[float, Any, Any, Any]:
    m = 1j * omega * np.eye(a.shape[0]) - a - a_d * np.exp(-1j * theta)
    u, s, vh = np.linalg.svd(m)
    return float(s[-1]), m, u[:, -1], vh[-1].conj()


def _refine(a: np.ndarray, a_d: np.ndarray, omega: float, theta: float, norm_sum: float) -> tuple[float, float] | None:
    """Newton on uᴴ(iωI − A − A_d e^{−iθ})v = 0 in (ω, θ); None unless the backward error ends below 1e-10."""
    best = (_residual(a, a_d, omega, theta)[0], omega, theta)
    for _ in range(_NEWTON_STEPS):
        sigma, m, left, right = _residual(a, a_d, omega, theta)
        if sigma < best[0]:
            best = (sigma, omega, theta)
        if sigma <= 1e-15 * (omega + norm_sum):
            break
        value = left.conj() @ m @ right
        d_omega = left.conj() @ (1j * right)
        d_theta = left.conj() @ (1j * a_d * np.exp(-1j * theta)) @ right
        jac = np.array([[d_omega.real, d_theta.real], [d_omega.imag, d_theta.imag]])
        try:
            step = np.linalg.solve(jac, -np.array([value.real, value.imag]))
        except np.linalg.LinAlgError:
            break
        if not np.all(np.isfinite(step)) or abs(step[0]) > 0.5 * omega or abs(step[1]) > 0.5:
            break
        omega, theta = omega + float(step[0]), theta + float(step[1])
    sigma, omega, theta = best
    sigma_end = _residual(a, a_d, omega, theta)[0]
    if min(sigma, sigma_end) > _BACKWARD_ERROR * (omega + norm_sum) or omega <= 0.0:
        return None
    return omega, theta


def _direction(a: np.ndarray, a_d: np.ndarray, omega: float, tau: float) -> int:
    n = a.shape[0]
    s = 1j * omega
    delay_term = a_d * np.exp(-s * tau)
    m = s * np.eye(n) - a - delay_term
    u, _, vh = np.linalg.svd(m)
    left, right = u[:, -1], vh[-1].conj()
    d_m_ds = np.eye(n) + tau * delay_term
    d_m_dtau = s * delay_term
    ds_dtau = -(left.conj() @ d_m_dtau @ right) / (left.conj() @ d_m_ds @ right)
    return 1 if ds_dtau.real > 0 else -1


@dataclass(frozen=True)
class _Sweep:
    intervals: list[tuple[float, float]]
    complete: bool
    resolved_to: float


def _stable_intervals(unstable0: int, crossings: list[Crossing], max_events: int) -> _Sweep:
    """Sweep the crossings in τ (lazily, a heap of one next event per family), counting RHP roots."""
    if not crossings:
        return _Sweep([(0.0, math.inf)] if unstable0 == 0 else [], True, math.inf)
    has_down = any(c.direction < 0 for c in crossings)
    # Σ_up ω >= Σ_down ω holds for a retarded system; the stopping rule below relies on it.
    rate_ok = sum(c.frequency * c.direction * c.multiplicity for c in crossings) >= 0.0
    pairs = sum(c.multiplicity for c in crossings)
    heap = [(c.delay, i, 0) for i, c in enumerate(crossings)]
    heapq.heapify(heap)
    intervals: list[tuple[float, float]] = []
    count = unstable0
    start: float | None = 0.0 if count == 0 else None
    for _ in range(max_events):
        tau, i, k = heapq.heappop(heap)
        c = crossings[i]
        heapq.heappush(heap, (c.delay + (k + 1) * c.period, i, k + 1))
        before = count
        count = max(0, count + 2 * c.direction * c.multiplicity)
        if before == 0 and count > 0 and start is not None:
            if tau > start:
                intervals.append((start, tau))
            start = None
        elif before > 0 and count == 0:
            start = tau
        if count > 0 and (not has_down or (rate_ok and count > 2 * pairs)):
            return _Sweep(intervals, True, math.inf)
    next_tau = heap[0][0]
    if start is not None:
        intervals.append((start, next_tau))
    return _Sweep(intervals, False, next_tau)
