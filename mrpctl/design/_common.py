"""Shared helpers of the design package: system checks, read-only arrays, the guarded Clarabel call."""

from __future__ import annotations

import enum
import functools
import logging
import time
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg

from mrpctl._validation import finite_array
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.model import plant_model
from mrpctl.spacecraft import Spacecraft

_LOG = logging.getLogger(__name__)

#: The default of a deprecated keyword: not given.
NOT_GIVEN: Any = object()


def delay_rate_argument(delay_rate: Any, rate: Any) -> Any:
    """The bound on the delay's rate dτ/dt of a design function: ``delay_rate``, or ``rate``, its old name.

    ``rate`` is deprecated (a DeprecationWarning): elsewhere in mrpctl ``rate`` is a measurement rate in Hz.
    """
    if rate is NOT_GIVEN:
        return delay_rate
    warnings.warn(
        "rate= (the bound on the delay's rate d tau/dt) is deprecated: use delay_rate= (rate is the measurement "
        "rate in Hz elsewhere in mrpctl)",
        DeprecationWarning,
        stacklevel=3,
    )
    if delay_rate is not None:
        raise SpecificationError("give delay_rate (rate is its deprecated name), not both")
    return rate


def renamed_attribute(owner: Any, old: str, new: str) -> Any:
    """``owner.new``, read through its deprecated name ``old`` (a DeprecationWarning naming both)."""
    warnings.warn(
        f"{type(owner).__name__}.{old} is deprecated: use .{new} (rate is the measurement rate in Hz elsewhere in "
        "mrpctl)",
        DeprecationWarning,
        stacklevel=3,
    )
    return getattr(owner, new)


#: cvxpy statuses that carry a usable solution (only "optimal": "optimal_inaccurate" never certifies).
OPTIMAL = "optimal"


def system_matrices(A: Any, A_d: Any) -> tuple[np.ndarray, np.ndarray]:
    """Check (A, A_d) of ẋ = A x + A_d x(t − τ): finite, square, same shape; return float64 copies."""
    a = finite_array("A", A)
    if a.ndim == 0:
        a = a.reshape(1, 1)
    if a.ndim != 2 or a.shape[0] != a.shape[1] or a.shape[0] == 0:
        raise DimensionError(f"A: expected a square (n, n) matrix but found shape {a.shape}")
    a_d = finite_array("A_d", A_d)
    if a_d.ndim == 0:
        a_d = a_d.reshape(1, 1)
    if a_d.shape != a.shape:
        raise DimensionError(f"A_d: expected shape {a.shape} (the shape of A) but found {a_d.shape}")
    return np.array(a, dtype=float), np.array(a_d, dtype=float)


def balancing(a: np.ndarray, a_d: np.ndarray) -> np.ndarray:
    """Diagonal of the power-of-two similarity T that balances |A| + |A_d| (exact in floating point).

    T⁻¹AT, T⁻¹A_dT have the characteristic roots of (A, A_d) and, for LMIs, congruent certificates;
    the balanced matrices are what the eigenvalue and LMI computations see (LAPACK gebal, scaling only).
    """

    mag = np.abs(a) + np.abs(a_d)
    if a.shape[0] == 1 or not np.any(mag - np.diag(np.diag(mag))):
        return np.ones(a.shape[0])
    _, (scale, _) = scipy.linalg.matrix_balance(mag, permute=False, separate=True)
    return np.clip(np.asarray(scale, dtype=float), 2.0**-60, 2.0**60)


