"""The tracking loop against Basilisk's guidance chain (skipped without Basilisk, the optional ``basilisk`` extra).

Basilisk's tracking stack is a reference module (``inertial3D`` for a fixed target, ``hillPoint`` for the Hill
frame of the spacecraft's own orbit), ``attTrackingError`` (σ_B/R, ω_B/R, ω_R/N and ω̇_R/N in body components) and
``mrpFeedback``. Its ``controlLawType = 1`` torque, with no integral term and no known torque, is

    u = −K σ_B/R − P ω_B/R + ω × (J ω) + J (ω̇_R − ω × ω_R),

which is mrpctl's tracking law with ``feedforward=True`` and the gains [−K I, −4P I] of the paper's convention
u = K [σ; ω/4] (``interop.basilisk_mrp_feedback`` maps them). At τ = 0 with the task order of the paper cross-check
(``test_interop.py``: the spacecraft integrates to t_k first, the controller's torque of t_k is held over
[t_k, t_{k+1}]) both are the same zero-order-hold loop integrated by RK4 at the control period.

For nadir pointing Basilisk's reference is not a formula: ``hillPoint`` builds the Hill frame from the position and
velocity of the spacecraft, which Basilisk integrates in the Earth's point-mass field from the circular orbit's
initial state (μ of Basilisk's Earth, given to mrpctl's orbit too). So this also checks mrpctl's closed-form
circular orbit against an integrated one. The runs stay below |σ_B/N| = 1 (Basilisk switches the body's MRP after
an integration, mrpctl at its samples) and the tracking error below 180°.
"""

from __future__ import annotations

import numpy as np
import pytest
from basilisk_hub import simulation_and_hub

from mrpctl import simulate
from mrpctl.flight import Hysteretic
from mrpctl.guidance import CircularOrbit, InertialPointing, NadirPointing
from mrpctl.interop import basilisk_mrp_feedback
from mrpctl.model import state
from mrpctl.spacecraft import Spacecraft

INERTIA = np.diag([0.2, 0.25, 0.15])
#: Scalar gains (Basilisk's K and P act the same on every axis): u = −0.05 σ − 0.4 ω.
GAIN = np.hstack((-0.05 * np.eye(3), -1.6 * np.eye(3)))  # x = [σ; ω/4]: the rate block is 4 P
PERIOD = 0.01
#: Basilisk 2.12's Earth (``gravBodyFactory.createEarth().mu``, DE430's GM), not mrpctl's default ``EARTH_MU``
#: (JGM-3's 3.986004415e14): the orbit below is built with it, so both sides fly the same orbit.
BASILISK_EARTH_MU = 3.98600436e14


