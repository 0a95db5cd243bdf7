"""What the eigenvalues λ of a loop transfer matrix L say at a crossing frequency, shared by the continuous
(`mrpctl.design.performance`) and the sampled (`mrpctl.design.sampled_margins`) margins: the eigenvalues that lie
on the negative real axis (a common gain factor 1/|λ| puts a closed-loop root there) and those on the unit circle
(a common phase lag puts one there). Eigenvalues within 1e3 times the closest one's distance (or 1e-9) count as
on it: identical axes cross together."""

from __future__ import annotations

import numpy as np

__all__ = ["negative_axis_factors", "unit_circle_angles"]


def negative_axis_factors(lam: np.ndarray) -> list[float]:
    """The gain factors 1/|λ| of the eigenvalues on the negative real axis (none crossing the positive axis)."""
    near = np.abs(lam.imag) / np.maximum(np.abs(lam), 1e-300)
    picked = np.flatnonzero(near <= max(1e3 * float(np.min(near)), 1e-9))
    return [1.0 / abs(lam[j]) for j in picked if lam[j].real < 0.0]


def unit_circle_angles(lam: np.ndarray) -> list[float]:
    """arg λ of the eigenvalues on the unit circle."""
    gap = np.abs(np.abs(lam) - 1.0)
    picked = np.flatnonzero(gap <= max(1e3 * float(np.min(gap)), 1e-9))
    return [float(np.angle(lam[j])) for j in picked]
