"""The certified region of attraction of the delayed saturated loop (mrpctl.design.attraction), checked by the
nonlinear compiled loop on its boundary."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mrpctl import Spacecraft, simulate_batch
from mrpctl.design.attraction import AttractionStatus, attraction_blocks, certify_attraction, linear_radius
from mrpctl.errors import SpecificationError
from mrpctl.flight import ActuatorModel, Hysteretic
from mrpctl.flight.steering import SteeringLaw
from mrpctl.model import gain_from_pd

CUBESAT = Spacecraft(np.diag([0.2, 0.25, 0.15]))
K = gain_from_pd(CUBESAT, [-(2.224**2)] * 3, [-2 * 2.224] * 3)  # synthesize_pd(sc, 0.2, zeta=1)'s omega_n
ACTUATOR = ActuatorModel(5e-3)


@pytest.fixture(scope="module")
def region() -> object:
    return certify_attraction(CUBESAT, K, 0.2, ACTUATOR)


def test_the_cubesat_region_is_certified_in_physical_units(region: object) -> None:
    assert region.status is AttractionStatus.CERTIFIED and region.certified
    assert region.torque == 5e-3 and 0.0 < region.level <= 1.0
    # the linear region of K alone (|K x| <= U) is about |sigma| < 1e-3 (0.23 deg): the certificate reaches beyond
    assert math.radians(0.1) < region.max_angle < math.radians(5.0)
    assert 1e-3 < region.max_rate < 0.05
    assert all(margin >= 1e-9 for name, margin in region.margins if name != "domain")
    text = str(region)
    assert "certified" in text and "deg of the target" in text and "rad/s" in text


def test_the_certificate_blocks_recomputed_independently(region: object) -> None:
    """The returned P, M and the level make the domain condition hold: |G x| <= U is what the sector needs, and
    x0 in the ellipsoid has V(0) <= c, with x0ᵀ P x0 <= V(0) (S is positive definite)."""
    assert region.P is not None and region.matrix is not None
    assert np.all(np.linalg.eigvalsh(region.matrix - region.P) > 0)  # M - P = tau S > 0
    inside = region.contains(np.zeros(6))
    assert bool(inside[0])
    far = np.array([1.0, 0, 0, 0, 0, 0])
    assert not bool(region.contains(far)[0])


def _boundary(region: object, runs: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(runs, 6))
    quadratic = np.einsum("ni,ij,nj->n", v, region.matrix, v)
    return v * (0.999 * np.sqrt(region.level / quadratic))[:, None]


def test_no_run_started_on_the_boundary_fails(region: object) -> None:
    """200 runs on the ellipsoid's boundary (scaled by 0.999) with the nonlinear compiled loop (MRP kinematics,
    gyroscopic torque, 1000 Hz sample and hold, the 5 mN m limit): every one settles, none diverges."""
    x0 = _boundary(region, 200, seed=5)
    assert np.all(region.contains(x0))
    batch = simulate_batch(CUBESAT, K, x0, tau=0.2, rule=Hysteretic(0.0), t_final=30.0, actuator=ACTUATOR)
    times = np.asarray(batch.settling_time)
    assert np.all(np.isfinite(times)), np.sum(~np.isfinite(times))
    assert np.all(times < 29.0)


def test_the_sampled_basin_is_larger_than_the_ellipsoid(region: object) -> None:
    """The certificate is conservative, not wrong: along 8 boundary directions the loop still settles in 60 s from
    10 x the boundary state (design/wheels.md: min 20.5, median 52.3 over 40 directions)."""
    x0 = 10.0 * _boundary(region, 8, seed=6)
    batch = simulate_batch(CUBESAT, K, x0, tau=0.2, rule=Hysteretic(0.0), t_final=60.0, rate=200.0, actuator=ACTUATOR)
    assert np.all(np.isfinite(np.asarray(batch.settling_time)))


def test_a_loop_unstable_at_the_delay_is_not_certified() -> None:
    """omega_n tau = 1.5: the linear delayed loop is unstable (its exact delay margin is below 0.2 s), so no
    ellipsoid exists; the result says so with the solver's statuses."""
    fast = gain_from_pd(CUBESAT, [-(7.5**2)] * 3, [-2 * 7.5] * 3)
    result = certify_attraction(CUBESAT, fast, 0.2, ACTUATOR, multipliers=5)
    assert result.status in (AttractionStatus.NOT_CERTIFIED, AttractionStatus.SOLVER_FAILED)
    assert not result.certified and result.matrix is None and result.max_rate == 0.0
    assert result.solver_status != "optimal"
    assert "not certified" in str(result) or "solver failed" in str(result)
    with pytest.raises(SpecificationError, match="no ellipsoid"):
        result.contains(np.zeros(6))


