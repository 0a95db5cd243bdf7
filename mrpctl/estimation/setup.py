"""The estimated loop of a scenario as one value: the sensors it measures with and the estimator it runs."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mrpctl.errors import SpecificationError
from mrpctl.estimation.filters import Estimator, EstimatorKind
from mrpctl.estimation.sensors import ARCSEC, Sensors

__all__ = ["EstimatedLoop"]


@dataclass(frozen=True, eq=False)
class EstimatedLoop:
    """A scenario's estimated loop (its ``[estimator]`` table): the control law on the estimate.

    ``Scenario.simulate_estimated()`` runs it as ``simulate(..., sensors=sensors, estimator=estimator)``.

    Parameters
    ----------
    sensors : Sensors
        The late star tracker (its latency is the scenario's ``tau``), the gyro and the noise seed.
    estimator : Estimator
        The estimator and its tuning. Default ``Estimator()`` (the MEKF, Farrenkopf's P₀).
    """

    sensors: Sensors
    estimator: Estimator = field(default_factory=Estimator)

    def __post_init__(self) -> None:
        if not isinstance(self.sensors, Sensors):
            raise SpecificationError(f"sensors must be a Sensors value, got {type(self.sensors).__name__}")
        if not isinstance(self.estimator, Estimator):
            raise SpecificationError(f"estimator must be an Estimator, got {type(self.estimator).__name__}")

    def __str__(self) -> str:
        tracker, gyro = self.sensors.star_tracker, self.sensors.gyro
        noise = np.round(np.asarray(tracker.noise) / ARCSEC, 3).tolist()
        dropout = f", {tracker.dropout:.0%} dropouts" if tracker.dropout else ""
        kind = EstimatorKind(self.estimator.kind).value
        return (
            f"estimator: {kind} on a {tracker.rate:g} Hz star tracker of {noise} arcsec "
            f"(1 sigma) {tracker.latency:g} s late{dropout} and a gyro of {gyro.rate_noise:g} rad/sqrt(s), "
            f"bias walk {gyro.bias_walk:g} rad/s^1.5; noise seed {self.sensors.seed}"
        )
