"""python-control and Basilisk interop, checked against python-control and independent references."""

from __future__ import annotations

import itertools
import math

import control  # type: ignore[import-untyped]
import numpy as np
import pytest
from basilisk_hub import simulation_and_hub

from mrpctl import DelayAware, NoSwitching, Spacecraft, paper, simulate
from mrpctl.design import linearized_loop, pd_gains
from mrpctl.errors import SpecificationError
from mrpctl.interop import (
    STATE_LABELS,
    basilisk_mrp_feedback,
    basilisk_state,
    delayed_loop,
    from_time_response,
    gain_from_basilisk,
    loop_margins,
    state_from_basilisk,
    to_time_response,
)
from mrpctl.model import plant_model


def _spectral_roots(a: np.ndarray, a_d: np.ndarray, tau: float, m: int = 60) -> np.ndarray:
    """Eigenvalues of the Chebyshev discretisation of the DDE's infinitesimal generator (Breda et al. 2005)."""
    x = np.cos(np.pi * np.arange(m + 1) / m)
    c = np.hstack([2.0, np.ones(m - 1), 2.0]) * (-1.0) ** np.arange(m + 1)
    dx = x[:, None] - x[None, :]
    d = np.outer(c, 1.0 / c) / (dx + np.eye(m + 1))
    d -= np.diag(d.sum(axis=1))
    n = a.shape[0]
    gen = np.kron(d * (2.0 / tau), np.eye(n))
    gen[:n, :] = 0.0
    gen[:n, :n] = a
    gen[:n, m * n :] = a_d
    return np.linalg.eigvals(gen)


def _exact_rightmost(k1: float, k2: float, tau: float) -> complex:
    """The rightmost root of s^2 - (k2 s + k1) e^{-s tau} = 0 (one axis), spectral seed polished by Newton."""
    roots = _spectral_roots(np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0, 0.0], [k1, k2]]), tau)
    s = complex(roots[np.argmax(roots.real + 1e-9 * roots.imag)])
    for _ in range(50):
        e = np.exp(-s * tau)
        f = s * s - (k2 * s + k1) * e
        df = 2 * s - k2 * e + tau * (k2 * s + k1) * e
        s -= f / df
    assert abs(s * s - (k2 * s + k1) * np.exp(-s * tau)) < 1e-10 * max(1.0, abs(s) ** 2)
    return s


def test_statespace_matrices_are_the_plant_and_the_loop() -> None:
    loop = delayed_loop(paper.SPACECRAFT, paper.GAIN, tau=0.5)
    model = plant_model(paper.SPACECRAFT)
    assert isinstance(loop.plant, control.StateSpace)
    assert np.array_equal(loop.plant.A, model.A) and np.array_equal(loop.plant.B, model.B)
    assert np.array_equal(loop.plant.C, np.eye(6)) and not np.any(loop.plant.D)
    assert np.array_equal(loop.A_d, linearized_loop(paper.SPACECRAFT, paper.GAIN).A_d)
    assert loop.tau == 0.5 and tuple(loop.plant.state_labels) == STATE_LABELS
    # B = [0; J^-1 / 4] on x = [sigma; omega/4]
    assert np.allclose(loop.plant.B[3:], np.diag(1.0 / (4.0 * np.asarray(paper.INERTIA))), rtol=1e-15)


def test_pade_poles_approach_the_exact_rightmost_roots() -> None:
    tau = 0.5
    linear = linearized_loop(paper.SPACECRAFT, paper.GAIN)
    exact = max(
        (_exact_rightmost(float(a_d[1, 0]), float(a_d[1, 1]), tau) for _, a_d in linear.axes),
        key=lambda s: s.real,
    )
    loop = delayed_loop(paper.SPACECRAFT, paper.GAIN, tau=tau)
    errors = []
    for order in (1, 2, 3, 4, 6, 8):
        poles = control.poles(loop.pade(order))
        assert len(poles) == 6 + 3 * order
        upper = poles[poles.imag >= 0]
        nearest = upper[np.argmin(np.abs(upper - exact))]
        assert abs(float(np.max(poles.real)) - exact.real) <= abs(nearest - exact) + 1e-12
        errors.append(abs(nearest - exact) / abs(exact))
    # geometric convergence down to rounding (about 1e-14 from order 4 on)
    assert errors[0] > 1e-4 and all(b < 1e-3 * a for a, b in itertools.pairwise(errors[:4])), errors
    assert max(errors[3:]) < 1e-12, errors


