"""Exact delay margin of ẋ = A x + A_d x(t − τ) from the imaginary-axis crossings of its roots."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg

from mrpctl.design._common import system_matrices

__all__ = ["Crossing", "DelayMargin", "delay_margin"]

_UNIT_CIRCLE_TOL = 1e-6
_AXIS_TOL = 1e-7
_ZERO_FREQUENCY = 1e-10


@dataclass(frozen=True)
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
    """

    frequency: float
    delay: float
    period: float
    direction: int

    def __str__(self) -> str:
        way = "destabilising" if self.direction > 0 else "stabilising"
        return f"omega = {self.frequency:.6g} rad/s at tau = {self.delay:.6g} s (+k {self.period:.6g} s), {way}"


@dataclass(frozen=True)
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
    """

    margin: float
    stable_without_delay: bool
    crossings: tuple[Crossing, ...]
    stable_intervals: tuple[tuple[float, float], ...]
    reason: str

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


def delay_margin(A: Any, A_d: Any) -> DelayMargin:
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

    Parameters
    ----------
    A, A_d : array_like
        (n, n) system matrices (1/s). A scalar is read as a 1×1 matrix.

    Returns
    -------
    DelayMargin

    Raises
    ------
    DimensionError
        If A is not square or A_d does not match it.
    SpecificationError
        If an entry is NaN or inf.

    Examples
    --------
    >>> round(delay_margin(0.0, -1.0).margin, 6)  # ẋ = −x(t − τ): π/2
    1.570796
    """
    a, a_d = system_matrices(A, A_d)
    n = a.shape[0]
    eig0 = np.linalg.eigvals(a + a_d)
    scale = max(1.0, float(np.max(np.abs(eig0))))
    if np.any(np.abs(eig0) <= 1e-12 * max(1.0, np.linalg.norm(a, 2) + np.linalg.norm(a_d, 2))):
        return DelayMargin(
            margin=0.0,
            stable_without_delay=False,
            crossings=(),
            stable_intervals=(),
            reason="A + A_d is singular: s = 0 is a characteristic root for every delay",
        )
    crossings = _crossings(a, a_d, n, scale)
    unstable0 = int(np.sum(eig0.real > _AXIS_TOL * scale))
    on_axis = bool(np.any(np.abs(eig0.real) <= _AXIS_TOL * scale))
    stable0 = unstable0 == 0 and not on_axis
    intervals = _stable_intervals(unstable0 + (2 if on_axis else 0), crossings)
    if not crossings:
        margin = math.inf if stable0 else 0.0
        reason = (
            "no imaginary-axis crossing: stable for every delay"
            if stable0
            else "no imaginary-axis crossing and A + A_d is not Hurwitz: unstable for every delay"
        )
    elif stable0:
        margin = crossings[0].delay if crossings[0].direction > 0 else _first_destabilising(crossings)
        reason = f"first destabilising crossing at omega = {_frequency_at(crossings, margin):.6g} rad/s"
    else:
        margin = 0.0
        reason = (
            "A + A_d is not Hurwitz; stable only on the listed intervals"
            if intervals
            else "A + A_d is not Hurwitz and no delay stabilises the system"
        )
    if stable0 and intervals and intervals[0][0] == 0.0:
        margin = intervals[0][1]
    return DelayMargin(
        margin=float(margin),
        stable_without_delay=stable0,
        crossings=tuple(crossings),
        stable_intervals=tuple(intervals),
        reason=reason,
    )


def _first_destabilising(crossings: list[Crossing]) -> float:
    return min((c.delay for c in crossings if c.direction > 0), default=math.inf)


def _frequency_at(crossings: list[Crossing], tau: float) -> float:
    for c in crossings:
        k = round((tau - c.delay) / c.period) if c.period > 0 else 0
        if abs(c.delay + k * c.period - tau) <= 1e-9 * max(1.0, tau):
            return c.frequency
    return math.nan


