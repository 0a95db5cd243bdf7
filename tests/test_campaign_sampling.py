"""Campaign specification and sampling: uniform on SO(3), replayable from (seed, index), valid inertias."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from scipy import stats
from scipy.spatial.transform import Rotation

from mrpctl import mrp
from mrpctl.campaign.sampling import (
    haar_angle_cdf,
    quaternion_to_mrp,
    run_inputs,
    uniform_quaternions,
)
from mrpctl.campaign.spec import parse_campaign
from mrpctl.errors import SpecificationError

BASE = {
    "name": "t",
    "count": 20000,
    "seed": 11,
    "tau": 0.5,
    "rate": 1000.0,
    "t_final": 0.1,
    "spacecraft": {"inertia": [140.0, 100.0, 80.0]},
    "gains": {"k_sigma": -70.11, "k_omega": -163.08},
    "rule": {"type": "delay-aware"},
}


def spec_with(**dispersions: dict) -> dict:
    data = copy.deepcopy(BASE)
    data["dispersions"] = dispersions
    return data


def _ks_uniform_angle(sigma: np.ndarray, low: float = 0.0, high: float = math.pi) -> float:
    angle = 4.0 * np.arctan(np.linalg.norm(sigma, axis=1))
    f_low, f_high = haar_angle_cdf(low), haar_angle_cdf(high)
    return float(stats.kstest(angle, lambda t: (haar_angle_cdf(t) - f_low) / (f_high - f_low)).pvalue)


@pytest.fixture(scope="module")
def uniform_sigma() -> np.ndarray:
    """10^4 attitudes of a campaign dispersed over the whole of SO(3)."""
    return run_inputs(parse_campaign(spec_with(attitude={"angle_deg": [0.0, 180.0]})), 0, 10000).sigma0


def test_attitudes_uniform_on_so3_angle_density(uniform_sigma):
    """10^4 sampled rotations: principal angle against the Haar CDF (θ − sin θ)/π (KS), not the uniform CDF."""
    sigma = uniform_sigma
    assert np.all(np.linalg.norm(sigma, axis=1) <= 1.0 + 1e-15)  # short set
    assert _ks_uniform_angle(sigma) > 1e-3
    angle = 4.0 * np.arctan(np.linalg.norm(sigma, axis=1))
    # the KS test has power: the same angles are far from a uniform angle on [0, π]
    assert stats.kstest(angle, stats.uniform(0, math.pi).cdf).pvalue < 1e-10


def test_attitudes_axis_isotropic(uniform_sigma):
    """Axes ê of the sampled rotations: mean ≈ 0, second moment ≈ I/3, each component uniform on [−1, 1]."""
    sigma = uniform_sigma
    axis = sigma / np.linalg.norm(sigma, axis=1, keepdims=True)
    n = len(axis)
    assert np.all(np.abs(axis.mean(axis=0)) < 4.0 / math.sqrt(3 * n))  # 4 standard errors
    moment = axis.T @ axis / n
    assert np.allclose(moment, np.eye(3) / 3.0, atol=4.0 * math.sqrt(4.0 / 45.0 / n))
    for i in range(3):  # Archimedes: a component of a uniform unit vector is uniform on [-1, 1]
        assert stats.kstest(axis[:, i], stats.uniform(-1, 2).cdf).pvalue > 1e-3


def test_quaternion_sampler_matches_scipy_rotation_conventions():
    """σ from our quaternions is scipy's short MRP of the same rotation (scalar-last there), and mrpctl.mrp agrees."""
    normals = np.random.default_rng(5).standard_normal((500, 4))
    q = uniform_quaternions(normals)
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0, rtol=1e-15, atol=0)
    assert np.all(q[:, 0] >= 0)
    sigma = quaternion_to_mrp(q)
    rotation = Rotation.from_quat(np.column_stack((q[:, 1:], q[:, :1])))  # scipy: [x, y, z, w]
    assert np.allclose(sigma, rotation.as_mrp(), rtol=0, atol=1e-14)
    assert np.allclose(sigma, mrp.from_quaternion(q), rtol=0, atol=1e-15)
    # scipy's own uniform sampler has the same angle law (an independent cross-check of the density)
    reference = Rotation.random(10000, random_state=3).magnitude()
    ours = 4.0 * np.arctan(
        np.linalg.norm(
            quaternion_to_mrp(uniform_quaternions(np.random.default_rng(9).standard_normal((10000, 4)))), axis=1
        )
    )
    assert stats.ks_2samp(ours, reference).pvalue > 1e-3


