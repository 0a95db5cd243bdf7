"""Gain synthesis for a given delay τ: fastest certified PD gains, and descriptor-method state feedback."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Any, overload

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from mrpctl._validation import positive_scalar
from mrpctl.design._common import NOT_GIVEN, SynthesisStatus, axis_a, delay_rate_argument, order_value
from mrpctl.design.gains import PDGains, damping_kind, pd_gains
from mrpctl.design.interval import (
    DelayRate,
)
from mrpctl.design.lmi import (
    DEFAULT_MARGIN_TOL,
    Certificate,
    Positivity,
    bracket_root,
    certify_checked,
    check_positivity,
    criterion_name,
)
from mrpctl.design.loop import linearized_loop
from mrpctl.design.margin import DelayMargin, delay_margin
from mrpctl.design.robust import (
    RobustPDSynthesis,
    synthesize_robust_pd,
)
from mrpctl.design.state_feedback import LMISynthesis, shifted_certificate, synthesize_lmi
from mrpctl.errors import SpecificationError
from mrpctl.spacecraft import Spacecraft, check_spacecraft

__all__ = [
    "LMISynthesis",
    "PDSynthesis",
    "SynthesisStatus",
    "synthesize_lmi",
    "synthesize_pd",
]


# --------------------------------------------------------------------------------------------
# synthesize_pd: the decay-optimal delayed PD loop, in normalised time.
#
# Per axis, σ̈ = K₁σ(t − τ) + K₂σ̇(t − τ) with K₁ = −ωₙ², K₂ = −2ζωₙ. In t' = t/τ and y = (σ, τσ̇)
# this is y' = A y + A_d(w, ζ) y(t' − 1) with A = [[0, 1], [0, 0]], A_d = [[0, 0], [−w², −2ζw]],
# w = ωₙτ: one problem for every τ. Its characteristic function is λ² + (2ζwλ + w²)e^{−λ}, λ = sτ.
# --------------------------------------------------------------------------------------------

#: Chebyshev nodes of the spectral discretisation of the unit-delay generator (roots |λ| <~ 10 resolved).
_SPECTRAL_NODES = 20
#: Newton steps polishing the rightmost spectral roots on the quasi-polynomial.
_POLISH_STEPS = 15
#: Evaluations of the Nelder-Mead search over (w, ζ) (measured: 400 give w, ζ to 3e-5-6e-5 relative, 800 to 1e-7).
_NELDER_MEAD_EVALUATIONS = 400
#: Range searched for ζ when ``zeta=None`` (the lower end is 1 without ``allow_underdamped``).
_ZETA_RANGE = (0.2, 3.0)


@functools.lru_cache(maxsize=1)
def _generator_template() -> np.ndarray:
    """Chebyshev differentiation on θ ∈ [−1, 0] (Trefethen), as the generator of a 2-state DDE."""
    m = _SPECTRAL_NODES
    x = np.cos(np.pi * np.arange(m + 1) / m)
    c = np.hstack([2.0, np.ones(m - 1), 2.0]) * (-1.0) ** np.arange(m + 1)
    dx = x[:, None] - x[None, :]
    d = np.outer(c, 1.0 / c) / (dx + np.eye(m + 1))
    d = (d - np.diag(d.sum(axis=1))) * 2.0
    gen = np.kron(d, np.eye(2))
    gen[:2, :] = 0.0
    gen[0, 1] = 1.0
    return gen


def pd_rightmost_root(w: float, zeta: float) -> complex:
    """Rightmost root λ = sτ of λ² + (2ζwλ + w²) e^{−λ} = 0 (the delayed PD loop at w = ωₙτ).

    Spectral discretisation of the infinitesimal generator (Breda, Maset & Vermiglio 2005) for
    the candidates, each polished by Newton steps on the quasi-polynomial itself.
    """
    a, b = w * w, 2.0 * zeta * w
    gen = _generator_template().copy()
    m = _SPECTRAL_NODES
    gen[1, 2 * m] = -a
    gen[1, 2 * m + 1] = -b
    ev = np.linalg.eigvals(gen)
    lam = ev[np.argsort(-ev.real)[:6]].astype(complex)
    for _ in range(_POLISH_STEPS):
        e = np.exp(-lam)
        f = lam * lam + (b * lam + a) * e
        fp = 2.0 * lam + (b - b * lam - a) * e
        step = np.where(np.abs(fp) > 0.0, f / np.where(np.abs(fp) > 0.0, fp, 1.0), 0.0)
        step = np.where(np.abs(step) < 0.5, step, 0.0)  # a wild step keeps the spectral value
        lam = lam - step
    return complex(lam[int(np.argmax(lam.real))])


def _unit_axis(zeta: float) -> tuple[np.ndarray, np.ndarray]:
    """The normalised per-axis loop at w = 1 (A from the one plant model, A_d = [[0, 0], [−1, −2ζ]])."""
    a = axis_a()
    return a, np.array([[0.0, 0.0], [-1.0, -2.0 * zeta]])


def _w_bound(zeta: float) -> float:
    """Exact stability bound on w = ωₙτ: the loop's exact margin at ωₙ = 1 (margins scale as 1/ωₙ)."""
    return float(delay_margin(*_unit_axis(zeta)).margin)