def test_pade_loop_changes_stability_at_the_exact_margin() -> None:
    margin = linearized_loop(paper.SPACECRAFT, paper.GAIN).delay_margin().margin
    below = delayed_loop(paper.SPACECRAFT, paper.GAIN, tau=0.999 * margin).pade(8)
    above = delayed_loop(paper.SPACECRAFT, paper.GAIN, tau=1.001 * margin).pade(8)
    assert np.max(control.poles(below).real) < 0 < np.max(control.poles(above).real)


def test_zero_delay_closes_the_loop_exactly() -> None:
    loop = delayed_loop(paper.SPACECRAFT, paper.GAIN, tau=0.0)
    closed = loop.pade(3)
    expected = np.linalg.eigvals(loop.A + loop.A_d)
    assert np.allclose(np.sort_complex(control.poles(closed)), np.sort_complex(expected), rtol=1e-12)


def test_pade_order_is_checked() -> None:
    loop = delayed_loop(paper.SPACECRAFT, paper.GAIN, tau=0.5)
    with pytest.raises(SpecificationError, match="order"):
        loop.pade(0)


def test_margins_match_the_exact_delay_margin_and_the_analytic_formula() -> None:
    margins = loop_margins(paper.SPACECRAFT, paper.GAIN)
    assert margins.delay_margin == pytest.approx(
        linearized_loop(paper.SPACECRAFT, paper.GAIN).delay_margin().margin, rel=1e-9
    )
    assert margins.critical.axis == 2  # the J = 80 axis sets the margin
    for axis, inertia in zip(margins.axes, paper.INERTIA, strict=True):
        a = -paper.GAIN_SIGMA / (4 * inertia)
        b = -paper.GAIN_OMEGA / (4 * inertia)
        wc = math.sqrt((b * b + math.sqrt(b**4 + 4 * a * a)) / 2)  # |(b i w + a)| = w^2
        assert axis.crossover == pytest.approx(wc, rel=1e-9)
        assert axis.phase_margin == pytest.approx(math.atan2(b * wc, a), rel=1e-9)
    assert "axis 3 sets it" in str(margins)


def test_margins_refuse_coupled_axes() -> None:
    k = np.array(paper.GAIN, dtype=float)
    k[0, 1] = -5.0
    with pytest.raises(SpecificationError, match="coupled"):
        loop_margins(paper.SPACECRAFT, k)


def test_time_response_round_trip() -> None:
    run = simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, tau=0.5, rule=DelayAware(), t_final=1.0)
    response = to_time_response(run)
    assert isinstance(response, control.TimeResponseData)
    assert np.array_equal(response.time, run.t)
    assert np.array_equal(response.outputs, run.x.T) and np.array_equal(response.states, run.x.T)
    assert np.array_equal(response.inputs, run.u.T)
    assert list(response.input_labels) == ["u1", "u2", "u3"]
    t, x, u = from_time_response(response)
    assert np.array_equal(t, run.t) and np.array_equal(x, run.x) and np.array_equal(u, run.u)
    assert not x.flags.writeable
    with pytest.raises(SpecificationError, match="TimeResponseData"):
        from_time_response(run)


def test_recorded_run_obeys_the_statespace_plant_near_the_origin() -> None:
    """Independent: the ZOH discretisation of the StateSpace plant, driven by the recorded torque,
    reproduces a small-angle run of the nonlinear simulator (errors O(|x|^2))."""
    x0 = np.array([1e-4, -2e-4, 1.5e-4, 1e-5, 0.0, -1e-5])
    run = simulate(paper.SPACECRAFT, paper.GAIN, x0, tau=0.0, rule=NoSwitching(), t_final=2.0)
    discrete = control.c2d(delayed_loop(paper.SPACECRAFT, paper.GAIN).plant, 1.0 / run.rate, method="zoh")
    x = run.x
    predicted = x[:-1] @ np.asarray(discrete.A).T + run.u[:-1] @ np.asarray(discrete.B).T
    assert np.max(np.abs(predicted - x[1:])) < 1e-6 * np.max(np.abs(x))


