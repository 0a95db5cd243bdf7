"""A certified region of attraction of the delayed loop with a saturated torque: an ellipsoid in (σ, ω).

The loop is the linearised one of [`mrpctl.design.lmi`][mrpctl.design.lmi] with the actuator's limit on the
delayed command (``design/wheels.md``, "Design for the actuator"):

    ẋ = A x + B sat(K x(t − τ)),   A = [[0, I], [0, 0]],  B = [0; J⁻¹/4],  x = [σ; ω/4],

and a history constant at x0 (the simulator's ``history="constant"``). With the dead zone
ψ = v − sat(v), v = K x(t − τ), the loop is ẋ = A x + BK x(t − τ) − Bψ. The generalised sector
condition (Tarbouriech, Garcia, Gomes da Silva & Queinnec, *Stability and Stabilization of Linear
Systems with Saturating Actuators*, Springer 2011, Lemma 1.6): if |G x(t − τ)| <= U then
ψᵀ t (ψ − (K − G) x(t − τ)) <= 0 for a scalar t > 0. U is the inscribed ball of the actuator's
limits (min(min u_max,i, u_norm)): the condition then holds for the direction-preserving scaling
(the scaled vector is at least U long when it is scaled) and for the per-axis clip (term by term).

With the Jensen functional V = xᵀPx + ∫_{t−τ}^{t} xᵀSx + τ∫_{−τ}^{0}∫_{t+θ}^{t} ẋᵀRẋ and
ζ = [x; x(t − τ); ψ], F = [A, BK, −B], the S-procedure gives V̇ <= ζᵀ(Φ₀ + τ²FᵀRF)ζ < 0 with

    Φ₀ = He(E₁ᵀ P F) + E₁ᵀSE₁ − E₂ᵀSE₂ − (E₁ − E₂)ᵀR(E₁ − E₂) − He(E₃ᵀ(t E₃ − (tK − Z) E₂)),   Z = t G,

wherever the sector condition holds; it holds along every trajectory that starts with V <= 1 when
[[P, Zᵀ], [Z, t² U² I]] ⪰ 0 (x(t − τ)ᵀ P x(t − τ) <= V <= 1, and the history is x0 with
x0ᵀ P x0 <= V(0)). V(0) = x0ᵀ(P + τS)x0 for the constant history, so the certified set of initial
states is the ellipsoid E = {x0 : x0ᵀ(P + τS)x0 <= c}. The LMI is solved in normalised time
(unit delay) and scaled coordinates, for a grid of t (the problem is convex for a fixed t),
maximising E against a reference shape; the float64 recomputation of the blocks decides, and the
level c is shrunk below 1 if the recomputed domain block asks for it.

What it covers: the linearised rigid body (σ̇ = ω/4, J ω̇ = u), a constant delay τ in continuous
time, the torque limit; not the MRP kinematics' nonlinearity, the gyroscopic torque, the sample and
hold, or noise (the simulation test checks the nonlinear compiled loop on the boundary of E).
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mrpctl._validation import positive_scalar
from mrpctl.design._common import solve
from mrpctl.errors import SpecificationError
from mrpctl.flight.models import ActuatorModel
from mrpctl.flight.steering import SteeringLaw
from mrpctl.model import gain_matrix
from mrpctl.spacecraft import Spacecraft, check_spacecraft

__all__ = ["AttractionRegion", "AttractionStatus", "attraction_blocks", "certify_attraction", "linear_radius"]

_MARGIN_TOL = 1e-9
_EPSILON = 1e-7
#: The centring solve accepts an ellipsoid this much smaller (in γ) than the optimum, for its margins.
_BACK_OFF = 1.05


class AttractionStatus(enum.Enum):
    """Outcome of [`certify_attraction`][mrpctl.design.attraction.certify_attraction]."""

    CERTIFIED = "certified"
    NOT_CERTIFIED = "not certified"
    SOLVER_FAILED = "solver failed"


@dataclass(frozen=True)
class AttractionRegion:
    """Result of [`certify_attraction`][mrpctl.design.attraction.certify_attraction].

    Attributes
    ----------
    status : AttractionStatus
        CERTIFIED only when the solver said ``optimal`` and the float64 recomputation of every block
        keeps a relative margin of at least 1e-9.
    tau : float
    torque : float
        U (N m), the inscribed ball of the actuator's limits the sector condition uses.
    matrix : numpy.ndarray or None
        (6, 6) M = P + τS on x = [σ; ω/4]: the ellipsoid E = {x : xᵀ M x <= level}.
    level : float
        c (<= 1).
    P : numpy.ndarray or None
        (6, 6) the functional's P on x (x(t − τ)ᵀ P x(t − τ) <= c along the certified runs).
    multiplier : float
        The sector condition's scalar t.
    max_angle : float
        The largest principal angle (rad) from the target certified for every axis at rest.
    max_rate : float
        The largest rate (rad/s) certified for every axis at the target attitude.
    steering_covered : bool or None
        With a steering law: True when the law equals K on the whole of {xᵀPx <= c} (its rate limit
        is not reached there), so that the certificate holds for the steering law too.
    solver_status : str
    margins : tuple of (str, float)
        The recomputed relative margins of the blocks.
    reason : str
    """

    status: AttractionStatus
    tau: float
    torque: float
    matrix: np.ndarray | None = field(repr=False)
    level: float
    P: np.ndarray | None = field(repr=False)
    multiplier: float
    max_angle: float
    max_rate: float
    steering_covered: bool | None
    solver_status: str
    margins: tuple[tuple[str, float], ...]
    reason: str

    @property
    def certified(self) -> bool:
        """True when the ellipsoid is certified."""
        return self.status is AttractionStatus.CERTIFIED

    def contains(self, x: Any) -> np.ndarray:
        """Whether the states x ((6,) or (N, 6), x = [σ; ω/4]) are in the certified ellipsoid."""
        if self.matrix is None:
            raise SpecificationError("contains: no ellipsoid was certified")
        rows = np.atleast_2d(np.asarray(x, dtype=float))
        return np.einsum("ni,ij,nj->n", rows, self.matrix, rows) <= self.level

    def __str__(self) -> str:
        head = (
            f"Region of attraction (Jensen functional, sector condition, tau = {self.tau:g} s, U = {self.torque:g} N m)"
        )
        if not self.certified:
            return f"{head}: {self.status.value} (solver: {self.solver_status})\n  {self.reason}"
        covered = (
            ""
            if self.steering_covered is None
            else "\n  steering law covered: "
            + ("yes" if self.steering_covered else "no (its rate limit is reached inside)")
        )
        return (
            f"{head}: certified\n  every axis at rest within {math.degrees(self.max_angle):.4g} deg of the target, "
            f"or at the target with |omega| <= {self.max_rate:.4g} rad/s (ellipsoid x^T M x <= {self.level:.4g})"
            f"{covered}\n  {self.reason}"
        )


def attraction_blocks(
    a: np.ndarray, b: np.ndarray, k: np.ndarray, tau: float, P: Any, S: Any, R: Any, Z: Any, t: float, u: float
) -> dict[str, Any]:
    """The LMI's blocks (module docstring) at delay τ for ẋ = a x + b sat(k x(t − τ)) with |sat| limit u:
    ``derivative`` Φ₀ + τ²FᵀRF (negative definite), ``domain`` [[P, Zᵀ], [Z, t²u² I]] (semidefinite),
    and S, R, P (positive definite). NumPy arrays in, NumPy out; cvxpy expressions in, expressions out."""
    n, m = a.shape[0], b.shape[1]
    e1 = np.hstack((np.eye(n), np.zeros((n, n + m))))
    e2 = np.hstack((np.zeros((n, n)), np.eye(n), np.zeros((n, m))))
    e3 = np.hstack((np.zeros((m, 2 * n)), np.eye(m)))
    f = np.hstack((a, b @ k, -b))
    e0 = e1 - e2

    def he(x: Any) -> Any:
        return x + x.T

    sector = e3.T @ (t * e3 - (t * k - Z) @ e2)
    phi0 = he(e1.T @ P @ f) + e1.T @ S @ e1 - e2.T @ S @ e2 - e0.T @ R @ e0 - he(sector)
    numeric = isinstance(P, np.ndarray)
    if numeric:
        derivative = phi0 + tau**2 * f.T @ R @ f
        domain = np.block([[P, Z.T], [Z, t * t * u * u * np.eye(m)]])
    else:
        # deferred: cvxpy, only when an LMI is solved
        import cvxpy as cp

        derivative = cp.bmat([[phi0, tau * f.T @ R], [tau * R @ f, -R]])  # Schur form of the τ² term
        domain = cp.bmat([[P, Z.T], [Z, t * t * u * u * np.eye(m)]])
    return {"derivative": derivative, "domain": domain, "S": S, "R": R, "P": P}


def certify_attraction(
    spacecraft: Spacecraft,
    K: Any,
    tau: float,
    actuator: ActuatorModel,
    *,
    angle_scale: float = math.pi,
    rate_scale: float = 0.05,
    law: SteeringLaw | None = None,
    multipliers: int = 17,
) -> AttractionRegion:
    """The certified ellipsoid of initial states (constant history) of the delayed saturated loop.

    Parameters
    ----------
    spacecraft : Spacecraft
    K : array_like
        (3, 6) gains on x = [σ; ω/4] (N m): the PD law (or the steering law's K).
    tau : float
        The delay τ > 0 (s).
    actuator : mrpctl.flight.ActuatorModel
        The torque limits (the sector condition uses the inscribed ball U).
    angle_scale, rate_scale : float, keyword-only
        The reference shape the ellipsoid is maximised against: principal angle (rad) and rate
        (rad/s) weighted as equals (defaults π and 0.05 rad/s).
    law : SteeringLaw, keyword-only
        A steering law with the same K: the LMI then also keeps {xᵀPx <= 1} inside the attitudes where
        the law is K (|σ| <= s_K, `linear_radius`), so that the certificate covers the steering law
        (``steering_covered``, rechecked on the result).
    multipliers : int, keyword-only
        Number of values of the sector multiplier t tried (a log grid, then refined).

    Returns
    -------
    AttractionRegion
        NOT_CERTIFIED or SOLVER_FAILED (with the solver's status) when no t gives a certificate.
    """
    # deferred: cvxpy (about 1 s to import), only when the LMI is solved
    import cvxpy as cp

    spacecraft = check_spacecraft(spacecraft)
    gain = gain_matrix(K)
    tau = positive_scalar("tau", tau)
    angle_scale = positive_scalar("angle_scale", angle_scale)
    rate_scale = positive_scalar("rate_scale", rate_scale)
    if not isinstance(actuator, ActuatorModel):
        raise SpecificationError(f"actuator must be a mrpctl.flight.ActuatorModel, got {actuator!r}")
    u0 = min(float(np.min(actuator.u_max)), actuator.norm_limit)
    n = 6
    a = np.zeros((n, n))
    a[0:3, 3:6] = np.eye(3)
    b = np.vstack((np.zeros((3, 3)), spacecraft.inertia_inverse / 4.0))
    # scaled coordinates x = D y (σ where the σ term alone saturates, ω/4 where the rate term does),
    # normalised time t' = t/τ and torque in units of U: every number near one
    d1 = u0 / max(float(np.linalg.norm(gain[:, 0:3], 2)), 1e-300)
    d2 = u0 / max(float(np.linalg.norm(gain[:, 3:6], 2)), 1e-300)
    scale = np.diag([d1] * 3 + [d2] * 3)
    inv = np.linalg.inv(scale)
    a_y = tau * inv @ a @ scale
    b_y = tau * inv @ b * u0
    k_y = gain @ scale / u0
    sigma_ref = math.tan(angle_scale / 4.0)
    weight = np.diag([1.0 / sigma_ref**2] * 3 + [16.0 / rate_scale**2] * 3)
    weight_y = scale @ weight @ scale

    P = cp.Variable((n, n), symmetric=True)
    S = cp.Variable((n, n), symmetric=True)
    R = cp.Variable((n, n), symmetric=True)
    Z = cp.Variable((3, n))
    gamma = cp.Variable()
    mu = cp.Variable()

    linear_zone: list[Any] = []
    if law is not None:  # {yᵀ P y <= 1} inside |σ| <= 0.99 s_K: [[P, E_σᵀ], [E_σ, (0.99 s_K / d1)² I]] ⪰ 0
        radius = 0.99 * linear_radius(law, gain) / d1
        selector = np.hstack((np.eye(3), np.zeros((3, 3))))
        linear_zone.append(cp.bmat([[P, selector.T], [selector, radius**2 * np.eye(3)]]) >> 0)

    def attempt(t: float, bound: float | None = None) -> tuple[Any, ...]:
        """min γ at the multiplier t; with ``bound`` the centring solve: the largest common margin μ of the
        strict blocks with γ <= bound (a certificate the float64 recomputation can confirm)."""
        blocks = attraction_blocks(a_y, b_y, k_y, 1.0, P, S, R, Z, t, 1.0)
        size = blocks["derivative"].shape[0]
        margin = _EPSILON if bound is None else mu
        constraints = [
            *linear_zone,
            blocks["derivative"] << -margin * np.eye(size),
            blocks["domain"] >> 0,
            S >> margin * np.eye(n),
            R >> margin * np.eye(n),
            P >> margin * np.eye(n),
            P + S << gamma * weight_y,
        ]
        if bound is None:
            problem = cp.Problem(cp.Minimize(gamma), constraints)
        else:
            problem = cp.Problem(cp.Maximize(mu), [*constraints, gamma <= bound, mu <= 1.0])
        outcome = solve(problem)
        if not outcome.optimal:
            return math.inf, outcome.status if not outcome.error else outcome.error, None
        values = tuple(np.asarray(v.value, dtype=float) for v in (P, S, R, Z))
        return float(np.asarray(gamma.value)), outcome.status, values

    grid = np.logspace(-4, 4, max(int(multipliers), 3))
    tried = [(t, *attempt(float(t))) for t in grid]
    best = min(tried, key=lambda item: item[1])
    if math.isfinite(best[1]):  # refine around the best t of the grid (golden section in log t)
        step = float(np.log(grid[1] / grid[0]))
        low, high = math.log(best[0]) - step, math.log(best[0]) + step
        ratio = (math.sqrt(5.0) - 1.0) / 2.0
        for _ in range(5):
            m1, m2 = high - ratio * (high - low), low + ratio * (high - low)
            r1, r2 = attempt(math.exp(m1)), attempt(math.exp(m2))
            tried += [(math.exp(m1), *r1), (math.exp(m2), *r2)]
            if r1[0] <= r2[0]:
                high = m2
            else:
                low = m1
        best = min(tried, key=lambda item: item[1])
    statuses = sorted({str(item[2]) for item in tried})
    if not math.isfinite(best[1]):
        failed = all(item[2] not in ("infeasible", "infeasible_inaccurate", "optimal_inaccurate") for item in tried)
        status = AttractionStatus.SOLVER_FAILED if failed else AttractionStatus.NOT_CERTIFIED
        return _empty(
            status,
            tau,
            u0,
            ", ".join(statuses),
            f"no multiplier t in [1e-4, 1e4] gave a solution ({len(tried)} solves)",
        )
    t_best, gamma_best = best[0], best[1]
    centred = attempt(t_best, _BACK_OFF * gamma_best)
    t_best, _, solver_status, values = (t_best, *centred) if centred[2] is not None else best
    p_y, s_y, r_y, z_y = values
    numeric = attraction_blocks(a_y, b_y, k_y, 1.0, p_y, s_y, r_y, z_y, t_best, 1.0)
    margins = []
    for name, block in numeric.items():
        sym = (block + block.T) / 2.0
        eigenvalues = np.linalg.eigvalsh(-sym if name == "derivative" else sym)
        margins.append((name, float(eigenvalues[0] / max(np.linalg.norm(sym, 2), 1e-300))))
    strict = [m for name, m in margins if name != "domain"]
    if min(strict) < _MARGIN_TOL:
        failing = min((m for m in margins if m[0] != "domain"), key=lambda m: m[1])
        return _empty(
            AttractionStatus.NOT_CERTIFIED,
            tau,
            u0,
            str(solver_status),
            f"the float64 recomputation fails block {failing[0]} (relative margin {failing[1]:.3g})",
            tuple(margins),
        )
    # the domain: |G y| <= 1 on {yᵀ P y <= c} with G = Z/t exactly: c = 1/λ_max(P^{-1/2} GᵀG P^{-1/2}) capped at 1
    g = z_y / t_best
    root = np.linalg.cholesky(p_y)
    inner = np.linalg.solve(root, g.T)
    level = min(1.0, 1.0 / float(np.linalg.eigvalsh(inner.T @ inner)[-1]))
    matrix = inv.T @ (p_y + s_y) @ inv  # V(0) in x: x0ᵀ (P + τS) x0 (unit delay in y: P + S)
    p_x = inv.T @ p_y @ inv
    matrix, p_x = (matrix + matrix.T) / 2.0, (p_x + p_x.T) / 2.0
    max_sigma = math.sqrt(level / float(np.linalg.eigvalsh(matrix[0:3, 0:3])[-1]))
    max_rate = 4.0 * math.sqrt(level / float(np.linalg.eigvalsh(matrix[3:6, 3:6])[-1]))
    covered = None if law is None else _steering_covered(law, gain, p_x, level)
    return AttractionRegion(
        status=AttractionStatus.CERTIFIED,
        tau=tau,
        torque=u0,
        matrix=_readonly(matrix),
        level=level,
        P=_readonly(p_x),
        multiplier=t_best,
        max_angle=4.0 * math.atan(max_sigma),
        max_rate=max_rate,
        steering_covered=covered,
        solver_status=str(solver_status),
        margins=tuple(margins),
        reason=(
            f"best of {len(tried)} solves at t = {t_best:.4g} (statuses {', '.join(statuses)}); covers the linearised "
            "body with a constant delay in continuous time, not the MRP kinematics' nonlinearity, the gyroscopic "
            "torque or the sample and hold"
        ),
    )


def linear_radius(law: SteeringLaw, K: Any) -> float:
    """s_K: the largest |σ| up to which the steering law ``law`` is K (its rate limit, and its momentum limit
    when it has one, not reached), by the sufficient test of ``steering_covered`` (bisection to 1e-6
    relative); inf when it never is reached."""
    gain = gain_matrix(K)
    matrix = 4.0 * np.linalg.solve(gain[:, 3:6], gain[:, 0:3])
    rate_map = float(np.linalg.norm(matrix, 2))
    momentum_map = _momentum_map(law, matrix)

    def linear(s: float) -> bool:
        phi = 4.0 * math.atan(s)
        below = law.momentum_limit is None or momentum_map * s <= law.momentum_limit
        return below and rate_map <= law.rate_command_limit(phi) / phi * 4.0 / (1.0 + s * s)

    low, high = 0.0, 1.0
    if linear(high):
        return math.inf
    while high - low > 1e-6 * high:
        middle = (low + high) / 2.0
        low, high = (middle, high) if linear(middle) else (low, middle)
    return low


def _steering_covered(law: SteeringLaw, gain: np.ndarray, p_x: np.ndarray, level: float) -> bool:
    """True when |ω_lin| <= L(φ) on {xᵀPx <= c}: the steering law is K there (a sufficient test: the
    largest |ω_lin| against L at the largest angle's lower envelope, checked on the σ-projection)."""
    # the σ-projection of {xᵀPx <= c} is {σᵀ Q⁻¹ σ <= c} with Q the σσ block of P⁻¹
    q = np.linalg.inv(p_x)[0:3, 0:3]
    rate_map = 4.0 * np.linalg.solve(gain[:, 3:6], gain[:, 0:3])  # ω_lin = −rate_map σ
    # |ω_lin| <= L(φ) for all σ in the projection: L is concave increasing with L(φ) >= L(φ_max) φ/φ_max for
    # φ <= φ_max, and φ = 4 atan|σ| >= 4|σ|/(1 + |σ|²)... use the sufficient bound |ω_lin| <= ‖rate_map‖ |σ|
    # against the chord of L through the origin and (φ_max, L(φ_max)), with φ >= 4|σ|/(1 + s²) on |σ| <= s
    s = math.sqrt(level * float(np.linalg.eigvalsh(q)[-1]))
    phi_max = 4.0 * math.atan(s)
    if phi_max == 0.0:
        return True
    chord = law.rate_command_limit(phi_max) / phi_max  # L(φ) >= chord φ on [0, φ_max]
    # with a momentum limit h also |J ω_lin| <= ‖J rate_map‖ |σ| <= h
    if law.momentum_limit is not None and _momentum_map(law, rate_map) * s > law.momentum_limit:
        return False
    return float(np.linalg.norm(rate_map, 2)) <= chord * 4.0 / (1.0 + s * s)


def _momentum_map(law: SteeringLaw, rate_map: np.ndarray) -> float:
    """‖J rate_map‖₂: |J ω_lin| per unit |σ| (0 without the law's momentum limit)."""
    if law.spacecraft is None:
        return 0.0
    return float(np.linalg.norm(law.spacecraft.inertia @ rate_map, 2))


def _readonly(array: np.ndarray) -> np.ndarray:
    out = np.array(array, dtype=float)
    out.setflags(write=False)
    return out


def _empty(
    status: AttractionStatus,
    tau: float,
    u0: float,
    solver_status: str,
    reason: str,
    margins: tuple[tuple[str, float], ...] = (),
) -> AttractionRegion:
    return AttractionRegion(
        status=status,
        tau=tau,
        torque=u0,
        matrix=None,
        level=0.0,
        P=None,
        multiplier=math.nan,
        max_angle=0.0,
        max_rate=0.0,
        steering_covered=None,
        solver_status=solver_status,
        margins=margins,
        reason=reason,
    )
