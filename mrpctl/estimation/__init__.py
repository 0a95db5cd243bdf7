"""Attitude estimation: the sensors (a late star tracker, a gyro with a drifting bias) and the estimators.

* [`sensors`][mrpctl.estimation.sensors]: [`StarTracker`][mrpctl.estimation.StarTracker] and
  [`Gyro`][mrpctl.estimation.Gyro] as frozen, validated values, and their clock on the controller's;
* [`filters`][mrpctl.estimation.filters]: the MEKF and the MRP-based EKF with shadow-set switching as
  CasADi Functions (pure SX), the delayed star-tracker update by buffered re-propagation, the tuning
  (Farrenkopf's steady state as the default initial covariance);
* [`run`][mrpctl.estimation.run]: the sensors' streams and the filter compiled over a whole run;
* [`setup`][mrpctl.estimation.setup]: [`EstimatedLoop`][mrpctl.estimation.EstimatedLoop], a scenario's sensors and
  estimator (its ``[estimator]`` table);
* [`export`][mrpctl.estimation.export]: the estimator's sample as a CasADi Function, C source and a manifest.

The equations, the shadow-set covariance mapping and the measurements are in ``design/estimation.md``.
"""

from __future__ import annotations

from mrpctl.estimation.filters import (
    COVARIANCE_SIZE,
    Estimator,
    EstimatorFunctions,
    EstimatorKind,
    EstimatorTuning,
    estimator_functions,
    farrenkopf_steady_state,
    relative_rotation_expr,
    shadow_jacobian_expr,
)
from mrpctl.estimation.run import (
    CHUNK,
    FilterRun,
    NativeFunction,
    SensorStreams,
    filter_run,
    filter_run_function,
    sensor_streams,
)
from mrpctl.estimation.sensors import ARCSEC, Gyro, SensorClock, Sensors, StarTracker
from mrpctl.estimation.setup import EstimatedLoop

__all__ = [
    "ARCSEC",
    "CHUNK",
    "COVARIANCE_SIZE",
    "EstimatedLoop",
    "Estimator",
    "EstimatorFunctions",
    "EstimatorKind",
    "EstimatorTuning",
    "FilterRun",
    "Gyro",
    "NativeFunction",
    "SensorClock",
    "SensorStreams",
    "Sensors",
    "StarTracker",
    "estimator_functions",
    "farrenkopf_steady_state",
    "filter_run",
    "filter_run_function",
    "relative_rotation_expr",
    "sensor_streams",
    "shadow_jacobian_expr",
]
