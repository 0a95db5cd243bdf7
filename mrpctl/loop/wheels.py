"""The flight sample on a reaction-wheel cluster: the controller-side rule, the allocation and the wheels (pure SX).

[`wheel_core_function`][mrpctl.loop.wheels.wheel_core_function] is the sample of
[`flight_core_function`][mrpctl.loop.flight_core_function] (the same ports, the same measurement, ring and
rule [`Hysteretic`][mrpctl.flight.Hysteretic]) with the body torque made by N wheels
([`WheelCluster`][mrpctl.wheels.WheelCluster]): the command u_c is allocated to motor torques by
the minimum-norm pseudo-inverse (plus the null-space term), each motor torque is clipped to its
wheel's u_max and cut by its speed limit, held over the period, and the spacecraft and its wheels
are integrated together by RK4 ([`wheel_dynamics_expr`][mrpctl.model.wheel_dynamics_expr]). The wheel
speeds are carried in the sample's memory after the flight sample's ten entries
(`WHEEL_MEMORY_FIELDS`). Equations and semantics: ``design/wheels.md``.
"""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from mrpctl.errors import SpecificationError
from mrpctl.flight import (
    FLIGHT_CONSTANTS_SIZE,
    FLIGHT_MEMORY_SIZE,
    NOISE_SIZE,
    NoiseForm,
    raw_measurement_function,
    selection_function,
    short_expr,
)
from mrpctl.flight.steering import SteeringLaw, steering_command_expr
from mrpctl.model import (
    INPUT_SIZE,
    STATE_SIZE,
    wheel_body_rate_expr,
    wheel_hub_inertia,
    wheel_momenta_expr,
    wheel_momentum_dynamics_expr,
    wheel_speeds_expr,
)
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import MEMORY_SIZE, PARAMETER_SIZE, OnCurrent
from mrpctl.wheels import WheelCluster, allocation_matrix, null_space_projector, wheel_memory_size

__all__ = [
    "SQUARED_PEAKS",
    "wheel_allocation_function",
    "wheel_controller_function",
    "wheel_core_function",
    "wheel_memory",
    "wheel_memory_roots",
    "wheel_step_function",
]