def test_basilisk_gain_mapping_gives_the_same_torque(rng: np.random.Generator) -> None:
    bsk = basilisk_mrp_feedback(paper.GAIN)
    assert pytest.approx(paper.GAIN_SIGMA * -1.0, rel=1e-15) == bsk.K
    assert pytest.approx(-paper.GAIN_OMEGA / 4.0, rel=1e-15) == bsk.P
    assert bsk.Ki < 0 and bsk.controlLawType == 0
    for x in rng.normal(size=(20, 6)):
        sigma_bn, omega_bn_b = basilisk_state(x)
        torque_bsk = -(bsk.K * sigma_bn + bsk.P * omega_bn_b)  # mrpFeedback, omega_r = 0, Ki off, no wheels
        assert np.allclose(torque_bsk, np.asarray(paper.GAIN) @ x, rtol=1e-13, atol=1e-12)
        assert np.allclose(state_from_basilisk(sigma_bn, omega_bn_b), x, rtol=1e-15)
    assert np.allclose(gain_from_basilisk(bsk.K, bsk.P), paper.GAIN, rtol=1e-15)


def test_basilisk_refuses_per_axis_gains() -> None:
    per_axis = pd_gains(
        Spacecraft(np.array([12.0, 15.0, 9.0])), zeta=1.0, omega_n=0.5
    ).K  # k_sigma = 4 J K1: differs per axis
    with pytest.raises(SpecificationError, match=r"scalar times I3.*k_sigma\) differs per axis \(diagonal \[") as info:
        basilisk_mrp_feedback(per_axis)
    assert "k_omega) differs per axis" in str(info.value) and "nearest=True" in str(info.value)
    coupled = np.array(paper.GAIN, dtype=float)
    coupled[0, 4] = 0.5
    with pytest.raises(SpecificationError, match=r"k_omega\) couples the axes \(entry \[0, 1\] = 0.5\)") as info:
        basilisk_mrp_feedback(coupled)
    assert "k_sigma" not in str(info.value)  # the scalar block is not blamed


def test_basilisk_nearest_scalar_gains_report_what_is_not_applied(rng: np.random.Generator) -> None:
    per_axis = np.asarray(pd_gains(Spacecraft(np.array([12.0, 15.0, 9.0])), zeta=1.0, omega_n=0.5).K)
    bsk = basilisk_mrp_feedback(per_axis, nearest=True)
    k_sigma, k_omega = np.mean(np.diag(per_axis[:, :3])), np.mean(np.diag(per_axis[:, 3:]))
    assert pytest.approx(-k_sigma, rel=1e-15) == bsk.K and pytest.approx(-k_omega / 4.0, rel=1e-15) == bsk.P
    for x in rng.normal(size=(5, 6)):  # Basilisk's torque plus what it leaves out is mrpctl's u = K x
        sigma_bn, omega_bn_b = basilisk_state(x)
        torque_bsk = -(bsk.K * sigma_bn + bsk.P * omega_bn_b)
        assert np.allclose(torque_bsk + bsk.unmapped @ x, per_axis @ x, rtol=1e-13, atol=1e-12)
    assert np.max(np.abs(bsk.unmapped)) > 1.0 and "NOT the same controller" in str(bsk)
    exact = basilisk_mrp_feedback(paper.GAIN, nearest=True)
    assert not np.any(exact.unmapped) and "NOT" not in str(exact) and exact == basilisk_mrp_feedback(paper.GAIN)


