"""Gain synthesis for a given delay τ: fastest certified PD gains, and descriptor-method state feedback."""

from __future__ import annotations

import enum
import functools
import math
from dataclasses import dataclass, field
from typing import Any, overload

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from mrpctl._validation import nonnegative_scalar, positive_scalar, readonly
from mrpctl.design._common import OPTIMAL, order_value, solve
from mrpctl.design.gains import PDGains, damping_kind, pd_gains
from mrpctl.design.interval import (
    DelayRate,
    UnknownRate,
    descriptor_interval_blocks,
    interval_unknowns,
    solve_lmi,
)
from mrpctl.design.lmi import (
    DEFAULT_MARGIN_TOL,
    WIRTINGER,
    Certificate,
    CertificateStatus,
    PerThread,
    Positivity,
    bracket_root,
    certify_checked,
    check_positivity,
    criterion_name,
    legendre_rows,
)
from mrpctl.design.loop import linearized_loop
from mrpctl.design.margin import DelayMargin, delay_margin
from mrpctl.design.polytope import (
    VERTEX_LIMIT,
    Functional,
    InertiaPolytope,
    PolytopeCertificate,
    certify_polytope,
    inertia_polytope,
    vertex_blocks,
)
from mrpctl.design.robust import (
    DelayModel,
    DelaySet,
    RobustPDSynthesis,
    delay_set,
    exact_check_of_set,
    synthesize_robust_pd,
)
from mrpctl.errors import SpecificationError
from mrpctl.model import gain_from_pd, plant_model
from mrpctl.spacecraft import Spacecraft, check_spacecraft

__all__ = [
    "LMISynthesis",
    "PDSynthesis",
    "SynthesisStatus",
    "synthesize_lmi",
    "synthesize_pd",
]


class SynthesisStatus(enum.Enum):
    """Outcome of a synthesis."""

    #: Gains found, and re-verified by `certify` and the exact margin.
    SYNTHESIZED = "synthesized and verified"
    #: The synthesis LMI was feasible but the re-verification of the gains failed.
    NOT_VERIFIED = "synthesized but not verified"
    #: No gains found (the LMI is infeasible for every tuning tried).
    INFEASIBLE = "infeasible"
    #: The solver failed on every attempt.
    SOLVER_FAILED = "solver failed"


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
    a = _axis_a()
    return a, np.array([[0.0, 0.0], [-1.0, -2.0 * zeta]])


@functools.lru_cache(maxsize=1)
def _axis_a() -> np.ndarray:
    plant = plant_model(Spacecraft(np.ones(3)))
    # The (σ₁, ω₁/4) block of A is [[0, 1], [0, 0]]; in (σ, τσ̇) and t/τ it is the same matrix.
    return np.array(plant.A[np.ix_((0, 3), (0, 3))], dtype=float)


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
    rate: None = None,
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
    rate: DelayRate | float | None = None,
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
    rate: DelayRate | float | None = None,
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
    rate : DelayRate or float, optional
        With ``tau_min``: the bound on τ̇ (a number μ means |τ̇| <= μ; None: unknown rate).

    Returns
    -------
    PDSynthesis or RobustPDSynthesis
        PDSynthesis without the robust options (the nominal design above). With any of
        ``tolerance``, ``product_bound``, ``period``, ``tau_min``, ``rate`` given:
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
    if any(v is not None for v in (tolerance, product_bound, period, tau_min, rate)):
        if positivity is not Positivity.RELAXED or margin_tol != DEFAULT_MARGIN_TOL:
            raise SpecificationError(
                "positivity and margin_tol apply only to the nominal design (not with tolerance, product_bound, "
                "period, tau_min or rate)"
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
            rate=rate,
            rtol=max(rtol, 1e-3),
            omega_max=w / tau,
        )
    a_u = _axis_a()
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
            decay_cert = _shifted_certificate(loop, beta * back_off / tau, tau, order, margin_tol, positivity)
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