def wheel_step_function(spacecraft: Spacecraft, wheels: WheelCluster, period: float, substeps: int) -> ca.Function:
    """``step(x, speeds, motor, w) -> (x_next, speeds_next)``: RK4 over one period h of the spacecraft and its
    wheels with the motor torques and the external torque held, ``substeps`` equal substeps.

    RK4 steps the momentum coordinates (σ, H, h_s) of
    [`wheel_momentum_dynamics_expr`][mrpctl.model.wheel_momentum_dynamics_expr], mapped from (σ, ω, Ω) at the
    start and back at the end ([`wheel_momenta_expr`][mrpctl.model.wheel_momenta_expr],
    [`wheel_body_rate_expr`][mrpctl.model.wheel_body_rate_expr], [`wheel_speeds_expr`][mrpctl.model.wheel_speeds_expr]):
    a linear change of coordinates, under which RK4's steps are the same up to rounding. Without friction
    ḣ_s = u_s does not depend on the state: h_s at a stage's time t is h_s(0) + t u_s (RK4's weighted sum of
    four equal slopes is that value too), and the body rate, linear in (H, h_s), is ω = f(H, 0) + r(t) with
    r(t) = r(0) + t f(0, u_s) and r(0) = ω(0) − f(H(0), 0) (f = `wheel_body_rate_expr`): one M⁻¹ H a stage and
    nothing per wheel; Ω(h) = Ω(0) + g(ω(h) − ω(0), h u_s) (g = `wheel_speeds_expr`, linear, with
    g(ω(0), h_s(0)) = Ω(0))."""
    count = wheels.count
    x = ca.SX.sym("x", STATE_SIZE)
    speeds = ca.SX.sym("speeds", count)
    motor = ca.SX.sym("motor", count)
    w = ca.SX.sym("w", INPUT_SIZE)
    attitude, spin = ca.SX.sym("attitude", 6), ca.SX.sym("spin", count)  # (σ, H) and h_s
    sigma_dot, momentum_dot, spin_dot = wheel_momentum_dynamics_expr(
        spacecraft, wheels, attitude[0:3], attitude[3:6], spin, motor, w
    )
    dt = period / substeps
    omega = 4 * x[3:6]
    total, s = wheel_momenta_expr(spacecraft, wheels, omega, speeds)
    z = ca.vertcat(x[0:3], total)
    change = ca.DM.zeros(3)  # H − H(0), the sum of the substeps' increments
    if ca.depends_on(spin_dot, ca.vertcat(attitude, spin)):  # friction: h_s is a state of the stages
        dynamics = ca.Function(
            "wheel_momentum_dynamics", [attitude, spin, motor, w], [ca.vertcat(sigma_dot, momentum_dot), spin_dot]
        )
        spun = ca.DM.zeros(count)  # h_s − h_s(0)
        for _ in range(substeps):
            k1, l1 = dynamics(z, s, motor, w)
            k2, l2 = dynamics(z + (dt / 2) * k1, s + (dt / 2) * l1, motor, w)
            k3, l3 = dynamics(z + (dt / 2) * k2, s + (dt / 2) * l2, motor, w)
            k4, l4 = dynamics(z + dt * k3, s + dt * l3, motor, w)
            step_z = (dt / 6) * (k1 + 2 * k2 + 2 * k3 + k4)
            step_s = (dt / 6) * (l1 + 2 * l2 + 2 * l3 + l4)
            z, s = z + step_z, s + step_s
            change, spun = change + step_z[3:6], spun + step_s
        turned = wheel_body_rate_expr(spacecraft, wheels, change, spun)  # ω(h) − ω(0)
        x_next = ca.vertcat(z[0:3], (omega + turned) / 4)
        return _step(x, speeds, motor, w, x_next, speeds + wheel_speeds_expr(wheels, turned, spun))
    # no friction: ḣ_s = u_s held; the stages' body rates from the linearity of ω in (H, h_s)
    rate = ca.SX.sym("omega", 3)
    held = wheel_momentum_dynamics_expr(spacecraft, wheels, attitude[0:3], attitude[3:6], spin, motor, w, omega=rate)
    dynamics = ca.Function("wheel_momentum_dynamics", [attitude, rate, w], [ca.vertcat(held[0], held[1])])
    zero = ca.DM.zeros(count)

    def free(momentum: Any) -> Any:  # f(H, 0) = M⁻¹ H
        return wheel_body_rate_expr(spacecraft, wheels, momentum, zero)

    slope = wheel_body_rate_expr(spacecraft, wheels, ca.DM.zeros(3), spin_dot)  # f(0, u_s): dr/dt
    offset = omega - free(total)  # r(0)
    offsets: dict[int, Any] = {0: offset}

    def at(half_steps: int) -> Any:  # r at t = half_steps dt/2, one expression per time
        if half_steps not in offsets:
            offsets[half_steps] = offset + (half_steps * dt / 2) * slope
        return offsets[half_steps]

    for j in range(substeps):
        first = omega if j == 0 else free(z[3:6]) + at(2 * j)
        k1 = dynamics(z, first, w)
        y = z + (dt / 2) * k1
        k2 = dynamics(y, free(y[3:6]) + at(2 * j + 1), w)
        y = z + (dt / 2) * k2
        k3 = dynamics(y, free(y[3:6]) + at(2 * j + 1), w)
        y = z + dt * k3
        k4 = dynamics(y, free(y[3:6]) + at(2 * j + 2), w)
        step_z = (dt / 6) * (k1 + 2 * k2 + 2 * k3 + k4)
        z, change = z + step_z, change + step_z[3:6]
    # ω(h) − ω(0) = f(H(h) − H(0), h u_s), from the increments (no cancellation against the stored momenta)
    turned = free(change) + period * slope
    x_next = ca.vertcat(z[0:3], (omega + turned) / 4)
    return _step(x, speeds, motor, w, x_next, speeds + wheel_speeds_expr(wheels, turned, period * spin_dot))


def _step(x: Any, speeds: Any, motor: Any, w: Any, x_next: Any, speeds_next: Any) -> ca.Function:
    return ca.Function(
        "wheel_step",
        [x, speeds, motor, w],
        [x_next, speeds_next],
        ["x", "speeds", "motor", "w"],
        ["x_next", "speeds_next"],
    )