def test_basilisk_mrp_feedback_module_agrees() -> None:
    """When Basilisk is installed: its mrpFeedback torque equals mrpctl's u = K x on the paper's gains."""
    pytest.importorskip("Basilisk")
    from Basilisk.architecture import messaging  # type: ignore[import-untyped]
    from Basilisk.fswAlgorithms import mrpFeedback  # type: ignore[import-untyped]
    from Basilisk.utilities import SimulationBaseClass, macros  # type: ignore[import-untyped]

    bsk = basilisk_mrp_feedback(paper.GAIN)
    x = np.asarray(paper.INITIAL_STATE, dtype=float)
    sigma_bn, omega_bn_b = basilisk_state(x)
    sim = SimulationBaseClass.SimBaseClass()
    process = sim.CreateNewProcess("process")
    process.addTask(sim.CreateNewTask("task", macros.sec2nano(0.1)))
    module = mrpFeedback.mrpFeedback()
    module.ModelTag = "mrpFeedback"
    module.K, module.P, module.Ki = bsk.K, bsk.P, bsk.Ki
    module.controlLawType = bsk.controlLawType
    sim.AddModelToTask("task", module)
    guidance = messaging.AttGuidMsgPayload()
    guidance.sigma_BR = sigma_bn.tolist()
    guidance.omega_BR_B = omega_bn_b.tolist()
    guidance_msg = messaging.AttGuidMsg().write(guidance)
    config = messaging.VehicleConfigMsgPayload()
    config.ISCPntB_B = np.asarray(paper.SPACECRAFT.inertia).ravel().tolist()
    config_msg = messaging.VehicleConfigMsg().write(config)
    module.guidInMsg.subscribeTo(guidance_msg)
    module.vehConfigInMsg.subscribeTo(config_msg)
    log = module.cmdTorqueOutMsg.recorder()
    sim.AddModelToTask("task", log)
    sim.InitializeSimulation()
    sim.ConfigureStopTime(macros.sec2nano(0.1))
    sim.ExecuteSimulation()
    assert np.allclose(np.asarray(log.torqueRequestBody)[-1], np.asarray(paper.GAIN) @ x, rtol=1e-12)


def test_basilisk_closed_loop_matches_an_undelayed_run() -> None:
    """When Basilisk is installed: its spacecraft + attTrackingError + mrpFeedback loop with the mapped
    gains is mrpctl's tau = 0 run to round-off (OnCurrent: both switch at |sigma| = 1) over 10 s."""
    pytest.importorskip("Basilisk")
    from Basilisk.architecture import messaging  # type: ignore[import-untyped]
    from Basilisk.fswAlgorithms import attTrackingError, inertial3D, mrpFeedback  # type: ignore[import-untyped]
    from Basilisk.simulation import extForceTorque, simpleNav  # type: ignore[import-untyped]
    from Basilisk.utilities import macros  # type: ignore[import-untyped]

    from mrpctl import OnCurrent

    t_final, period = 10.0, 1e-3
    bsk = basilisk_mrp_feedback(paper.GAIN)
    sim, body = simulation_and_hub(period, np.diag(paper.INERTIA), paper.INITIAL_STATE)
    torque = extForceTorque.ExtForceTorque()
    torque.ModelTag = "torque"
    body.addDynamicEffector(torque)
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
    control_module = mrpFeedback.mrpFeedback()
    control_module.ModelTag = "mrpFeedback"
    control_module.K, control_module.P, control_module.Ki = bsk.K, bsk.P, bsk.Ki
    control_module.controlLawType = bsk.controlLawType
    config = messaging.VehicleConfigMsgPayload()
    config.ISCPntB_B = np.diag(paper.INERTIA).ravel().tolist()
    config_msg = messaging.VehicleConfigMsg().write(config)
    control_module.guidInMsg.subscribeTo(error.attGuidOutMsg)
    control_module.vehConfigInMsg.subscribeTo(config_msg)
    torque.cmdTorqueInMsg.subscribeTo(control_module.cmdTorqueOutMsg)
    # highest priority first: the spacecraft integrates to t_k, the torque effector takes the torque of t_k last
    # (mrpctl's zero-order hold; with the effector before the controller it would hold the torque of t_{k-1})
    for priority, module in enumerate((torque, control_module, error, reference, nav, body), start=5):
        sim.AddModelToTask("task", module, priority)
    log = body.scStateOutMsg.recorder()
    sim.AddModelToTask("task", log)
    sim.InitializeSimulation()
    sim.ConfigureStopTime(macros.sec2nano(t_final))
    sim.ExecuteSimulation()
    sigma_bsk = np.asarray(log.sigma_BN)

    run = simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, tau=0.0, rule=OnCurrent(), t_final=t_final)
    assert sigma_bsk.shape == run.sigma.shape and run.switch_count == 1
    # every sample, the switch at 0.438 s included (both take the short set at the same sample): measured 1.1e-16
    assert np.max(np.abs(sigma_bsk - run.sigma)) <= 1e-12
