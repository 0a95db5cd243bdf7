"""Per-sample records of flight runs (issue 10): h_k, σ_c,k and the delay used, against the NumPy reference."""

from __future__ import annotations

import numpy as np
import pytest
from flight_reference import _tumbles, reference_loop

from mrpctl import OnCurrent, paper, simulate, simulate_batch
from mrpctl.engines import scalar as _engine
from mrpctl.flight import ActuatorModel, DelayModel, Hysteretic, SensorModel

GAINS = 0.05 * paper.GAIN


def test_records_with_every_option_equal_the_reference_loop() -> None:
    x0 = _tumbles(3, 4.0, 5)
    limit, w = np.array([0.5, 0.4, 0.6]), np.array([0.01, 0.02, -0.01])
    sensor = SensorModel(attitude_noise=0.02, rate_noise=1e-3, gyro_bias=[2e-3, 0.0, -1e-3], seed=3)
    ref = reference_loop(
        paper.SPACECRAFT.inertia,
        GAINS,
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
    assert ref.h is not None and ref.sigma_c is not None
    assert np.sum(ref.logic_switch_count) >= 4  # h takes both values (this set of tumbles: 1, 4, 0)
    for i in range(len(x0)):
        run = simulate(
            paper.SPACECRAFT,
            GAINS,
            x0[i],
            tau=0.05,
            rate=100.0,
            rule=Hysteretic(0.1),
            t_final=8.0,
            actuator=ActuatorModel(limit, norm_max=0.7),
            disturbance=w,
            sensor=sensor,
        )
        assert run.logic is not None and run.sigma_c is not None and run.delay_used is not None
        assert run.logic.tolist() == ref.h[i].tolist()
        assert np.max(np.abs(run.sigma_c - ref.sigma_c[i])) < 1e-12
        assert run.delay_used.tolist() == ref.delay_used.tolist() == [5] * ref.n
        # h flips exactly at the recorded switches
        assert (np.flatnonzero(np.diff(run.logic)) + 1).tolist() == run.switch_indices.tolist()


@pytest.mark.parametrize("keep_every", [1, 3])
def test_records_with_a_varying_delay_equal_the_reference_loop(
    keep_every: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    x0 = _tumbles(2, 5.0, 2)
    rate, t_final, n = 100.0, 8.0, 801
    sensor = SensorModel(attitude_noise=0.01, rate_noise=1e-4, seed=2)
    rng = np.random.default_rng(4)
    models = (
        DelayModel.jitter(0.02, 0.12, seed=9),
        DelayModel.sequence(rng.integers(1, 13, n) / rate, tau_min=0.01, tau_max=0.12),
    )
    monkeypatch.setattr(_engine, "SLICE_SAMPLES", 150)  # the schedule is carried across slices
    for model in models:
        ref = reference_loop(
            paper.SPACECRAFT.inertia,
            GAINS,
            x0,
            rate=rate,
            t_final=t_final,
            delta=0.1,
            delays=model.samples(rate, 0, n),
            history=12,
            sensors=sensor,
        )
        assert ref.h is not None and ref.sigma_c is not None
        assert len(set(ref.delay_used[12:].tolist())) > 3  # the delay used varies
        for i in range(len(x0)):
            run = simulate(
                paper.SPACECRAFT,
                GAINS,
                x0[i],
                tau=0.12,
                rate=rate,
                rule=Hysteretic(0.1),
                t_final=t_final,
                sensor=sensor,
                delay=model,
                keep_every=keep_every,
            )
            assert run.logic is not None and run.sigma_c is not None and run.delay_used is not None
            assert run.delay_used.tolist() == ref.delay_used[::keep_every].tolist()
            assert run.logic.tolist() == ref.h[i][::keep_every].tolist()
            assert np.max(np.abs(run.sigma_c - ref.sigma_c[i][::keep_every])) < 1e-12
            assert len(run.logic) == len(run.t) == len(run.sigma)


def test_zero_delta_records_the_on_current_measurement() -> None:
    """δ = 0: σ_c,k = short(σ(t_k − τ)) (OnCurrent's recorded σ, d samples earlier), h flips once, one delay late."""
    common = dict(tau=0.5, rate=1000.0, t_final=1.5)
    plain = simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, rule=OnCurrent(), **common)
    run = simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, rule=Hysteretic(0.0), **common)
    assert run.logic is not None and run.sigma_c is not None
    d = run.delay_samples
    np.testing.assert_allclose(run.sigma_c[d:], plain.sigma[:-d], rtol=0, atol=1e-15)
    np.testing.assert_allclose(run.sigma_c[:d], np.broadcast_to(paper.INITIAL_STATE[0:3], (d, 3)), rtol=0, atol=1e-15)
    assert np.max(np.linalg.norm(run.sigma_c, axis=1)) <= 1.0
    assert (np.flatnonzero(np.diff(run.logic)) + 1).tolist() == [944] == [plain.switch_indices[0] + d]


def test_records_are_absent_where_they_do_not_apply() -> None:
    common = dict(tau=0.05, rate=100.0, t_final=1.0)
    for result in (
        simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, rule=OnCurrent(), **common),
        simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, rule=Hysteretic(0.1), keep_every=None, **common),
    ):
        assert result.logic is None and result.sigma_c is None and result.delay_used is None
    batch = simulate_batch(
        paper.SPACECRAFT,
        paper.GAIN,
        _tumbles(2, 1.0, 1),
        rule=Hysteretic(0.1),
        trajectories=True,
        keep_every=4,
        **common,
    )
    assert batch.runs is not None
    for i, run in enumerate(batch.runs):
        alone = simulate(
            paper.SPACECRAFT, paper.GAIN, _tumbles(2, 1.0, 1)[i], rule=Hysteretic(0.1), keep_every=4, **common
        )
        assert run.logic is not None and alone.logic is not None and run.sigma_c is not None
        assert run.logic.tobytes() == alone.logic.tobytes() and run.sigma_c.tobytes() == alone.sigma_c.tobytes()
        assert not run.logic.flags.writeable and run.logic.shape == run.t.shape


def test_the_memory_estimate_counts_the_records() -> None:
    from mrpctl.errors import SpecificationError
    from mrpctl.simulation import _budget

    n, d = 201, 5
    common = dict(tau=0.05, rate=100.0, t_final=2.0, keep_every=1)
    plain = _budget.run_bytes(n, 1) + _budget.workspace_bytes(n, d, 1)
    flight = _budget.run_bytes(n, 1, flight=True) + _budget.workspace_bytes(n, d, 1)
    run = simulate(
        paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, rule=Hysteretic(0.1), memory_limit=flight, **common
    )
    assert run.logic is not None and run.sigma_c is not None and run.delay_used is not None
    assert run.command is not None
    assert run.sigma_measured is not None and run.omega_measured is not None
    held = run.logic.nbytes + run.sigma_c.nbytes + run.delay_used.nbytes + run.command.nbytes
    held += run.sigma_measured.nbytes + run.omega_measured.nbytes
    assert flight - plain >= 2 * held  # the records as computed and their read-only copies
    simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, rule=OnCurrent(), memory_limit=plain, **common)
    with pytest.raises(SpecificationError, match="memory_limit"):
        simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, rule=Hysteretic(0.1), memory_limit=plain, **common)
