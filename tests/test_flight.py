"""Tests of mrpctl.flight: option values, random streams, CasADi builders, and the NumPy reference loop."""

from __future__ import annotations

import itertools
import math

import casadi as ca
import numpy as np
import pytest
from flight_reference import reference_loop, used_measurements
from scipy import stats
from scipy.spatial.transform import Rotation

from mrpctl import OnCurrent, mrp, paper, simulate_batch
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.flight import (
    ActuatorModel,
    DelayKind,
    DelayModel,
    Disturbance,
    Hysteretic,
    Saturation,
    SensorModel,
    actuator_function,
    compose_mrp_expr,
    hysteresis_function,
    measurement_function,
    newest_arrived,
    selection_function,
)
from mrpctl.model import plant_model

RNG_SEED = 20261201


def _rotation(sigma: np.ndarray) -> Rotation:
    """scipy Rotation of the passive [BN] of σ (scipy's matrix is [BN]ᵀ)."""
    return Rotation.from_matrix(np.swapaxes(mrp.to_dcm(sigma), -1, -2))


# ============================================================================ bad input
@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        (dict(attitude_noise=-0.1), "attitude_noise"),
        (dict(attitude_noise=math.nan), "attitude_noise"),
        (dict(rate_noise=-1e-3), "rate_noise"),
        (dict(rate_noise=math.inf), "rate_noise"),
        (dict(gyro_bias=[0.0, 1.0]), "gyro_bias"),
        (dict(gyro_bias=[0.0, math.nan, 0.0]), "gyro_bias"),
        (dict(seed=-1), "seed"),
        (dict(seed=True), "seed"),
    ],
)
def test_sensor_model_refuses_bad_input(kwargs, name):
    with pytest.raises(ValueError, match=name):
        SensorModel(**kwargs)


@pytest.mark.parametrize("delta", [-0.01, 1.0, 1.5, math.nan, True])
def test_hysteretic_refuses_delta_outside_unit_interval(delta):
    with pytest.raises(SpecificationError, match="delta"):
        Hysteretic(delta)


def test_hysteretic_alpha_and_delta_are_inverse():
    for alpha in (1.0, 1.05, 1.2, 1.5, 3.0):
        rule = Hysteretic.from_alpha(alpha)
        assert rule.alpha == pytest.approx(alpha, rel=1e-14)
    assert Hysteretic(0.0).alpha == 1.0
    with pytest.raises(SpecificationError, match="alpha"):
        Hysteretic.from_alpha(0.99)
    assert Hysteretic(0.2).min_dwell_time(2.0) == pytest.approx(0.4)
    assert "alpha" in str(Hysteretic(0.1))


@pytest.mark.parametrize(
    ("kwargs", "error", "name"),
    [
        (dict(u_max=0.0), SpecificationError, "u_max"),
        (dict(u_max=[1.0, -1.0, 1.0]), SpecificationError, "u_max"),
        (dict(u_max=[1.0, 1.0]), DimensionError, "u_max"),
        (dict(u_max=math.nan), SpecificationError, "u_max"),
        (dict(u_max=1.0, norm_max=0.0), SpecificationError, "norm_max"),
        (dict(u_max=1.0, mode="clip"), SpecificationError, "mode"),
    ],
)
def test_actuator_model_refuses_bad_input(kwargs, error, name):
    with pytest.raises(error, match=name):
        ActuatorModel(**kwargs)


def test_actuator_model_scalar_limit_is_per_axis():
    model = ActuatorModel(2.0, norm_max=3.0)
    assert model.u_max.tolist() == [2.0, 2.0, 2.0]
    assert not model.u_max.flags.writeable
    assert model.norm_limit == 3.0
    assert ActuatorModel([1, 2, 3]).norm_limit == math.inf


