"""Guards on the integration step: the rotation per RK4 step at the initial states."""

from __future__ import annotations

import warnings

import numpy as np

from mrpctl.conventions import state_parts
from mrpctl.errors import StepWarning

#: Largest rotation per RK4 step (rad). RK4's error on a rotation of θ per step is ~θ⁵ a step (θ⁴ per rad
#: turned): a 1 000 rad/s spin about a principal axis over 1 s ends 2.4e-6 rad off at θ = 0.1 and 1.1e-2 rad
#: off at θ = 1 (0.685 rad for a tumbling asymmetric body).
MAX_STEP_ROTATION = 0.1


def check_step_rotation(states: np.ndarray, rate: float, substeps: int) -> None:
    """Warn when |ω| h / substeps of any initial state (x = [σ; ω/4]) is above ``MAX_STEP_ROTATION``."""
    omega = float(np.max(np.linalg.norm(state_parts(np.reshape(states, (-1, 6)))[1], axis=1)))
    step = omega / (rate * substeps)
    if step > MAX_STEP_ROTATION:
        needed = int(np.ceil(omega / (rate * MAX_STEP_ROTATION)))
        fastest = omega / (64 * MAX_STEP_ROTATION)
        way_out = f"substeps={needed}" if needed <= 64 else f"substeps=64 and a rate of at least {fastest:.4g} Hz"
        warnings.warn(
            f"substeps: the initial rate |omega| = {omega:.4g} rad/s turns {step:.3g} rad per RK4 step (rate "
            f"{rate:g} Hz, substeps {substeps}), above {MAX_STEP_ROTATION:g} rad: the integration cannot resolve "
            f"the motion (RK4's error grows as the 4th power of the step); use {way_out}",
            StepWarning,
            stacklevel=3,
        )
