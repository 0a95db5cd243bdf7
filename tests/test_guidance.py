"""Guidance profiles (mrpctl.guidance): each against an independent computation (scipy's Rotation,
finite differences of the profile's own attitude, the orbit's geometry), and their refusals."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mrpctl import mrp
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.guidance import (
    EARTH_MU,
    EARTH_RADIUS,
    CircularOrbit,
    EigenaxisSlew,
    FileReference,
    GuidanceProfile,
    InertialPointing,
    NadirPointing,
    check_reference,
    reference_samples,
)
from mrpctl.model import gravity_gradient_expr


def _scipy_mrp(rotation: Rotation) -> np.ndarray:
    """scipy's short-set MRP of a rotation (as_mrp returns the short set)."""
    return np.asarray(rotation.as_mrp())


def _same_attitude(a: np.ndarray, b: np.ndarray) -> float:
    """Largest principal angle (rad) between attitudes a and b (rows)."""
    return float(np.max(np.abs(mrp.to_rotation_vector(mrp.subtract(a, b)))))


def _kinematic_residual(profile: GuidanceProfile, t: np.ndarray) -> float:
    """max |σ̇ (central difference of the profile's σ) − ¼ B(σ) [RN] ω_R/N| over t."""
    h = 1e-4
    now, before, after = profile.samples(t), profile.samples(t - h), profile.samples(t + h)
    difference = (after[:, 0:3] - before[:, 0:3]) / (2 * h)
    omega_r = np.einsum("nij,nj->ni", mrp.to_dcm(now[:, 0:3]), now[:, 3:6])
    return float(np.max(np.abs(difference - mrp.sigma_dot(now[:, 0:3], omega_r))))


# ------------------------------------------------------------------------------------------- inertial
def test_inertial_pointing_holds_its_attitude() -> None:
    sigma = [0.1, -0.3, 0.2]
    rows = InertialPointing(sigma).samples(np.linspace(0.0, 10.0, 11))
    assert rows.shape == (11, 9)
    np.testing.assert_array_equal(rows[:, 0:3], np.tile(sigma, (11, 1)))
    np.testing.assert_array_equal(rows[:, 3:], 0.0)
    assert "inertial pointing" in str(InertialPointing(sigma))


@pytest.mark.parametrize(
    ("value", "error", "words"),
    [
        ([0.0, 0.0, 2.0], SpecificationError, "short-set"),
        ([0.0, np.nan, 0.0], SpecificationError, "finite"),
        ([0.0, 0.0], DimensionError, "sigma"),
    ],
)
def test_inertial_pointing_refuses_bad_attitudes(value: list[float], error: type, words: str) -> None:
    with pytest.raises(error, match="sigma") as info:
        InertialPointing(value)
    assert words in str(info.value)


# ----------------------------------------------------------------------------------------------- slew
def _slew(**overrides: object) -> EigenaxisSlew:
    options: dict[str, object] = {
        "start": [0.1, 0.2, -0.1],
        "axis": [0.0, 0.6, 0.8],
        "angle": math.radians(270.0),
        "rate_limit": 0.05,
        "acceleration_limit": 0.01,
        "t_start": 5.0,
    }
    options.update(overrides)
    return EigenaxisSlew(**options)  # type: ignore[arg-type]


@pytest.mark.parametrize("angle_deg", [270.0, 10.0])  # trapezoidal and triangular
def test_slew_rate_and_acceleration_never_exceed_their_limits(angle_deg: float) -> None:
    slew = _slew(angle=math.radians(angle_deg))
    t = np.concatenate((np.linspace(0.0, slew.t_end + 5.0, 20001), [slew.t_start, slew.t_end]))
    rows = slew.samples(t)
    rate = np.linalg.norm(rows[:, 3:6], axis=1)
    accel = np.linalg.norm(rows[:, 6:9], axis=1)
    assert rate.max() <= slew.rate_limit * (1 + 1e-15)
    assert accel.max() <= slew.acceleration_limit * (1 + 1e-15)
    if angle_deg == 270.0:
        assert slew.coast_time > 0.0 and rate.max() == pytest.approx(slew.rate_limit, rel=1e-12)
    else:
        assert slew.coast_time == 0.0 and slew.peak_rate < slew.rate_limit
        assert slew.peak_rate == pytest.approx(math.sqrt(math.radians(10.0) * 0.01), rel=1e-12)
    # rest before and after; the rate integrates to the angle (trapezoid rule on a fine grid)
    assert np.all(rate[(t < slew.t_start) | (t >= slew.t_end)] == 0.0)
    theta, theta_dot, _ = slew.angle_profile(np.linspace(0.0, slew.t_end + 5.0, 200001))
    grid = np.linspace(0.0, slew.t_end + 5.0, 200001)
    assert np.trapezoid(theta_dot, grid) == pytest.approx(slew.angle, rel=1e-8)
    assert theta[-1] == slew.angle