def test_delay_model_refuses_bad_input():
    with pytest.raises(SpecificationError, match="delays"):
        DelayModel.sequence([0.1, 0.3], tau_min=0.1, tau_max=0.2)
    with pytest.raises(SpecificationError, match="delays"):
        DelayModel.sequence([0.1, math.nan], tau_min=0.1, tau_max=0.2)
    with pytest.raises(DimensionError, match="delays"):
        DelayModel.sequence([[0.1, 0.1]], tau_min=0.1, tau_max=0.2)
    with pytest.raises(SpecificationError, match="tau_max"):
        DelayModel.jitter(0.2, 0.1)
    with pytest.raises(SpecificationError, match="tau"):
        DelayModel.constant(-0.1)
    sequence = DelayModel.sequence([0.1, 0.2, 0.1], tau_min=0.1, tau_max=0.2)
    with pytest.raises(DimensionError, match=r"delays: expected shape \(n,\) = \(4,\)"):
        sequence.check_horizon(4)
    sequence.check_horizon(3)
    with pytest.raises(DimensionError, match="delays"):
        sequence.samples(100.0, 0, 4)
    with pytest.raises(SpecificationError, match="whole numbers of measurement periods"):
        sequence.samples(15.0, 0, 3)
    assert sequence.samples(100.0, 0, 3).tolist() == [10, 20, 10]
    assert sequence.kind is DelayKind.SEQUENCE


def test_disturbance_refuses_wrong_shapes():
    for bad in ([1.0, 2.0], np.zeros((5, 4)), np.zeros((0, 3)), np.zeros((2, 3, 1))):
        with pytest.raises(DimensionError, match="torque"):
            Disturbance(bad)
    with pytest.raises(SpecificationError, match="torque"):
        Disturbance([0.0, math.inf, 0.0])
    varying = Disturbance(np.arange(12.0).reshape(4, 3))
    with pytest.raises(DimensionError, match=r"torque: expected shape \(n, 3\) = \(5, 3\)"):
        varying.check_horizon(5)
    varying.check_horizon(4)
    assert varying.samples(1, 3).tolist() == [[3, 4, 5], [6, 7, 8]]
    assert Disturbance([1.0, 2.0, 3.0]).samples(0, 2).tolist() == [[1, 2, 3], [1, 2, 3]]


# ============================================================================ random streams
def test_noise_stream_does_not_depend_on_slicing_and_is_seeded():
    sensor = SensorModel(attitude_noise=0.01, rate_noise=0.002, seed=7)
    n = 2 * 4096 + 123
    whole = sensor.noise(0, n)
    cuts = [0, 1, 17, 4095, 4096 + 5, 2 * 4096, n]
    parts = [sensor.noise(a, b) for a, b in itertools.pairwise(cuts)]
    for i in range(2):
        assert np.array_equal(np.vstack([p[i] for p in parts]), whole[i])
    again = SensorModel(attitude_noise=0.01, rate_noise=0.002, seed=7).noise(0, n)
    assert np.array_equal(again[0], whole[0]) and np.array_equal(again[1], whole[1])
    other = SensorModel(attitude_noise=0.01, rate_noise=0.002, seed=8).noise(0, n)
    assert not np.any(other[0] == whole[0])
    assert not np.any(whole[0] / 0.01 == whole[1] / 0.002)  # attitude and rate streams are distinct
    zero = SensorModel().noise(5, 50)
    assert not np.any(zero[0]) and not np.any(zero[1]) and zero[0].shape == (45, 3)


def test_jitter_stream_does_not_depend_on_slicing_and_stays_in_bounds():
    model = DelayModel.jitter(0.01, 0.05, seed=3)
    whole = model.samples(1000.0, 0, 4096 + 500)
    assert whole.min() == 10 and whole.max() == 50
    assert np.array_equal(
        np.concatenate((model.samples(1000.0, 0, 300), model.samples(1000.0, 300, 4096 + 500))), whole
    )
    assert np.array_equal(DelayModel.jitter(0.02, 0.02, seed=3).samples(1000.0, 0, 100), np.full(100, 20))


