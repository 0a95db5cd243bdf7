"""Gain, phase and delay margins of the sampled loop: u held over [t_k, t_{k+1}), u_k = K x(t_{k−d}).

The loop is broken at the plant input of the zero-order-hold discretisation x_{k+1} = Φ x_k + Γ u_k
(`mrpctl.design.sampled.lifted_matrices`): L(z) = −K (zI − Φ)⁻¹ Γ z^{−d}, evaluated on the unit circle
z = e^{iωh}, 0 < ω ≤ π/h (the Nyquist frequency). As for the continuous loop
(`mrpctl.design.performance.loop_margins_delayed`) a factor k or a phase e^{−iφ} is applied to every channel at
once: the gain margins are 1/|λ| where an eigenvalue λ of L crosses the negative real axis, the phase margin
π − |arg λ| where |λ| = 1. The delay margin is the sampled loop's own: the number of further whole samples of
delay it stays stable for (`max_stable_delay_samples`, exact), not a phase divided by a frequency, since a
sampled controller can only be late by whole samples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from mrpctl._validation import integer, positive_scalar
from mrpctl.design._loop_eigen import negative_axis_factors, unit_circle_angles
from mrpctl.design.sampled import lifted_matrices, max_stable_delay_samples, sampled_stability, sampled_system
from mrpctl.errors import SpecificationError

__all__ = ["SampledLoopMargins", "loop_margins_sampled"]

#: Gain factors above this are reported as an infinite gain margin (as for the continuous loop).
_GAIN_MARGIN_CAP = 1e3


@dataclass(frozen=True, eq=False)
class SampledLoopMargins:
    """Margins of the sampled loop broken at the plant input, L(z) = −K (zI − Φ)⁻¹ Γ z^{−d}.

    Attributes
    ----------
    period : float
        h (s).
    delay_samples : int
        d, the loop's delay in samples.
    stable : bool
        The lifted closed loop's spectral radius is < 1 (exact); the margins mean something only then.
    spectral_radius : float
        That radius.
    gain_margin : float
        Smallest factor k > 1 on K that puts a closed-loop pole on the unit circle (``inf`` when none up to 1e3).
    phase_crossover : float
        ω (rad/s) of that pole (nan when the margin is infinite).
    lower_gain_margin : float
        Largest factor k < 1 that does (0.0 when none).
    lower_phase_crossover : float
    phase_margin : float
        Smallest phase lag φ (rad) on every channel that puts a pole on the circle (``inf`` when no eigenvalue of
        L reaches modulus 1 below the Nyquist frequency).
    gain_crossover : float
        ω (rad/s) where it does.
    max_stable_delay_samples : int
        The largest d' such that the loop is stable for every delay 0, 1, ..., d' samples
        (`mrpctl.design.sampled.max_stable_delay_samples`, exact; ``d_limit`` when stable up to the search's
        limit; −1 when unstable without delay).
    delay_margin_samples : int or None
        Further whole samples of delay beyond d the loop stays stable for: d' − d when d' >= d; −1 when the loop
        is unstable at d; None when it is stable at d but unstable at some smaller delay (then d' < d says so).
    """

    period: float
    delay_samples: int
    stable: bool
    spectral_radius: float
    gain_margin: float
    phase_crossover: float
    lower_gain_margin: float
    lower_phase_crossover: float
    phase_margin: float
    gain_crossover: float
    max_stable_delay_samples: int
    delay_margin_samples: int | None

    @property
    def gain_margin_db(self) -> float:
        """20 log₁₀ of the gain margin (dB)."""
        return 20.0 * math.log10(self.gain_margin) if self.gain_margin > 0 else -math.inf

    @property
    def delay_margin(self) -> float:
        """The delay margin in seconds: ``delay_margin_samples`` · h (nan when it is not defined)."""
        if self.delay_margin_samples is None or self.delay_margin_samples < 0:
            return math.nan
        return self.delay_margin_samples * self.period

    def __str__(self) -> str:
        state = "stable" if self.stable else "UNSTABLE (margins meaningless)"
        return (
            f"sampled at h = {self.period:.6g} s, d = {self.delay_samples} ({state}, spectral radius "
            f"{self.spectral_radius:.9g}): gain margin {self.gain_margin:.6g} ({self.gain_margin_db:.4g} dB) at "
            f"{self.phase_crossover:.6g} rad/s, phase margin {math.degrees(self.phase_margin):.5g} deg at "
            f"{self.gain_crossover:.6g} rad/s, " + self._delay_words()
        )

    def _delay_words(self) -> str:
        if self.delay_margin_samples is None:
            return (
                f"no delay margin: unstable at a smaller delay (every delay stable only up to "
                f"{self.max_stable_delay_samples} samples)"
            )
        if self.delay_margin_samples < 0:
            return "no delay margin (unstable at d)"
        return f"delay margin {self.delay_margin_samples} more samples ({self.delay_margin:.6g} s)"


def loop_margins_sampled(
    A: Any, B: Any, K: Any, period: Any, *, delay_samples: Any = 0, points: Any = 4000, d_limit: Any = 2000
) -> SampledLoopMargins:
    """Gain, phase and delay margins of the sampled loop u_k = K x_{k−d} held over a period on ẋ = A x + B u.

    The eigenvalues of L(e^{iωh}) are sampled on ``points`` frequencies, geometric from 1e-6 π/h to π/h with
    at least one point every 0.02 rad of ωh·(d + 1), and every change in the number of eigenvalues in the upper
    half-plane or outside the unit circle is bisected to 1e-13 relative.

    Parameters
    ----------
    A, B, K : array_like
        (n, n), (n, m) and (m, n).
    period : float
        h (s), > 0.
    delay_samples : int, optional
        d >= 0.
    points : int, optional
        Grid points, >= 100 (default 4000).
    d_limit : int, optional
        The delay-margin search's largest d (default 2000).

    Returns
    -------
    SampledLoopMargins
    """
    a, b, k = sampled_system(A, B, K)
    h = positive_scalar("period", period)
    d = integer("delay_samples", delay_samples, minimum=0)
    points = integer("points", points, minimum=100)
    d_limit = integer("d_limit", d_limit, minimum=d + 1)
    if not np.any(k):
        raise SpecificationError("K is zero: the loop has no feedback and no margins")
    phi, gamma = lifted_matrices(a, b, h)
    n = a.shape[0]
    nyquist = math.pi / h
    grid = np.geomspace(1e-6 * nyquist, nyquist, points)
    fine = np.linspace(grid[0], nyquist, math.ceil(math.pi * (d + 1) / 0.02) + 2)
    grid = np.unique(np.concatenate((grid, fine)))

    def loop(w: np.ndarray) -> np.ndarray:
        z = np.exp(1j * w * h)
        m = z[:, None, None] * np.eye(n) - phi
        x = np.linalg.solve(m, np.broadcast_to(gamma, (len(w), *gamma.shape)))
        return np.linalg.eigvals(-(k @ x) * (z ** (-d))[:, None, None])

    def upper(w: float) -> int:
        return int(np.sum(loop(np.array([w]))[0].imag > 0.0))

    def outside(w: float) -> int:
        return int(np.sum(np.abs(loop(np.array([w]))[0]) > 1.0))

    values = np.concatenate([loop(chunk) for chunk in np.array_split(grid, max(1, len(grid) // 4096))])
    ups = np.sum(values.imag > 0.0, axis=1)
    outs = np.sum(np.abs(values) > 1.0, axis=1)
    gm_up, wpc_up, gm_low, wpc_low = math.inf, math.nan, 0.0, math.nan
    crossings = list(np.flatnonzero(np.diff(ups)))
    # at the Nyquist frequency L is real (a real system at z = −1): a crossing of the axis may sit there
    crossings_at_nyquist = [len(grid) - 1]
    for i in crossings + crossings_at_nyquist:
        w = nyquist if i == len(grid) - 1 else _bisect(upper, float(grid[i]), float(grid[i + 1]))
        for factor in negative_axis_factors(loop(np.array([w]))[0]):
            if 1.0 < factor < gm_up and factor <= _GAIN_MARGIN_CAP:
                gm_up, wpc_up = factor, w
            elif gm_low < factor < 1.0:
                gm_low, wpc_low = factor, w
    pm, wgc = math.inf, math.nan
    for i in np.flatnonzero(np.diff(outs)):
        w = _bisect(outside, float(grid[i]), float(grid[i + 1]))
        for phase in unit_circle_angles(loop(np.array([w]))[0]):
            margin = math.pi - abs(phase)
            if margin < pm:
                pm, wgc = margin, w
    stability = sampled_stability(a, b, k, h, delay_samples=d)
    largest = max_stable_delay_samples(a, b, k, h, d_limit=d_limit)
    extra: int | None = -1
    if stability.stable:
        extra = largest - d if largest >= d else None
    return SampledLoopMargins(
        period=h,
        delay_samples=d,
        stable=stability.stable,
        spectral_radius=stability.spectral_radius,
        gain_margin=gm_up,
        phase_crossover=wpc_up,
        lower_gain_margin=gm_low,
        lower_phase_crossover=wpc_low,
        phase_margin=pm,
        gain_crossover=wgc,
        max_stable_delay_samples=largest,
        delay_margin_samples=extra,
    )


def _bisect(count: Any, lo: float, hi: float) -> float:
    """The frequency in (lo, hi) where the integer function ``count`` changes."""
    c_lo = count(lo)
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if count(mid) == c_lo:
            lo = mid
        else:
            hi = mid
        if hi - lo <= 1e-13 * hi:
            break
    return 0.5 * (lo + hi)