def _basilisk_tracking_run(
    x0: np.ndarray, t_final: float, *, target: np.ndarray | None = None, orbit: CircularOrbit | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """σ_B/N, ω_B/N and Basilisk's σ_B/R at every control sample of Basilisk's closed tracking loop."""
    from Basilisk.architecture import messaging  # type: ignore[import-untyped]
    from Basilisk.fswAlgorithms import attTrackingError, hillPoint, inertial3D, mrpFeedback  # type: ignore[import-untyped]
    from Basilisk.simulation import extForceTorque, simpleNav  # type: ignore[import-untyped]
    from Basilisk.utilities import macros, simIncludeGravBody  # type: ignore[import-untyped]

    gains = basilisk_mrp_feedback(GAIN)
    sim, body = simulation_and_hub(PERIOD, INERTIA, x0)
    modules: list[object] = []
    if orbit is not None:
        gravity = simIncludeGravBody.gravBodyFactory()
        earth = gravity.createEarth()
        earth.isCentralBody = True
        assert earth.mu == BASILISK_EARTH_MU
        gravity.addBodiesTo(body)
        radius = (BASILISK_EARTH_MU / orbit.orbit_rate**2) ** (1.0 / 3.0)
        hill = orbit.hill_dcm([0.0])[0]
        body.hub.r_CN_NInit = (radius * hill[0]).reshape(3, 1).tolist()
        body.hub.v_CN_NInit = (radius * orbit.orbit_rate * hill[1]).reshape(3, 1).tolist()
    torque = extForceTorque.ExtForceTorque()
    torque.ModelTag = "torque"
    body.addDynamicEffector(torque)
    nav = simpleNav.SimpleNav()
    nav.ModelTag = "nav"
    nav.scStateInMsg.subscribeTo(body.scStateOutMsg)
    if orbit is None:
        reference = inertial3D.inertial3D()
        reference.sigma_R0N = np.asarray(target, dtype=float).tolist()
    else:
        reference = hillPoint.hillPoint()
        reference.transNavInMsg.subscribeTo(nav.transOutMsg)
    reference.ModelTag = "reference"
    error = attTrackingError.attTrackingError()
    error.ModelTag = "error"
    error.attNavInMsg.subscribeTo(nav.attOutMsg)
    error.attRefInMsg.subscribeTo(reference.attRefOutMsg)
    control = mrpFeedback.mrpFeedback()
    control.ModelTag = "mrpFeedback"
    control.K, control.P, control.Ki = gains.K, gains.P, gains.Ki
    control.controlLawType = 1
    vehicle = messaging.VehicleConfigMsgPayload()
    vehicle.ISCPntB_B = INERTIA.ravel().tolist()
    vehicle_msg = messaging.VehicleConfigMsg().write(vehicle)
    control.guidInMsg.subscribeTo(error.attGuidOutMsg)
    control.vehConfigInMsg.subscribeTo(vehicle_msg)
    torque.cmdTorqueInMsg.subscribeTo(control.cmdTorqueOutMsg)
    modules += [torque, control, error, reference, nav, body]
    # highest priority first: the spacecraft integrates to t_k, the torque effector takes the torque of t_k last
    for priority, module in enumerate(modules, start=5):
        sim.AddModelToTask("task", module, priority)
    state_log = body.scStateOutMsg.recorder()
    error_log = error.attGuidOutMsg.recorder()
    sim.AddModelToTask("task", state_log)
    sim.AddModelToTask("task", error_log)
    sim.InitializeSimulation()
    sim.ConfigureStopTime(macros.sec2nano(t_final))
    sim.ExecuteSimulation()
    return np.asarray(state_log.sigma_BN), np.asarray(state_log.omega_BN_B), np.asarray(error_log.sigma_BR)


def _assert_same_loop(run: object, sigma: np.ndarray, omega: np.ndarray, sigma_br: np.ndarray) -> None:
    assert sigma.shape == run.sigma.shape  # type: ignore[attr-defined]
    assert run.max_sigma < 1.0 and np.linalg.norm(run.sigma, axis=1).max() < 1.0  # type: ignore[attr-defined]
    for ours, theirs in ((run.sigma, sigma), (run.omega, omega)):  # type: ignore[attr-defined]
        assert np.abs(ours - theirs).max() <= 1e-12 * np.abs(theirs).max()  # measured 6e-17 to 1.3e-14
    # Basilisk's error message of t_k is the error the controller used at t_k, at tau = 0 the true error of t_k
    phi = np.degrees(4.0 * np.arctan(np.linalg.norm(sigma_br, axis=1)))
    pointing = run.pointing_error  # type: ignore[attr-defined]
    assert np.abs(pointing[1:] - phi[1:]).max() <= 1e-12 * phi.max()  # measured 6e-16 to 3.6e-15


@pytest.mark.parametrize("target", [[0.3, -0.2, 0.1], [0.0, 0.0, 0.6]])
def test_inertial_pointing_matches_basilisk_inertial3d(target: list[float]) -> None:
    """A fixed target 40-120° away, a tumbling start: attitude, rate and σ_B/R at every sample."""
    pytest.importorskip("Basilisk")
    x0 = state([0.1, 0.05, -0.1], [0.01, -0.02, 0.015])
    t_final = 60.0
    sigma, omega, sigma_br = _basilisk_tracking_run(x0, t_final, target=np.asarray(target))
    run = simulate(
        Spacecraft(INERTIA),
        GAIN,
        x0,
        tau=0.0,
        rule=Hysteretic(0.0),
        t_final=t_final,
        rate=1.0 / PERIOD,
        reference=InertialPointing(np.asarray(target)),
        feedforward=True,
    )
    _assert_same_loop(run, sigma, omega, sigma_br)


def test_nadir_pointing_matches_basilisk_hillpoint_on_an_integrated_orbit() -> None:
    """A 500 km orbit inclined 45°: the Hill frame turns at n ≈ 1.1e-3 rad/s and the body starts 20° off it."""
    pytest.importorskip("Basilisk")
    orbit = CircularOrbit.from_altitude(
        500e3, mu=BASILISK_EARTH_MU, inclination=np.radians(45.0), raan=np.radians(30.0), latitude=0.2
    )
    reference = NadirPointing(orbit)
    sigma_r0 = reference.samples([0.0])[0, :3]
    # 20 degrees about an axis from the reference attitude, and the reference's own rate plus a tumble
    offset = np.array([0.3, -0.5, 0.2]) / np.linalg.norm([0.3, -0.5, 0.2]) * np.tan(np.radians(20.0) / 4.0)
    sigma0 = _compose(offset, sigma_r0)
    omega_r_b = _dcm(sigma0) @ reference.samples([0.0])[0, 3:6]
    x0 = state(sigma0, omega_r_b + np.array([0.004, -0.003, 0.002]))
    t_final = 60.0
    sigma, omega, sigma_br = _basilisk_tracking_run(x0, t_final, orbit=orbit)
    run = simulate(
        Spacecraft(INERTIA),
        GAIN,
        x0,
        tau=0.0,
        rule=Hysteretic(0.0),
        t_final=t_final,
        rate=1.0 / PERIOD,
        reference=reference,
        feedforward=True,
    )
    _assert_same_loop(run, sigma, omega, sigma_br)


def _compose(sigma_br: np.ndarray, sigma_rn: np.ndarray) -> np.ndarray:
    """σ_B/N = σ_B/R ⊕ σ_R/N by the DCMs ([BN] = [BR][RN]), through scipy's Rotation (an independent route)."""
    from scipy.spatial.transform import Rotation

    def rotation(s: np.ndarray) -> Rotation:
        # the MRP's DCM is the passive rotation: [BN] = R.as_matrix().T for R = Rotation.from_mrp(s)
        return Rotation.from_mrp(s)

    combined = rotation(sigma_rn) * rotation(sigma_br)
    return np.asarray(combined.as_mrp())


def _dcm(sigma: np.ndarray) -> np.ndarray:
    """[BN] of σ_B/N through scipy (the passive DCM: the transpose of the active rotation's matrix)."""
    from scipy.spatial.transform import Rotation

    return np.asarray(Rotation.from_mrp(sigma).as_matrix().T)