def test_attitude_error_angle_has_the_requested_rms_chi2_at_1e5_samples():
    """|θ|²/σ_θ² summed over 10⁵ measurements is χ² with 3·10⁵ dof (angles from scipy, not from θ)."""
    n = 100_000
    sensor = SensorModel(attitude_noise=0.01, seed=11)
    theta, eta = sensor.noise(0, n)
    rng = np.random.default_rng(RNG_SEED)
    sigma = mrp.short(rng.normal(size=(n, 3)))
    x = np.hstack((sigma, np.zeros((n, 3))))
    x_meas, _ = measurement_function().map(n)(x.T, theta.T, eta.T, np.zeros((3, n)))
    measured = np.asarray(x_meas).T[:, 0:3]
    angles = (_rotation(sigma).inv() * _rotation(measured)).magnitude()
    statistic = np.sum(angles**2) / sensor.attitude_noise**2
    dof = 3 * n
    assert stats.chi2.ppf(1e-6, dof) < statistic < stats.chi2.ppf(1 - 1e-6, dof)
    assert math.sqrt(np.mean(angles**2)) == pytest.approx(math.sqrt(3) * 0.01, rel=0.01)


# ============================================================================ CasADi builders
def test_measurement_composes_a_rotation_after_the_true_attitude_as_scipy_does():
    rng = np.random.default_rng(RNG_SEED)
    n = 300
    sigma = rng.normal(size=(n, 3)) * 1.5  # both sets
    theta = rng.normal(size=(n, 3)) * 0.5
    omega = rng.normal(size=(n, 3))
    eta = rng.normal(size=(n, 3)) * 0.01
    bias = rng.normal(size=3) * 0.001
    x = np.hstack((sigma, omega / 4))
    x_meas, q_meas = measurement_function().map(n)(x.T, theta.T, eta.T, np.tile(bias[:, None], (1, n)))
    x_meas, q_meas = np.asarray(x_meas).T, np.asarray(q_meas).T
    expected = _rotation(sigma) * Rotation.from_rotvec(theta)  # [B~N]^T = [BN]^T [B~B]^T
    assert np.max(np.abs(np.swapaxes(mrp.to_dcm(x_meas[:, 0:3]), 1, 2) - expected.as_matrix())) < 1e-12
    assert np.all(np.linalg.norm(x_meas[:, 0:3], axis=1) <= 1.0 + 1e-15)  # short set
    scipy_q = expected.as_quat(canonical=True)  # scalar last, w >= 0
    assert np.max(np.abs(q_meas - np.hstack((scipy_q[:, 3:], scipy_q[:, :3])))) < 1e-12
    assert np.max(np.abs(4 * x_meas[:, 3:6] - (omega + bias + eta))) < 1e-15


def test_measurement_without_noise_returns_the_short_state_bit_for_bit():
    rng = np.random.default_rng(RNG_SEED + 1)
    sigma = mrp.short(rng.normal(size=(50, 3)))
    x = np.hstack((sigma, rng.normal(size=(50, 3))))
    out, _ = measurement_function().map(50)(x.T, np.zeros((3, 50)), np.zeros((3, 50)), np.zeros((3, 50)))
    assert np.array_equal(np.asarray(out).T, x)


def test_compose_mrp_matches_mrp_add_and_scipy():
    rng = np.random.default_rng(RNG_SEED + 2)
    a, b = ca.SX.sym("a", 3), ca.SX.sym("b", 3)
    compose = ca.Function("compose", [a, b], [compose_mrp_expr(a, b)])
    for _ in range(100):
        s1, s2 = mrp.short(rng.normal(size=3)), mrp.short(rng.normal(size=3))
        out = np.asarray(compose(s1, s2)).ravel()
        assert np.max(np.abs(mrp.to_dcm(out) - mrp.to_dcm(s2) @ mrp.to_dcm(s1))) < 1e-12
        assert np.max(np.abs(mrp.to_dcm(out) - mrp.to_dcm(mrp.add(s1, s2)))) < 1e-12


def _hysteresis_numpy(h: float, q: np.ndarray, delta: float) -> tuple[float, np.ndarray, bool]:
    switched = h * q[0] < -delta
    if switched:
        h = -h
    return h, h * q[1:] / (1 + h * q[0]), bool(switched)


