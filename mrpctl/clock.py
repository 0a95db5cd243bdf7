"""The sample clock of the loop: a delay as a whole number of measurement periods, and the RK4 substeps.

One rule for every surface that takes a delay and a rate (simulate, the predictor, export, scenarios):
τ · rate must be a whole number d of periods, to a relative tolerance (τ is rounded where it is written).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from mrpctl._validation import integer, nonnegative_scalar, positive_scalar
from mrpctl.errors import SpecificationError

__all__ = ["MAX_SUBSTEPS", "check_substeps", "delay_samples"]

_DELAY_TOLERANCE = 1e-9
#: RK4 substeps per measurement period at most. The step is unrolled into the generated
#: code (about 0.5 kB of C and 0.1 s of gcc per substep): 64 substeps already make h/64 a
#: step far below any period the loop can resolve, while 1000 would take minutes and
#: > 2 GB to compile. For a finer integration raise the rate instead.
MAX_SUBSTEPS = 64


def delay_samples(tau: Any, rate: Any) -> int:
    """d = τ · rate as an integer (τ in s, rate in Hz).

    Raises
    ------
    SpecificationError
        If τ < 0, rate <= 0, or τ · rate is not an integer to 1e-9 (relative, at least 1e-9 absolute).
    """
    tau = nonnegative_scalar("tau", tau)
    rate = positive_scalar("rate", rate)
    samples = tau * rate
    if not math.isfinite(samples) or samples > 2.0**53:
        raise SpecificationError(
            f"tau * rate must be a whole number of measurement periods below 2^53: tau = {tau!r} s and "
            f"rate = {rate!r} Hz give tau * rate = {samples!r}"
        )
    d = round(samples)
    if abs(samples - d) > _DELAY_TOLERANCE * max(1.0, abs(samples)):  # relative: tau * rate is rounded
        raise SpecificationError(
            f"tau * rate must be a whole number of measurement periods: tau = {tau!r} s and "
            f"rate = {rate!r} Hz give tau * rate = {samples!r}; choose tau as a multiple of 1/rate"
        )
    return int(d)


def check_substeps(substeps: Any) -> int:
    """RK4 substeps per measurement period: an integer in 1 .. `MAX_SUBSTEPS`."""
    if isinstance(substeps, int | np.integer) and not isinstance(substeps, bool) and substeps > MAX_SUBSTEPS:
        raise SpecificationError(
            f"substeps must be <= {MAX_SUBSTEPS}, got {substeps}: each substep is unrolled into the compiled "
            f"code (1000 substeps take minutes and > 2 GB to compile); for a finer step raise rate instead"
        )
    return integer("substeps", substeps, minimum=1)


# ================================================================ symbolic building blocks
