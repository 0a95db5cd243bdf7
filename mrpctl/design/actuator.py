"""Design for the actuator: a saturation-aware law (the rate-limited MRP steering law) for a torque limit
and an envelope of initial states to recover from (``design/wheels.md``, "Design for the actuator").

The linear gains K are [`synthesize_pd`][mrpctl.design.synthesize_pd]'s (certified for the delay τ);
the law's rate limit and deceleration come from the actuator and the inertia: the torque every
direction is guaranteed, U = min(min u_max,i, u_norm), the inertia J_max about the slowest axis and
the gyroscopic torque |ω × Jω| <= ω² (J_max − J_min)/2 at the rate limit. The settling time of the
envelope's worst case is *predicted* by a kinematic estimate (stop the initial rate, a trapezoidal
slew of π, the reaction lag, the linear tail); the design does not simulate (the measured numbers
are those of ``bench/actuator_design.py``). When the time asked is below a lower bound that holds
for any law, the result says so (``INFEASIBLE``) with the numbers.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mrpctl._validation import nonnegative_scalar, positive_scalar
from mrpctl.design.synthesis import synthesize_pd
from mrpctl.errors import SpecificationError
from mrpctl.flight.models import ActuatorModel
from mrpctl.flight.steering import SteeringLaw
from mrpctl.spacecraft import Spacecraft, check_spacecraft

__all__ = [
    "SETTLING_OMEGA",
    "SETTLING_SIGMA",
    "ActuatorDesign",
    "ActuatorDesignStatus",
    "design_for_actuator",
    "guaranteed_torque",
    "slew_lower_bound",
]

#: The settling tolerances the prediction aims at (mrpctl's settling: |σ| < 1e-2, |ω| < 1e-3 rad/s).
SETTLING_SIGMA, SETTLING_OMEGA = 1e-2, 1e-3


class ActuatorDesignStatus(enum.Enum):
    """Outcome of [`design_for_actuator`][mrpctl.design.actuator.design_for_actuator]."""

    #: A law whose predicted worst-case settling time meets the time asked.
    DESIGNED = "designed"
    #: A law was designed but its predicted worst-case settling time exceeds the time asked
    #: (no law was proven unable to meet it).
    NOT_MET = "predicted settling time above the time asked"
    #: The time asked is below the lower bound of any law (a rest-to-rest 180 degree slew).
    INFEASIBLE = "infeasible for any law"


@dataclass(frozen=True)
class ActuatorDesign:
    """Result of [`design_for_actuator`][mrpctl.design.actuator.design_for_actuator].

    Attributes
    ----------
    status : ActuatorDesignStatus
    K : numpy.ndarray
        (3, 6) linear gains (N m, on x = [σ; ω/4]): the law near the target.
    law : SteeringLaw
        The steering law (rate limit, deceleration, lag).
    tau : float
        The delay (s).
    max_rate : float
        The envelope's largest initial rate (rad/s), any attitude.
    settling_time : float
        The time asked for the envelope to settle (s).
    predicted_time : float
        The predicted worst-case settling time of the envelope under the law (s); inf when the
        gyroscopic torque at the envelope's rate is above the guaranteed torque.
    lower_bound : float
        A lower bound on the worst-case settling time of any law (s): 2 √(π J_min / U_max), the
        rest-to-rest 180° slew with the largest torque magnitude U_max the actuator can give.
    torque : float
        U (N m): the torque the actuator guarantees in every direction.
    linear : Any
        The [`PDSynthesis`][mrpctl.design.PDSynthesis] of K.
    reason : str
    """

    status: ActuatorDesignStatus
    K: np.ndarray = field(repr=False)
    law: SteeringLaw
    tau: float
    max_rate: float
    settling_time: float
    predicted_time: float
    lower_bound: float
    torque: float
    linear: Any = field(repr=False)
    reason: str

    @property
    def designed(self) -> bool:
        """True when the predicted worst-case settling time meets the time asked."""
        return self.status is ActuatorDesignStatus.DESIGNED

    def __str__(self) -> str:
        return (
            f"Design for the actuator (tau = {self.tau:g} s, torque {self.torque:.4g} N m in every direction, "
            f"envelope |omega0| <= {self.max_rate:g} rad/s, any attitude): {self.status.value}\n"
            f"  {self.law}\n"
            f"  linear gains: omega_n = {self.linear.omega_n:.4g} rad/s, zeta = {self.linear.zeta:.4g} "
            f"({self.linear.status.value})\n"
            f"  predicted worst-case settling {self.predicted_time:.4g} s; asked {self.settling_time:.4g} s; "
            f"lower bound of any law {self.lower_bound:.4g} s\n"
            f"  {self.reason}"
        )


def guaranteed_torque(actuator: ActuatorModel) -> tuple[float, float]:
    """(U_min, U_max) (N m): the torque magnitude the actuator gives in every direction (the box's
    inscribed ball, or the norm limit) and the largest it gives in some direction."""
    if not isinstance(actuator, ActuatorModel):
        raise SpecificationError(f"actuator must be a mrpctl.flight.ActuatorModel, got {actuator!r}")
    limits = np.asarray(actuator.u_max, dtype=float)
    norm = actuator.norm_limit
    return min(float(np.min(limits)), norm), min(float(np.linalg.norm(limits)), norm)


def slew_lower_bound(angle: float, inertia: float, torque: float) -> float:
    """2 √(θ J / u) (s): the rest-to-rest time of a slew of θ (rad) about an axis of inertia J (kg m²) at
    torque u (N m), bang-bang."""
    return 2.0 * math.sqrt(angle * inertia / torque)


def design_for_actuator(
    spacecraft: Spacecraft,
    tau: float,
    actuator: ActuatorModel,
    *,
    max_rate: float,
    settling_time: float = 60.0,
    braking: float = 0.6,
    order: int = 3,
) -> ActuatorDesign:
    """The saturation-aware law for ``actuator`` and the envelope (|ω₀| <= ``max_rate``, any attitude).

    Parameters
    ----------
    spacecraft : Spacecraft
    tau : float
        Measurement delay τ > 0 (s).
    actuator : mrpctl.flight.ActuatorModel
        The body torque limits (per axis, and the norm limit).
    max_rate : float, keyword-only
        The envelope's largest initial rate (rad/s), >= 0.
    settling_time : float, keyword-only
        The time (s) in which the envelope must settle (|σ| < 1e-2, |ω| < 1e-3 rad/s); default 60.
    braking : float, keyword-only
        The share (0, 1) of the guaranteed torque the law's stopping distance counts on (the rest is
        left to the gyroscopic torque and the delay); default 0.6.
    order : int, keyword-only
        Bessel-Legendre order of the linear gains' certificate.

    Returns
    -------
    ActuatorDesign
        ``DESIGNED`` when the predicted worst case meets ``settling_time``, ``NOT_MET`` when it does
        not, ``INFEASIBLE`` when ``settling_time`` is below the lower bound of any law.

    Raises
    ------
    SpecificationError
        On a non-positive τ, a negative or non-finite ``max_rate``, ``braking`` outside (0, 1), or a
        non-positive ``settling_time``.
    """
    spacecraft = check_spacecraft(spacecraft)
    tau = positive_scalar("tau", tau)
    max_rate = nonnegative_scalar("max_rate", max_rate)  # the envelope's largest initial rate (rad/s)
    settling_time = positive_scalar("settling_time", settling_time)
    braking = positive_scalar("braking", braking)
    if braking >= 1.0:
        raise SpecificationError(
            f"braking (the share of the torque the stopping distance counts on) must be < 1, got {braking}"
        )
    u_min, u_max = guaranteed_torque(actuator)
    eigenvalues = np.linalg.eigvalsh(spacecraft.inertia)
    j_min, j_max = float(eigenvalues[0]), float(eigenvalues[-1])
    spread = (j_max - j_min) / 2.0  # max |n × Jn| over unit n

    linear = synthesize_pd(spacecraft, tau, zeta=1.0, order=order)
    K = np.asarray(linear.gains.K, dtype=float)
    omega_n, zeta = linear.omega_n, linear.zeta
    rate_gain = 2.0 * zeta * omega_n  # b: the rate loop's bandwidth (1/s)
    command_gain = omega_n / (2.0 * zeta)  # k: ω_lin = k φ near the target

    a_full = u_min / j_max
    a = braking * a_full
    gyro_rate = math.inf if spread == 0.0 else math.sqrt((1.0 - braking) * u_min / spread)
    rate_limit = min(math.sqrt(math.pi * a), gyro_rate)
    lag = tau + 1.0 / rate_gain
    law = SteeringLaw(rate_limit, a, lag)

    lower = slew_lower_bound(math.pi, j_min, u_max)
    predicted = _predicted_time(law, a_full, u_min, j_max, spread, max_rate, command_gain, linear.exact_decay_rate)
    numbers = (
        f"U = {u_min:.4g} N m, J in [{j_min:.4g}, {j_max:.4g}] kg m^2: deceleration {a:.4g} rad/s^2 "
        f"({braking:g} of U/J_max), rate limit {rate_limit:.4g} rad/s "
        f"({'gyroscopic torque' if gyro_rate < math.sqrt(math.pi * a) else 'time-optimal for 180 deg'})"
    )
    if settling_time < lower:
        status = ActuatorDesignStatus.INFEASIBLE
        reason = (
            f"no law settles the envelope in {settling_time:g} s: a rest-to-rest 180 deg slew about the axis of "
            f"J_min = {j_min:.4g} kg m^2 at the largest torque {u_max:.4g} N m takes at least {lower:.4g} s; {numbers}"
        )
    elif predicted > settling_time:
        status = ActuatorDesignStatus.NOT_MET
        reason = (
            f"the law's predicted worst case is {predicted:.4g} s, above the {settling_time:g} s asked (a prediction, "
            f"not a proof: no law was shown unable to); {numbers}"
        )
    else:
        status = ActuatorDesignStatus.DESIGNED
        reason = f"predicted worst case {predicted:.4g} s (a kinematic estimate, not a certificate); {numbers}"
    return ActuatorDesign(
        status=status,
        K=K,
        law=law,
        tau=tau,
        max_rate=max_rate,
        settling_time=settling_time,
        predicted_time=predicted,
        lower_bound=lower,
        torque=u_min,
        linear=linear,
        reason=reason,
    )


def _predicted_time(
    law: SteeringLaw,
    a_full: float,
    u_min: float,
    j_max: float,
    spread: float,
    max_rate: float,
    command_gain: float,
    decay: float,
) -> float:
    """The kinematic estimate of the envelope's worst-case settling time (s): stop |ω₀| = ``max_rate``
    against the gyroscopic torque, slew π on the law's trapezoid, the reaction lag, and the linear tail
    from the angle where the rate limit meets the linear command down to the settling tolerances."""
    left = u_min - max_rate**2 * spread
    if left <= 0.0:
        return math.inf
    stop = max_rate * j_max / left
    a, w = law.acceleration, law.rate_limit
    slew = math.pi / w + w / a if math.pi >= w * w / a else 2.0 * math.sqrt(math.pi / a)
    k = command_gain
    switch = 2.0 * a * max(1.0 - law.lag * k, 0.05) / k**2  # L(φ) = k φ
    tolerance = min(4.0 * SETTLING_SIGMA, SETTLING_OMEGA / k)
    tail = math.log(max(switch / tolerance, 1.0)) / decay if decay > 0 else math.inf
    return stop + slew + law.lag + tail