def test_hysteresis_function_matches_the_rule_and_bounds_sigma_c():
    rng = np.random.default_rng(RNG_SEED + 3)
    function = hysteresis_function()
    for _ in range(400):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        h = float(rng.choice([-1.0, 1.0]))
        delta = float(rng.uniform(0, 0.9))
        h_next, sigma_c, switched = (np.asarray(v).ravel() for v in function(h, q, delta))
        h_ref, sigma_ref, switched_ref = _hysteresis_numpy(h, q, delta)
        assert h_next[0] == h_ref and bool(switched[0]) == switched_ref
        assert np.max(np.abs(sigma_c - sigma_ref)) <= 1e-12 * max(1.0, np.linalg.norm(sigma_ref))
        assert np.linalg.norm(sigma_c) <= Hysteretic(delta).alpha * (1 + 1e-12)
        # σ_c describes the measured attitude
        assert np.max(np.abs(mrp.to_dcm(sigma_c) - mrp.to_dcm(mrp.from_quaternion(q)))) < 1e-12


def test_selection_function_equals_unwrapped_quaternion_hysteresis_on_noisy_sequences():
    """The MRP form (sensor's short set + continuity sign c) against the quaternion form on q̂."""
    rng = np.random.default_rng(RNG_SEED + 4)
    select, hysteresis = selection_function(), hysteresis_function()
    for delta in (0.0, 0.05, 0.3):
        # a tumble through Φ = 180° several times, with noise
        angles = np.linspace(0, 5 * np.pi, 700) + rng.normal(size=700) * 0.02
        axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
        q_true = np.hstack((np.cos(angles / 2)[:, None], np.sin(angles / 2)[:, None] * axis))
        canonical = np.where(q_true[:, :1] < 0, -q_true, q_true)
        sigma = canonical[:, 1:] / (1 + canonical[:, :1])
        h_mrp, c, prev = 1.0, 1.0, sigma[0]
        h_q, q_prev = 1.0, canonical[0]
        switches = 0
        for k in range(len(sigma)):
            h_mrp, c, sigma_c, sw = (np.asarray(v).ravel() for v in select(h_mrp, c, sigma[k], prev, delta))
            h_mrp, c = float(h_mrp[0]), float(c[0])
            prev = sigma[k]
            q_hat = canonical[k] if np.dot(canonical[k], q_prev) >= 0 else -canonical[k]
            q_prev = q_hat
            h_q_next, sigma_q, sw_q = (np.asarray(v).ravel() for v in hysteresis(h_q, q_hat, delta))
            h_q = float(h_q_next[0])
            assert h_mrp == h_q and sw[0] == sw_q[0], k
            assert np.max(np.abs(sigma_c - sigma_q)) <= 1e-12 * max(1.0, np.linalg.norm(sigma_q))
            switches += int(sw[0])
            if delta == 0.0:
                assert np.array_equal(sigma_c, sigma[k])  # δ = 0: the sensor's short set, bit for bit
        assert switches >= 2


def _saturate_numpy(u, u_max, norm_max, clip):
    if clip:
        v = np.clip(u, -u_max, u_max)
        r = np.linalg.norm(v) / norm_max
        return (v / r if r > 1 else v), bool(np.any(np.abs(u) > u_max) or r > 1)
    r = max(np.max(np.abs(u) / u_max), np.linalg.norm(u) / norm_max)
    return (np.clip(u / r, -u_max, u_max) if r > 1 else u), bool(r > 1)


@pytest.mark.parametrize("mode", list(Saturation))
def test_actuator_function_limits_preserve_direction_and_add_the_disturbance(mode):
    rng = np.random.default_rng(RNG_SEED + 5)
    function = actuator_function(mode)
    u_max = np.array([0.5, 1.0, 2.0])
    for _ in range(300):
        u = rng.normal(size=3) * 3
        w = rng.normal(size=3) * 0.1
        norm_max = float(rng.choice([math.inf, 1.5]))
        applied, plant, saturated = (np.asarray(v).ravel() for v in function(u, u_max, norm_max, w))
        expected, sat = _saturate_numpy(u, u_max, norm_max, mode is Saturation.CLIP)
        assert np.max(np.abs(applied - expected)) < 1e-12 and bool(saturated[0]) == sat
        assert np.all(np.abs(applied) <= u_max)  # never exceeds, not even by rounding
        assert np.linalg.norm(applied) <= norm_max * (1 + 4 * np.finfo(float).eps)
        assert np.array_equal(plant, applied + w)
        if mode is Saturation.SCALE:  # direction preserved
            assert np.linalg.norm(np.cross(applied, u)) <= 1e-12 * np.linalg.norm(u) ** 2
            assert np.dot(applied, u) > 0
        big = (np.asarray(v).ravel() for v in function(u, u_max * 1e6, 1e9, np.zeros(3)))
        assert np.array_equal(next(big), u)  # a limit that is not reached changes nothing, bit for bit


