"""The linear predictor form: the NumPy reference (tests/predictor_reference.py, form "linear") checked
against independent results, then the compiled engine checked against the reference.

The linear form runs the linear zero-order-hold model of [σ; ω/4] as its copy and applies the FSA
increment v = τ w_y + S_σ on the rotation group through the [3/2] Padé form of tan (see the reference's
docstring). Its three self-checks need no engine: at small angles it is the linearised FSA loop; about
one principal axis, where the linear model is exact in the rotation angle, its prediction error is the
Padé remainder; without α no switch is recorded.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from mrpctl import paper
from mrpctl.design import pd_gains
from mrpctl.predictor import perturbed_spacecraft

sys.path.insert(0, str(Path(__file__).parent))
import predictor_reference as ref

SC = paper.SPACECRAFT
J = np.diag(SC.inertia)
X0 = np.array([0.93, 0.0, 0.0, 0.46 / 4, 0.0, 0.0])
TUMBLE = np.array([0.3, -0.5, 0.2, 4.0 / 4, -2.0 / 4, 3.0 / 4])  # |ω| = 5.4 rad/s


def _gain(omega_n: float) -> np.ndarray:
    return pd_gains(SC, zeta=1.0, omega_n=omega_n).K


def _pade_remainder(x: float) -> float:
    """Angle error (rad) of the [3/2] Padé MRP of a rotation by 4x: 4 |x − atan(x (15 − x²)/(15 − 6x²))|.

    ≈ 4x⁷/1575 /(1 + tan²x) (tan x − P(x) = x⁷/1575 + O(x⁹)); increasing in x on [0, 1.25).
    """
    return 4.0 * abs(x - math.atan(x * (15.0 - x * x) / (15.0 - 6.0 * x * x)))


# ------------------------------------------------------------------ the reference, without the engine
@pytest.mark.parametrize("e", [0.0, 0.1])
def test_small_motion_is_the_linearised_fsa_loop(e: float) -> None:
    """|x0| = ε: the reference equals `linear_run` (ẋ = A x + B u, exact ZOH, FSA sums with B_m) to O(ε²).

    The linear parts agree exactly: for the double integrator A² = 0, so the plant's RK4 step and the
    copy's ZOH step are both e^{Ah} (and Γ) exactly, and the copy's forced response over τ is the FSA sum
    Σ e^{A(t_k − t_{j+1})} Γ_m u_j. What is left is quadratic in the amplitude: the kinematic terms
    σ×ω, σσᵀω, σ²ω, the gyroscopic ω × Jω, and the group composition C(p) C(σ_y) in place of σ_y + v
    (tan v − v is cubic). The relative difference is therefore c ε with c = O(1) (measured: c = 0.21 at
    e = 0, 0.235 at e = 0.1): it must be below ε/2, and it must scale as ε (a factor 10 ± 1 % from
    ε = 1e-4 to 1e-5, measured 10.000; the next terms are a further O(ε) relative, rounding ~1e-16).
    """
    plant = np.diag(J) * (1.0 + e)
    gain = _gain(1.0)
    rate, tau, t_final = 100.0, 0.5, 3.0
    a = np.block([[np.zeros((3, 3)), np.eye(3)], [np.zeros((3, 3)), np.zeros((3, 3))]])
    b = np.vstack((np.zeros((3, 3)), np.linalg.inv(plant) / 4.0))
    b_model = np.vstack((np.zeros((3, 3)), np.linalg.inv(np.diag(J)) / 4.0))
    direction = np.array([0.5, -1.0, 0.75, 0.2, 0.15, -0.25])  # max |component| = 1
    relative = []
    for eps in (1e-4, 1e-5):
        x0 = eps * direction
        r = ref.run(plant, J, gain, x0, tau=tau, rate=rate, t_final=t_final, form="linear")
        xs, preds = ref.linear_run(a, b, b_model, gain, x0, d=round(tau * rate), h=1.0 / rate, n=len(r.t))
        assert r.switches == []
        scale = np.max(np.abs(xs))
        worst = max(
            np.max(np.abs(r.x - xs)) / scale,
            np.max(np.abs(r.x_hat - preds)) / scale,
            np.max(np.abs(r.u - preds @ gain.T)) / np.max(np.abs(r.u)),
        )
        assert worst <= 0.5 * eps
        relative.append(worst)
    assert 9.9 <= relative[0] / relative[1] <= 10.1


def test_single_axis_prediction_error_is_the_pade_remainder() -> None:
    """J_m = J, the paper case about x only (ωₙ = 3, τ = 0.5 s, 100 Hz, 20 s).

    About one principal axis the rotation angle θ = 4 atan σ_x obeys θ̈ = u_x/J_x exactly, so the copy's
    linear ZOH model is exact in θ/4 and v_k is the rotation over the last τ (over [0, t_k] for k < d), /4.
    The only prediction error is then the Padé error of tan: at every sample at most the remainder at
    |v_k| (v_k taken from the plant's own angles), plus the plant's RK4 error over τ (measured 2.6e-9 rad;
    2.5e-13 with 10 substeps: O(h⁴)), bounded by 1e-8 rad. The largest error is the remainder at the
    largest |v| (measured 5.605e-6 rad at |v| = 0.419; the remainder there 5.604e-6). The rate is predicted
    exactly (ω̇ is constant over a sample, which RK4 integrates exactly): rounding only.
    """
    gain = _gain(3.0)
    rate, tau = 100.0, 0.5
    d = round(tau * rate)
    r = ref.run(J, J, gain, X0, tau=tau, rate=rate, t_final=20.0, form="linear")
    assert not np.any(r.x[:, [1, 2, 4, 5]]) and not np.any(r.x_hat[:, [1, 2, 4, 5]])
    theta = np.unwrap(4.0 * np.arctan(r.x[:, 0]))  # unwrap: the plant's σ is kept in the short set
    start = np.maximum(np.arange(len(theta)) - d, 0)
    v = np.abs(theta - theta[start]) / 4.0
    remainder = np.array([_pade_remainder(float(x)) for x in v])
    assert np.max(r.attitude_error - remainder) <= 1e-8
    late = r.attitude_error[d:]
    worst = float(np.max(late))
    assert worst <= _pade_remainder(float(np.max(v[d:]))) + 1e-8
    assert worst == pytest.approx(_pade_remainder(float(np.max(v[d:]))), rel=1e-3)  # the Padé error is what is seen
    assert 5e-6 < worst < 6e-6  # (5.605e-6 rad measured)
    assert np.max(r.rate_error) <= 1e-14
    assert r.settling_time is not None


def test_no_alpha_records_no_switch() -> None:
    """α = None: no switch, although the prediction leaves the unit ball; identical to α = 1 before its switch."""
    plant = np.diag(perturbed_spacecraft(SC, 0.1).inertia)
    options = dict(tau=0.5, rate=100.0, t_final=4.0, form="linear")
    never = ref.run(plant, J, _gain(1.0), TUMBLE, alpha=None, **options)  # type: ignore[arg-type]
    switching = ref.run(plant, J, _gain(1.0), TUMBLE, alpha=1.0, **options)  # type: ignore[arg-type]
    assert never.switches == []
    assert np.max(np.linalg.norm(never.sigma_hat, axis=1)) > 1.2  # not vacuous: |σ̂| > α would have switched
    assert len(switching.switches) >= 1
    first = switching.switches[0]
    assert np.array_equal(never.x_hat[:first], switching.x_hat[:first])
    assert np.max(np.linalg.norm(switching.sigma_hat, axis=1)) < 1.0
