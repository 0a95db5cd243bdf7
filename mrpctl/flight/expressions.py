"""The CasADi expression builders of one flight sample (each also a small pure-SX ``casadi.Function``):
the sensor's rotation and composition, the short set, the controller-side selection and the actuator."""

from __future__ import annotations

import enum
import math
from functools import lru_cache
from typing import Any

import casadi as ca

from mrpctl.errors import SpecificationError
from mrpctl.mrp import skew_expr

__all__ = [
    "NoiseForm",
    "Saturation",
    "actuator_function",
    "compose_mrp_expr",
    "hysteresis_function",
    "measurement_function",
    "quaternion_from_mrp_expr",
    "raw_measurement_function",
    "rotation_mrp_function",
    "rotation_vector_to_mrp_expr",
    "selection_function",
    "short_expr",
]


class Saturation(enum.Enum):
    """How a torque limit acts on a commanded torque u."""

    #: One factor s ∈ (0, 1] on the whole vector: direction preserved, every limit met.
    SCALE = "scale"
    #: Each axis clipped on its own (independent actuators), then the norm limit by scaling.
    CLIP = "clip"


def rotation_vector_to_mrp_expr(theta: Any) -> Any:
    """σ = tan(|θ|/4) θ/|θ| of a rotation vector θ (rad, any angle), exactly 0 at θ = 0 (SX).

    σ = k(Φ²) θ with Φ = |θ|. For Φ <= π (|σ| <= 1), k is Cephes' rational tan (Moshier, Cephes
    2.8, ``double/tan.c``: tan x = x + x³ P(x²)/Q(x²) for |x| <= π/4, x = Φ/4), written in
    y = Φ²/16 = x² as k = 1/4 + y P(y) / (4 Q(y)): no sqrt, no tan, one division, within 1 ulp of
    tan(Φ/4)/Φ (``tests/test_sensor_rotation.py``). For Φ > π, k = tan(Φ/4)/Φ by libm (its exact
    argument reduction keeps every angle, the largest accepted noise included, the NumPy
    reference's rotation); σ may then be the long set. CasADi's if_else computes both branches
    (the virtual machine and the lanes run tan(0) on the main path); in CasADi's generated C gcc
    makes the libm call a branch, so that the main path runs neither sqrt nor tan. Both share the
    one division.
    """
    angle_squared = ca.dot(theta, theta)
    return _tan_quarter_ratio_expr(angle_squared) * theta


#: Cephes tan.c (release 2.8, June 2000, S. L. Moshier), the IEEE coefficients of P and Q (Q monic,
#: its leading 1 left out) of tan x = x + x³ P(x²)/Q(x²), |x| <= π/4; highest power first.
_TAN_P = (-1.30936939181383777646e4, 1.15351664838587416140e6, -1.79565251976484877988e7)
_TAN_Q = (1.36812963470692954678e4, -1.32089234440210967447e6, 2.50083801823357915839e7, -5.38695755929454629881e7)
#: Φ² beyond which Cephes' interval |Φ/4| <= π/4 is left (π² in float64, within an ulp of π²).
_PI_SQUARED = math.pi * math.pi


def _tan_quarter_ratio_expr(angle_squared: Any) -> Any:
    """k = tan(Φ/4)/Φ from Φ² = ``angle_squared`` (SX): 1/4 at 0; see
    [`rotation_vector_to_mrp_expr`][mrpctl.flight.rotation_vector_to_mrp_expr]."""
    y = 0.0625 * angle_squared  # x² = Φ²/16 exactly (a power of two)
    p = (_TAN_P[0] * y + _TAN_P[1]) * y + _TAN_P[2]
    q = (((y + _TAN_Q[0]) * y + _TAN_Q[1]) * y + _TAN_Q[2]) * y + _TAN_Q[3]
    wide = angle_squared > _PI_SQUARED
    # Φ > π: tan(Φ/4)/Φ as before (sqrt(0) and tan(0) where both branches are computed)
    angle = ca.sqrt(ca.if_else(wide, angle_squared, 0.0))
    numerator = ca.if_else(wide, ca.tan(0.25 * angle), y * p)
    denominator = ca.if_else(wide, angle, 4.0 * q)  # 4 Q exactly: k = 1/4 + yP/(4Q) = (1 + yP/Q)/4
    return ca.if_else(wide, 0.0, 0.25) + numerator / denominator


