"""The gravity-gradient torque in the flown plant (``simulate(..., gravity_gradient=orbit)``).

Checked against a NumPy RK4 of the rigid body written here (no mrpctl dynamics: scipy's Rotation for the
DCMs, the MRP kinematics and Euler's equations written out), against the equilibrium of a body at rest in the
Hill frame, against the gravity-gradient pitch frequency (linear and the exact pendulum period), against the
steady offset the tracking linearisation predicts for products of inertia, and the lanes against the scalar
engine bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.special import ellipk

from mrpctl import OnCurrent, Predictor, paper, simulate, simulate_batch
from mrpctl._compile import find_compiler
from mrpctl.design.tracking import tracking_linearization
from mrpctl.engines import lanes as lane_engines
from mrpctl.errors import SpecificationError
from mrpctl.estimation import Gyro, Sensors, StarTracker
from mrpctl.flight import ActuatorModel, DelayModel, Hysteretic, SensorModel
from mrpctl.guidance import CircularOrbit, NadirPointing
from mrpctl.predictor import OnPredicted
from mrpctl.simulation import _batch
from mrpctl.spacecraft import Spacecraft
from mrpctl.wheels import WheelCluster

pytestmark = pytest.mark.skipif(find_compiler() is None, reason="the compiled engine needs a C compiler")

FULL_J = np.array([[140.0, 4.0, -2.0], [4.0, 100.0, 3.0], [-2.0, 3.0, 80.0]])
#: A fast orbit (period 126 s), so that the gravity gradient is large over a short run.
FAST = CircularOrbit(orbit_rate=0.05, inclination=0.7, raan=0.4, latitude=0.3)
#: Principal inertias in the Hill axes (x radial, y along-track, z normal) with J_z > J_y > J_x: the Hill attitude
#: is passively stable under the gravity gradient (pitch for J_y > J_x, roll-yaw in the Lagrange region).
STABLE_J = (80.0, 100.0, 140.0)


# ------------------------------------------------------------------ the NumPy reference (written separately)
def _bn(sigma: np.ndarray) -> np.ndarray:
    """[BN] (passive) of the MRP σ_B/N: scipy's active matrix of the same MRP, transposed."""
    return Rotation.from_mrp(sigma).as_matrix().T


def _in_plane(inclination: float, raan: float) -> tuple[np.ndarray, np.ndarray]:
    """ê₁, ê₂ of the orbit plane: the first two columns of R_z(Ω) R_x(i) (scipy, intrinsic Z-X)."""
    frame = Rotation.from_euler("ZX", [raan, inclination]).as_matrix()
    return frame[:, 0], frame[:, 1]


