"""Reference tracking in the flight loop: the reference rows, the two error conventions under delay, and the
tracking controller's expressions (tracking error, feedforward), each a small pure-SX builder.

A reference is one row per controller sample k (t_k = k/rate) of 9 numbers, Basilisk's
``AttRefMsgPayload`` convention: σ_R/N (MRP), ω_R/N (rad/s, components in the inertial frame N),
ω̇_R/N (rad/s², N components). The controller, from the delayed measurement [σ̃_B/N; ω̃_B/N/4]
(body components), forms

    σ_B/R = short(σ_B/N ⊕ σ_N/R),       `[BR] = [BN][NR]`, σ_N/R = −σ_R/N (MRP composition)
    ω_B/R = ω̃ − [B̃N] ω_R/N            (body components; [B̃N] of the measured σ̃_B/N)

and the tracking law

    u_c = K [σ_c; ω_B/R/4] + f,   f = ω̃ × (J ω̃) + J([B̃N] ω̇_R/N − ω̃ × [B̃N] ω_R/N)   (optional)

where σ_c is the controller-side rule's choice of set of σ_B/R ([`Hysteretic`][mrpctl.flight.Hysteretic]) and
ω̃ the delayed measured body rate: the controller has nothing newer. ``design/tracking.md`` derives it
and measures the two conventions of [`ErrorTime`][mrpctl.flight.tracking.ErrorTime].
"""

from __future__ import annotations

import enum
from typing import Any

import casadi as ca
import numpy as np

from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.mrp import skew_expr

__all__ = [
    "DEFAULT_POINTING_TOLERANCE",
    "REFERENCE_BOUND",
    "REFERENCE_TOLERANCE",
    "REFERENCE_WIDTH",
    "ErrorTime",
    "ReferenceStream",
    "feedforward_expr",
    "pointing_metrics",
    "reference_stream",
    "rotate_expr",
    "rotation_scale",
    "settling_error_expr",
    "tracking_error_expr",
]

#: Numbers of one reference row: σ_R/N (3), ω_R/N (3, rad/s, N components), ω̇_R/N (3, rad/s², N components).
REFERENCE_WIDTH = 9
#: |σ_R/N| may exceed 1 by this much (a reference written in the short set, with rounding).
REFERENCE_TOLERANCE = 1e-9
#: The bound on |σ_R/N|² = (σ₁² + σ₂²) + σ₃² (in this order: the compiled engine's check of its rows is the same).
REFERENCE_BOUND = (1.0 + REFERENCE_TOLERANCE) ** 2
#: The slew time's default tolerance on the pointing error Φ_B/R (degrees).
DEFAULT_POINTING_TOLERANCE = 0.1


class ErrorTime(enum.Enum):
    """At which time the controller takes the reference it compares the delayed measurement with.

    ``MEASUREMENT``: the reference at the measurement's time t_{k−d}: the error of a consistent
    pair, the attitude error the spacecraft had τ ago (no bookkeeping lag; the default).
    ``CURRENT``: the reference at t_k, the latest one: a measurement of t_{k−d} against the reference
    of now, with a built-in lag of about ω_R τ for a rotating reference (nadir pointing).
    The whole row (σ_R, ω_R, ω̇_R, feedforward included) is taken at that time. With d = 0 the two coincide.
    """

    MEASUREMENT = "measurement"
    CURRENT = "current"


def rotate_expr(sigma: Any, v: Any, scale: Any = None) -> Any:
    """[BN](σ) v (SX): N components of v into B components, [BN] = I + (8[σ×]² − 4(1 − |σ|²)[σ×])/(1 + |σ|²)².

    Written with two cross products (no matrix): v + a σ × (σ × v) − b σ × v with the coefficients
    a = 8/(1 + |σ|²)², b = 4 (1 − |σ|²)/(1 + |σ|²)² of [`rotation_scale`][mrpctl.flight.tracking.rotation_scale]
    (``scale`` when the caller has them: one division for several vectors). With v = 0 it returns v's values
    (up to the sign of a zero).
    """
    eight, four = rotation_scale(sigma) if scale is None else scale
    once = skew_expr(sigma) @ v
    twice = skew_expr(sigma) @ once
    return v + (eight * twice - four * once)