def test_slew_attitude_matches_scipy_and_its_own_kinematics() -> None:
    slew = _slew()
    t = np.linspace(0.0, slew.t_end + 2.0, 301)
    rows = slew.samples(t)
    theta, _, _ = slew.angle_profile(t)
    # scipy: R(t) = R0 * rotation by theta about the body (start-frame) axis; add = R1 * R2 in scipy terms
    start = Rotation.from_mrp(np.array(slew.start))
    expected = np.array([_scipy_mrp(start * Rotation.from_rotvec(np.array(slew.axis) * th)) for th in theta])
    assert _same_attitude(rows[:, 0:3], expected) < 1e-12
    assert np.all(np.linalg.norm(rows[:, 0:3], axis=1) <= 1.0 + 1e-12)
    # the rate and acceleration are about the same inertial axis [R0 N]^T e
    axis_n = mrp.to_dcm(np.array(slew.start)).T @ np.array(slew.axis)
    np.testing.assert_allclose(np.cross(rows[:, 3:6], axis_n), 0.0, atol=1e-15)
    # sigma_dot of the profile's attitude agrees with its rate (away from the short-set switch)
    away = np.linalg.norm(rows[:, 0:3], axis=1) < 0.95
    assert _kinematic_residual(slew, t[away & (t > 1.0)]) < 1e-8


def test_slew_to_a_target_goes_the_short_way_and_ends_there() -> None:
    start = mrp.from_principal_rotation([1.0, 0.0, 0.0], 0.3)
    target = mrp.from_principal_rotation([0.0, 1.0, 1.0], 2.0)
    slew = EigenaxisSlew(start=start, target=target, rate_limit=0.1, acceleration_limit=0.02)
    expected_angle = np.linalg.norm(
        (Rotation.from_mrp(np.array(start)).inv() * Rotation.from_mrp(np.array(target))).as_rotvec()
    )
    assert slew.angle == pytest.approx(expected_angle, rel=1e-12)
    assert slew.angle <= math.pi
    assert _same_attitude(slew.final, target) < 1e-12
    assert "eigenaxis slew" in str(slew)


@pytest.mark.parametrize(
    ("overrides", "name"),
    [
        ({"rate_limit": 0.0}, "rate_limit"),
        ({"rate_limit": -1.0}, "rate_limit"),
        ({"acceleration_limit": 0.0}, "acceleration_limit"),
        ({"acceleration_limit": math.inf}, "acceleration_limit"),
        ({"angle": 0.0}, "angle"),
        ({"angle": math.nan}, "angle"),
        ({"axis": [0.0, 0.0, 2.0]}, "axis"),
        ({"axis": [0.0, 0.0, 0.0]}, "axis"),
        ({"start": [1.5, 0.0, 0.0]}, "start"),
        ({"t_start": -1.0}, "t_start"),
        ({"target": [0.0, 0.1, 0.0]}, "not both"),
    ],
)
def test_slew_refuses_bad_input_naming_the_parameter(overrides: dict[str, object], name: str) -> None:
    with pytest.raises(SpecificationError, match=name):
        _slew(**overrides)


def test_slew_needs_a_target_or_an_axis_and_angle() -> None:
    with pytest.raises(SpecificationError, match="target"):
        EigenaxisSlew(start=[0.0, 0.0, 0.0], rate_limit=0.1, acceleration_limit=0.1)
    with pytest.raises(SpecificationError, match="target equals start"):
        EigenaxisSlew(start=[0.1, 0.0, 0.0], target=[0.1, 0.0, 0.0], rate_limit=0.1, acceleration_limit=0.1)
    with pytest.raises(DimensionError, match="axis"):
        _slew(axis=[1.0, 0.0])


