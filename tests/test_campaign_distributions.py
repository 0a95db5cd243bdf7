"""Campaign dispersions beside uniform: normal and truncated normal, checked against scipy.stats' CDFs."""

from __future__ import annotations

import copy

import numpy as np
import pytest
from scipy import stats

from mrpctl.campaign.distributions import Normal, TruncatedNormal, Uniform, parse_distribution
from mrpctl.campaign.sampling import run_inputs
from mrpctl.campaign.spec import parse_campaign
from mrpctl.errors import SpecificationError

BASE = {
    "name": "t",
    "count": 4000,
    "seed": 5,
    "tau": 0.5,
    "rate": 1000.0,
    "t_final": 0.1,
    "spacecraft": {"inertia": [140.0, 100.0, 80.0]},
    "gains": {"k_sigma": -70.11, "k_omega": -163.08},
    "rule": {"type": "hysteretic", "delta": 0.1},
}


def _spec(**dispersions: dict):
    data = copy.deepcopy(BASE)
    data["dispersions"] = dispersions
    return parse_campaign(data)


def test_a_pair_and_a_uniform_table_draw_the_same_numbers_as_the_uniform_formula():
    pair = run_inputs(_spec(gains={"scale": [0.9, 1.1]}), 0, 500).gain_scale
    table = run_inputs(_spec(gains={"scale": {"distribution": "uniform", "low": 0.9, "high": 1.1}}), 0, 500).gain_scale
    assert np.array_equal(pair, table)
    # the variates of the run's stream in the order run_inputs draws them (the gain's is the 13th
    # number of (seed, case)), through the formula a uniform dispersion always used: low + (high - low) q
    for index in range(10):
        generator = np.random.default_rng(np.random.SeedSequence(5, spawn_key=(index,)))
        generator.standard_normal(7), generator.random(), generator.standard_normal(3), generator.random(2)
        assert pair[index] == 0.9 + (1.1 - 0.9) * generator.random()


def test_normal_gain_scale_follows_the_normal_cdf():
    spec = _spec(gains={"scale": {"distribution": "normal", "mean": 1.0, "std": 0.05}})
    scale = run_inputs(spec, 0, 4000).gain_scale
    assert stats.kstest(scale, stats.norm(1.0, 0.05).cdf).pvalue > 1e-3
    # power: the same draws are far from a uniform of the same mean and spread
    assert stats.kstest(scale, stats.uniform(1.0 - 0.0866, 0.1732).cdf).pvalue < 1e-6


def test_truncated_normal_rate_stays_in_its_interval_and_follows_its_cdf():
    magnitude_law = {"distribution": "truncnorm", "mean": 0.02, "std": 0.02, "low": 0.0, "high": 0.05}
    spec = _spec(omega={"magnitude": magnitude_law})
    omega = run_inputs(spec, 0, 4000).omega0
    magnitude = np.linalg.norm(omega, axis=1)
    assert magnitude.min() >= 0.0 and magnitude.max() <= 0.05 * (1 + 1e-12)
    a, b = (0.0 - 0.02) / 0.02, (0.05 - 0.02) / 0.02
    assert stats.kstest(magnitude, stats.truncnorm(a, b, loc=0.02, scale=0.02).cdf).pvalue > 1e-3
    assert stats.kstest(magnitude, stats.uniform(0.0, 0.05).cdf).pvalue < 1e-6


def test_flight_dispersions_take_distributions():
    spec = _spec(
        actuator={"u_max": {"distribution": "truncnorm", "mean": 2.0, "std": 0.5, "low": 1.0, "high": float("inf")}},
        sensor={"rate_noise": {"distribution": "truncnorm", "mean": 1e-4, "std": 1e-4, "low": 0.0, "high": 3e-4}},
    )
    inputs = run_inputs(spec, 0, 2000)
    assert np.all(inputs.u_max >= 1.0) and np.all(np.isfinite(inputs.u_max))
    assert np.all(inputs.u_max[:, 0] == inputs.u_max[:, 1])
    assert stats.kstest(inputs.u_max[:, 0], stats.truncnorm(-2.0, np.inf, loc=2.0, scale=0.5).cdf).pvalue > 1e-3
    assert np.all((inputs.rate_noise >= 0.0) & (inputs.rate_noise <= 3e-4))


def test_each_run_depends_only_on_seed_and_index():
    spec = _spec(gains={"scale": {"distribution": "normal", "mean": 1.0, "std": 0.05}})
    assert np.array_equal(run_inputs(spec, 0, 300).gain_scale[120:130], run_inputs(spec, 120, 130).gain_scale)


@pytest.mark.parametrize(
    ("value", "message"),
    [
        (
            {"distribution": "normal", "mean": 0.02, "std": 0.01},
            r"omega.magnitude: every draw must lie in \[0, inf\).*truncnorm",
        ),
        ({"distribution": "gauss", "mean": 0.0, "std": 1.0}, r"omega.magnitude.distribution must be one of"),
        ({"distribution": "normal", "mean": 0.0}, r"missing \['std'\]"),
        ({"distribution": "normal", "mean": 0.0, "std": 1.0, "low": 0.0}, r"unknown \['low'\]"),
        ({"distribution": "truncnorm", "mean": 0.0, "std": -1.0, "low": 0.0, "high": 1.0}, r"std > 0"),
        ({"distribution": "truncnorm", "mean": 0.0, "std": 1.0, "low": 1.0, "high": 1.0}, r"low < high"),
        ({"distribution": "truncnorm", "mean": 0.0, "std": 1.0, "low": -1.0, "high": 1.0}, r"must be >= 0"),
        ({"distribution": "truncnorm", "mean": 0.0, "std": 1e-3, "low": 50.0, "high": 60.0}, r"holds no probability"),
        ({"distribution": "uniform", "low": float("nan"), "high": 1.0}, r"omega.magnitude.low"),
        ([0.1, 0.2, 0.3], r"pair \[low, high\]"),
        ("wide", r"pair \[low, high\] or a distribution table"),
    ],
)
def test_bad_distributions_name_the_parameter(value, message):
    with pytest.raises(SpecificationError, match=message):
        _spec(omega={"magnitude": value})


def test_bounded_quantities_refuse_a_support_that_crosses_their_bound():
    with pytest.raises(SpecificationError, match=r"actuator.u_max: every draw must lie in \(0, inf\) \(must be > 0\)"):
        _spec(actuator={"u_max": {"distribution": "truncnorm", "mean": 1.0, "std": 1.0, "low": 0.0, "high": 2.0}})
    with pytest.raises(SpecificationError, match=r"hysteresis.delta: every draw must lie in \[0, 1\) \(must be < 1\)"):
        _spec(hysteresis={"delta": {"distribution": "uniform", "low": 0.0, "high": 1.0}})


def test_values_and_strings():
    assert str(Uniform(0.0, 1.0)) == "uniform [0, 1]"
    assert "mean 1" in str(Normal(1.0, 0.1))
    assert str(TruncatedNormal(0.0, 1.0, 0.0, 2.0)).startswith("truncated normal")
    assert parse_distribution("x", [1.0, 2.0]) == Uniform(1.0, 2.0)
    # a variate of exactly 0 gives a finite normal draw, not -inf
    assert np.isfinite(Normal(0.0, 1.0).quantile(np.array([0.0]))[0])