@dataclass(frozen=True, eq=False)
class LMISynthesis:
    """Result of [`synthesize_lmi`][mrpctl.design.synthesize_lmi]: a delayed state feedback u = K x(t − τ).

    With the robust options, ``certificate`` and ``decay_certificate`` are
    [`PolytopeCertificate`][mrpctl.design.PolytopeCertificate] objects of the whole set (the independent
    analysis of K and of its α-shifted loops).

    Attributes
    ----------
    status : SynthesisStatus
    tau : float
        The delay τ (s).
    decay_rate : float
        The decay rate α (1/s) imposed through z = e^{αt} x.
    order : int
        Bessel-Legendre order N of the synthesis LMI (0 Jensen, 1 Wirtinger).
    K : numpy.ndarray or None
        (3, 6) gain on x = [σ; ω/4] (N m); None when nothing was found.
    epsilon : float
        The descriptor tuning scalar ε (s) of P₃ = εP₂ that was kept (nan when none).
    certificate : Certificate or None
        [`certify`][mrpctl.design.certify] of ẋ = A x + B K x(t − τ) at τ (same order).
    decay_certificate : Certificate or None
        [`certify`][mrpctl.design.certify] of the shifted system ż = (A + αI) z + e^{ατ} B K z(t − τ).
    margin : DelayMargin or None
        Exact delay margin of the loop under K (at the nominal inertia).
    solves : int
        Synthesis LMI solves (ε line search).
    reason : str
    model : DelayModel
        The delay covered (robust synthesis; CONSTANT for the nominal one).
    tau_min, tau_max : float
        The delay interval covered (s): [τ, τ] for a constant delay, [d·h, d·h + h] = [τ, τ + h] for
        the sampled loop, [tau_min, τ] for the jitter.
    tolerance, product_bound : float
        The inertia set covered (0, 0: the nominal spacecraft).
    exact_check : str
        Robust synthesis: what the exact reference said about K over the set (empty otherwise).
    """

    status: SynthesisStatus
    tau: float
    decay_rate: float
    order: int
    K: np.ndarray | None = field(repr=False)
    epsilon: float
    certificate: Certificate | PolytopeCertificate | None = field(repr=False)
    decay_certificate: Certificate | PolytopeCertificate | None = field(repr=False)
    margin: DelayMargin | None = field(repr=False)
    solves: int
    reason: str
    model: DelayModel = DelayModel.CONSTANT
    tau_min: float = math.nan
    tau_max: float = math.nan
    tolerance: float = 0.0
    product_bound: float = 0.0
    exact_check: str = ""

    @property
    def synthesized(self) -> bool:
        """True when K was found and verified."""
        return self.status is SynthesisStatus.SYNTHESIZED

    @property
    def robust(self) -> bool:
        """True when the synthesis covered a delay interval, a sampled loop or an inertia set."""
        return self.model is not DelayModel.CONSTANT or self.tolerance > 0.0 or self.product_bound > 0.0

    def __str__(self) -> str:
        head = (
            f"LMI synthesis for tau = {self.tau:g} s, decay rate {self.decay_rate:g} 1/s "
            f"({criterion_name(self.order)}, descriptor method): {self.status.value}"
        )
        lines = [head]
        if self.robust:
            span = f"{self.model.value}, tau in [{self.tau_min:.6g}, {self.tau_max:.6g}] s"
            lines.append(
                f"  robust: {span}, "
                + (
                    "nominal inertia"
                    if self.tolerance == 0.0 and self.product_bound == 0.0
                    else f"inertia +/-{100 * self.tolerance:g} %, |J_ij| <= {self.product_bound:g} kg m^2"
                )
            )
            if self.exact_check:
                lines.append(f"  {self.exact_check}")
        lines.append(f"  {self.reason}")
        if self.K is not None:
            margin = self.margin.margin if self.margin is not None else math.nan
            lines.append(f"  epsilon = {self.epsilon:.4g} s; exact delay margin {margin:.6g} s")
            lines.append(f"  K = {np.array2string(self.K, precision=5, max_line_width=200)}")
        return "\n".join(lines)


