"""Input checks shared by the public functions: shapes, finiteness, signs."""

from __future__ import annotations

import math
import os
from typing import TYPE_CHECKING, Any

import numpy as np

from mrpctl.errors import DimensionError, SpecificationError

if TYPE_CHECKING:
    pass


def _shape_text(shape: tuple[int | None, ...] | tuple[Any, ...]) -> str:
    return "(" + ", ".join("..." if s is None else str(s) for s in shape) + ")"


def finite_array(name: str, value: Any, shape: tuple[int | None, ...] | None = None) -> np.ndarray:
    """Return ``value`` as a float64 array, checking its shape and that it is finite.

    ``shape`` may hold ``None`` as its first entry for "any leading axes"
    (for example ``(None, 3)`` accepts (3,), (n, 3), (n, m, 3)).
    """
    if value is None:
        raise SpecificationError(f"{name} must be numeric, got None")
    try:
        raw = np.asarray(value)
        if np.iscomplexobj(raw):
            raise SpecificationError(f"{name} must be real: found complex entries (dtype {raw.dtype})")
        # a boolean or a string among numbers (NumPy would read [20, 20, True] as [20, 20, 1] and "0.5" as 0.5;
        # a string makes the whole array one of strings, or of objects when ragged)
        listed_bool = isinstance(value, list | tuple) and _lists_a_bool(value)
        if raw.dtype == bool or listed_bool or (raw.dtype == object and _has_bool(raw)):
            raise SpecificationError(f"{name} must be numeric, got booleans {value!r}")
        if raw.dtype.kind in "US" or (raw.dtype == object and _has_str(raw)):
            raise SpecificationError(f"{name} must be numeric, got strings {value!r}")
        array = np.asarray(raw, dtype=float)
    except (TypeError, ValueError) as exc:
        if isinstance(exc, SpecificationError):
            raise
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


def _has_bool(array: np.ndarray) -> bool:
    return any(isinstance(item, bool | np.bool_) for item in array.ravel().tolist())


def _has_str(array: np.ndarray) -> bool:
    return any(isinstance(item, str | bytes) for item in array.ravel().tolist())


def _lists_a_bool(value: Any) -> bool:
    """True when a (nested) list or tuple holds a boolean (NumPy reads [20, 20, True] as integers, no object)."""
    for item in value:
        if isinstance(item, bool | np.bool_) or (isinstance(item, np.ndarray) and item.dtype == bool):
            return True
        if isinstance(item, list | tuple) and _lists_a_bool(item):
            return True
    return False


def finite_scalar(name: str, value: Any) -> float:
    """Return ``value`` as a finite real float (booleans and complex numbers are refused)."""
    if isinstance(value, bool | np.bool_):
        raise SpecificationError(f"{name} must be a real number, got the boolean {value!r}")
    if isinstance(value, str | bytes) or (isinstance(value, np.ndarray) and value.dtype.kind in "US"):
        raise SpecificationError(f"{name} must be a real number, got the string {value!r}")
    if isinstance(value, complex | np.complexfloating) or (isinstance(value, np.ndarray) and np.iscomplexobj(value)):
        raise SpecificationError(f"{name} must be a real number, got the complex value {value!r}")
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


def readonly(array: Any, dtype: Any = float) -> np.ndarray:
    """Return a read-only copy of ``array`` as ``dtype`` (for frozen result objects)."""
    out = np.array(array, dtype=dtype, copy=True)
    out.setflags(write=False)
    return out


def sealed(array: np.ndarray) -> np.ndarray:
    """Make an array that the caller allocated read-only in place (no copy) and return it."""
    array.setflags(write=False)
    return array


def integer(name: str, value: Any, *, minimum: int | None = None, maximum: int | None = None) -> int:
    """Return ``value`` as an int (booleans refused) within [minimum, maximum]."""
    if isinstance(value, bool | np.bool_) or not isinstance(value, int | np.integer):
        raise SpecificationError(f"{name} must be an integer, got {value!r}")
    number = int(value)
    if minimum is not None and number < minimum:
        raise SpecificationError(f"{name} must be >= {minimum}, got {number}")
    if maximum is not None and number > maximum:
        raise SpecificationError(f"{name} must be <= {maximum}, got {number}")
    return number


def available_memory() -> int | None:
    """Bytes of physical memory available now (``os.sysconf``), None where the system does not say.

    The one reading behind the up-front memory refusals of `simulate`, `simulate_batch`, the lanes and the
    predictor's margin search.
    """
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, ValueError, OSError):
        return None
