"""The rigid spacecraft: its inertia, validated once."""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from mrpctl._validation import finite_array, readonly
from mrpctl.errors import DimensionError, InertiaWarning, SpecificationError

__all__ = ["Spacecraft"]

_SYMMETRY_RTOL = 1e-9


@dataclass(frozen=True, eq=False, init=False)
class Spacecraft:
    """A rigid spacecraft with inertia matrix J (kg m², body frame B).

    Parameters
    ----------
    inertia : array_like
        Either the three principal inertias (J = diag(J₁, J₂, J₃)) or a full 3×3
        matrix. It must be symmetric (to a relative 1e-9) and positive definite.

    Raises
    ------
    DimensionError
        If ``inertia`` is neither (3,) nor (3, 3).
    SpecificationError
        If ``inertia`` holds NaN or inf, is not symmetric or not positive definite.

    Warns
    -----
    InertiaWarning
        If the principal inertias break the rigid-body triangle inequality
        Jᵢ <= Jⱼ + Jₖ (no real mass distribution has them).

    Examples
    --------
    >>> Spacecraft([140, 100, 80]).principal_inertias
    array([ 80., 100., 140.])
    """

    inertia: np.ndarray
    inertia_inverse: np.ndarray = field(repr=False)

    def __init__(self, inertia: ArrayLike) -> None:
        raw = finite_array("inertia", inertia)
        if raw.shape == (3,):
            matrix = np.diag(raw)
        elif raw.shape == (3, 3):
            matrix = raw
        else:
            raise DimensionError(f"inertia: expected shape (3,) or (3, 3) but found {raw.shape}")
        scale = max(float(np.max(np.abs(matrix))), 1e-300)
        asymmetry = float(np.max(np.abs(matrix - matrix.T)))
        if asymmetry > _SYMMETRY_RTOL * scale:
            raise SpecificationError(f"inertia must be symmetric: max |J - J^T| = {asymmetry:.3g} kg m^2")
        matrix = 0.5 * (matrix + matrix.T)
        eigenvalues = np.linalg.eigvalsh(matrix)
        if eigenvalues[0] <= 0.0:
            raise SpecificationError(
                f"inertia must be positive definite: smallest eigenvalue is {eigenvalues[0]:.6g} kg m^2"
            )
        j1, j2, j3 = eigenvalues
        if j3 > j1 + j2 * (1.0 + 1e-12):
            warnings.warn(
                f"inertia violates the rigid-body triangle inequality: principal inertias "
                f"{eigenvalues} have {j3:.6g} > {j1:.6g} + {j2:.6g}",
                InertiaWarning,
                stacklevel=2,
            )
        object.__setattr__(self, "inertia", readonly(matrix))
        object.__setattr__(self, "inertia_inverse", readonly(np.linalg.inv(matrix)))

    @property
    def principal_inertias(self) -> np.ndarray:
        """The eigenvalues of J in ascending order (kg m²)."""
        return np.linalg.eigvalsh(self.inertia)

    @property
    def is_diagonal(self) -> bool:
        """True when J is diagonal, so the linearised loop splits into three axes."""
        return bool(np.all(self.inertia == np.diag(np.diag(self.inertia))))

    @property
    def satisfies_triangle_inequality(self) -> bool:
        """True when every principal inertia is at most the sum of the other two."""
        j1, j2, j3 = self.principal_inertias
        return bool(j3 <= (j1 + j2) * (1.0 + 1e-12))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Spacecraft):
            return NotImplemented
        return bool(np.array_equal(self.inertia, other.inertia))

    def __hash__(self) -> int:
        return hash(self.inertia.tobytes())

    def __repr__(self) -> str:
        if self.is_diagonal:
            return f"Spacecraft(inertia={np.diag(self.inertia).tolist()})"
        return f"Spacecraft(inertia={self.inertia.tolist()})"

    def __str__(self) -> str:
        if self.is_diagonal:
            return "Spacecraft J = diag(" + ", ".join(f"{v:g}" for v in np.diag(self.inertia)) + ") kg m^2"
        return f"Spacecraft J = {self.inertia.tolist()} kg m^2"


def check_spacecraft(value: Any, name: str = "spacecraft") -> Spacecraft:
    """Return ``value`` if it is a [`mrpctl.Spacecraft`][mrpctl.Spacecraft], else raise SpecificationError naming
    ``name``."""
    if not isinstance(value, Spacecraft):
        raise SpecificationError(
            f"{name} must be a mrpctl.Spacecraft (e.g. Spacecraft([140, 100, 80])), got {type(value).__name__}"
        )
    return value