class _SynthesisProblem:
    """The descriptor-method synthesis LMI of order N, parameterised in (τ, τ², ε, A, εA, B, εB).

    ζ̄ = [x; ẋ; x(t−τ); Ω₀; ...; Ω_{N−1}] after the congruence diag(X, ..., X), X = P₂⁻¹:
    Ψ = He(G(τ)ᵀ P̄ H) + diag(S̄, 0, −S̄, 0) + τ² e₂ᵀ R̄ e₂ − Σₖ (2k+1) E_kᵀ R̄ E_k
        + He([I, εI, 0, ...]ᵀ [A X, −X, B Y, 0, ...]) ≺ 0,
    with S̄, R̄ ≻ 0, τP̄ + diag(0, S̄, 3S̄, ...) ≻ 0, and K = Y X⁻¹. All products are parameter ×
    variable (DPP); decision variables are normalised and the margin t maximised.
    """

    def __init__(self, n: int, m: int, order: int) -> None:
        # deferred: cvxpy (about 1 s to import), only when an LMI is solved
        import cvxpy as cp

        blocks = order + 3
        size = blocks * n
        par = {
            "tau": cp.Parameter(nonneg=True),
            "tau2": cp.Parameter(nonneg=True),
            "eps": cp.Parameter(nonneg=True),
            "A": cp.Parameter((n, n)),
            "epsA": cp.Parameter((n, n)),
            "B": cp.Parameter((n, m)),
            "epsB": cp.Parameter((n, m)),
        }
        self.params = par
        self.P = cp.Variable(((order + 1) * n, (order + 1) * n), symmetric=True)
        self.S = cp.Variable((n, n), symmetric=True)
        self.R = cp.Variable((n, n), symmetric=True)
        self.X = cp.Variable((n, n))
        self.Y = cp.Variable((m, n))
        self.t = cp.Variable()
        P, S, R, X, Y, t = self.P, self.S, self.R, self.X, self.Y, self.t
        eye = np.eye(n)

        def sel(block: int) -> np.ndarray:
            out = np.zeros((n, size))
            out[:, block * n : (block + 1) * n] = eye
            return out

        rows = legendre_rows(order)  # Δ_k over [x, x_d, Ω_0..Ω_{N−1}]
        cols = [0, 2, *range(3, 3 + order)]  # their places in ζ̄ (ẋ is block 1)
        e_mats = [sum(rows[k, i] * sel(c) for i, c in enumerate(cols)) for k in range(order + 1)]
        # G(τ)ᵀ P̄ H with ξ = [x; τΩ₀; ...] and ξ̇ = [ẋ; Δ₀; ...; Δ_{N−1}].
        h_mat = np.vstack([sel(1), *e_mats[:order]])
        g0 = np.vstack([sel(0)] + [np.zeros((n, size))] * order)
        g1 = np.vstack([np.zeros((n, size))] + [sel(3 + k) for k in range(order)])
        he = g0.T @ (P @ h_mat) + par["tau"] * (g1.T @ (P @ h_mat))
        psi = he + he.T
        psi = psi + sel(0).T @ S @ sel(0) - sel(2).T @ S @ sel(2)
        psi = psi + par["tau2"] * (sel(1).T @ R @ sel(1))
        for k, e in enumerate(e_mats):
            psi = psi - (2 * k + 1) * (e.T @ R @ e)
        w0 = par["A"] @ X @ sel(0) - X @ sel(1) + par["B"] @ Y @ sel(2)
        w1 = par["epsA"] @ X @ sel(0) - par["eps"] * (X @ sel(1)) + par["epsB"] @ Y @ sel(2)
        desc = sel(0).T @ w0 + sel(1).T @ w1
        psi = psi + desc + desc.T
        psi = 0.5 * (psi + psi.T)
        pos = par["tau"] * P
        for k in range(order):
            block = np.zeros(((order + 1) * n, n))
            block[(k + 1) * n : (k + 2) * n, :] = eye
            pos = pos + (2 * k + 1) * (block @ S @ block.T)
        pos = 0.5 * (pos + pos.T)
        self.problem = cp.Problem(
            cp.Maximize(t),
            [
                -psi >> t * np.eye(size),
                pos >> t * np.eye((order + 1) * n),
                S >> t * np.eye(n),
                R >> t * np.eye(n),
                cp.trace(pos) + cp.trace(S) + cp.trace(R) == 1.0,
            ],
        )

    def set(self, a: np.ndarray, b: np.ndarray, tau: float, eps: float) -> None:
        p = self.params
        p["tau"].value = tau
        p["tau2"].value = tau * tau
        p["eps"].value = eps
        p["A"].value = a
        p["epsA"].value = eps * a
        p["B"].value = b
        p["epsB"].value = eps * b


