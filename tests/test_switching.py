"""Switching rules: validation, and each CasADi rule against the rule written in NumPy."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mrpctl.errors import SpecificationError
from mrpctl.switching import BoundaryLayer, DelayAware, NoSwitching, OnCurrent, OnDelayed, SwitchingRule

RULES = [NoSwitching(), OnCurrent(), OnDelayed(), BoundaryLayer(0.05), DelayAware(), DelayAware(1.2)]


def expected_switch(rule: SwitchingRule, sigma: np.ndarray, sigma_meas: np.ndarray, since: float, d: int) -> bool:
    """The rules as stated in the issue, on norms (not squared norms)."""
    current = np.linalg.norm(sigma)
    delayed = np.linalg.norm(sigma_meas)
    if isinstance(rule, NoSwitching):
        return False
    if isinstance(rule, OnCurrent):
        return bool(current >= 1.0)
    if isinstance(rule, OnDelayed):
        return bool(delayed >= 1.0)
    if isinstance(rule, BoundaryLayer):
        return bool(1.0 <= delayed <= 1.0 + rule.eps)
    if isinstance(rule, DelayAware):
        return bool(delayed >= rule.alpha and since >= d)
    raise AssertionError(rule)


@pytest.mark.parametrize("rule", RULES, ids=str)
def test_rule_function_matches_numpy(rule: SwitchingRule, rng: np.random.Generator) -> None:
    d = 7
    function = rule.function(delay_samples=d)
    assert function.name_in() == ["x", "x_meas", "memory"]
    assert function.name_out() == ["x_next", "memory_next", "switched"]
    for _ in range(300):
        x = np.concatenate((rng.normal(size=3) * rng.uniform(0.2, 1.5) / np.sqrt(3), rng.normal(size=3)))
        meas = np.concatenate((rng.normal(size=3), rng.normal(size=3)))
        meas[:3] *= rng.uniform(0.9, 1.3) / np.linalg.norm(meas[:3])
        since = float(rng.integers(0, d + 1))
        x_next, _, switched = (np.asarray(v).ravel() for v in function(x, meas, since))
        expect = expected_switch(rule, x[:3], meas[:3], since, d)
        assert bool(switched[0]) is expect
        sigma = x[:3]
        if expect:
            np.testing.assert_allclose(x_next[:3], -sigma / (sigma @ sigma), rtol=1e-15)
        else:
            np.testing.assert_array_equal(x_next[:3], sigma)
        np.testing.assert_array_equal(x_next[3:], x[3:])  # omega is never touched


def test_delay_aware_memory_counts_samples_since_the_last_switch() -> None:
    d = 3
    rule = DelayAware()
    function = rule.function(delay_samples=d)
    memory = rule.initial_memory(delay_samples=d)
    assert memory == d
    outside = np.array([1.2, 0, 0, 0, 0, 0])
    switches = []
    for _ in range(8):
        _, memory, switched = function(outside, outside, memory)
        memory = float(memory)
        switches.append(int(switched))
    # Switch, then wait until the measurement postdates the switch (k - d >= k_last).
    assert switches == [1, 0, 0, 1, 0, 0, 1, 0]


def test_delay_aware_without_delay_acts_like_a_threshold() -> None:
    function = DelayAware(1.1).function(delay_samples=0)
    x = np.array([1.05, 0, 0, 0, 0, 0])
    assert int(function(x, x, 1.0)[2]) == 0
    x[0] = 1.2
    assert int(function(x, x, 1.0)[2]) == 1


def test_hysteresis_delta() -> None:
    assert DelayAware().hysteresis_delta == 0.0
    alpha = 1.3
    assert DelayAware(alpha).hysteresis_delta == pytest.approx((alpha**2 - 1) / (alpha**2 + 1))


@pytest.mark.parametrize("eps", [0.0, -0.1, float("nan"), float("inf"), "thin"])
def test_boundary_layer_rejects_bad_eps(eps: object) -> None:
    with pytest.raises(SpecificationError, match="eps"):
        BoundaryLayer(eps)  # type: ignore[arg-type]


@pytest.mark.parametrize("alpha", [0.99, 0.0, float("nan")])
def test_delay_aware_rejects_alpha_below_one(alpha: float) -> None:
    with pytest.raises(SpecificationError, match="alpha"):
        DelayAware(alpha)


def test_rules_are_frozen_values_with_readable_text() -> None:
    rule = BoundaryLayer(0.005)
    with pytest.raises(dataclasses.FrozenInstanceError):
        rule.eps = 0.1  # type: ignore[misc]
    assert rule == BoundaryLayer(0.005) and hash(rule) == hash(BoundaryLayer(0.005))
    assert "0.005" in str(rule)
    assert "1.2" in str(DelayAware(1.2)) and "delta" in str(DelayAware(1.2))
    for each in RULES:
        assert str(each).split()[0] == type(each).__name__


def test_bad_delay_samples() -> None:
    with pytest.raises(SpecificationError, match="delay_samples"):
        OnDelayed().function(delay_samples=-1)
    with pytest.raises(SpecificationError, match="delay_samples"):
        OnDelayed().function(delay_samples=2.0)  # type: ignore[arg-type]
