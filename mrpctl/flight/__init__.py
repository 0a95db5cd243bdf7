"""The loop as flown: sensor, actuator, delay and disturbance models, and controller-side set selection.

The paper's loop (``mrpctl.switching``) switches the *plant's* MRP and the controller reads back
whatever set the plant was in τ ago. Flight software works differently: a star tracker reports an
attitude, the plant's MRP set is a simulation detail, and the controller alone chooses which MRP set
to feed its control law, from the delayed (noisy) measurement, keeping that choice in its own memory.
This module holds the pieces of that loop (see ``design/flight.md`` for the equations):

* option values, frozen and validated: [`SensorModel`][mrpctl.flight.SensorModel],
[`ActuatorModel`][mrpctl.flight.ActuatorModel],
  [`DelayModel`][mrpctl.flight.DelayModel], [`Disturbance`][mrpctl.flight.Disturbance], and the controller-side rule
  [`Hysteretic`][mrpctl.flight.Hysteretic]
  (Mayhew, Sanfelice and Teel 2011);
* seeded noise and jitter streams that depend only on (seed, sample index), never on how the
  horizon is sliced ([`SensorModel.noise`][mrpctl.flight.SensorModel.noise],
  [`DelayModel.samples`][mrpctl.flight.DelayModel.samples]);
* the newest-arrived measurement schedule of a time-varying delay ([`newest_arrived`][mrpctl.flight.newest_arrived]);
* the CasADi expression builders of one flight sample, each also a small pure-SX
  ``casadi.Function`` with named ports: [`measurement_function`][mrpctl.flight.measurement_function],
  [`hysteresis_function`][mrpctl.flight.hysteresis_function], [`selection_function`][mrpctl.flight.selection_function],
  [`actuator_function`][mrpctl.flight.actuator_function].

Conventions are those of [`mrpctl.mrp`][mrpctl.mrp]: σ = tan(Φ/4) ê, quaternions scalar first,
[BN] passive, x = [σ; ω/4].
"""

from __future__ import annotations

from mrpctl.flight.expressions import (
    NoiseForm,
    Saturation,
    actuator_function,
    compose_mrp_expr,
    hysteresis_function,
    measurement_function,
    quaternion_from_mrp_expr,
    raw_measurement_function,
    rotation_mrp_function,
    rotation_vector_to_mrp_expr,
    selection_function,
    short_expr,
)
from mrpctl.flight.models import (
    FLIGHT_CONSTANTS_SIZE,
    FLIGHT_MEMORY_SIZE,
    NOISE_REVISION,
    NOISE_SIZE,
    STREAM_ATTITUDE,
    STREAM_JITTER,
    STREAM_RATE,
    ActuatorModel,
    DelayKind,
    DelayModel,
    Disturbance,
    Hysteretic,
    SensorModel,
    newest_arrived,
    newest_arrived_slice,
)
from mrpctl.flight.streams import stream_key, stream_normals
from mrpctl.flight.tracking import ErrorTime

__all__ = [
    "FLIGHT_CONSTANTS_SIZE",
    "FLIGHT_MEMORY_SIZE",
    "NOISE_REVISION",
    "NOISE_SIZE",
    "STREAM_ATTITUDE",
    "STREAM_JITTER",
    "STREAM_RATE",
    "ActuatorModel",
    "DelayKind",
    "DelayModel",
    "Disturbance",
    "ErrorTime",
    "Hysteretic",
    "NoiseForm",
    "Saturation",
    "SensorModel",
    "actuator_function",
    "compose_mrp_expr",
    "hysteresis_function",
    "measurement_function",
    "newest_arrived",
    "newest_arrived_slice",
    "quaternion_from_mrp_expr",
    "raw_measurement_function",
    "rotation_mrp_function",
    "rotation_vector_to_mrp_expr",
    "selection_function",
    "short_expr",
    "stream_key",
    "stream_normals",
]