def rotation_scale(sigma: Any, squared: Any = None) -> tuple[Any, Any]:
    """(a, b) = (8/(1 + |σ|²)², 4 (1 − |σ|²)/(1 + |σ|²)²) of [`rotate_expr`][mrpctl.flight.tracking.rotate_expr]
    (SX; ``squared`` = |σ|² when known), at one division.

    a is 8/((1 + |σ|²)²), not 8 (1/(1 + |σ|²)²): CasADi rewrites a product with 1/x into a division, which
    would put one division in every component of every rotation; b = (1 − |σ|²)(a/2).
    """
    squared = ca.dot(sigma, sigma) if squared is None else squared
    eight = 8 / ((1 + squared) * (1 + squared))
    return eight, (1 - squared) * (0.5 * eight)


def tracking_error_expr(
    sigma_bn: Any, omega_scaled: Any, sigma_rn: Any, omega_rn: Any, *, settling: bool = False
) -> tuple[Any, ...]:
    """(σ_B/R short, ω_B/R/4, [BN] ω_R/N, the rotation's scale) from σ_B/N, ω_B/N/4 (body), σ_R/N and ω_R/N
    (N components) (SX); with ``settling`` a fifth entry, |σ_B/R|² of
    [`settling_error_expr`][mrpctl.flight.tracking.settling_error_expr] from the same |σ_B/N|² and D (its bits).

    σ_B/R is σ_B/N ⊕ σ_N/R, σ_N/R = −σ_R/N (`[BR] = [BN][NR]`, Schaub & Junkins Eq. 3.152),
    n/D with n = (1 − |σ_R|²) σ_B − (1 − |σ_B|²) σ_R + 2 σ_B × σ_R and D = 1 + |σ_R|²|σ_B|² + 2 σ_R·σ_B, in
    its short set at one division: n/D when |n|² <= D², else −n D/|n|² (the shadow).
    ω_B/R/4 = ω/4 − ([BN] ω_R/N)/4. With σ_R/N = 0 and ω_R/N = 0 they equal a short σ_B/N and ω/4 in value
    (bit for bit up to the sign of a zero: n = σ_B, D = 1). |σ_B/N|² is computed once for the composition
    and the rotation; the scale is returned for the feedforward's rotation of ω̇_R.
    """
    s_body = ca.dot(sigma_bn, sigma_bn)
    s_ref = ca.dot(sigma_rn, sigma_rn)
    numerator = (1 - s_ref) * sigma_bn - (1 - s_body) * sigma_rn + 2 * (skew_expr(sigma_bn) @ sigma_rn)
    denominator = 1 + s_ref * s_body + 2 * ca.dot(sigma_rn, sigma_bn)
    size = ca.dot(numerator, numerator)
    long_set = size > denominator * denominator
    # one division: −D/|n|² (the shadow) or 1/D; |n|² > D² >= 0 makes the shadow's divisor positive
    factor = ca.if_else(long_set, -denominator, 1.0) / ca.if_else(long_set, size, denominator)
    sigma_br = numerator * factor
    scale = rotation_scale(sigma_bn, s_body)
    omega_r_body = rotate_expr(sigma_bn, omega_rn, scale)
    if settling:
        squared = _short_squared(sigma_bn - sigma_rn, denominator)
        return sigma_br, omega_scaled - 0.25 * omega_r_body, omega_r_body, scale, squared
    return sigma_br, omega_scaled - 0.25 * omega_r_body, omega_r_body, scale


def _short_squared(delta: Any, denominator: Any) -> Any:
    """|Δ|²/D, or D/|Δ|² when |Δ|² > D (the shadow), at one division."""
    distance = ca.dot(delta, delta)
    long_set = distance > denominator
    return ca.if_else(long_set, denominator, distance) / ca.if_else(long_set, distance, denominator)