#: ``_synthesis_problem(n, m, order)``: compiled once per shape and per thread (thread-safe).
_synthesis_problem = PerThread(_SynthesisProblem)


def _synthesize_pair(
    a: np.ndarray, b: np.ndarray, tau: float, order: int, epsilons: np.ndarray
) -> tuple[np.ndarray | None, float, int, str]:
    """Line search on ε; returns (K, ε, solves, status text) for the best margin t > 0."""
    lmi = _synthesis_problem(a.shape[0], b.shape[1], order)
    best: tuple[float, np.ndarray, float] | None = None
    statuses = []
    for eps in epsilons:
        lmi.set(a, b, tau, float(eps))
        outcome = solve(lmi.problem)
        statuses.append(outcome.status)
        if not outcome.optimal or lmi.t.value is None or lmi.X.value is None:
            continue
        t_opt = float(lmi.t.value)
        if t_opt <= 0.0 or (best is not None and t_opt <= best[0]):
            continue
        x = np.asarray(lmi.X.value, dtype=float)
        if np.linalg.cond(x) > 1e12:
            continue
        best = (t_opt, np.asarray(lmi.Y.value, dtype=float) @ np.linalg.inv(x), float(eps))
    if best is None:
        failed = all(s != OPTIMAL for s in statuses)
        return None, math.nan, len(epsilons), "solver failed" if failed else "infeasible"
    return best[1], best[2], len(epsilons), "optimal"


