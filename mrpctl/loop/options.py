"""The loop as flown, resolved once: the actuator, disturbance, sensor, delay and predictor options checked
against the rule and turned into the run-time constants and initial memories of the compiled samples.

`simulate`, `simulate_batch`, the lanes, the predictor and `export` all resolve their options here.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mrpctl._compile import find_compiler
from mrpctl.errors import CodegenError, SpecificationError
from mrpctl.flight import (
    FLIGHT_MEMORY_SIZE,
    ActuatorModel,
    DelayKind,
    DelayModel,
    Disturbance,
    Hysteretic,
    Saturation,
    SensorModel,
)
from mrpctl.guidance import CircularOrbit, NadirPointing
from mrpctl.loop.functions import PREDICTOR_MEMORY_SIZE, inertia_input, inertia_values
from mrpctl.model import ORBIT_SIZE
from mrpctl.predictor import OnPredicted, Predictor
from mrpctl.spacecraft import Spacecraft

__all__ = [
    "NO_FLIGHT_OPTIONS",
    "as_disturbance",
    "check_predictor",
    "flight_constants",
    "flight_memory",
    "flight_options",
    "flight_structure",
    "gravity_gradient_options",
    "orbit_constants",
    "predictor_constants",
    "predictor_disturbance",
    "predictor_memory",
    "varying_delay",
]


def as_disturbance(value: Any, name: str = "disturbance") -> Disturbance:
    """``value`` as a [Disturbance][mrpctl.flight.Disturbance] (a (3,) torque or (n, 3) rows, N m); an error
    names ``name``, the parameter it came from."""
    if isinstance(value, Disturbance):
        return value
    try:
        return Disturbance(value)
    except ValueError as error:
        message = str(error)
        raise type(error)(message if message.startswith(name) else f"{name}: {message}") from error


def flight_options(
    rule: Any, actuator: Any, disturbance: Any, sensor: Any = None
) -> tuple[np.ndarray | None, Saturation]:
    """The flight sample's constants (u_max (3), u_norm, w (3), bias (3)) and the saturation mode."""
    if actuator is None and disturbance is None and sensor is None:
        return None, Saturation.SCALE
    if not isinstance(rule, Hysteretic):
        raise SpecificationError(
            "actuator, disturbance, sensor: the actuator, disturbance and sensor models run in the flight loop only; "
            f"use rule=mrpctl.flight.Hysteretic(delta) (Hysteretic(0.0) is OnCurrent's control), got {rule}"
        )
    return flight_constants(actuator, disturbance, sensor)


def flight_constants(actuator: Any, disturbance: Any, sensor: Any) -> tuple[np.ndarray | None, Saturation]:
    """The checked actuator, disturbance and sensor models as the flight constants and the saturation mode.

    A per-sample disturbance ((n, 3) rows or a function of time; the flight loop and the predictor
    stream it) leaves w = 0 in the constants."""
    if actuator is None and disturbance is None and sensor is None:
        return None, Saturation.SCALE
    if actuator is not None and not isinstance(actuator, ActuatorModel):
        raise SpecificationError(f"actuator must be a mrpctl.flight.ActuatorModel or None, got {actuator!r}")
    if disturbance is not None:
        disturbance = as_disturbance(disturbance)
    if sensor is not None and not isinstance(sensor, SensorModel):
        raise SpecificationError(f"sensor must be a mrpctl.flight.SensorModel or None, got {sensor!r}")
    options = np.zeros(10)
    options[0:4] = np.inf
    if sensor is not None:
        options[7:10] = sensor.gyro_bias
    if actuator is not None:
        options[0:3] = actuator.u_max
        options[3] = actuator.norm_limit
    if disturbance is not None and disturbance.constant:
        options[4:7] = disturbance.torque
    return options, Saturation.SCALE if actuator is None else actuator.mode


def predictor_disturbance(disturbance: Any, n: int | None, name: str = "disturbance") -> Disturbance | None:
    """The predictor run's disturbance as a [`Disturbance`][mrpctl.flight.Disturbance] (None: none), per-sample rows
    checked
    against the n samples of the run (None: an export, any number of rows); an error names ``name``
    (the parameter, or ``disturbance[i]``)."""
    if disturbance is None:
        return None
    try:
        if not isinstance(disturbance, Disturbance):
            disturbance = Disturbance(disturbance)
        if n is not None:
            disturbance.check_horizon(n)
    except ValueError as error:
        message = str(error)
        raise type(error)(message if message.startswith(name) else f"{name}: {message}") from error
    return disturbance


