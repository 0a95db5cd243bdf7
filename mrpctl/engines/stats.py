"""The statistics vector accumulated by the generated sample code, and the run constants."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "DIVERGENCE_BOUND",
    "HISTORY_KINDS",
    "SETTLING_OMEGA",
    "SETTLING_SIGMA",
    "STATS_SIZE",
    "S_FLIPS",
    "S_UPREV",
    "Metrics",
    "initial_stats",
]

#: Settling: |σ| below this (dimensionless) ...
SETTLING_SIGMA = 1e-2
#: ... and |ω| below this (rad/s), from the settling time to the end of the run.
SETTLING_OMEGA = 1e-3
#: A run is stopped and flagged diverged when |σ| or |ω| (rad/s) exceeds this or is not finite.
DIVERGENCE_BOUND = 1e6
#: The history names accepted by `mrpctl.simulate` (or give a (d, 6) array).
HISTORY_KINDS = ("constant", "zero-input")

# Layout of the statistics vector accumulated in the generated code.
S_K, S_N, S_COUNT, S_FIRST, S_LAST = 0, 1, 2, 3, 4
S_FLIPS = slice(5, 8)
S_UPREV = slice(8, 11)
S_UNSETTLED, S_MAX_SIGMA, S_DIVERGED, S_PEAK_TORQUE = 11, 12, 13, 14
STATS_SIZE = 15


def initial_stats(n: int) -> np.ndarray:
    """The statistics vector at k = 0 of a run of n samples."""
    stats = np.zeros(STATS_SIZE)
    stats[S_N] = n
    stats[[S_FIRST, S_LAST, S_UNSETTLED, S_DIVERGED]] = -1.0
    return stats


@dataclass(frozen=True)
class Metrics:
    """The statistics vector decoded (indices are sample numbers k, -1 for "never")."""

    switch_count: int
    first_switch_index: int
    last_switch_index: int
    sign_flips: np.ndarray
    unsettled_index: int
    max_sigma: float
    diverged_index: int
    peak_torque: float

    @classmethod
    def from_stats(cls, stats: np.ndarray) -> Metrics:
        return cls(
            switch_count=round(stats[S_COUNT]),
            first_switch_index=round(stats[S_FIRST]),
            last_switch_index=round(stats[S_LAST]),
            sign_flips=np.rint(stats[S_FLIPS]).astype(np.int64),
            unsettled_index=round(stats[S_UNSETTLED]),
            max_sigma=math.sqrt(stats[S_MAX_SIGMA]),
            diverged_index=round(stats[S_DIVERGED]),
            peak_torque=float(stats[S_PEAK_TORQUE]),
        )

    @property
    def diverged(self) -> bool:
        return self.diverged_index >= 0

    def valid_samples(self, n: int) -> int:
        """Samples with a good state: n, or up to and including the one where the run diverged."""
        return self.diverged_index + 1 if self.diverged else n