# ============================================================================ delay schedule
def test_newest_arrived_on_a_hand_written_out_of_order_pattern():
    # measurement j:  0  1  2  3  4  5  6  7
    # delay d_j:      3  1  1  4  0  2  3  0
    # arrives at:     3  2  3  7  4  7  9  7
    delays = np.array([3, 1, 1, 4, 0, 2, 3, 0])
    # k=0,1: history (D = 4: m_-4 at 0, m_-3 at 1); k=2: m_1; k=3: m_2 (m_0 arrives too, older: never used);
    # k=4..6: m_4; k=7: m_7 (m_3, m_5 arrive with it, overtaken: never used)
    expected = np.array([-4, -3, 1, 2, 4, 4, 4, 7])
    for implementation in (lambda: newest_arrived(delays, history=4)[0], lambda: used_measurements(delays, 4)):
        assert implementation().tolist() == expected.tolist()
    used, delay_used = newest_arrived(delays, history=4)
    assert delay_used.tolist() == (np.arange(8) - expected).tolist()
    assert 0 not in used and 3 not in used and 5 not in used


def test_newest_arrived_agrees_with_the_reference_and_reduces_to_a_constant_delay():
    rng = np.random.default_rng(RNG_SEED + 6)
    for _ in range(20):
        depth = int(rng.integers(0, 12))
        delays = rng.integers(0, depth + 1, size=200)
        used, delay_used = newest_arrived(delays, history=depth)
        assert np.array_equal(used, used_measurements(delays, depth))
        assert np.all(np.diff(used) >= 0) and np.all(delay_used >= 0)
        assert np.all(used >= np.arange(200) - depth)  # measurement k − D has always arrived
    used, delay_used = newest_arrived(np.full(50, 7), history=7)
    assert np.array_equal(used, np.arange(50) - 7) and np.all(delay_used == 7)
    with pytest.raises(SpecificationError, match="delays"):
        newest_arrived(np.array([0, 5]), history=3)


# ============================================================================ reference loop
PAPER_D = 500


@pytest.fixture(scope="module")
def paper_on_current():
    return simulate_batch(
        paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, tau=0.5, rule=OnCurrent(), t_final=1.5, trajectories=True
    ).runs[0]


def test_reference_with_delta_zero_reproduces_on_current(paper_on_current):
    run = paper_on_current
    ref = reference_loop(
        paper.SPACECRAFT.inertia, paper.GAIN, paper.INITIAL_STATE, rate=1000.0, t_final=1.5, delays=PAPER_D
    )
    assert np.max(np.abs(ref.sigma[0] - run.sigma)) < 1e-12
    assert np.max(np.abs(ref.omega[0] - run.omega)) < 1e-12
    assert np.max(np.abs(ref.u_applied[0] - run.u)) < 1e-12 * np.max(np.abs(run.u))
    assert ref.plant_switch_samples().tolist() == run.switch_indices.tolist() == [444]
    # the controller's logic switches when the crossing reaches it, one delay later
    assert ref.logic_switch_samples().tolist() == [444 + PAPER_D]
    assert np.max(np.linalg.norm(ref.sigma_c[0], axis=1)) <= 1.0


def test_plant_bookkeeping_changes_no_rotation():
    sensor = SensorModel(attitude_noise=0.002, rate_noise=1e-4, seed=5)
    common = dict(rate=200.0, t_final=2.5, delays=100, delta=Hysteretic.from_alpha(1.2).delta, sensors=sensor)
    short = reference_loop(paper.SPACECRAFT.inertia, paper.GAIN, paper.INITIAL_STATE, keep_short=True, **common)
    free = reference_loop(paper.SPACECRAFT.inertia, paper.GAIN, paper.INITIAL_STATE, keep_short=False, **common)
    assert short.plant_switch_count[0] >= 1 and free.plant_switch_count[0] == 0
    assert np.max(np.linalg.norm(free.sigma[0], axis=1)) > 1.0  # the free run really went long
    assert np.max(np.abs(mrp.to_dcm(short.sigma[0]) - mrp.to_dcm(free.sigma[0]))) < 1e-9
    assert short.logic_switch_samples().tolist() == free.logic_switch_samples().tolist()


