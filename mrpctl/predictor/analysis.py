"""The predictor loop's exact analysis (the equations are in `mrpctl.predictor` and ``design/predictor.md``):
the linearised loop matrices, their stability (STABLE / UNSTABLE / UNRESOLVED), the inertia-mismatch margin
with its brackets, and the PD design that uses them."""

from __future__ import annotations

import enum
import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg

from mrpctl._validation import available_memory, finite_scalar, integer, positive_scalar, readonly
from mrpctl.clock import delay_samples
from mrpctl.design import delay_margin, pd_gains
from mrpctl.errors import InertiaWarning, SpecificationError
from mrpctl.model import STATE_SIZE, gain_matrix, linear_matrices, pd_from_gain
from mrpctl.spacecraft import Spacecraft, check_spacecraft

__all__ = [
    "MarginInterval",
    "MismatchMargin",
    "PredictorDesign",
    "PredictorStability",
    "StabilityMethod",
    "StabilityStatus",
    "inertia_mismatch_margin",
    "lifted_spectral_radius",
    "margin_side",
    "margin_side_bracket",
    "perturbed_spacecraft",
    "predictor_loop_matrices",
    "predictor_stability",
    "sampled_predictor_matrices",
    "synthesize_predictor_pd",
]

#: Smallest |e| scanned by the margin search, and the scan's geometric ratio.
_SCAN_START = 1e-3
_SCAN_RATIO = 1.25
#: The negative side stops at e = −(1 − this): J_plant = 1e-3 J_model.
_NEGATIVE_END = 1.0 - 1e-3
_MAX_BISECTIONS = 200
_DESIGN_GRID = 10


class StabilityMethod(enum.Enum):
    """How the exact stability test was made."""

    #: Continuous loop: imaginary-axis crossings of the quasi-polynomial (crossing method).
    CROSSING = "crossing"
    #: Sampled loop: spectral radius of the lifted block-companion matrix.
    LIFTED = "lifted"
    #: Sampled loop split per axis: roots of the scalar characteristic polynomial of degree d + 2.
    AXIS_POLYNOMIAL = "axis-polynomial"


class StabilityStatus(enum.Enum):
    """The verdict of [predictor_stability][mrpctl.predictor.predictor_stability]."""

    #: Every root is shown inside the unit circle (sampled) or the crossing count is 0 (continuous).
    STABLE = "stable"
    #: A root is shown on or outside the unit circle (sampled), or the crossing count is not 0.
    UNSTABLE = "unstable"
    #: Sampled loop: a root lies so close to the unit circle that the floating-point test cannot tell
    #: which side it is on; ``radius_bounds`` is the interval that contains the spectral radius.
    UNRESOLVED = "unresolved"


@dataclass(frozen=True, eq=False)
class PredictorStability:
    """Exact stability of the linearised predictor loop for one (model, plant, K, τ, rate).

    Attributes
    ----------
    stable : bool
        True only when the loop is shown exponentially stable (``status`` is STABLE); False for
        UNSTABLE *and* UNRESOLVED (read ``status`` to tell them apart).
    method : StabilityMethod
    spectral_radius : float
        Sampled loop: the largest |λ| (dimensionless; the midpoint of ``radius_bounds`` when only
        bounds are known); ``nan`` for the continuous test and for the split test without ``radius``.
    tau : float
        Delay τ (s).
    rate : float or None
        Measurement rate (Hz), None for the continuous loop.
    status : StabilityStatus
        STABLE, UNSTABLE or UNRESOLVED (default: from ``stable``).
    radius_bounds : tuple of float or None
        Sampled loop: an interval (lo, hi) that contains the spectral radius when it was bounded
        (always when ``status`` is UNRESOLVED; with ``radius`` for the split test; always for the
        lifted test), None otherwise.
    """

    stable: bool
    method: StabilityMethod
    spectral_radius: float
    tau: float
    rate: float | None
    status: StabilityStatus | None = None
    radius_bounds: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if self.status is None:
            object.__setattr__(self, "status", StabilityStatus.STABLE if self.stable else StabilityStatus.UNSTABLE)

    @property
    def resolved(self) -> bool:
        """True when the test reached a verdict (STABLE or UNSTABLE)."""
        return self.status is not StabilityStatus.UNRESOLVED

    def __str__(self) -> str:
        verdict = {
            StabilityStatus.STABLE: "stable",
            StabilityStatus.UNSTABLE: "UNSTABLE",
            StabilityStatus.UNRESOLVED: "UNRESOLVED (a root next to the unit circle)",
        }[self.status or StabilityStatus.UNSTABLE]
        where = "continuous" if self.rate is None else f"sampled at {self.rate:g} Hz"
        if self.radius_bounds is not None and (
            self.status is StabilityStatus.UNRESOLVED or self.radius_bounds[1] - self.radius_bounds[0] > 1e-9
        ):
            radius = f", spectral radius in [{self.radius_bounds[0]:.12f}, {self.radius_bounds[1]:.12f}]"
        elif not math.isnan(self.spectral_radius):
            radius = f", spectral radius {self.spectral_radius:.9f}"
        else:
            radius = ""
        return f"predictor loop {verdict} at tau = {self.tau:g} s ({where}, {self.method.value}{radius})"


