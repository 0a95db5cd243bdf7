"""The attitude loop linearised at the origin, ẋ = A x + B K x(t − τ), and its per-axis split."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mrpctl._validation import positive_scalar, readonly
from mrpctl.design._common import is_diagonal, order_value
from mrpctl.design.lmi import (
    DEFAULT_MARGIN_TOL,
    Certificate,
    CertificateStatus,
    DelayCertification,
    Positivity,
    SearchStatus,
    certify_checked,
    check_positivity,
    max_certified_delay,
    verified_margins,
)
from mrpctl.design.margin import DelayMargin, delay_margin
from mrpctl.model import gain_matrix, pd_from_gain, plant_model
from mrpctl.spacecraft import Spacecraft, check_spacecraft

__all__ = ["LinearizedLoop", "linearized_loop"]


@dataclass(frozen=True, eq=False)
class LinearizedLoop:
    """ẋ = A x + A_d x(t − τ) with A_d = B K: the delayed loop u = K x(t − τ) linearised at x = 0.

    Attributes
    ----------
    spacecraft : Spacecraft
    K : numpy.ndarray
        (3, 6) gain on x = [σ; ω/4] (N m).
    A : numpy.ndarray
        (6, 6) [[0, I₃], [0, 0]].
    A_d : numpy.ndarray
        (6, 6) B K = [[0, 0], [K₁, K₂]].
    axes : tuple of (numpy.ndarray, numpy.ndarray)
        When K₁ and K₂ are diagonal the loop is three independent 2×2 systems on (σᵢ, ωᵢ/4):
        A_i = [[0, 1], [0, 0]], A_d,i = [[0, 0], [K₁ᵢᵢ, K₂ᵢᵢ]]; empty tuple otherwise.
    """

    spacecraft: Spacecraft
    K: np.ndarray = field(repr=False)
    A: np.ndarray = field(repr=False)
    A_d: np.ndarray = field(repr=False)
    axes: tuple[tuple[np.ndarray, np.ndarray], ...] = field(repr=False)

    @property
    def split(self) -> bool:
        """True when the loop splits into three per-axis 2×2 problems."""
        return bool(self.axes)

    def __str__(self) -> str:
        how = "three decoupled axes" if self.split else "coupled axes"
        return f"linearised delayed loop of {self.spacecraft} ({how})"

    def delay_margin(self) -> DelayMargin:
        """Exact delay margin of the 6×6 loop ([`delay_margin`][mrpctl.design.delay_margin])."""
        return delay_margin(self.A, self.A_d)

    def certify(
        self,
        tau: float,
        *,
        order: int = 3,
        positivity: Positivity = Positivity.RELAXED,
        margin_tol: float = DEFAULT_MARGIN_TOL,
    ) -> Certificate:
        """[`certify`][mrpctl.design.certify] for the 6×6 loop, solved per axis when it splits.

        Per-axis decision matrices are assembled block-diagonally into the 6×6 coordinates, and the
        assembled certificate is re-verified on the full 6×6 LMI blocks in float64.
        """
        tau = positive_scalar("tau", tau)
        order = order_value(order)
        positivity = check_positivity(positivity)
        margin_tol = positive_scalar("margin_tol", margin_tol)
        if not self.split:
            return certify_checked(self.A, self.A_d, tau, order, margin_tol, True, positivity)
        cache: dict[bytes, Certificate] = {}
        certs = []
        for a_i, a_d_i in self.axes:
            key = a_d_i.tobytes()
            if key not in cache:
                cache[key] = certify_checked(a_i, a_d_i, tau, order, margin_tol, True, positivity)
            certs.append(cache[key])
        return self._assemble(certs, tau, order, positivity, margin_tol, sum(c.solve_time for c in cache.values()))

    def max_certified_delay(
        self,
        *,
        order: int = 3,
        rtol: float = 1e-4,
        positivity: Positivity = Positivity.RELAXED,
        margin_tol: float = DEFAULT_MARGIN_TOL,
    ) -> DelayCertification:
        """[`max_certified_delay`][mrpctl.design.max_certified_delay] for the loop, per axis when it splits.

        The certified interval is the intersection of the per-axis intervals; the certificate at
        its upper end is assembled and re-verified on the full 6×6 LMI.
        """
        if not self.split:
            return max_certified_delay(
                self.A, self.A_d, order=order, rtol=rtol, positivity=positivity, margin_tol=margin_tol
            )
        cache: dict[bytes, DelayCertification] = {}
        results = []
        for a_i, a_d_i in self.axes:
            key = a_d_i.tobytes()
            if key not in cache:
                cache[key] = max_certified_delay(
                    a_i, a_d_i, order=order, rtol=rtol, positivity=positivity, margin_tol=margin_tol
                )
            results.append(cache[key])
        solves = sum(r.solves for r in cache.values())
        time = sum(r.solve_time for r in cache.values())
        failed = [i + 1 for i, r in enumerate(results) if not r.certified]
        if failed:
            reasons = "; ".join(f"axis {i}: {results[i - 1].reason}" for i in failed)
            return DelayCertification(
                SearchStatus.NOT_CERTIFIED, order, math.nan, math.nan, None, solves, time, reasons
            )
        lower = max(r.lower for r in results)
        upper = min(r.upper for r in results)
        limiting = int(np.argmin([r.upper for r in results])) + 1
        if lower > upper:
            return DelayCertification(
                SearchStatus.NOT_CERTIFIED,
                order,
                math.nan,
                math.nan,
                None,
                solves,
                time,
                "the per-axis certified intervals do not intersect",
            )
        cert = self.certify(upper, order=order, positivity=positivity, margin_tol=margin_tol)
        capped = any(r.status is SearchStatus.SEARCH_LIMIT for r in results)
        status = SearchStatus.SEARCH_LIMIT if capped else SearchStatus.CERTIFIED
        reason = f"per axis, limited by axis {limiting}; {results[limiting - 1].reason}"
        return DelayCertification(status, order, lower, upper, cert, solves, time + cert.solve_time, reason)

    def _assemble(
        self,
        certs: list[Certificate],
        tau: float,
        order: int,
        positivity: Positivity,
        margin_tol: float,
        time: float,
    ) -> Certificate:
        base: dict[str, Any] = {
            "order": order,
            "tau": tau,
            "solver": "CLARABEL",
            "solve_time": time,
            "positivity": positivity,
        }
        bad = [(i + 1, c) for i, c in enumerate(certs) if not c.certified]
        if bad:
            failed = any(c.status is CertificateStatus.SOLVER_FAILED for _, c in bad)
            return Certificate(
                status=CertificateStatus.SOLVER_FAILED if failed else CertificateStatus.NOT_CERTIFIED,
                P=None,
                S=None,
                R=None,
                margins=(),
                solver_status=", ".join(c.solver_status for c in certs),
                solver_margin=min(c.solver_margin for c in certs),
                reason="; ".join(f"axis {i}: {c.reason}" for i, c in bad),
                **base,
            )
        n = 6
        blocks = order + 1
        p = np.zeros((blocks * n, blocks * n))
        s = np.zeros((n, n))
        r = np.zeros((n, n))
        for i, c in enumerate(certs):
            assert c.P is not None and c.S is not None and c.R is not None  # certified above
            idx = (i, 3 + i)
            for b in range(blocks):
                for d in range(blocks):
                    for k in range(2):
                        for m in range(2):
                            p[b * n + idx[k], d * n + idx[m]] = c.P[b * 2 + k, d * 2 + m]
            s[np.ix_(idx, idx)] = c.S
            r[np.ix_(idx, idx)] = c.R
        margins = verified_margins(self.A, self.A_d, tau, p, s, r, order=order, positivity=positivity)
        worst = min(margins, key=lambda m: m.relative)
        ok = worst.relative >= margin_tol
        return Certificate(
            status=CertificateStatus.CERTIFIED if ok else CertificateStatus.NOT_CERTIFIED,
            P=readonly(p),
            S=readonly(s),
            R=readonly(r),
            margins=margins,
            solver_status="optimal (3 axes)",
            solver_margin=min(c.solver_margin for c in certs),
            reason=(
                f"per-axis certificates assembled and re-verified on the 6x6 LMI; smallest relative margin "
                f"{worst.relative:.3g} ({worst.name})"
                if ok
                else f"assembled 6x6 block {worst.name!r} has relative margin {worst.relative:.3g} < {margin_tol:g}"
            ),
            **base,
        )


def linearized_loop(spacecraft: Spacecraft, K: Any) -> LinearizedLoop:
    """Linearise the delayed loop u = K x(t − τ) at x = 0: (A, A_d = B K) and the per-axis split.

    Parameters
    ----------
    spacecraft : Spacecraft
    K : array_like
        (3, 6) gain on x = [σ; ω/4] (N m), convention K = [4 J K₁, 4 J K₂].

    Returns
    -------
    LinearizedLoop
        With ``axes`` filled when K₁ = J⁻¹K_σ/4 and K₂ = J⁻¹K_ω/4 are diagonal (e.g. diagonal J and
        diagonal gain blocks): the 6×6 LMI then splits into three 2×2 LMIs with the same answer.
    """
    spacecraft = check_spacecraft(spacecraft)
    k = gain_matrix(K)
    plant = plant_model(spacecraft)
    a, a_d = plant.closed_loop_matrices(k)
    k1, k2 = pd_from_gain(spacecraft, k)
    axes: tuple[tuple[np.ndarray, np.ndarray], ...] = ()
    if is_diagonal(k1) and is_diagonal(k2):
        a_axis = readonly(plant.A[np.ix_((0, 3), (0, 3))])  # the (σ₁, ω₁/4) block of the one model's A
        axes = tuple((a_axis, readonly([[0.0, 0.0], [k1[i, i], k2[i, i]]])) for i in range(3))
    return LinearizedLoop(spacecraft=spacecraft, K=readonly(k), A=readonly(a), A_d=readonly(a_d), axes=axes)
