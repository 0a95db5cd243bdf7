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
from mrpctl.mrp import b_matrix_expr, skew_expr
from mrpctl.spacecraft import Spacecraft, check_spacecraft

__all__ = [
    "INPUT_SIZE",
    "STATE_SIZE",
    "PlantModel",
    "dynamics_expr",
    "gain_from_pd",
    "gain_matrix",
    "pd_from_gain",
    "plant_model",
    "state",
    "state_parts",
]

STATE_SIZE = 6
INPUT_SIZE = 3


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


def plant_model(spacecraft: Spacecraft) -> PlantModel:
    """Build the CasADi plant of ``spacecraft`` (cheap: a few SX nodes)."""
    spacecraft = check_spacecraft(spacecraft)
    x = ca.SX.sym("x", STATE_SIZE)
    u = ca.SX.sym("u", INPUT_SIZE)
    xdot = dynamics_expr(spacecraft, x, u)
    a_matrix = np.block([[np.zeros((3, 3)), np.eye(3)], [np.zeros((3, 3)), np.zeros((3, 3))]])
    b_matrix = np.vstack((np.zeros((3, 3)), spacecraft.inertia_inverse / 4.0))
    drift = ca.substitute(xdot, u, ca.DM.zeros(INPUT_SIZE)) - ca.DM(a_matrix) @ x
    return PlantModel(
        spacecraft=spacecraft,
        dynamics=ca.Function("dynamics", [x, u], [xdot], ["x", "u"], ["xdot"]),
        nonlinearity=ca.Function("f", [x], [ca.simplify(drift)], ["x"], ["f"]),
        A=readonly(a_matrix),
        B=readonly(b_matrix),
    )


def gain_matrix(K: Any) -> np.ndarray:
    """Check that K is a finite (3, 6) feedback gain acting on x = [σ; ω/4]; a physical
    [`PDGains`][mrpctl.conventions.PDGains] is converted to it (K = [−P_σ, −4 P_ω])."""
    return feedback_gain(K)
