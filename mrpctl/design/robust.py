"""Robust PD synthesis: the fastest PD gains certified for an inertia polytope and the flown delay.

The delay is one of: a constant τ; an interval τ(t) ∈ [τ_min, τ] with a rate bound (jitter); the
sampled-data sawtooth τ(t) ∈ [d h, (d+1) h], τ̇ = 1 (the loop as simulated at period h with
τ = d h). The plants are the vertices of [`inertia_polytope`][mrpctl.design.inertia_polytope]
(tolerance 0 means the nominal spacecraft), certified by
[`certify_polytope`][mrpctl.design.certify_polytope]: for a constant delay a vertex-dependent
Lyapunov-Krasovskii functional per axis (one functional common to the 64 vertices with products of
inertia); for the interval and sampled delays one functional common to the vertices. A certificate
test that ends SOLVER_FAILED (after the polytope's own retries) counts as not certified; the count
is in ``reason``.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import Any

from mrpctl._validation import integer, nonnegative_scalar, positive_scalar
from mrpctl.design._common import NOT_GIVEN, delay_rate_argument, order_value, renamed_attribute
from mrpctl.design.gains import PDGains, pd_gains
from mrpctl.design.interval import DelayRate, rate_value
from mrpctl.design.lmi import CertificateStatus
from mrpctl.design.margin import delay_margin
from mrpctl.design.polytope import PolytopeCertificate, certify_polytope, exact_polytope_margin, inertia_polytope
from mrpctl.design.sampled import sampled_stability, spacecraft_axes
from mrpctl.errors import SpecificationError
from mrpctl.spacecraft import Spacecraft, check_spacecraft

__all__ = [
    "DelayModel",
    "DelaySet",
    "RobustPDSynthesis",
    "RobustStatus",
    "delay_set",
    "exact_check_of_set",
    "synthesize_robust_pd",
]


class DelayModel(enum.Enum):
    """Which delay the robust certificate covers."""

    CONSTANT = "constant delay"
    INTERVAL = "interval time-varying delay"
    SAMPLED = "sampled-data sawtooth delay"


class RobustStatus(enum.Enum):
    """Outcome of [`synthesize_robust_pd`][mrpctl.design.synthesize_robust_pd]."""

    SYNTHESIZED = "synthesized, certified and checked exactly"
    NOT_VERIFIED = "certified, but the exact check failed (report this)"
    INFEASIBLE = "no gain certified"


@dataclass(frozen=True, eq=False)
class RobustPDSynthesis:
    """Result of [`synthesize_robust_pd`][mrpctl.design.synthesize_robust_pd].

    Attributes
    ----------
    status : RobustStatus
    model : DelayModel
    tau_min, tau_max : float
        The delay interval covered (s) (equal for a constant delay).
    tolerance, product_bound : float
        The inertia set.
    omega_n : float
        Certified natural frequency (rad/s) of the nominal design (nan when infeasible).
    gains : PDGains or None
    certificate : PolytopeCertificate or None
    exact_check : str
        What the exact reference said about the returned gains.
    solves : int
        Number of certificate evaluations.
    reason : str
    """

    status: RobustStatus
    model: DelayModel
    tau_min: float
    tau_max: float
    tolerance: float
    product_bound: float
    omega_n: float
    gains: PDGains | None = field(repr=False)
    certificate: PolytopeCertificate | None = field(repr=False)
    exact_check: str
    solves: int
    reason: str

    def __str__(self) -> str:
        return (
            f"robust PD ({self.model.value}, tau in [{self.tau_min:.6g}, {self.tau_max:.6g}] s, "
            f"{_inertia_words(self.tolerance)}): {self.status.value}; omega_n = {self.omega_n:.6g} rad/s "
            f"({self.solves} certificates)\n  {self.exact_check}\n  {self.reason}"
        )


def synthesize_robust_pd(
    spacecraft: Spacecraft,
    tau: float,
    *,
    zeta: float = 1.0,
    order: int = 2,
    tolerance: float = 0.0,
    product_bound: float = 0.0,
    period: float | None = None,
    tau_min: float | None = None,
    delay_rate: DelayRate | float | None = None,
    rate: Any = NOT_GIVEN,
    rtol: float = 1e-3,
    omega_max: float | None = None,
) -> RobustPDSynthesis:
    """The largest ωₙ (at ζ) whose PD gains are certified for every inertia of the set and the delay.

    Parameters
    ----------
    spacecraft : Spacecraft
        Nominal spacecraft (diagonal J); gains are [`pd_gains`][mrpctl.design.pd_gains] of it.
    tau : float
        Delay (s): the constant delay, the upper end of the jitter interval, or (with ``period``)
        the delay d·h of the sampled loop (τ/h must be an integer to 1e-9).
    zeta : float, optional
        Damping ratio (default 1).
    order : int, optional
        Bessel-Legendre order of the certificate (default 2).
    tolerance, product_bound : float, optional
        The inertia set (see [`inertia_polytope`][mrpctl.design.inertia_polytope]).
    period : float, optional
        Sampling period h (s): certify the sawtooth τ(t) ∈ [τ, τ + h], τ̇ = 1.
    tau_min : float, optional
        Lower end of a jitter interval [tau_min, tau] (s), with ``delay_rate`` (None: unknown rate);
        ``tau_min`` equal to ``tau`` is the constant delay, and ``delay_rate`` without ``tau_min`` is refused.
    delay_rate : DelayRate or float, optional
        Bound on the delay's rate dτ/dt with ``tau_min`` (``rate``: its deprecated name).
    rtol : float, optional
        Relative width of the final ωₙ bracket.
    omega_max : float, optional
        Search no higher than this ωₙ (rad/s): it is tested first and returned when certified, else
        the search runs below it. [`synthesize_pd`][mrpctl.design.synthesize_pd] passes its
        decay-optimal nominal ωₙ, so a set close to the nominal one gives the nominal design.
    """
    sc = check_spacecraft(spacecraft)
    tau = positive_scalar("tau", tau)
    zeta = positive_scalar("zeta", zeta)
    order = order_value(order)
    tol = nonnegative_scalar("tolerance", tolerance)
    pb = nonnegative_scalar("product_bound", product_bound)
    rtol = positive_scalar("rtol", rtol)
    poly = inertia_polytope(sc, tol, product_bound=pb)
    delays = delay_set(tau, period=period, tau_min=tau_min, delay_rate=delay_rate_argument(delay_rate, rate))
    model, lo, hi, rate_v, d = delays.model, delays.tau_min, delays.tau_max, delays.delay_rate, delays.samples
    top = None if omega_max is None else positive_scalar("omega_max", omega_max)
    solves = 0
    failures = 0

    def test(omega: float) -> PolytopeCertificate:
        nonlocal solves, failures
        solves += 1
        gains = pd_gains(sc, zeta=zeta, omega_n=omega, allow_underdamped=True)
        if model is DelayModel.CONSTANT:
            cert = certify_polytope(poly, gains.K, hi, order=order)
        else:
            cert = certify_polytope(poly, gains.K, hi, order=order, tau_min=lo, delay_rate=rate_v)
        failures += cert.status is CertificateStatus.SOLVER_FAILED
        return cert

    unit = delay_margin([[0.0, 1.0], [0.0, 0.0]], [[0.0, 0.0], [-1.0, -2.0 * zeta]]).margin
    bound = unit / hi
    base: dict[str, Any] = {"model": model, "tau_min": lo, "tau_max": hi, "tolerance": tol, "product_bound": pb}

    def checked(omega: float, cert: PolytopeCertificate, reason: str) -> RobustPDSynthesis:
        """The certified gains at ``omega``, checked by the exact reference."""
        gains = pd_gains(sc, zeta=zeta, omega_n=omega, allow_underdamped=True)
        ok, check = exact_check_of_set(poly, gains.K, model, lo, hi, period, d)
        return RobustPDSynthesis(
            RobustStatus.SYNTHESIZED if ok else RobustStatus.NOT_VERIFIED,
            omega_n=omega,
            gains=gains,
            certificate=cert,
            exact_check=check,
            solves=solves,
            reason=reason + _failed(failures),
            **base,
        )

    if top is not None:
        cert = test(top)
        if cert.certified:
            return checked(top, cert, f"omega_max = {top:.6g} rad/s itself is certified for the whole set")
        bound = min(bound, top)
    good, good_cert = math.nan, None
    for f in (0.5, 0.1, 0.01):
        cert = test(f * bound)
        if cert.certified:
            good, good_cert = f * bound, cert
            break
    if good_cert is None:
        return RobustPDSynthesis(
            RobustStatus.INFEASIBLE,
            omega_n=math.nan,
            gains=None,
            certificate=None,
            exact_check="",
            solves=solves,
            reason=f"no omega_n down to 1 % of {bound:.6g} rad/s certified{_failed(failures)}",
            **base,
        )
    bad = 2.0 * good if top is None else min(2.0 * good, top)
    for _ in range(40):
        if top is not None and bad >= top:
            break  # omega_max was tested first: not certified
        cert = test(bad)
        if not cert.certified:
            break
        good, good_cert = bad, cert
        bad = 2.0 * bad if top is None else min(2.0 * bad, top)
    for _ in range(100):
        if bad - good <= rtol * good:
            break
        mid = 0.5 * (good + bad)
        cert = test(mid)
        if cert.certified:
            good, good_cert = mid, cert
        else:
            bad = mid
    return checked(good, good_cert, f"largest certified omega_n to rtol {rtol:g}")


@dataclass(frozen=True)
class DelaySet:
    """The delay a robust certificate covers (see `delay_set`).

    Attributes
    ----------
    model : DelayModel
    tau_min, tau_max : float
        The delay interval (s); equal for a constant delay.
    delay_rate : DelayRate
        τ̇ bound (sawtooth for the sampled loop; unknown for a constant delay, where it is unused).
    samples : int
        d = τ/h of the sampled loop (0 otherwise).
    period : float or None
        Sampling period h (s) of the sampled loop.
    """

    model: DelayModel
    tau_min: float
    tau_max: float
    delay_rate: DelayRate
    samples: int = 0
    period: float | None = None

    @property
    def rate(self) -> DelayRate:
        """Deprecated name of ``delay_rate`` (``rate`` is a measurement rate in Hz elsewhere in mrpctl)."""
        return renamed_attribute(self, "rate", "delay_rate")


def delay_set(
    tau: float,
    *,
    period: float | None = None,
    tau_min: float | None = None,
    delay_rate: DelayRate | float | None = None,
    rate: Any = NOT_GIVEN,
) -> DelaySet:
    """Check and classify the delay options shared by the robust syntheses.

    ``period`` h: the sampled loop, τ(t) ∈ [τ, τ + h], τ̇ = 1 (τ/h must be whole to 1e-9);
    ``tau_min`` (with ``delay_rate``, None = unknown; ``rate`` is its deprecated name): τ(t) ∈ [tau_min, τ]
    (``tau_min`` = τ is the constant delay); neither: the constant delay τ. ``period`` with ``tau_min``,
    ``delay_rate`` without
    ``tau_min`` and ``tau_min`` > τ are refused (SpecificationError naming the parameter).
    """
    tau = positive_scalar("tau", tau)
    if period is not None and tau_min is not None:
        raise SpecificationError("give either period (sampled loop) or tau_min (jitter interval), not both")
    rate = delay_rate_argument(delay_rate, rate)
    if rate is not None and tau_min is None:
        raise SpecificationError("delay_rate applies only with tau_min (the jitter interval [tau_min, tau])")
    if period is not None:
        h = positive_scalar("period", period)
        ratio = tau / h
        d = integer("tau / period", round(ratio), minimum=0)
        if abs(ratio - d) > 1e-9 * max(1.0, ratio):
            raise SpecificationError(f"tau / period must be an integer number of samples, got {ratio:.12g}")
        return DelaySet(DelayModel.SAMPLED, tau, tau + h, DelayRate.sawtooth(), d, h)
    if tau_min is not None:
        lo = nonnegative_scalar("tau_min", tau_min)
        rate_v = rate_value(rate)
        if lo == tau:
            return DelaySet(DelayModel.CONSTANT, tau, tau, rate_v)
        if not tau > lo:
            raise SpecificationError(f"tau_min must not exceed tau, got [{lo}, {tau}]")
        return DelaySet(DelayModel.INTERVAL, lo, tau, rate_v)
    return DelaySet(DelayModel.CONSTANT, tau, tau, DelayRate.unknown())


def _inertia_words(tolerance: float) -> str:
    """'inertia +/-20 %', or 'nominal inertia' for tolerance 0 (not '+/-0 %')."""
    return "nominal inertia" if tolerance == 0.0 else f"inertia +/-{100 * tolerance:g} %"


def _failed(count: int) -> str:
    return f" ({count} certificate test(s) SOLVER_FAILED, counted as not certified)" if count else ""


def exact_check_of_set(
    poly: Any, K: Any, model: DelayModel, lo: float, hi: float, period: float | None, d: int
) -> tuple[bool, str]:
    """The exact reference for the gain K over an inertia set: (passed, what it found).

    Sampled loop: the lifted spectral radius per axis at J = (1 ± tol) J₀ (the lifted check needs a
    diagonal J, so products of inertia are not covered by it). Otherwise the smallest exact
    constant-delay margin over the grid of [`exact_polytope_margin`][mrpctl.design.exact_polytope_margin]
    (21 points per axis), which must exceed ``hi``.

    Parameters
    ----------
    poly : InertiaPolytope
    K : array_like
        (3, 6) gain (N m).
    model : DelayModel
    lo, hi : float
        The delay interval (s).
    period : float or None
        Sampling period h (s) of the sampled loop.
    d : int
        Delay in samples of the sampled loop.
    """
    if model is DelayModel.SAMPLED and period is not None:
        worst = 0.0
        # one end when the tolerance is 0: the box is the nominal inertia (its lifted loops once, not twice)
        for scale in dict.fromkeys((1.0 - poly.tolerance, 1.0 + poly.tolerance)):
            sc = Spacecraft(scale * poly.nominal.inertia)
            for a, b, k in spacecraft_axes(sc, K):
                if a.shape[0] * (d + 1) > 4000:
                    return True, "exact lifted check skipped (companion too large)"
                worst = max(worst, sampled_stability(a, b, k, period, delay_samples=d).spectral_radius)
        return worst < 1.0, f"exact lifted spectral radius at the box ends: {worst:.9f}"
    margin = exact_polytope_margin(poly, K, points=21)
    return margin > hi, f"exact worst constant-delay margin over the inertia grid {margin:.6g} s (need > {hi:.6g})"