def wheel_allocation_function(spacecraft: Spacecraft, wheels: WheelCluster) -> ca.Function:
    """``allocation(command, omega, speeds) -> (motor, body, torque_limited, speed_limited)`` (pure SX).

    The controller's side of the wheels: from the body torque request u_c (N m), the measured rate ω
    (rad/s; used by the gyroscopic term only) and the wheel speeds Ω (rad/s):

    1. with ``gyroscopic``, u_c + ω × (J ω + Gs h_s), h_s,i = Js,i (g_iᵀ ω + Ω_i) (``mrpFeedback``);
    2. u_s = A u_c' − k_n P diag(Js) (Ω − Ω_bias) (A of [`allocation_matrix`][mrpctl.wheels.allocation_matrix],
       P of [`null_space_projector`][mrpctl.wheels.null_space_projector]; the second term with k_n > 0 only);
    3. each u_s,i clipped to [−u_max,i, u_max,i] (``torque_limited``_i = 1 when it was);
    4. u_s,i = 0 when |Ω_i| >= Ω_max,i and Ω_i u_s,i >= 0 (``speed_limited``_i = 1).

    ``motor`` is the motor torques (N m, on the wheels), ``body`` = −Gs u_s the torque the body receives
    from them (N m).
    """
    count = wheels.count
    command = ca.SX.sym("command", INPUT_SIZE)
    omega = ca.SX.sym("omega", INPUT_SIZE)
    speeds = ca.SX.sym("speeds", count)
    axes = ca.DM(wheels.spin_axes)
    js = ca.DM(wheels.spin_inertia)
    request = command
    if wheels.gyroscopic:
        # J ω + Gs h_s with h_s = diag(Js) (Gsᵀ ω + Ω): (J + Gs diag(Js) Gsᵀ) ω + Gs diag(Js) Ω, the constant
        # 2 J − M (M = J − Gs diag(Js) Gsᵀ) times ω and the wheels' momentum, which the sample computes anyway
        twice = ca.DM(2.0 * spacecraft.inertia - wheel_hub_inertia(spacecraft, wheels))
        request = command + ca.cross(omega, twice @ omega + axes @ (js * speeds))
    motor = ca.DM(allocation_matrix(wheels)) @ request
    if wheels.null_gain > 0.0:
        drive = ca.DM(-wheels.null_gain * null_space_projector(wheels))
        motor = motor + drive @ (js * (speeds - ca.DM(wheels.bias_speeds)))
    limit = ca.DM(wheels.torque_limit)
    torque_limited = ca.fabs(motor) > limit  # a comparison: 1.0 or 0.0
    motor = ca.fmin(ca.fmax(motor, -limit), limit)
    speed_limited = ca.logic_and(ca.fabs(speeds) >= ca.DM(wheels.speed_limit), speeds * motor >= 0)
    motor = ca.if_else(speed_limited, 0.0, motor)
    body = -(axes @ motor)
    return ca.Function(
        "allocation",
        [command, omega, speeds],
        [motor, body, torque_limited, speed_limited],
        ["command", "omega", "speeds"],
        ["motor", "body", "torque_limited", "speed_limited"],
    )


def wheel_controller_function(
    spacecraft: Spacecraft, wheels: WheelCluster, *, law: SteeringLaw | None = None
) -> ca.Function:
    """``wheel_controller(x_meas, memory, speeds, K, parameters) -> (motor, body, memory_next, command,
    torque_limited, speed_limited)`` (pure SX): the flight software of the wheel loop, once per sample.

    From the delayed measurement ``x_meas`` = [σ̃; ω̃/4] (the controller takes its short set), the
    controller memory (h, c, σ̃_prev) (5), the wheel speeds Ω_k (N, rad/s), the gain K (3 × 6, N m) and
    ``parameters`` = (δ,): the MRP set selection of [`Hysteretic`][mrpctl.flight.Hysteretic], u_c =
    K [σ_c; ω̃/4] (``command``, N m) and the allocation of
    [`wheel_allocation_function`][mrpctl.loop.wheels.wheel_allocation_function]: ``motor`` the wheel motor
    torques u_s (N m, clipped and speed-cut), ``body`` = −Gs u_s. The same expressions as the controller
    part of [`wheel_core_function`][mrpctl.loop.wheels.wheel_core_function]. With ``law`` (a
    [`SteeringLaw`][mrpctl.flight.steering.SteeringLaw]) u_c is the steering law's
    ([`steering_command_expr`][mrpctl.flight.steering.steering_command_expr], as in the wheel sample); None
    (default): the PD law.
    """
    allocation = wheel_allocation_function(spacecraft, wheels)
    x_meas = ca.SX.sym("x_meas", STATE_SIZE)
    memory = ca.SX.sym("memory", 5)
    speeds = ca.SX.sym("speeds", wheels.count)
    gain = ca.SX.sym("K", INPUT_SIZE, STATE_SIZE)
    parameters = ca.SX.sym("parameters", PARAMETER_SIZE)
    sigma_seen = short_expr(x_meas[0:3])
    h_next, c_next, sigma_c, _ = selection_function()(memory[0], memory[1], sigma_seen, memory[2:5], parameters[0])
    if law is None:
        command = gain @ ca.vertcat(sigma_c, x_meas[3:6])
    else:
        command = steering_command_expr(law, gain, sigma_c, x_meas[3:6])[0]
    motor, body, torque_limited, speed_limited = allocation(command, 4 * x_meas[3:6], speeds)
    return ca.Function(
        "wheel_controller",
        [x_meas, memory, speeds, gain, parameters],
        [motor, body, ca.vertcat(h_next, c_next, sigma_seen), command, torque_limited, speed_limited],
        ["x_meas", "memory", "speeds", "K", "parameters"],
        ["motor", "body", "memory_next", "command", "torque_limited", "speed_limited"],
    )


