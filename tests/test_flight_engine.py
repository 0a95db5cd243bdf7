"""The flight loop in the compiled engine (issue 10, phase 2), against the NumPy reference loop."""

from __future__ import annotations

import itertools

import casadi as ca
import numpy as np
import pytest
from flight_reference import reference_loop

from mrpctl import OnCurrent, closed_loop_functions, mrp, paper, simulate, simulate_batch
from mrpctl.engines import scalar as _engine
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.flight import (
    ActuatorModel,
    DelayModel,
    Disturbance,
    Hysteretic,
    NoiseForm,
    Saturation,
    SensorModel,
    measurement_function,
    newest_arrived,
    newest_arrived_slice,
    raw_measurement_function,
    rotation_mrp_function,
    short_expr,
)
from mrpctl.spacecraft import Spacecraft

PAPER_D = 500
ALPHA_12 = Hysteretic.from_alpha(1.2).delta


def _tumbles(count: int, omega_max: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    sigma = mrp.short(rng.normal(size=(count, 3)))
    direction = rng.normal(size=(count, 3))
    omega = direction / np.linalg.norm(direction, axis=1, keepdims=True) * rng.uniform(1.0, omega_max, (count, 1))
    return np.hstack((sigma, omega / 4))


def _bits(values: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(values, dtype=np.float64).view(np.uint64)


def test_delta_zero_equals_on_current_states_bit_for_bit_torques_up_to_the_sign_of_zero():
    common = dict(tau=0.5, t_final=1.5)
    plant_side = simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, rule=OnCurrent(), **common)
    flight = simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, rule=Hysteretic(0.0), **common)
    assert np.array_equal(_bits(flight.sigma), _bits(plant_side.sigma))
    assert np.array_equal(_bits(flight.omega), _bits(plant_side.omega))
    # the torques are equal under ==; where their bits differ, both are zero (+0 in one, -0 in the other)
    assert np.array_equal(flight.u, plant_side.u)
    differ = _bits(flight.u) != _bits(plant_side.u)
    assert np.all(flight.u[differ] == 0.0) and np.all(np.signbit(flight.u[differ]) != np.signbit(plant_side.u[differ]))
    # the run's switches are the controller's logic switches: the crossing reaches it one delay later
    assert plant_side.switch_indices.tolist() == [444]
    assert flight.switch_indices.tolist() == [444 + PAPER_D]
    assert flight.switch_count == 1


@pytest.mark.parametrize("delta", [0.0, 0.05, ALPHA_12])
def test_engine_equals_the_reference_loop_on_the_paper_case(delta):
    run = simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, tau=0.5, rule=Hysteretic(delta), t_final=1.5)
    ref = reference_loop(
        paper.SPACECRAFT.inertia, paper.GAIN, paper.INITIAL_STATE, rate=1000.0, t_final=1.5, delta=delta, delays=PAPER_D
    )
    assert run.switch_indices.tolist() == ref.logic_switch_samples().tolist()
    assert run.switch_count == ref.logic_switch_count[0]
    assert np.max(np.abs(ref.sigma[0] - run.sigma)) < 1e-12
    assert np.max(np.abs(ref.omega[0] - run.omega)) < 1e-12
    assert np.max(np.abs(ref.u_applied[0] - run.u)) < 1e-12 * np.max(np.abs(run.u))
    assert np.max(np.abs(run.sigma)) <= 1.0  # the plant's bookkeeping keeps it short


def test_engine_equals_the_reference_loop_on_tumbles():
    delta = 0.15
    gains = 0.05 * paper.GAIN  # slow control: the tumbles pass Φ = 180° several times
    x0 = _tumbles(4, 5.0, 1)
    ref = reference_loop(paper.SPACECRAFT.inertia, gains, x0, rate=100.0, t_final=8.0, delta=delta, delays=5)
    assert np.sum(ref.logic_switch_count) >= 8  # the comparison covers many logic switches
    for i in range(len(x0)):
        run = simulate(paper.SPACECRAFT, gains, x0[i], tau=0.05, rate=100.0, rule=Hysteretic(delta), t_final=8.0)
        assert run.switch_indices.tolist() == ref.logic_switch_samples(i).tolist()
        scale = np.max(np.abs(ref.omega[i]))
        assert np.max(np.abs(ref.sigma[i] - run.sigma)) < 1e-12
        assert np.max(np.abs(ref.omega[i] - run.omega)) < 1e-12 * scale
        assert np.max(np.abs(ref.u_applied[i] - run.u)) < 1e-12 * np.max(np.abs(run.u))