def synthesize_lmi(
    spacecraft: Spacecraft,
    tau: float,
    *,
    decay_rate: float,
    order: int = WIRTINGER,
    epsilons: Any = None,
    margin_tol: float = DEFAULT_MARGIN_TOL,
    tolerance: float | None = None,
    product_bound: float | None = None,
    period: float | None = None,
    tau_min: float | None = None,
    rate: DelayRate | float | None = None,
) -> LMISynthesis:
    """Delayed state feedback u = K x(t − τ) with decay rate α by the descriptor method.

    With z = e^{αt} x the loop becomes ż = (A + αI) z + e^{ατ} B K z(t − τ); its order-N
    functional (N = 0 Jensen, N = 1 Wirtinger, higher N Bessel-Legendre) is combined with the
    descriptor identity 2(xᵀP₂ᵀ + ẋᵀP₃ᵀ)(−ẋ + A x + B K x(t − τ)) = 0 (Fridman 2001), P₃ = εP₂, and
    the congruence X = P₂⁻¹, Y = K X makes the condition an LMI in (P̄, S̄, R̄, X, Y) for each ε.
    ε is line-searched on a logarithmic grid and the feasible point with the largest normalised
    margin is kept; K = Y X⁻¹. Without a decay rate the LMI accepts arbitrarily small gains, so α
    is the design objective. When J is diagonal the three axes share one 2×2 synthesis of the
    loop gains (K₁, K₂), and K = [4 J K₁, 4 J K₂].

    Every K found is re-verified: [`certify`][mrpctl.design.certify] of the loop at τ and of the
    shifted loop (decay rate α), and [`delay_margin`][mrpctl.design.delay_margin] > τ.

    Parameters
    ----------
    spacecraft : Spacecraft
    tau : float
        Delay τ > 0 (s).
    decay_rate : float
        α >= 0 (1/s); keyword-only and required.
    order : int, optional
        Bessel-Legendre order N (default 1, Wirtinger).
    epsilons : array_like, optional
        Values of ε (s) to try; default τ × logspace(−1.5, 1.5, 9).
    margin_tol : float, optional
        Relative eigenvalue margin for the re-verification certificates.
    tolerance, product_bound : float, optional
        Robust synthesis over the inertia set of [`inertia_polytope`][mrpctl.design.inertia_polytope]
        (relative per-axis tolerance 0 <= tol < 1 of a diagonal nominal J; |J_ij| bound, kg m²).
    period : float, optional
        Robust synthesis for the sampled loop at period h (s), ZOH: the sawtooth τ(t) ∈ [τ, τ + h],
        τ̇ = 1 (τ/h must be whole).
    tau_min : float, optional
        Robust synthesis for the jitter τ(t) ∈ [tau_min, τ] (s); ``tau_min`` = τ is the constant delay.
    rate : DelayRate or float, optional
        With ``tau_min``: bound on τ̇ (a number μ means |τ̇| <= μ; None: unknown).

    Returns
    -------
    LMISynthesis

    Notes
    -----
    **Robust synthesis** (any of ``tolerance``, ``product_bound``, ``period``, ``tau_min``,
    ``rate``; design/lmi.md section 7.8). The multipliers X = P₂⁻¹ and Y = K X are common to every
    vertex of the plant polytope, so the congruenced LMI is affine in the plant matrices (A, B) and
    the vertex LMIs cover the convex hull. Diagonal set: per axis the normalised loop has the input
    gain b = J₀/J ∈ [1/(1+tol), 1/(1−tol)] (2 vertices, one 2×2 synthesis shared by the axes);
    with products of inertia the 6×6 loop at the (deduplicated) vertices of the J⁻¹ box. Constant
    delay: the order-N functional of this function, vertex-dependent up to
    `VERTEX_LIMIT` vertices (common above). Jitter and sampled loop:
    the interval criterion of `interval` (order-N Bessel-Legendre with the
    reciprocally convex combination, N = 1: Wirtinger) in descriptor form
    (`descriptor_interval_blocks`), one functional common to the
    vertices; the decay rate enters as z = e^{αt} x, whose delayed gain e^{ατ(t)} varies in
    [e^{ατ_min}, e^{ατ_max}] (two more vertices). Every K found is re-verified by
    [`certify_polytope`][mrpctl.design.certify_polytope] (the analysis, at α = 0 and at the decay rate)
    and by the exact reference (the grid of exact constant-delay margins over the set, or the
    lifted spectral radius of the sampled loop at the box ends). The set equal to the nominal one
    (tolerance 0, no products, constant delay) runs the nominal synthesis above, number for number.

    Raises
    ------
    SpecificationError
        If τ <= 0 or NaN, α < 0 or NaN, ε values are not positive, or a robust option is invalid
        (tolerance < 0 or >= 1, τ/period not whole, both ``period`` and ``tau_min``, ``rate``
        without ``tau_min``, a coupled nominal J with a robust option).
    """
    spacecraft = check_spacecraft(spacecraft)
    tau = positive_scalar("tau", tau)
    alpha = nonnegative_scalar("decay_rate", decay_rate)
    order = order_value(order)
    margin_tol = positive_scalar("margin_tol", margin_tol)
    robust = any(v is not None for v in (tolerance, product_bound, period, tau_min, rate))
    delays = delay_set(tau, period=period, tau_min=tau_min, rate=rate)
    poly = None
    if robust:
        poly = inertia_polytope(
            spacecraft,
            0.0 if tolerance is None else tolerance,
            product_bound=0.0 if product_bound is None else product_bound,
        )
    scale = delays.tau_max
    if epsilons is None:
        eps_grid = scale * np.logspace(-1.5, 1.5, 9)
    else:
        eps_grid = np.atleast_1d(np.asarray(epsilons, dtype=float))
        if eps_grid.ndim != 1 or eps_grid.size == 0 or not np.all(np.isfinite(eps_grid)) or np.any(eps_grid <= 0):
            raise SpecificationError(f"epsilons must be a non-empty list of finite values > 0, got {epsilons!r}")
    nominal_set = poly is None or (poly.tolerance == 0.0 and poly.product_bound == 0.0)
    if poly is not None and not (nominal_set and delays.model is DelayModel.CONSTANT):
        return _synthesize_lmi_robust(spacecraft, poly, delays, alpha, order, eps_grid, margin_tol)
    gain = math.exp(alpha * tau)
    if spacecraft.is_diagonal:
        # Per axis, in (σᵢ, ωᵢ/4): ẋ = [[0, 1], [0, 0]] x + [0; 1] v with v = uᵢ / (4Jᵢ), and
        # v = [K₁, K₂] x(t − τ) is the same loop for every axis, so it is synthesized once and
        # scaled: K = [4 J K₁, 4 J K₂].
        a_s = _axis_a() + alpha * np.eye(2)
        b_s = gain * np.array([[0.0], [1.0]])
        where = "the per-axis loop"
    else:
        plant = plant_model(spacecraft)
        a_s = plant.A + alpha * np.eye(6)
        b_s = gain * plant.B
        where = "the 6x6 loop"
    k_part, eps, solves, text = _synthesize_pair(a_s, b_s, tau, order, eps_grid)
    if k_part is None:
        status = SynthesisStatus.SOLVER_FAILED if text == "solver failed" else SynthesisStatus.INFEASIBLE
        return LMISynthesis(
            status,
            tau,
            alpha,
            order,
            None,
            math.nan,
            None,
            None,
            None,
            solves,
            f"synthesis LMI {text} for {where} at every epsilon tried",
            tau_min=tau,
            tau_max=tau,
        )
    if spacecraft.is_diagonal:
        k = gain_from_pd(spacecraft, np.full(3, k_part[0, 0]), np.full(3, k_part[0, 1]))
    else:
        k = k_part
    loop = linearized_loop(spacecraft, k)
    cert = loop.certify(tau, order=order, margin_tol=margin_tol)
    decay_cert = _shifted_certificate(loop, alpha, tau, order, margin_tol, Positivity.RELAXED)
    margin = delay_margin(loop.A, loop.A_d)
    verified = cert.certified and decay_cert.certified and margin.margin > tau
    if verified:
        reason = f"K certified at tau and for decay rate {alpha:g} 1/s; exact margin {margin.margin:.6g} s"
    else:
        reason = "re-verification failed: " + "; ".join(
            text
            for ok, text in (
                (cert.certified, f"certificate at tau: {cert.status.value}"),
                (decay_cert.certified, f"decay certificate: {decay_cert.status.value}"),
                (margin.margin > tau, f"exact margin {margin.margin:.6g} s"),
            )
            if not ok
        )
    return LMISynthesis(
        SynthesisStatus.SYNTHESIZED if verified else SynthesisStatus.NOT_VERIFIED,
        tau,
        alpha,
        order,
        readonly(k),
        eps,
        cert,
        decay_cert,
        margin,
        solves,
        reason,
        tau_min=tau,
        tau_max=tau,
    )