# ---------------------------------------------------------------------------------------------- orbit
def test_orbit_rate_from_altitude_and_geometry() -> None:
    orbit = CircularOrbit.from_altitude(500e3, inclination=math.radians(51.6), raan=0.4, latitude=0.3)
    assert orbit.orbit_rate == pytest.approx(math.sqrt(EARTH_MU / (EARTH_RADIUS + 500e3) ** 3), rel=1e-15)
    assert orbit.orbit_rate == pytest.approx(1.10678e-3, rel=1e-5)
    t = np.linspace(0.0, orbit.period, 97)
    r = orbit.r_hat(t)
    np.testing.assert_allclose(np.linalg.norm(r, axis=1), 1.0, rtol=1e-15)
    np.testing.assert_allclose(r @ orbit.normal, 0.0, atol=1e-15)
    # the normal is the direction of r x v (v by central differences), and the angle advances at n
    h = 1e-3
    v = (orbit.r_hat(t + h) - orbit.r_hat(t - h)) / (2 * h)
    np.testing.assert_allclose(np.cross(r, v), np.tile(orbit.orbit_rate * orbit.normal, (len(t), 1)), atol=1e-12)
    # scipy: Euler 3-1-3 (Omega, i, u) rotates the x axis onto r
    expected = Rotation.from_euler("ZXZ", [0.4, math.radians(51.6), 0.3]).apply([1.0, 0.0, 0.0])
    np.testing.assert_allclose(r[0], expected, atol=1e-15)


def test_hill_frame_rate_is_n_about_the_normal_and_closes_after_one_orbit() -> None:
    orbit = CircularOrbit(1e-3, inclination=1.0, raan=-0.7, latitude=2.5)
    nadir = NadirPointing(orbit)
    t = np.linspace(0.0, orbit.period, 400)
    rows = nadir.samples(t)
    np.testing.assert_allclose(rows[:, 3:6], np.tile(orbit.orbit_rate * orbit.normal, (len(t), 1)), rtol=0, atol=1e-18)
    np.testing.assert_array_equal(rows[:, 6:9], 0.0)
    assert _same_attitude(rows[0, 0:3], rows[-1, 0:3]) < 1e-12  # sigma_R closes after one orbit
    # the axes: x = r_hat, y = along-track (h x r), z = h; compared with scipy's DCM of sigma_RN
    dcm_rn = np.array([Rotation.from_mrp(s).as_matrix().T for s in rows[:, 0:3]])  # scipy's matrix is [NR]
    np.testing.assert_allclose(dcm_rn[:, 0], nadir.r_hat(t), atol=1e-14)
    np.testing.assert_allclose(dcm_rn[:, 2], np.tile(orbit.normal, (len(t), 1)), atol=1e-14)
    np.testing.assert_allclose(dcm_rn[:, 1], np.cross(orbit.normal, nadir.r_hat(t)), atol=1e-14)
    # the attitude turns at the rate the rows give
    assert _kinematic_residual(nadir, t[1:-1]) < 1e-10


@pytest.mark.parametrize(
    ("build", "name"),
    [
        (lambda: CircularOrbit(0.0), "orbit_rate"),
        (lambda: CircularOrbit(-1e-3), "orbit_rate"),
        (lambda: CircularOrbit(math.nan), "orbit_rate"),
        (lambda: CircularOrbit(1e-3, inclination=4.0), "inclination"),
        (lambda: CircularOrbit.from_radius(0.0), "radius"),
        (lambda: CircularOrbit.from_radius(7e6, mu=-1.0), "mu"),
        (lambda: CircularOrbit.from_altitude(-5.0), "altitude"),
        (lambda: NadirPointing(1e-3), "orbit"),  # type: ignore[arg-type]
    ],
)
def test_orbit_refuses_bad_input(build: object, name: str) -> None:
    with pytest.raises(SpecificationError, match=name):
        build()  # type: ignore[operator]


# ----------------------------------------------------------------------------------------------- file
def _rows(n: int) -> np.ndarray:
    return NadirPointing(CircularOrbit(1e-3)).samples(np.arange(n) / 10.0)