def _tumbling_batch(count, omega_max, seed):
    rng = np.random.default_rng(seed)
    sigma = mrp.short(rng.normal(size=(count, 3)))
    direction = rng.normal(size=(count, 3))
    omega = direction / np.linalg.norm(direction, axis=1, keepdims=True) * rng.uniform(1.0, omega_max, (count, 1))
    return np.hstack((sigma, omega / 4))


def test_dwell_time_on_a_tumbling_batch():
    delta = 0.15
    gains = 0.05 * paper.GAIN  # slow control: the batch keeps tumbling through Φ = 180° many times
    ref = reference_loop(
        paper.SPACECRAFT.inertia,
        gains,
        _tumbling_batch(16, 5.0, 1),
        rate=100.0,
        t_final=8.0,
        delta=delta,
        delays=5,
        trajectories=False,
    )
    several = ref.logic_switch_count >= 2
    assert several.sum() >= 8
    dwell = ref.min_dwell[several] / ref.rate
    bound = 4 * delta / ref.max_omega[several]
    assert np.all(dwell >= bound)


def test_no_logic_switch_when_the_noise_stays_below_delta():
    """At rest at Φ = 180° (q₀ = 0): noise moves q₀ by at most sin(|θ|/2) <= |θ|/2 < δ."""
    x0 = np.hstack((mrp.from_principal_rotation([0.0, 0.6, 0.8], math.pi)[None], np.zeros((1, 3))))
    sensor = SensorModel(attitude_noise=0.002, seed=2)
    t_final, rate = 3.0, 200.0
    theta, _ = sensor.noise(0, 601)
    delta = 0.01
    assert np.max(np.linalg.norm(theta, axis=1)) / 2 < delta  # the premise, checked on the very samples
    kwargs = dict(rate=rate, t_final=t_final, delays=3, sensors=sensor)
    quiet = reference_loop(paper.SPACECRAFT.inertia, np.zeros((3, 6)), x0, delta=delta, **kwargs)
    assert quiet.logic_switch_count[0] == 0
    chatter = reference_loop(paper.SPACECRAFT.inertia, np.zeros((3, 6)), x0, delta=0.0, **kwargs)
    assert chatter.logic_switch_count[0] > 50  # without hysteresis the same noise flips h again and again


def test_saturation_large_limit_is_the_unsaturated_run_and_small_limit_holds():
    x0 = _tumbling_batch(4, 3.0, 3)
    kwargs = dict(rate=100.0, t_final=3.0, delays=20, delta=0.1, sensors=SensorModel(attitude_noise=0.001, seed=4))
    free = reference_loop(paper.SPACECRAFT.inertia, paper.GAIN, x0, **kwargs)
    large = reference_loop(paper.SPACECRAFT.inertia, paper.GAIN, x0, u_max=1e6, norm_max=1e7, **kwargs)
    for name in ("sigma", "omega", "u_applied", "h"):
        assert np.array_equal(getattr(large, name), getattr(free, name)), name
    assert not large.saturated.any()
    for clip in (False, True):
        small = reference_loop(
            paper.SPACECRAFT.inertia, paper.GAIN, x0, u_max=[2.0, 3.0, 4.0], norm_max=4.5, clip=clip, **kwargs
        )
        assert np.all(np.abs(small.u_applied) <= np.array([2.0, 3.0, 4.0]))
        assert np.all(np.linalg.norm(small.u_applied, axis=2) <= 4.5 * (1 + 4 * np.finfo(float).eps))
        assert np.all(small.saturated_fraction > 0.1) and np.all(small.peak_command_norm > 4.5)
        assert np.allclose(small.saturated_fraction, small.saturated.mean(axis=1))
        mode = Saturation.CLIP if clip else Saturation.SCALE
        applied = actuator_function(mode).map(small.n * 4)(
            small.u_command.reshape(-1, 3).T, np.array([2.0, 3.0, 4.0]), 4.5, np.zeros(3)
        )[0]
        assert np.max(np.abs(np.asarray(applied).T - small.u_applied.reshape(-1, 3))) < 1e-12