# --------------------------------------------------------------------------------------------
# Robust descriptor synthesis: common X = P₂⁻¹ and Y = K X over the vertices of the plant polytope.
# Time is normalised by τ_max (A·τ_max, B·τ_max, ε/τ_max); K is unchanged by the normalisation.
# --------------------------------------------------------------------------------------------


def _robust_plants(
    spacecraft: Spacecraft, poly: InertiaPolytope, delays: DelaySet, alpha: float
) -> tuple[np.ndarray, list[np.ndarray], list[float], bool]:
    """(A + αI, the vertex input matrices B_i, the delayed gains g, per-axis?) of the shifted loop."""
    if poly.diagonal:
        a = _axis_a() + alpha * np.eye(2)
        ends = sorted({1.0 / (1.0 + poly.tolerance), 1.0 / (1.0 - poly.tolerance)})
        bs = [np.array([[0.0], [b]]) for b in ends]
        split = True
    else:
        a = plant_model(spacecraft).A + alpha * np.eye(6)
        bs = []
        seen: set[bytes] = set()
        for jinv in poly.vertices:
            if jinv.tobytes() not in seen:
                seen.add(jinv.tobytes())
                bs.append(np.vstack((np.zeros((3, 3)), jinv / 4.0)))
        split = False
    ends_t = (delays.tau_max,) if delays.model is DelayModel.CONSTANT else (delays.tau_min, delays.tau_max)
    gains = sorted({math.exp(alpha * t) for t in ends_t})
    return a, bs, gains, split