@functools.lru_cache(maxsize=64)
def _best_w(zeta: float) -> tuple[float, complex]:
    """The w = ωₙτ in (0, w_bound(ζ)) that minimises Re of the rightmost root, and that root."""

    bound = _w_bound(zeta)
    res = minimize_scalar(
        lambda w: pd_rightmost_root(w, zeta).real,
        bounds=(1e-6 * bound, bound),
        method="bounded",
        options={"xatol": 1e-9 * bound, "maxiter": 200},
    )
    w = float(res.x)
    return w, pd_rightmost_root(w, zeta)


@functools.lru_cache(maxsize=4)
def _best_w_zeta(zeta_min: float) -> tuple[float, float, complex]:
    """(w, ζ, λ) minimising Re λ over w > 0 and ζ ∈ [zeta_min, 3].

    The optimum is a cusp (a multiple root: Re λ grows like the cube root of the distance to it),
    so a derivative-free Nelder-Mead search is used, started from the best point of a coarse grid;
    it is compared with the 1-D optimum on the boundary ζ = zeta_min. The answer does not depend on
    the spacecraft or on τ, so it is computed once per process.
    """

    zeta_max = _ZETA_RANGE[1]

    def objective(v: np.ndarray) -> float:
        w, z = float(v[0]), float(v[1])
        if w <= 0.0 or z < zeta_min or z > zeta_max:
            return 1.0 + abs(w) + abs(z)  # outside: worse than any stable design (Re λ < 0)
        return pd_rightmost_root(w, z).real

    grid = [(f * _w_bound(z), z) for z in np.linspace(zeta_min, zeta_max, 6) for f in (0.25, 0.5, 0.75)]
    start = min(grid, key=lambda p: objective(np.array(p)))
    simplex = [start, (start[0] * 0.8, start[1]), (start[0], min(start[1] + 0.15, zeta_max))]
    res = minimize(
        objective,
        np.array(start),
        method="Nelder-Mead",
        options={"xatol": 1e-10, "fatol": 1e-14, "maxfev": _NELDER_MEAD_EVALUATIONS, "initial_simplex": simplex},
    )
    w, z = float(res.x[0]), float(res.x[1])
    w_edge, lam_edge = _best_w(zeta_min)
    if objective(res.x) >= lam_edge.real or z - zeta_min <= 1e-6 * zeta_min:
        return w_edge, zeta_min, lam_edge
    return w, z, pd_rightmost_root(w, z)


