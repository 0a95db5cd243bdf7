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

On a reaction-wheel cluster ([`WheelCluster`][mrpctl.wheels.WheelCluster]) U is the body torque the
allocation gives in every direction before a wheel reaches its torque limit, and the wheels' speed limits
bound the momentum the body may take: the law's commanded rate carries at most the momentum the wheels
hold in every direction (its momentum limit), and the prediction's cruise is slowed to what is left once
the envelope's initial momentum is stored.
"""

from __future__ import annotations

import enum
import itertools
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
from mrpctl.wheels import WheelCluster, allocation_matrix

__all__ = [
    "SETTLING_OMEGA",
    "SETTLING_SIGMA",
    "ActuatorDesign",
    "ActuatorDesignStatus",
    "design_for_actuator",
    "guaranteed_momentum",
    "guaranteed_torque",
    "slew_lower_bound",
]

# Up to this many wheels the largest body torque is found over the vertices of the torque box (2^N).
_VERTEX_WHEELS = 12

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
    momentum : float or None
        A wheel cluster's: the body momentum (N m s) its wheels hold in every direction from their initial
        speeds ([`guaranteed_momentum`][mrpctl.design.actuator.guaranteed_momentum]); None for an ideal torque.
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
    momentum: float | None = None

    @property
    def designed(self) -> bool:
        """True when the predicted worst-case settling time meets the time asked."""
        return self.status is ActuatorDesignStatus.DESIGNED

    def __str__(self) -> str:
        held = "" if self.momentum is None else f", wheels holding {self.momentum:.4g} N m s"
        return (
            f"Design for the actuator (tau = {self.tau:g} s, torque {self.torque:.4g} N m in every direction{held}, "
            f"envelope |omega0| <= {self.max_rate:g} rad/s, any attitude): {self.status.value}\n"
            f"  {self.law}\n"
            f"  linear gains: omega_n = {self.linear.omega_n:.4g} rad/s, zeta = {self.linear.zeta:.4g} "
            f"({self.linear.status.value})\n"
            f"  predicted worst-case settling {self.predicted_time:.4g} s; asked {self.settling_time:.4g} s; "
            f"lower bound of any law {self.lower_bound:.4g} s\n"
            f"  {self.reason}"
        )


def _allocation_rows(wheels: WheelCluster) -> np.ndarray:
    """|a_i| (N,): the norms of the allocation's rows, for a cluster that controls all three axes."""
    if wheels.control_axes.shape[0] != 3:
        raise SpecificationError(
            "actuator: the design needs a wheel cluster that controls all three body axes (control_axes of 3 "
            f"rows), got {wheels.control_axes.shape[0]}"
        )
    return np.linalg.norm(allocation_matrix(wheels), axis=1)


def guaranteed_torque(actuator: ActuatorModel | WheelCluster) -> tuple[float, float]:
    """(U_min, U_max) (N m): the torque magnitude the actuator gives in every direction (the box's
    inscribed ball, or the norm limit) and the largest it gives in some direction.

    For a [`WheelCluster`][mrpctl.wheels.WheelCluster] (controlling all three axes): the allocation
    u_s = A u_c reaches wheel i's limit at |a_iᵀ u_c| = u_max,i, so every body torque of magnitude
    U_min = min_i u_max,i / |a_i| is given unclipped (the null-space term, the gyroscopic term and friction
    not counted); U_max = max |Gs u_s| over the box |u_s,i| <= u_max,i (its vertices, up to 12 wheels; the
    bound Σ u_max,i beyond)."""
    if isinstance(actuator, WheelCluster):
        rows = _allocation_rows(actuator)
        limits = np.asarray(actuator.torque_limit, dtype=float)
        if actuator.count <= _VERTEX_WHEELS:
            signs = np.array(list(itertools.product((-1.0, 1.0), repeat=actuator.count)))
            largest = float(np.linalg.norm((signs * limits) @ actuator.spin_axes.T, axis=1).max())
        else:
            largest = float(limits.sum())
        return float(np.min(limits / rows)), largest
    if not isinstance(actuator, ActuatorModel):
        raise SpecificationError(
            f"actuator must be a mrpctl.flight.ActuatorModel or a mrpctl.wheels.WheelCluster, got {actuator!r}"
        )
    limits = np.asarray(actuator.u_max, dtype=float)
    norm = actuator.norm_limit
    return min(float(np.min(limits)), norm), min(float(np.linalg.norm(limits)), norm)


def guaranteed_momentum(wheels: WheelCluster) -> float:
    """The body momentum |J ω| (N m s) the wheels take in every direction from their initial speeds.

    A body momentum p taken from the wheels (the total fixed) moves their spin momenta by the
    allocation's distribution, Js,i ΔΩ_i = a_iᵀ p; wheel i stays within its speed limit while
    |Js,i Ω_i(0) + a_iᵀ p| <= Js,i Ω_max,i, so for every direction of p
    |p| <= min_i (Js,i Ω_max,i − Js,i |Ω_i(0)|) / |a_i| (may be <= 0: a wheel starts at its limit)."""
    if not isinstance(wheels, WheelCluster):
        raise SpecificationError(f"wheels must be a mrpctl.wheels.WheelCluster, got {wheels!r}")
    rows = _allocation_rows(wheels)
    spare = wheels.spin_inertia * (wheels.speed_limit - np.abs(wheels.speeds))
    return float(np.min(spare / rows))