def compose_mrp_expr(sigma_first: Any, sigma_second: Any) -> Any:
    """σ(F/N) of `[FN] = [FB][BN]` from σ_first = σ(B/N) and σ_second = σ(F/B) (SX).

    σ = ((1 − |σ₁|²) σ₂ + (1 − |σ₂|²) σ₁ − 2 σ₂ × σ₁) / (1 + |σ₁|² |σ₂|² − 2 σ₁·σ₂)
    (Schaub & Junkins Eq. 3.152), the quaternion product written in MRPs. The result may be
    the long set. With σ₂ = 0 it returns σ₁ exactly (bit for bit).
    """
    s1 = ca.dot(sigma_first, sigma_first)
    s2 = ca.dot(sigma_second, sigma_second)
    numerator = (1 - s1) * sigma_second + (1 - s2) * sigma_first - 2 * (skew_expr(sigma_second) @ sigma_first)
    return numerator * (1 / (1 + s1 * s2 - 2 * ca.dot(sigma_first, sigma_second)))  # one division, not three


def short_expr(sigma: Any) -> Any:
    """The short set (|σ| <= 1) of σ (SX): σ unchanged when |σ|² <= 1, else −σ/|σ|²."""
    squared = ca.dot(sigma, sigma)
    return ca.if_else(squared > 1, _safe_shadow_expr(sigma, squared), sigma)


def _safe_shadow_expr(sigma: Any, squared: Any) -> Any:
    # −σ/|σ|² from |σ|² = ``squared`` (computed once by the caller: SX does not merge two dot products).
    # Both if_else branches are evaluated: keep the unused shadow of σ = 0 finite.
    return sigma * (-1 / ca.if_else(squared > 0, squared, 1.0))  # one division, not three


def quaternion_from_mrp_expr(sigma: Any) -> Any:
    """β = ((1 − |σ|²)/(1 + |σ|²), 2σ/(1 + |σ|²)) (scalar first) of σ (SX); β₀ >= 0 for a short σ."""
    squared = ca.dot(sigma, sigma)
    return ca.vertcat((1 - squared) / (1 + squared), 2 * sigma / (1 + squared))


class NoiseForm(enum.Enum):
    """How a sample receives the sensor's attitude noise.

    ``ROTATION_VECTOR``: θ (rad), and the sample computes its MRP σ(θ)
    ([`rotation_vector_to_mrp_expr`][mrpctl.flight.rotation_vector_to_mrp_expr]):
    the exported samples, the virtual machine and the lane engine. ``MRP``: σ(θ) itself, computed before the
    sample by [`rotation_mrp_function`][mrpctl.flight.rotation_mrp_function] (the same expressions, so the same bits):
    the compiled scalar
    engine, which turns a block of θ rows into their MRPs at once, so that tan's latency is not on the
    sample's path.
    """

    ROTATION_VECTOR = "rotation_vector"
    MRP = "mrp"


@lru_cache(maxsize=1)
def rotation_mrp_function() -> ca.Function:
    """``rotation_mrp(rotation_noise) -> rotation_noise_mrp``: σ(θ) of
    [`rotation_vector_to_mrp_expr`][mrpctl.flight.rotation_vector_to_mrp_expr] (pure SX)."""
    theta = ca.SX.sym("rotation_noise", 3)
    return ca.Function(
        "rotation_mrp", [theta], [rotation_vector_to_mrp_expr(theta)], ["rotation_noise"], ["rotation_noise_mrp"]
    )


def _sensor_expressions(form: NoiseForm) -> tuple[list[Any], list[str], Any, Any]:
    """The sensor's inputs (x, rotation noise, rate noise, bias), their names, σ ⊕ σ(θ) (either set) and ω̃."""
    if not isinstance(form, NoiseForm):
        raise SpecificationError(f"form must be a mrpctl.flight.NoiseForm, got {form!r}")
    x = ca.SX.sym("x", 6)
    noise_name = "rotation_noise" if form is NoiseForm.ROTATION_VECTOR else "rotation_noise_mrp"
    noise = ca.SX.sym(noise_name, 3)
    eta = ca.SX.sym("rate_noise", 3)
    bias = ca.SX.sym("bias", 3)
    rotation = rotation_vector_to_mrp_expr(noise) if form is NoiseForm.ROTATION_VECTOR else noise
    omega_meas = 4 * x[3:6] + bias + eta
    names = ["x", noise_name, "rate_noise", "bias"]
    return [x, noise, eta, bias], names, compose_mrp_expr(x[0:3], rotation), omega_meas


