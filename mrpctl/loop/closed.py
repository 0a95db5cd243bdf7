"""The closed loop as CasADi Functions: controller, rule, RK4 step, one sample, one chunk.

`closed_loop_functions` assembles them (with the options of `mrpctl.loop.options` bound) into a
`ClosedLoopFunctions`.

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

from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from mrpctl._validation import finite_array, integer, readonly
from mrpctl.clock import check_substeps, delay_samples
from mrpctl.errors import SpecificationError
from mrpctl.flight import (
    FLIGHT_CONSTANTS_SIZE,
    FLIGHT_MEMORY_SIZE,
    NOISE_SIZE,
    ActuatorModel,
    DelayModel,
    Disturbance,
    Hysteretic,
    Saturation,
    SensorModel,
    actuator_function,
    measurement_function,
    selection_function,
    short_expr,
)
from mrpctl.flight.tracking import REFERENCE_WIDTH, ErrorTime, feedforward_expr, tracking_error_expr
from mrpctl.loop.functions import (
    CONTROLLER_MEMORY_SIZE,
    PREDICTOR_MEMORY_SIZE,
    PREDICTOR_RING_WIDTH,
    InertiaInput,
    chunk_function,
    core_function,
    flight_chunk_function,
    flight_core_function,
    inertia_input,
    inertia_values,
    linear_model_step_expr,
    linear_prediction_expr,
    prediction_expr,
    predictor_core_function,
    step_function,
)
from mrpctl.loop.options import (
    NO_FLIGHT_OPTIONS,
    check_predictor,
    flight_constants,
    flight_memory,
    flight_options,
    predictor_constants,
    predictor_disturbance,
    varying_delay,
)
from mrpctl.model import INPUT_SIZE, STATE_SIZE, gain_matrix, plant_model
from mrpctl.predictor import OnPredicted, PredictorForm
from mrpctl.spacecraft import Spacecraft, check_spacecraft
from mrpctl.switching import MEMORY_SIZE, OnCurrent, SwitchingRule

__all__ = [
    "PREDICTOR_MEMORY_LAYOUT",
    "ClosedLoopFunctions",
    "FlightOptions",
    "check_rule",
    "closed_loop_functions",
]


def check_rule(rule: Any, name: str = "rule") -> SwitchingRule:
    """Return ``rule`` if it is a [`SwitchingRule`][mrpctl.switching.SwitchingRule], else raise SpecificationError."""
    if not isinstance(rule, SwitchingRule):
        raise SpecificationError(
            f"{name} must be a switching rule such as mrpctl.switching.OnDelayed(), got {type(rule).__name__}: {rule!r}"
        )
    return rule


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
    tracking_controller : casadi.Function or None
        Tracking loop only (``tracking=True``): ``tracking_controller(x_meas, memory, reference, delta) ->
        (u, u_command, memory_next, switched, sigma_br)``: the flight controller on the tracking error of the
        delayed measurement against ``reference`` (9: σ_R/N, ω_R/N, ω̇_R/N, the row of the error time;
        ``design/tracking.md``), memory (h, c, σ_B/R,prev), u_command = K [σ_c; ω_B/R/4] (+ feedforward).
        ``sample`` and ``chunk`` then take ``reference`` (the row of t_k: the true error) and
        ``reference_error`` (the row of the error time) and give ``tracking_error`` (the true [σ_B/R; ω_B/R/4]).
    tracking : dict or None
        Tracking loop only: ``{"error_time": ErrorTime, "feedforward": bool}``.
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
    tracking_controller: ca.Function | None = field(default=None, repr=False)
    tracking: dict[str, Any] | None = None

    @property
    def period(self) -> float:
        """Measurement period h = 1/rate (s)."""
        return 1.0 / self.rate

    def functions(self) -> dict[str, ca.Function]:
        """The Functions by name, for export.

        Paper rules: dynamics, controller, rule, step, sample, chunk. Flight loop:
        dynamics, flight_controller, sensor, step, sample, chunk; tracking: tracking_controller in place of
        flight_controller. Predictor: dynamics,
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
        if self.tracking_controller is not None and self.sensor is not None:
            return {
                "dynamics": self.dynamics,
                "tracking_controller": self.tracking_controller,
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
    tracking: bool = False,
    error_time: ErrorTime = ErrorTime.MEASUREMENT,
    feedforward: bool = False,
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
    tracking, error_time, feedforward : keyword-only
        The tracking loop (``rule=Hysteretic(...)``): ``sample`` and ``chunk`` take the reference rows and
        ``tracking_controller`` replaces ``flight_controller`` (see
        [`ClosedLoopFunctions`][mrpctl.loop.ClosedLoopFunctions]); ``error_time`` is recorded (which row the
        caller feeds as ``reference_error``), ``feedforward`` adds the feedforward terms.

    Raises
    ------
    SpecificationError, DimensionError
        On invalid parameters, or a flight model with a paper rule.
    """
    spacecraft = check_spacecraft(spacecraft)
    gain = gain_matrix(K)
    rule = check_rule(rule)
    d = delay_samples(tau, rate)
    rate = float(rate)
    substeps = check_substeps(substeps)
    period = 1.0 / rate
    if not isinstance(tracking, bool) or not isinstance(feedforward, bool):
        raise SpecificationError(f"tracking, feedforward must be True or False, got {tracking!r}, {feedforward!r}")
    if feedforward and not tracking:
        raise SpecificationError("feedforward: the feedforward terms need the tracking loop (tracking=True)")
    tracked = None
    if tracking:
        if predictor is not None or not isinstance(rule, Hysteretic):
            raise SpecificationError(
                f"tracking: the tracking loop is the flight loop's (rule=mrpctl.flight.Hysteretic(delta), no "
                f"predictor), got rule {rule}"
            )
        try:
            tracked = {"error_time": ErrorTime(error_time), "feedforward": feedforward}
        except ValueError as error:
            raise SpecificationError(f"error_time must be an mrpctl.flight.ErrorTime, got {error_time!r}") from error
    if predictor is not None or isinstance(rule, OnPredicted):
        return _predictor_loop(
            spacecraft, gain, rule, d, float(tau), rate, substeps, actuator, disturbance, sensor, delay, predictor
        )
    options, saturation = flight_options(rule, actuator, disturbance, sensor)
    sequence = getattr(delay, "delays", None)
    horizon = 1 if sequence is None else len(sequence)
    varying = varying_delay(rule, delay, d, rate, horizon)
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
            spacecraft, gain, rule, d, period, substeps, flight, tracked
        )
        return ClosedLoopFunctions(
            **common,
            controller=controller,
            sample=sample,
            chunk=flight_chunk_function(sample, d),
            flight_controller=flight_controller if tracked is None else None,
            sensor=sensor_function,
            flight=flight,
            tracking_controller=None if tracked is None else flight_controller,
            tracking=tracked,
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
        chunk=chunk_function(sample, d),
    )


def _flight_functions(
    spacecraft: Spacecraft,
    gain: np.ndarray,
    rule: Hysteretic,
    d: int,
    period: float,
    substeps: int,
    flight: FlightOptions,
    tracked: dict[str, Any] | None = None,
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
    tracking = {} if tracked is None else {"reference_input": True, "feedforward": tracked["feedforward"]}
    core = flight_core_function(
        spacecraft, d, period, substeps, saturation=flight.saturation, torque_input=per_sample, **tracking
    )
    x = ca.SX.sym("x", STATE_SIZE)
    memory = ca.SX.sym("memory", FLIGHT_MEMORY_SIZE)
    x_delayed = ca.SX.sym("x_delayed", STATE_SIZE)
    noise = ca.SX.sym("noise", NOISE_SIZE)
    inputs, names = [x, memory, x_delayed, noise], ["x", "memory", "x_delayed", "noise"]
    torque = [ca.SX.sym("torque", INPUT_SIZE)] if per_sample else []  # w_k, the per-sample disturbance
    rows = [ca.SX.sym(name, REFERENCE_WIDTH) for name in ("reference", "reference_error")] if tracking else []
    bound = list(core(x, memory, x_delayed, ca.DM(gain), ca.DM(rule.parameters()), constants, noise, *torque, *rows))
    sample = ca.Function(
        "sample",
        inputs + torque + rows,
        bound,
        names + (["torque"] if per_sample else []) + (["reference", "reference_error"] if tracking else []),
        ["x_next", "memory_next", "x_meas", "u", "switched", "measurement"] + (["tracking_error"] if tracking else []),
    )

    measured = ca.SX.sym("x_meas", STATE_SIZE)
    controller_memory = ca.SX.sym("memory", CONTROLLER_MEMORY_SIZE)
    delta = ca.SX.sym("delta")
    sigma_seen = short_expr(measured[0:3])
    rate_seen = measured[3:6]
    row = ca.SX.sym("reference", REFERENCE_WIDTH)
    if tracked is not None:  # the sample's expressions in the same order (flight_core_function)
        sigma_bn = sigma_seen
        sigma_seen, rate_seen, omega_r_body, scale = tracking_error_expr(sigma_bn, measured[3:6], row[0:3], row[3:6])
    h_next, c_next, sigma_c, switched = selection_function()(
        controller_memory[0], controller_memory[1], sigma_seen, controller_memory[2:5], delta
    )
    command = ca.DM(gain) @ ca.vertcat(sigma_c, rate_seen)
    if tracked is not None and tracked["feedforward"]:
        inertia = ca.DM(spacecraft.inertia)
        command = command + feedforward_expr(inertia, 4 * measured[3:6], sigma_bn, omega_r_body, row[6:9], scale)
    u = actuator_function(flight.saturation)(command, constants[0:3], constants[3], ca.DM.zeros(3))[0]
    if tracked is not None:
        controller = ca.Function(
            "tracking_controller",
            [measured, controller_memory, row, delta],
            [u, command, ca.vertcat(h_next, c_next, sigma_seen), switched, sigma_seen],
            ["x_meas", "memory", "reference", "delta"],
            ["u", "u_command", "memory_next", "switched", "sigma_br"],
        )
    else:
        controller = ca.Function(
            "flight_controller",
            [measured, controller_memory, delta],
            [u, command, ca.vertcat(h_next, c_next, sigma_seen), switched],
            ["x_meas", "memory", "delta"],
            ["u", "u_command", "memory_next", "switched"],
        )

    true_state = OnCurrent().expressions(x, x, ca.SX.zeros(MEMORY_SIZE), delay_samples=d)[0]
    measurement = measurement_function()(true_state, noise[0:3], noise[3:6], constants[7:10])[0]
    sensor = ca.Function("sensor", [x, noise], [true_state, measurement], ["x", "noise"], ["x_true", "measurement"])
    return sample, controller, sensor


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
      model copy: `prediction_expr`, u_c = K x̂, the actuator, z_{k+1} = short(RK4_m(z_k, u));
    * ``prediction(y, z_delayed, z, sigma_prev) -> (x_hat, switched)``: the correction and the rule;
    * ``model_step(z, u) -> z_next``: one RK4 step of J_m over h, kept in the short set;
    * with the predictor's form `PredictorForm.LINEAR`: `linear_prediction_expr` and the linear copy's exact ZOH
      step (`linear_model_step_expr`, never shortened) in their place;
    * ``sensor(x, noise) -> (x_true, measurement)``: as in the flight loop.

    The pieces are written from the same builders in the same order as ``sample``.
    """
    checked = check_predictor(predictor, rule, "constant", delay, compiled=False)
    assert checked is not None
    disturbance = predictor_disturbance(disturbance, None)
    per_sample = disturbance is not None and not disturbance.constant
    options, saturation = flight_constants(actuator, disturbance, sensor)
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
        form=checked.form,
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
    linear = checked.form is PredictorForm.LINEAR
    if linear:
        j_inv = ca.DM(model_j_inv if model_kind is InertiaInput.DIAGONAL else checked.model.inertia_inverse)
        z_next = linear_model_step_expr(z, u_in, j_inv, period)
    else:
        raw = step_function(spacecraft, period, 1, inertia=model_kind)(z, u_in, ca.DM(model_j), ca.DM(model_j_inv))
        z_next = ca.vertcat(short_expr(raw[0:3]), raw[3:6])
    model_step = ca.Function("model_step", [z, u_in], [z_next], ["z", "u"], ["z_next"])
    y = ca.SX.sym("y", STATE_SIZE)
    z_delayed = ca.SX.sym("z_delayed", STATE_SIZE)
    previous = ca.SX.sym("sigma_prev", 3)
    predict = linear_prediction_expr if linear else prediction_expr
    x_hat, switched = predict(y, z_delayed, z, previous, alpha[0], constants[FLIGHT_CONSTANTS_SIZE])
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