@dataclass(frozen=True)
class MarginInterval:
    """The interval of relative inertia errors e (J_plant = (1 + e) J_model) containing 0 that keeps K stable.

    Attributes
    ----------
    lower, upper : float
        Stable for every scanned e in (lower, upper); ``lower`` < 0 < ``upper``. Each end is the stable
        side of its bracket, or the search limit.
    lower_capped, upper_capped : bool
        True when the end is the search limit (still stable there), not a stability boundary.
    lower_bracket, upper_bracket : tuple of float or None
        (shown stable, not shown stable): the two e of the final bisection step, the stability boundary
        between them (width <= ``rtol`` relative); both equal to the limit when capped; None when not
        computed (a hand-built interval).
    lower_unresolved, upper_unresolved : bool
        True when the bracket's outer e was UNRESOLVED (a root within rounding of the unit circle), not
        shown unstable: the boundary is then within the bracket or within that rounding band beyond it.
    """

    lower: float
    upper: float
    lower_capped: bool
    upper_capped: bool
    lower_bracket: tuple[float, float] | None = None
    upper_bracket: tuple[float, float] | None = None
    lower_unresolved: bool = False
    upper_unresolved: bool = False

    @property
    def symmetric(self) -> float:
        """min(−lower, upper): the ± margin."""
        return min(-self.lower, self.upper)

    def __str__(self) -> str:
        def end(value: float, capped: bool, bracket: tuple[float, float] | None, unresolved: bool) -> str:
            if capped:
                return f"{value:+.4%} (limit)"
            if bracket is None:
                return f"{value:+.4%}"
            lo, hi = sorted(bracket)
            note = ", unresolved end" if unresolved else ""
            return f"{value:+.4%} (boundary in [{lo:+.4%}, {hi:+.4%}]{note})"

        lo = end(self.lower, self.lower_capped, self.lower_bracket, self.lower_unresolved)
        hi = end(self.upper, self.upper_capped, self.upper_bracket, self.upper_unresolved)
        return f"e in ({lo}, {hi})"


@dataclass(frozen=True, eq=False)
class MismatchMargin:
    """Result of [`inertia_mismatch_margin`][mrpctl.predictor.inertia_mismatch_margin].

    Attributes
    ----------
    uniform : MarginInterval
        J_plant = (1 + e) J_model.
    per_axis : tuple of MarginInterval
        Axis i alone: J_plant = S J_model S with S = diag(1, .., √(1 + e), .., 1) (for a diagonal
        J_model, J_ii → (1 + e) J_ii); empty when not requested.
    tau : float
        Delay τ (s).
    rate : float or None
        Measurement rate (Hz), None for the continuous loop.
    evaluations : int
        Number of exact stability tests made.
    """

    uniform: MarginInterval
    per_axis: tuple[MarginInterval, ...]
    tau: float
    rate: float | None
    evaluations: int

    @property
    def symmetric(self) -> float:
        """The largest m with every case (uniform and each axis) stable on (−m, m)."""
        return min([self.uniform.symmetric] + [m.symmetric for m in self.per_axis])

    def __str__(self) -> str:
        where = "continuous" if self.rate is None else f"sampled at {self.rate:g} Hz"
        lines = [f"inertia mismatch margin at tau = {self.tau:g} s ({where}): +/-{self.symmetric:.4%}"]
        lines.append(f"  uniform  {self.uniform}")
        lines += [f"  axis {i + 1}   {m}" for i, m in enumerate(self.per_axis)]
        return "\n".join(lines)


@dataclass(frozen=True, eq=False)
class PredictorDesign:
    """Result of [`synthesize_predictor_pd`][mrpctl.predictor.synthesize_predictor_pd]: the fastest PD at ζ whose
    predictor loop keeps the margin.

    Attributes
    ----------
    K : numpy.ndarray
        (3, 6) gain on x = [σ; ω/4] (N m), K = [4 J K₁, 4 J K₂] with K₁ = −ωₙ² I, K₂ = −2ζωₙ I.
    omega_n : float
        ωₙ (rad/s), the stable side of a bracket narrower than ``rtol``.
    zeta : float
    required : float
        The required ± relative inertia error e (J_plant = (1 + e) J_model).
    margin : MismatchMargin
        The margin of the returned gain.
    """

    K: np.ndarray = field(repr=False)
    omega_n: float
    zeta: float
    required: float
    margin: MismatchMargin

    def __str__(self) -> str:
        return (
            f"predictor PD: omega_n = {self.omega_n:.6g} rad/s, zeta = {self.zeta:g}, keeps +/-{self.required:.2%} "
            f"inertia error (margin +/-{self.margin.symmetric:.4%})"
        )


# ========================================================================== matrices
def _inputs(spacecraft: Any, K: Any, tau: Any, plant: Any) -> tuple[Spacecraft, np.ndarray, float, Spacecraft]:
    model = check_spacecraft(spacecraft, "spacecraft")
    gain = gain_matrix(K)
    tau_value = finite_scalar("tau", tau)
    if tau_value < 0.0:
        raise SpecificationError(f"tau must be >= 0 s, got {tau_value}")
    true_plant = model if plant is None else check_spacecraft(plant, "plant")
    return model, gain, tau_value, true_plant