#: The entries of the wheel sample's memory kept squared: the peak |u_c|² (N² m²) and the peak |Gs diag(Js) Ω|²
#: (N² m² s²), the last entries of the flight part and of the wheel part (the index from the end of the memory for
#: the second). The correctly rounded square root is monotone, so the root of the peak square is the peak of the
#: roots bit for bit: one root at the end of a run (`wheel_memory_roots`) instead of two a sample.
SQUARED_PEAKS = (FLIGHT_MEMORY_SIZE - 1, -1)


def wheel_memory_roots(memory: np.ndarray) -> np.ndarray:
    """The wheel sample's memory after a run (one row, or one row per run) with its `SQUARED_PEAKS` entries
    replaced by their square roots (a copy): the peak |u_c| (N m) and the peak |Gs diag(Js) Ω| (N m s)."""
    rows = np.array(memory, dtype=float)
    for index in SQUARED_PEAKS:
        rows[..., index] = np.sqrt(rows[..., index])
    return rows


def wheel_memory(flight_memory: np.ndarray, wheels: WheelCluster) -> np.ndarray:
    """The wheel sample's memory at k = 0: the flight sample's ``flight_memory`` (10), then Ω(0) and the
    wheel accumulators at 0 (`WHEEL_MEMORY_FIELDS`)."""
    part = np.zeros(wheel_memory_size(wheels.count))
    part[0 : wheels.count] = wheels.speeds
    return np.concatenate((np.asarray(flight_memory, dtype=float), part))