def test_zero_delay_and_a_full_inertia_equal_the_reference_loop():
    craft = Spacecraft(np.array([[140.0, 4.0, -2.0], [4.0, 100.0, 3.0], [-2.0, 3.0, 80.0]]))
    gains = 0.02 * paper.GAIN
    x0 = _tumbles(1, 5.0, 9)[0]
    run = simulate(craft, gains, x0, tau=0.0, rate=100.0, rule=Hysteretic(0.1), t_final=6.0)
    ref = reference_loop(craft.inertia, gains, x0, rate=100.0, t_final=6.0, delta=0.1, delays=0)
    assert ref.logic_switch_count[0] >= 2
    assert run.switch_indices.tolist() == ref.logic_switch_samples().tolist()
    assert np.max(np.abs(ref.sigma[0] - run.sigma)) < 1e-12
    assert np.max(np.abs(ref.omega[0] - run.omega)) < 1e-12 * np.max(np.abs(ref.omega[0]))


@pytest.mark.parametrize("trajectories", [True, False])
def test_simulate_batch_equals_simulate(trajectories):
    gains = 0.05 * paper.GAIN
    x0 = _tumbles(3, 5.0, 2)
    rules = [Hysteretic(0.0), Hysteretic(0.15), Hysteretic(ALPHA_12)]
    common = dict(tau=0.05, rate=100.0, t_final=8.0)
    batch = simulate_batch(paper.SPACECRAFT, gains, x0, rule=rules, trajectories=trajectories, **common)
    for i in range(3):
        run = simulate(paper.SPACECRAFT, gains, x0[i], rule=rules[i], **common)
        assert batch.switch_count[i] == run.switch_count
        assert batch.peak_torque[i] == run.peak_torque
        assert np.array_equal(batch.max_sigma[i], run.max_sigma)
        if trajectories:
            assert batch.runs is not None
            assert np.array_equal(batch.runs[i].sigma, run.sigma)
            assert np.array_equal(batch.runs[i].u, run.u)
            assert np.array_equal(batch.runs[i].switch_indices, run.switch_indices)
    assert np.sum(batch.switch_count) >= 3


def test_slices_of_the_c_driver_give_the_same_run(monkeypatch):
    """The horizon cut into slices of 97 samples: the memory (h, c, σ̃_prev) is carried across them."""
    gains = 0.05 * paper.GAIN
    x0 = _tumbles(1, 5.0, 3)[0]
    seen: list[int] = []
    whole = simulate(paper.SPACECRAFT, gains, x0, tau=0.05, rate=100.0, rule=Hysteretic(0.15), t_final=8.0)
    monkeypatch.setattr(_engine, "SLICE_SAMPLES", 97)
    again = simulate(
        paper.SPACECRAFT,
        gains,
        x0,
        tau=0.05,
        rate=100.0,
        rule=Hysteretic(0.15),
        t_final=8.0,
        keep_every=2,
        progress=lambda done, n: seen.append(done),
    )
    assert seen[0] == 97 and seen[-1] == 801
    assert np.array_equal(again.sigma, whole.sigma[::2])
    assert again.switch_count == whole.switch_count >= 2
    assert np.array_equal(again.switch_times[: len(again.switch_times)], whole.switch_times)


def test_closed_loop_functions_of_the_flight_rule_and_the_refused_options():
    # the flight loop's Functions (their numbers against simulate: tests/test_export_flight.py)
    closed = closed_loop_functions(paper.SPACECRAFT, paper.GAIN, tau=0.5, rule=Hysteretic(0.1))
    assert set(closed.functions()) == {"dynamics", "flight_controller", "sensor", "step", "sample", "chunk"}
    with pytest.raises(SpecificationError, match="Hysteretic"):
        closed_loop_functions(paper.SPACECRAFT, paper.GAIN, tau=0.5, rule=OnCurrent(), actuator=ActuatorModel(1.0))