def _reference_run(
    inertia: np.ndarray,
    gain: np.ndarray,
    x0: np.ndarray,
    *,
    d: int,
    rate: float,
    n_samples: int,
    substeps: int,
    orbit: tuple[float, float, float, float] | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(σ_k, ω_k, u_k) of the delayed loop u_k = K [short(σ_{k−d}); ω_{k−d}/4] (constant history x0) on the
    rigid body J ω̇ = −ω × Jω + u + 3n² r̂_B × J r̂_B, σ̇ = ¼[(1 − σ²)I + 2[σ×] + 2σσᵀ]ω, RK4 with ``substeps``
    substeps, the MRP kept in the short set at each sample; ``orbit`` = (n, i, Ω, u₀) or None (no torque)."""
    j_inv = np.linalg.inv(inertia)
    h = 1.0 / rate
    dt = h / substeps
    if orbit is not None:
        n_orbit, inclination, raan, u0 = orbit
        e1, e2 = _in_plane(inclination, raan)

    def torque(sigma: np.ndarray, t: float) -> np.ndarray:
        if orbit is None:
            return np.zeros(3)
        r_n = math.cos(u0 + n_orbit * t) * e1 + math.sin(u0 + n_orbit * t) * e2
        r_b = _bn(sigma) @ r_n
        return 3.0 * n_orbit**2 * np.cross(r_b, inertia @ r_b)

    def derivative(state: np.ndarray, u: np.ndarray, t: float) -> np.ndarray:
        sigma, omega = state[0:3], state[3:6]
        s2 = sigma @ sigma
        sigma_dot = 0.25 * ((1.0 - s2) * omega + 2.0 * np.cross(sigma, omega) + 2.0 * sigma * (sigma @ omega))
        omega_dot = j_inv @ (-np.cross(omega, inertia @ omega) + u + torque(sigma, t))
        return np.concatenate((sigma_dot, omega_dot))

    def short(sigma: np.ndarray) -> np.ndarray:
        s2 = sigma @ sigma
        return -sigma / s2 if s2 >= 1.0 else sigma

    state = np.concatenate((x0[0:3], 4.0 * x0[3:6]))
    sigmas, omegas, torques = np.empty((n_samples, 3)), np.empty((n_samples, 3)), np.empty((n_samples, 3))
    for k in range(n_samples):
        state[0:3] = short(state[0:3])
        sigmas[k], omegas[k] = state[0:3], state[3:6]
        if k >= d:
            seen = np.concatenate((short(sigmas[k - d]), omegas[k - d] / 4.0))
        else:
            seen = np.concatenate((short(x0[0:3]), x0[3:6]))
        u = gain @ seen
        torques[k] = u
        t = k * h
        for j in range(substeps):
            t0 = t + j * dt
            k1 = derivative(state, u, t0)
            k2 = derivative(state + dt / 2 * k1, u, t0 + dt / 2)
            k3 = derivative(state + dt / 2 * k2, u, t0 + dt / 2)
            k4 = derivative(state + dt * k3, u, t0 + dt)
            state = state + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return sigmas, omegas, torques


def _relative(got: np.ndarray, want: np.ndarray) -> float:
    """The largest relative difference of the rows (|Δ| / |want| at each sample)."""
    return float(np.max(np.linalg.norm(got - want, axis=1) / np.linalg.norm(want, axis=1)))


@pytest.mark.parametrize(
    ("inertia", "closed", "substeps"),
    [(FULL_J, False, 1), (FULL_J, False, 3), (FULL_J, True, 1), (np.diag([140.0, 100.0, 80.0]), True, 2)],
)
def test_the_plant_equals_a_numpy_rk4_with_the_gravity_gradient(inertia, closed, substeps):
    """A free tumble (K = 0) and the delayed closed loop (Hysteretic(0): the short set of σ(t − τ)), 20 s at 50 Hz
    on the fast inclined orbit: every sample to 1e-12 relative; the torque changes the run by far more."""
    spacecraft = Spacecraft(inertia)
    gain = np.asarray(paper.GAIN) if closed else np.zeros((3, 6))
    x0 = np.array([0.3, -0.5, 0.6, 0.02, -0.03, 0.015]) if closed else np.array([0.2, -0.4, 0.5, 0.01, 0.02, -0.03])
    rate, t_final, tau = 50.0, 20.0, 0.2 if closed else 0.0
    run = simulate(
        spacecraft, gain, x0, tau=tau, rule=Hysteretic(0.0), t_final=t_final, rate=rate, substeps=substeps,
        gravity_gradient=FAST,
    )  # fmt: skip
    orbit = (FAST.orbit_rate, FAST.inclination, FAST.raan, FAST.latitude)
    count = len(run.t)
    d = round(tau * rate)
    sigma, omega, u = _reference_run(inertia, gain, x0, d=d, rate=rate, n_samples=count, substeps=substeps, orbit=orbit)
    assert _relative(run.sigma, sigma) < 1e-12
    assert _relative(run.omega, omega) < 1e-12
    if closed:
        assert _relative(run.u, u) < 1e-12
    _, free_omega, _ = _reference_run(inertia, gain, x0, d=d, rate=rate, n_samples=count, substeps=substeps, orbit=None)
    assert _relative(run.omega, free_omega) > 1e-3  # the torque matters in these runs
    plain = simulate(spacecraft, gain, x0, tau=tau, rule=Hysteretic(0.0), t_final=t_final, rate=rate, substeps=substeps)
    assert _relative(plain.omega, free_omega) < 1e-12  # and None is the plant without it


def _hill_start(orbit: CircularOrbit, pitch: float) -> np.ndarray:
    """x0 of a body at rest in the Hill frame turned by ``pitch`` about the orbit normal (its z axis)."""
    hn = Rotation.from_mrp(NadirPointing(orbit).samples([0.0])[0, 0:3]).as_matrix().T  # [HN] at t = 0
    bh = Rotation.from_rotvec([0.0, 0.0, pitch]).as_matrix().T  # [BH]: the passive rotation about ẑ_H
    sigma = Rotation.from_matrix((bh @ hn).T).as_mrp()
    return np.concatenate((sigma, [0.0, 0.0, orbit.orbit_rate / 4.0]))  # ω_B/N = n ĥ = n ẑ_B


def _hill_angles(run, orbit: CircularOrbit) -> np.ndarray:
    """(len(t), 3): the body's rotation vector relative to the Hill frame ([BH] = [BN][HN]ᵀ), rad."""
    hn = np.swapaxes(orbit.hill_dcm(run.t), 1, 2)  # [NH]
    bn = Rotation.from_mrp(np.array(run.sigma)).as_matrix().transpose(0, 2, 1)
    return Rotation.from_matrix(np.swapaxes(bn @ hn, 1, 2)).as_rotvec()  # the active rotation of [BH]ᵀ


def test_a_body_at_rest_in_the_hill_frame_with_principal_axes_aligned_stays_there():
    """J diagonal, x radial, y along-track, z normal: r̂_B = x̂, J r̂_B ∥ r̂_B, no gravity-gradient torque, and ω = n ẑ
    is a principal axis: the body turns with the Hill frame (two orbits, K = 0). J_z > J_y > J_x (the Lagrange
    region: stable in pitch and in roll-yaw, so that round-off is not amplified)."""
    spacecraft = Spacecraft(STABLE_J)
    x0 = _hill_start(FAST, 0.0)
    run = simulate(
        spacecraft, np.zeros((3, 6)), x0, tau=0.0, rule=Hysteretic(0.0), t_final=2 * FAST.period, rate=100.0,
        gravity_gradient=FAST,
    )  # fmt: skip
    assert np.max(np.abs(_hill_angles(run, FAST))) < 1e-12  # rad, after 250 s (measured 2.0e-14)
    assert np.max(np.abs(run.omega[:, 2] - FAST.orbit_rate)) == 0.0  # no pitch torque at all
    assert np.max(np.abs(run.omega[:, 0:2])) < 1e-14  # rad/s; measured 4.5e-16, round-off carried for 2 orbits
    # the first sample's rate change is the torque of a round-off attitude error: 3n² ΔJ · 1e-16 rad over h
    h = 1.0 / 100.0
    bound = 3.0 * FAST.orbit_rate**2 * 60.0 * 1e-16 * h / 80.0
    assert np.max(np.abs(run.omega[1, 0:2])) < bound
    # the same body turned 0.01 rad in pitch feels the torque J_z θ̈ = 3n²(J_x − J_y) sin θ cos θ at once
    turned = simulate(
        spacecraft, np.zeros((3, 6)), _hill_start(FAST, 0.01), tau=0.0, rule=Hysteretic(0.0), t_final=1.0, rate=100.0,
        gravity_gradient=FAST,
    )  # fmt: skip
    jx, jy, jz = STABLE_J
    expected = 3.0 * FAST.orbit_rate**2 * (jx - jy) * math.sin(0.01) * math.cos(0.01) / jz * h
    assert turned.omega[1, 2] - FAST.orbit_rate == pytest.approx(expected, rel=1e-6)


def _period(t: np.ndarray, angle: np.ndarray) -> float:
    """The mean period of ``angle``(t) from its zero crossings, two a period (linear interpolation)."""
    at = np.flatnonzero(np.signbit(angle[:-1]) != np.signbit(angle[1:]))
    crossings = t[at] - angle[at] * (t[at + 1] - t[at]) / (angle[at + 1] - angle[at])
    assert len(crossings) >= 4
    return float(2.0 * (crossings[-1] - crossings[0]) / (len(crossings) - 1))


@pytest.mark.parametrize("pitch", [1e-3, 0.3])
def test_a_pitch_offset_oscillates_at_the_gravity_gradient_pitch_frequency(pitch):
    """About the orbit normal (body z) J_z θ̈ = 3n²(J_x − J_y) sin θ cos θ: for J_y > J_x a pendulum in 2θ of
    ω_p = n √(3 (J_y − J_x)/J_z), period (4/ω_p) K(sin² θ₀); the linearisation's pitch block has ±i ω_p."""
    spacecraft = Spacecraft(STABLE_J)
    run = simulate(
        spacecraft, np.zeros((3, 6)), _hill_start(FAST, pitch), tau=0.0, rule=Hysteretic(0.0), t_final=700.0,
        rate=20.0, gravity_gradient=FAST,
    )  # fmt: skip
    angles = _hill_angles(run, FAST)
    assert np.max(np.abs(angles[:, 0:2])) < 1e-12  # planar: roll and yaw stay 0
    assert np.max(np.abs(angles[:, 2])) == pytest.approx(pitch, rel=1e-9)
    jx, jy, jz = STABLE_J
    omega_p = FAST.orbit_rate * math.sqrt(3.0 * (jy - jx) / jz)
    exact = 4.0 / omega_p * ellipk(math.sin(pitch) ** 2)
    measured = _period(run.t, angles[:, 2])
    assert measured == pytest.approx(exact, rel=1e-10)  # measured 5e-12 (1e-3 rad), 4e-13 (0.3 rad)
    if pitch > 0.1:  # the amplitude's correction is resolved: the linear period is off by about θ₀²/4
        assert abs(measured * omega_p / (2 * math.pi) - 1.0) > 0.01
    else:
        assert measured == pytest.approx(2 * math.pi / omega_p, rel=1e-6)
    # the same frequency from the tracking linearisation (pitch: the z block of A, ẋ = A x with K = 0)
    linear = tracking_linearization(spacecraft, np.zeros((3, 6)), NadirPointing(FAST), feedforward=False)
    pitch_block = np.asarray(linear.A)[np.ix_([2, 5], [2, 5])]
    assert np.sort(np.linalg.eigvals(pitch_block).imag) == pytest.approx([-omega_p, omega_p], rel=1e-12)


def test_products_of_inertia_leave_the_offset_the_linearisation_predicts():
    """Nadir pointing with the paper's gain and feedforward, J with products of inertia (500 km): the gravity
    gradient's unbalanced torque holds the error at x = (A + A_d)⁻¹ B L_unbalanced (the linear steady state);
    without the torque (or with a J diagonal in the Hill axes) the error stays at rounding."""
    orbit = CircularOrbit.from_altitude(500e3, inclination=1.2, raan=0.5)
    reference = NadirPointing(orbit)
    rows = reference.samples([0.0])[0]
    rate, t_final = 200.0, 120.0
    results = {}
    for name, inertia, gravity in (("full", FULL_J, orbit), ("free", FULL_J, None), ("diagonal", paper.INERTIA, orbit)):
        spacecraft = Spacecraft(inertia)
        x0 = np.concatenate((rows[0:3], Rotation.from_mrp(rows[0:3]).as_matrix().T @ rows[3:6] / 4.0))
        run = simulate(
            spacecraft, paper.GAIN, x0, tau=0.5, rule=Hysteretic(0.0), t_final=t_final, rate=rate,
            reference=reference, feedforward=True, gravity_gradient=gravity, keep_every=100,
        )  # fmt: skip
        rn = Rotation.from_mrp(reference.samples(run.t)[:, 0:3])
        sigma_br = (rn.inv() * Rotation.from_mrp(np.array(run.sigma))).as_mrp()  # the active form of [BR] = [BN][RN]ᵀ
        results[name] = (spacecraft, sigma_br[-1], np.max(np.abs(sigma_br[-10:] - sigma_br[-1])))
    spacecraft, final, drift = results["full"]
    linear = tracking_linearization(spacecraft, paper.GAIN, reference, feedforward=True)
    predicted = np.linalg.solve(linear.A + linear.A_d, linear.B @ linear.unbalanced_torque)[0:3]
    assert np.linalg.norm(predicted) > 1e-8  # an offset worth measuring
    assert drift < 1e-4 * np.linalg.norm(final)  # settled
    assert np.linalg.norm(final - predicted) < 1e-6 * np.linalg.norm(predicted)  # measured 2.3e-9
    assert np.linalg.norm(results["free"][1]) < 1e-13
    assert np.linalg.norm(results["diagonal"][1]) < 1e-13


def _bits(a, b) -> bool:
    a, b = np.atleast_1d(np.asarray(a, dtype=float)), np.atleast_1d(np.asarray(b, dtype=float))
    return a.shape == b.shape and np.array_equal(a.view(np.uint8), b.view(np.uint8))


_FIELDS = ("switch_count", "first_switch_time", "sign_flips", "settling_time", "diverged", "max_sigma", "peak_torque")


@pytest.mark.parametrize("case", ["regulation", "tracking", "limits"])
def test_the_lanes_fly_the_gravity_gradient_as_the_scalar_engine_bit_for_bit(case):
    """Dispersed runs (per-run δ, 11 runs: two batches of W = 8, one padded) with a noisy biased sensor, on the
    fast orbit, regulating, tracking its Hill frame with feedforward, or with saturating torque limits, a constant
    disturbance and a jittered delay: lanes = scalar engine = simulate, every metric's bits."""
    tracking = case == "tracking"
    more = {}
    if case == "limits":
        more = dict(
            actuator=ActuatorModel([0.5, 0.4, 0.6], norm_max=0.7), disturbance=[0.01, 0.02, -0.01],
            delay=DelayModel.jitter(0.04, 0.1, seed=4),
        )  # fmt: skip
    rng = np.random.default_rng(5)
    x0 = np.hstack((rng.normal(size=(11, 3)) * 0.4, rng.normal(size=(11, 3)) * 0.02))
    rules = [Hysteretic(delta) for delta in np.linspace(0.0, 0.2, len(x0))]
    sensor = SensorModel(attitude_noise=1e-3, rate_noise=1e-4, gyro_bias=[1e-4, 0.0, -2e-4], seed=9)
    options = dict(
        tau=0.1, rate=50.0, rule=rules, t_final=30.0, sensor=sensor, gravity_gradient=NadirPointing(FAST), threads=2,
        **({"reference": NadirPointing(FAST), "feedforward": True} if tracking else {}), **more,
    )  # fmt: skip
    spacecraft = Spacecraft(FULL_J)
    lanes = simulate_batch(spacecraft, paper.GAIN, x0, **options)
    assert any(key[-1] == "gravity" for key in lane_engines._ENGINES)
    _batch._LANES = False
    try:
        scalar = simulate_batch(spacecraft, paper.GAIN, x0, **options)
    finally:
        _batch._LANES = True
    for name in _FIELDS + (("saturated_fraction", "peak_command") if more else ()):
        assert _bits(getattr(lanes, name), getattr(scalar, name)), name
    if more:
        assert np.all(np.asarray(lanes.saturated_fraction) > 0.0)
    single = {key: value for key, value in options.items() if key not in ("rule", "threads")}
    one = simulate(spacecraft, paper.GAIN, x0[4], rule=rules[4], keep_every=None, **single)
    assert _bits(one.max_sigma, lanes.max_sigma[4]) and _bits(one.peak_torque, lanes.peak_torque[4])
    plain = simulate_batch(spacecraft, paper.GAIN, x0, **{k: v for k, v in options.items() if k != "gravity_gradient"})
    assert not np.array_equal(plain.max_sigma, lanes.max_sigma)  # the torque is in the lanes' runs


def test_bad_gravity_gradient_options_are_refused_naming_the_parameter():
    x0 = np.array([0.1, 0.0, 0.0, 0.0, 0.0, 0.0])
    common = dict(tau=0.0, t_final=1.0, rate=10.0)
    with pytest.raises(SpecificationError, match=r"gravity_gradient must be a mrpctl\.guidance\.CircularOrbit"):
        simulate(paper.SPACECRAFT, paper.GAIN, x0, rule=Hysteretic(0.0), gravity_gradient=0.05, **common)
    with pytest.raises(SpecificationError, match=r"gravity_gradient: .*flight loop only.*Hysteretic"):
        simulate(paper.SPACECRAFT, paper.GAIN, x0, rule=OnCurrent(), gravity_gradient=FAST, **common)
    with pytest.raises(SpecificationError, match="gravity_gradient: the predictor"):
        simulate(
            paper.SPACECRAFT, paper.GAIN, x0, rule=OnPredicted(1.0), predictor=Predictor(model=paper.SPACECRAFT),
            gravity_gradient=FAST, **common,
        )  # fmt: skip
    with pytest.raises(SpecificationError, match="gravity_gradient: not options of the estimated loop"):
        simulate(
            paper.SPACECRAFT, paper.GAIN, x0, rule=Hysteretic(0.0), gravity_gradient=FAST, **common,
            sensors=Sensors(StarTracker(noise=1e-4, rate=10.0, latency=0.0), Gyro(rate_noise=1e-5, bias_walk=1e-7)),
        )  # fmt: skip
    with pytest.raises(SpecificationError, match=r"gravity_gradient: .*flight loop only"):
        simulate_batch(paper.SPACECRAFT, paper.GAIN, x0, rule=OnCurrent(), gravity_gradient=FAST, **common)
    wheels = WheelCluster(np.eye(3), 1e-2, 1.0, 1e3)
    for run in (simulate, simulate_batch):
        with pytest.raises(SpecificationError, match="gravity_gradient: the wheel cluster"):
            run(paper.SPACECRAFT, paper.GAIN, x0, rule=Hysteretic(0.0), wheels=wheels, gravity_gradient=FAST, **common)


def test_the_virtual_machine_fallback_flies_the_gravity_gradient_as_the_compiled_engine():
    """Without a C compiler the same sample runs in CasADi's virtual machine (its sample counter gives t_k too)."""
    from mrpctl.engines.scalar import engine
    from mrpctl.engines.vm import VirtualMachineEngine
    from mrpctl.loop.options import gravity_gradient_options

    spacecraft = Spacecraft(FULL_J)
    rule = Hysteretic(0.0)
    x0 = np.array([0.2, -0.4, 0.5, 0.01, 0.02, -0.03])
    compiled = engine(spacecraft, rule, 5, 0.02, 2, gravity_gradient=True)
    assert compiled.compiled_code
    machine = VirtualMachineEngine(compiled.virtual_machine_sample(), 5, compiled.inertia, flight=True)
    options = gravity_gradient_options(FAST, rule, None, period=0.02, substeps=2)
    outputs = []
    for found in (compiled, machine):
        outputs.append(
            found.run(
                x0,
                0.0,
                x0[None],
                np.asarray(paper.GAIN),
                np.array(rule.parameters()),
                600,
                spacecraft=spacecraft,
                keep_every=1,
                workspace=found.workspace(600, switches=True),
                switch_limit=600,
                flight_options=options,
            )
        )
    sigma, omega, _ = _reference_run(
        FULL_J, np.asarray(paper.GAIN), x0, d=5, rate=50.0, n_samples=600, substeps=2,
        orbit=(FAST.orbit_rate, FAST.inclination, FAST.raan, FAST.latitude),
    )  # fmt: skip
    for out in outputs:
        assert _relative(out.measurements[:, 0:3], sigma) < 1e-12
        assert _relative(4.0 * out.measurements[:, 3:6], omega) < 1e-12
    with pytest.raises(ValueError, match="flight_options: this engine takes 20 flight constants"):
        compiled.run(
            x0, 0.0, x0[None], np.asarray(paper.GAIN), np.array(rule.parameters()), 10, spacecraft=spacecraft,
            keep_every=1, workspace=compiled.workspace(10, switches=True),
        )  # fmt: skip