@dataclass(frozen=True, eq=False)
class PDSynthesis:
    """Result of [`synthesize_pd`][mrpctl.design.synthesize_pd]: the decay-optimal delayed PD gains and their
    certificates.

    Attributes
    ----------
    status : SynthesisStatus
    tau : float
        The delay τ (s) the gains are designed and certified for.
    order : int
        Bessel-Legendre order N of the certificates.
    gains : PDGains
        The PD gains (same ζ, ωₙ on every axis) whose exact rightmost characteristic root at τ is
        leftmost. Always present (check ``status`` for whether they were verified).
    certificate : Certificate
        The LMI certificate of the 6×6 loop at τ under ``gains`` (exponential stability).
    margin : DelayMargin
        The exact delay margin of the loop under ``gains`` (> τ when verified).
    solves : int
        LMI solves used.
    reason : str
    decay_rate : float
        The certified decay rate α (1/s): the shifted loop ż = (A + αI) z + e^{ατ} A_d z(t − τ)
        is certified, so every solution decays at least like e^{−αt}; nan when none was certified.
    decay_certificate : Certificate or None
        That certificate of the shifted 6×6 loop.
    rightmost_root : complex
        The exact rightmost characteristic root s (1/s) of the loop at τ (computed independently of
        the LMI: spectral discretisation polished by Newton on s² + (2ζωₙ s + ωₙ²) e^{−sτ}).
    """

    status: SynthesisStatus
    tau: float
    order: int
    gains: PDGains = field(repr=False)
    certificate: Certificate = field(repr=False)
    margin: DelayMargin = field(repr=False)
    solves: int
    reason: str
    decay_rate: float = math.nan
    decay_certificate: Certificate | None = field(default=None, repr=False)
    rightmost_root: complex = complex(math.nan, math.nan)

    @property
    def synthesized(self) -> bool:
        """True when gains were found and verified."""
        return self.status is SynthesisStatus.SYNTHESIZED

    @property
    def omega_n(self) -> float:
        """The natural frequency ωₙ (rad/s) of the design."""
        return float(self.gains.omega_n[0])

    @property
    def zeta(self) -> float:
        """The damping ratio ζ of the design."""
        return float(self.gains.zeta[0])

    @property
    def exact_decay_rate(self) -> float:
        """−Re of the exact rightmost root (1/s): the true decay rate, >= ``decay_rate``."""
        return -self.rightmost_root.real

    def __str__(self) -> str:
        head = f"PD synthesis for tau = {self.tau:g} s ({criterion_name(self.order)}): {self.status.value}"
        margin = self.margin.margin
        root = self.rightmost_root
        return (
            f"{head}\n  omega_n = {self.omega_n:.6g} rad/s (omega_n tau = {self.omega_n * self.tau:.6g}), "
            f"zeta = {self.zeta:.4g} ({damping_kind(self.zeta)})\n"
            f"  certified decay rate {self.decay_rate:.6g} 1/s; exact rightmost root {root.real:.6g}"
            f"{'+' if root.imag >= 0 else '-'}{abs(root.imag):.6g}j 1/s; exact delay margin {margin:.6g} s; "
            f"{self.solves} LMI solves\n  {self.reason}"
        )


@overload
def synthesize_pd(
    spacecraft: Spacecraft,
    tau: float,
    *,
    zeta: float | None = 1.0,
    order: int = 3,
    allow_underdamped: bool = False,
    rtol: float = 1e-4,
    positivity: Positivity = Positivity.RELAXED,
    margin_tol: float = DEFAULT_MARGIN_TOL,
    tolerance: None = None,
    product_bound: None = None,
    period: None = None,
    tau_min: None = None,
    delay_rate: None = None,
) -> PDSynthesis: ...


@overload
def synthesize_pd(
    spacecraft: Spacecraft,
    tau: float,
    *,
    zeta: float | None = 1.0,
    order: int = 3,
    allow_underdamped: bool = False,
    rtol: float = 1e-4,
    positivity: Positivity = Positivity.RELAXED,
    margin_tol: float = DEFAULT_MARGIN_TOL,
    tolerance: float | None = None,
    product_bound: float | None = None,
    period: float | None = None,
    tau_min: float | None = None,
    delay_rate: DelayRate | float | None = None,
    rate: Any = NOT_GIVEN,
) -> PDSynthesis | RobustPDSynthesis: ...