def slew_lower_bound(angle: float, inertia: float, torque: float) -> float:
    """2 √(θ J / u) (s): the rest-to-rest time of a slew of θ (rad) about an axis of inertia J (kg m²) at
    torque u (N m), bang-bang."""
    return 2.0 * math.sqrt(angle * inertia / torque)


def design_for_actuator(
    spacecraft: Spacecraft,
    tau: float,
    actuator: ActuatorModel | WheelCluster,
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
    actuator : mrpctl.flight.ActuatorModel or mrpctl.wheels.WheelCluster
        The body torque limits (per axis, and the norm limit), or a reaction-wheel cluster controlling all
        three axes: U and U_max from its torque limits and allocation
        ([`guaranteed_torque`][mrpctl.design.actuator.guaranteed_torque]), and the rate limit at most
        the momentum limit h of the commanded rate, |J ω| <= h, h the momentum its wheels hold in every
        direction ([`guaranteed_momentum`][mrpctl.design.actuator.guaranteed_momentum]). The prediction's cruise is
        then at most (h − J_max ``max_rate``) / J_max (the envelope's initial momentum stored first), and
        infinite when that is <= 0.
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
        On a non-positive τ, a negative or non-finite ``max_rate``, ``braking`` outside (0, 1), a
        non-positive ``settling_time``, or a wheel cluster that does not control all three axes or whose
        wheels start with no momentum to spare (a wheel at its speed limit).
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
    cause = "gyroscopic torque" if gyro_rate < math.sqrt(math.pi * a) else "time-optimal for 180 deg"
    lag = tau + 1.0 / rate_gain
    momentum = None
    cruise = math.inf  # the prediction's cruise rate beside the law's limit
    if isinstance(actuator, WheelCluster):
        momentum = guaranteed_momentum(actuator)
        if momentum <= 0.0:
            raise SpecificationError(
                f"actuator: a wheel starts at its speed limit (the wheels hold {momentum:.4g} N m s in the worst "
                "direction); start the cluster below its speed limits (WheelCluster speeds)"
            )
        cruise = (momentum - j_max * max_rate) / j_max
        law = SteeringLaw(rate_limit, a, lag, momentum_limit=momentum, spacecraft=spacecraft)
    else:
        law = SteeringLaw(rate_limit, a, lag)

    lower = slew_lower_bound(math.pi, j_min, u_max)
    predicted = (
        math.inf
        if cruise <= 0.0
        else _predicted_time(
            law, a_full, u_min, j_max, spread, max_rate, command_gain, linear.exact_decay_rate, cruise=cruise
        )
    )
    numbers = (
        f"U = {u_min:.4g} N m, J in [{j_min:.4g}, {j_max:.4g}] kg m^2: deceleration {a:.4g} rad/s^2 "
        f"({braking:g} of U/J_max), rate limit {rate_limit:.4g} rad/s ({cause})"
    )
    if momentum is not None:
        numbers += (
            f"; the wheels hold {momentum:.4g} N m s in every direction (the law's momentum limit: "
            f"{momentum / j_max:.4g} to {momentum / j_min:.4g} rad/s), "
        ) + (
            f"{momentum - j_max * max_rate:.4g} N m s once the envelope's initial momentum is stored "
            f"(a cruise of {cruise:.4g} rad/s in the worst case)"
            if cruise > 0.0
            else f"less than the envelope's initial momentum {j_max * max_rate:.4g} N m s"
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
        momentum=momentum,
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
    *,
    cruise: float = math.inf,
) -> float:
    """The kinematic estimate of the envelope's worst-case settling time (s): stop |ω₀| = ``max_rate``
    against the gyroscopic torque, slew π on the law's trapezoid (its cruise at most ``cruise``), the
    reaction lag, and the linear tail from the angle where the rate limit meets the linear command down
    to the settling tolerances."""
    left = u_min - max_rate**2 * spread
    if left <= 0.0:
        return math.inf
    stop = max_rate * j_max / left
    a, w = law.acceleration, min(law.rate_limit, cruise)
    slew = math.pi / w + w / a if math.pi >= w * w / a else 2.0 * math.sqrt(math.pi / a)
    k = command_gain
    switch = 2.0 * a * max(1.0 - law.lag * k, 0.05) / k**2  # L(φ) = k φ
    tolerance = min(4.0 * SETTLING_SIGMA, SETTLING_OMEGA / k)
    tail = math.log(max(switch / tolerance, 1.0)) / decay if decay > 0 else math.inf
    return stop + slew + law.lag + tail