def test_the_virtual_machine_fallback_equals_the_compiled_engine():
    from mrpctl.engines.vm import VirtualMachineEngine

    gains = 0.05 * paper.GAIN
    x0 = _tumbles(1, 5.0, 1)[0]
    rule = Hysteretic(0.15)
    compiled = _engine.engine(paper.SPACECRAFT, rule, 5, 0.01, 1)
    assert compiled.compiled_code
    machine = VirtualMachineEngine(compiled.virtual_machine_sample(), 5, compiled.inertia, flight=True)
    outputs = []
    for found in (compiled, machine):
        outputs.append(
            found.run(
                x0,
                0.0,
                x0[None],
                gains,
                np.array(rule.parameters()),
                400,
                spacecraft=paper.SPACECRAFT,
                keep_every=1,
                workspace=found.workspace(400, switches=True),
                switch_limit=400,
            )
        )
    ref = reference_loop(paper.SPACECRAFT.inertia, gains, x0, rate=100.0, t_final=3.99, delta=0.15, delays=5)
    assert ref.logic_switch_count[0] >= 2
    for out in outputs:
        assert out.switch_indices.tolist() == ref.logic_switch_samples().tolist()
        assert np.max(np.abs(out.measurements[:, 0:3] - ref.sigma[0])) < 1e-12


# ============================================================================ step 2: actuator and disturbance
def test_a_large_limit_and_zero_disturbance_equal_the_unsaturated_run_bit_for_bit():
    common = dict(tau=0.5, t_final=1.5, rule=Hysteretic(0.05))
    free = simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, **common)
    for mode in Saturation:
        large = simulate(
            paper.SPACECRAFT,
            paper.GAIN,
            paper.INITIAL_STATE,
            actuator=ActuatorModel(1e6, norm_max=1e7, mode=mode),
            disturbance=np.zeros(3),
            **common,
        )
        assert np.array_equal(large.sigma, free.sigma)
        assert np.array_equal(large.omega, free.omega)
        assert np.array_equal(large.u, free.u)
        assert large.saturated_fraction == 0.0
        # the peak command is the largest |u_c| the controller asked for (here = the applied torque)
        assert large.peak_command is not None
        assert np.array_equal(large.peak_command[0:3], np.max(np.abs(free.u), axis=0))
        assert large.peak_command[3] == pytest.approx(np.max(np.linalg.norm(free.u, axis=1)), rel=1e-15)
    assert free.saturated_fraction == 0.0


@pytest.mark.parametrize("mode", list(Saturation))
def test_the_applied_torque_never_exceeds_a_small_limit_and_the_reference_agrees(mode):
    gains = 0.05 * paper.GAIN
    x0 = _tumbles(3, 3.0, 3)
    limit, norm = np.array([0.4, 0.3, 0.5]), 0.55
    w = np.array([0.02, -0.01, 0.015])
    ref = reference_loop(
        paper.SPACECRAFT.inertia,
        gains,
        x0,
        rate=100.0,
        t_final=6.0,
        delta=0.15,
        delays=5,
        u_max=limit,
        norm_max=norm,
        clip=mode is Saturation.CLIP,
        disturbance=w,
    )
    actuator = ActuatorModel(limit, norm_max=norm, mode=mode)
    for i in range(len(x0)):
        run = simulate(
            paper.SPACECRAFT,
            gains,
            x0[i],
            tau=0.05,
            rate=100.0,
            rule=Hysteretic(0.15),
            t_final=6.0,
            actuator=actuator,
            disturbance=Disturbance(w),
        )
        assert np.all(np.abs(run.u) <= limit)
        assert np.all(np.linalg.norm(run.u, axis=1) <= norm * (1 + 1e-15))
        assert run.saturated_fraction is not None and run.peak_command is not None
        assert 0.05 < run.saturated_fraction == ref.saturated_fraction[i]
        assert np.max(run.peak_command[0:3]) > np.max(limit)  # the command really exceeded the limit
        assert np.allclose(run.peak_command[0:3], ref.peak_command[i], rtol=1e-12, atol=0)
        assert run.peak_command[3] == pytest.approx(ref.peak_command_norm[i], rel=1e-12)
        assert run.switch_indices.tolist() == ref.logic_switch_samples(i).tolist()
        assert np.max(np.abs(ref.sigma[i] - run.sigma)) < 1e-12
        assert np.max(np.abs(ref.u_applied[i] - run.u)) < 1e-12