def _crossings(a: np.ndarray, a_d: np.ndarray, n: int, scale: float) -> list[Crossing]:
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
    found: list[tuple[float, float]] = []
    for z in z_values:
        if abs(abs(z) - 1.0) > _UNIT_CIRCLE_TOL:
            continue
        z_unit = z / abs(z)
        for lam in np.linalg.eigvals(a + a_d * z_unit):
            if abs(lam.real) > _AXIS_TOL * scale or lam.imag <= _ZERO_FREQUENCY * scale:
                continue
            omega, theta = _refine(a, a_d, float(lam.imag), float(-np.angle(z_unit)))
            if omega <= _ZERO_FREQUENCY * scale:
                continue
            theta = math.fmod(theta, 2.0 * math.pi)
            if theta < 0.0:
                theta += 2.0 * math.pi
            if any(abs(omega - w) <= 1e-8 * scale and abs(theta - t) <= 1e-8 for w, t in found):
                continue
            found.append((omega, theta))
    crossings = []
    for omega, theta in found:
        tau0 = theta / omega
        crossings.append(
            Crossing(
                frequency=omega,
                delay=tau0,
                period=2.0 * math.pi / omega,
                direction=_direction(a, a_d, omega, tau0),
            )
        )
    crossings.sort(key=lambda c: c.delay)
    return crossings


def _refine(a: np.ndarray, a_d: np.ndarray, omega: float, theta: float) -> tuple[float, float]:
    """Newton steps on uᴴ(iωI − A − A_d e^{−iθ})v = 0 in the two reals (ω, θ); u, v singular vectors."""
    n = a.shape[0]
    for _ in range(3):
        m = 1j * omega * np.eye(n) - a - a_d * np.exp(-1j * theta)
        u, s, vh = np.linalg.svd(m)
        left, right = u[:, -1], vh[-1].conj()
        value = left.conj() @ m @ right  # = smallest singular value times a phase
        d_omega = left.conj() @ (1j * right)
        d_theta = left.conj() @ (1j * a_d * np.exp(-1j * theta)) @ right
        jac = np.array([[d_omega.real, d_theta.real], [d_omega.imag, d_theta.imag]])
        try:
            step = np.linalg.solve(jac, -np.array([value.real, value.imag]))
        except np.linalg.LinAlgError:
            break
        if not np.all(np.isfinite(step)) or abs(step[0]) > 1e-3 * max(1.0, abs(omega)):
            break
        omega, theta = omega + float(step[0]), theta + float(step[1])
        if s[-1] < 1e-15 * max(1.0, s[0]):
            break
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


def _stable_intervals(unstable0: int, crossings: list[Crossing]) -> list[tuple[float, float]]:
    """Sweep the crossings in τ, counting right-half-plane roots (two per crossing pair)."""
    if not crossings:
        return [(0.0, math.inf)] if unstable0 == 0 else []
    horizon = _switch_horizon(unstable0, crossings)
    events: list[tuple[float, int]] = []
    for c in crossings:
        k = 0
        while True:
            tau = c.delay + k * c.period
            if tau > horizon:
                break
            events.append((tau, c.direction))
            k += 1
    events.sort()
    intervals: list[tuple[float, float]] = []
    count = unstable0
    start = 0.0 if count == 0 else None
    for tau, direction in events:
        before = count
        count = max(0, count + 2 * direction)
        if before == 0 and count > 0 and start is not None:
            if tau > start:
                intervals.append((start, tau))
            start = None
        elif before > 0 and count == 0:
            start = tau
    if start is not None:
        intervals.append((start, math.inf))
    return intervals


def _switch_horizon(unstable0: int, crossings: list[Crossing]) -> float:
    """A delay after which the count of unstable roots can never return to zero."""
    up = [c for c in crossings if c.direction > 0]
    down = [c for c in crossings if c.direction < 0]
    rate = sum(c.frequency for c in up) - sum(c.frequency for c in down)
    last_start = max(c.delay for c in crossings)
    longest = max(c.period for c in crossings)
    if rate <= 0.0:
        return last_start + 200.0 * longest
    # count(τ) >= unstable0 + Σ_up 2((τ − τ₀)/T) − Σ_down 2((τ − τ₀)/T + 1) > 0 once τ exceeds:
    offset = sum(c.delay * c.frequency for c in up) / math.pi - sum(c.delay * c.frequency for c in down) / math.pi
    bound = (2.0 * len(down) + 2.0 * len(up) - unstable0 + offset) / (rate / math.pi)
    return max(last_start, bound) + longest