@lru_cache(maxsize=2)
def measurement_function(form: NoiseForm = NoiseForm.ROTATION_VECTOR) -> ca.Function:
    """``measurement(x, rotation_noise, rate_noise, bias) -> (x_meas, q_meas)`` (pure SX).

    x = [σ; ω/4] is the true state (σ in either set). The sensor reports the short set of
    the measured attitude, σ̃ = short(σ ⊕ σ(θ)) with [B̃N] = [B̃B](θ)[BN], the rate
    ω̃ = ω + b + η, and x_meas = [σ̃; ω̃/4]; q_meas is σ̃'s quaternion (β₀ >= 0). With zero
    noise and bias and a short σ, x_meas is x bit for bit. With ``form`` = `NoiseForm.MRP` the
    second input is σ(θ) (``rotation_noise_mrp``, from [`rotation_mrp_function`][mrpctl.flight.rotation_mrp_function])
    instead of θ:
    the same numbers, bit for bit. [`raw_measurement_function`][mrpctl.flight.raw_measurement_function] is the same
    before the short set.
    """
    inputs, names, composed, omega_meas = _sensor_expressions(form)
    sigma_meas = short_expr(composed)
    x_meas = ca.vertcat(sigma_meas, 0.25 * omega_meas)  # = omega_meas / 4 exactly (a power of two)
    return ca.Function(
        "measurement", inputs, [x_meas, quaternion_from_mrp_expr(sigma_meas)], names, ["x_meas", "q_meas"]
    )


@lru_cache(maxsize=2)
def raw_measurement_function(form: NoiseForm = NoiseForm.ROTATION_VECTOR) -> ca.Function:
    """``raw_measurement(x, rotation_noise, rate_noise, bias) -> x_raw`` (pure SX): [σ ⊕ σ(θ); ω̃/4].

    [`measurement_function`][mrpctl.flight.measurement_function] before its short set: the attitude in either set, so
    that
    x_meas = [short(x_raw[0:3]); x_raw[3:6]] bit for bit. The flight sample puts x_raw in its ring
    and takes the short set of the delayed entry, which it needs for the history anyway: one short
    set a sample, not two.
    """
    inputs, names, composed, omega_meas = _sensor_expressions(form)
    return ca.Function("raw_measurement", inputs, [ca.vertcat(composed, 0.25 * omega_meas)], names, ["x_raw"])


@lru_cache(maxsize=1)
def hysteresis_function() -> ca.Function:
    """``hysteresis(h, q, delta) -> (h_next, sigma_c, switched)`` (pure SX): the Mayhew-Sanfelice-Teel rule.

    q (4, scalar first, unit) is the measured quaternion, continuous in time (its sign
    chosen by continuity, not by β₀ >= 0). h_next = −h when h q₀ < −δ, else h;
    σ_c = h_next q_v / (1 + h_next q₀); switched = 1.0 when h flipped.
    """
    h = ca.SX.sym("h")
    q = ca.SX.sym("q", 4)
    delta = ca.SX.sym("delta")
    switched = ca.if_else(h * q[0] < -delta, 1.0, 0.0)
    h_next = ca.if_else(switched, -h, h)
    sigma_c = h_next * q[1:4] / (1 + h_next * q[0])
    return ca.Function(
        "hysteresis", [h, q, delta], [h_next, sigma_c, switched], ["h", "q", "delta"], ["h_next", "sigma_c", "switched"]
    )