def settling_error_expr(sigma_bn: Any, omega_scaled: Any, sigma_rn: Any, omega_rn: Any) -> tuple[Any, Any]:
    """(|σ_B/R|² of the short set, ω_B/R in rad/s) from σ_B/N, ω_B/N/4 (body), σ_R/N and ω_R/N (N components)
    (SX): what the engines' settling statistic and max |σ| take of the true error, without forming σ_B/R.

    With Δ = σ_B − σ_R and D = 1 + |σ_R|²|σ_B|² + 2 σ_R·σ_B (the denominator of
    [`tracking_error_expr`][mrpctl.flight.tracking.tracking_error_expr]), its numerator n has |n|² = D |Δ|²
    (the quaternion form: cos(Φ/2)-wise, (1 + |σ_B|²)(1 + |σ_R|²) β_B·β_R = D − |Δ|² and the sum with the product
    is D + |Δ|²), so |σ_B/R|² = |Δ|²/D in the short set (|Δ|² <= D, i.e. |n|² <= D² for D > 0) and D/|Δ|² for
    the shadow, at one division and without n; near σ_B = σ_R it is more accurate than |n/D|² (no cancellation
    in n). ω_B/R = 4 (ω_B/N/4) − [BN] ω_R/N (4 x is exact: the same bits as 4 (ω/4 − ([BN] ω_R/N)/4)). With
    σ_R/N = 0 and ω_R/N = 0: |σ_B|² and ω bit for bit (Δ = σ_B, D = 1), the regulation sample's statistics.
    """
    s_body = ca.dot(sigma_bn, sigma_bn)
    denominator = 1 + ca.dot(sigma_rn, sigma_rn) * s_body + 2 * ca.dot(sigma_rn, sigma_bn)
    squared = _short_squared(sigma_bn - sigma_rn, denominator)
    omega_br = 4 * omega_scaled - rotate_expr(sigma_bn, omega_rn, rotation_scale(sigma_bn, s_body))
    return squared, omega_br


def feedforward_expr(
    inertia: Any, omega: Any, sigma_bn: Any, omega_r_body: Any, domega_rn: Any, scale: Any = None
) -> Any:
    """f = ω × (J ω) + J([BN] ω̇_R/N − ω × ω_R^B) (SX, N m): the MRP tracking law's feedforward.

    ``omega`` the body rate the controller has (rad/s), ``omega_r_body`` = [BN] ω_R/N (rad/s, body),
    ``domega_rn`` = ω̇_R/N (rad/s², N components), rotated here by [BN](σ_B/N) (``scale`` from
    [`tracking_error_expr`][mrpctl.flight.tracking.tracking_error_expr]); J (3 × 3) a constant or the run-time
    inertia.
    """
    cross = skew_expr(omega)
    return cross @ (inertia @ omega) + inertia @ (rotate_expr(sigma_bn, domega_rn, scale) - cross @ omega_r_body)