def similarity(m: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """T⁻¹ M T for T = diag(scale)."""
    return (1.0 / scale)[:, None] * m * scale[None, :]


def order_value(order: Any) -> int:
    """Check the Bessel-Legendre order N (0 = Jensen, 1 = Wirtinger)."""
    if isinstance(order, bool) or not isinstance(order, (int, np.integer)):
        raise SpecificationError(f"order must be an integer N >= 0 (0 Jensen, 1 Wirtinger), got {order!r}")
    if order < 0 or order > 10:
        raise SpecificationError(f"order must satisfy 0 <= N <= 10, got {order}")
    return int(order)


def readonly(array: Any, *, dtype: Any = float) -> np.ndarray:
    """A read-only copy of ``array`` keeping complex values when ``dtype`` is complex."""
    out = np.array(array, dtype=dtype, copy=True)
    out.setflags(write=False)
    return out


def is_panic(exc: BaseException) -> bool:
    """True for the ``pyo3_runtime.PanicException`` raised when Clarabel's Rust core panics."""
    return type(exc).__name__ == "PanicException"


@dataclass(frozen=True)
class SolveOutcome:
    """What one guarded solve returned: cvxpy status (or error text) and the wall time (s)."""

    status: str
    time: float
    error: str = ""

    @property
    def optimal(self) -> bool:
        return self.status == OPTIMAL and not self.error


def solve(problem: Any) -> SolveOutcome:
    """Solve a cvxpy problem with Clarabel; errors and Rust panics become an outcome, never an exception.

    ``warm_start=False``: warm starts through Clarabel's update path gave spurious solver errors during
    bisection.
    """
    # deferred: cvxpy (about 1 s to import), only when an LMI is solved
    import cvxpy as cp

    start = time.perf_counter()
    try:
        with warnings.catch_warnings():
            # "Solution may be inaccurate": the status says so, and inaccurate never certifies.
            warnings.simplefilter("ignore", UserWarning)
            problem.solve(solver=cp.CLARABEL, warm_start=False)
    except cp.error.SolverError as exc:
        _LOG.debug("Clarabel failed: %s", exc)
        return SolveOutcome("solver_error", time.perf_counter() - start, f"SolverError: {exc}")
    except (ArithmeticError, np.linalg.LinAlgError) as exc:
        _LOG.debug("Clarabel failed: %s", exc)
        return SolveOutcome("solver_error", time.perf_counter() - start, f"{type(exc).__name__}: {exc}")
    except BaseException as exc:
        if not is_panic(exc):
            raise
        _LOG.warning("Clarabel panicked: %s", exc)
        return SolveOutcome("solver_error", time.perf_counter() - start, f"PanicException: {exc}")
    return SolveOutcome(str(problem.status), time.perf_counter() - start)


def is_diagonal(m: np.ndarray) -> bool:
    """True when the off-diagonal entries of ``m`` are at most 1e-12 of its largest entry."""
    off = m - np.diag(np.diag(m))
    return bool(np.max(np.abs(off)) <= 1e-12 * max(1e-300, float(np.max(np.abs(m)))))


class SynthesisStatus(enum.Enum):
    """Outcome of a synthesis."""

    #: Gains found, and re-verified by `certify` and the exact margin.
    SYNTHESIZED = "synthesized and verified"
    #: The synthesis LMI was feasible but the re-verification of the gains failed.
    NOT_VERIFIED = "synthesized but not verified"
    #: No gains found (the LMI is infeasible for every tuning tried).
    INFEASIBLE = "infeasible"
    #: The solver failed on every attempt.
    SOLVER_FAILED = "solver failed"


@functools.lru_cache(maxsize=1)
def axis_a() -> np.ndarray:
    """A of the normalised per-axis loop (σ, τσ̇) in t/τ, from the one plant model: [[0, 1], [0, 0]]."""
    plant = plant_model(Spacecraft(np.ones(3)))
    # The (σ₁, ω₁/4) block of A is [[0, 1], [0, 0]]; in (σ, τσ̇) and t/τ it is the same matrix.
    return np.array(plant.A[np.ix_((0, 3), (0, 3))], dtype=float)


def real_matrix(name: str, value: Any, rows: int | None = None, cols: int | None = None) -> np.ndarray:
    """``value`` as a finite 2-D array (a scalar is 1 × 1, a vector a column unless ``cols`` asks for a row), of
    ``rows`` × ``cols`` when given; DimensionError naming ``name`` otherwise."""
    m = finite_array(name, value)
    if m.ndim == 0:
        m = m.reshape(1, 1)
    if m.ndim == 1:
        m = m.reshape(-1, 1) if cols is None or cols == 1 else m.reshape(1, -1)
    if m.ndim != 2 or (rows is not None and m.shape[0] != rows) or (cols is not None and m.shape[1] != cols):
        want = f"({rows if rows is not None else 'any'}, {cols if cols is not None else 'any'})"
        raise DimensionError(f"{name}: expected shape {want} but found {m.shape}")
    return m
