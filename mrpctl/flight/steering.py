"""A saturation-aware control law for the flight loop: the PD law with a rate-limited MRP steering command.

The flight loop's PD law u_c = K [σ_c; ω̃/4] asks, far from the target, for torques hundreds of
times what a small actuator gives; the loop then spends minutes saturated. The steering law keeps
the same K near the target and limits the *rate it commands* far from it, so that the body never
turns faster than it can stop in the angle that remains (Schaub & Junkins, "MRP steering law",
*Analytical Mechanics of Space Systems*, 4th ed., §8.5, with the rate limit of a stopping distance).

Write K = [K_σ, K_ω] (N m, on x = [σ; ω/4]). With an invertible K_ω the PD law is a rate loop
u_c = K_ω (ω̃/4 − ω_lin/4) around the linear rate command ω_lin = −4 K_ω⁻¹ K_σ σ_c (rad/s). The
steering law scales that command down to the rate limit of the remaining angle φ = 4 atan|σ_c|:

    L(φ) = min(ω_max, √((a T)² + 2 a φ) − a T),    s = min(1, L(φ) / |ω_lin|),
    u_c  = K_ω ω̃/4 + s K_σ σ_c,

where a (rad/s²) is the deceleration the body can count on and T (s) the reaction lag (the
measurement delay and the rate loop's time constant): L is the largest rate from which the body,
coasting for T and then braking at a, stops within φ. With s = 1 (near the target, where
|ω_lin| <= L) the law *is* the PD law K. The actuator's limits act on u_c as for the PD law.

With a momentum limit h and the spacecraft's J (a reaction-wheel cluster's: the body momentum its wheels
hold in every direction) the scale also keeps the momentum of the commanded rate within h,

    s = min(1, L(φ) / |ω_lin|, h / |J ω_lin|),

a direction-dependent rate limit h / |J ω̂| (faster about the axes of small inertia).
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from mrpctl._validation import nonnegative_scalar, positive_scalar
from mrpctl.errors import SpecificationError
from mrpctl.flight.models import Hysteretic
from mrpctl.spacecraft import Spacecraft

__all__ = ["SteeringLaw", "check_law", "steering_command_expr"]


@dataclass(frozen=True)
class SteeringLaw:
    """The rate-limited MRP steering law (module docstring): K's attitude term scaled so that the
    commanded rate stays below the rate from which the body can stop in the remaining angle.

    The law's numbers are constants of the compiled sample: each law is its own engine (compiled
    once, cached on disk like every engine).

    Parameters
    ----------
    rate_limit : float
        ω_max > 0, the largest commanded rate (rad/s).
    acceleration : float
        a > 0, the deceleration the stopping-distance limit assumes (rad/s²); choose it below the
        actuator's u_max / J_max (the design leaves a margin for the gyroscopic torque).
    lag : float
        T >= 0, the reaction time included in the stopping distance (s): the measurement delay
        plus the rate loop's time constant. Default 0.
    momentum_limit : float or None
        h > 0 (N m s): the largest body momentum |J ω| of the commanded rate (a wheel cluster's
        momentum capacity); given with ``spacecraft``. Default None: no momentum limit.
    spacecraft : Spacecraft or None
        The spacecraft whose inertia J measures the commanded rate's momentum (with ``momentum_limit``).
    """

    rate_limit: float
    acceleration: float
    lag: float = 0.0
    momentum_limit: float | None = None
    spacecraft: Spacecraft | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "rate_limit", positive_scalar("rate_limit", self.rate_limit))
        object.__setattr__(self, "acceleration", positive_scalar("acceleration", self.acceleration))
        object.__setattr__(self, "lag", nonnegative_scalar("lag", self.lag))
        if (self.momentum_limit is None) != (self.spacecraft is None):
            raise SpecificationError(
                "momentum_limit: give it with the spacecraft whose inertia measures the momentum (both or neither), "
                f"got momentum_limit={self.momentum_limit!r}, spacecraft={self.spacecraft!r}"
            )
        if self.momentum_limit is not None:
            object.__setattr__(self, "momentum_limit", positive_scalar("momentum_limit", self.momentum_limit))
            if not isinstance(self.spacecraft, Spacecraft):
                raise SpecificationError(
                    f"spacecraft must be a mrpctl.Spacecraft, got {type(self.spacecraft).__name__}"
                )

    def rate_command_limit(self, angle: float) -> float:
        """L(φ) (rad/s): the largest commanded rate at the remaining angle φ (rad)."""
        a, lag = self.acceleration, self.lag
        return min(self.rate_limit, math.sqrt((a * lag) ** 2 + 2.0 * a * max(angle, 0.0)) - a * lag)

    def label(self) -> str:
        """A short name of the law's numbers (part of its compiled engine's name)."""
        text = f"{self.rate_limit!r}_{self.acceleration!r}_{self.lag!r}"
        if self.momentum_limit is not None and self.spacecraft is not None:  # else the label of before
            text += f"_{self.momentum_limit!r}_{self.spacecraft.inertia.tobytes().hex()}"
        return "steer_" + hashlib.sha256(text.encode()).hexdigest()[:10]

    def __str__(self) -> str:
        momentum = "" if self.momentum_limit is None else f", body momentum limit {self.momentum_limit:.4g} N m s"
        return (
            f"SteeringLaw (rate limit {self.rate_limit:.4g} rad/s, deceleration {self.acceleration:.4g} rad/s^2, "
            f"lag {self.lag:.4g} s{momentum})"
        )


def steering_command_expr(law: SteeringLaw, gain: Any, sigma: Any, rate: Any) -> tuple[Any, Any]:
    """(u_c, s): the steering law's commanded torque (N m) and its attitude scale s in (0, 1] (SX).

    ``gain`` is K (3, 6), ``sigma`` the MRP the law uses (σ_c), ``rate`` the measured ω̃/4.
    """
    k_sigma, k_omega = gain[:, 0:3], gain[:, 3:6]
    attitude = k_sigma @ sigma
    direction = ca.solve(k_omega, attitude)  # −ω_lin/4
    linear_rate = 4.0 * ca.norm_2(direction)  # |ω_lin| = 4 |K_ω⁻¹ K_σ σ_c|
    angle = 4.0 * ca.atan(ca.norm_2(sigma))
    a, lag = law.acceleration, law.lag
    limit = ca.fmin(law.rate_limit, ca.sqrt((a * lag) ** 2 + 2.0 * a * angle) - a * lag)
    over = linear_rate > limit
    # both if_else branches are evaluated: keep the unused quotient finite at σ_c = 0
    scale = ca.if_else(over, limit / ca.if_else(over, linear_rate, 1.0), 1.0)
    if law.momentum_limit is not None and law.spacecraft is not None:
        momentum = 4.0 * ca.norm_2(ca.DM(law.spacecraft.inertia) @ direction)  # |J ω_lin|
        heavy = scale * momentum > law.momentum_limit
        scale = ca.if_else(heavy, law.momentum_limit / ca.if_else(heavy, momentum, 1.0), scale)
    return k_omega @ rate + scale * attitude, scale


def check_law(law: Any, rules: Any, gains: Any, *, predictor: Any = None) -> SteeringLaw | None:
    """The ``law`` option checked against the rules, the gains (N, 3, 6) and the predictor: a
    [`SteeringLaw`][mrpctl.flight.steering.SteeringLaw] runs in the flight loop (rule ``Hysteretic``) with an
    invertible rate block K_ω of every gain; None passes."""
    if law is None:
        return None
    if not isinstance(law, SteeringLaw):
        raise SpecificationError(f"law must be a mrpctl.flight.steering.SteeringLaw or None, got {law!r}")
    if predictor is not None:
        raise SpecificationError("law: the steering law runs in the flight loop, not with the predictor: drop law=")
    for rule in rules:
        if not isinstance(rule, Hysteretic):
            raise SpecificationError(
                "law: the steering law runs in the flight loop only; use rule=mrpctl.flight.Hysteretic(delta) "
                f"(Hysteretic(0.0) is OnCurrent's set), got {rule}"
            )
    for i, gain in enumerate(np.asarray(gains, dtype=float).reshape(-1, 3, 6)):
        block = gain[:, 3:6]
        singular = np.linalg.svd(block, compute_uv=False)
        if not singular[-1] > 1e-12 * max(singular[0], 1e-300):
            raise SpecificationError(
                f"K{'' if i == 0 else f'[{i}]'}: the steering law needs an invertible rate block K[:, 3:6] (the rate "
                f"loop), got singular values {singular}"
            )
    return law