def test_jitter_with_equal_bounds_is_the_constant_delay_and_records_the_delay_used():
    x0 = _tumbling_batch(3, 2.0, 5)
    kwargs = dict(rate=100.0, t_final=3.0, delta=0.05, sensors=SensorModel(attitude_noise=0.003, seed=6))
    n = 301
    constant = reference_loop(paper.SPACECRAFT.inertia, paper.GAIN, x0, delays=10, **kwargs)
    equal = DelayModel.jitter(0.1, 0.1, seed=9).samples(100.0, 0, n)
    jittered = reference_loop(paper.SPACECRAFT.inertia, paper.GAIN, x0, delays=equal, **kwargs)
    for name in ("sigma", "omega", "u_applied", "h", "sigma_c"):
        assert np.array_equal(getattr(jittered, name), getattr(constant, name)), name
    assert np.all(constant.delay_used == 10)
    # real jitter: the controller's delay stays in [d_min, d_max] once the history is consumed
    model = DelayModel.jitter(0.05, 0.15, seed=9)
    d_min, d_max = model.bounds(100.0)
    varying = reference_loop(
        paper.SPACECRAFT.inertia, paper.GAIN, x0, delays=model.samples(100.0, 0, n), history=d_max, **kwargs
    )
    assert np.all(varying.delay_used <= d_max) and np.all(varying.delay_used[d_max:] >= d_min)
    assert np.array_equal(varying.used, newest_arrived(model.samples(100.0, 0, n), history=d_max)[0])
    assert len(np.unique(varying.delay_used)) > 5