def predictor_loop_matrices(
    spacecraft: Spacecraft, K: Any, tau: float, *, plant: Spacecraft | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(A₀, A₁) of the continuous predictor loop dx̂/dt = A₀ x̂(t) + A₁ x̂(t − τ), linearised at x = 0.

    A₀ = A + B_m K and A₁ = e^{Aτ} (B − B_m) K, with B_m from the controller's model ``spacecraft``
    and B from ``plant`` (default: the model itself, then A₁ = 0).

    Parameters
    ----------
    spacecraft : Spacecraft
        The controller's model (inertia J_m, kg m²).
    K : array_like
        (3, 6) gain on x = [σ; ω/4] (N m): u = K x̂.
    tau : float
        Measurement delay τ >= 0 (s).
    plant : Spacecraft, keyword-only
        The true plant (inertia J, kg m²).
    """

    model, gain, tau_value, true_plant = _inputs(spacecraft, K, tau, plant)
    a, b_m = linear_matrices(model)
    b = linear_matrices(true_plant)[1]
    a0 = a + b_m @ gain
    a1 = scipy.linalg.expm(a * tau_value) @ (b - b_m) @ gain
    return readonly(a0), readonly(a1)


def sampled_predictor_matrices(
    spacecraft: Spacecraft, K: Any, tau: float, *, plant: Spacecraft | None = None, rate: float = 1000.0
) -> tuple[np.ndarray, np.ndarray, int]:
    """(F₀, F₁, d) of the sampled predictor loop x̂_{k+1} = F₀ x̂_k + F₁ x̂_{k−d} (zero-order hold, h = 1/rate).

    F₀ = Φ + Γ_m K and F₁ = Φ^d (Γ − Γ_m) K with Φ = e^{Ah}, Γ = ∫₀ʰ e^{As} ds B (exact discretisation, by
    the matrix exponential of the augmented matrix [[A, B], [0, 0]] h).

    Raises
    ------
    SpecificationError
        If τ · rate is not a whole number of samples (the message names tau).
    """
    model, gain, tau_value, true_plant = _inputs(spacecraft, K, tau, plant)
    d = delay_samples(tau_value, rate)
    h = 1.0 / positive_scalar("rate", rate)
    phi, gamma_m = _zoh(*linear_matrices(model), h)
    _, gamma = _zoh(*linear_matrices(true_plant), h)
    f0 = phi + gamma_m @ gain
    f1 = np.linalg.matrix_power(phi, d) @ (gamma - gamma_m) @ gain
    return readonly(f0), readonly(f1), d


def _zoh(a: np.ndarray, b: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:

    n, m = b.shape
    augmented = np.zeros((n + m, n + m))
    augmented[:n, :n] = a
    augmented[:n, n:] = b
    exp = scipy.linalg.expm(augmented * h)
    return exp[:n, :n], exp[:n, n:]


# ========================================================================= stability
def predictor_stability(
    spacecraft: Spacecraft,
    K: Any,
    tau: float,
    *,
    plant: Spacecraft | None = None,
    rate: float | None = 1000.0,
    radius: bool = False,
) -> PredictorStability:
    """Exact stability of the linearised predictor loop with model ``spacecraft`` and true ``plant``.

    When the loop splits into three axes (diagonal J_m, J and gain blocks) each 2×2 axis is tested
    alone: continuous, by the crossing method of [`mrpctl.design.delay_margin`][mrpctl.design.delay_margin]; sampled, by
    the
    number of roots of the axis polynomial λ^d det(λI − F₀) − c(λ) inside the unit circle (the winding
    number of λ^{−d}-scaled values on |λ| = 1, on a grid refined until every phase step is < π/2).
    Otherwise the 6×6 loop is tested: crossing method, or the eigenvalues of the lifted matrix of size
    6 (d + 1) (slow for d in the hundreds).

    Parameters
    ----------
    spacecraft : Spacecraft
        The controller's model (J_m).
    K : array_like
        (3, 6) gain on x = [σ; ω/4] (N m).
    tau : float
        Delay τ (s); with ``rate`` a whole number d of samples.
    plant : Spacecraft, keyword-only
        The true plant (default: the model).
    rate : float or None, keyword-only
        Measurement rate (Hz) of the sampled loop (default 1000); None tests the continuous loop.
    radius : bool, keyword-only
        Sampled, split loop: also compute the spectral radius (bisection on the circle radius, on root counts
        that can be certified; ``radius_bounds`` is the interval reached). Often about 1e-5 wide, but wider
        where the counts cannot be certified near the root: the shipped predictor-paper case (d = 500, exact
        model, true radius 0.98814) gives [0.95268, 1.00496]. The verdict does not depend on it (the count on
        the unit circle). The lifted test always gives the radius.

    Returns
    -------
    PredictorStability
    """
    model, gain, tau_value, true_plant = _inputs(spacecraft, K, tau, plant)
    if rate is None:
        a0, a1 = predictor_loop_matrices(model, gain, tau_value, plant=true_plant)
        if _splits(a0, a1):
            ok = all(_continuous_stable(a0[np.ix_(ix, ix)], a1[np.ix_(ix, ix)], tau_value) for ix in _AXES)
        else:
            ok = _continuous_stable(a0, a1, tau_value)
        return PredictorStability(ok, StabilityMethod.CROSSING, math.nan, tau_value, None)
    rate_value = positive_scalar("rate", rate)
    f0, f1, d = sampled_predictor_matrices(model, gain, tau_value, plant=true_plant, rate=rate_value)
    if _splits(f0, f1) and d > 0:
        polys = [_axis_polynomial(f0[np.ix_(ix, ix)], f1[np.ix_(ix, ix)]) for ix in _AXES]
        pairs = [(a, c) for a, c in polys if a is not None and c is not None]
        if len(pairs) == len(polys):
            counts = [_count_inside(a, c, d, 1.0) for a, c in pairs]
            bounds: tuple[float, float] | None = None
            if any(n is not None and n < d + 2 for n in counts):
                status = StabilityStatus.UNSTABLE
            elif all(n == d + 2 for n in counts):
                status = StabilityStatus.STABLE
            else:
                status = StabilityStatus.UNRESOLVED
            if status is StabilityStatus.UNRESOLVED:
                brackets = [
                    (0.0, 0.0) if n == d + 2 else _unit_bracket(a, c, d)
                    for (a, c), n in zip(pairs, counts, strict=True)
                ]
                bounds = (max(b[0] for b in brackets), max(b[1] for b in brackets))
            elif radius:
                brackets = [_axis_radius_bounds(a, c, d) for a, c in pairs]
                bounds = (max(b[0] for b in brackets), max(b[1] for b in brackets))
            rho = math.nan if bounds is None else 0.5 * (bounds[0] + bounds[1])
            return PredictorStability(
                status is StabilityStatus.STABLE,
                StabilityMethod.AXIS_POLYNOMIAL,
                rho,
                tau_value,
                rate_value,
                status,
                bounds,
            )
    rho, bound = _lifted_radius_and_bound(f0, f1, d)
    bounds = (max(0.0, rho - bound), rho + bound)
    if bounds[1] < 1.0:
        status = StabilityStatus.STABLE
    elif bounds[0] >= 1.0:
        status = StabilityStatus.UNSTABLE
    else:
        status = StabilityStatus.UNRESOLVED
    return PredictorStability(
        status is StabilityStatus.STABLE, StabilityMethod.LIFTED, rho, tau_value, rate_value, status, bounds
    )


_AXES = tuple([i, 3 + i] for i in range(3))


def _continuous_stable(a0: np.ndarray, a1: np.ndarray, tau: float) -> bool:

    if not np.any(a1):
        return bool(np.all(np.linalg.eigvals(a0).real < 0.0))
    margin = delay_margin(a0, a1)
    return bool(margin.is_stable(tau)) if tau > 0.0 else margin.stable_without_delay


def _splits(f0: np.ndarray, f1: np.ndarray) -> bool:
    mask = np.zeros((STATE_SIZE, STATE_SIZE), dtype=bool)
    for ix in _AXES:
        mask[np.ix_(ix, ix)] = True
    return bool(not np.any(f0[~mask]) and not np.any(f1[~mask]))


def _lifted(f0: np.ndarray, f1: np.ndarray, d: int) -> np.ndarray:
    n = f0.shape[0]
    if d == 0:
        return f0 + f1
    size = n * (d + 1)
    lifted = np.zeros((size, size))
    lifted[:n, :n] = f0
    lifted[:n, n * d :] = f1
    lifted[n:, : n * d] = np.eye(n * d)
    return lifted


def lifted_spectral_radius(f0: Any, f1: Any, d: int) -> float:
    """Spectral radius of the lifted matrix of x̂_{k+1} = F₀ x̂_k + F₁ x̂_{k−d} (state [x̂_k; ...; x̂_{k−d}]).

    The block-companion matrix has size n (d + 1); for d = 0 it is F₀ + F₁. The value is LAPACK's
    (``numpy.linalg.eigvals``); its error bound is in [predictor_stability][mrpctl.predictor.predictor_stability].
    """
    f0 = np.asarray(f0, dtype=float)
    f1 = np.asarray(f1, dtype=float)
    d = integer("d", d, minimum=0)
    return float(np.max(np.abs(np.linalg.eigvals(_lifted(f0, f1, d)))))


def _lifted_radius_and_bound(f0: np.ndarray, f1: np.ndarray, d: int) -> tuple[float, float]:
    """(ρ, δ): the computed spectral radius of the lifted matrix M and a first-order error bound.

    LAPACK's QR algorithm returns the exact eigenvalues of M + E with ‖E‖_F <= p(N) u ‖M‖_F (backward
    stable; u = 2^-53, N the size; p(N) = N is taken). A simple eigenvalue λ with right and left
    eigenvectors x, y moves by at most κ(λ) ‖E‖₂ + O(‖E‖²) with κ(λ) = ‖x‖ ‖y‖ / |yᴴ x| (Wilkinson).
    δ = max over the eigenvalues of the largest moduli of 4 κ(λ) N u ‖M‖_F: first order only (a
    defective eigenvalue has κ = ∞ and gives δ = ∞, i.e. no claim).
    """

    m = _lifted(f0, f1, d)
    w, left, right = scipy.linalg.eig(m, left=True, right=True)
    moduli = np.abs(w)
    rho = float(np.max(moduli))
    size = m.shape[0]
    scale = 4.0 * size * np.finfo(float).eps / 2.0 * float(np.linalg.norm(m))
    near = moduli >= rho - 1e-3 * max(rho, 1.0)
    kappa = []
    for i in np.flatnonzero(near):
        x, y = right[:, i], left[:, i]
        overlap = abs(np.vdot(y, x))
        kappa.append(math.inf if overlap == 0.0 else float(np.linalg.norm(x) * np.linalg.norm(y) / overlap))
    return rho, max(kappa) * scale


def _axis_polynomial(f0: np.ndarray, f1: np.ndarray) -> tuple[np.ndarray, np.ndarray] | tuple[None, None]:
    """(a, c) with det(λ^{d+1} I − λ^d F₀ − F₁) = λ^d (λ^d a(λ) − c(λ)) for 2×2 blocks and rank F₁ <= 1.

    det(λ^d M − F₁) with M = λI − F₀ is λ^{2d} det M − λ^d c(λ) + det F₁, where
    c = M₀₀ F₁,₁₁ + M₁₁ F₁,₀₀ − M₀₁ F₁,₁₀ − M₁₀ F₁,₀₁ (degree 1) and a = det M (degree 2). F₁ = Φ^d ΔΓ K
    has rank <= 1, so det F₁ = 0: the nonzero roots solve λ^d a(λ) − c(λ) = 0 (degree d + 2); the d
    roots at 0 of the lifted matrix do not change its spectral radius. (None, None) if det F₁ ≠ 0.
    """
    a = np.array([1.0, -(f0[0, 0] + f0[1, 1]), f0[0, 0] * f0[1, 1] - f0[0, 1] * f0[1, 0]])
    m00 = np.array([1.0, -f0[0, 0]])
    m11 = np.array([1.0, -f0[1, 1]])
    c = m00 * f1[1, 1] + m11 * f1[0, 0] + np.array([0.0, f0[0, 1] * f1[1, 0] + f0[1, 0] * f1[0, 1]])
    det_f1 = f1[0, 0] * f1[1, 1] - f1[0, 1] * f1[1, 0]
    scale = max(1e-300, float(np.max(np.abs(f1))))
    if abs(det_f1) > 1e-12 * scale**2:
        return None, None
    return a, c


#: Total number of points the certified winding count may use on one circle before it gives up.
_MAX_WINDING_POINTS = 400_000
_UNIT_ROUNDOFF = np.finfo(float).eps / 2.0


def _count_inside(a: np.ndarray, c: np.ndarray, d: int, rho: float) -> int | None:
    """Number of roots of λ^d a(λ) − c(λ) in |λ| < ρ, certified, or None when it cannot be certified.

    The count is the winding number of f(θ) = a(λ) − c(λ) λ^{−d} + d (ρ >= 1; f = λ^d a(λ) − c(λ) for
    ρ < 1) around 0, λ = ρ e^{iθ}. It is certified, not only refined until it looks settled:

    * L bounds |df/dθ| on the circle (from the coefficients' moduli), ε bounds the rounding error of
      each computed value (16 (d + 2) u (Σ|a_i|ρ^i + Σ|c_i|ρ^i ρ^{∓d}): the phase d θ of λ^{∓d} is
      computed with absolute error below about 2π d u, the rest with a few u; u = 2^-53);
    * an arc [θ_i, θ_{i+1}] is accepted when L Δθ < |f_i| − ε: then the true f stays in a disc about
      f(θ_i) that excludes 0, its phase changes by less than π/2 along the arc and equals the
      principal argument of f_{i+1}/f_i; arcs that fail are halved (adaptive, only next to a root);
    * the computed steps differ from the true ones by at most 2 asin(ε/(|f| − ε)) at each end; the
      count is returned when that total is below π/2 (so rounding the sum to a multiple of 2π is exact).

    None when an arc cannot be accepted within [_MAX_WINDING_POINTS][mrpctl.predictor._MAX_WINDING_POINTS]
    points: a root lies within about ε/L of the circle.
    """
    mod_a, mod_c = np.abs(a), np.abs(c)
    eps_u = _UNIT_ROUNDOFF
    if rho >= 1.0:
        s = rho ** (-d)
        big_a = mod_a[0] * rho**2 + mod_a[1] * rho + mod_a[2]
        big_c = (mod_c[0] * rho + mod_c[1]) * s
        lipschitz = 2.0 * mod_a[0] * rho**2 + mod_a[1] * rho + mod_c[0] * rho * s + d * big_c
        offset = d
    else:
        s = rho**d
        big_a = (mod_a[0] * rho**2 + mod_a[1] * rho + mod_a[2]) * s
        big_c = mod_c[0] * rho + mod_c[1]
        lipschitz = (2.0 * mod_a[0] * rho**2 + mod_a[1] * rho) * s + d * big_a + mod_c[0] * rho
        offset = 0
    eps = 16.0 * (d + 2) * eps_u * (big_a + big_c)

    def values(theta: np.ndarray) -> np.ndarray:
        lam = rho * np.exp(1j * theta)
        if rho >= 1.0:
            return np.polyval(a, lam) - np.polyval(c, lam) * np.exp(-d * math.log(rho) - 1j * d * theta)
        return np.exp(d * math.log(rho) + 1j * d * theta) * np.polyval(a, lam) - np.polyval(c, lam)

    theta = np.linspace(0.0, 2.0 * np.pi, 16 * (d + 2) + 1)
    f = values(theta)
    if not np.all(np.isfinite(np.abs(f))):
        return None
    # Only the halves of the arcs that failed are tested again (an accepted arc keeps its ends and its
    # |f_i|, so it stays accepted); the open arcs are kept in the order of the circle, and the grid is
    # put together once at the end from the left ends of the accepted arcs and θ = 2π.
    points = theta.size
    kept_theta, kept_f = [theta[-1:]], [f[-1:]]
    left, right, f_left, f_right = theta[:-1], theta[1:], f[:-1], f[1:]
    while True:
        bad = lipschitz * (right - left) >= np.abs(f_left) - eps
        kept_theta.append(left[~bad])
        kept_f.append(f_left[~bad])
        if not np.any(bad):
            break
        count = int(bad.sum())
        if points + count > _MAX_WINDING_POINTS:
            return None
        points += count
        left, right, f_left, f_right = left[bad], right[bad], f_left[bad], f_right[bad]
        middle = 0.5 * (left + right)
        new = values(middle)
        if not np.all(np.isfinite(np.abs(new))):
            return None
        left, right = np.column_stack((left, middle)).ravel(), np.column_stack((middle, right)).ravel()
        f_left, f_right = np.column_stack((f_left, new)).ravel(), np.column_stack((new, f_right)).ravel()
    theta = np.concatenate(kept_theta)
    order = np.argsort(theta, kind="stable")
    f = np.concatenate(kept_f)[order]
    modulus = np.abs(f)
    phase_error = float(np.sum(2.0 * np.arcsin(np.minimum(1.0, eps / (modulus - eps)))))
    if phase_error >= 0.5 * np.pi:
        return None
    steps = np.angle(f[1:] / f[:-1])
    return offset + round(float(np.sum(steps)) / (2.0 * np.pi))


def _inside(a: np.ndarray, c: np.ndarray, d: int, rho: float) -> int:
    """[_count_inside][mrpctl.predictor._count_inside], −1 when it cannot be certified (the old interface)."""
    count = _count_inside(a, c, d, rho)
    return -1 if count is None else count


def _unit_bracket(a: np.ndarray, c: np.ndarray, d: int) -> tuple[float, float]:
    """(1 − δ, 1 + δ) with the largest |λ| inside, for the smallest δ = 1e-7 · 10^j (j <= 6) certified on both sides.

    Used when the count on |λ| = 1 itself cannot be certified: the largest root is then within δ of the
    circle (fewer than d + 2 roots certified in |λ| < 1 − δ, all in |λ| < 1 + δ).
    """
    low, high = 0.0, math.inf
    for j in range(7):
        delta = 1e-7 * 10.0**j
        if high == math.inf and _count_inside(a, c, d, 1.0 + delta) == d + 2:
            high = 1.0 + delta
        if low == 0.0:
            inner = _count_inside(a, c, d, 1.0 - delta)
            if inner is not None and inner < d + 2:
                low = 1.0 - delta
        if low > 0.0 and high < math.inf:
            break
    return low, high


def _axis_radius_bounds(a: np.ndarray, c: np.ndarray, d: int) -> tuple[float, float]:
    """(lo, hi) with the largest |λ| of λ^d a(λ) − c(λ) in [lo, hi], by bisection on certified counts.

    hi: a radius where all d + 2 roots are certified inside; lo: one where fewer are (or 0). The
    bisection stops at hi − lo <= 1e-12 hi, or when the counts next to the root cannot be certified
    (both quarter points tried); at most 200 steps.
    """
    coefficients = np.concatenate((a, np.zeros(d)))
    coefficients[-2:] -= c
    low, high = 0.0, 1.0 + float(np.max(np.abs(coefficients[1:])))  # Cauchy's bound
    full = d + 2
    for _ in range(_MAX_BISECTIONS):
        if high - low <= 1e-12 * high:
            break
        for middle in (0.5 * (low + high), 0.75 * low + 0.25 * high, 0.25 * low + 0.75 * high):
            count = _count_inside(a, c, d, middle) if middle > 0.0 else 0
            if count is not None:
                break
        else:
            break
        if count == full:
            high = middle
        else:
            low = middle
    return low, high


def _axis_spectral_radius(a: np.ndarray, c: np.ndarray, d: int) -> float:
    """Largest |λ| of λ^d a(λ) − c(λ): the upper end of [_axis_radius_bounds][mrpctl.predictor._axis_radius_bounds]."""
    return _axis_radius_bounds(a, c, d)[1]


# ============================================================================ margin
def perturbed_spacecraft(spacecraft: Spacecraft, e: float, axis: int | None = None) -> Spacecraft:
    """The plant with relative inertia error e against the model J: J_plant = (1 + e) J_model, or S J S with
    S = I + (√(1 + e) − 1) e_i e_iᵀ on axis i (the one convention of ``inertia_error`` in mrpctl)."""
    model = check_spacecraft(spacecraft, "spacecraft")
    e = finite_scalar("e", e)
    if e <= -1.0:
        raise SpecificationError(f"e (relative inertia error) must be > -1, got {e}")
    if axis is None:
        matrix = (1.0 + e) * model.inertia
    else:
        axis = integer("axis", axis, minimum=0, maximum=2)
        s = np.eye(3)
        s[axis, axis] = math.sqrt(1.0 + e)
        matrix = s @ model.inertia @ s
    with warnings.catch_warnings():
        # A hypothetical plant of a robustness study may break the triangle inequality: not an error here.
        warnings.simplefilter("ignore", InertiaWarning)
        return Spacecraft(matrix)


def _side_bracket(stable: Callable[[float], bool], sign: float, end: float, rtol: float) -> tuple[float, float, bool]:
    """(good, bad, capped): scan |e| geometrically from 1e-3 to ``end``, bisect the first [stable, not stable] pair.

    ``good`` is the last |e| shown stable, ``bad`` the first not shown stable beyond it (``bad - good <=
    rtol bad``, or 200 bisections: the search always terminates); capped: stable up to ``end`` (bad = end).
    Both are signed.
    """
    good = 0.0
    magnitude = _SCAN_START
    while True:
        magnitude = min(magnitude, end)
        if not stable(sign * magnitude):
            bad = magnitude
            break
        good = magnitude
        if magnitude >= end:
            return sign * end, sign * end, True
        magnitude *= _SCAN_RATIO
    for _ in range(_MAX_BISECTIONS):
        if bad - good <= rtol * bad:
            break
        middle = 0.5 * (good + bad)
        if stable(sign * middle):
            good = middle
        else:
            bad = middle
    return sign * good, sign * bad, False


def margin_side(stable: Callable[[float], bool], sign: float, end: float, rtol: float) -> tuple[float, bool]:
    """Scan |e| geometrically from 1e-3 to ``end``; bisect the first [stable, unstable] pair to ``rtol``."""
    good, _, capped = _side_bracket(stable, sign, end, rtol)
    return good, capped


def margin_side_bracket(
    stable: Callable[[float], bool], sign: float, end: float, rtol: float
) -> tuple[float, float, bool]:
    """[`margin_side`][mrpctl.predictor.analysis.margin_side] with its bracket: (stable, not shown stable, capped).

    The stability boundary lies between the two signed e (relative width ``rtol``); both are ``sign * end``
    when capped (stable up to the search limit).
    """
    return _side_bracket(stable, sign, end, rtol)


def inertia_mismatch_margin(
    spacecraft: Spacecraft,
    K: Any,
    tau: float,
    *,
    rate: float | None = 1000.0,
    per_axis: bool = True,
    rtol: float = 1e-3,
    e_max: float = 10.0,
) -> MismatchMargin:
    """The largest relative inertia errors (J_plant = (1 + e) J_model, both signs) that keep K stable.

    The predictor uses the model ``spacecraft``; the plant's inertia is perturbed uniformly and, when
    ``per_axis``, on one axis at a time. On each side |e| is scanned geometrically (ratio 1.25) from
    1e-3 to the search limit (``e_max`` above, J_plant = 1e-3 J_model below) with the exact test of
    [`predictor_stability`][mrpctl.predictor.predictor_stability], and the first [stable, unstable] pair is
    bisected to relative width ``rtol``: the search always terminates (at most ~50 + 200 tests per side).
    "Stable" means shown stable (status STABLE): an UNRESOLVED test counts as not stable, so each end is a
    shown-stable e,
    and each end's bracket (``lower_bracket``, ``upper_bracket``) is the final [stable, not stable]
    pair, with ``*_unresolved`` set when its outer e was unresolved rather than unstable. A stable island
    narrower than one scan step beyond the first instability is not reported (the answer is the
    interval around 0).

    Parameters
    ----------
    spacecraft : Spacecraft
        The controller's model J_m (kg m²).
    K : array_like
        (3, 6) gain on x = [σ; ω/4] (N m).
    tau : float
        Delay τ (s), a whole number of samples at ``rate``.
    rate : float or None, keyword-only
        Measurement rate (Hz), default 1000; None analyses the continuous loop.
    per_axis : bool, keyword-only
        Also give the margin of each axis alone.
    rtol : float, keyword-only
        Relative width of the final brackets (default 1e-3).
    e_max : float, keyword-only
        Upper search limit for e (default 10, J_plant = 11 J_model).

    Returns
    -------
    MismatchMargin

    Raises
    ------
    SpecificationError
        If the loop is unstable at e = 0 (no margin to speak of), or an argument is invalid.
    """
    model, gain, tau_value, _ = _inputs(spacecraft, K, tau, None)
    if not isinstance(per_axis, bool):
        raise SpecificationError(f"per_axis must be True or False, got {per_axis!r}")
    rtol = positive_scalar("rtol", rtol)
    e_max = positive_scalar("e_max", e_max)
    if rate is not None:
        _check_margin_memory(delay_samples(tau_value, rate), rate)
    evaluations = 0
    cache: dict[tuple[bytes, float], StabilityStatus] = {}

    def status_at(e: float, axis: int | None) -> StabilityStatus:
        nonlocal evaluations
        plant = perturbed_spacecraft(model, e, axis)
        key = (plant.inertia.tobytes(), e)
        if key not in cache:
            evaluations += 1
            status = predictor_stability(model, gain, tau_value, plant=plant, rate=rate).status
            cache[key] = StabilityStatus.UNSTABLE if status is None else status
        return cache[key]

    def stable_at(e: float, axis: int | None) -> bool:
        return status_at(e, axis) is StabilityStatus.STABLE

    if not predictor_stability(model, gain, tau_value, rate=rate).stable:
        raise SpecificationError(
            f"K is not stable with the predictor even with an exact model (tau = {tau_value:g} s): "
            "the delay-free loop A + B K must be stable; choose stabilising gains first"
        )

    def interval(axis: int | None) -> MarginInterval:
        upper, upper_out, upper_capped = _side_bracket(lambda e: stable_at(e, axis), 1.0, e_max, rtol)
        lower, lower_out, lower_capped = _side_bracket(lambda e: stable_at(e, axis), -1.0, _NEGATIVE_END, rtol)
        unresolved = StabilityStatus.UNRESOLVED
        return MarginInterval(
            lower,
            upper,
            lower_capped,
            upper_capped,
            (lower, lower_out),
            (upper, upper_out),
            not lower_capped and status_at(lower_out, axis) is unresolved,
            not upper_capped and status_at(upper_out, axis) is unresolved,
        )

    uniform = interval(None)
    axes: tuple[MarginInterval, ...] = ()
    if per_axis:
        k1, k2 = pd_from_gain(model, gain)
        if model.is_diagonal and _is_diag(k1) and _is_diag(k2):
            # Decoupled: axis i alone perturbs only its own 2x2 loop; identical axes share the answer.
            seen: dict[tuple[float, float], MarginInterval] = {}
            found = []
            for i in range(3):
                key = (float(k1[i, i]), float(k2[i, i]))
                if key not in seen:
                    seen[key] = interval(i)
                found.append(seen[key])
            axes = tuple(found)
        else:
            axes = tuple(interval(i) for i in range(3))
    return MismatchMargin(uniform, axes, tau_value, None if rate is None else float(rate), evaluations)


def _check_margin_memory(d: int, rate: Any) -> None:
    """Refuse up front a margin search whose exact tests cannot fit in memory (estimated, a lower bound).

    Each test of a split loop evaluates the axis polynomial of degree d + 2 on a grid of at least
    16 (d + 2) points of the unit circle (complex values and their phases: >= 32 bytes a point); the
    lifted test of an unsplit loop needs a matrix of 6 (d + 1) squared doubles, more still.
    """
    estimate = 32.0 * 16 * (d + 2)
    available = available_memory()
    if available is None:
        return
    if estimate > 0.5 * available:
        raise SpecificationError(
            f"rate: tau * rate = {d} delay samples; each exact stability test of the margin search needs at "
            f"least {estimate / 1e9:.3g} GB (half of the {available / 1e9:.3g} GB available is the limit): use a "
            "lower rate, or rate=None for the continuous loop"
        )


def _is_diag(m: np.ndarray) -> bool:
    return bool(np.all(m == np.diag(np.diag(m))))


# ============================================================================ design
def synthesize_predictor_pd(
    spacecraft: Spacecraft,
    tau: float,
    *,
    mismatch: float = 0.1,
    zeta: float = 1.0,
    rate: float | None = 1000.0,
    rtol: float = 1e-3,
) -> PredictorDesign:
    """The fastest PD gains (largest ωₙ at ζ) whose predictor loop keeps a ± ``mismatch`` inertia margin.

    The requirement is tested exactly ([`predictor_stability`][mrpctl.predictor.predictor_stability]) at e = ±m j/10, j
    = 1..10,
    uniform and per axis (the uniform test covers the axes when J_m is diagonal: the loop then splits
    and the uniform error is stable exactly when each axis loop is). ωₙ is doubled from
    0.05/τ until the requirement fails (at most 40 doublings) and the bracket is bisected to ``rtol``.
    The returned ωₙ is the requirement-keeping side of the final bracket.

    Parameters
    ----------
    spacecraft : Spacecraft
        The controller's model J_m (kg m²); the gains are K = [4 J_m K₁, 4 J_m K₂].
    tau : float
        Delay τ > 0 (s).
    mismatch : float, keyword-only
        Required relative inertia error m in (0, 1) that must stay stable on both sides, e = ±m with
        J_plant = (1 + e) J_model (default 0.1).
    zeta : float, keyword-only
        Damping ratio ζ > 0 (default 1).
    rate : float or None, keyword-only
        Measurement rate (Hz), default 1000; None designs for the continuous loop.
    rtol : float, keyword-only
        Relative width of the final ωₙ bracket.

    Returns
    -------
    PredictorDesign

    Raises
    ------
    SpecificationError
        On invalid input, or when no ωₙ down to 0.05/τ keeps the margin.
    """

    model = check_spacecraft(spacecraft, "spacecraft")
    tau_value = positive_scalar("tau", tau)
    m = positive_scalar("mismatch", mismatch)
    if m >= 1.0:
        raise SpecificationError(f"mismatch must be < 1 (a relative inertia error), got {m}")
    zeta = positive_scalar("zeta", zeta)
    rtol = positive_scalar("rtol", rtol)
    if rate is not None:
        delay_samples(tau_value, rate)

    # Decoupled axes: the uniform error is stable iff every axis loop is, which covers each axis alone.
    axes: list[int | None] = [None] if model.is_diagonal else [None, 0, 1, 2]

    def gain(omega_n: float) -> np.ndarray:
        return pd_gains(model, zeta=zeta, omega_n=omega_n, allow_underdamped=True).K

    def keeps(omega_n: float) -> bool:
        k = gain(omega_n)
        if not predictor_stability(model, k, tau_value, rate=rate).stable:
            return False
        grid = [m * j / _DESIGN_GRID for j in range(1, _DESIGN_GRID + 1)]
        for e in grid:
            for sign in (1.0, -1.0):
                for axis in axes:
                    plant = perturbed_spacecraft(model, sign * e, axis)
                    if not predictor_stability(model, k, tau_value, plant=plant, rate=rate).stable:
                        return False
        return True

    good = 0.05 / tau_value
    if not keeps(good):
        raise SpecificationError(
            f"no omega_n down to {good:.4g} rad/s keeps a +/-{m:.2%} inertia margin at tau = {tau_value:g} s"
        )
    bad = good
    for _ in range(40):
        bad *= 2.0
        if not keeps(bad):
            break
        good = bad
    else:
        raise SpecificationError(f"the margin is kept up to omega_n = {bad:.4g} rad/s: no finite fastest gain")
    for _ in range(_MAX_BISECTIONS):
        if bad - good <= rtol * bad:
            break
        middle = 0.5 * (good + bad)
        if keeps(middle):
            good = middle
        else:
            bad = middle
    k = gain(good)
    margin = inertia_mismatch_margin(model, k, tau_value, rate=rate, rtol=rtol)
    return PredictorDesign(readonly(k), good, zeta, m, margin)
