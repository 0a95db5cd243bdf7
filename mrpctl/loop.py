"""The closed loop as CasADi Functions: controller, rule, RK4 step, one sample, one chunk.

Shared by [`mrpctl.simulation`][mrpctl.simulation] (whose engine adds the metric accumulators and a C
horizon driver around [`core_function`][mrpctl.loop.core_function]) and [`mrpctl.export`][mrpctl._export.export] (which
generates
C for [`closed_loop_functions`][mrpctl.loop.closed_loop_functions]). The model (paper Eq. nonc, sampled; see
``design/switching.md``)::

    ẋ(t) = A x + B u(t) + f(x),   x = [σ; ω/4]
    u(t) = u_k = K m_{k−d}          for t in [t_k, t_{k+1}),  t_k = k h,  h = 1/rate
    m_k  = rule(x(t_k), m_{k−d})    the state after the switching rule at t_k

with τ = d h (d an integer >= 0). At each sample k: (1) the rule may replace σ_k by its
shadow; (2) the result is recorded as the measurement m_k; (3) u_k = K m_{k−d} is held
over one period (zero-order hold; for d = 0, u_k = K m_k); (4) the plant of
[`mrpctl.model.dynamics_expr`][mrpctl.model.dynamics_expr] is integrated over one period by RK4 with a fixed
number of substeps.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from mrpctl._validation import check_spacecraft, integer, nonnegative_scalar, positive_scalar, readonly
from mrpctl.errors import SpecificationError
from mrpctl.flight import (
    FLIGHT_CONSTANTS_SIZE,
    FLIGHT_MEMORY_SIZE,
    NOISE_SIZE,
    ActuatorModel,
    DelayModel,
    Disturbance,
    Hysteretic,
    NoiseForm,
    Saturation,
    SensorModel,
    actuator_function,
    measurement_function,
    quaternion_from_mrp_expr,
    raw_measurement_function,
    selection_function,
    short_expr,
)
from mrpctl.model import INPUT_SIZE, STATE_SIZE, dynamics_expr, gain_matrix, plant_model
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import MEMORY_SIZE, PARAMETER_SIZE, OnCurrent, SwitchingRule

__all__ = [
    "CONTROLLER_MEMORY_SIZE",
    "MAX_SUBSTEPS",
    "PREDICTOR_MEMORY_SIZE",
    "PREDICTOR_RING_WIDTH",
    "ClosedLoopFunctions",
    "FlightOptions",
    "InertiaInput",
    "check_rule",
    "check_substeps",
    "closed_loop_functions",
    "core_function",
    "delay_samples",
    "flight_core_function",
    "inertia_input",
    "inertia_values",
    "predictor_constants_size",
    "predictor_core_function",
    "step_function",
]

_DELAY_TOLERANCE = 1e-9
#: RK4 substeps per measurement period at most. The step is unrolled into the generated
#: code (about 0.5 kB of C and 0.1 s of gcc per substep): 64 substeps already make h/64 a
#: step far below any period the loop can resolve, while 1000 would take minutes and
#: > 2 GB to compile. For a finer integration raise the rate instead.
MAX_SUBSTEPS = 64


# =============================================================================== inputs
def delay_samples(tau: Any, rate: Any) -> int:
    """d = τ · rate as an integer (τ in s, rate in Hz).

    Raises
    ------
    SpecificationError
        If τ < 0, rate <= 0, or τ · rate is not an integer to 1e-9 (relative, at least 1e-9 absolute).
    """
    tau = nonnegative_scalar("tau", tau)
    rate = positive_scalar("rate", rate)
    samples = tau * rate
    if not math.isfinite(samples) or samples > 2.0**53:
        raise SpecificationError(
            f"tau * rate must be a whole number of measurement periods below 2^53: tau = {tau!r} s and "
            f"rate = {rate!r} Hz give tau * rate = {samples!r}"
        )
    d = round(samples)
    if abs(samples - d) > _DELAY_TOLERANCE * max(1.0, abs(samples)):  # relative: tau * rate is rounded
        raise SpecificationError(
            f"tau * rate must be a whole number of measurement periods: tau = {tau!r} s and "
            f"rate = {rate!r} Hz give tau * rate = {samples!r}; choose tau as a multiple of 1/rate"
        )
    return int(d)


def check_rule(rule: Any, name: str = "rule") -> SwitchingRule:
    """Return ``rule`` if it is a [`SwitchingRule`][mrpctl.switching.SwitchingRule], else raise SpecificationError."""
    if not isinstance(rule, SwitchingRule):
        raise SpecificationError(
            f"{name} must be a switching rule such as mrpctl.switching.OnDelayed(), got {type(rule).__name__}: {rule!r}"
        )
    return rule


def check_substeps(substeps: Any) -> int:
    """RK4 substeps per measurement period: an integer in 1 .. `MAX_SUBSTEPS`."""
    if isinstance(substeps, int | np.integer) and not isinstance(substeps, bool) and substeps > MAX_SUBSTEPS:
        raise SpecificationError(
            f"substeps must be <= {MAX_SUBSTEPS}, got {substeps}: each substep is unrolled into the compiled "
            f"code (1000 substeps take minutes and > 2 GB to compile); for a finer step raise rate instead"
        )
    return integer("substeps", substeps, minimum=1)


# ================================================================ symbolic building blocks
class InertiaInput(enum.Enum):
    """How a run-time inertia enters a compiled Function (see [`inertia_input`][mrpctl.loop.inertia_input])."""

    #: J and J⁻¹ diagonal: two 3-vectors (the diagonals), the same operations as constants.
    DIAGONAL = "diagonal"
    #: Full 3 × 3 J and J⁻¹ (column-major).
    FULL = "full"


def inertia_input(spacecraft: Spacecraft) -> InertiaInput:
    """DIAGONAL when both J and J⁻¹ of ``spacecraft`` are exactly diagonal, else FULL."""
    for matrix in (spacecraft.inertia, spacecraft.inertia_inverse):
        if np.any(matrix != np.diag(np.diag(matrix))):
            return InertiaInput.FULL
    return InertiaInput.DIAGONAL


def inertia_values(spacecraft: Spacecraft, kind: InertiaInput) -> tuple[np.ndarray, np.ndarray]:
    """The run-time inputs J, J⁻¹ of ``spacecraft`` for a Function built with ``kind`` (contiguous)."""
    if kind is InertiaInput.DIAGONAL:
        return np.diag(spacecraft.inertia).copy(), np.diag(spacecraft.inertia_inverse).copy()
    return np.ascontiguousarray(spacecraft.inertia.T), np.ascontiguousarray(spacecraft.inertia_inverse.T)


def _inertia_symbols(kind: InertiaInput) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX]:
    """(J input, J⁻¹ input, J as 3 × 3, J⁻¹ as 3 × 3); diagonal matrices are structurally diagonal."""
    if kind is InertiaInput.DIAGONAL:
        j, j_inv = ca.SX.sym("J", 3), ca.SX.sym("J_inv", 3)
        return j, j_inv, ca.diag(j), ca.diag(j_inv)
    j, j_inv = ca.SX.sym("J", 3, 3), ca.SX.sym("J_inv", 3, 3)
    return j, j_inv, j, j_inv


def step_function(
    spacecraft: Spacecraft, period: float, substeps: int, *, inertia: InertiaInput | None = None
) -> ca.Function:
    """``step(x, u) -> x_next``: RK4 over one period h with ``substeps`` equal substeps.

    With ``inertia`` the spacecraft's J and J⁻¹ are inputs instead of constants:
    ``step(x, u, J, J_inv) -> x_next`` (the layout of ``inertia``, see [`InertiaInput`][mrpctl.loop.InertiaInput]).
    """
    x = ca.SX.sym("x", STATE_SIZE)
    u = ca.SX.sym("u", INPUT_SIZE)
    extra: list[ca.SX] = []
    if inertia is None:
        dynamics = plant_model(spacecraft).dynamics
    else:
        j_in, j_inv_in, j, j_inv = _inertia_symbols(inertia)
        extra = [j_in, j_inv_in]
        xdot = dynamics_expr(None, x, u, inertia=j, inertia_inverse=j_inv)
        dynamics = ca.Function("dynamics", [x, u, j_in, j_inv_in], [xdot])
    dt = period / substeps
    z = x
    for _ in range(substeps):
        k1 = dynamics(z, u, *extra)
        k2 = dynamics(z + (dt / 2) * k1, u, *extra)
        k3 = dynamics(z + (dt / 2) * k2, u, *extra)
        k4 = dynamics(z + dt * k3, u, *extra)
        z = z + (dt / 6) * (k1 + 2 * k2 + 2 * k3 + k4)
    names = ["x", "u"] + (["J", "J_inv"] if extra else [])
    return ca.Function("step", [x, u, *extra], [z], names, ["x_next"])


def core_function(
    spacecraft: Spacecraft,
    rule: SwitchingRule,
    d: int,
    period: float,
    substeps: int,
    *,
    inertia: InertiaInput | None = None,
) -> ca.Function:
    """One sample with K and the rule parameters as inputs (pure SX).

    ``core(x, memory, x_delayed, K, parameters) -> (x_next, memory_next, x_meas, u, switched)``;
    with ``inertia``, J and J⁻¹ are two more inputs (``..., parameters, J, J_inv``).
    """
    if isinstance(rule, Hysteretic):
        raise SpecificationError(
            "rule: Hysteretic is a controller-side rule; build its sample with flight_core_function"
        )
    step = step_function(spacecraft, period, substeps, inertia=inertia)
    x = ca.SX.sym("x", STATE_SIZE)
    memory = ca.SX.sym("memory", MEMORY_SIZE)
    x_delayed = ca.SX.sym("x_delayed", STATE_SIZE)
    gain = ca.SX.sym("K", INPUT_SIZE, STATE_SIZE)
    parameters = ca.SX.sym("parameters", PARAMETER_SIZE)
    extra = [] if inertia is None else list(_inertia_symbols(inertia)[:2])
    seen_by_rule = x_delayed if d > 0 else x
    x_meas, memory_next, switched = rule.expressions(x, seen_by_rule, memory, delay_samples=d, parameters=parameters)
    u = gain @ (x_delayed if d > 0 else x_meas)
    x_next = step(x_meas, u, *extra)
    return ca.Function(
        "core",
        [x, memory, x_delayed, gain, parameters, *extra],
        [x_next, memory_next, x_meas, u, switched],
        ["x", "memory", "x_delayed", "K", "parameters"] + (["J", "J_inv"] if extra else []),
        ["x_next", "memory_next", "x_meas", "u", "switched"],
    )


def flight_core_function(
    spacecraft: Spacecraft,
    d: int,
    period: float,
    substeps: int,
    *,
    inertia: InertiaInput | None = None,
    saturation: Saturation = Saturation.SCALE,
    sensor: bool = True,
    limited: bool = True,
    disturbed: bool = True,
    records: bool = False,
    torque_input: bool = False,
    noise_form: NoiseForm = NoiseForm.ROTATION_VECTOR,
    short_measurements: bool = False,
    squared_peak: bool = False,
) -> ca.Function:
    """One sample of the flight loop with the controller-side rule [`Hysteretic`][mrpctl.flight.Hysteretic] (pure SX).

    ``core(x, memory, x_delayed, K, parameters[, J, J_inv], flight, noise) ->
    (x_next, memory_next, x_meas, u, switched, measurement)``:
    the ports of [`core_function`][mrpctl.loop.core_function] with memory (h, c, σ̃_prev, n_sat, peak |u_c,i| (3), peak
    |u_c|)
    of `FLIGHT_MEMORY_SIZE`, parameters (δ,), the run-time constants
    ``flight`` = (u_max (3), u_norm, w (3), gyro bias (3)) (N m, rad/s; inf: no limit), and per
    sample ``noise`` = (θ_k, η_k) (rad, rad/s). Without ``sensor`` the ``noise`` input and the
    ``measurement`` output are left out and the measurement is the bookkept state (the
    virtual machine's form). The sample is specialised by structure, each form giving the full
    sample's numbers bit for bit on the runs it serves: without ``sensor`` for an ideal sensor
    (no noise, no bias: m_k = x_meas exactly), without ``limited`` for no actuator limit
    (u_max = u_norm = inf: u = u_c, the saturated count stays 0; u_max, u_norm unused), without
    ``disturbed`` for w = 0 (u + w = u; w unused). With ``records`` a last output ``record`` =
    (h_{k+1}, σ_c,k, u_c,k) (the logic variable after the rule, the MRP the control law used, the
    commanded torque before the actuator limits, N m): the result's per-sample records. With
    ``torque_input`` a last input ``torque`` (3, N m) is the disturbance w_k of the sample (a
    per-sample disturbance streamed by the engine; the constant w in ``flight`` is then unused).
    ``noise_form`` ([`NoiseForm`][mrpctl.flight.NoiseForm]): with ``MRP`` the first half of ``noise`` is the
    attitude noise's MRP σ(θ_k) ([`rotation_mrp_function`][mrpctl.flight.rotation_mrp_function], computed by the engine
    before the sample) instead of θ_k: the same numbers bit for bit.
    With ``short_measurements`` (only without ``sensor``) the controller reads ``x_delayed`` (and,
    for d = 0, m_k) as it is, without taking its short set: the same numbers bit for bit for a
    caller whose history rows are in the short set already (the compiled engine maps them through
    the same SX, ``mrpctl.simulation._engine.short_history``), as every m_k the sample writes is then
    x_meas, bookkept by ``OnCurrent``, a fixed point of the short-set map (design/flight.md, phase
    8b); a sensor's entries are its measurements, whose short set the controller takes. With
    ``squared_peak`` the memory's last entry is the peak |u_c|² (N² m²): one square root at the end
    gives the peak |u_c| bit for bit (the correctly rounded square root is monotone: the max of the
    roots is the root of the max), instead of one a sample (the compiled engine's, ``Engine.run``).
    At sample k:

    1. plant bookkeeping: σ_k ← its shadow when |σ_k|² >= 1 (the ``OnCurrent`` expressions;
       no physical effect): x_meas, the true state recorded in the result;
    2. the sensor ([`raw_measurement_function`][mrpctl.flight.raw_measurement_function]): m_k = [σ_k ⊕ σ(θ_k); ω̃_k/4]
       (the ring's entry, the attitude in either set; x_meas bit for bit without noise and bias);
    3. the controller reads the delayed measurement m_{k−d} (m_k when d = 0), takes its short
       set σ̃ and applies [`selection_function`][mrpctl.flight.selection_function] with its memory
       (h, c, σ̃_prev) and δ: σ_c, and ``switched`` = 1.0 when h flipped (the run's switches);
    4. u_c = K [σ_c; ω̃_{k−d}/4]; the actuator ([`actuator_function`][mrpctl.flight.actuator_function] of
       ``saturation``) gives the applied torque u (the ``u`` output), and u + w is held over
       the period while the plant is integrated by RK4.

    With δ = 0, no limit (inf) and w = 0, σ_c = σ̃ at every sample and u is ``OnCurrent``'s
    K m_{k−d} bit for bit.
    """
    if short_measurements and sensor:
        raise SpecificationError("short_measurements: only without a sensor (its measurements are not bookkept)")
    step = step_function(spacecraft, period, substeps, inertia=inertia)
    x = ca.SX.sym("x", STATE_SIZE)
    memory = ca.SX.sym("memory", FLIGHT_MEMORY_SIZE)
    x_delayed = ca.SX.sym("x_delayed", STATE_SIZE)
    gain = ca.SX.sym("K", INPUT_SIZE, STATE_SIZE)
    parameters = ca.SX.sym("parameters", PARAMETER_SIZE)
    extra = [] if inertia is None else list(_inertia_symbols(inertia)[:2])
    flight = ca.SX.sym("flight", FLIGHT_CONSTANTS_SIZE)
    noise = ca.SX.sym("noise", NOISE_SIZE)
    torque = ca.SX.sym("torque", INPUT_SIZE)
    w = torque if torque_input else flight[4:7]
    disturbed = disturbed or torque_input
    x_meas = OnCurrent().expressions(x, x, memory[0:MEMORY_SIZE], delay_samples=d)[0]
    # the ring holds the sensor's raw measurement (either set); the short set of the entry read is taken here,
    # as for the history's entries: the same σ̃ as measurement_function's, bit for bit
    measure = raw_measurement_function(noise_form)
    measured = measure.call([x_meas, noise[0:3], noise[3:6], flight[7:10]])[0] if sensor else x_meas
    seen = x_delayed if d > 0 else measured
    # without a sensor m_k is x_meas, bookkept short by OnCurrent: only a history row may be long
    sigma_seen = seen[0:3] if short_measurements else short_expr(seen[0:3])
    h_next, c_next, sigma_c, switched = selection_function()(
        memory[0], memory[1], sigma_seen, memory[2:5], parameters[0]
    )
    command = gain @ ca.vertcat(sigma_c, seen[3:6])
    if limited:
        u, u_plant, saturated = actuator_function(saturation)(command, flight[0:3], flight[3], w)
        count = memory[5] + saturated
        if not disturbed:
            u_plant = u
    else:
        # + the saturated count (0 in a run without a limit): −0 becomes +0, as the full sample's
        # if_else in the actuator does (the recorded u keeps its bits, sign of zero included)
        u, count = command + memory[5], memory[5]
        u_plant = u + w if disturbed else u
    x_next = step(x_meas, u_plant, *extra)
    size = ca.fabs(command)
    memory_next = ca.vertcat(
        h_next,
        c_next,
        sigma_seen,
        count,
        ca.fmax(memory[6:9], size),
        ca.fmax(memory[9], ca.sumsqr(command) if squared_peak else ca.norm_2(command)),
    )
    names = ["x", "memory", "x_delayed", "K", "parameters"] + (["J", "J_inv"] if extra else []) + ["flight"]
    inputs = [x, memory, x_delayed, gain, parameters, *extra, flight] + ([noise] if sensor else [])
    names += ["noise"] if sensor else []
    if torque_input:
        inputs.append(torque)
        names.append("torque")
    output_names = ["x_next", "memory_next", "x_meas", "u", "switched"] + (["measurement"] if sensor else [])
    outputs = [x_next, memory_next, x_meas, u, switched] + ([measured] if sensor else [])
    if records:
        output_names.append("record")
        outputs.append(ca.vertcat(h_next, sigma_c, command))
    return ca.Function("core", inputs, outputs, names, output_names)


#: The predictor sample's memory: (1, 1, σ̂_prev (3), the actuator accumulators of the flight sample (5),
#: the model copy z (6)); entries 2..9 mean what they mean in the flight sample's memory.
PREDICTOR_MEMORY_SIZE = FLIGHT_MEMORY_SIZE + STATE_SIZE
#: One ring entry of the predictor sample: the measurement m_k and the model copy z_k.
PREDICTOR_RING_WIDTH = 2 * STATE_SIZE
#: Below this |σ̂|² the continuity test of the predicted MRP is skipped (its shadow is far away).
_CONTINUITY_FLOOR = 1e-8
_SMALL_ROTATION = 1e-4


def predictor_constants_size(model_inertia: InertiaInput) -> int:
    """Length of the predictor sample's ``flight`` input: the flight constants, τ, J_m and J_m⁻¹."""
    per_matrix = 3 if model_inertia is InertiaInput.DIAGONAL else 9
    return FLIGHT_CONSTANTS_SIZE + 1 + 2 * per_matrix


def _quaternion_product(a: Any, b: Any) -> Any:
    """β of [FN] = C(a) C(b) with a = β(F/B), b = β(B/N) (scalar first; Schaub & Junkins Eq. 3.105)."""
    scalar = a[0] * b[0] - ca.dot(a[1:4], b[1:4])
    vector = a[0] * b[1:4] + b[0] * a[1:4] - ca.cross(a[1:4], b[1:4])
    return ca.vertcat(scalar, vector)


def _rotation_quaternion(theta: Any) -> Any:
    """β of [BN] = exp(−[θ×]) (a rotation by the vector θ, rad): (cos(φ/2), sin(φ/2) θ/φ), φ = |θ|."""
    squared = ca.dot(theta, theta)
    angle = ca.sqrt(squared)
    small = angle < _SMALL_ROTATION
    safe = ca.if_else(small, 1.0, angle)
    # sin(φ/2)/φ and its series 1/2 − φ²/48 + φ⁴/3840 near 0 (both if_else branches are evaluated).
    factor = ca.if_else(small, 0.5 - squared / 48.0 + squared**2 / 3840.0, ca.sin(safe / 2.0) / safe)
    return ca.vertcat(ca.cos(angle / 2.0), factor * theta)


def _short_mrp_from_quaternion(q: Any) -> Any:
    """The short-set MRP of a unit quaternion (either sign): q_v/(1 + q₀) for q₀ >= 0, else −q_v/(1 − q₀)."""
    positive = q[0] >= 0
    return ca.if_else(positive, q[1:4] / (1 + q[0]), -q[1:4] / (1 - q[0]))


def predictor_core_function(
    spacecraft: Spacecraft,
    d: int,
    period: float,
    substeps: int,
    *,
    inertia: InertiaInput | None = None,
    model_inertia: InertiaInput = InertiaInput.DIAGONAL,
    saturation: Saturation = Saturation.SCALE,
    sensor: bool = False,
    limited: bool = True,
    torque_input: bool = False,
) -> ca.Function:
    """One sample of the predictor loop (``design/predictor.md``, form (b)) (pure SX).

    ``core(x, memory, x_delayed, K, parameters[, J, J_inv], flight[, noise][, torque]) ->
    (x_next, memory_next, x_meas, u, switched, ring)``: memory of `PREDICTOR_MEMORY_SIZE`
    (1, 1, σ̂_prev, the flight sample's actuator accumulators, the model copy z); ``x_delayed`` and
    ``ring`` are entries of `PREDICTOR_RING_WIDTH`: (m_k, z_k), read back as (y_k, z_{k−d}) =
    (m_{k−d}, z_{k−d}); parameters (α,) (inf: never switch); ``flight`` = (u_max (3), u_norm,
    w (3), gyro bias (3), τ, J_m, J_m⁻¹) with the model's inertia in the layout ``model_inertia``;
    ``noise`` (with ``sensor``) as in [`flight_core_function`][mrpctl.loop.flight_core_function]. Without ``limited``
    the
    actuator is left out of the expressions (u = u_c; u_max, u_norm unused), which saves its
    libm calls. With ``torque_input`` a last input ``torque`` (3, N m) is the disturbance w_k of the
    sample (a per-sample disturbance streamed by the engine; the constant w in ``flight`` is then
    unused); like the constant w it acts on the plant only. At sample k:

    1. plant bookkeeping (``OnCurrent``, no physical effect): x_meas, recorded in the result;
    2. the sensor (with ``sensor``): m_k, else m_k = x_meas;
    3. the prediction from y = m_{k−d} (m_k when d = 0) and the model copy: the inertial attitude
       error C_E = C(z_{k−d})ᵀ C(y) and the body-rate error δω = ω_y − ω_z(k−d) are carried to now,
       Ĉ = C(τ δω) C(z_k) C_E and ω̂ = ω_z(k) + δω (quaternion products, no DCM);
    4. the rule on the prediction: σ̂ is the short MRP of Ĉ, replaced by its shadow when that is
       nearer σ̂_{k−1} (continuity, when |σ̂|² > 1e-8), then by its shadow when |σ̂| >= α, which is
       the sample's ``switched``;
    5. u_c = K [σ̂; ω̂/4]; the actuator gives the applied torque u; the plant is integrated with
       u + w (``substeps`` RK4 substeps), the model copy with u alone by one RK4 step of J_m, and
       kept in the short set: z_{k+1} = short(RK4_m(z_k, u)). The controller does not know w: the
       copy never sees it, it enters the prediction only through the measurement y.
    """
    step = step_function(spacecraft, period, substeps, inertia=inertia)
    model_step = step_function(spacecraft, period, 1, inertia=model_inertia)
    x = ca.SX.sym("x", STATE_SIZE)
    memory = ca.SX.sym("memory", PREDICTOR_MEMORY_SIZE)
    x_delayed = ca.SX.sym("x_delayed", PREDICTOR_RING_WIDTH)
    gain = ca.SX.sym("K", INPUT_SIZE, STATE_SIZE)
    parameters = ca.SX.sym("parameters", PARAMETER_SIZE)
    extra = [] if inertia is None else list(_inertia_symbols(inertia)[:2])
    flight = ca.SX.sym("flight", predictor_constants_size(model_inertia))
    noise = ca.SX.sym("noise", NOISE_SIZE)
    torque = ca.SX.sym("torque", INPUT_SIZE)
    w = torque if torque_input else flight[4:7]
    per_matrix = 3 if model_inertia is InertiaInput.DIAGONAL else 9
    start = FLIGHT_CONSTANTS_SIZE + 1
    model_j = flight[start : start + per_matrix]
    model_j_inv = flight[start + per_matrix : start + 2 * per_matrix]
    if model_inertia is InertiaInput.FULL:
        model_j, model_j_inv = ca.reshape(model_j, 3, 3), ca.reshape(model_j_inv, 3, 3)
    tau = flight[FLIGHT_CONSTANTS_SIZE]

    x_meas = OnCurrent().expressions(x, x, memory[0:MEMORY_SIZE], delay_samples=d)[0]
    measured = measurement_function()(x_meas, noise[0:3], noise[3:6], flight[7:10])[0] if sensor else x_meas
    z = memory[FLIGHT_MEMORY_SIZE:PREDICTOR_MEMORY_SIZE]
    y, z_old = (x_delayed[0:STATE_SIZE], x_delayed[STATE_SIZE:]) if d > 0 else (measured, z)
    x_hat, switched = prediction_expr(y, z_old, z, memory[2:5], parameters[0], tau)
    sigma_hat = x_hat[0:3]

    command = gain @ x_hat
    if limited:
        u, u_plant, saturated = actuator_function(saturation)(command, flight[0:3], flight[3], w)
    else:
        u, u_plant, saturated = command, command + w, ca.DM(0.0)
    x_next = step(x_meas, u_plant, *extra)
    z_next = model_step(z, u, model_j, model_j_inv)
    z_next = ca.vertcat(short_expr(z_next[0:3]), z_next[3:6])
    # the peaks by comparisons: casadi_fmax is a libm call per use (no -ffinite-math-only)
    size = [ca.fabs(command[i]) for i in range(INPUT_SIZE)]
    peaks = [ca.if_else(size[i] > memory[6 + i], size[i], memory[6 + i]) for i in range(INPUT_SIZE)]
    norm = ca.norm_2(command)
    memory_next = ca.vertcat(
        memory[0:2],
        sigma_hat,
        memory[5] + saturated,
        *peaks,
        ca.if_else(norm > memory[9], norm, memory[9]),
        z_next,
    )
    inputs = [x, memory, x_delayed, gain, parameters, *extra, flight] + ([noise] if sensor else [])
    names = ["x", "memory", "x_delayed", "K", "parameters"] + (["J", "J_inv"] if extra else []) + ["flight"]
    names += ["noise"] if sensor else []
    if torque_input:
        inputs.append(torque)
        names.append("torque")
    return ca.Function(
        "core",
        inputs,
        [x_next, memory_next, x_meas, u, switched, ca.vertcat(measured, z)],
        names,
        ["x_next", "memory_next", "x_meas", "u", "switched", "ring"],
    )


def prediction_expr(y: Any, z_old: Any, z: Any, previous: Any, alpha: Any, tau: Any) -> tuple[Any, Any]:
    """(x̂, switched): the predictor's correction and its switching rule as SX expressions.

    From the delayed measurement y = [σ_y; ω_y/4], the model copy z_{k−d} (``z_old``) and z_k (``z``),
    the previous σ̂ (``previous``), α and τ (s): Ĉ = C(τ δω) C(z_k) C(z_{k−d})ᵀ C(y) by quaternion
    products, σ̂ its short MRP, the shadow when nearer ``previous`` (|σ̂|² > 1e-8), then the shadow
    when |σ̂|² >= α² (``switched`` = 1.0); x̂ = [σ̂; ω_z(k)/4 + (ω_y − ω_z(k−d))/4].
    """
    q_y = quaternion_from_mrp_expr(y[0:3])
    q_old = quaternion_from_mrp_expr(z_old[0:3])
    q_z = quaternion_from_mrp_expr(z[0:3])
    q_error = _quaternion_product(ca.vertcat(q_old[0], -q_old[1:4]), q_y)  # C(z_{k−d})ᵀ C(y)
    delta_omega = 4 * (y[3:6] - z_old[3:6])
    q_hat = _quaternion_product(_rotation_quaternion(tau * delta_omega), _quaternion_product(q_z, q_error))
    sigma_hat = _short_mrp_from_quaternion(q_hat)
    shadow = _safe_shadow(sigma_hat)
    nearer = ca.logic_and(
        ca.dot(sigma_hat, sigma_hat) > _CONTINUITY_FLOOR,
        ca.norm_2(shadow - previous) < ca.norm_2(sigma_hat - previous),
    )
    sigma_hat = ca.if_else(nearer, shadow, sigma_hat)
    switched = ca.if_else(ca.dot(sigma_hat, sigma_hat) >= alpha * alpha, 1.0, 0.0)
    sigma_hat = ca.if_else(switched, _safe_shadow(sigma_hat), sigma_hat)
    return ca.vertcat(sigma_hat, z[3:6] + (y[3:6] - z_old[3:6])), switched


def _safe_shadow(sigma: Any) -> Any:
    # Both if_else branches are evaluated: keep the unused shadow of σ = 0 finite.
    squared = ca.dot(sigma, sigma)
    return -sigma / ca.if_else(squared > 0, squared, 1.0)


def _chunk_function(sample: ca.Function, d: int) -> ca.Function:
    """``chunk(x, memory, history) -> (x_end, memory_end, measurements, u, switched)``.

    One chunk is max(d, 1) samples, a ``mapaccum`` of ``sample``.
    """
    length = max(d, 1)
    accumulated = sample.mapaccum("chunk_samples", length, 2)
    x = ca.MX.sym("x", STATE_SIZE)
    memory = ca.MX.sym("memory", MEMORY_SIZE)
    history = ca.MX.sym("history", STATE_SIZE, length)
    xs, memories, measurements, u, switched = accumulated(x, memory, history)
    return ca.Function(
        "chunk",
        [x, memory, history],
        [xs[:, length - 1], memories[:, length - 1], measurements, u, switched],
        ["x", "memory", "history"],
        ["x_end", "memory_end", "measurements", "u", "switched"],
    )


#: The controller's own memory in `ClosedLoopFunctions.flight_controller`: (h, c, σ̃_prev (3)).
CONTROLLER_MEMORY_SIZE = 5
#: Names of the flight sample's memory entries (`FLIGHT_MEMORY_SIZE`), in order.
FLIGHT_MEMORY_LAYOUT = (
    "h",
    "c",
    "sigma_prev_1",
    "sigma_prev_2",
    "sigma_prev_3",
    "saturated_samples",
    "peak_u_command_1",
    "peak_u_command_2",
    "peak_u_command_3",
    "peak_u_command_norm",
)


def _flight_chunk_function(sample: ca.Function, d: int) -> ca.Function:
    """``chunk(x, memory, history, noise[, torque]) -> (x_end, memory_end, states, measurements, u, switched)``.

    max(d, 1) samples of the flight ``sample`` (a ``mapaccum``); ``history`` holds the
    measurements m_{k−d}, …, m_{k−1} (the previous chunk's ``measurements``), ``noise`` one
    column (θ_k; η_k) per sample, ``states`` the bookkept true states x_k; ``torque`` (when
    ``sample`` has it: a per-sample disturbance) one column w_k (N m) per sample.
    """
    length = max(d, 1)
    accumulated = sample.mapaccum("chunk_samples", length, 2)
    x = ca.MX.sym("x", STATE_SIZE)
    memory = ca.MX.sym("memory", FLIGHT_MEMORY_SIZE)
    history = ca.MX.sym("history", STATE_SIZE, length)
    noise = ca.MX.sym("noise", NOISE_SIZE, length)
    inputs, names = [x, memory, history, noise], ["x", "memory", "history", "noise"]
    if "torque" in sample.name_in():
        inputs.append(ca.MX.sym("torque", INPUT_SIZE, length))
        names.append("torque")
    xs, memories, states, u, switched, measurements = accumulated(*inputs)
    return ca.Function(
        "chunk",
        inputs,
        [xs[:, length - 1], memories[:, length - 1], states, measurements, u, switched],
        names,
        ["x_end", "memory_end", "states", "measurements", "u", "switched"],
    )


@dataclass(frozen=True, eq=False)
class FlightOptions:
    """The models of the loop as flown that a [`ClosedLoopFunctions`][mrpctl.loop.ClosedLoopFunctions] was built with.

    Attributes
    ----------
    actuator : mrpctl.flight.ActuatorModel or None
        Torque limits (None: none).
    disturbance : mrpctl.flight.Disturbance or None
        Body-frame torque w (N m) (None: zero): constant (bound into the Functions), or per sample
        (then w_k is the ``torque`` input of ``sample`` and ``chunk``; not bound).
    sensor : mrpctl.flight.SensorModel or None
        Noise and gyro bias (None: an ideal sensor). The noise θ_k, η_k is an input of
        ``sample`` and ``chunk`` (``SensorModel.noise(k0, k1)``); the bias is a constant.
    delay : mrpctl.flight.DelayModel or None
        A time-varying delay (None: the constant τ); ``sample`` takes whichever measurement
        the schedule picks as ``x_delayed``.
    constants : numpy.ndarray
        The flight sample's run-time constants (u_max (3), u_norm, w (3), gyro bias (3)) bound
        into the Functions (N m, rad/s; inf: no limit).
    saturation : mrpctl.flight.Saturation
        The actuator's mode (``SCALE`` without an actuator).
    """

    actuator: ActuatorModel | None
    disturbance: Disturbance | None
    sensor: SensorModel | None
    delay: DelayModel | None
    constants: np.ndarray = field(repr=False)
    saturation: Saturation

    def initial_memory(self, x0: Any, delay_samples: int, history: Any = None) -> np.ndarray:
        """The ``sample`` memory at k = 0 for the initial state x0 (see `FLIGHT_MEMORY_LAYOUT`).

        h = c = +1, σ̃_prev the short set of the σ the controller sees at k = 0 (the first
        history row for d > 0, by default x0; the bookkept σ0 for d = 0), accumulators 0. The
        first five entries are the ``flight_controller`` memory.
        """
        from mrpctl._validation import finite_array
        from mrpctl.simulation._engine import flight_memory  # the engine's own initialisation

        x0 = finite_array("x0", x0, (STATE_SIZE,))
        rows = x0[None, :] if history is None else finite_array("history", history)
        return flight_memory(x0, rows, integer("delay_samples", delay_samples, minimum=0))


@dataclass(frozen=True, eq=False)
class ClosedLoopFunctions:
    """The closed loop as named CasADi Functions (the building blocks of the simulator).

    All ports carry x = [σ; ω/4] (6), u in N m (3); K and the rule's parameters are
    constants in the expressions. ``dynamics``, ``controller``, ``switching``, ``step``
    and ``sample`` are pure SX Functions; ``chunk`` is an MX ``mapaccum`` of ``sample``
    (a loop, not an unrolled expression), also code-generatable and serialisable.

    With the controller-side rule [`Hysteretic`][mrpctl.flight.Hysteretic] (``flight`` is not
    None) ``sample`` and ``chunk`` are the flight loop's ([`flight_core_function`][mrpctl.loop.flight_core_function]
    with
    K, δ and the [`FlightOptions`][mrpctl.loop.FlightOptions] constants bound), and ``flight_controller`` and
    ``sensor`` are what flight software and a sensor simulation need; see
    [`functions`][mrpctl.loop.ClosedLoopFunctions.functions].

    Attributes
    ----------
    dynamics : casadi.Function
        ``dynamics(x, u) -> xdot`` from [`mrpctl.model`][mrpctl.model].
    controller : casadi.Function
        ``controller(x_meas) -> u``: u = K x_meas.
    switching : casadi.Function
        ``rule(x, x_meas, memory) -> (x_next, memory_next, switched)``.
    step : casadi.Function
        ``step(x, u) -> x_next``: RK4 over one measurement period h with ``substeps``.
    sample : casadi.Function
        ``sample(x, memory, x_delayed) -> (x_next, memory_next, x_meas, u, switched)``:
        one measurement period (rule, record, hold, integrate); ``x_delayed`` is m_{k−d}
        and is not used when d = 0. Flight loop: ``sample(x, memory, x_delayed, noise) ->
        (x_next, memory_next, x_meas, u, switched, measurement)`` with the memory of
        `FLIGHT_MEMORY_LAYOUT`, ``noise`` = (θ_k; η_k) (rad, rad/s), ``x_meas`` the
        bookkept true state, ``measurement`` the sensor's m_k (what goes into the delay
        line) and ``u`` the applied torque (without the disturbance).
    chunk : casadi.Function
        ``chunk(x, memory, history) -> (x_end, memory_end, measurements, u, switched)``:
        max(d, 1) samples; ``history`` (6 × d) is the previous chunk's ``measurements``.
        Flight loop: ``chunk(x, memory, history, noise) -> (x_end, memory_end, states,
        measurements, u, switched)``.
    initial_memory : float
        The rule memory at k = 0 (flight loop: see
        [`FlightOptions.initial_memory`][mrpctl.loop.FlightOptions.initial_memory]).
    flight_controller : casadi.Function or None
        Flight loop only: ``flight_controller(x_meas, memory, delta) -> (u, u_command,
        memory_next, switched)``: from the delayed measurement [σ̃; ω̃/4] and the
        controller memory (h, c, σ̃_prev) the set selection with hysteresis δ, the
        commanded torque u_c = K [σ_c; ω̃/4] and the applied (limited) torque u (N m).
    sensor : casadi.Function or None
        Flight loop only: ``sensor(x, noise) -> (x_true, measurement)``: the plant's MRP kept
        in the short set (no physical effect) and the measurement of it with noise θ_k, η_k
        and the gyro bias.
    flight : FlightOptions or None
        The flight models (None for the paper's state-side rules).
    """

    spacecraft: Spacecraft
    K: np.ndarray = field(repr=False)
    rule: SwitchingRule
    tau: float
    rate: float
    delay_samples: int
    substeps: int
    initial_memory: float
    dynamics: ca.Function = field(repr=False)
    controller: ca.Function = field(repr=False)
    switching: ca.Function = field(repr=False)
    step: ca.Function = field(repr=False)
    sample: ca.Function = field(repr=False)
    chunk: ca.Function = field(repr=False)
    flight_controller: ca.Function | None = field(default=None, repr=False)
    sensor: ca.Function | None = field(default=None, repr=False)
    flight: FlightOptions | None = None
    predictor: Any = None
    predictor_controller: ca.Function | None = field(default=None, repr=False)
    prediction: ca.Function | None = field(default=None, repr=False)
    model_step: ca.Function | None = field(default=None, repr=False)

    @property
    def period(self) -> float:
        """Measurement period h = 1/rate (s)."""
        return 1.0 / self.rate

    def functions(self) -> dict[str, ca.Function]:
        """The Functions by name, for export.

        Paper rules: dynamics, controller, rule, step, sample, chunk. Flight loop:
        dynamics, flight_controller, sensor, step, sample, chunk. Predictor: dynamics,
        predictor_controller, prediction, model_step, sensor, step, sample, chunk.
        """
        if self.predictor_controller is not None and self.prediction is not None and self.model_step is not None:
            assert self.sensor is not None
            return {
                "dynamics": self.dynamics,
                "predictor_controller": self.predictor_controller,
                "prediction": self.prediction,
                "model_step": self.model_step,
                "sensor": self.sensor,
                "step": self.step,
                "sample": self.sample,
                "chunk": self.chunk,
            }
        if self.flight_controller is not None and self.sensor is not None:
            return {
                "dynamics": self.dynamics,
                "flight_controller": self.flight_controller,
                "sensor": self.sensor,
                "step": self.step,
                "sample": self.sample,
                "chunk": self.chunk,
            }
        return {
            "dynamics": self.dynamics,
            "controller": self.controller,
            "rule": self.switching,
            "step": self.step,
            "sample": self.sample,
            "chunk": self.chunk,
        }

    def __str__(self) -> str:
        lines = [
            f"Closed loop: {self.spacecraft}, tau = {self.tau:g} s = {self.delay_samples} samples "
            f"at {self.rate:g} Hz, RK4 with {self.substeps} substep(s), rule {self.rule}"
        ]
        if self.flight is not None:
            models = [self.flight.actuator, self.flight.disturbance, self.flight.sensor, self.flight.delay]
            lines.append("  flight models: " + (", ".join(str(m) for m in models if m is not None) or "none"))
        lines += [f"  {function}" for function in self.functions().values()]
        return "\n".join(lines)


def _as_disturbance(disturbance: Any) -> Disturbance | None:
    """The export's disturbance as a [`Disturbance`][mrpctl.flight.Disturbance] (None: none given)."""
    if disturbance is None or isinstance(disturbance, Disturbance):
        return disturbance
    return Disturbance(disturbance)


def closed_loop_functions(
    spacecraft: Spacecraft,
    K: Any,
    *,
    tau: float,
    rule: SwitchingRule,
    rate: float = 1000.0,
    substeps: int = 1,
    actuator: ActuatorModel | None = None,
    disturbance: Any = None,
    sensor: SensorModel | None = None,
    delay: DelayModel | None = None,
    predictor: Any = None,
) -> ClosedLoopFunctions:
    """Build the closed loop's named CasADi Functions (see [`ClosedLoopFunctions`][mrpctl.loop.ClosedLoopFunctions]).

    Parameters
    ----------
    spacecraft : Spacecraft
        The plant.
    K : array_like
        (3, 6) gain acting on x = [σ; ω/4]: u = K x(t − τ).
    tau : float, keyword-only
        Delay τ (s), a whole number d of periods 1/rate (with ``delay``: its tau_max).
    rule : SwitchingRule, keyword-only
        The shadow-set switching rule, or the controller-side [`Hysteretic`][mrpctl.flight.Hysteretic].
    rate : float, keyword-only
        Measurement rate (Hz), default 1000.
    substeps : int, keyword-only
        RK4 substeps per measurement period, default 1.
    actuator, disturbance, sensor, delay : keyword-only
        The flight loop's models, as in [`mrpctl.simulate`][mrpctl.simulation.simulate] (``rule=Hysteretic(...)``
        only; the same checks): [`ActuatorModel`][mrpctl.flight.ActuatorModel], a constant
        [`Disturbance`][mrpctl.flight.Disturbance] (or a (3,) torque, N m; a per-sample one, (n, 3) rows or
        a function of time, makes w_k an input ``torque`` of ``sample`` (3) and ``chunk`` (3 × max(d, 1))),
        [`SensorModel`][mrpctl.flight.SensorModel], [`DelayModel`][mrpctl.flight.DelayModel].
    predictor : mrpctl.Predictor, keyword-only
        The predictor controller (with ``rule=OnPredicted(alpha)``; actuator, disturbance (constant, or
        per sample: the ``torque`` input of ``sample`` and ``chunk``, plant only) and sensor allowed,
        no delay model): ``sample`` and ``chunk`` are the engine's predictor sample with K,
        α, τ, J_m and the flight constants bound, and ``predictor_controller``, ``prediction``,
        ``model_step`` and ``sensor`` are the flight-software pieces (see `_predictor_loop`).

    Raises
    ------
    SpecificationError, DimensionError
        On invalid parameters, or a flight model with a paper rule.
    """
    # The simulator's own checks of the flight options (one copy); imported here because
    # mrpctl.simulation imports this module.
    from mrpctl.simulation._engine import NO_FLIGHT_OPTIONS
    from mrpctl.simulation._simulate import _flight_options, _varying_delay

    spacecraft = check_spacecraft(spacecraft)
    gain = gain_matrix(K)
    rule = check_rule(rule)
    d = delay_samples(tau, rate)
    rate = float(rate)
    substeps = check_substeps(substeps)
    period = 1.0 / rate
    from mrpctl.predictor import OnPredicted  # mrpctl.predictor imports this module

    if predictor is not None or isinstance(rule, OnPredicted):
        return _predictor_loop(
            spacecraft, gain, rule, d, float(tau), rate, substeps, actuator, disturbance, sensor, delay, predictor
        )
    options, saturation = _flight_options(rule, actuator, disturbance, sensor)
    sequence = getattr(delay, "delays", None)
    horizon = 1 if sequence is None else len(sequence)
    varying = _varying_delay(rule, delay, d, rate, horizon)
    common = dict(
        spacecraft=spacecraft,
        K=readonly(gain),
        rule=rule,
        tau=float(tau),
        rate=rate,
        delay_samples=d,
        substeps=substeps,
        initial_memory=rule.initial_memory(delay_samples=d),
        dynamics=plant_model(spacecraft).dynamics,
        switching=rule.function(delay_samples=d),
        step=step_function(spacecraft, period, substeps),
    )
    x_meas = ca.SX.sym("x_meas", STATE_SIZE)
    controller = ca.Function("controller", [x_meas], [ca.DM(gain) @ x_meas], ["x_meas"], ["u"])
    if isinstance(rule, Hysteretic):
        flight = FlightOptions(
            actuator=actuator,
            disturbance=_as_disturbance(disturbance),
            sensor=sensor,
            delay=varying,
            constants=readonly(NO_FLIGHT_OPTIONS if options is None else options),
            saturation=saturation,
        )
        sample, flight_controller, sensor_function = _flight_functions(
            spacecraft, gain, rule, d, period, substeps, flight
        )
        return ClosedLoopFunctions(
            **common,
            controller=controller,
            sample=sample,
            chunk=_flight_chunk_function(sample, d),
            flight_controller=flight_controller,
            sensor=sensor_function,
            flight=flight,
        )
    core = core_function(spacecraft, rule, d, period, substeps)
    x = ca.SX.sym("x", STATE_SIZE)
    memory = ca.SX.sym("memory", MEMORY_SIZE)
    x_delayed = ca.SX.sym("x_delayed", STATE_SIZE)
    bound = list(core(x, memory, x_delayed, ca.DM(gain), ca.DM(rule.parameters())))
    sample = ca.Function(
        "sample",
        [x, memory, x_delayed],
        bound,
        ["x", "memory", "x_delayed"],
        ["x_next", "memory_next", "x_meas", "u", "switched"],
    )
    return ClosedLoopFunctions(
        **common,
        controller=controller,
        sample=sample,
        chunk=_chunk_function(sample, d),
    )


def _flight_functions(
    spacecraft: Spacecraft,
    gain: np.ndarray,
    rule: Hysteretic,
    d: int,
    period: float,
    substeps: int,
    flight: FlightOptions,
) -> tuple[ca.Function, ca.Function, ca.Function]:
    """(sample, flight_controller, sensor) of the flight loop with K, δ and the flight constants bound.

    ``sample`` is [`flight_core_function`][mrpctl.loop.flight_core_function] (the simulator's sample) with its run-time
    inputs bound; ``flight_controller`` and ``sensor`` are written from the same builders
    ([`selection_function`][mrpctl.flight.selection_function], [`actuator_function`][mrpctl.flight.actuator_function],
    [`measurement_function`][mrpctl.flight.measurement_function]) in the same order, so that a loop of
    ``sensor``, ``flight_controller`` and ``step`` gives the sample's numbers bit for bit.
    """
    constants = ca.DM(np.asarray(flight.constants))
    per_sample = flight.disturbance is not None and not flight.disturbance.constant
    core = flight_core_function(spacecraft, d, period, substeps, saturation=flight.saturation, torque_input=per_sample)
    x = ca.SX.sym("x", STATE_SIZE)
    memory = ca.SX.sym("memory", FLIGHT_MEMORY_SIZE)
    x_delayed = ca.SX.sym("x_delayed", STATE_SIZE)
    noise = ca.SX.sym("noise", NOISE_SIZE)
    inputs, names = [x, memory, x_delayed, noise], ["x", "memory", "x_delayed", "noise"]
    torque = [ca.SX.sym("torque", INPUT_SIZE)] if per_sample else []  # w_k, the per-sample disturbance
    bound = list(core(x, memory, x_delayed, ca.DM(gain), ca.DM(rule.parameters()), constants, noise, *torque))
    sample = ca.Function(
        "sample",
        inputs + torque,
        bound,
        names + (["torque"] if per_sample else []),
        ["x_next", "memory_next", "x_meas", "u", "switched", "measurement"],
    )

    measured = ca.SX.sym("x_meas", STATE_SIZE)
    controller_memory = ca.SX.sym("memory", CONTROLLER_MEMORY_SIZE)
    delta = ca.SX.sym("delta")
    sigma_seen = short_expr(measured[0:3])
    h_next, c_next, sigma_c, switched = selection_function()(
        controller_memory[0], controller_memory[1], sigma_seen, controller_memory[2:5], delta
    )
    command = ca.DM(gain) @ ca.vertcat(sigma_c, measured[3:6])
    u = actuator_function(flight.saturation)(command, constants[0:3], constants[3], ca.DM.zeros(3))[0]
    flight_controller = ca.Function(
        "flight_controller",
        [measured, controller_memory, delta],
        [u, command, ca.vertcat(h_next, c_next, sigma_seen), switched],
        ["x_meas", "memory", "delta"],
        ["u", "u_command", "memory_next", "switched"],
    )

    true_state = OnCurrent().expressions(x, x, ca.SX.zeros(MEMORY_SIZE), delay_samples=d)[0]
    measurement = measurement_function()(true_state, noise[0:3], noise[3:6], constants[7:10])[0]
    sensor = ca.Function("sensor", [x, noise], [true_state, measurement], ["x", "noise"], ["x_true", "measurement"])
    return sample, flight_controller, sensor


#: Names of the predictor sample's memory entries (`PREDICTOR_MEMORY_SIZE`), in order.
PREDICTOR_MEMORY_LAYOUT = (
    "unused_1",
    "unused_2",
    "sigma_hat_prev_1",
    "sigma_hat_prev_2",
    "sigma_hat_prev_3",
    "saturated_samples",
    "peak_u_command_1",
    "peak_u_command_2",
    "peak_u_command_3",
    "peak_u_command_norm",
    "z_1",
    "z_2",
    "z_3",
    "z_4",
    "z_5",
    "z_6",
)


def _predictor_loop(
    spacecraft: Spacecraft,
    gain: np.ndarray,
    rule: SwitchingRule,
    d: int,
    tau: float,
    rate: float,
    substeps: int,
    actuator: Any,
    disturbance: Any,
    sensor: Any,
    delay: Any,
    predictor: Any,
) -> ClosedLoopFunctions:
    """The predictor loop's Functions (K, α, τ, J_m and the flight constants bound into them).

    * ``sample(x, memory, x_delayed, noise) -> (x_next, memory_next, x_meas, u, switched, ring)``:
      the engine's sample ([`predictor_core_function`][mrpctl.loop.predictor_core_function]); memory of
      `PREDICTOR_MEMORY_LAYOUT`,
      ``x_delayed`` = (m_{k−d}; z_{k−d}) (12), ``ring`` = (m_k; z_k), the next entry of the delay line;
    * ``chunk(x, memory, history, noise)``: max(d, 1) samples (``mapaccum``), ``history`` 12 × d;
    * with a per-sample disturbance (rows or a function of time) both take w_k as a last input
      ``torque`` (3 N m; chunk: 3 × max(d, 1), one column per sample), added to u on the plant only
      (``step(x, u + w_k)``; the model copy and ``predictor_controller`` never see it);
    * ``predictor_controller(y, z_delayed, z, sigma_prev) -> (u, u_command, x_hat, switched, z_next)``:
      what flight software runs each sample, from the delayed measurement y and its own record of the
      model copy: [`prediction_expr`][mrpctl.loop.prediction_expr], u_c = K x̂, the actuator, z_{k+1} = short(RK4_m(z_k,
      u));
    * ``prediction(y, z_delayed, z, sigma_prev) -> (x_hat, switched)``: the correction and the rule;
    * ``model_step(z, u) -> z_next``: one RK4 step of J_m over h, kept in the short set;
    * ``sensor(x, noise) -> (x_true, measurement)``: as in the flight loop.

    The pieces are written from the same builders in the same order as ``sample``.
    """
    from mrpctl.simulation._engine import predictor_constants
    from mrpctl.simulation._simulate import _check_predictor, _flight_constants, _predictor_disturbance

    checked = _check_predictor(predictor, rule, "constant", delay, compiled=False)
    assert checked is not None
    disturbance = _predictor_disturbance(disturbance, None)
    per_sample = disturbance is not None and not disturbance.constant
    options, saturation = _flight_constants(actuator, disturbance, sensor)
    constants_array = predictor_constants(options, tau, checked.model)
    constants = ca.DM(constants_array)
    period = 1.0 / rate
    model_kind = inertia_input(checked.model)
    core = predictor_core_function(
        spacecraft,
        d,
        period,
        substeps,
        model_inertia=model_kind,
        saturation=saturation,
        sensor=True,
        torque_input=per_sample,
    )
    x = ca.SX.sym("x", STATE_SIZE)
    memory = ca.SX.sym("memory", PREDICTOR_MEMORY_SIZE)
    x_delayed = ca.SX.sym("x_delayed", PREDICTOR_RING_WIDTH)
    noise = ca.SX.sym("noise", NOISE_SIZE)
    torque = [ca.SX.sym("torque", INPUT_SIZE)] if per_sample else []  # w_k, the per-sample disturbance
    alpha = ca.DM(rule.parameters())
    bound = list(core(x, memory, x_delayed, ca.DM(gain), alpha, constants, noise, *torque))
    outputs = ["x_next", "memory_next", "x_meas", "u", "switched", "ring"]
    names = ["x", "memory", "x_delayed", "noise"] + (["torque"] if per_sample else [])
    sample = ca.Function("sample", [x, memory, x_delayed, noise, *torque], bound, names, outputs)

    length = max(d, 1)
    accumulated = sample.mapaccum("chunk_samples", length, 2)
    mx_x = ca.MX.sym("x", STATE_SIZE)
    mx_memory = ca.MX.sym("memory", PREDICTOR_MEMORY_SIZE)
    history = ca.MX.sym("history", PREDICTOR_RING_WIDTH, length)
    mx_noise = ca.MX.sym("noise", NOISE_SIZE, length)
    mx_torque = [ca.MX.sym("torque", INPUT_SIZE, length)] if per_sample else []  # one column w_k per sample
    xs, memories, states, u_all, switched_all, ring = accumulated(mx_x, mx_memory, history, mx_noise, *mx_torque)
    chunk = ca.Function(
        "chunk",
        [mx_x, mx_memory, history, mx_noise, *mx_torque],
        [xs[:, length - 1], memories[:, length - 1], states, ring, u_all, switched_all],
        [*names[0:2], "history", *names[3:]],
        ["x_end", "memory_end", "states", "ring", "u", "switched"],
    )

    model_j, model_j_inv = inertia_values(checked.model, model_kind)
    z = ca.SX.sym("z", STATE_SIZE)
    u_in = ca.SX.sym("u", INPUT_SIZE)
    raw = step_function(spacecraft, period, 1, inertia=model_kind)(z, u_in, ca.DM(model_j), ca.DM(model_j_inv))
    model_step = ca.Function(
        "model_step",
        [z, u_in],
        [ca.vertcat(short_expr(raw[0:3]), raw[3:6])],
        ["z", "u"],
        ["z_next"],
    )
    y = ca.SX.sym("y", STATE_SIZE)
    z_delayed = ca.SX.sym("z_delayed", STATE_SIZE)
    previous = ca.SX.sym("sigma_prev", 3)
    x_hat, switched = prediction_expr(y, z_delayed, z, previous, alpha[0], constants[FLIGHT_CONSTANTS_SIZE])
    prediction = ca.Function(
        "prediction",
        [y, z_delayed, z, previous],
        [x_hat, switched],
        ["y", "z_delayed", "z", "sigma_prev"],
        ["x_hat", "switched"],
    )
    command = ca.DM(gain) @ x_hat
    u = actuator_function(saturation)(command, constants[0:3], constants[3], ca.DM.zeros(3))[0]
    predictor_controller = ca.Function(
        "predictor_controller",
        [y, z_delayed, z, previous],
        [u, command, x_hat, switched, model_step(z, u)],
        ["y", "z_delayed", "z", "sigma_prev"],
        ["u", "u_command", "x_hat", "switched", "z_next"],
    )
    true_state = OnCurrent().expressions(x, x, ca.SX.zeros(MEMORY_SIZE), delay_samples=d)[0]
    measurement = measurement_function()(true_state, noise[0:3], noise[3:6], constants[7:10])[0]
    sensor_function = ca.Function(
        "sensor", [x, noise], [true_state, measurement], ["x", "noise"], ["x_true", "measurement"]
    )
    x_meas = ca.SX.sym("x_meas", STATE_SIZE)
    flight = FlightOptions(
        actuator=actuator,
        disturbance=disturbance,
        sensor=sensor,
        delay=None,
        constants=readonly(constants_array[0:FLIGHT_CONSTANTS_SIZE]),
        saturation=saturation,
    )
    return ClosedLoopFunctions(
        spacecraft=spacecraft,
        K=readonly(gain),
        rule=rule,
        tau=tau,
        rate=rate,
        delay_samples=d,
        substeps=substeps,
        initial_memory=0.0,
        dynamics=plant_model(spacecraft).dynamics,
        controller=ca.Function("controller", [x_meas], [ca.DM(gain) @ x_meas], ["x_meas"], ["u"]),
        switching=rule.function(delay_samples=d),
        step=step_function(spacecraft, period, substeps),
        sample=sample,
        chunk=chunk,
        sensor=sensor_function,
        flight=flight,
        predictor=checked,
        predictor_controller=predictor_controller,
        prediction=prediction,
        model_step=model_step,
    )