def synthesize_pd(
    spacecraft: Spacecraft,
    tau: float,
    *,
    zeta: float | None = 1.0,
    order: int = 3,
    allow_underdamped: bool = False,
    rtol: float = 1e-4,
    positivity: Positivity = Positivity.RELAXED,
    margin_tol: float = DEFAULT_MARGIN_TOL,
    tolerance: float | None = None,
    product_bound: float | None = None,
    period: float | None = None,
    tau_min: float | None = None,
    delay_rate: DelayRate | float | None = None,
    rate: Any = NOT_GIVEN,
) -> PDSynthesis | RobustPDSynthesis:
    """The fastest-decaying delayed PD gains for the delay τ, with a certified decay rate.

    The loop per axis is σ̈ = K₁σ(t − τ) + K₂σ̇(t − τ), K₁ = −ωₙ², K₂ = −2ζωₙ (the gains of
    [`pd_gains`][mrpctl.design.pd_gains]), with characteristic function s² + (2ζωₙ s + ωₙ²)e^{−sτ}.
    In normalised time t/τ it depends on w = ωₙτ and ζ only, so the design is searched in w (and ζ)
    once for every τ: w (and ζ when ``zeta=None``) minimises the real part of the exact rightmost
    root (bounded scalar searches on the spectral abscissa). With ζ free the optimum is the triple
    root λ = sτ = −(2 − √2) of multiplicity-induced dominancy (w ≈ 0.2813, ζ ≈ 0.8197); with ζ = 1,
    w ≈ 0.4449 and sτ ≈ −0.2954.

    The LMI then certifies the design in the same normalised time (unit delay): stability, and the
    largest decay rate α for which the shifted loop ż = (A + αI) z + e^{ατ} A_d z(t − τ) is certified
    (a safeguarded root search in ατ to relative width ``rtol``). Both certificates are re-verified
    on the 6×6 loop of ``spacecraft`` at τ, and the exact delay margin is checked to exceed τ.

    Parameters
    ----------
    spacecraft : Spacecraft
    tau : float
        Delay τ > 0 (s).
    zeta : float or None, optional
        Damping ratio ζ (default 1, critically damped; < 1 needs ``allow_underdamped``). None
        optimises ζ too, over [1, 3], or over [0.2, 3] with ``allow_underdamped``.
    order : int, optional
        Bessel-Legendre order N of the certificates (default 3).
    allow_underdamped : bool, optional
        Accept ζ < 1.
    rtol : float, optional
        Relative width of the final bracket on the certified decay rate.
    positivity : Positivity, optional
        Positivity condition of the certificates.
    margin_tol : float, optional
        Relative eigenvalue margin of the certificates.
    tolerance, product_bound : float, optional
        Robust design over the inertia set of [`inertia_polytope`][mrpctl.design.inertia_polytope]
        (relative per-axis tolerance 0 <= tol < 1 on the diagonal of a diagonal nominal J; bound on
        |J_ij| (kg m²)).
    period : float, optional
        Robust design for the sampled loop at period h (s) with ZOH: the sawtooth τ(t) ∈ [τ, τ + h],
        τ̇ = 1 (τ/h must be a whole number).
    tau_min : float, optional
        Robust design for the jitter τ(t) ∈ [tau_min, τ] (s) (``tau_min`` = τ: the constant delay).
    delay_rate : DelayRate or float, optional
        With ``tau_min``: the bound on τ̇ (a number μ means |τ̇| <= μ; None: unknown rate); ``rate`` is its
        deprecated name (DeprecationWarning).

    Returns
    -------
    PDSynthesis or RobustPDSynthesis
        PDSynthesis without the robust options (the nominal design above). With any of
        ``tolerance``, ``product_bound``, ``period``, ``tau_min``, ``delay_rate`` given:
        [`RobustPDSynthesis`][mrpctl.design.RobustPDSynthesis] from
        [`synthesize_robust_pd`][mrpctl.design.synthesize_robust_pd] (the one robust search), started at the
        decay-optimal nominal ωₙ = w/τ above: when the polytope certificate (order ``order``) holds
        there for the whole set, those are the gains (so a tolerance 0 returns the nominal design's
        gains); else the largest ωₙ below it that is certified, to relative width max(``rtol``,
        1e-3), then checked exactly (grid margin, or the lifted spectral radius for the sampled
        loop). Infeasible is a status, not an exception. ``positivity`` and ``margin_tol`` apply to
        the nominal design only (non-default values are refused with the robust options).

    Raises
    ------
    SpecificationError
        If τ <= 0 or NaN, ζ <= 0 (or < 1 without ``allow_underdamped``), or an option is invalid
        (tolerance < 0 or >= 1, τ/period not whole, both ``period`` and ``tau_min``, ``rate``
        without ``tau_min``, a coupled nominal J with the robust options).

    Examples
    --------
    >>> from mrpctl import paper
    >>> d = synthesize_pd(paper.SPACECRAFT, 0.5, zeta=None, allow_underdamped=True)
    >>> round(d.omega_n * 0.5, 3), round(d.zeta, 3), d.decay_rate < d.exact_decay_rate
    (0.281, 0.82, True)
    """
    spacecraft = check_spacecraft(spacecraft)
    tau = positive_scalar("tau", tau)
    order = order_value(order)
    rtol = positive_scalar("rtol", rtol)
    if rtol >= 0.5:
        raise SpecificationError(f"rtol must be < 0.5, got {rtol}")
    positivity = check_positivity(positivity)
    margin_tol = positive_scalar("margin_tol", margin_tol)
    if not isinstance(allow_underdamped, bool):
        raise SpecificationError(f"allow_underdamped must be True or False, got {allow_underdamped!r}")
    if zeta is None:
        w, z, lam = _best_w_zeta(_ZETA_RANGE[0] if allow_underdamped else 1.0)
        how = f"w = omega_n tau and zeta optimised (zeta in [{_ZETA_RANGE[0] if allow_underdamped else 1.0:g}, 3])"
    else:
        z = positive_scalar("zeta", zeta)
        pd_gains(spacecraft, zeta=z, omega_n=1.0, allow_underdamped=allow_underdamped)  # checks ζ
        w, lam = _best_w(z)
        how = f"w = omega_n tau optimised at zeta = {z:g}"
    rate = delay_rate_argument(delay_rate, rate)
    if any(v is not None for v in (tolerance, product_bound, period, tau_min, rate)):
        if positivity is not Positivity.RELAXED or margin_tol != DEFAULT_MARGIN_TOL:
            raise SpecificationError(
                "positivity and margin_tol apply only to the nominal design (not with tolerance, product_bound, "
                "period, tau_min or delay_rate)"
            )
        return synthesize_robust_pd(
            spacecraft,
            tau,
            zeta=z,
            order=order,
            tolerance=0.0 if tolerance is None else tolerance,
            product_bound=0.0 if product_bound is None else product_bound,
            period=period,
            tau_min=tau_min,
            delay_rate=rate,
            rtol=max(rtol, 1e-3),
            omega_max=w / tau,
        )
    a_u = axis_a()
    a_d_u = np.array([[0.0, 0.0], [-w * w, -2.0 * z * w]])
    solves = 0

    def shifted(beta: float) -> Certificate:
        nonlocal solves
        solves += 1
        return certify_checked(a_u + beta * np.eye(2), math.exp(beta) * a_d_u, 1.0, order, margin_tol, True, positivity)

    gains = pd_gains(spacecraft, zeta=z, omega_n=w / tau, allow_underdamped=allow_underdamped or z < 1.0)
    loop = linearized_loop(spacecraft, gains.K)
    margin = loop.delay_margin()
    root = complex(lam) / tau
    beta_exact = -lam.real
    unit = shifted(0.0)
    beta = math.nan
    if unit.certified:
        for fraction in (0.9, 0.5, 0.2, 0.05):
            cert = shifted(fraction * beta_exact)
            if cert.certified:
                beta, _ = bracket_root(shifted, fraction * beta_exact, cert, beta_exact, rtol)
                break
    certificate = loop.certify(tau, order=order, positivity=positivity, margin_tol=margin_tol)
    decay_cert = None
    alpha = math.nan
    if math.isfinite(beta):
        for back_off in (1.0, 1.0 - 10.0 * rtol, 0.99):
            decay_cert = shifted_certificate(loop, beta * back_off / tau, tau, order, margin_tol, positivity)
            if decay_cert.certified:
                alpha = beta * back_off / tau
                break
    checks = (
        (certificate.certified, f"certificate at tau: {certificate.status.value}"),
        (decay_cert is not None and decay_cert.certified, "no decay rate certified"),
        (margin.margin > tau, f"exact margin {margin.margin:.6g} s <= tau"),
        (not alpha >= -root.real, "certified decay above the exact one (soundness check failed)"),
    )
    failed = [text for ok, text in checks if not ok]
    if failed:
        status = SynthesisStatus.NOT_VERIFIED
        reason = f"{how}; re-verification failed: " + "; ".join(failed)
    else:
        status = SynthesisStatus.SYNTHESIZED
        reason = (
            f"{how}; exact rightmost root at s tau = {lam.real:.6g}; certified alpha tau = {alpha * tau:.6g} "
            f"(rtol {rtol:g}); exact margin {margin.margin:.6g} s"
        )
    return PDSynthesis(
        status,
        tau,
        order,
        gains,
        certificate,
        margin,
        solves + (3 if loop.split else 1),
        reason,
        decay_rate=alpha,
        decay_certificate=decay_cert,
        rightmost_root=root,
    )
