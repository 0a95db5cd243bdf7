"""The CasADi MRP composition and DCM expressions (mrpctl.mrp.add_expr, subtract_expr, dcm_expr)
against the NumPy functions and scipy's Rotation."""

from __future__ import annotations

import casadi as ca
import numpy as np
from scipy.spatial.transform import Rotation

from mrpctl import mrp


def _functions() -> tuple[ca.Function, ca.Function, ca.Function]:
    a = ca.SX.sym("a", 3)
    b = ca.SX.sym("b", 3)
    return (
        ca.Function("add", [a, b], [mrp.add_expr(a, b)]),
        ca.Function("subtract", [a, b], [mrp.subtract_expr(a, b)]),
        ca.Function("dcm", [a], [mrp.dcm_expr(a)]),
    )


def test_composition_expressions_match_numpy_and_scipy() -> None:
    add, subtract, dcm = _functions()
    rng = np.random.default_rng(3)
    for _ in range(50):
        s1 = mrp.short(rng.normal(size=3) * 0.6)
        s2 = mrp.short(rng.normal(size=3) * 0.6)
        composed = np.asarray(add(s1, s2)).ravel()
        # same attitude as the NumPy add and as scipy's R1 * R2 (design/conventions.md)
        np.testing.assert_allclose(mrp.to_dcm(composed), mrp.to_dcm(mrp.add(s1, s2)), atol=1e-13)
        expected = (Rotation.from_mrp(s1) * Rotation.from_mrp(s2)).as_matrix().T
        np.testing.assert_allclose(mrp.to_dcm(composed), expected, atol=1e-13)
        relative = np.asarray(subtract(s1, s2)).ravel()
        np.testing.assert_allclose(mrp.to_dcm(relative), mrp.to_dcm(mrp.subtract(s1, s2)), atol=1e-13)
        np.testing.assert_allclose(mrp.to_dcm(relative), mrp.to_dcm(s1) @ mrp.to_dcm(s2).T, atol=1e-13)
        np.testing.assert_allclose(np.asarray(dcm(s1)), mrp.to_dcm(s1), atol=1e-15)
    # add inverts subtract: sigma_B/N = sigma_R/N (+) (sigma_B/N (-) sigma_R/N)
    s, r = np.array([0.3, -0.2, 0.5]), np.array([-0.4, 0.1, 0.2])
    back = np.asarray(add(r, np.asarray(subtract(s, r)).ravel())).ravel()
    np.testing.assert_allclose(mrp.to_dcm(back), mrp.to_dcm(s), atol=1e-14)
