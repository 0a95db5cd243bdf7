"""Input checks shared by the public functions: shapes, finiteness, signs."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from mrpctl.errors import DimensionError, SpecificationError


def _shape_text(shape: tuple[int | None, ...] | tuple[Any, ...]) -> str:
    return "(" + ", ".join("..." if s is None else str(s) for s in shape) + ")"


def finite_array(name: str, value: Any, shape: tuple[int | None, ...] | None = None) -> np.ndarray:
    """Return ``value`` as a float64 array, checking its shape and that it is finite.

    ``shape`` may hold ``None`` as its first entry for "any leading axes"
    (for example ``(None, 3)`` accepts (3,), (n, 3), (n, m, 3)).
    """
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise SpecificationError(f"{name} must be numeric, got {value!r}") from exc
    if shape is not None:
        if shape and shape[0] is None:
            tail = shape[1:]
            ok = array.ndim >= len(tail) and array.shape[array.ndim - len(tail) :] == tail
            expected = "(..., " + ", ".join(str(s) for s in tail) + ")"
        else:
            ok = array.shape == shape
            expected = _shape_text(shape)
        if not ok:
            raise DimensionError(f"{name}: expected shape {expected} but found {array.shape}")
    if not np.all(np.isfinite(array)):
        raise SpecificationError(f"{name} must be finite (no NaN or inf), got {array}")
    return array


def finite_scalar(name: str, value: Any) -> float:
    """Return ``value`` as a finite float."""
    try:
        number = float(value)
    except (TypeError, ValueError) as exc:
        raise SpecificationError(f"{name} must be a real number, got {value!r}") from exc
    if not math.isfinite(number):
        raise SpecificationError(f"{name} must be finite, got {number}")
    return number


def positive_scalar(name: str, value: Any) -> float:
    """Return ``value`` as a finite float > 0."""
    number = finite_scalar(name, value)
    if number <= 0.0:
        raise SpecificationError(f"{name} must be > 0, got {number}")
    return number


def nonnegative_scalar(name: str, value: Any) -> float:
    """Return ``value`` as a finite float >= 0."""
    number = finite_scalar(name, value)
    if number < 0.0:
        raise SpecificationError(f"{name} must be >= 0, got {number}")
    return number


def readonly(array: np.ndarray) -> np.ndarray:
    """Return a read-only copy of ``array`` (for frozen result objects)."""
    out = np.array(array, dtype=float, copy=True)
    out.setflags(write=False)
    return out
