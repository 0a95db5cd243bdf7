"""The closed loop's symbolic building blocks: the RK4 step, the sample cores (paper rules, flight loop,
predictor) and their d-sample chunks, as CasADi Functions built from the one plant model.

J enters either as a constant or as a run-time input ([`InertiaInput`][mrpctl.loop.InertiaInput]), so one compiled
engine
serves every spacecraft of a campaign.
"""

from __future__ import annotations

import enum
from typing import Any

import casadi as ca
import numpy as np

from mrpctl.errors import SpecificationError
from mrpctl.flight import (
    FLIGHT_CONSTANTS_SIZE,
    FLIGHT_MEMORY_SIZE,
    NOISE_SIZE,
    Hysteretic,
    NoiseForm,
    Saturation,
    actuator_function,
    measurement_function,
    quaternion_from_mrp_expr,
    raw_measurement_function,
    selection_function,
    short_expr,
)
from mrpctl.flight.steering import SteeringLaw, steering_command_expr
from mrpctl.flight.tracking import REFERENCE_WIDTH, feedforward_expr, settling_error_expr, tracking_error_expr
from mrpctl.model import (
    INPUT_SIZE,
    ORBIT_SIZE,
    STATE_SIZE,
    dynamics_expr,
    gravity_gradient_expr,
    orbit_phase_expr,
    orbit_position_expr,
    orbit_turn_expr,
    plant_model,
)
from mrpctl.predictor.controller import PredictorForm
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import MEMORY_SIZE, PARAMETER_SIZE, OnCurrent, SwitchingRule

__all__ = [
    "CONTROLLER_MEMORY_SIZE",
    "FLIGHT_MEMORY_LAYOUT",
    "PREDICTOR_MEMORY_SIZE",
    "PREDICTOR_RING_WIDTH",
    "InertiaInput",
    "chunk_function",
    "core_function",
    "flight_chunk_function",
    "flight_core_function",
    "inertia_input",
    "inertia_values",
    "prediction_expr",
    "predictor_constants_size",
    "predictor_core_function",
    "step_function",
    "true_error_function",
]


class InertiaInput(enum.Enum):
    """How a run-time inertia enters a compiled Function (see [`inertia_input`][mrpctl.loop.inertia_input])."""

    #: J and J⁻¹ diagonal: two 3-vectors (the diagonals), the same operations as constants.
    DIAGONAL = "diagonal"
    #: Full 3 × 3 J and J⁻¹ (column-major).
    FULL = "full"


#: The off-diagonal entries of a 3x3 matrix, row by row.
_OFF_DIAGONAL = np.array([1, 2, 3, 5, 6, 7])


