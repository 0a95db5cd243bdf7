"""The closed loop as CasADi Functions, shared by the simulator's engines and by the export.

One description of the loop as flown, in three modules that import one way:

* `mrpctl.loop.functions`: the RK4 step, the sample cores (paper rules, controller-side hysteresis
  with actuator, disturbance, sensor and delay, the predictor) and their chunks;
* `mrpctl.loop.options`: the flight options resolved against the rule (constants, initial memories);
* `mrpctl.loop.closed`: `closed_loop_functions`, the named Functions of one loop.

The sample clock (`delay_samples`, `check_substeps`, `MAX_SUBSTEPS`) lives in `mrpctl.clock`, below the
predictor, and is re-exported here.
"""

from __future__ import annotations

from mrpctl.clock import MAX_SUBSTEPS, check_substeps, delay_samples
from mrpctl.loop.closed import (
    PREDICTOR_MEMORY_LAYOUT,
    ClosedLoopFunctions,
    FlightOptions,
    check_rule,
    closed_loop_functions,
)
from mrpctl.loop.functions import (
    CONTROLLER_MEMORY_SIZE,
    FLIGHT_MEMORY_LAYOUT,
    PREDICTOR_MEMORY_SIZE,
    PREDICTOR_RING_WIDTH,
    InertiaInput,
    core_function,
    flight_core_function,
    inertia_input,
    inertia_values,
    predictor_constants_size,
    predictor_core_function,
    step_function,
)

__all__ = [
    "CONTROLLER_MEMORY_SIZE",
    "FLIGHT_MEMORY_LAYOUT",
    "MAX_SUBSTEPS",
    "PREDICTOR_MEMORY_LAYOUT",
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
