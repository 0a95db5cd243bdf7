"""The plant as CasADi expressions: the only place the attitude dynamics are written.

State x = [σ; ω/4] ∈ R⁶ (paper Eq. 6), torque input u ∈ R³ (N m):

    ẋ = A x + B u + f(x)                                 (paper Eqs. 6-7)
    σ̇ = ¼ B(σ) ω,    J ω̇ = −ω × J ω + u                   (paper Eq. 3)

with A = [[0, I₃], [0, 0]], B = [0; ¼ J⁻¹] and
f(x) = [(B(x₁) − I₃) x₂; −4 J⁻¹ [x₂×] J x₂].

The direct form (σ̇, ω̇) is written once here; f is derived from it as
f(x) = ẋ(x, 0) − A x, so the split and the dynamics cannot disagree.

The gain convention (see ``design/conventions.md``): u = K x with
K = [4 J K₁, 4 J K₂] ∈ R³ˣ⁶, so that B K = [[0, 0], [K₁, K₂]] and the linearised
loop is σ̈ = K₁ σ + K₂ σ̇ (paper Eq. pd_design).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from mrpctl._validation import readonly
from mrpctl.conventions import feedback_gain, gain_from_pd, pd_from_gain, state, state_parts
from mrpctl.errors import SpecificationError
from mrpctl.mrp import add_expr, b_matrix_expr, dcm_expr, skew_expr, subtract_expr
from mrpctl.spacecraft import Spacecraft, check_spacecraft
from mrpctl.wheels import WheelCluster

__all__ = [
    "INPUT_SIZE",
    "ORBIT_SIZE",
    "STATE_SIZE",
    "PlantModel",
    "dynamics_expr",
    "gain_from_pd",
    "gain_matrix",
    "gravity_gradient_expr",
    "linear_matrices",
    "orbit_phase_expr",
    "orbit_position_expr",
    "orbit_turn_expr",
    "pd_from_gain",
    "plant_model",
    "state",
    "state_parts",
    "tracking_error_dynamics_expr",
    "wheel_body_rate_expr",
    "wheel_dynamics_expr",
    "wheel_hub_inertia",
    "wheel_momenta_expr",
    "wheel_momentum_dynamics_expr",
    "wheel_speeds_expr",
]

STATE_SIZE = 6
INPUT_SIZE = 3
#: A circular orbit as the run-time constants of a compiled sample: (n, u₀, ê₁ (3), ê₂ (3), cos δ, sin δ) with δ
#: the angle the orbit turns in half an RK4 substep; see [`orbit_position_expr`][mrpctl.model.orbit_position_expr]
#: and [`orbit_turn_expr`][mrpctl.model.orbit_turn_expr].
ORBIT_SIZE = 10


def dynamics_expr(
    spacecraft: Spacecraft | None, x: Any, u: Any, *, inertia: Any = None, inertia_inverse: Any = None
) -> Any:
    """ẋ for x = [σ; ω/4] and torque u, as a CasADi expression (SX or MX).

    σ̇ = ¼ B(σ) ω and ω̇ = J⁻¹ (−ω × J ω + u), then ẋ = [σ̇; ω̇/4].

    Parameters
    ----------
    spacecraft : Spacecraft or None
        Its J and J⁻¹ (kg m², 1/(kg m²)) enter as constants, unless given below.
    x, u : casadi.SX or casadi.MX
        State (6) and torque (3, N m).
    inertia, inertia_inverse : casadi.SX or casadi.MX, keyword-only
        3 × 3 expressions (for example symbols, possibly structurally diagonal) used
        instead of the spacecraft's constants: the inertia as a run-time input of a
        compiled Function. Give both, or neither.
    """
    if (inertia is None) != (inertia_inverse is None):
        raise ValueError("dynamics_expr: give both inertia and inertia_inverse, or neither")
    if inertia is None:
        if spacecraft is None:
            raise ValueError("dynamics_expr: give a spacecraft or inertia and inertia_inverse")
        inertia = ca.DM(spacecraft.inertia)
        inertia_inverse = ca.DM(spacecraft.inertia_inverse)
    sigma = x[0:3]
    omega = 4 * x[3:6]
    sigma_dot = b_matrix_expr(sigma) @ omega / 4
    omega_dot = inertia_inverse @ (-skew_expr(omega) @ (inertia @ omega) + u)
    return ca.vertcat(sigma_dot, omega_dot / 4)


def wheel_hub_inertia(spacecraft: Spacecraft, wheels: WheelCluster) -> np.ndarray:
    """M = J − Gs diag(Js) Gsᵀ (kg m²): the inertia that multiplies ω̇ once the wheels' spin equations are
    eliminated (Basilisk's ``matrixD`` of balanced wheels). J is the whole spacecraft's inertia, wheels
    included; M must be positive definite (Js small enough against J). An entry below the rounding of M's
    largest diagonal entry (machine epsilon times it) is the rounding of a zero (the off-diagonal entries of a
    pyramid's Σ Js,i g_i g_iᵀ, 1e-20 against 0.2 kg m²) and is set to 0, so that such an M is diagonal."""
    axes = wheels.spin_axes
    hub = spacecraft.inertia - (axes * wheels.spin_inertia) @ axes.T
    hub = (hub + hub.T) / 2.0
    hub[np.abs(hub) < np.finfo(float).eps * np.max(np.abs(np.diag(hub)))] = 0.0
    if np.min(np.linalg.eigvalsh(hub)) <= 0.0:
        raise SpecificationError(
            "spin_inertia: J − Gs diag(Js) Gsᵀ is not positive definite (the wheels' spin inertia cannot exceed "
            "the spacecraft's inertia J, which includes the wheels)"
        )
    return hub


def _has_friction(wheels: WheelCluster) -> bool:
    return bool(np.any(wheels.viscous > 0.0) or np.any(wheels.coulomb > 0.0))


def _wheel_friction_expr(wheels: WheelCluster, speeds: Any) -> Any:
    """−τ_f (N, N m), the friction torque's opposite, of the wheels at the speeds Ω: f_c,i sgn Ω_i + c_i Ω_i,
    linear through zero below the limit-cycle speed; None when every c_i and f_c,i is 0 (no friction terms in
    the expressions)."""
    if not _has_friction(wheels):
        return None
    viscous, coulomb, cycle = (ca.DM(a) for a in (wheels.viscous, wheels.coulomb, wheels.limit_cycle_speed))
    # f_c sgn Ω as copysign(f_c, Ω): the same value wherever it is used (|Ω| >= ω_lc > 0), one operation
    outside = ca.copysign(coulomb, speeds) + viscous * speeds
    inside = (coulomb + viscous * cycle) / cycle * speeds
    return ca.if_else(ca.fabs(speeds) < cycle, inside, outside)


def _wheel_balance_expr(wheels: WheelCluster, omega: Any, momentum: Any, speeds: Any, motor: Any, w: Any) -> Any:
    """(Ḣ, ḣ_s): the balance of the total angular momentum H (body frame, N m) and of the wheels' spin momenta
    (N, N m): Ḣ = −ω × H + w (the motor torques and the friction are internal), ḣ_s,i = u_s,i + τ_f,i(Ω_i)."""
    friction = _wheel_friction_expr(wheels, speeds)
    spin_dot = motor if friction is None else motor - friction
    momentum_dot = ca.cross(momentum, omega)  # −ω × H
    if w is not None:
        momentum_dot = momentum_dot + w
    return momentum_dot, spin_dot


def wheel_momenta_expr(spacecraft: Spacecraft, wheels: WheelCluster, omega: Any, speeds: Any) -> tuple[Any, Any]:
    """(H, h_s) of the body rate ω (rad/s) and the wheel speeds Ω (N, rad/s, relative to the body): the total
    angular momentum H = J ω + Gs diag(Js) Ω (body frame, N m s; J the whole spacecraft's inertia) and the
    wheels' spin momenta h_s,i = Js,i (g_iᵀ ω + Ω_i) (N m s), as CasADi expressions. The inverse map is
    [`wheel_body_rate_expr`][mrpctl.model.wheel_body_rate_expr] and
    [`wheel_speeds_expr`][mrpctl.model.wheel_speeds_expr]."""
    axes = ca.DM(wheels.spin_axes)
    js = ca.DM(wheels.spin_inertia)
    momentum = ca.DM(spacecraft.inertia) @ omega + axes @ (js * speeds)
    return momentum, js * (axes.T @ omega + speeds)


def wheel_body_rate_expr(spacecraft: Spacecraft, wheels: WheelCluster, momentum: Any, spin: Any) -> Any:
    """ω = M⁻¹ (H − Gs h_s) (rad/s) of the total angular momentum H and the spin momenta h_s, M = J − Gs diag(Js)
    Gsᵀ ([`wheel_hub_inertia`][mrpctl.model.wheel_hub_inertia], a constant of the expression)."""
    hub_inverse = ca.DM(np.linalg.inv(wheel_hub_inertia(spacecraft, wheels)))
    return hub_inverse @ (momentum - ca.DM(wheels.spin_axes) @ spin)


def wheel_speeds_expr(wheels: WheelCluster, omega: Any, spin: Any) -> Any:
    """Ω_i = h_s,i / Js,i − g_iᵀ ω (rad/s, relative to the body) of the spin momenta h_s and the body rate ω
    (h_s,i times the constant 1/Js,i: a multiplication, not a division, per wheel)."""
    return spin * ca.DM(1.0 / wheels.spin_inertia) - ca.DM(wheels.spin_axes).T @ omega


def wheel_momentum_dynamics_expr(
    spacecraft: Spacecraft,
    wheels: WheelCluster,
    sigma: Any,
    momentum: Any,
    spin: Any,
    motor: Any,
    w: Any = None,
    *,
    omega: Any = None,
) -> tuple[Any, Any, Any]:
    """(σ̇, Ḣ, ḣ_s) of the spacecraft with its wheel cluster in momentum coordinates, as CasADi expressions.

    The state of [`wheel_dynamics_expr`][mrpctl.model.wheel_dynamics_expr] mapped linearly
    ([`wheel_momenta_expr`][mrpctl.model.wheel_momenta_expr]): the attitude σ, the total angular momentum H
    (body frame, N m s) and the spin momenta h_s (N, N m s). With ω = M⁻¹ (H − Gs h_s) and, for the friction,
    Ω = h_s/Js − Gsᵀ ω:

        σ̇ = ¼ B(σ) ω,    Ḣ = −ω × H + w,    ḣ_s,i = u_s,i + τ_f,i

    the same equations as `wheel_dynamics_expr` (its M ω̇ = Ḣ − Gs ḣ_s and Ω̇ = ḣ_s/Js − Gsᵀ ω̇). Without
    friction ḣ_s = u_s does not depend on the state. RK4 is affine-invariant: stepping these coordinates gives
    the steps of `wheel_dynamics_expr`'s up to rounding, with fewer operations per stage (no M⁻¹ Gs u_s, Gsᵀ ω̇
    or per-wheel state in the stages). ``omega``: the body rate of (H, h_s) when the caller has it (an expression
    equal to `wheel_body_rate_expr`'s, for instance from its linearity in (H, h_s)); None: computed here.
    """
    if omega is None:
        omega = wheel_body_rate_expr(spacecraft, wheels, momentum, spin)
    speeds = wheel_speeds_expr(wheels, omega, spin) if _has_friction(wheels) else None  # only the friction's
    momentum_dot, spin_dot = _wheel_balance_expr(wheels, omega, momentum, speeds, motor, w)
    return b_matrix_expr(sigma) @ omega / 4, momentum_dot, spin_dot


def wheel_dynamics_expr(
    spacecraft: Spacecraft, wheels: WheelCluster, x: Any, speeds: Any, motor: Any, w: Any = None
) -> tuple[Any, Any]:
    """(ẋ, Ω̇) of the spacecraft with its wheel cluster, as CasADi expressions (SX or MX).

    x = [σ; ω/4] (6), wheel speeds Ω (N, rad/s, relative to the body), motor torques u_s (N, N m,
    on the wheels) and an external body torque w (3, N m; None: 0). With J the whole spacecraft's
    inertia (wheels included), H = J ω + Gs diag(Js) Ω, the friction torque τ_f,i of each wheel
    ([`WheelCluster`][mrpctl.wheels.WheelCluster]) and M = J − Gs diag(Js) Gsᵀ:

        σ̇ = ¼ B(σ) ω
        M ω̇ = −ω × H − Gs (u_s + τ_f) + w
        Ω̇_i = (u_s,i + τ_f,i)/Js,i − g_iᵀ ω̇

    (Basilisk's balanced wheels, ``reactionWheelStateEffector``): the balance laws Ḣ = −ω × H + w and
    ḣ_s = u_s + τ_f of [`wheel_momentum_dynamics_expr`][mrpctl.model.wheel_momentum_dynamics_expr] in the
    coordinates (σ, ω, Ω). Friction terms are left out of the expressions when every c_i and f_c,i is 0.
    """
    hub_inverse = ca.DM(np.linalg.inv(wheel_hub_inertia(spacecraft, wheels)))
    axes = ca.DM(wheels.spin_axes)
    sigma = x[0:3]
    omega = 4 * x[3:6]
    momentum = wheel_momenta_expr(spacecraft, wheels, omega, speeds)[0]
    momentum_dot, spin_dot = _wheel_balance_expr(wheels, omega, momentum, speeds, motor, w)
    omega_dot = hub_inverse @ (momentum_dot - axes @ spin_dot)
    speeds_dot = wheel_speeds_expr(wheels, omega_dot, spin_dot)
    sigma_dot = b_matrix_expr(sigma) @ omega / 4
    return ca.vertcat(sigma_dot, omega_dot / 4), speeds_dot


def gravity_gradient_expr(sigma_BN: Any, r_hat_N: Any, n: Any, inertia: Any) -> Any:
    """The gravity-gradient torque 3 n² r̂_B × (J r̂_B) (N m, body frame) as a CasADi expression.

    r̂_B = [BN](σ_BN) r̂_N is the unit vector from the Earth's centre to the spacecraft in body
    components, n the orbit rate (rad/s; n² = μ/r³ on a circular orbit of radius r) and J the
    inertia (kg m², body frame). The torque of a rigid body in a central inverse-square field to first
    order in its size (Schaub & Junkins, *Analytical Mechanics of Space Systems*, gravity-gradient
    torque; Basilisk's ``GravityGradientEffector``).

    Parameters
    ----------
    sigma_BN : casadi.SX or casadi.MX
        Attitude σ_B/N (3).
    r_hat_N : casadi.SX, casadi.MX or array_like
        Unit position vector in N components (3); it is used as given (not normalised).
    n : float or casadi expression
        Orbit rate (rad/s).
    inertia : array_like or casadi expression
        J, 3 × 3 (kg m²).
    """
    sigma_BN, r_hat_N, inertia = (_casadi(v) for v in (sigma_BN, r_hat_N, inertia))
    # r̂_B = [BN] r̂_N = r̂ + (8 σ × (σ × r̂) − 4 (1 − |σ|²) σ × r̂)/(1 + |σ|²)²: dcm_expr's matrix applied by two
    # cross products (no 3 × 3 matrix)
    squared = ca.dot(sigma_BN, sigma_BN)
    once = ca.cross(sigma_BN, r_hat_N)
    r_b = r_hat_N + (8 * ca.cross(sigma_BN, once) - 4 * (1 - squared) * once) / ((1 + squared) * (1 + squared))
    return 3 * n**2 * ca.cross(r_b, inertia @ r_b)


def orbit_phase_expr(orbit: Any, t: Any) -> tuple[Any, Any]:
    """(cos u, sin u), u = u₀ + n t, of a circular orbit ``orbit`` (`ORBIT_SIZE`, see `orbit_position_expr`) at
    ``t`` (s), as CasADi expressions."""
    angle = orbit[1] + orbit[0] * t
    return ca.cos(angle), ca.sin(angle)


def orbit_turn_expr(orbit: Any, phase: tuple[Any, Any]) -> tuple[Any, Any]:
    """The phase (cos u, sin u) turned by δ, the orbit's angle in half an RK4 substep, by the angle-addition
    formulas with the constants cos δ, sin δ of ``orbit`` (no libm call): (cos(u + δ), sin(u + δ))."""
    cosine, sine = phase
    return cosine * orbit[8] - sine * orbit[9], sine * orbit[8] + cosine * orbit[9]


def orbit_position_expr(orbit: Any, phase: tuple[Any, Any]) -> Any:
    """r̂_N = cos u ê₁ + sin u ê₂ (N components) of a circular orbit at the phase (cos u, sin u), as a CasADi
    expression: with `orbit_phase_expr`, r̂_N(t) = cos(u₀ + n t) ê₁ + sin(u₀ + n t) ê₂.

    ``orbit`` holds (n, u₀, ê₁ (3), ê₂ (3), cos δ, sin δ) (`ORBIT_SIZE`): the orbit rate (rad/s), the argument of
    latitude at t = 0 (rad), the two in-plane unit axes, ê₁ to the ascending node and ê₂ = ĥ × ê₁
    ([`CircularOrbit.in_plane_axes`][mrpctl.guidance.CircularOrbit.in_plane_axes]), and the cosine and sine of
    δ = n dt/2, the angle of half an RK4 substep dt (`orbit_turn_expr`).
    """
    cosine, sine = phase
    return cosine * orbit[2:5] + sine * orbit[5:8]


def _casadi(value: Any) -> Any:
    """``value`` unchanged if a CasADi expression, else a ca.DM (a NumPy vector would be a row in ``@``)."""
    if isinstance(value, ca.SX | ca.MX | ca.DM):
        return value
    return ca.DM(np.asarray(value, dtype=float))


def tracking_error_dynamics_expr(
    spacecraft: Spacecraft,
    e: Any,
    u: Any,
    sigma_RN: Any,
    omega_RN_N: Any,
    domega_RN_N: Any,
    *,
    torque: Any = None,
) -> Any:
    """ė of the tracking error e = [σ_B/R; ω_B/R/4] (body components) as a CasADi expression.

    Built by composition, without a hand-written error equation: the body state
    x = [σ_B/N; ω_B/N/4] is rebuilt from e and the reference (σ_B/N = σ_R/N ⊕ σ_B/R,
    ω_B/N = ω_B/R + [BN] ω_R/N), its derivative is [`dynamics_expr`][mrpctl.model.dynamics_expr]
    with the torque u + L, and ė is the chain rule of the error map
    e = g(x, σ_R/N, ω_R/N) = [σ_B/N ⊖ σ_R/N; (ω_B/N − [BN] ω_R/N)/4] along the body and the
    reference motion (σ̇_R/N = ¼ B(σ_R/N) [RN] ω_R/N, ω̇_R/N given).

    Parameters
    ----------
    spacecraft : Spacecraft
        Its inertia J.
    e : casadi.SX or casadi.MX
        Tracking error [σ_B/R; ω_B/R/4] (6).
    u : casadi.SX or casadi.MX
        Control torque (3, N m, body frame).
    sigma_RN, omega_RN_N, domega_RN_N : casadi.SX, casadi.MX or array_like
        Reference attitude (MRP), rate (rad/s) and acceleration (rad/s²), the rates in N components
        (Basilisk's ``AttRefMsgPayload``: ``sigma_RN``, ``omega_RN_N``, ``domega_RN_N``).
    torque : callable, optional
        ``torque(sigma_BN) -> L``: an environment torque (N m, body frame) of the body attitude, for
        instance ``lambda s: gravity_gradient_expr(s, r_hat_N, n, J)``. None: no torque.
    """
    sc = check_spacecraft(spacecraft)
    sigma_RN, omega_RN_N, domega_RN_N = (_casadi(v) for v in (sigma_RN, omega_RN_N, domega_RN_N))
    x_s = ca.SX.sym("x", STATE_SIZE)
    sr_s = ca.SX.sym("sigma_RN", 3)
    wr_s = ca.SX.sym("omega_RN_N", 3)
    sigma_b, omega_b = x_s[0:3], 4 * x_s[3:6]
    error = ca.vertcat(subtract_expr(sigma_b, sr_s), (omega_b - dcm_expr(sigma_b) @ wr_s) / 4)
    maps = ca.Function(
        "error_map",
        [x_s, sr_s, wr_s],
        [ca.jacobian(error, x_s), ca.jacobian(error, sr_s), ca.jacobian(error, wr_s)],
    )
    sigma_BN = add_expr(sigma_RN, e[0:3])
    omega_BN = 4 * e[3:6] + dcm_expr(sigma_BN) @ omega_RN_N
    x = ca.vertcat(sigma_BN, omega_BN / 4)
    load = u if torque is None else u + torque(sigma_BN)
    x_dot = dynamics_expr(sc, x, load)
    sigma_R_dot = b_matrix_expr(sigma_RN) @ (dcm_expr(sigma_RN) @ omega_RN_N) / 4
    d_x, d_sigma_R, d_omega_R = maps(x, sigma_RN, omega_RN_N)
    return d_x @ x_dot + d_sigma_R @ sigma_R_dot + d_omega_R @ domega_RN_N


@dataclass(frozen=True, eq=False)
class PlantModel:
    """The plant of one spacecraft as named CasADi Functions and the paper's split.

    Attributes
    ----------
    spacecraft : Spacecraft
        The spacecraft whose inertia J enters the dynamics.
    dynamics : casadi.Function
        ``dynamics(x, u) -> xdot``: ẋ = A x + B u + f(x).
    nonlinearity : casadi.Function
        ``f(x) -> f``: the paper's f(x) of Eq. 7.
    A : numpy.ndarray
        (6, 6) constant matrix [[0, I₃], [0, 0]].
    B : numpy.ndarray
        (6, 3) constant matrix [0; ¼ J⁻¹].
    """

    spacecraft: Spacecraft
    dynamics: ca.Function = field(repr=False)
    nonlinearity: ca.Function = field(repr=False)
    A: np.ndarray = field(repr=False)
    B: np.ndarray = field(repr=False)

    def closed_loop_matrices(self, K: Any) -> tuple[np.ndarray, np.ndarray]:
        """(A, A_d) = (A, B K) of the loop linearised at x = 0: ẋ = A x + A_d x(t − τ)."""
        return self.A, readonly(self.B @ gain_matrix(K))


def linear_matrices(spacecraft: Spacecraft) -> tuple[np.ndarray, np.ndarray]:
    """(A, B) of [`PlantModel`][mrpctl.model.PlantModel] without building its CasADi functions.

    The same arrays, bit for bit, as ``plant_model(spacecraft).A`` and ``.B``: for loops that only need
    the linear part (the predictor's margins evaluate it hundreds of times; the CasADi plant costs about
    a thousand times more than these two arrays).
    """
    spacecraft = check_spacecraft(spacecraft)
    a_matrix = np.block([[np.zeros((3, 3)), np.eye(3)], [np.zeros((3, 3)), np.zeros((3, 3))]])
    b_matrix = np.vstack((np.zeros((3, 3)), spacecraft.inertia_inverse / 4.0))
    return readonly(a_matrix), readonly(b_matrix)


def plant_model(spacecraft: Spacecraft) -> PlantModel:
    """Build the CasADi plant of ``spacecraft`` (cheap: a few SX nodes)."""
    spacecraft = check_spacecraft(spacecraft)
    x = ca.SX.sym("x", STATE_SIZE)
    u = ca.SX.sym("u", INPUT_SIZE)
    xdot = dynamics_expr(spacecraft, x, u)
    a_matrix, b_matrix = linear_matrices(spacecraft)
    drift = ca.substitute(xdot, u, ca.DM.zeros(INPUT_SIZE)) - ca.DM(a_matrix) @ x
    return PlantModel(
        spacecraft=spacecraft,
        dynamics=ca.Function("dynamics", [x, u], [xdot], ["x", "u"], ["xdot"]),
        nonlinearity=ca.Function("f", [x], [ca.simplify(drift)], ["x"], ["f"]),
        A=a_matrix,
        B=b_matrix,
    )


def gain_matrix(K: Any) -> np.ndarray:
    """Check that K is a finite (3, 6) feedback gain acting on x = [σ; ω/4]; a physical
    [`PDGains`][mrpctl.conventions.PDGains] is converted to it (K = [−P_σ, −4 P_ω])."""
    return feedback_gain(K)
