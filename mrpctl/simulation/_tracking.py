"""The reference-tracking options of ``simulate`` and ``simulate_batch``, checked against the rule."""

from __future__ import annotations

from typing import Any

from mrpctl._validation import positive_scalar
from mrpctl.errors import SpecificationError
from mrpctl.flight import Hysteretic
from mrpctl.flight.tracking import ErrorTime, ReferenceStream, reference_stream

#: What the message for a plant-side rule says (design/tracking.md, "The switching rules on σ_B/R").
_PLANT_SIDE = (
    "rule: {rule} switches the plant's own MRP sigma_BN, which a tracking controller does not feed back (it forms "
    "sigma_BR from the measurement and the reference); with a reference the controller chooses the set of sigma_BR "
    "itself: use rule=mrpctl.flight.Hysteretic(delta) (Hysteretic(0.0): the short set of sigma_BR at every sample, "
    "OnCurrent's rule on sigma_BR; delta > 0: the hysteresis on sigma_BR)"
)


def tracking_options(
    reference: Any,
    error_time: Any,
    feedforward: Any,
    pointing_tolerance: Any,
    *,
    rule: Any,
    predictor: Any,
    n: int,
    rate: float,
    d: int,
    name: str = "reference",
    defer_values: bool = False,
) -> tuple[ReferenceStream | None, bool, float]:
    """(the checked reference stream or None, feedforward, the pointing tolerance in degrees); ``defer_values``: an
    array's values are checked by the run (`ReferenceStream.check_rows`, the compiled engine as it reads them)."""
    if not isinstance(feedforward, bool):
        raise SpecificationError(f"feedforward must be True or False, got {feedforward!r}")
    tolerance = positive_scalar("pointing_tolerance", pointing_tolerance)
    if reference is None:
        if feedforward:
            raise SpecificationError("feedforward: the feedforward terms need a reference (give reference=...)")
        return None, False, tolerance
    if predictor is None and not isinstance(rule, Hysteretic):
        raise SpecificationError(_PLANT_SIDE.format(rule=rule))
    if error_time is None:  # the prediction is of now: its error is against the reference of now
        error_time = ErrorTime.MEASUREMENT if predictor is None else ErrorTime.CURRENT
    stream = reference_stream(reference, n, rate, d, error_time, name, defer_values=defer_values)
    return stream, feedforward, tolerance
