"""Dispersed tumbles for the lane-engine tests (tests/test_lanes_flight.py, tests/test_lanes_structure.py)."""

from __future__ import annotations

import numpy as np

from mrpctl import mrp, paper


def dispersed(count: int, seed: int, *, diverging_every: int) -> tuple[np.ndarray, np.ndarray]:
    """``count`` seeded tumbles up to 5 rad/s with 0.05 x the paper's gain, every ``diverging_every``-th run
    1000 x the paper's gain (it diverges at 100 Hz): the initial states [σ; ω/4] and the gains."""
    rng = np.random.default_rng(seed)
    sigma = mrp.short(rng.normal(size=(count, 3)))
    direction = rng.normal(size=(count, 3))
    omega = direction / np.linalg.norm(direction, axis=1, keepdims=True) * rng.uniform(0.5, 5.0, (count, 1))
    gains = np.repeat(0.05 * paper.GAIN[None], count, axis=0)
    gains[::diverging_every] *= 20000.0
    return np.hstack((sigma, omega / 4)), gains
