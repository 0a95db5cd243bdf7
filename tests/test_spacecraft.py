"""Spacecraft: accepted forms of the inertia and every rejection rule."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from mrpctl import Spacecraft
from mrpctl.errors import DimensionError, InertiaWarning, SpecificationError


def test_vector_and_matrix_forms_agree() -> None:
    a = Spacecraft([140, 100, 80])
    b = Spacecraft(np.diag([140.0, 100.0, 80.0]))
    assert a == b
    assert hash(a) == hash(b)
    assert a.is_diagonal
    assert np.array_equal(a.principal_inertias, [80.0, 100.0, 140.0])
    assert np.allclose(a.inertia @ a.inertia_inverse, np.eye(3), atol=1e-15)


def test_full_matrix_is_kept(rng: np.random.Generator) -> None:
    rotation = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    inertia = rotation @ np.diag([10.0, 12.0, 15.0]) @ rotation.T
    sc = Spacecraft(inertia)
    assert not sc.is_diagonal
    assert np.allclose(sc.principal_inertias, [10.0, 12.0, 15.0], rtol=1e-12)


def test_inertia_is_read_only() -> None:
    sc = Spacecraft([1, 2, 2])
    with pytest.raises(ValueError, match="read-only"):
        sc.inertia[0, 0] = 5.0
    with pytest.raises(AttributeError):
        sc.inertia = np.eye(3)  # type: ignore[misc]


def test_str_and_repr() -> None:
    sc = Spacecraft([140, 100, 80])
    assert str(sc) == "Spacecraft J = diag(140, 100, 80) kg m^2"
    assert repr(sc) == "Spacecraft(inertia=[140.0, 100.0, 80.0])"


def test_non_symmetric_rejected() -> None:
    inertia = np.diag([10.0, 10.0, 10.0])
    inertia[0, 1] = 1.0
    with pytest.raises(SpecificationError, match="inertia must be symmetric"):
        Spacecraft(inertia)


def test_indefinite_rejected_with_eigenvalue() -> None:
    with pytest.raises(SpecificationError, match=r"inertia must be positive definite: smallest eigenvalue is -5"):
        Spacecraft([10.0, -5.0, 10.0])
    with pytest.raises(SpecificationError, match="positive definite"):
        Spacecraft([[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    with pytest.raises(SpecificationError, match="smallest eigenvalue is 0"):
        Spacecraft([0.0, 1.0, 1.0])


@pytest.mark.parametrize("bad", [[np.nan, 1, 1], [1, np.inf, 1]])
def test_non_finite_rejected(bad: list[float]) -> None:
    with pytest.raises(SpecificationError, match="inertia must be finite"):
        Spacecraft(bad)


@pytest.mark.parametrize("bad", [[1.0, 2.0], np.eye(2), np.ones((3, 3, 1))])
def test_wrong_shape_rejected(bad: object) -> None:
    with pytest.raises(DimensionError, match=r"inertia: expected shape \(3,\) or \(3, 3\)"):
        Spacecraft(bad)


def test_non_numeric_rejected() -> None:
    with pytest.raises(SpecificationError, match="inertia must be numeric"):
        Spacecraft(["a", "b", "c"])


def test_triangle_inequality_flagged() -> None:
    with pytest.warns(InertiaWarning, match="triangle inequality"):
        sc = Spacecraft([1.0, 1.0, 3.0])
    assert not sc.satisfies_triangle_inequality


def test_valid_inertia_does_not_warn() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sc = Spacecraft([140, 100, 80])
    assert sc.satisfies_triangle_inequality
    # A thin plate sits exactly on the boundary J3 = J1 + J2: still physical.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert Spacecraft([1.0, 2.0, 3.0]).satisfies_triangle_inequality