def test_flight_options_refuse_bad_input():
    common = dict(tau=0.0, t_final=0.1)
    with pytest.raises(SpecificationError, match="actuator, disturbance"):
        simulate(
            paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, rule=OnCurrent(), actuator=ActuatorModel(1.0), **common
        )
    with pytest.raises(SpecificationError, match="actuator"):
        simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, rule=Hysteretic(), actuator=1.0, **common)
    with pytest.raises(DimensionError, match=r"disturbance: expected shape \(n, 3\) = \(101, 3\)"):  # 101 samples
        simulate(
            paper.SPACECRAFT,
            paper.GAIN,
            paper.INITIAL_STATE,
            rule=Hysteretic(),
            disturbance=np.zeros((100, 3)),
            **common,
        )
    with pytest.raises(DimensionError, match="torque"):
        simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, rule=Hysteretic(), disturbance=[1.0, 2.0], **common)


# ============================================================================ step 3: sensor noise
NOISY = SensorModel(attitude_noise=0.01, rate_noise=2e-4, gyro_bias=[1e-4, -2e-4, 5e-5], seed=11)


def test_noise_on_the_paper_case_equals_the_reference_loop():
    """α = 1 chatters under 0.01 rad noise near Φ = 180°, α = 1.2 does not (design/flight.md)."""
    counts = {}
    for alpha in (1.0, 1.2):
        delta = Hysteretic.from_alpha(alpha).delta
        run = simulate(
            paper.SPACECRAFT,
            paper.GAIN,
            paper.INITIAL_STATE,
            tau=0.5,
            rule=Hysteretic(delta),
            t_final=2.0,
            sensor=NOISY,
        )
        ref = reference_loop(
            paper.SPACECRAFT.inertia,
            paper.GAIN,
            paper.INITIAL_STATE,
            rate=1000.0,
            t_final=2.0,
            delta=delta,
            delays=PAPER_D,
            sensors=NOISY,
        )
        assert run.switch_indices.tolist() == ref.logic_switch_samples().tolist()
        assert np.max(np.abs(ref.sigma[0] - run.sigma)) < 1e-12
        assert np.max(np.abs(ref.omega[0] - run.omega)) < 1e-12
        assert np.max(np.abs(ref.u_applied[0] - run.u)) < 1e-12 * np.max(np.abs(run.u))
        counts[alpha] = run.switch_count
    assert counts[1.0] > 10 and counts[1.2] <= 1


def test_every_option_on_tumbles_equals_the_reference_loop():
    gains = 0.05 * paper.GAIN
    x0 = _tumbles(3, 4.0, 5)
    limit, w = np.array([0.5, 0.4, 0.6]), np.array([0.01, 0.02, -0.01])
    sensor = SensorModel(attitude_noise=0.02, rate_noise=1e-3, gyro_bias=[2e-3, 0.0, -1e-3], seed=3)
    ref = reference_loop(
        paper.SPACECRAFT.inertia,
        gains,
        x0,
        rate=100.0,
        t_final=8.0,
        delta=0.1,
        delays=5,
        sensors=sensor,
        u_max=limit,
        norm_max=0.7,
        disturbance=w,
    )
    assert np.sum(ref.logic_switch_count) >= 6
    for i in range(len(x0)):
        run = simulate(
            paper.SPACECRAFT,
            gains,
            x0[i],
            tau=0.05,
            rate=100.0,
            rule=Hysteretic(0.1),
            t_final=8.0,
            actuator=ActuatorModel(limit, norm_max=0.7),
            disturbance=w,
            sensor=sensor,
        )
        assert run.switch_indices.tolist() == ref.logic_switch_samples(i).tolist()
        assert run.saturated_fraction == ref.saturated_fraction[i]
        assert np.max(np.abs(ref.sigma[i] - run.sigma)) < 1e-12
        assert np.max(np.abs(ref.omega[i] - run.omega)) < 1e-12 * np.max(np.abs(ref.omega[i]))
        assert np.max(np.abs(ref.u_applied[i] - run.u)) < 1e-12


