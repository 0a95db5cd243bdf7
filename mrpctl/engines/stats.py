"""The statistics vector accumulated by the generated sample code, and the run constants."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "DIVERGENCE_BOUND",
    "HISTORY_KINDS",
    "SETTLING_ATTITUDE_DEG",
    "SETTLING_OMEGA",
    "SETTLING_SIGMA",
    "STATS_SIZE",
    "S_FLIPS",
    "S_UPREV",
    "Metrics",
    "initial_stats",
    "settling_bounds",
]

#: Settling by default: |σ| below this (dimensionless) ...
SETTLING_SIGMA = 1e-2
#: ... and |ω| below this (rad/s), from the settling time to the end of the run.
SETTLING_OMEGA = 1e-3
#: The default attitude tolerance as a principal angle (deg): |σ| = tan(Φ/4) < 1e-2 ⇔ Φ < 4 atan(1e-2) = 2.2918°
#: (tan(radians(SETTLING_ATTITUDE_DEG)/4) is exactly SETTLING_SIGMA).
SETTLING_ATTITUDE_DEG = math.degrees(4.0 * math.atan(SETTLING_SIGMA))
#: A run is stopped and flagged diverged when |σ| or |ω| (rad/s) exceeds this or is not finite.
DIVERGENCE_BOUND = 1e6
#: The history names accepted by `mrpctl.simulate` (or give a (d, 6) array).
HISTORY_KINDS = ("constant", "zero-input")

# Layout of the statistics vector accumulated in the generated code.
S_K, S_N, S_COUNT, S_FIRST, S_LAST = 0, 1, 2, 3, 4
S_FLIPS = slice(5, 8)
S_UPREV = slice(8, 11)
S_UNSETTLED, S_MAX_SIGMA, S_DIVERGED, S_PEAK_TORQUE = 11, 12, 13, 14
# The settling tolerances |σ|², |ω|² (run-time constants: the sample passes them on unchanged)
S_SETTLE_SIGMA, S_SETTLE_OMEGA = 15, 16
# The changes of the plant's MRP set (the sample replaced σ_k by its shadow): the rule's switches for the
# plant-side rules, the bookkeeping's for the flight loop and the predictor
S_SET_CHANGES = 17
STATS_SIZE = 18


def settling_bounds(attitude_deg: float = SETTLING_ATTITUDE_DEG, rate: float = SETTLING_OMEGA) -> tuple[float, float]:
    """(|σ|², |ω|²) bounds of "settled" for a principal-angle tolerance (deg) and a rate tolerance (rad/s).

    The defaults give (1e-2², 1e-3²) exactly, the bounds the sample compiled in before they were inputs.
    The values are checked by the caller ([`settling_tolerances`][mrpctl.simulation.settling_tolerances]).
    """
    sigma = math.tan(math.radians(attitude_deg) / 4.0)
    return sigma * sigma, rate * rate


def initial_stats(n: int, settling: tuple[float, float] | None = None) -> np.ndarray:
    """The statistics vector at k = 0 of a run of n samples (``settling``: the squared bounds of
    [`settling_bounds`][mrpctl.engines.stats.settling_bounds], default those of the default tolerances)."""
    stats = np.zeros(STATS_SIZE)
    stats[S_N] = n
    stats[[S_FIRST, S_LAST, S_UNSETTLED, S_DIVERGED]] = -1.0
    stats[[S_SETTLE_SIGMA, S_SETTLE_OMEGA]] = (SETTLING_SIGMA**2, SETTLING_OMEGA**2) if settling is None else settling
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
    set_changes: int = 0

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
            set_changes=round(stats[S_SET_CHANGES]),
        )

    @property
    def diverged(self) -> bool:
        return self.diverged_index >= 0

    def valid_samples(self, n: int) -> int:
        """Samples with a good state: n, or up to and including the one where the run diverged."""
        return self.diverged_index + 1 if self.diverged else n