def _constant_blocks(
    plants: list[tuple[np.ndarray, np.ndarray]], order: int, eps: float, vertex: bool
) -> tuple[list[UnknownRate], Any, list[str]]:
    """Unknowns, block function and normalised blocks of the constant-delay descriptor synthesis (τ = 1).

    ζ̃ = [x; x(t − 1); Ω₀ … Ω_{N−1}; ẋ] as in `vertex_blocks`, whose
    plant-free part Ψ (A = A_d = 0, M = 0) is reused; the descriptor term after the congruence is
    He((e_x + ε e_ẋ)ᵀ (A X e_x + B Y e_d − X e_ẋ)).
    """
    n, m = plants[0][0].shape[0], plants[0][1].shape[1]
    size = (order + 1) * n
    k = (order + 3) * n
    zero_n = np.zeros((n, n))
    zero_m = np.zeros((k, n))
    ex = np.zeros((n, k))
    ex[:, :n] = np.eye(n)
    ed = np.zeros((n, k))
    ed[:, n : 2 * n] = np.eye(n)
    edx = np.zeros((n, k))
    edx[:, k - n :] = np.eye(n)
    left = ex + eps * edx
    tags = [str(i) for i in range(len(plants))] if vertex else [""]
    unknowns = []
    for tag in tags:
        unknowns += [UnknownRate(f"P{tag}", size, size, True), UnknownRate(f"S{tag}", n, n, True)]
        unknowns.append(UnknownRate(f"R{tag}", n, n, True))
    unknowns += [UnknownRate("G", n, n, False), UnknownRate("Y", m, n, False)]

    def blocks(mats: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        out: dict[str, np.ndarray] = {}
        g, y = mats["G"], mats["Y"]
        for i, (a, b) in enumerate(plants):
            tag = tags[i] if vertex else ""
            base = vertex_blocks(zero_n, zero_n, mats[f"P{tag}"], mats[f"S{tag}"], mats[f"R{tag}"], zero_m, order=order)
            desc = left.T @ (a @ g @ ex + b @ y @ ed - g @ edx)
            out[f"derivative[vertex {i}]"] = base["derivative"] - (desc + desc.T)
            if vertex or i == 0:
                for name in ("S", "R", "positivity"):
                    out[f"{name}[vertex {i}]"] = base[name]
        return out

    count = len(plants) if vertex else 1
    normalise = [f"{name}[vertex {i}]" for i in range(count) for name in ("S", "R", "positivity")]
    return unknowns, blocks, normalise


def _interval_problem(
    plants: list[tuple[np.ndarray, np.ndarray]], h1: float, rate: DelayRate, order: int, eps: float
) -> tuple[list[UnknownRate], Any, list[str]]:
    """Unknowns, block function and normalised blocks of the interval descriptor synthesis (τ_max = 1)."""
    n, m = plants[0][0].shape[0], plants[0][1].shape[1]
    unknowns = interval_unknowns(n, order, h1 > 0.0, rate)
    normalise = [u.name for u in unknowns if u.symmetric]
    unknowns += [UnknownRate("G", n, n, False), UnknownRate("Y", m, n, False)]
    fixed = {key: np.zeros((n, n)) for key in ("S1", "R1", "Q", "U", "Z")}

    def blocks(mats: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        return descriptor_interval_blocks(plants, h1, rate, {**fixed, **mats}, order=order, epsilon=eps)

    return unknowns, blocks, normalise


def _robust_gain(
    plants: list[tuple[np.ndarray, np.ndarray]],
    delays: DelaySet,
    order: int,
    eps_grid: np.ndarray,
    vertex: bool,
) -> tuple[np.ndarray | None, float, int, str]:
    """Line search on ε of the robust synthesis LMI; (K, ε (s), solves, status text) for the best t > 0."""
    hi = delays.tau_max
    scaled = [(hi * a, hi * b) for a, b in plants]
    best: tuple[float, np.ndarray, float] | None = None
    statuses = []
    for eps in eps_grid:
        if delays.model is DelayModel.CONSTANT:
            unknowns, blocks, normalise = _constant_blocks(scaled, order, float(eps) / hi, vertex)
        else:
            unknowns, blocks, normalise = _interval_problem(
                scaled, delays.tau_min / hi, delays.rate, order, float(eps) / hi
            )
        outcome, values, t_opt = solve_lmi(unknowns, blocks, {}, normalise)
        statuses.append(outcome.status)
        if values is None or not t_opt > 0.0 or (best is not None and t_opt <= best[0]):
            continue
        g = values["G"]
        if np.linalg.cond(g) > 1e12:
            continue
        best = (t_opt, values["Y"] @ np.linalg.inv(g), float(eps))
    if best is None:
        failed = all(st != OPTIMAL for st in statuses)
        return None, math.nan, len(eps_grid), "solver failed" if failed else "infeasible"
    return best[1], best[2], len(eps_grid), "optimal"


def _synthesize_lmi_robust(
    spacecraft: Spacecraft,
    poly: InertiaPolytope,
    delays: DelaySet,
    alpha: float,
    order: int,
    eps_grid: np.ndarray,
    margin_tol: float,
) -> LMISynthesis:
    a, bs, gains, split = _robust_plants(spacecraft, poly, delays, alpha)
    plants = [(a, g * b) for b in bs for g in gains]
    vertex = delays.model is DelayModel.CONSTANT and len(plants) <= VERTEX_LIMIT
    functional = Functional.VERTEX if vertex else Functional.COMMON
    where = (
        f"{'the per-axis loop' if split else 'the 6x6 loop'} at {len(plants)} vertices "
        f"({functional.value}), {delays.model.value}"
    )
    k_part, eps, solves, text = _robust_gain(plants, delays, order, eps_grid, vertex)
    lo, hi = delays.tau_min, delays.tau_max
    base: dict[str, Any] = {
        "model": delays.model,
        "tau_min": lo,
        "tau_max": hi,
        "tolerance": poly.tolerance,
        "product_bound": poly.product_bound,
    }
    tau = hi if delays.model is not DelayModel.SAMPLED else lo
    if k_part is None:
        status = SynthesisStatus.SOLVER_FAILED if text == "solver failed" else SynthesisStatus.INFEASIBLE
        return LMISynthesis(
            status,
            tau,
            alpha,
            order,
            None,
            math.nan,
            None,
            None,
            None,
            solves,
            f"robust synthesis LMI {text} for {where} at every epsilon tried",
            **base,
        )
    k = gain_from_pd(spacecraft, np.full(3, k_part[0, 0]), np.full(3, k_part[0, 1])) if split else k_part
    interval = delays.model is not DelayModel.CONSTANT
    extra: dict[str, Any] = {"tau_min": lo, "rate": delays.rate} if interval else {}
    cert = certify_polytope(poly, k, hi, order=order, margin_tol=margin_tol, **extra)
    decay_cert = certify_polytope(poly, k, hi, order=order, margin_tol=margin_tol, decay_rate=alpha, **extra)
    exact_ok, exact_text = exact_check_of_set(poly, k, delays.model, lo, hi, delays.period, delays.samples)
    loop = linearized_loop(spacecraft, k)
    margin = delay_margin(loop.A, loop.A_d)
    checks = (
        (cert.certified, f"certificate of the set: {cert.status.value}"),
        (decay_cert.certified, f"decay certificate of the set: {decay_cert.status.value}"),
        (exact_ok, exact_text),
    )
    failed = [why for ok, why in checks if not ok]
    if failed:
        status, reason = SynthesisStatus.NOT_VERIFIED, "re-verification failed: " + "; ".join(failed)
    else:
        status = SynthesisStatus.SYNTHESIZED
        reason = (
            f"K synthesized for {where}; certified for the set at alpha = 0 and {alpha:g} 1/s "
            f"({cert.solve_time + decay_cert.solve_time:.2f} s of analysis)"
        )
    return LMISynthesis(
        status,
        tau,
        alpha,
        order,
        readonly(k),
        eps,
        cert,
        decay_cert,
        margin,
        solves,
        reason,
        exact_check=exact_text,
        **base,
    )


def _shifted_certificate(
    loop: Any, alpha: float, tau: float, order: int, margin_tol: float, positivity: Positivity
) -> Certificate:
    """certify ż = (A + αI) z + e^{ατ} A_d z(t − τ): exponential decay at rate α, per axis when split."""
    gain = math.exp(alpha * tau)
    pairs = loop.axes if loop.split else ((loop.A, loop.A_d),)
    cache: dict[bytes, Certificate] = {}
    certs = []
    for a, a_d in pairs:
        key = a_d.tobytes()
        if key not in cache:
            cache[key] = certify_checked(
                a + alpha * np.eye(a.shape[0]), gain * a_d, tau, order, margin_tol, True, positivity
            )
        certs.append(cache[key])
    worst = min(certs, key=lambda c: (c.certified, c.min_margin if c.margins else -math.inf))
    if all(c.certified for c in certs):
        return worst
    if any(c.status is CertificateStatus.SOLVER_FAILED for c in certs):
        return next(c for c in certs if c.status is CertificateStatus.SOLVER_FAILED)
    return worst