def test_constant_disturbance_spins_an_uncontrolled_body_as_j_inverse_w_t():
    w = np.array([0.7, 0.0, 0.0])  # about a principal axis: ω × J ω = 0, so ω_x = w t / J_x exactly
    ref = reference_loop(paper.SPACECRAFT.inertia, np.zeros((3, 6)), np.zeros(6), rate=50.0, t_final=4.0, disturbance=w)
    t = np.arange(ref.n) / 50.0
    assert np.max(np.abs(ref.omega[0, :, 0] - w[0] * t / paper.INERTIA[0])) < 1e-13
    ramp = np.tile(w, (ref.n, 1)) * (np.arange(ref.n) % 2)[:, None]  # per-sample array: on every other sample
    varying = reference_loop(
        paper.SPACECRAFT.inertia, np.zeros((3, 6)), np.zeros(6), rate=50.0, t_final=4.0, disturbance=ramp
    )
    assert varying.omega[0, -1, 0] == pytest.approx(w[0] * (ref.n // 2) / 50.0 / paper.INERTIA[0], rel=1e-12)


# ============================================================================ builders in a loop
def _builder_loop(x0, K, *, rate, n, delta, sensor, delays, depth, actuator, disturbance):
    """A flight loop driven from Python through the CasADi builders (the pieces phase 2 compiles)."""
    dynamics = plant_model(paper.SPACECRAFT).dynamics
    x, u = ca.SX.sym("x", 6), ca.SX.sym("u", 3)
    dt = 1.0 / rate
    k1 = dynamics(x, u)
    k2 = dynamics(x + dt / 2 * k1, u)
    k3 = dynamics(x + dt / 2 * k2, u)
    k4 = dynamics(x + dt * k3, u)
    step = ca.Function("step", [x, u], [x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)])
    measure, select, act = measurement_function(), selection_function(), actuator_function(actuator.mode)
    theta, eta = sensor.noise(0, n)
    used, _ = newest_arrived(delays, history=depth)
    w_all = disturbance.samples(0, n)
    state = np.array(x0, dtype=float)
    measured = np.zeros((n, 6))
    h, c, previous = 1.0, 1.0, None
    out = dict(sigma=np.zeros((n, 3)), h=np.zeros(n), u=np.zeros((n, 3)), switched=np.zeros(n))
    for k in range(n):
        if state[0:3] @ state[0:3] >= 1:  # plant bookkeeping: short set
            state[0:3] = -state[0:3] / (state[0:3] @ state[0:3])
        out["sigma"][k] = state[0:3]
        measured[k] = np.asarray(measure(state, theta[k], eta[k], sensor.gyro_bias)[0]).ravel()
        m = measured[used[k]] if used[k] >= 0 else np.asarray(x0, dtype=float)
        previous = m[0:3] if previous is None else previous
        h_next, c_next, sigma_c, sw = select(h, c, m[0:3], previous, delta)
        h, c, previous = float(h_next), float(c_next), m[0:3]
        command = K @ np.concatenate((np.asarray(sigma_c).ravel(), m[3:6]))
        applied, plant, _ = act(command, actuator.u_max, actuator.norm_limit, w_all[k])
        out["h"][k], out["u"][k], out["switched"][k] = h, np.asarray(applied).ravel(), float(sw)
        state = np.asarray(step(state, plant)).ravel()
    return out


def test_casadi_builders_in_a_loop_match_the_reference_with_noise_saturation_jitter_and_disturbance():
    rate, t_final = 200.0, 4.0
    n = 801
    x0 = np.concatenate(
        (mrp.from_principal_rotation([0.2, 1.0, -0.3], np.radians(150.0)), np.array([1.2, 0.4, -0.3]) / 4)
    )
    sensor = SensorModel(attitude_noise=0.004, rate_noise=2e-3, gyro_bias=[1e-3, -2e-3, 5e-4], seed=12)
    jitter = DelayModel.jitter(0.05, 0.2, seed=13)
    _, d_max = jitter.bounds(rate)
    delays = jitter.samples(rate, 0, n)
    actuator = ActuatorModel([20.0, 15.0, 15.0], norm_max=25.0)
    rng = np.random.default_rng(RNG_SEED + 7)
    disturbance = Disturbance(rng.normal(size=(n, 3)) * 0.5)
    delta = Hysteretic.from_alpha(1.1).delta
    loop = _builder_loop(
        x0,
        paper.GAIN,
        rate=rate,
        n=n,
        delta=delta,
        sensor=sensor,
        delays=delays,
        depth=d_max,
        actuator=actuator,
        disturbance=disturbance,
    )
    ref = reference_loop(
        paper.SPACECRAFT.inertia,
        paper.GAIN,
        x0,
        rate=rate,
        t_final=t_final,
        delta=delta,
        delays=delays,
        history=d_max,
        sensors=sensor,
        u_max=actuator.u_max,
        norm_max=25.0,
        disturbance=disturbance.torque,
    )
    assert ref.n == n
    assert np.flatnonzero(loop["switched"]).tolist() == ref.logic_switch_samples().tolist()
    assert ref.logic_switch_count[0] >= 1 and ref.saturated.any()
    assert np.array_equal(loop["h"], ref.h[0])
    assert np.max(np.abs(loop["sigma"] - ref.sigma[0])) < 1e-12
    assert np.max(np.abs(loop["u"] - ref.u_applied[0])) < 1e-12 * np.max(np.abs(ref.u_applied))


def test_option_values_print_their_parameters_and_compare_without_raising():
    assert "0.01 rad" in str(SensorModel(attitude_noise=0.01)) and str(SensorModel()) == "SensorModel (ideal)"
    assert "|u| <= 5" in str(ActuatorModel(2.0, norm_max=5.0)) and "clip" in str(
        ActuatorModel(1.0, mode=Saturation.CLIP)
    )
    assert "jitter in [0.1, 0.2] s" in str(DelayModel.jitter(0.1, 0.2))
    assert "constant tau = 0.5 s" in str(DelayModel.constant(0.5))
    assert "3 given delays" in str(DelayModel.sequence([0.1, 0.1, 0.2], tau_min=0.1, tau_max=0.2))
    assert "constant [1, 0, 0]" in str(Disturbance([1.0, 0.0, 0.0]))
    sensor = SensorModel(gyro_bias=[1.0, 2.0, 3.0])
    assert sensor == sensor and sensor != SensorModel(gyro_bias=[1.0, 2.0, 3.0])  # eq=False: identity, never raises
    assert not sensor.gyro_bias.flags.writeable