def check_predictor(predictor: Any, rule: Any, history: Any, delay: Any, *, compiled: bool = True) -> Predictor | None:
    """The predictor option, checked against the rule, the history and the delay model (and, with
    ``compiled``, that a C compiler is there to run it)."""
    if predictor is None:
        if isinstance(rule, OnPredicted):
            raise SpecificationError(
                "rule: OnPredicted switches on the predicted attitude; give predictor=mrpctl.Predictor(model=...)"
            )
        return None
    if not isinstance(predictor, Predictor):
        raise SpecificationError(f"predictor must be a mrpctl.Predictor or None, got {predictor!r}")
    if not isinstance(rule, OnPredicted):
        raise SpecificationError(
            "rule: with a predictor the controller chooses its MRP set on the predicted attitude; use "
            f"rule=mrpctl.OnPredicted(alpha) (alpha=1: short set, > 1: hysteresis, None: never switch), got {rule}"
        )
    if not (isinstance(history, str) and history == "constant"):
        raise SpecificationError(
            "history: the predictor's model copy starts at x0, the constant history; only history='constant' is "
            f"supported with a predictor, got {history if isinstance(history, str) else 'an array'}"
        )
    if delay is not None:
        raise SpecificationError(
            "delay: the predictor runs with the constant delay tau only (its correction needs the age of each "
            "measurement; a DelayModel, jitter included, is not supported with a predictor): drop delay="
        )
    if compiled and find_compiler() is None:
        raise CodegenError("predictor: the predictor loop needs the compiled engine (a C compiler); none was found")
    return predictor


def varying_delay(rule: Any, delay: Any, d: int, rate: float, n: int) -> DelayModel | None:
    """The delay model the engine schedules (None: the constant delay d)."""
    if delay is None:
        return None
    if not isinstance(delay, DelayModel):
        raise SpecificationError(f"delay must be a mrpctl.flight.DelayModel or None, got {delay!r}")
    if not isinstance(rule, Hysteretic):
        raise SpecificationError(
            f"delay: a time-varying delay runs in the flight loop only; use rule=mrpctl.flight.Hysteretic(delta) "
            f"(Hysteretic(0.0) is OnCurrent's control), got {rule}"
        )
    low, high = delay.bounds(rate)
    if high != d:
        raise SpecificationError(
            f"delay: tau must equal delay.tau_max (the history depth): tau is {d} periods, tau_max {high} periods"
        )
    if delay.kind is DelayKind.CONSTANT:
        return None
    if low < 1:
        raise SpecificationError(
            f"delay: tau_min must be >= 1/rate = {1.0 / rate:g} s in the engine (a measurement is used one period "
            f"after it is taken at the earliest), got {delay.tau_min:g} s"
        )
    delay.check_horizon(n)
    return delay


def flight_memory(x0: np.ndarray, history: np.ndarray, d: int) -> np.ndarray:
    """The flight sample's memory at k = 0: h = c = +1 and σ̃_prev the σ̃ the controller sees at k = 0.

    That is short(σ) of the first history row for d > 0, the bookkept σ0 (shadow when
    |σ0|² >= 1) for d = 0, so that the continuity test makes no flip at k = 0.
    """
    sigma = np.array(history[0][0:3] if d > 0 else x0[0:3], dtype=float)
    squared = float(sigma @ sigma)
    if squared > 1.0 or (d == 0 and squared >= 1.0):
        sigma = -sigma / squared
    memory = np.zeros(FLIGHT_MEMORY_SIZE)  # the actuator accumulators start at 0
    memory[0:2] = 1.0
    memory[2:5] = sigma
    return memory


def predictor_memory(x0: np.ndarray) -> np.ndarray:
    """The predictor sample's memory at k = 0: σ̂_prev = z_0 = short(x0) (|σ|² > 1: shadow), accumulators 0.

    The model copy starts at the initial state, the latest value of the constant history: for
    k < d the measurement and the model state at t_{k−d} are both that state, so x̂_k = z_k.
    """
    z = np.array(x0, dtype=float)
    squared = float(z[0:3] @ z[0:3])
    if squared > 1.0:
        z[0:3] = -z[0:3] / squared
    memory = np.zeros(PREDICTOR_MEMORY_SIZE)
    memory[0:2] = 1.0
    memory[2:5] = z[0:3]
    memory[FLIGHT_MEMORY_SIZE:] = z
    return memory


