"""Issue 9 defects and streaming: engine cache keys, substeps bound, stop at divergence,
slices (bit-identical, interruptible), memory (estimate and refusal, bounded buffers),
keep_every, peak torque, per-run spacecraft, result.plot delegation.

References: full runs (every sample kept) for the decimated and metrics-only runs, the
unsliced run for the sliced one, separate simulate() calls for the batch, the kept
torque array for the peak torque, OnDelayed for a user rule with the same condition.
"""

from __future__ import annotations

import dataclasses
import threading
import tracemalloc
from typing import Any

import casadi as ca
import numpy as np
import pytest

import mrpctl
from mrpctl import paper, plots
from mrpctl.engines import scalar as _engine
from mrpctl.errors import SpecificationError
from mrpctl.simulation import MAX_SUBSTEPS, SimulationResult, _budget, _simulate, simulate, simulate_batch
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import BoundaryLayer, DelayAware, OnDelayed, SwitchingRule

SC = paper.SPACECRAFT
X0 = np.asarray(paper.INITIAL_STATE, dtype=float)
UNSTABLE = np.hstack((np.zeros((3, 3)), 2000.0 * np.eye(3)))  # positive rate feedback: omega explodes


def _same_run(a: SimulationResult, b: SimulationResult) -> None:
    for name in ("t", "sigma", "omega", "u", "switch_indices", "switch_times", "sign_flips"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    for name in ("max_sigma", "peak_torque", "settling_time", "diverged", "switch_count", "samples"):
        assert getattr(a, name) == getattr(b, name), name


# ------------------------------------------------------------------ engine cache key
class Threshold(SwitchingRule):
    """A user's rule: switch when |σ(m_{k−d})| >= threshold, the threshold a plain attribute."""

    def __init__(self, threshold: float) -> None:
        self.threshold = threshold

    def _condition(self, sigma: Any, sigma_meas: Any, memory: Any, parameters: Any, d: int) -> Any:
        return ca.dot(sigma_meas, sigma_meas) >= self.threshold**2


def test_user_rule_with_an_attribute_gets_its_own_engine() -> None:
    arguments: dict[str, Any] = dict(tau=0.5, t_final=20.0)
    wide = simulate(SC, paper.GAIN, X0, rule=Threshold(1.5), **arguments)
    unit = simulate(SC, paper.GAIN, X0, rule=Threshold(1.0), **arguments)  # main: the engine of Threshold(1.5)
    reference = simulate(SC, paper.GAIN, X0, rule=OnDelayed(), **arguments)  # the same condition, built in
    assert reference.switch_count > 100
    _same_run(unit, reference)
    assert wide.switch_count != unit.switch_count


def test_built_in_rules_share_an_engine_whatever_their_parameters() -> None:
    period = 1e-3
    first = _engine.engine(SC, BoundaryLayer(0.005), 20, period, 1)
    assert _engine.engine(SC, BoundaryLayer(0.2), 20, period, 1) is first
    assert _engine.engine(SC, DelayAware(1.2), 20, period, 1) is _engine.engine(SC, DelayAware(), 20, period, 1)
    assert _engine.engine(SC, OnDelayed(), 20, period, 1) is not first


# ------------------------------------------------------------------ substeps bound
def test_substeps_is_bounded() -> None:
    with pytest.raises(SpecificationError, match=rf"substeps must be <= {MAX_SUBSTEPS}.*raise rate"):
        simulate(SC, paper.GAIN, X0, tau=0.0, rule=OnDelayed(), t_final=1.0, substeps=1000)
    with pytest.raises(SpecificationError, match="substeps"):
        simulate_batch(SC, paper.GAIN, X0, tau=0.0, rule=OnDelayed(), t_final=1.0, substeps=MAX_SUBSTEPS + 1)
    assert mrpctl.loop.check_substeps(MAX_SUBSTEPS) == MAX_SUBSTEPS


# ------------------------------------------------------------------ divergence stops the run
def test_a_diverging_run_stops_at_the_first_divergence(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(_engine, "SLICE_SAMPLES", 50)
    seen: list[int] = []
    run = simulate(
        SC, UNSTABLE, X0, tau=0.0, rule=OnDelayed(), t_final=30.0, progress=lambda done, n: seen.append(done)
    )
    n = 30001
    assert run.diverged and run.samples < n // 10
    assert len(run.t) == run.samples and np.all(np.isfinite(run.sigma))
    assert seen[-1] == run.samples  # the last slice ended at the diverging sample: nothing after it ran
    assert len(seen) == -(-run.samples // 50)


# ------------------------------------------------------------------ slices
def test_tiny_slices_give_the_same_bits(monkeypatch: pytest.MonkeyPatch) -> None:
    cases: list[dict[str, Any]] = [
        dict(tau=0.02, rule=OnDelayed(), t_final=3.0),
        dict(tau=0.0, rule=DelayAware(), t_final=2.0, keep_every=3),
        dict(tau=0.05, rule=BoundaryLayer(0.01), t_final=2.0, history="zero-input", substeps=2),
    ]
    whole = [simulate(SC, paper.GAIN, X0, **case) for case in cases]
    batch = simulate_batch(SC, paper.GAIN, [X0, -X0], tau=0.02, rule=OnDelayed(), t_final=2.0, trajectories=True)
    monkeypatch.setattr(_engine, "SLICE_SAMPLES", 7)  # slices of 7 (3 with two substeps) samples: cuts everywhere
    for case, reference in zip(cases, whole, strict=True):
        _same_run(simulate(SC, paper.GAIN, X0, **case), reference)
    sliced = simulate_batch(SC, paper.GAIN, [X0, -X0], tau=0.02, rule=OnDelayed(), t_final=2.0, trajectories=True)
    for a, b in zip(sliced.runs or (), batch.runs or (), strict=True):
        _same_run(a, b)
    np.testing.assert_array_equal(sliced.switch_count, batch.switch_count)


def test_keyboard_interrupt_from_progress_stops_a_long_run() -> None:
    calls: list[int] = []

    def interrupt(done: int, total: int) -> None:
        calls.append(done)
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):  # 10^7 samples; one slice runs
        simulate(SC, paper.GAIN, X0, tau=0.5, rule=OnDelayed(), t_final=1e4, keep_every=None, progress=interrupt)
    assert calls == [_engine.SLICE_SAMPLES]


def test_keyboard_interrupt_stops_a_batch_and_its_workers() -> None:
    before = threading.active_count()
    calls: list[tuple[int, int]] = []

    def interrupt(done: int, total: int) -> None:
        calls.append((done, total))
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        simulate_batch(
            SC, paper.GAIN, [X0, -X0, X0], tau=0.5, rule=OnDelayed(), t_final=1e4, threads=2, progress=interrupt
        )
    assert len(calls) == 1 and calls[0][0] < calls[0][1] == 3 * 10_000_001
    assert threading.active_count() == before  # the workers saw the stop flag and ended


# ------------------------------------------------------------------ memory
def test_a_run_that_would_not_fit_is_refused_up_front() -> None:
    with pytest.raises(
        SpecificationError, match=r"t_final = 100000 s with keep_every = 1 needs about 12 GB.*keep_every"
    ):
        simulate(SC, paper.GAIN, X0, tau=0.5, rule=OnDelayed(), t_final=1e5, memory_limit=4e9)
    with pytest.raises(SpecificationError, match=r"1000 runs \(their kept samples.*memory_limit"):
        simulate_batch(
            SC, paper.GAIN, np.tile(X0, (1000, 1)), tau=0.5, rule=OnDelayed(), t_final=100.0, trajectories=True,
            memory_limit=1e8,
        )  # fmt: skip
    # the way out: every 1000th sample is about 10 MB (+ at most 17 MB of switch instants)
    assert _budget.run_bytes(100_000_001, 1000) < 3e7
    assert _budget.run_bytes(100_000_001, None) <= _budget.SWITCH_LIMIT * 16
    assert _budget.memory_limit_bytes(None) > 0


def test_a_long_delay_stores_one_history_column() -> None:
    tracemalloc.start()
    try:
        long = simulate(SC, paper.GAIN, X0, tau=1e5, rule=OnDelayed(), t_final=1.0)  # d = 10^8 > n
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 20e6  # main: the whole 6 x 10^8 history, 4.8 GB
    # no measurement arrives before t = 1 s for any d > n: the same arithmetic as d = 2000
    _same_run(dataclasses.replace(long, tau=2.0, delay_samples=2000), simulate(
        SC, paper.GAIN, X0, tau=2.0, rule=OnDelayed(), t_final=1.0
    ))  # fmt: skip
    assert np.all(long.u == long.u[0])


def test_a_batch_without_trajectories_allocates_per_worker_not_per_run() -> None:
    x0 = np.tile(X0, (2000, 1))
    simulate_batch(SC, paper.GAIN, x0[:2], tau=0.5, rule=OnDelayed(), t_final=0.01)  # compile outside the trace
    tracemalloc.start()
    try:
        batch = simulate_batch(SC, paper.GAIN, x0, tau=0.5, rule=OnDelayed(), t_final=0.01, threads=2)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert len(batch) == 2000
    assert peak < 6e6  # main: a 6 x 500 history block per run up front, 48 MB


# ------------------------------------------------------------------ keep_every
@pytest.fixture(scope="module")
def full_run() -> SimulationResult:
    return simulate(SC, paper.GAIN, X0, tau=0.5, rule=OnDelayed(), t_final=20.0)


@pytest.mark.parametrize("every", [2, 7, 1000, 30000])
def test_decimated_arrays_are_the_full_arrays_sliced(full_run: SimulationResult, every: int) -> None:
    run = simulate(SC, paper.GAIN, X0, tau=0.5, rule=OnDelayed(), t_final=20.0, keep_every=every)
    for name in ("t", "sigma", "omega", "u"):
        np.testing.assert_array_equal(getattr(run, name), getattr(full_run, name)[::every], err_msg=name)
    np.testing.assert_array_equal(run.switch_indices, full_run.switch_indices)  # the instants stay exact
    assert run.switch_count == full_run.switch_count > 1000
    assert (run.max_sigma, run.peak_torque, run.settling_time) == (
        full_run.max_sigma,
        full_run.peak_torque,
        full_run.settling_time,
    )
    assert f"every {every}th sample kept" in str(run)


def test_metrics_only_run_has_the_full_run_statistics(full_run: SimulationResult) -> None:
    run = simulate(SC, paper.GAIN, X0, tau=0.5, rule=OnDelayed(), t_final=20.0, keep_every=None)
    assert run.t.shape == (0,) and run.sigma.shape == (0, 3) and run.u.shape == (0, 3)
    np.testing.assert_array_equal(run.switch_indices, full_run.switch_indices)
    np.testing.assert_array_equal(run.sign_flips, full_run.sign_flips)
    for name in ("max_sigma", "peak_torque", "settling_time", "switch_count", "first_switch_time", "last_switch_time"):
        assert getattr(run, name) == getattr(full_run, name), name
    assert "metrics only" in str(run)
    diverged = simulate(SC, UNSTABLE, X0, tau=0.0, rule=OnDelayed(), t_final=30.0, keep_every=None)
    assert (
        diverged.diverged
        and diverged.samples == simulate(SC, UNSTABLE, X0, tau=0.0, rule=OnDelayed(), t_final=30.0).samples
    )


def test_switch_list_is_bounded_but_the_count_stays_exact(
    full_run: SimulationResult, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(_simulate, "SWITCH_LIMIT", 3)
    run = simulate(SC, paper.GAIN, X0, tau=0.5, rule=OnDelayed(), t_final=20.0, keep_every=10)
    np.testing.assert_array_equal(run.switch_indices, full_run.switch_indices[:3])
    assert run.switch_count == full_run.switch_count
    assert run.last_switch_time == full_run.last_switch_time == full_run.switch_times[-1]


def test_keep_every_is_checked() -> None:
    bad: Any
    for bad in (0, -3, 1.5, True):
        with pytest.raises(SpecificationError, match="keep_every"):
            simulate(SC, paper.GAIN, X0, tau=0.0, rule=OnDelayed(), t_final=1.0, keep_every=bad)


# ------------------------------------------------------------------ peak torque, per-run spacecraft, plot
def test_peak_torque_is_the_largest_torque_component(full_run: SimulationResult) -> None:
    assert full_run.peak_torque == np.max(np.abs(full_run.u)) > 0
    batch = simulate_batch(SC, paper.GAIN, [X0, 0.1 * X0], tau=0.5, rule=OnDelayed(), t_final=20.0)
    assert batch.peak_torque[0] == full_run.peak_torque
    assert 0 < batch.peak_torque[1] < batch.peak_torque[0]
    assert "peak torque" in str(full_run) and "peak torque" in str(batch)


def test_batch_with_a_spacecraft_per_run_matches_separate_runs() -> None:
    crafts = [
        Spacecraft(np.diag([140.0, 100.0, 80.0])),
        Spacecraft(np.array([[120.0, 5.0, -3.0], [5.0, 100.0, 2.0], [-3.0, 2.0, 90.0]])),
    ]
    x1 = np.array([0.5, 0.2, -0.1, 0.05, 0.0, 0.02])
    batch = simulate_batch(crafts, paper.GAIN, [X0, x1], tau=0.02, rule=DelayAware(), t_final=3.0, trajectories=True)
    assert batch.spacecraft == tuple(crafts)
    for i, (craft, x0) in enumerate(zip(crafts, [X0, x1], strict=True)):
        single = simulate(craft, paper.GAIN, x0, tau=0.02, rule=DelayAware(), t_final=3.0)
        _same_run(batch.runs[i], single)  # type: ignore[index]
        assert batch.max_sigma[i] == single.max_sigma and batch.switch_count[i] == single.switch_count
    with pytest.raises(mrpctl.DimensionError, match="spacecraft"):
        simulate_batch(crafts, paper.GAIN, [X0, x1, X0], tau=0.02, rule=DelayAware(), t_final=1.0)
    with pytest.raises(SpecificationError, match=r"spacecraft\[1\]"):
        simulate_batch([SC, "SC"], paper.GAIN, X0, tau=0.02, rule=DelayAware(), t_final=1.0)  # type: ignore[list-item]


def test_plot_delegates_to_the_plots_module(full_run: SimulationResult, monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[tuple[Any, dict[str, Any]]] = []

    def recorder(answer: str) -> Any:
        def plot(result: Any, **kwargs: Any) -> str:
            calls.append((result, kwargs))
            return answer

        return plot

    monkeypatch.setattr(plots, "plot_response", recorder("figure"))
    monkeypatch.setattr(plots, "plot_batch", recorder("batch"), raising=False)
    assert full_run.plot(title="x") == "figure"
    batch = simulate_batch(SC, paper.GAIN, X0, tau=0.5, rule=OnDelayed(), t_final=0.1)
    assert batch.plot(bins=3) == "batch"
    assert calls == [(full_run, {"title": "x"}), (batch, {"bins": 3})]


def test_mrpctl_simulate_is_the_function() -> None:
    assert mrpctl.simulate is simulate and mrpctl.simulate_batch is simulate_batch
    assert callable(mrpctl.simulate) and mrpctl.simulation.SimulationResult is SimulationResult


def test_one_engine_serves_every_spacecraft_of_a_layout() -> None:
    period = 1e-3
    a, b = Spacecraft(np.array([140.0, 100.0, 80.0])), Spacecraft(np.array([30.0, 25.0, 20.0]))
    full = Spacecraft(np.array([[120.0, 5.0, -3.0], [5.0, 100.0, 2.0], [-3.0, 2.0, 90.0]]))
    assert _engine.engine(a, OnDelayed(), 20, period, 1) is _engine.engine(b, OnDelayed(), 20, period, 1)
    assert _engine.engine(full, OnDelayed(), 20, period, 1) is not _engine.engine(a, OnDelayed(), 20, period, 1)
    # the inertia is an input: the small spacecraft's run is its own, not the first one's
    x1 = np.array([0.5, 0.2, -0.1, 0.05, 0.0, 0.02])
    runs = [simulate(craft, paper.GAIN, x1, tau=0.02, rule=OnDelayed(), t_final=2.0) for craft in (a, b)]
    assert not np.array_equal(runs[0].sigma, runs[1].sigma)


def test_concatenated_batches_equal_one_batch() -> None:
    """BatchResult.concatenate of two batches equals the batch of all their runs, field by field."""
    import dataclasses

    from mrpctl import BatchResult, DelayAware, paper, simulate_batch

    x0 = np.array([[0.93, 0, 0, 0.46 / 4, 0, 0], [0.5, 0.2, 0, 0, 0.1, 0], [0.1, 0, 0.3, 0, 0, 0.2]])
    run = dict(tau=0.05, rule=DelayAware(), t_final=2.0, rate=100.0)
    whole = simulate_batch(paper.SPACECRAFT, paper.GAIN, x0, **run)
    parts = BatchResult.concatenate(
        [
            simulate_batch(paper.SPACECRAFT, paper.GAIN, x0[:2], **run),
            simulate_batch(paper.SPACECRAFT, paper.GAIN, x0[2:], **run),
        ]
    )
    for f in dataclasses.fields(BatchResult):
        a, b = getattr(parts, f.name), getattr(whole, f.name)
        if isinstance(a, np.ndarray):
            assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), f.name
        else:
            assert a == b, f.name
    with pytest.raises(SpecificationError, match="batches"):
        BatchResult.concatenate([whole, simulate_batch(paper.SPACECRAFT, paper.GAIN, x0, **{**run, "t_final": 1.0})])