def wheel_core_function(
    spacecraft: Spacecraft,
    wheels: WheelCluster,
    d: int,
    period: float,
    substeps: int,
    *,
    sensor: bool = True,
    disturbed: bool = True,
    records: bool = False,
    torque_input: bool = False,
    noise_form: NoiseForm = NoiseForm.ROTATION_VECTOR,
    short_measurements: bool = False,
    law: SteeringLaw | None = None,
) -> ca.Function:
    """One sample of the flight loop on the wheel cluster (pure SX).

    ``core(x, memory, x_delayed, K, parameters, flight[, noise][, torque]) ->
    (x_next, memory_next, x_meas, u, switched[, measurement][, record])``: the ports of
    [`flight_core_function`][mrpctl.loop.flight_core_function] without a run-time inertia (J, the wheels
    and the allocation are constants of the sample). ``memory`` is the flight sample's ten entries
    (h, c, σ̃_prev, the samples with a wheel clipped to its torque limit, peak |u_c,i|, peak |u_c|) and
    the wheel part (Ω, peak |Ω_i|, samples at the torque limit and at the speed limit per wheel, peak
    |Gs diag(Js) Ω|), the two peak norms kept squared (`SQUARED_PEAKS`, `wheel_memory_roots` after a run);
    ``flight`` = (u_max (3), u_norm, w (3), gyro bias (3)) whose u_max, u_norm must be inf (the limits are
    the wheels'). ``u`` is the body torque of the motors −Gs u_s (N m);
    ``record`` (with ``records``) = (h_{k+1}, σ_c,k, u_c,k, Ω_k (N), u_s,k (N)). The wheel speeds the
    controller reads are those of the sample instant (tachometers, no delay); the attitude and the
    rate are the delayed measurement, as in the flight sample. ``law``: the body torque request u_c is the
    steering law's ([`steering_command_expr`][mrpctl.flight.steering.steering_command_expr], as in the flight
    sample), then allocated to the wheels; None (default): the PD law u_c = K [σ_c; ω̃/4]. The other keywords
    as in [`flight_core_function`][mrpctl.loop.flight_core_function].
    """
    if short_measurements and sensor:
        raise SpecificationError("short_measurements: only without a sensor (its measurements are not bookkept)")
    count = wheels.count
    step = wheel_step_function(spacecraft, wheels, period, substeps)
    allocation = wheel_allocation_function(spacecraft, wheels)
    size = FLIGHT_MEMORY_SIZE + wheel_memory_size(count)
    x = ca.SX.sym("x", STATE_SIZE)
    memory = ca.SX.sym("memory", size)
    x_delayed = ca.SX.sym("x_delayed", STATE_SIZE)
    gain = ca.SX.sym("K", INPUT_SIZE, STATE_SIZE)
    parameters = ca.SX.sym("parameters", PARAMETER_SIZE)
    flight = ca.SX.sym("flight", FLIGHT_CONSTANTS_SIZE)
    noise = ca.SX.sym("noise", NOISE_SIZE)
    torque = ca.SX.sym("torque", INPUT_SIZE)
    w = torque if torque_input else flight[4:7]
    disturbed = disturbed or torque_input
    x_meas = OnCurrent().expressions(x, x, memory[0:MEMORY_SIZE], delay_samples=d)[0]
    measure = raw_measurement_function(noise_form)
    measured = measure.call([x_meas, noise[0:3], noise[3:6], flight[7:10]])[0] if sensor else x_meas
    seen = x_delayed if d > 0 else measured
    sigma_seen = seen[0:3] if short_measurements else short_expr(seen[0:3])
    h_next, c_next, sigma_c, switched = selection_function()(
        memory[0], memory[1], sigma_seen, memory[2:5], parameters[0]
    )
    if law is None:
        command = gain @ ca.vertcat(sigma_c, seen[3:6])
    else:
        command = steering_command_expr(law, gain, sigma_c, seen[3:6])[0]
    start = FLIGHT_MEMORY_SIZE
    speeds = memory[start : start + count]
    motor, body, torque_limited, speed_limited = allocation(command, 4 * seen[3:6], speeds)
    x_next, speeds_next = step(x_meas, speeds, motor, w if disturbed else ca.DM.zeros(INPUT_SIZE))
    clipped = torque_limited[0]  # 1.0 when a wheel is at its torque limit: a comparison or their disjunction
    for i in range(1, count):
        clipped = ca.logic_or(clipped, torque_limited[i])
    peak_speed = memory[start + count : start + 2 * count]
    momentum = ca.sumsqr(ca.DM(wheels.spin_axes) @ (ca.DM(wheels.spin_inertia) * speeds))  # squared (SQUARED_PEAKS)
    # a sample that does not count leaves the memory as it was: the carried entries by a selection (the engines'
    # guard), the accumulators by adding 0 or taking the peak with 0 (each >= +0: the same bits, fewer operations)
    counted = ca.SX.sym("counted")

    def kept(new: Any, old: Any) -> Any:
        return ca.if_else(counted, new, old)

    def added(value: Any) -> Any:
        return ca.if_else(counted, value, 0.0)

    memory_next = ca.vertcat(
        kept(h_next, memory[0]),
        kept(c_next, memory[1]),
        kept(sigma_seen, memory[2:5]),
        memory[5] + added(clipped),
        ca.fmax(memory[6:9], added(ca.fabs(command))),
        ca.fmax(memory[9], added(ca.sumsqr(command))),
        kept(speeds_next, speeds),
        ca.fmax(peak_speed, added(ca.fabs(speeds))),
        memory[start + 2 * count : start + 3 * count] + added(torque_limited),
        memory[start + 3 * count : start + 4 * count] + added(speed_limited),
        ca.fmax(memory[start + 4 * count], added(momentum)),
    )
    names = ["x", "memory", "x_delayed", "K", "parameters", "flight"]
    inputs = [x, memory, x_delayed, gain, parameters, flight] + ([noise] if sensor else [])
    names += ["noise"] if sensor else []
    if torque_input:
        inputs.append(torque)
        names.append("torque")
    inputs.append(counted)
    names.append("counted")
    output_names = ["x_next", "memory_next", "x_meas", "u", "switched"] + (["measurement"] if sensor else [])
    outputs = [x_next, memory_next, x_meas, body, switched] + ([measured] if sensor else [])
    if records:
        output_names.append("record")
        # (h, σ_c, u_c, σ̃, ω̃) as the flight sample's record, then the wheel speeds and motor torques
        outputs.append(ca.vertcat(h_next, sigma_c, command, sigma_seen, 4 * seen[3:6], speeds, motor))
    # one node per repeated expression (the wheel momenta of the allocation, the step and the peaks, |Ω|, 4 ω̃):
    # the same operations on the same operands, the same numbers; the lanes' loops do not merge them themselves
    return ca.Function("core", inputs, ca.cse(outputs), names, output_names)
