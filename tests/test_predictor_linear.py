"""The linear predictor form: the NumPy reference (tests/predictor_reference.py, form "linear") checked
against independent results, then the compiled engine checked against the reference.

The linear form runs the linear zero-order-hold model of [σ; ω/4] as its copy and applies the FSA
increment v = τ w_y + S_σ on the rotation group through the [3/2] Padé form of tan (see the reference's
docstring). Its three self-checks need no engine: at small angles it is the linearised FSA loop; about
one principal axis, where the linear model is exact in the rotation angle, its prediction error is the
Padé remainder; without α no switch is recorded. The engine (`PredictorForm.LINEAR`) then matches the
reference on test_predictor_engine's cases and flight options with identical switch samples and states
within its RTOL = 1e-14 relative (measured: at most 7.2e-16 for states, 3.7e-16 for torques), and the
batch, on the scalar and the lane engine, holds `simulate`'s bits.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mrpctl import OnPredicted, paper, simulate, simulate_batch
from mrpctl._compile import find_compiler
from mrpctl.design import pd_gains
from mrpctl.engines import lanes as lane_engines
from mrpctl.flight import ActuatorModel, Saturation, SensorModel
from mrpctl.predictor import Predictor, PredictorForm, perturbed_spacecraft
from mrpctl.spacecraft import Spacecraft

sys.path.insert(0, str(Path(__file__).parent))
import predictor_reference as ref
from lane_assertions import assert_row_is_the_run, assert_same_bits, one_run
from test_predictor_engine import CASES, RTOL, TUMBLE2, _assert_matches, _engine_state

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


# ------------------------------------------------------------------ the compiled engine against the reference
LINEAR = Predictor(model=SC, form=PredictorForm.LINEAR)
# The reference's switch samples with the linear form on the CASES of test_predictor_engine (not a vacuous
# comparison: most cases switch, two of them twice; tumble-exact-model switches 2 samples after form (b)).
LINEAR_SWITCHES = {
    "paper-exact-model": [44],
    "paper-plant+10%": [44],
    "paper-fast-plant-10%": [],
    "tumble-exact-model": [30],
    "tumble-slow-plant+10%": [21, 176],
    "tumble2-slow-plant+10%": [7, 477],
    "tumble2-plant-15%": [],
    "tumble2-hysteresis": [11, 502],
    "tumble-never-switch": [],
}
ENGINE_CASES = [pytest.param(*case.values[:5], id=case.id) for case in CASES]


@pytest.mark.parametrize(("x0", "gain", "e", "alpha", "t_final"), ENGINE_CASES)
def test_engine_equals_the_reference_loop(
    x0: np.ndarray, gain: np.ndarray, e: float, alpha: float | None, t_final: float, request: pytest.FixtureRequest
) -> None:
    """The plant is (1 + e) J_model; identical switch samples, states and torques within RTOL (1e-14) relative."""
    plant = perturbed_spacecraft(SC, e)
    result = simulate(plant, gain, x0, tau=0.5, rule=OnPredicted(alpha), t_final=t_final, rate=100.0, predictor=LINEAR)
    reference = ref.run(
        np.diag(plant.inertia), J, gain, x0, tau=0.5, rate=100.0, t_final=t_final, form="linear", alpha=alpha
    )
    _assert_matches(result, reference, gain)
    assert reference.switches == LINEAR_SWITCHES[request.node.callspec.id]


def test_the_linear_form_is_not_the_default_form() -> None:
    """Not vacuous: on a tumble the two forms switch on different samples (the reference: 30 and 28)."""
    options: dict[str, Any] = dict(tau=0.5, rule=OnPredicted(), t_final=1.0, rate=100.0)
    linear = simulate(SC, _gain(1.0), TUMBLE, predictor=LINEAR, **options)
    default = simulate(SC, _gain(1.0), TUMBLE, predictor=Predictor(model=SC), **options)
    assert linear.switch_indices.tolist() == [30] and default.switch_indices.tolist() == [28]


def test_actuator_limits_drive_the_linear_copy_with_the_applied_torque() -> None:
    plant = perturbed_spacecraft(SC, 0.1)
    gain = _gain(2.0)
    result = simulate(
        plant,
        gain,
        TUMBLE,
        tau=0.5,
        rule=OnPredicted(),
        t_final=3.0,
        rate=100.0,
        predictor=LINEAR,
        actuator=ActuatorModel(u_max=50.0, mode=Saturation.CLIP),
    )
    reference = ref.run(
        np.diag(plant.inertia), J, gain, TUMBLE, tau=0.5, rate=100.0, t_final=3.0, form="linear", u_max=50.0
    )
    _assert_matches(result, reference, gain)
    assert np.max(np.abs(result.u)) == 50.0
    assert result.saturated_fraction is not None and result.saturated_fraction > 0.1


@pytest.mark.parametrize("rows", [False, True])
def test_disturbance_acts_on_the_plant_only(rows: bool) -> None:
    """A constant torque, or one row per sample: on the plant, never on the linear copy."""
    n = 301
    w = np.array([0.3, -0.2, 0.1])
    if rows:
        w = w * np.cos(np.arange(n) / 100.0)[:, None] + 0.05 * np.random.default_rng(5).standard_normal((n, 3))
    options: dict[str, Any] = dict(tau=0.5, rate=100.0, t_final=3.0)
    result = simulate(SC, _gain(1.0), TUMBLE, rule=OnPredicted(), predictor=LINEAR, disturbance=w, **options)
    reference = ref.run(J, J, _gain(1.0), TUMBLE, form="linear", disturbance=w, **options)
    _assert_matches(result, reference, _gain(1.0))
    undisturbed = ref.run(J, J, _gain(1.0), TUMBLE, form="linear", **options)
    assert np.max(np.abs(undisturbed.x - reference.x)) > 1e-4  # the disturbance is not vacuous


def test_sensor_noise_and_bias_enter_the_correction() -> None:
    """The noisy delayed measurement is y (the same noise stream in the reference)."""
    sensor = SensorModel(attitude_noise=1e-3, rate_noise=1e-3, gyro_bias=[1e-3, -2e-3, 0.5e-3], seed=7)
    n = 301
    theta, eta = sensor.noise(0, n)
    options: dict[str, Any] = dict(tau=0.5, rate=100.0, t_final=3.0)
    result = simulate(
        perturbed_spacecraft(SC, 0.1),
        _gain(1.0),
        TUMBLE,
        rule=OnPredicted(),
        predictor=LINEAR,
        sensor=sensor,
        **options,
    )
    noise = (theta, eta, np.asarray(sensor.gyro_bias))
    reference = ref.run(J * 1.1, J, _gain(1.0), TUMBLE, form="linear", noise=noise, **options)
    assert result.switch_indices.tolist() == reference.switches
    # The sensor composes MRPs where the reference multiplies DCMs: the same bound holds.
    assert np.max(np.abs(_engine_state(result) - reference.x)) <= RTOL * np.max(np.abs(reference.x))
    noiseless = ref.run(J * 1.1, J, _gain(1.0), TUMBLE, form="linear", **options)
    assert np.max(np.abs(noiseless.x - reference.x)) > 1e-6  # the noise is not vacuous


def test_full_inertia_model_and_plant() -> None:
    """A coupled (non-diagonal) model and plant: J_m⁻¹ u in the linear copy is a full 3×3 product."""
    coupled = Spacecraft(np.array([[140.0, 5.0, 0.0], [5.0, 100.0, 3.0], [0.0, 3.0, 80.0]]))
    plant = perturbed_spacecraft(coupled, 0.1, axis=1)
    gain = pd_gains(coupled, zeta=1.0, omega_n=1.0).K
    predictor = Predictor(model=coupled, form=PredictorForm.LINEAR)
    result = simulate(plant, gain, TUMBLE, tau=0.3, rule=OnPredicted(), t_final=3.0, rate=100.0, predictor=predictor)
    reference = ref.run(plant.inertia, coupled.inertia, gain, TUMBLE, tau=0.3, rate=100.0, t_final=3.0, form="linear")
    _assert_matches(result, reference, gain)


def test_batch_and_lanes_equal_simulate_bit_for_bit(monkeypatch: pytest.MonkeyPatch) -> None:
    """simulate_batch with the linear form: with trajectories (scalar engine, thread pool) each run holds
    simulate's bits; metrics only, every run goes on the lane engine and each row holds simulate's bits."""
    states = np.array([X0, TUMBLE, TUMBLE2, X0 + 0.05])
    plants = [perturbed_spacecraft(SC, e) for e in (0.0, 0.1, -0.1, 0.05)]
    gains = np.array([_gain(1.0), _gain(2.0), _gain(0.5), _gain(1.0)])
    case: dict[str, Any] = dict(
        spacecraft=plants,
        K=gains,
        x0=states,
        tau=[0.2, 0.5, 0.3, 0.2],
        rule=[OnPredicted(), OnPredicted(1.1), OnPredicted(), OnPredicted(None)],
        actuator=[None, ActuatorModel(u_max=50.0), None, None],
        sensor=[None, None, SensorModel(attitude_noise=1e-3, rate_noise=1e-3, seed=3), None],
        disturbance=[np.zeros(3), np.zeros(3), np.array([0.1, 0.0, -0.1]), np.zeros(3)],
        predictor=LINEAR,
    )
    common: dict[str, Any] = dict(t_final=2.0, rate=100.0)
    singles = [simulate(**one_run(case, i), **common) for i in range(len(states))]
    with_paths = simulate_batch(**case, **common, trajectories=True, threads=2)
    assert with_paths.runs is not None
    for run, single in zip(with_paths.runs, singles, strict=True):
        assert np.array_equal(run.sigma, single.sigma) and np.array_equal(run.omega, single.omega)
        assert np.array_equal(run.u, single.u) and np.array_equal(run.switch_indices, single.switch_indices)
    packed: list[int] = []
    pack = lane_engines.closed_loop_batches

    def spy(engine: Any, x0: Any, *args: Any, **kwargs: Any) -> Any:
        packed.append(len(x0))
        return pack(engine, x0, *args, **kwargs)

    monkeypatch.setattr(lane_engines, "closed_loop_batches", spy)
    lanes = simulate_batch(**case, **common, threads=2)
    if find_compiler() is not None:
        assert sum(packed) == len(states)  # every run on the lanes
    for i, single in enumerate(singles):
        assert_row_is_the_run(lanes, i, single)
        assert np.asarray(lanes.max_sigma)[i].tobytes() == np.asarray(single.max_sigma).tobytes()
    assert_same_bits(lanes, with_paths)
    assert sum(s.switch_count for s in singles) >= 2