def test_principal_angle_range_keeps_haar_density():
    spec = parse_campaign(spec_with(attitude={"angle_deg": [150.0, 179.0]}))
    sigma = run_inputs(spec, 0, 10000).sigma0
    angle = 4.0 * np.arctan(np.linalg.norm(sigma, axis=1))
    assert angle.min() >= math.radians(150.0) - 1e-12 and angle.max() <= math.radians(179.0) + 1e-12
    assert _ks_uniform_angle(sigma, math.radians(150.0), math.radians(179.0)) > 1e-3


def test_run_inputs_depend_on_seed_and_index_only():
    """Run i alone equals run i of a block; other dispersions do not shift its attitude; seeds differ."""
    dispersions = {
        "attitude": {},
        "omega": {"magnitude": [0.1, 0.2]},
        "tau": {"range": [0.3, 0.6], "step": 0.1},
        "gains": {"scale": [0.9, 1.1]},
        "inertia": {"axis_tolerance": 0.05, "product_tolerance": 2.0},
    }
    spec = parse_campaign(spec_with(**dispersions))
    block = run_inputs(spec, 100, 140)
    for j, i in enumerate(range(100, 140)):
        one = run_inputs(spec, i)
        for name in ("sigma0", "omega0", "inertia", "tau", "gain_scale"):
            assert np.array_equal(getattr(one, name)[0], getattr(block, name)[j])
    attitude_only = run_inputs(parse_campaign(spec_with(attitude={})), 100, 140)
    assert np.array_equal(attitude_only.sigma0, block.sigma0)
    other_seed = parse_campaign({**spec_with(**dispersions), "seed": 12})
    assert not np.array_equal(run_inputs(other_seed, 100, 140).sigma0, block.sigma0)
    rate = np.linalg.norm(block.omega0, axis=1)
    assert np.all((rate >= 0.1 - 1e-15) & (rate <= 0.2 + 1e-15))
    assert set(np.round(block.tau * 1000).astype(int)) <= {300, 400, 500, 600}
    assert np.all((block.gain_scale >= 0.9) & (block.gain_scale <= 1.1))


def test_dispersed_inertias_are_physically_valid():
    spec = parse_campaign(spec_with(inertia={"axis_tolerance": 0.6, "product_tolerance": 30.0}))
    inputs = run_inputs(spec, 0, 300)
    for J in inputs.inertia:
        assert np.array_equal(J, J.T)
        eig = np.linalg.eigvalsh(J)
        assert eig[0] > 0 and eig[2] <= eig[0] + eig[1]
    assert np.any(inputs.inertia_attempts > 1)  # wide tolerances do reject (and redraw)
    diag = np.diagonal(inputs.inertia, axis1=1, axis2=2) / np.array([140.0, 100.0, 80.0])
    assert np.all(np.abs(diag - 1.0) <= 0.6 + 1e-12)


def test_impossible_inertia_tolerance_is_refused():
    # a thin rod base (triangle inequality at its limit) with axis tolerances: almost always invalid
    data = spec_with(inertia={"axis_tolerance": 0.0, "product_tolerance": 50.0})
    data["spacecraft"] = {"inertia": [1.0, 1.0, 2.0]}
    with pytest.raises(SpecificationError, match="inertia"):
        run_inputs(parse_campaign(data), 0, 50)


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"colour": 1}, "unknown key 'colour'"),
        ({"dispersions": {"attitude": {"angles": [0, 1]}}}, "unknown key 'angles'"),
        ({"dispersions": {"spin": {}}}, "unknown key 'spin'"),
        ({"count": 0}, "count must be >= 1"),
        ({"count": True}, "count must be an integer"),
        ({"dispersions": {"tau": {"range": [0.3, 0.6], "step": 0.00015}}}, "tau.step"),
        ({"dispersions": {"attitude": {"angle_deg": [0, 200]}}}, "angle_deg"),
        ({"dispersions": {"inertia": {"axis_tolerance": 1.5}}}, "axis_tolerance"),
        ({"dispersions": {"omega": {"magnitude": [0.3, 0.1]}}}, "omega.magnitude"),
    ],
)
def test_bad_specifications_name_the_key(change, match):
    data = {**copy.deepcopy(BASE), **change}
    with pytest.raises(SpecificationError, match=match):
        parse_campaign(data)


def test_missing_seed_is_an_error():
    data = copy.deepcopy(BASE)
    del data["seed"]
    with pytest.raises(SpecificationError, match="seed"):
        parse_campaign(data)


def test_example_campaigns_parse():
    from pathlib import Path

    from mrpctl.campaign import load_campaign

    folder = Path(__file__).resolve().parents[1] / "examples" / "campaigns"
    files = sorted(folder.glob("*.toml"))
    assert files
    for path in files:
        spec = load_campaign(path)
        assert spec.count >= 1 and str(spec)
