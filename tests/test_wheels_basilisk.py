"""The wheel cluster against Basilisk's reactionWheelStateEffector + rwMotorTorque + mrpFeedback (skipped without
Basilisk, the optional ``basilisk`` extra).

The same loop on both sides at tau = 0: at t_k the spacecraft has been integrated to t_k, the navigation,
the tracking error (inertial, zero reference), mrpFeedback and rwMotorTorque run on the state at t_k, and the
wheel effector takes the new motor torques (clipped to u_max) for [t_k, t_{k+1}]: mrpctl's zero-order hold.
Basilisk runs a task's modules from the highest priority down, so the spacecraft has the highest priority and
the wheel effector the lowest (the task order of the paper cross-check in ``test_interop.py``). Basilisk's
speed test reads Ω(t_k) (its spacecraft's postIntegration refreshes the effectors' states), as mrpctl's does.
The run stays below |σ| = 1 (Basilisk switches σ after an integration when |σ| > 1, mrpctl at its samples when
|σ|² >= 1) and below the speed limit; the speed cut is checked in ``test_wheels.py`` against the reference loop.
"""

from __future__ import annotations

import numpy as np
import pytest
from basilisk_hub import simulation_and_hub

from mrpctl import simulate
from mrpctl.flight import Hysteretic
from mrpctl.interop import basilisk_mrp_feedback
from mrpctl.model import state
from mrpctl.spacecraft import Spacecraft
from mrpctl.wheels import WheelCluster

INERTIA = np.diag([0.2, 0.25, 0.15])
SPIN_INERTIA = 2e-4
TORQUE_LIMIT = 5e-3
SPEED_LIMIT_RPM = 6000.0
VISCOUS = 1e-7
COULOMB = 1e-5


@pytest.mark.parametrize("law", [0, 1])
def test_basilisk_reaction_wheel_loop_matches_the_wheel_sample(law: int) -> None:
    """controlLawType 0 (no gyroscopic term at a zero reference) and 1 (ω × (J ω + Gs h_s), mrpctl's
    ``gyroscopic=True``); orthogonal wheels with friction, the torque limit reached at the start."""
    pytest.importorskip("Basilisk")
    from Basilisk.architecture import messaging  # type: ignore[import-untyped]
    from Basilisk.fswAlgorithms import (  # type: ignore[import-untyped]
        attTrackingError,
        inertial3D,
        mrpFeedback,
        rwMotorTorque,
    )
    from Basilisk.simulation import reactionWheelStateEffector, simpleNav  # type: ignore[import-untyped]
    from Basilisk.utilities import macros, simIncludeRW  # type: ignore[import-untyped]

    t_final, period = 30.0, 0.01
    craft = Spacecraft(INERTIA)
    K = np.hstack((-0.05 * np.eye(3), -1.2 * np.eye(3)))
    x0 = state([0.2, -0.1, 0.15], [0.01, -0.02, 0.015])
    speeds0_rpm = np.array([500.0, -300.0, 800.0])
    speed_limit = SPEED_LIMIT_RPM * macros.RPM
    wheels = WheelCluster.orthogonal(
        SPIN_INERTIA,
        TORQUE_LIMIT,
        speed_limit,
        viscous=VISCOUS,
        coulomb=COULOMB,
        speeds=speeds0_rpm * macros.RPM,
        gyroscopic=law == 1,
    )
    gains = basilisk_mrp_feedback(K)
    # BalancedWheels add no mass properties to the spacecraft (the effector's IEffPntB_B stays 0): the hub's
    # inertia is the whole spacecraft's, wheels included, which is mrpctl's J
    sim, body = simulation_and_hub(period, INERTIA, x0)
    factory = simIncludeRW.rwFactory()
    for axis, speed in zip(np.eye(3), speeds0_rpm, strict=True):
        factory.create(
            "custom",
            axis.tolist(),
            Js=SPIN_INERTIA,
            Omega=float(speed),
            Omega_max=SPEED_LIMIT_RPM,
            u_max=TORQUE_LIMIT,
            useMaxTorque=True,
            useRWfriction=True,
            fCoulomb=COULOMB,
            cViscous=VISCOUS,
            RWModel=messaging.BalancedWheels,
        )
    effector = reactionWheelStateEffector.ReactionWheelStateEffector()
    factory.addToSpacecraft("wheels", effector, body)
    config_msg = factory.getConfigMessage()

    nav = simpleNav.SimpleNav()
    nav.ModelTag = "nav"
    nav.scStateInMsg.subscribeTo(body.scStateOutMsg)
    reference = inertial3D.inertial3D()
    reference.ModelTag = "reference"
    reference.sigma_R0N = [0.0, 0.0, 0.0]
    error = attTrackingError.attTrackingError()
    error.ModelTag = "error"
    error.attNavInMsg.subscribeTo(nav.attOutMsg)
    error.attRefInMsg.subscribeTo(reference.attRefOutMsg)
    control = mrpFeedback.mrpFeedback()
    control.ModelTag = "mrpFeedback"
    control.K, control.P, control.Ki = gains.K, gains.P, gains.Ki
    control.controlLawType = law
    vehicle = messaging.VehicleConfigMsgPayload()
    vehicle.ISCPntB_B = INERTIA.ravel().tolist()
    vehicle_msg = messaging.VehicleConfigMsg().write(vehicle)
    control.guidInMsg.subscribeTo(error.attGuidOutMsg)
    control.vehConfigInMsg.subscribeTo(vehicle_msg)
    control.rwParamsInMsg.subscribeTo(config_msg)
    control.rwSpeedsInMsg.subscribeTo(effector.rwSpeedOutMsg)
    allocation = rwMotorTorque.rwMotorTorque()
    allocation.ModelTag = "rwMotorTorque"
    allocation.controlAxes_B = np.eye(3).ravel().tolist()
    allocation.vehControlInMsg.subscribeTo(control.cmdTorqueOutMsg)
    allocation.rwParamsInMsg.subscribeTo(config_msg)
    effector.rwMotorCmdInMsg.subscribeTo(allocation.rwMotorTorqueOutMsg)
    # highest priority first: the spacecraft integrates to t_k, the effector takes u_k last
    for priority, module in enumerate((effector, allocation, control, error, reference, nav, body), start=5):
        sim.AddModelToTask("task", module, priority)
    state_log = body.scStateOutMsg.recorder()
    speed_log = effector.rwSpeedOutMsg.recorder()
    sim.AddModelToTask("task", state_log)
    sim.AddModelToTask("task", speed_log)
    sim.InitializeSimulation()
    sim.ConfigureStopTime(macros.sec2nano(t_final))
    sim.ExecuteSimulation()
    sigma_bsk = np.asarray(state_log.sigma_BN)
    omega_bsk = np.asarray(state_log.omega_BN_B)
    speeds_bsk = np.asarray(speed_log.wheelSpeeds)[:, 0:3]

    run = simulate(craft, K, x0, tau=0.0, rule=Hysteretic(0.0), t_final=t_final, rate=1.0 / period, wheels=wheels)
    assert run.wheels is not None
    assert sigma_bsk.shape == run.sigma.shape
    assert run.wheels.torque_limited_time.max() > 0.0  # the clip acted
    assert np.abs(run.wheels.speeds).max() < speed_limit and run.max_sigma < 1.0  # see the module docstring
    for ours, theirs in ((run.sigma, sigma_bsk), (run.omega, omega_bsk), (run.wheels.speeds, speeds_bsk)):
        assert np.abs(ours - theirs).max() <= 1e-12 * np.abs(theirs).max()