def inertia_input(spacecraft: Spacecraft) -> InertiaInput:
    """DIAGONAL when both J and J⁻¹ of ``spacecraft`` are exactly diagonal (every off-diagonal entry ±0), else
    FULL. (Called per run of a batch: a gather of the six entries, not a comparison with a rebuilt matrix.)"""
    for matrix in (spacecraft.inertia, spacecraft.inertia_inverse):
        if matrix.ravel()[_OFF_DIAGONAL].any():
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
    spacecraft: Spacecraft,
    period: float,
    substeps: int,
    *,
    inertia: InertiaInput | None = None,
    gravity_gradient: bool = False,
) -> ca.Function:
    """``step(x, u) -> x_next``: RK4 over one period h with ``substeps`` equal substeps.

    With ``inertia`` the spacecraft's J and J⁻¹ are inputs instead of constants:
    ``step(x, u, J, J_inv) -> x_next`` (the layout of ``inertia``, see [`InertiaInput`][mrpctl.loop.InertiaInput]).
    With ``gravity_gradient`` two more inputs ``orbit`` (`ORBIT_SIZE`: n, u₀, ê₁, ê₂, cos δ, sin δ of a circular
    orbit, δ = n dt/2) and ``time`` (t_k, s, the start of the period) add the gravity-gradient torque of the
    plant's own J, [`gravity_gradient_expr`][mrpctl.model.gravity_gradient_expr] of the stage's attitude and of
    r̂_N = [`orbit_position_expr`][mrpctl.model.orbit_position_expr] at the stage's time (t_k + j dt, + dt/2,
    + dt/2, + dt for substep j, dt = h/substeps), to the held torque u inside every RK4 stage. The phase
    (cos u, sin u) is computed once a sample at t_k ([`orbit_phase_expr`][mrpctl.model.orbit_phase_expr]) and
    turned by δ to the later stage times ([`orbit_turn_expr`][mrpctl.model.orbit_turn_expr]: one cosine and one
    sine a sample, whatever the substeps).
    """
    x = ca.SX.sym("x", STATE_SIZE)
    u = ca.SX.sym("u", INPUT_SIZE)
    extra: list[ca.SX] = []
    if inertia is None:
        dynamics = plant_model(spacecraft).dynamics
        j_matrix: Any = ca.DM(spacecraft.inertia)
    else:
        j_in, j_inv_in, j_matrix, j_inv = _inertia_symbols(inertia)
        extra = [j_in, j_inv_in]
        xdot = dynamics_expr(None, x, u, inertia=j_matrix, inertia_inverse=j_inv)
        dynamics = ca.Function("dynamics", [x, u, j_in, j_inv_in], [xdot])
    names = ["x", "u"] + (["J", "J_inv"] if extra else [])
    orbit = ca.SX.sym("orbit", ORBIT_SIZE)
    time = ca.SX.sym("time")
    dt = period / substeps

    def torque(z: Any, phase: Any) -> Any:
        """The torque of one stage: u, plus the gravity gradient at the stage's attitude and orbit phase."""
        if not gravity_gradient:
            return u
        return u + gravity_gradient_expr(z[0:3], orbit_position_expr(orbit, phase), orbit[0], j_matrix)

    # the orbit's phase (cos u, sin u) at t_k from libm, then turned by δ = n dt/2 to each later stage time
    start: Any = orbit_phase_expr(orbit, time) if gravity_gradient else None
    z = x
    for _ in range(substeps):
        middle: Any = orbit_turn_expr(orbit, start) if gravity_gradient else None
        end: Any = orbit_turn_expr(orbit, middle) if gravity_gradient else None
        k1 = dynamics(z, torque(z, start), *extra)
        z2 = z + (dt / 2) * k1
        k2 = dynamics(z2, torque(z2, middle), *extra)
        z3 = z + (dt / 2) * k2
        k3 = dynamics(z3, torque(z3, middle), *extra)
        z4 = z + dt * k3
        k4 = dynamics(z4, torque(z4, end), *extra)
        z = z + (dt / 6) * (k1 + 2 * k2 + 2 * k3 + k4)
        start = end
    if gravity_gradient:
        return ca.Function("step", [x, u, *extra, orbit, time], [z], [*names, "orbit", "time"], ["x_next"])
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
    reference_input: bool = False,
    feedforward: bool = False,
    law: SteeringLaw | None = None,
    gravity_gradient: bool = False,
    settling_output: bool = False,
    lagged_settling: bool = False,
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
    (h_{k+1}, σ_c,k, u_c,k, σ̃_k, ω̃_k) (the logic variable after the rule, the MRP the control law used, the
    commanded torque before the actuator limits, N m, and what the controller read: the short set of the
    delayed measured attitude, after the noise, and the delayed measured rate, rad/s): the result's
    per-sample records. With
    ``torque_input`` a last input ``torque`` (3, N m) is the disturbance w_k of the sample (a
    per-sample disturbance streamed by the engine; the constant w in ``flight`` is then unused).
    ``noise_form`` ([`NoiseForm`][mrpctl.flight.NoiseForm]): with ``MRP`` the first half of ``noise`` is the
    attitude noise's MRP σ(θ_k) ([`rotation_mrp_function`][mrpctl.flight.rotation_mrp_function], computed by the engine
    before the sample) instead of θ_k: the same numbers bit for bit.
    With ``short_measurements`` (only without ``sensor``) the controller reads ``x_delayed`` (and,
    for d = 0, m_k) as it is, without taking its short set: the same numbers bit for bit for a
    caller whose history rows are in the short set already (the compiled engine maps them through
    the same SX, ``mrpctl.engines.scalar.short_history``), as every m_k the sample writes is then
    x_meas, bookkept by ``OnCurrent``, a fixed point of the short-set map (design/flight.md, phase
    8b); a sensor's entries are its measurements, whose short set the controller takes. With
    ``squared_peak`` the memory's last entry is the peak |u_c|² (N² m²): one square root at the end
    gives the peak |u_c| bit for bit (the correctly rounded square root is monotone: the max of the
    roots is the root of the max), instead of one a sample (the compiled engine's, ``Engine.run``).
    With ``law`` (a [`SteeringLaw`][mrpctl.flight.steering.SteeringLaw]) the command of step 4 is the
    steering law's, u_c = K_ω ω̃/4 + s K_σ σ_c with s in (0, 1] the rate limit's scale
    ([`steering_command_expr`][mrpctl.flight.steering.steering_command_expr]); None (default): the PD law.
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

    With ``reference_input`` the sample tracks a reference (``design/tracking.md``): two last inputs
    ``reference`` (9) = (σ_R/N, ω_R/N, ω̇_R/N) at t_k and ``reference_error`` (9), the same at the controller's
    error time (see [`ErrorTime`][mrpctl.flight.tracking.ErrorTime]); the controller forms σ_B/R and ω_B/R from
    the delayed measurement and the second row
    ([`tracking_error_expr`][mrpctl.flight.tracking.tracking_error_expr]), the selection (continuity and
    hysteresis) acts on σ_B/R, u_c = K [σ_c; ω_B/R/4] (+ with ``feedforward``
    [`feedforward_expr`][mrpctl.flight.tracking.feedforward_expr] of the measured delayed ω̃), and a last output
    ``tracking_error`` (6) is the true error [σ_B/R; ω_B/R/4] at t_k (from x_meas and the first row), which
    the records (10: (h, σ_c, u_c, σ_B/R)) and the engine's settling statistics use. With ``settling_output``
    (the engines') that last output is ``tracking_settling`` (4) = (|σ_B/R|², ω_B/R in rad/s) of the true error
    ([`settling_error_expr`][mrpctl.flight.tracking.settling_error_expr]: what the statistics take, without
    forming σ_B/R) and the records leave the true σ_B/R out: the scalar engine's driver computes it for the kept
    samples only (``true_error_function``, the same expressions as ``tracking_error``'s σ_B/R: its bits).
    With ``lagged_settling`` (also ``settling_output``; an ideal sensor, d >= 1, the caller feeding the row of
    t_{k−d} as ``reference_error`` and a fixed delay) the output is ``tracking_settling_lagged``: the same
    numbers for the true error of t_{k−d}, which is the controller's own error then (m_{k−d} is x_meas of
    t_{k−d}: the same inputs, the same expressions, 4 (ω̃/4 − [BN] ω_R/4) = 4 (ω̃/4) − [BN] ω_R exactly), so
    the true error at t_k is not formed; the engine folds sample k − d's statistics at sample k and the last
    d samples' from the ring at the end of the run.

    With ``gravity_gradient`` the plant flies the gravity-gradient torque 3 n² r̂_B × (J r̂_B) of a circular orbit
    inside its RK4 stages ([`step_function`][mrpctl.loop.step_function]): ``flight`` grows by the orbit's
    constants (n, u₀, ê₁, ê₂, cos δ, sin δ) (`ORBIT_SIZE`, after the ten flight constants) and a last input
    ``sample_index`` (k, the sample's index; the engines feed it from their sample counter) gives the
    sample's time t_k = k h. The controller does not know the torque (no feedforward of it).
    """
    if feedforward and not reference_input:
        raise SpecificationError("feedforward: the feedforward terms need a reference (reference_input)")
    if settling_output and not reference_input:
        raise SpecificationError("settling_output: the true error's statistics need a reference (reference_input)")
    if lagged_settling and (not settling_output or sensor or d < 1):
        raise SpecificationError(
            "lagged_settling: the controller's error is the true error of t_{k-d} with settling_output, an ideal "
            "sensor (sensor=False) and d >= 1 only"
        )
    if short_measurements and sensor:
        raise SpecificationError("short_measurements: only without a sensor (its measurements are not bookkept)")
    step = step_function(spacecraft, period, substeps, inertia=inertia, gravity_gradient=gravity_gradient)
    x = ca.SX.sym("x", STATE_SIZE)
    memory = ca.SX.sym("memory", FLIGHT_MEMORY_SIZE)
    x_delayed = ca.SX.sym("x_delayed", STATE_SIZE)
    gain = ca.SX.sym("K", INPUT_SIZE, STATE_SIZE)
    parameters = ca.SX.sym("parameters", PARAMETER_SIZE)
    symbols = None if inertia is None else _inertia_symbols(inertia)
    extra = [] if symbols is None else list(symbols[:2])
    flight = ca.SX.sym("flight", FLIGHT_CONSTANTS_SIZE + (ORBIT_SIZE if gravity_gradient else 0))
    sample_index = ca.SX.sym("sample_index")
    noise = ca.SX.sym("noise", NOISE_SIZE)
    torque = ca.SX.sym("torque", INPUT_SIZE)
    reference = ca.SX.sym("reference", REFERENCE_WIDTH)  # at t_k
    reference_error = ca.SX.sym("reference_error", REFERENCE_WIDTH)  # at the controller's error time
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
    rate_seen = seen[3:6]
    if reference_input:
        # the tracking error of the delayed measurement against the controller's reference row (its error time)
        sigma_bn = sigma_seen
        row = reference_error
        formed = tracking_error_expr(sigma_bn, seen[3:6], row[0:3], row[3:6], settling=lagged_settling)
        sigma_seen, rate_seen, omega_r_body, scale = formed[0:4]
    h_next, c_next, sigma_c, switched = selection_function()(
        memory[0], memory[1], sigma_seen, memory[2:5], parameters[0]
    )
    if law is None:
        command = gain @ ca.vertcat(sigma_c, rate_seen)
    else:
        command = steering_command_expr(law, gain, sigma_c, rate_seen)[0]
    if feedforward:
        j_matrix = ca.DM(spacecraft.inertia) if symbols is None else symbols[2]
        command = command + feedforward_expr(j_matrix, 4 * seen[3:6], sigma_bn, omega_r_body, row[6:9], scale)
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
    if gravity_gradient:  # the orbit's constants after the flight constants, t_k = k h
        orbit = flight[FLIGHT_CONSTANTS_SIZE : FLIGHT_CONSTANTS_SIZE + ORBIT_SIZE]
        x_next = step(x_meas, u_plant, *extra, orbit, sample_index * period)
    else:
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
    if reference_input:
        inputs += [reference, reference_error]
        names += ["reference", "reference_error"]
    if gravity_gradient:
        inputs.append(sample_index)
        names.append("sample_index")
    output_names = ["x_next", "memory_next", "x_meas", "u", "switched"] + (["measurement"] if sensor else [])
    outputs = [x_next, memory_next, x_meas, u, switched] + ([measured] if sensor else [])
    recorded = []
    if lagged_settling:  # the statistics of the true error of t_{k-d}: the controller's error
        settling = ca.vertcat(formed[4], 4 * rate_seen)
    elif reference_input and settling_output:  # what the statistics take of the true error at t_k
        settling = ca.vertcat(*settling_error_expr(x_meas[0:3], x_meas[3:6], reference[0:3], reference[3:6]))
    elif reference_input:  # the true pointing error at t_k: the metrics' state
        true_sigma, true_rate = tracking_error_expr(x_meas[0:3], x_meas[3:6], reference[0:3], reference[3:6])[0:2]
        recorded = [true_sigma]
    if records:
        output_names.append("record")
        outputs.append(ca.vertcat(h_next, sigma_c, command, sigma_seen, 4 * seen[3:6], *recorded))
    if reference_input:
        settled = "tracking_settling_lagged" if lagged_settling else "tracking_settling"
        output_names.append(settled if settling_output else "tracking_error")
        outputs.append(settling if settling_output else ca.vertcat(true_sigma, true_rate))
    return ca.Function("core", inputs, outputs, names, output_names)


def true_error_function(name: str = "true_error") -> ca.Function:
    """``true_error(x_meas, reference) -> sigma_br``: the true σ_B/R at t_k of the tracking sample's records
    (x_meas = [σ_B/N; ω_B/N/4], the row of t_k), the expressions of its ``tracking_error`` output (the same bits),
    for a driver that computes it for the kept samples only (``settling_output`` of
    [`flight_core_function`][mrpctl.loop.flight_core_function])."""
    x_meas = ca.SX.sym("x_meas", STATE_SIZE)
    reference = ca.SX.sym("reference", REFERENCE_WIDTH)
    sigma = tracking_error_expr(x_meas[0:3], x_meas[3:6], reference[0:3], reference[3:6])[0]
    return ca.Function(name, [x_meas, reference], [sigma], ["x_meas", "reference"], ["sigma_br"])


#: The predictor sample's memory: (1, 1, σ̂_prev (3), the actuator accumulators of the flight sample (5),
#: the model copy z (6)); entries 2..9 mean what they mean in the flight sample's memory.
PREDICTOR_MEMORY_SIZE = FLIGHT_MEMORY_SIZE + STATE_SIZE
#: One ring entry of the predictor sample: the measurement m_k and the model copy z_k.
PREDICTOR_RING_WIDTH = 2 * STATE_SIZE
#: Below this |σ̂|² the continuity test of the predicted MRP is skipped (its shadow is far away).
_CONTINUITY_FLOOR = 1e-8
_SMALL_ROTATION = 1e-4
#: The linear form's guard on its Padé factor: |v|² is held at 1.25² (a rotation of 5 rad over τ; the pole is at
#: |v|² = 2.5), so the predicted increment keeps its axis and grows monotonically, 4 atan(2.389 |v|) < 2π.
PADE_HOLD = 1.5625


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
    reference_input: bool = False,
    feedforward: bool = False,
    records: bool = False,
    form: PredictorForm = PredictorForm.NONLINEAR,
) -> ca.Function:
    """One sample of the predictor loop (``design/predictor.md``, form (b); with ``form`` LINEAR the linear
    form of `linear_prediction_expr`) (pure SX).

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
    unused); like the constant w it acts on the plant only. With ``records`` a last output ``record`` =
    (σ_y, ω_y, σ̂, ω̂, u_c) (15): what the controller saw, the delayed measurement y = m_{k−d} (attitude as
    measured, after the noise; rate in rad/s), its prediction x̂ after the rule (σ̂ in the set it switched to,
    ω̂ in rad/s) and the commanded torque (N m). At sample k:

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

    With ``form`` = `PredictorForm.LINEAR` steps 3 and 5 are `linear_prediction_expr` and the copy's exact ZOH
    step of the linearised model, z_{k+1} = Φ z_k + Γ_m u (`linear_model_step_expr`, never shortened).

    With ``reference_input`` the predictor tracks a reference (``design/tracking.md``): the inputs
    ``reference`` (the row of t_k: the true error) and ``reference_error`` (the controller's row) as in
    [`flight_core_function`][mrpctl.loop.flight_core_function]; step 4 acts on the tracking error of the
    prediction, σ_B/R = short(σ̂ ⊕ σ_N/R) and ω_B/R = ω̂ − [B̂N] ω_R/N (continuity, then the shadow when
    |σ_B/R| >= α), u_c = K [σ_B/R; ω_B/R/4] (+ with ``feedforward`` the terms of ω̂, [B̂N] and the model's
    J_m), and the outputs end with ``record`` (10: 1, σ_B/R used, u_c, the true σ_B/R) and ``tracking_error``.
    """
    if feedforward and not reference_input:
        raise SpecificationError("feedforward: the feedforward terms need a reference (reference_input)")
    linear = PredictorForm.parse(form) is PredictorForm.LINEAR
    step = step_function(spacecraft, period, substeps, inertia=inertia)
    model_step = None if linear else step_function(spacecraft, period, 1, inertia=model_inertia)
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
    reference = ca.SX.sym("reference", REFERENCE_WIDTH)  # at t_k
    reference_error = ca.SX.sym("reference_error", REFERENCE_WIDTH)  # the controller's row
    if reference_input:
        x_hat, switched, predicted, omega_r_body, scale = _prediction_tracking_expr(
            y, z_old, z, memory[2:5], parameters[0], tau, reference_error, linear=linear
        )
    elif linear:
        x_hat, switched = linear_prediction_expr(y, z_old, z, memory[2:5], parameters[0], tau)
    else:
        x_hat, switched = prediction_expr(y, z_old, z, memory[2:5], parameters[0], tau)
    sigma_hat = x_hat[0:3]

    command = gain @ x_hat
    if feedforward:
        command = command + feedforward_expr(
            model_j if model_inertia is InertiaInput.FULL else ca.diag(model_j),
            4 * predicted[3:6],
            predicted[0:3],
            omega_r_body,
            reference_error[6:9],
            scale,
        )
    if limited:
        u, u_plant, saturated = actuator_function(saturation)(command, flight[0:3], flight[3], w)
    else:
        u, u_plant, saturated = command, command + w, ca.DM(0.0)
    x_next = step(x_meas, u_plant, *extra)
    if model_step is None:
        z_next = linear_model_step_expr(z, u, model_j_inv, period)
    else:
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
    outputs = [x_next, memory_next, x_meas, u, switched, ca.vertcat(measured, z)]
    output_names = ["x_next", "memory_next", "x_meas", "u", "switched", "ring"]
    if reference_input:
        inputs += [reference, reference_error]
        names += ["reference", "reference_error"]
        true_sigma, true_rate = tracking_error_expr(x_meas[0:3], x_meas[3:6], reference[0:3], reference[3:6])[0:2]
    if records or reference_input:
        # (σ_y, ω_y, σ̂, ω̂, u_c, σ_c): the measurement read, the prediction of the body (tracking: of σ_B/N,
        # ω_B/N), the torque commanded and the MRP the law used (tracking: the predicted error σ_B/R), then with a
        # reference the true error σ_B/R at t_k (the pointing metrics')
        body = predicted if reference_input else x_hat
        outputs.append(
            ca.vertcat(
                y[0:3],
                4 * y[3:6],
                body[0:3],
                4 * body[3:6],
                command,
                x_hat[0:3],
                *([true_sigma] if reference_input else []),
            )
        )
        output_names.append("record")
    if reference_input:
        outputs.append(ca.vertcat(true_sigma, true_rate))
        output_names.append("tracking_error")
    return ca.Function("core", inputs, outputs, names, output_names)


def _prediction_tracking_expr(
    y: Any, z_old: Any, z: Any, previous: Any, alpha: Any, tau: Any, row: Any, *, linear: bool = False
) -> tuple[Any, Any, Any, Any, Any]:
    """[`prediction_expr`][mrpctl.loop.prediction_expr] on the tracking error: (x̂ = [σ_B/R; ω_B/R/4], switched,
    the prediction [σ̂_B/N; ω̂/4], [B̂N] ω_R/N, the rotation scale) against the reference ``row`` (9); with
    ``linear`` the prediction of [`linear_prediction_expr`][mrpctl.loop.functions.linear_prediction_expr]."""
    if linear:
        predicted = ca.vertcat(_linear_prediction_mrp(y, z_old, z, tau), y[3:6] + (z[3:6] - z_old[3:6]))
    else:
        q_hat = _group_prediction_quaternion(y, z_old, z, tau)
        predicted = ca.vertcat(_short_mrp_from_quaternion(q_hat), z[3:6] + (y[3:6] - z_old[3:6]))
    sigma, rate, omega_r_body, scale = tracking_error_expr(predicted[0:3], predicted[3:6], row[0:3], row[3:6])
    shadow = _safe_shadow(sigma)
    nearer = ca.logic_and(
        ca.dot(sigma, sigma) > _CONTINUITY_FLOOR,
        ca.norm_2(shadow - previous) < ca.norm_2(sigma - previous),
    )
    sigma = ca.if_else(nearer, shadow, sigma)
    switched = ca.if_else(ca.dot(sigma, sigma) >= alpha * alpha, 1.0, 0.0)
    sigma = ca.if_else(switched, _safe_shadow(sigma), sigma)
    return ca.vertcat(sigma, rate), switched, predicted, omega_r_body, scale


def _group_prediction_quaternion(y: Any, z_old: Any, z: Any, tau: Any) -> Any:
    """β of form (b)'s prediction Ĉ = C(τ δω) C(z_k) C(z_{k−d})ᵀ C(y), δω = ω_y − ω_z(k−d) (quaternion products)."""
    q_y = quaternion_from_mrp_expr(y[0:3])
    q_old = quaternion_from_mrp_expr(z_old[0:3])
    q_z = quaternion_from_mrp_expr(z[0:3])
    q_error = _quaternion_product(ca.vertcat(q_old[0], -q_old[1:4]), q_y)  # C(z_{k−d})ᵀ C(y)
    delta_omega = 4 * (y[3:6] - z_old[3:6])
    return _quaternion_product(_rotation_quaternion(tau * delta_omega), _quaternion_product(q_z, q_error))


def prediction_expr(y: Any, z_old: Any, z: Any, previous: Any, alpha: Any, tau: Any) -> tuple[Any, Any]:
    """(x̂, switched): the predictor's correction and its switching rule as SX expressions.

    From the delayed measurement y = [σ_y; ω_y/4], the model copy z_{k−d} (``z_old``) and z_k (``z``),
    the previous σ̂ (``previous``), α and τ (s): Ĉ = C(τ δω) C(z_k) C(z_{k−d})ᵀ C(y) by quaternion
    products, σ̂ its short MRP, the shadow when nearer ``previous`` (|σ̂|² > 1e-8), then the shadow
    when |σ̂|² >= α² (``switched`` = 1.0); x̂ = [σ̂; ω_z(k)/4 + (ω_y − ω_z(k−d))/4].
    """
    sigma_hat = _short_mrp_from_quaternion(_group_prediction_quaternion(y, z_old, z, tau))
    shadow = _safe_shadow(sigma_hat)
    nearer = ca.logic_and(
        ca.dot(sigma_hat, sigma_hat) > _CONTINUITY_FLOOR,
        ca.norm_2(shadow - previous) < ca.norm_2(sigma_hat - previous),
    )
    sigma_hat = ca.if_else(nearer, shadow, sigma_hat)
    switched = ca.if_else(ca.dot(sigma_hat, sigma_hat) >= alpha * alpha, 1.0, 0.0)
    sigma_hat = ca.if_else(switched, _safe_shadow(sigma_hat), sigma_hat)
    return ca.vertcat(sigma_hat, z[3:6] + (y[3:6] - z_old[3:6])), switched


def linear_model_step_expr(z: Any, u: Any, model_j_inv: Any, period: float) -> Any:
    """z_{k+1} = Φ z_k + Γ_m u: the exact zero-order-hold step of the model linearised about the origin,
    ẋ = A x + B_m u with A = [0 I; 0 0], B_m = [0; ¼ J_m⁻¹] (x = [σ; ω/4]): σ += h w + (h²/8) J_m⁻¹ u,
    w += (h/4) J_m⁻¹ u. ``model_j_inv``: J_m⁻¹ as 3 diagonal values or a 3x3 SX."""
    acceleration = model_j_inv @ u if model_j_inv.shape == (3, 3) else model_j_inv * u
    h = float(period)
    return ca.vertcat(z[0:3] + h * z[3:6] + (h * h / 8.0) * acceleration, z[3:6] + (h / 4.0) * acceleration)


def _linear_prediction_mrp(y: Any, z_old: Any, z: Any, tau: Any) -> Any:
    """The short MRP of Ĉ = C(p) C(y): the FSA increment v = τ w_y + S_σ as the rotation 4v, by its [3/2] Padé
    MRP p = v N/D (N = 15 − h, D = 15 − 6h, h = min(|v|², `PADE_HOLD`)), with one division. p's quaternion is
    (D² − |v|² N², 2 N D v) / n_p and σ_y's (1 − |σ_y|², 2 σ_y) / n_y, with n_p = D² + |v|² N² and
    n_y = 1 + |σ_y|² their norms; with Q the product of the unnormalised two, the short MRP of Ĉ is
    sign(Q₀) Q_v / (n_p n_y + |Q₀|)."""
    increment = tau * y[3:6] + (z[0:3] - z_old[0:3] - tau * z_old[3:6])
    squared = ca.dot(increment, increment)
    held = ca.if_else(squared > PADE_HOLD, PADE_HOLD, squared)
    numerator, denominator = 15 - held, 15 - 6 * held
    d2, n2 = denominator * denominator, squared * (numerator * numerator)
    measured = ca.dot(y[0:3], y[0:3])
    q_p = ca.vertcat(d2 - n2, (2 * numerator * denominator) * increment)
    q = _quaternion_product(q_p, ca.vertcat(1 - measured, 2 * y[0:3]))
    return (ca.if_else(q[0] >= 0, 1.0, -1.0) / ((d2 + n2) * (1 + measured) + ca.fabs(q[0]))) * q[1:4]


def linear_prediction_expr(y: Any, z_old: Any, z: Any, previous: Any, alpha: Any, tau: Any) -> tuple[Any, Any]:
    """(x̂, switched) of the linear predictor form (`PredictorForm.LINEAR`) as SX expressions.

    The copy z is linear (`linear_model_step_expr`), so S = z_k − Φ^d z_{k−d} is its forced response over the
    last τ: S_σ = z_σ(k) − z_σ(k−d) − τ z_w(k−d), S_w = z_w(k) − z_w(k−d). The FSA prediction's σ increment
    v = τ w_y + S_σ is applied to the measured attitude as the rotation by 4v: Ĉ = C(p) C(y), with
    p = v (15 − h)/(15 − 6 h), h = min(|v|², `PADE_HOLD`), the [3/2] Padé form of tan(|v|) v/|v| (relative
    error below 1e-3 up to a rotation of π over τ); ŵ = w_y + S_w. The rule of
    [`prediction_expr`][mrpctl.loop.functions.prediction_expr] without dividing first: with s = |σ̂|² and
    c = σ̂·σ̂_{k−1}, the shadow −σ̂/s is nearer σ̂_{k−1} exactly when 1 + 2c < s (s − 2c) (continuity, when
    s > 1e-8), and the set chosen has |σ̂|² >= α² exactly when s >= α² (σ̂ kept) or α² s <= 1 (the shadow taken).
    No libm call; two divisions (the MRP of Ĉ, `_linear_prediction_mrp`, and the shadow).
    """
    sigma = _linear_prediction_mrp(y, z_old, z, tau)
    squared = ca.dot(sigma, sigma)
    along = ca.dot(sigma, previous)
    nearer = ca.logic_and(squared > _CONTINUITY_FLOOR, 1 + 2 * along < squared * (squared - 2 * along))
    limit = alpha * alpha
    switched = ca.if_else(nearer, limit * squared <= 1, squared >= limit)
    shadow = (-1 / ca.if_else(squared > 0, squared, 1.0)) * sigma
    sigma_hat = ca.if_else(nearer, ca.if_else(switched, sigma, shadow), ca.if_else(switched, shadow, sigma))
    return ca.vertcat(sigma_hat, y[3:6] + (z[3:6] - z_old[3:6])), ca.if_else(switched, 1.0, 0.0)


def _safe_shadow(sigma: Any) -> Any:
    # Both if_else branches are evaluated: keep the unused shadow of σ = 0 finite.
    squared = ca.dot(sigma, sigma)
    return -sigma / ca.if_else(squared > 0, squared, 1.0)


def chunk_function(sample: ca.Function, d: int) -> ca.Function:
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


def flight_chunk_function(sample: ca.Function, d: int) -> ca.Function:
    """``chunk(x, memory, history, noise[, torque]) -> (x_end, memory_end, states, measurements, u, switched)``.

    max(d, 1) samples of the flight ``sample`` (a ``mapaccum``); ``history`` holds the
    measurements m_{k−d}, …, m_{k−1} (the previous chunk's ``measurements``), ``noise`` one
    column (θ_k; η_k) per sample, ``states`` the bookkept true states x_k; ``torque`` (when
    ``sample`` has it: a per-sample disturbance) one column w_k (N m) per sample; ``reference`` and
    ``reference_error`` (a tracking sample) one column (9) per sample each, and a last output ``tracking_error``
    (6 per sample).
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
    for name in ("reference", "reference_error"):  # a tracking sample: one reference row per sample
        if name in sample.name_in():
            inputs.append(ca.MX.sym(name, REFERENCE_WIDTH, length))
            names.append(name)
    outs = accumulated(*inputs)
    xs, memories, states, u, switched, measurements = outs[0:6]
    tracking = ["tracking_error"] if "tracking_error" in sample.name_out() else []
    return ca.Function(
        "chunk",
        inputs,
        [xs[:, length - 1], memories[:, length - 1], states, measurements, u, switched, *outs[6 : 6 + len(tracking)]],
        names,
        ["x_end", "memory_end", "states", "measurements", "u", "switched", *tracking],
    )
