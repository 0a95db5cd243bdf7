"""predictor_stability's three statuses and the margin's brackets, against an independent radius."""

import numpy as np
import pytest
import scipy.linalg

from mrpctl import paper
from mrpctl.design import pd_gains
from mrpctl.predictor import (
    MarginInterval,
    StabilityStatus,
    inertia_mismatch_margin,
    perturbed_spacecraft,
    predictor_stability,
)

FAST = pd_gains(paper.SPACECRAFT, zeta=1.0, omega_n=12.85).K


def _independent_radius(e: float) -> float:
    """One axis of the paper case at 1 kHz, d = 500: eigenvalues of the 2(d + 1) lifted matrix (built here)."""
    j, wn, h, d = 80.0, 12.85, 1e-3, 500
    a = np.array([[0.0, 1.0], [0.0, 0.0]])
    k = np.array([[-4 * j * wn**2, -8 * j * wn]])

    def zoh(b):
        m = np.zeros((3, 3))
        m[:2, :2], m[:2, 2:] = a, b
        x = scipy.linalg.expm(m * h)
        return x[:2, :2], x[:2, 2:]

    phi, gm = zoh(np.array([[0.0], [1 / (4 * j)]]))
    _, g = zoh(np.array([[0.0], [1 / (4 * j * (1 + e))]]))
    lifted = np.zeros((2 * (d + 1), 2 * (d + 1)))
    lifted[:2, :2] = phi + gm @ k
    lifted[:2, 2 * d :] = np.linalg.matrix_power(phi, d) @ (g - gm) @ k
    lifted[2:, : 2 * d] = np.eye(2 * d)
    return float(np.max(np.abs(np.linalg.eigvals(lifted))))


def _status(e: float):
    return predictor_stability(paper.SPACECRAFT, FAST, 0.5, plant=perturbed_spacecraft(paper.SPACECRAFT, e))


def test_a_radius_just_below_one_is_stable_not_unstable():
    # independent radius 0.99999988: main reported UNSTABLE (the uniform grid could not resolve the winding)
    e = -0.19919
    assert 1.0 - 1e-6 < _independent_radius(e) < 1.0
    result = _status(e)
    assert result.status is StabilityStatus.STABLE and result.stable


def test_a_radius_within_rounding_of_one_is_unresolved_with_its_interval():
    e = -0.1992  # independent radius 1 - 8e-9
    assert abs(_independent_radius(e) - 1.0) < 1e-7
    result = _status(e)
    assert result.status is StabilityStatus.UNRESOLVED and not result.stable and not result.resolved
    lo, hi = result.radius_bounds
    assert lo < 1.0 < hi and lo <= _independent_radius(e) <= hi
    assert "UNRESOLVED" in str(result)


def test_clear_cases_keep_their_verdicts():
    assert _status(0.0).status is StabilityStatus.STABLE
    assert _status(-0.1993).status is StabilityStatus.UNSTABLE  # independent radius 1.0000011


@pytest.mark.slow
def test_margin_brackets_contain_the_independent_boundary():
    # the independent bisection (this radius, 1e-7 in e) puts the boundary at -19.92007 % and +30.72948 %
    margin = inertia_mismatch_margin(paper.SPACECRAFT, FAST, 0.5, per_axis=False).uniform
    for bracket, boundary in ((margin.lower_bracket, -0.1992007), (margin.upper_bracket, 0.3072948)):
        lo, hi = sorted(bracket)
        assert lo < boundary < hi
        assert hi - lo <= 1e-3 * max(abs(lo), abs(hi))
    assert margin.lower == margin.lower_bracket[0] and margin.upper == margin.upper_bracket[0]
    assert _independent_radius(margin.lower) < 1.0 and _independent_radius(margin.upper) < 1.0


def test_a_hand_built_interval_still_takes_four_fields():
    m = MarginInterval(-0.1, 0.2, False, True)
    assert m.lower_bracket is None and m.symmetric == pytest.approx(0.1)