def test_blocks_in_numpy_match_a_direct_lyapunov_derivative() -> None:
    """The derivative block against V̇ written out for one state: with P, S, R, Z = 0 but P = I the quadratic form
    of ζ is 2 xᵀ ẋ (the LK terms vanish) minus the sector term."""
    n = 2
    a = np.array([[0.0, 1.0], [0.0, 0.0]])
    b = np.array([[0.0], [1.0]])
    k = np.array([[-1.0, -1.5]])
    zero = np.zeros((n, n))
    blocks = attraction_blocks(a, b, k, 0.0, np.eye(n), zero, zero, np.zeros((1, n)), 2.0, 1.0)
    rng = np.random.default_rng(0)
    x, x_d, psi = rng.normal(size=n), rng.normal(size=n), rng.normal(size=1)
    zeta = np.r_[x, x_d, psi]
    xdot = a @ x + b @ (k @ x_d) - b @ psi
    sector = 2.0 * psi @ (2.0 * psi - 2.0 * k @ x_d)
    assert zeta @ blocks["derivative"] @ zeta == pytest.approx(2 * x @ xdot - sector, rel=1e-12)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: certify_attraction(CUBESAT, K, 0.0, ACTUATOR), "tau must be > 0"),
        (lambda: certify_attraction(CUBESAT, K, 0.2, 5e-3), "actuator must be"),
        (lambda: certify_attraction(CUBESAT, K, 0.2, ACTUATOR, rate_scale=-1.0), "rate_scale must be > 0"),
        (lambda: certify_attraction(CUBESAT, np.zeros((3, 5)), 0.2, ACTUATOR), "K"),
    ],
)
def test_bad_input_names_the_parameter(call: object, match: str) -> None:
    with pytest.raises((SpecificationError, ValueError), match=match):
        call()


def test_with_the_steering_law_the_certificate_covers_it() -> None:
    """With law= the ellipsoid is kept inside the attitudes where the steering law is K: the certificate is the
    steering law's too, and 100 boundary runs with the law settle."""
    law = SteeringLaw(0.1942, 0.012, 0.4248)
    radius = linear_radius(law, K)
    # the sufficient test by hand at the radius: |omega_lin| = 4 omega_n/2 |sigma| against the chord of L
    phi = 4.0 * math.atan(radius)
    assert pytest.approx(law.rate_command_limit(phi) / phi * 4.0 / (1.0 + radius**2), rel=1e-5) == 2 * 2.224
    region = certify_attraction(CUBESAT, K, 0.2, ACTUATOR, law=law)
    assert region.certified and region.steering_covered is True
    q = np.linalg.inv(region.P)[0:3, 0:3]
    assert math.sqrt(region.level * np.linalg.eigvalsh(q)[-1]) <= radius
    x0 = _boundary(region, 100, seed=7)
    batch = simulate_batch(CUBESAT, K, x0, tau=0.2, rule=Hysteretic(0.0), t_final=30.0, actuator=ACTUATOR, law=law)
    assert np.all(np.asarray(batch.settling_time) < 29.0)