@lru_cache(maxsize=1)
def selection_function() -> ca.Function:
    """``selection(h, c, sigma_meas, sigma_prev, delta) -> (h_next, c_next, sigma_c, switched)`` (pure SX).

    The controller-side rule on the sensor's short-set MRP σ̃ (β̃₀ >= 0), in the form the
    flight sample uses. The controller's continuous quaternion is q̂ = c β̃: c ∈ {−1, +1}
    flips when β̃ and the previous measurement's β̃' point to opposite hemispheres,
    β̃·β̃' < 0 ⇔ (1 − |σ̃|²)(1 − |σ̃'|²) + 4 σ̃·σ̃' < 0 (the attitude passed Φ = 180°).
    Then the rule of [`hysteresis_function`][mrpctl.flight.hysteresis_function] on q̂: with e = h c, h flips when
    e β̃₀ < −δ ⇔ e < 0 and (1 + δ)|σ̃|² < 1 − δ. σ_c = σ̃ when h_next c_next = +1 (bit for
    bit) and its shadow −σ̃/|σ̃|² otherwise. Identical to [`hysteresis_function`][mrpctl.flight.hysteresis_function] on
    q̂ up
    to rounding; with δ = 0 σ_c is σ̃ at every sample. h and c are ±1 (flips are products by ±1).
    """
    h = ca.SX.sym("h")
    c = ca.SX.sym("c")
    sigma = ca.SX.sym("sigma_meas", 3)
    previous = ca.SX.sym("sigma_prev", 3)
    delta = ca.SX.sym("delta")
    s_now = ca.dot(sigma, sigma)
    s_prev = ca.dot(previous, previous)
    flipped = (1 - s_now) * (1 - s_prev) + 4 * ca.dot(sigma, previous) < 0
    # h, c = ±1: a flip is a product by ±1 (exact), not an if_else (two selects and an add)
    c_next = c * (1 - 2 * flipped)
    effective = h * c_next
    switched = ca.if_else(ca.logic_and(effective < 0, (1 + delta) * s_now < 1 - delta), 1.0, 0.0)
    h_next = h * (1 - 2 * switched)
    # σ_c = σ (e = h_next c_next = +1) or its shadow −σ/|σ|²: σ times one selected factor, not three
    # selected components. if_else(e > 0, σ, shadow) was (e > 0 ? σ : 0) + (e <= 0 ? shadow : 0), which
    # turns a −0 into +0: so does the + (e² − 1) = +0 here (an exact zero that CasADi does not fold away).
    e = h_next * c_next
    factor = ca.if_else(e > 0, 1.0, -1 / ca.if_else(s_now > 0, s_now, 1.0))
    sigma_c = sigma * factor + (e * e - 1)
    return ca.Function(
        "selection",
        [h, c, sigma, previous, delta],
        [h_next, c_next, sigma_c, switched],
        ["h", "c", "sigma_meas", "sigma_prev", "delta"],
        ["h_next", "c_next", "sigma_c", "switched"],
    )


@lru_cache(maxsize=2)
def actuator_function(mode: Saturation = Saturation.SCALE) -> ca.Function:
    """``actuator(u, u_max, norm_max, w) -> (u_applied, u_plant, saturated)`` (pure SX).

    ``SCALE``: u_applied = u / r with r = max(maxᵢ |uᵢ|/u_max,ᵢ, |u|/u_norm) when r > 1
    (direction preserved), then clipped per axis so that rounding never exceeds u_max.
    ``CLIP``: uᵢ clipped to [−u_max,ᵢ, u_max,ᵢ], then scaled by u_norm/|u| if |u| > u_norm.
    A limit that is not reached leaves u bit for bit; ``norm_max`` = inf means no norm limit.
    u_plant = u_applied + w (the disturbance torque). saturated = 1.0 when a limit acted.
    """
    if not isinstance(mode, Saturation):
        raise SpecificationError(f"mode must be a mrpctl.flight.Saturation, got {mode!r}")
    u = ca.SX.sym("u", 3)
    u_max = ca.SX.sym("u_max", 3)
    norm_max = ca.SX.sym("norm_max")
    w = ca.SX.sym("w", 3)
    if mode is Saturation.SCALE:
        ratio = ca.fmax(ca.mmax(ca.fabs(u) / u_max), ca.norm_2(u) / norm_max)
        saturated = ratio > 1
        # u / r when r > 1, else u: one divisor selected, not three quotients (u / 1 is u exactly); the
        # if_else added +0 to the chosen branch (−0 → +0), and so does saturated² − saturated (= +0)
        scaled = u / ca.if_else(saturated, ratio, 1.0) + (saturated * saturated - saturated)
        applied = ca.fmin(ca.fmax(scaled, -u_max), u_max)
    else:
        clipped = ca.fmin(ca.fmax(u, -u_max), u_max)
        ratio = ca.norm_2(clipped) / norm_max
        scaled = ratio > 1
        applied = clipped / ca.if_else(scaled, ratio, 1.0) + (scaled * scaled - scaled)  # as in SCALE
        saturated = ca.logic_or(ca.mmax(ca.fabs(u) - u_max) > 0, ratio > 1)
    return ca.Function(
        "actuator",
        [u, u_max, norm_max, w],
        [applied, applied + w, saturated],  # a comparison: 1.0 or 0.0
        ["u", "u_max", "norm_max", "w"],
        ["u_applied", "u_plant", "saturated"],
    )
