"""The sensor's rotation without tan: the factor tan(Φ/4)/Φ against a 60-digit reference, the measured
rotation against scipy's Rotation (design/flight.md, phase 8a).

The reference of the factor is written independently of the code under test: tan = sin/cos by their
Taylor series in :mod:`decimal` at 60 digits, from the exact value of the float64 Φ² the SX receives.
"""

from __future__ import annotations

import math
from decimal import Decimal, localcontext
from fractions import Fraction

import casadi as ca
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mrpctl import mrp
from mrpctl.flight import measurement_function, rotation_vector_to_mrp_expr
from mrpctl.flight.expressions import _tan_quarter_ratio_expr

RNG_SEED = 20261202
#: Largest error of the main path (Φ <= π, Cephes' rational), in ulps of the exact factor (measured: 0.86).
MAIN_PATH_ULPS = 1.0


def _exact_factor(angle_squared: float) -> Fraction:
    """tan(Φ/4)/Φ for Φ = √(``angle_squared``) (the float's exact value), to 60 significant digits."""
    with localcontext() as context:
        context.prec = 60
        angle = Decimal(angle_squared).sqrt()
        if angle == 0:
            return Fraction(1, 4)
        x = angle / 4
        x2, floor = x * x, Decimal(10) ** -62
        sine, term, n = x, x, 1
        while abs(term) > floor:
            term = -term * x2 / ((n + 1) * (n + 2))
            sine, n = sine + term, n + 2
        cosine, term, n = Decimal(1), Decimal(1), 0
        while abs(term) > floor:
            term = -term * x2 / ((n + 1) * (n + 2))
            cosine, n = cosine + term, n + 2
        return Fraction(sine / cosine / angle)


def _ulps(value: float, exact: Fraction) -> float:
    return float(abs(Fraction(value) - exact) / Fraction(float(np.spacing(abs(float(exact))))))


def _factor(angle_squared: np.ndarray) -> np.ndarray:
    s = ca.SX.sym("s")
    function = ca.Function("factor", [s], [_tan_quarter_ratio_expr(s)])
    return np.asarray(function.map(angle_squared.size)(angle_squared[None, :])).ravel()


def _angles() -> np.ndarray:
    """Φ over [0, 4π]: a dense grid, random points, and clusters at 0, π, 2π, 3π, 4π (both sides)."""
    rng = np.random.default_rng(RNG_SEED)
    near = 10.0 ** rng.uniform(-15, -3, 120)
    clusters = [k * math.pi * (1 + sign * near) for k in (1, 2, 3, 4) for sign in (-1, 1)]
    return np.concatenate(
        [
            np.linspace(0.0, 4 * math.pi, 1201),
            rng.uniform(0.0, 4 * math.pi, 400),
            10.0 ** rng.uniform(-160, 0, 150),
            *clusters,
        ]
    )


def test_factor_is_within_an_ulp_of_tan_quarter_angle_over_angle_up_to_pi():
    """Φ <= π: Cephes' rational, no tan and no sqrt; exactly 1/4 at 0 and for Φ² below the float range."""
    phi = np.concatenate((_angles(), np.linspace(0.0, math.pi, 1001)))
    squared = np.concatenate((phi * phi, [0.0, 5e-324, 1e-300, 1e-20, math.pi**2, np.nextafter(math.pi**2, 0)]))
    squared = squared[squared <= math.pi**2]
    assert squared.size > 1600
    computed = _factor(squared)
    errors = np.array([_ulps(v, _exact_factor(s)) for v, s in zip(computed.tolist(), squared.tolist(), strict=True)])
    assert np.max(errors) <= MAIN_PATH_ULPS
    assert np.all(computed[squared < 1e-17] == 0.25)  # tan(Φ/4)/Φ = 1/4 + Φ²/192 + ...: 1/4 in float64


def test_factor_beyond_pi_is_libm_tan_within_its_rounding_and_the_angle_condition_number():
    """π < Φ <= 4π (the wide branch): tan(Φ/4)/Φ; near 2π the factor's condition number in Φ,
    κ = |Φ/(2 sin(Φ/2)) − 1|, amplifies sqrt's rounding of Φ (half an ulp): error <= 2 + κ ulps."""
    phi = _angles()
    squared = phi * phi
    squared = squared[squared > math.pi**2]
    assert squared.size > 800
    computed = _factor(squared)
    for value, s in zip(computed.tolist(), squared.tolist(), strict=True):
        angle = math.sqrt(s)
        kappa = abs(angle / (2 * math.sin(angle / 2)) - 1)
        assert _ulps(value, _exact_factor(s)) <= 2 + kappa, (s, value)


def _rotation(sigma: np.ndarray) -> Rotation:
    """scipy Rotation of the passive [BN] of σ (scipy's matrix is [BN]ᵀ)."""
    return Rotation.from_matrix(np.swapaxes(mrp.to_dcm(sigma), -1, -2))


def test_measured_rotation_is_scipys_composition_for_every_angle():
    """σ̃ = short(σ ⊕ σ(θ)) against scipy's [BN]ᵀ [B̃B]ᵀ, θ of |θ| up to 20 rad (> π, > 2π, > 4π)."""
    rng = np.random.default_rng(RNG_SEED + 1)
    n = 2000
    sigma = rng.normal(size=(n, 3)) * 1.5  # both sets
    direction = rng.normal(size=(n, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    angle = np.concatenate(
        (
            rng.uniform(0.0, 20.0, n - 400),
            10.0 ** rng.uniform(-12, -1, 100),
            math.pi * (1 + rng.uniform(-1e-6, 1e-6, 100)),
            2 * math.pi * (1 + rng.uniform(-1e-6, 1e-6, 100)),
            4 * math.pi * (1 + rng.uniform(-1e-6, 1e-6, 100)),
        )
    )
    theta = direction * angle[:, None]
    x = np.hstack((sigma, np.zeros((n, 3))))
    zeros = np.zeros((3, n))
    x_meas, q_meas = measurement_function().map(n)(x.T, theta.T, zeros, zeros)
    measured, q_meas = np.asarray(x_meas).T[:, 0:3], np.asarray(q_meas).T
    expected = _rotation(sigma) * Rotation.from_rotvec(theta)  # [B~N]^T = [BN]^T [B~B]^T
    assert np.max((expected.inv() * _rotation(measured)).magnitude()) < 1e-13
    assert np.all(np.linalg.norm(measured, axis=1) <= 1.0 + 1e-15)  # short set
    scipy_q = expected.as_quat(canonical=True)  # scalar last, w >= 0
    assert np.max(np.abs(q_meas - np.hstack((scipy_q[:, 3:], scipy_q[:, :3])))) < 1e-13


@pytest.mark.parametrize("theta", [[0.0, 0.0, 0.0], [-0.0, 0.0, -0.0], [1e-300, -2e-300, 5e-324]])
def test_no_or_subnormal_rotation_is_a_quarter_of_theta_exactly(theta: list[float]) -> None:
    vector = ca.SX.sym("theta", 3)
    function = ca.Function("to_mrp", [vector], [rotation_vector_to_mrp_expr(vector)])
    out = np.asarray(function(np.array(theta))).ravel()
    assert np.array_equal(out, 0.25 * np.array(theta))
