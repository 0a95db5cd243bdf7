"""What every engine shares: the per-thread buffers and the output of one run."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["RunOutput", "Workspace"]


@dataclass
class Workspace:
    """The buffers one thread reuses across the runs of one engine (no allocation per run)."""

    state: np.ndarray
    ring: np.ndarray
    switched: np.ndarray | None


@dataclass
class RunOutput:
    """What one run produced: the final statistics, kept arrays, switch indices."""

    stats: np.ndarray
    samples: int
    measurements: np.ndarray | None
    u: np.ndarray | None
    switch_indices: np.ndarray | None
    memory: np.ndarray | None = None  # the rule memory after the run (the flight accumulators)
    records: np.ndarray | None = None  # flight: the kept (h, sigma_c, u_c) rows
    delay_used: np.ndarray | None = None  # flight: the kept delays used (samples)