class ReferenceStream:
    """A checked reference, read slice by slice: (rows now; rows at the error time) of samples k0..k1.

    Built by [`reference_stream`][mrpctl.flight.tracking.reference_stream]. ``rows(k0, k1)`` gives two
    (k1 − k0, 9) blocks: the reference at t_k (the true pointing error, the metrics) and at the error time
    t_k − lag (the controller's), with lag = d samples for ``MEASUREMENT`` (held at row 0 before t = 0, as
    the constant history holds x0) and 0 for ``CURRENT``.
    """

    def __init__(
        self, source: Any, n: int, rate: float, lag: int, error_time: ErrorTime, name: str, unchecked: bool = False
    ) -> None:
        self._array = source if isinstance(source, np.ndarray) else None
        self._source = source
        self.n, self.rate, self.lag, self.error_time, self.name = n, rate, lag, error_time, name
        #: An array whose values are not checked yet: its consumer checks them (`check_rows`; the compiled scalar
        #: engine as it reads them). False for a ``samples(t)`` source (each slice is checked when evaluated).
        self.unchecked = unchecked and self._array is not None

    def check_rows(self, k0: int = 0) -> None:
        """Check the values of rows k0, k0 + 1, … of an unchecked array (the rows before k0 are good): raises the
        [`SpecificationError`][mrpctl.errors.SpecificationError] of
        [`reference_stream`][mrpctl.flight.tracking.reference_stream] (naming the first bad row of the whole array)."""
        if self._array is None or not self.unchecked:
            return
        if not _rows_good(self._array[k0:]):
            _check_values(self.name, self._array, "the rows")

    def samples(self, k0: int, k1: int) -> np.ndarray:
        """(k1 − k0, 9) reference rows of samples k0..k1 − 1 (k >= 0), checked."""
        if self._array is not None:
            return self._array[k0:k1]
        t = np.arange(k0, k1, dtype=float) / self.rate
        return _check_rows(self.name, self._source.samples(t), k1 - k0, f"{self.name}.samples(t)")

    def rows(self, k0: int, k1: int) -> tuple[np.ndarray, np.ndarray]:
        """((k1 − k0, 9) reference at t_k, (k1 − k0, 9) reference at the error time), C-contiguous.

        Views of an array reference (no copy), but for the first d rows of ``MEASUREMENT``, where the
        reference before t = 0 is held at row 0; the same array twice for ``CURRENT``.
        """
        low = max(k0 - self.lag, 0)
        block = np.ascontiguousarray(self.samples(low, k1))
        now = block[k0 - low :]
        if self.lag == 0:
            return now, now
        held = max(min(self.lag - k0, k1 - k0), 0)  # samples k whose error time k − lag is before t = 0
        if held == 0:
            return now, block[0 : k1 - k0]
        error = np.concatenate((np.repeat(block[0:1], held, axis=0), block[0 : k1 - k0 - held]))
        return now, error

    def held_rows(self, k0: int, k1: int) -> tuple[np.ndarray, np.ndarray, int]:
        """[`rows`][mrpctl.flight.tracking.ReferenceStream.rows] without the copy of the held rows: ((k1 − k0, 9)
        reference at t_k, the error-time rows from the one of sample k0 + held on, held), C-contiguous views of an
        array reference. Sample k of the slice takes error row max(k − k0 − held, 0): the first ``held`` samples
        (error time before t = 0) row 0 of the reference, as does sample k0 + held."""
        low = max(k0 - self.lag, 0)
        block = np.ascontiguousarray(self.samples(low, k1))
        held = max(min(self.lag - k0, k1 - k0), 0)
        return block[k0 - low :], block[0 : max(k1 - k0 - held, 1)], held

    def first(self) -> np.ndarray:
        """The controller's reference row at k = 0 (row 0 in both conventions)."""
        return np.array(self.samples(0, 1)[0])


def _array_rows(name: str, value: Any, what: str) -> np.ndarray:
    """``value`` as a C-contiguous (samples, 9) float array (its values not checked)."""
    try:
        array = np.ascontiguousarray(value, dtype=float)
    except (TypeError, ValueError) as error:
        raise SpecificationError(f"{name}: {what} must be numbers, got {type(value).__name__}") from error
    if array.ndim != 2 or array.shape[1] != REFERENCE_WIDTH:
        raise DimensionError(
            f"{name}: {what} must have shape (samples, {REFERENCE_WIDTH}) "
            "(sigma_RN, omega_RN_N, domega_RN_N per row) but found " + str(array.shape)
        )
    return array


def _check_rows(name: str, value: Any, rows: int | None, what: str) -> np.ndarray:
    array = _array_rows(name, value, what)
    if rows is not None and array.shape[0] != rows:
        raise DimensionError(f"{name}: {what} returned {array.shape[0]} rows for {rows} sample times")
    return array if _rows_good(array) else _check_values(name, array, what)


def _rows_good(array: np.ndarray) -> bool:
    """True when every entry is finite and every |σ_R/N|² <= `REFERENCE_BOUND` (False: look row by row).

    Two contiguous passes when the rows are good (a reference is checked on every call): the largest and the smallest
    entry are finite only when every entry is (a NaN or an inf reaches them), and entries within ±0.5 give
    |σ|² <= 0.75, far inside the bound whatever the rounding; else the row by row tests.
    """
    high, low = (float(array.max()), float(array.min())) if array.size else (0.0, 0.0)
    if not (np.isfinite(high) and np.isfinite(low)):
        return False
    return max(high, -low) <= 0.5 or not np.any(_sigma_squared(array) > REFERENCE_BOUND)


def _sigma_squared(array: np.ndarray) -> np.ndarray:
    """|σ_R/N|² of each row as (σ₁² + σ₂²) + σ₃², the operations of the compiled engine's check."""
    return (array[:, 0] * array[:, 0] + array[:, 1] * array[:, 1]) + array[:, 2] * array[:, 2]