def test_noise_is_the_same_in_any_slicing_and_on_a_rerun_and_changes_with_the_seed(monkeypatch):
    gains = 0.05 * paper.GAIN
    x0 = _tumbles(1, 5.0, 4)[0]
    sensor = SensorModel(attitude_noise=0.05, rate_noise=1e-3, seed=8)
    common = dict(tau=0.05, rate=100.0, rule=Hysteretic(0.05), t_final=8.0)
    whole = simulate(paper.SPACECRAFT, gains, x0, sensor=sensor, **common)
    again = simulate(
        paper.SPACECRAFT, gains, x0, sensor=SensorModel(attitude_noise=0.05, rate_noise=1e-3, seed=8), **common
    )
    other = simulate(
        paper.SPACECRAFT, gains, x0, sensor=SensorModel(attitude_noise=0.05, rate_noise=1e-3, seed=9), **common
    )
    monkeypatch.setattr(_engine, "SLICE_SAMPLES", 97)
    sliced = simulate(paper.SPACECRAFT, gains, x0, sensor=sensor, keep_every=3, **common)
    assert whole.switch_count >= 2
    assert np.array_equal(again.sigma, whole.sigma) and np.array_equal(again.u, whole.u)
    assert np.array_equal(sliced.sigma, whole.sigma[::3]) and np.array_equal(sliced.u, whole.u[::3])
    assert sliced.switch_count == whole.switch_count
    assert not np.array_equal(other.u, whole.u)


def test_an_ideal_sensor_is_no_sensor_bit_for_bit():
    common = dict(tau=0.5, t_final=1.5, rule=Hysteretic(0.0))
    free = simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, **common)
    ideal = simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, sensor=SensorModel(), **common)
    assert np.array_equal(ideal.sigma, free.sigma) and np.array_equal(ideal.u, free.u)
    with pytest.raises(SpecificationError, match="sensor"):
        simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, sensor=0.01, **common)


def test_simulate_batch_with_every_option_equals_simulate():
    gains = 0.05 * paper.GAIN
    x0 = _tumbles(3, 4.0, 6)
    options = dict(
        actuator=ActuatorModel([0.5, 0.4, 0.6], norm_max=0.7, mode=Saturation.CLIP),
        disturbance=[0.01, 0.0, -0.02],
        sensor=SensorModel(attitude_noise=0.02, rate_noise=1e-3, gyro_bias=[1e-3, 0.0, 0.0], seed=4),
        delay=DelayModel.jitter(0.01, 0.05, seed=3),
    )
    common = dict(tau=0.05, rate=100.0, t_final=8.0)
    rules = [Hysteretic(0.0), Hysteretic(0.1), Hysteretic(ALPHA_12)]
    for trajectories in (True, False):
        batch = simulate_batch(
            paper.SPACECRAFT, gains, x0, rule=rules, trajectories=trajectories, threads=2, **common, **options
        )
        for i in range(3):
            run = simulate(paper.SPACECRAFT, gains, x0[i], rule=rules[i], **common, **options)
            assert batch.switch_count[i] == run.switch_count
            assert batch.peak_torque[i] == run.peak_torque
            if trajectories:
                assert batch.runs is not None
                assert np.array_equal(batch.runs[i].sigma, run.sigma)
                assert np.array_equal(batch.runs[i].u, run.u)
    with pytest.raises(SpecificationError, match="flight loop only"):
        simulate_batch(paper.SPACECRAFT, gains, x0, rule=[Hysteretic(), OnCurrent(), Hysteretic()], **common, **options)