def predictor_constants(options: np.ndarray | None, tau: float, model: Spacecraft) -> np.ndarray:
    """The predictor sample's ``flight`` input: the flight constants (default none), τ (s), J_m, J_m⁻¹."""
    flight = NO_FLIGHT_OPTIONS if options is None else options
    inertia, inertia_inverse = inertia_values(model, inertia_input(model))
    return np.ascontiguousarray(np.concatenate((flight, [tau], inertia.ravel(), inertia_inverse.ravel())))


#: The flight sample's constants without actuator limits or disturbance: u_max = u_norm = inf, w = 0.
NO_FLIGHT_OPTIONS = np.array([np.inf, np.inf, np.inf, np.inf, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])


def flight_structure(options: np.ndarray | None, sensor: SensorModel | None) -> dict[str, bool]:
    """The flight sample's structure for a run's constants and sensor (keywords of `engine`).

    ``sensor``: noise or a gyro bias (an ideal sensor measures x_meas bit for bit); ``limited``:
    a finite u_max or u_norm; ``disturbed``: a non-zero torque w. ``options`` as
    `NO_FLIGHT_OPTIONS` (None: none), or (N, 10), one row per run: the union over the runs
    (the structure of a lane batch).
    """
    constants = NO_FLIGHT_OPTIONS if options is None else np.asarray(options, dtype=float)
    noisy = sensor is not None and (sensor.attitude_noise > 0.0 or sensor.rate_noise > 0.0)
    return {
        "sensor": bool(noisy or np.any(constants[..., 7:10] != 0.0)),
        "limited": bool(np.any(np.isfinite(constants[..., 0:4]))),
        "disturbed": bool(np.any(constants[..., 4:7] != 0.0)),
    }


def orbit_constants(value: Any, period: float, substeps: int, name: str = "gravity_gradient") -> np.ndarray:
    """The (`ORBIT_SIZE`,) constants (n, u₀, ê₁, ê₂, cos δ, sin δ) of a
    [`CircularOrbit`][mrpctl.guidance.CircularOrbit], or of the orbit of a
    [`NadirPointing`][mrpctl.guidance.NadirPointing], for RK4 substeps of dt = period/substeps (δ = n dt/2):
    what a gravity-gradient sample's ``flight`` input holds after the ten flight constants
    (``mrpctl.model.orbit_position_expr``, ``orbit_turn_expr``)."""
    orbit = value.orbit if isinstance(value, NadirPointing) else value
    if not isinstance(orbit, CircularOrbit):
        raise SpecificationError(
            f"{name} must be a mrpctl.guidance.CircularOrbit (or a NadirPointing, whose orbit is used) or None, "
            f"got {type(value).__name__}"
        )
    axes = orbit.in_plane_axes
    half = orbit.orbit_rate * (period / substeps / 2)  # the SX's dt/2, as the step function writes it
    constants = np.concatenate(
        ([orbit.orbit_rate, orbit.latitude], axes[:, 0], axes[:, 1], [np.cos(half), np.sin(half)])
    )
    assert constants.size == ORBIT_SIZE
    return constants


def gravity_gradient_options(
    value: Any,
    rule: Any,
    options: np.ndarray | None,
    *,
    period: float,
    substeps: int,
    predictor: Any = None,
    wheels: Any = None,
) -> np.ndarray | None:
    """The flight constants of a run with the gravity-gradient torque of ``value`` (`orbit_constants`) after
    ``options`` (None: `NO_FLIGHT_OPTIONS`); ``options`` unchanged when ``value`` is None. The torque is flown by the
    flight sample (``rule=Hysteretic(...)``) only: refused with the plant-side rules, the predictor and wheels."""
    if value is None:
        return options
    constants = orbit_constants(value, period, substeps)
    if predictor is not None:
        raise SpecificationError(
            "gravity_gradient: the predictor's plant does not fly the gravity-gradient torque yet (nor its model "
            "copy); fly it with rule=mrpctl.flight.Hysteretic(delta) and no predictor"
        )
    if wheels is not None:
        raise SpecificationError(
            "gravity_gradient: the wheel cluster's plant does not fly the gravity-gradient torque yet; fly it with an "
            "ideal body torque (wheels=None)"
        )
    if not isinstance(rule, Hysteretic):
        raise SpecificationError(
            "gravity_gradient: the gravity-gradient torque is flown by the flight loop only; use "
            f"rule=mrpctl.flight.Hysteretic(delta) (Hysteretic(0.0) is OnCurrent's control), got {rule}"
        )
    return np.concatenate((NO_FLIGHT_OPTIONS if options is None else options, constants))