def _check_values(name: str, array: np.ndarray, what: str) -> np.ndarray:
    """``array`` when its rows are good, else the error naming the first non-finite row, or the first row with
    |σ_R/N| > 1 (+ `REFERENCE_TOLERANCE`)."""
    finite = np.all(np.isfinite(array), axis=1)
    if not np.all(finite):
        raise SpecificationError(f"{name}: {what} must be finite; row {int(np.flatnonzero(~finite)[0])} is not")
    norms = _sigma_squared(array)
    if np.any(norms > REFERENCE_BOUND):
        bad = int(np.flatnonzero(norms > REFERENCE_BOUND)[0])
        raise SpecificationError(
            f"{name}: sigma_RN must be a short-set MRP (|sigma_RN| <= 1); row {bad} has |sigma_RN| = "
            f"{np.sqrt(norms[bad]):.6g}"
        )
    return array


def reference_stream(
    reference: Any,
    n: int,
    rate: float,
    delay_samples: int,
    error_time: Any,
    name: str = "reference",
    *,
    defer_values: bool = False,
) -> ReferenceStream:
    """The checked reference of a run of n samples at ``rate`` (Hz) with a delay of d samples.

    ``reference``: an (m, 9) array with m >= n rows (row k at t_k = k/rate; checked once, read through a
    view), or an object with a method ``samples(t) -> (len(t), 9)`` (evaluated slice by slice, each slice
    checked). ``error_time`` an [`ErrorTime`][mrpctl.flight.tracking.ErrorTime] (or its value, a string).
    ``defer_values``: an array's shape and rows are checked here, its values by the consumer
    ([`ReferenceStream.check_rows`][mrpctl.flight.tracking.ReferenceStream.check_rows]; the compiled scalar engine
    checks each row as it reads it, which saves the passes over the array), with the same errors.

    Raises
    ------
    DimensionError
        The rows are not (samples, 9), or too few.
    SpecificationError
        A non-finite entry, |σ_R/N| > 1 (+ `REFERENCE_TOLERANCE`), an unknown error time or a reference of
        another type.
    """
    try:
        error_time = ErrorTime(error_time)
    except ValueError as error:
        choices = ", ".join(f"ErrorTime.{e.name}" for e in ErrorTime)
        raise SpecificationError(f"error_time must be one of {choices}, got {error_time!r}") from error
    lag = delay_samples if error_time is ErrorTime.MEASUREMENT else 0
    if hasattr(reference, "samples") and callable(reference.samples) and not isinstance(reference, np.ndarray):
        stream = ReferenceStream(reference, n, rate, lag, error_time, name)
        stream.samples(0, 1)  # checked early: the first row
        return stream
    if isinstance(reference, str | bytes) or reference is None:
        raise SpecificationError(
            f"{name} must be an (n, 9) array of (sigma_RN, omega_RN_N, domega_RN_N) rows or an object with a "
            f"method samples(t), got {reference!r}"
        )
    if defer_values:
        array = _array_rows(name, reference, "the rows")
    else:
        array = np.ascontiguousarray(_check_rows(name, reference, None, "the rows"))
    if array.shape[0] < n:
        raise DimensionError(f"{name}: the run has {n} samples but the reference has {array.shape[0]} rows")
    return ReferenceStream(array, n, rate, lag, error_time, name, unchecked=defer_values)


def pointing_metrics(
    sigma_br: np.ndarray, t: np.ndarray, settling_time: float | None, tolerance: float
) -> dict[str, Any]:
    """The pointing metrics of kept samples: Φ_B/R(t) = 4 atan|σ_B/R| (deg), its max and RMS after settling,
    and the slew time (the first kept t from which Φ stays below ``tolerance`` degrees; None if never)."""
    angle = np.degrees(4.0 * np.arctan(np.sqrt(np.einsum("ij,ij->i", sigma_br, sigma_br))))
    after = angle[t >= settling_time] if settling_time is not None else angle[0:0]
    above = np.flatnonzero(angle >= tolerance)
    if angle.size == 0:
        slew = None
    elif above.size == 0:
        slew = float(t[0])
    else:
        slew = float(t[above[-1] + 1]) if above[-1] + 1 < angle.size else None
    return {
        "pointing_error": angle,
        "pointing_max": float(after.max()) if after.size else None,
        "pointing_rms": float(np.sqrt(np.mean(after**2))) if after.size else None,
        "slew_time": slew,
        "pointing_tolerance": float(tolerance),
    }