@pytest.mark.parametrize("suffix", [".csv", ".npy"])
def test_file_reference_reads_its_rows(tmp_path: object, suffix: str) -> None:
    rows = _rows(21)
    path = tmp_path / f"ref{suffix}"  # type: ignore[operator]
    if suffix == ".npy":
        np.save(path, rows)
    else:
        np.savetxt(path, rows, delimiter=",", header="sigma_RN, omega_RN_N, domega_RN_N", fmt="%.17g")
    reference = FileReference.read(path, rate=10.0, samples=21)
    np.testing.assert_array_equal(reference.samples(np.arange(21) / 10.0), rows)
    np.testing.assert_array_equal(reference.samples([0.5]), rows[5:6])
    assert "21 rows at 10 Hz" in str(reference)
    with pytest.raises(DimensionError, match=r"has 21 rows but the run needs 20"):
        FileReference.read(path, rate=10.0, samples=20)
    with pytest.raises(SpecificationError, match="sample times"):
        reference.samples([0.05])
    with pytest.raises(SpecificationError, match="sample times"):
        reference.samples([2.1])


def test_file_reference_refuses_bad_files(tmp_path: object) -> None:
    narrow = tmp_path / "narrow.csv"  # type: ignore[operator]
    np.savetxt(narrow, np.zeros((4, 6)), delimiter=",")
    with pytest.raises(DimensionError, match="6 columns"):
        FileReference.read(narrow, rate=1.0)
    long_set = _rows(4)
    long_set[2, 0:3] = [0.0, 0.0, 1.5]
    path = tmp_path / "long.npy"  # type: ignore[operator]
    np.save(path, long_set)
    with pytest.raises(SpecificationError, match=r"row 3 .*sigma_RN"):
        FileReference.read(path, rate=1.0)
    bad = _rows(4)
    bad[1, 4] = np.nan
    np.save(path, bad)
    with pytest.raises(SpecificationError, match="row 2, column 5"):
        FileReference.read(path, rate=1.0)
    with pytest.raises(SpecificationError, match="no file"):
        FileReference.read(tmp_path / "missing.csv", rate=1.0)  # type: ignore[operator]
    with pytest.raises(SpecificationError, match="rate"):
        FileReference(rows=_rows(3), rate=0.0)


# -------------------------------------------------------------------------------------------- helpers
def test_reference_samples_and_check_reference() -> None:
    slew = _slew()
    rows = reference_samples(slew, 50, 2.0)
    np.testing.assert_array_equal(rows, slew.samples(np.arange(50) / 2.0))
    assert not rows.flags.writeable
    with pytest.raises(DimensionError, match=r"reference: expected shape \(n, 9\)"):
        check_reference(np.zeros((5, 8)))
    with pytest.raises(DimensionError, match="expected 6 rows"):
        check_reference(np.zeros((5, 9)), 6)
    with pytest.raises(SpecificationError, match="finite"):
        check_reference(np.full((5, 9), np.inf))
    with pytest.raises(SpecificationError, match="profile"):
        reference_samples(np.zeros((5, 9)), 5, 1.0)  # type: ignore[arg-type]
    with pytest.raises(SpecificationError, match="samples"):
        reference_samples(slew, 0, 1.0)


# ------------------------------------------------------------------------------------ gravity gradient
def test_gravity_gradient_expression_against_numpy_and_scipy() -> None:
    rng = np.random.default_rng(7)
    sigma = ca.SX.sym("sigma", 3)
    r_hat = ca.SX.sym("r_hat", 3)
    n = ca.SX.sym("n")
    m = rng.normal(size=(3, 3))
    inertia = np.diag([140.0, 100.0, 80.0]) + 5.0 * (m + m.T)
    torque = ca.Function("gg", [sigma, r_hat, n], [gravity_gradient_expr(sigma, r_hat, n, inertia)])
    for _ in range(20):
        s = mrp.short(rng.normal(size=3))
        r = rng.normal(size=3)
        r /= np.linalg.norm(r)
        rate = 10 ** rng.uniform(-4, -2)
        # scipy's as_matrix() is [NB]: r_B = [NB]^T r_N
        r_b = Rotation.from_mrp(s).as_matrix().T @ r
        expected = 3.0 * rate**2 * np.cross(r_b, inertia @ r_b)
        np.testing.assert_allclose(np.asarray(torque(s, r, rate)).ravel(), expected, rtol=1e-12, atol=1e-18)
    # zero when r_hat is along a principal axis of a diagonal J
    diagonal = ca.Function("gg", [sigma], [gravity_gradient_expr(sigma, [1.0, 0.0, 0.0], 1e-3, np.diag([3.0, 2, 1]))])
    np.testing.assert_array_equal(np.asarray(diagonal(np.zeros(3))).ravel(), 0.0)