# ============================================================================ step 4: time-varying delay
def test_newest_arrived_slices_equal_the_whole_schedule():
    model = DelayModel.jitter(0.01, 0.2, seed=5)
    rate, n, depth = 100.0, 1000, 20
    whole = newest_arrived(model.samples(rate, 0, n), history=depth)[0]
    for cuts in ([0, n], [0, 1, 7, 300, 301, n], [*list(range(0, n, 33)), n]):
        newest, parts = -1 - depth, []
        for k0, k1 in itertools.pairwise(cuts):
            parts.append(newest_arrived_slice(model, rate, depth, k0, k1, newest))
            newest = int(parts[-1][-1])
        assert np.array_equal(np.concatenate(parts), whole)


def test_equal_jitter_bounds_equal_the_constant_delay_bit_for_bit():
    gains = 0.05 * paper.GAIN
    x0 = _tumbles(1, 5.0, 1)[0]
    common = dict(tau=0.05, rate=100.0, rule=Hysteretic(0.15), t_final=8.0)
    constant = simulate(paper.SPACECRAFT, gains, x0, **common)
    jitter = simulate(paper.SPACECRAFT, gains, x0, delay=DelayModel.jitter(0.05, 0.05, seed=1), **common)
    assert constant.switch_count >= 2
    assert np.array_equal(jitter.sigma, constant.sigma) and np.array_equal(jitter.u, constant.u)
    assert np.array_equal(jitter.switch_indices, constant.switch_indices)


def test_jitter_and_a_delay_sequence_equal_the_reference_loop(monkeypatch):
    gains = 0.05 * paper.GAIN
    x0 = _tumbles(2, 5.0, 2)
    rate, t_final = 100.0, 8.0
    n = 801
    sensor = SensorModel(attitude_noise=0.01, rate_noise=1e-4, seed=2)
    jitter = DelayModel.jitter(0.02, 0.12, seed=9)
    rng = np.random.default_rng(4)
    sequence = DelayModel.sequence(rng.integers(1, 13, n) / rate, tau_min=0.01, tau_max=0.12)
    monkeypatch.setattr(_engine, "SLICE_SAMPLES", 150)  # the schedule is carried across slices
    for model in (jitter, sequence):
        delays = model.samples(rate, 0, n)
        ref = reference_loop(
            paper.SPACECRAFT.inertia,
            gains,
            x0,
            rate=rate,
            t_final=t_final,
            delta=0.1,
            delays=delays,
            history=12,
            sensors=sensor,
        )
        assert np.any(np.diff(ref.used) == 0) and np.any(np.diff(ref.used) > 1)  # held and skipped measurements
        assert np.sum(ref.logic_switch_count) >= 2
        for i in range(len(x0)):
            run = simulate(
                paper.SPACECRAFT,
                gains,
                x0[i],
                tau=0.12,
                rate=rate,
                rule=Hysteretic(0.1),
                t_final=t_final,
                sensor=sensor,
                delay=model,
            )
            assert run.switch_indices.tolist() == ref.logic_switch_samples(i).tolist()
            assert np.max(np.abs(ref.sigma[i] - run.sigma)) < 1e-12
            assert np.max(np.abs(ref.u_applied[i] - run.u)) < 1e-12


def test_varying_delay_refuses_bad_input():
    common = dict(rate=100.0, t_final=1.0, rule=Hysteretic(0.1))
    x0 = paper.INITIAL_STATE
    with pytest.raises(SpecificationError, match="tau_max"):
        simulate(paper.SPACECRAFT, paper.GAIN, x0, tau=0.1, delay=DelayModel.jitter(0.01, 0.2), **common)
    with pytest.raises(SpecificationError, match="tau_min"):
        simulate(paper.SPACECRAFT, paper.GAIN, x0, tau=0.2, delay=DelayModel.jitter(0.0, 0.2), **common)
    with pytest.raises(DimensionError, match="delays"):
        short = DelayModel.sequence(np.full(50, 0.02), tau_min=0.01, tau_max=0.02)
        simulate(paper.SPACECRAFT, paper.GAIN, x0, tau=0.02, delay=short, **common)
    with pytest.raises(SpecificationError, match="flight loop only"):
        simulate(
            paper.SPACECRAFT,
            paper.GAIN,
            x0,
            tau=0.2,
            delay=DelayModel.jitter(0.01, 0.2),
            rate=100.0,
            t_final=1.0,
            rule=OnCurrent(),
        )


