"""The seed paper's example as named constants (Samiei & Butcher, sections IV-V)."""

from __future__ import annotations

import math

import numpy as np

from mrpctl._validation import readonly
from mrpctl.model import state
from mrpctl.spacecraft import Spacecraft

__all__ = [
    "BOUNDARY_LAYER_EPS",
    "EPS_STUDY",
    "GAIN",
    "GAIN_OMEGA",
    "GAIN_SIGMA",
    "INERTIA",
    "INITIAL_AXIS",
    "INITIAL_OMEGA",
    "INITIAL_PRINCIPAL_ANGLE",
    "INITIAL_SIGMA",
    "INITIAL_STATE",
    "MEASUREMENT_RATE",
    "PAPER_FIRST_SWITCH_TIME",
    "SPACECRAFT",
    "TAU",
    "summary",
]

# Section IV: "a rigid spacecraft with inertia matrix J = diag(140, 100, 80)" (kg m^2).
INERTIA = (140.0, 100.0, 80.0)
SPACECRAFT = Spacecraft(INERTIA)

# Eq. (k_PD): K = [-70.11 I3, -163.08 I3], acting on x = [sigma; omega/4] (Eq. ss).
GAIN_SIGMA = -70.11
GAIN_OMEGA = -163.08
GAIN = readonly(np.hstack((GAIN_SIGMA * np.eye(3), GAIN_OMEGA * np.eye(3))))

# Section IV: Phi = 171.6913 deg about e = [1, 0, 0], omega = [0.46, 0, 0] rad/s.
INITIAL_PRINCIPAL_ANGLE = math.radians(171.6913)
INITIAL_AXIS = readonly(np.array([1.0, 0.0, 0.0]))
# sigma = tan(Phi/4) e (Eq. 1): sigma_1 = 0.9300, as the paper states.
INITIAL_SIGMA = readonly(math.tan(INITIAL_PRINCIPAL_ANGLE / 4.0) * INITIAL_AXIS)
INITIAL_OMEGA = readonly(np.array([0.46, 0.0, 0.0]))
INITIAL_STATE = readonly(state(INITIAL_SIGMA, INITIAL_OMEGA))

# Section IV: tau = 0.5 s, states measured at 1 kHz.
TAU = 0.5
MEASUREMENT_RATE = 1000.0

# Section V: boundary layer thickness used for Fig. BL_solution.
BOUNDARY_LAYER_EPS = 0.005
# Section V discusses "large" and "small" eps; the reproduction sweeps these values.
EPS_STUDY = (0.001, 0.005, 0.05, 0.2)

# Section IV, tau = 0: "tumbling motion through Phi = 180 deg at t = 0.449 (sec)".
PAPER_FIRST_SWITCH_TIME = 0.449


def summary() -> str:
    """A few lines describing the paper's example: plant, gains, initial state, delay."""
    angle = math.degrees(INITIAL_PRINCIPAL_ANGLE)
    return "\n".join(
        (
            "Samiei & Butcher, MRP shadow-set switching under delayed feedback: the example",
            f"  plant         {SPACECRAFT}",
            "  state         x = [sigma; omega/4] in R^6, u = K x(t - tau)",
            f"  gain K        [{GAIN_SIGMA:g} I3, {GAIN_OMEGA:g} I3] (3x6, on x)",
            f"  initial state Phi = {angle:.4f} deg about body x -> sigma0 = {_vector(INITIAL_SIGMA)}, "
            f"omega0 = {_vector(INITIAL_OMEGA)} rad/s",
            f"  delay         tau = {TAU:g} s, measured at {MEASUREMENT_RATE:g} Hz",
            f"  boundary layer eps = {BOUNDARY_LAYER_EPS:g}",
        )
    )


def _vector(values: np.ndarray) -> str:
    return "[" + ", ".join(f"{v:.4f}" for v in values) + "]"