# ============================================================================ the noise rotation in the driver
def test_the_noise_mrp_form_is_the_rotation_vector_form_bit_for_bit():
    """measurement(x, σ(θ)) of NoiseForm.MRP, with σ(θ) from rotation_mrp_function, is measurement(x, θ) exactly."""
    rng = np.random.default_rng(11)
    n = 4000
    x = rng.normal(0.0, 0.7, (6, n))  # σ in either set (|σ| up to ~2), ω/4
    # small, moderate and large rotations (|θ| up to ~2π), and exact zeros
    theta = rng.standard_normal((3, n)) * np.repeat([1e-6, 1e-2, 0.5, 2.0], n // 4)
    theta[:, :7] = 0.0
    eta, bias = rng.normal(0, 1e-3, (3, n)), rng.normal(0, 1e-3, (3, n))
    direct = measurement_function(NoiseForm.ROTATION_VECTOR).map(n)(x, theta, eta, bias)
    rotation = rotation_mrp_function().map(n)(theta)
    staged = measurement_function(NoiseForm.MRP).map(n)(x, rotation, eta, bias)
    for a, b in zip(direct, staged, strict=True):
        assert np.array_equal(np.asarray(a).view(np.uint64), np.asarray(b).view(np.uint64))
    assert measurement_function(NoiseForm.MRP).name_in(1) == "rotation_noise_mrp"
    with pytest.raises(SpecificationError, match="NoiseForm"):
        measurement_function("mrp")  # type: ignore[arg-type]


def test_the_scalar_engine_draws_the_noise_rotation_in_its_driver_and_equals_the_sample_form(monkeypatch):
    """The scalar engine (σ(θ) per block in the driver) = the same engine with θ into the sample, bit for bit."""
    gains = 0.05 * paper.GAIN
    x0 = _tumbles(1, 5.0, 4)[0]
    sensor = SensorModel(attitude_noise=0.3, rate_noise=1e-3, gyro_bias=[1e-3, 0.0, -2e-3], seed=5)
    common = dict(tau=0.05, rate=100.0, rule=Hysteretic(0.05), t_final=8.0, sensor=sensor)
    driver = simulate(paper.SPACECRAFT, gains, x0, **common)
    monkeypatch.setattr(_engine, "_ROTATION_IN_DRIVER", False)
    _engine.clear_engines()
    try:
        sample = simulate(paper.SPACECRAFT, gains, x0, **common)
    finally:
        _engine.clear_engines()
    assert driver.switch_count >= 1
    assert np.array_equal(driver.sigma, sample.sigma) and np.array_equal(driver.u, sample.u)
    assert np.array_equal(driver.switch_indices, sample.switch_indices)


def test_the_raw_measurement_is_the_measurement_before_its_short_set_bit_for_bit():
    """x_meas = [short(x_raw[0:3]); x_raw[3:6]] exactly (the flight ring holds x_raw, the controller shortens it)."""
    rng = np.random.default_rng(12)
    n = 4000
    x = rng.normal(0.0, 0.7, (6, n))
    theta = rng.standard_normal((3, n)) * np.repeat([1e-6, 1e-2, 0.5, 2.0], n // 4)
    eta, bias = rng.normal(0, 1e-3, (3, n)), rng.normal(0, 1e-3, (3, n))
    x_meas, _ = measurement_function().map(n)(x, theta, eta, bias)
    x_raw = np.asarray(raw_measurement_function().map(n)(x, theta, eta, bias))
    sigma = ca.SX.sym("sigma", 3)
    shortened = np.asarray(ca.Function("short", [sigma], [short_expr(sigma)]).map(n)(x_raw[0:3]))
    long_set = np.sum(x_raw[0:3] ** 2, axis=0) > 1
    assert 100 < long_set.sum() < n - 100  # both sets occur
    assert np.array_equal(np.asarray(x_meas)[0:3].view(np.uint64), shortened.view(np.uint64))
    assert np.array_equal(np.asarray(x_meas)[3:6].view(np.uint64), x_raw[3:6].view(np.uint64))
