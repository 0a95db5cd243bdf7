"""``simulate``: one run's input checks, its engine and its result; the checks ``simulate_batch`` shares."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, overload

import numpy as np

from mrpctl._validation import finite_array, finite_scalar, positive_scalar, readonly
from mrpctl.conventions import initial_state
from mrpctl.engines.scalar import engine
from mrpctl.engines.stats import HISTORY_KINDS, SETTLING_ATTITUDE_DEG, SETTLING_OMEGA, settling_bounds
from mrpctl.errors import CodegenError, DimensionError, SpecificationError
from mrpctl.estimation import Estimator, Sensors
from mrpctl.flight import (
    ActuatorModel,
    DelayModel,
    Disturbance,
    Hysteretic,
    SensorModel,
)
from mrpctl.flight.steering import SteeringLaw, check_law
from mrpctl.flight.tracking import DEFAULT_POINTING_TOLERANCE, ErrorTime
from mrpctl.loop import check_rule, check_substeps, delay_samples
from mrpctl.loop.options import (
    as_disturbance,
    check_predictor,
    flight_constants,
    flight_options,
    flight_structure,
    gravity_gradient_options,
    predictor_constants,
    predictor_disturbance,
    varying_delay,
)
from mrpctl.model import STATE_SIZE, gain_matrix
from mrpctl.predictor import Predictor, PredictorForm
from mrpctl.simulation._budget import (
    SWITCH_LIMIT,
    check_keep_every,
    check_memory,
    jitter_bytes,
    memory_limit_bytes,
    run_bytes,
    sample_horizon,
    workspace_bytes,
)
from mrpctl.simulation._guards import check_step_rotation
from mrpctl.simulation._tracking import tracking_options
from mrpctl.simulation._wheels import (
    check_wheel_run,
    progress_stop,
    run_wheels,
    wheel_result,
    wheel_run_bytes,
)
from mrpctl.simulation.estimated import EstimatedResult, simulate_estimated_as_simulate
from mrpctl.simulation.results import SimulationResult, assemble_run
from mrpctl.spacecraft import Spacecraft, check_spacecraft
from mrpctl.switching import SwitchingRule
from mrpctl.wheels import WheelCluster


def measurement_history(history: Any, x0: np.ndarray, d: int) -> tuple[np.ndarray, Any]:
    """The measurements before t = 0 as (columns, 6) rows m_{−d}, … (one row for a constant
    history: only that row is stored), and the value to store in the result."""
    if isinstance(history, str):
        if history == "constant":
            return x0[None, :].copy(), history
        if history == "zero-input":
            return np.zeros((1, STATE_SIZE)), history
        raise SpecificationError(f"history must be one of {HISTORY_KINDS} or an array of shape (d, 6), got {history!r}")
    array = finite_array("history", history)
    if array.shape != (d, STATE_SIZE):
        raise DimensionError(
            f"history: expected shape (d, 6) = ({d}, 6) (d = tau * rate delayed states, oldest first) "
            f"but found {array.shape}"
        )
    if d == 0:
        return np.zeros((1, STATE_SIZE)), readonly(array)
    return np.ascontiguousarray(array), readonly(array)


def streamed_disturbance(disturbance: Any, n: int, name: str = "disturbance", hint: str = "") -> Disturbance | None:
    """The per-sample disturbance of a run of n samples (its rows checked, errors naming ``name``, ``hint``
    appended), or None (none or constant)."""
    if disturbance is None:
        return None
    if not isinstance(disturbance, Disturbance):
        disturbance = as_disturbance(disturbance, name)
    if disturbance.constant:
        return None
    try:
        disturbance.check_horizon(n, name)
    except DimensionError as error:
        if hint:
            raise DimensionError(f"{error}{hint}") from error
        raise
    return disturbance


def engine_structure(
    checked: Any, options: np.ndarray | None, sensor: Any, actuator: Any, *, gravity_gradient: bool = False
) -> dict[str, bool]:
    """The engine's structure keywords: the predictor's (sensor given, actuator given), or the
    flight sample's specialisation to the run's constants (`flight_structure`), with ``gravity_gradient=True``
    when the plant flies the gravity-gradient torque (the key is absent without it: the engine of before)."""
    if checked is not None:
        return {"sensor": sensor is not None, "limited": actuator is not None}
    return flight_structure(options, sensor) | ({"gravity_gradient": True} if gravity_gradient else {})


@overload
def simulate(
    spacecraft: Spacecraft,
    K: Any,
    x0: Any = ...,
    *,
    tau: float,
    rule: SwitchingRule,
    t_final: float,
    rate: float = ...,
    history: Any = ...,
    substeps: int = ...,
    keep_every: int | None = ...,
    memory_limit: float | None = ...,
    progress: Callable[[int, int], Any] | None = ...,
    actuator: ActuatorModel | None = ...,
    disturbance: Any = ...,
    sensor: SensorModel | None = ...,
    delay: DelayModel | None = ...,
    predictor: Predictor | None = ...,
    wheels: WheelCluster | None = ...,
    reference: Any = ...,
    error_time: ErrorTime | None = ...,
    feedforward: bool = ...,
    pointing_tolerance: float = ...,
    settling_attitude: float = ...,
    settling_rate: float = ...,
    law: SteeringLaw | None = ...,
    sigma0: Any = ...,
    omega0: Any = ...,
    sensors: None = ...,
    estimator: None = ...,
    gravity_gradient: Any = ...,
) -> SimulationResult: ...


@overload
def simulate(
    spacecraft: Spacecraft,
    K: Any,
    x0: Any = ...,
    *,
    tau: float,
    rule: SwitchingRule,
    t_final: float,
    rate: float = ...,
    history: Any = ...,
    substeps: int = ...,
    keep_every: int | None = ...,
    memory_limit: float | None = ...,
    progress: Callable[[int, int], Any] | None = ...,
    actuator: ActuatorModel | None = ...,
    disturbance: Any = ...,
    sensor: SensorModel | None = ...,
    delay: DelayModel | None = ...,
    predictor: Predictor | None = ...,
    wheels: WheelCluster | None = ...,
    reference: Any = ...,
    error_time: ErrorTime | None = ...,
    feedforward: bool = ...,
    pointing_tolerance: float = ...,
    settling_attitude: float = ...,
    settling_rate: float = ...,
    law: SteeringLaw | None = ...,
    sigma0: Any = ...,
    omega0: Any = ...,
    sensors: Sensors,
    estimator: Estimator | None = ...,
    gravity_gradient: None = ...,
) -> EstimatedResult: ...


def simulate(
    spacecraft: Spacecraft,
    K: Any,
    x0: Any = None,
    *,
    tau: float,
    rule: SwitchingRule,
    t_final: float,
    rate: float = 1000.0,
    history: Any = "constant",
    substeps: int = 1,
    keep_every: int | None = 1,
    memory_limit: float | None = None,
    progress: Callable[[int, int], Any] | None = None,
    actuator: ActuatorModel | None = None,
    disturbance: Any = None,
    sensor: SensorModel | None = None,
    delay: DelayModel | None = None,
    predictor: Predictor | None = None,
    wheels: WheelCluster | None = None,
    reference: Any = None,
    error_time: ErrorTime | None = None,
    feedforward: bool = False,
    pointing_tolerance: float = DEFAULT_POINTING_TOLERANCE,
    settling_attitude: float = SETTLING_ATTITUDE_DEG,
    settling_rate: float = SETTLING_OMEGA,
    law: SteeringLaw | None = None,
    sensors: Sensors | None = None,
    estimator: Estimator | None = None,
    sigma0: Any = None,
    omega0: Any = None,
    gravity_gradient: Any = None,
) -> SimulationResult | EstimatedResult:
    """Simulate the closed loop u(t) = K x(t − τ) with sampled measurements and switching.

    The model and the engine: ``design/switching.md``. A run is a few calls of compiled C
    (one per slice of 65 536 samples): Ctrl-C stops it within a slice; a diverging run
    stops at the first bad sample.

    Parameters
    ----------
    spacecraft : Spacecraft
        The plant (inertia J in kg m²).
    K : array_like or PDGains
        (3, 6) gain on x = [σ; ω/4] (N m), or the physical gains
        [`PDGains`][mrpctl.conventions.PDGains] of u = −P_σ σ − P_ω ω (K = [−P_σ, −4 P_ω], exact).
    x0 : array_like, optional
        (6,) initial state x = [σ; ω/4] (ω in rad/s; see [`mrpctl.conventions.state`][mrpctl.conventions.state]);
        or give ``sigma0`` and ``omega0`` instead.
    tau : float, keyword-only
        Measurement delay τ >= 0 (s), a whole number of periods 1/rate.
    rule : SwitchingRule, keyword-only
        Shadow-set switching rule, e.g. ``OnDelayed()``.
    t_final : float, keyword-only
        Horizon (s), > 0.
    rate : float, keyword-only
        Measurement rate (Hz), default 1000.
    history : {"constant", "zero-input"} or array_like, keyword-only
        Measurements before t = 0: x0 (the paper's φ(θ) = x0; default), zero (u = 0
        until the first measurement arrives), or a (d, 6) array m_{−d}, …, m_{−1}.
    substeps : int, keyword-only
        RK4 substeps per measurement period, 1 to 64 (default 1).
    keep_every : int or None, keyword-only
        Keep every k-th sample in the arrays (default 1: all); None keeps none (metrics
        and switch instants only). Metrics are always over every sample. Memory: about
        104 bytes per kept sample, plus the d-sample history.
    memory_limit : float, keyword-only
        Refuse up front a run whose kept arrays would exceed this many bytes; default half
        of the memory available (``os.sysconf``).
    progress : callable, keyword-only
        ``progress(samples_done, n)`` after each slice; an exception raised by it
        (KeyboardInterrupt included) stops the run and propagates.
    actuator : mrpctl.flight.ActuatorModel, keyword-only
        Torque limits of the flight loop (``rule=Hysteretic(...)`` only); None: none. The
        result's ``u`` is then the applied torque, ``saturated_fraction`` and
        ``peak_command`` report the limits.
    disturbance : mrpctl.flight.Disturbance or array_like (3,) or (n, 3), keyword-only
        A body-frame torque w (N m) added to the applied torque (``rule=Hysteretic(...)``, or the
        predictor: there on the plant only, never on the controller's model copy):
        constant (3,), one row per sample (n, 3), or ``Disturbance(function=w)`` with w(t) of the
        sample times (evaluated slice by slice); the per-sample forms are streamed per slice
        like the noise (compiled engine only; [`simulate_batch`][mrpctl.simulate_batch] takes them too, shared or per
        run).
    sensor : mrpctl.flight.SensorModel, keyword-only
        Attitude and rate noise and gyro bias of the flight loop's measurements
        (``rule=Hysteretic(...)`` only); the noise of each slice of samples is generated in
        NumPy from (seed, sample index), so a run is the same however it is sliced. The
        result's ``sigma``, ``omega`` stay the true (bookkept) state.
    delay : mrpctl.flight.DelayModel, keyword-only
        A time-varying delay (``rule=Hysteretic(...)`` only): a sequence of n delays or seeded
        jitter in [tau_min, tau_max], with ``tau`` = tau_max (the history depth) and
        tau_min >= 1/rate; the controller uses the newest measurement that has arrived.
    predictor : mrpctl.Predictor, keyword-only
        The predictor controller (``design/predictor.md``): u = K x̂ with x̂ the model copy's state
        corrected by the delayed measurement on the rotation group, with ``rule=OnPredicted(alpha)``
        (the switch is decided on the prediction). Runs with ``actuator`` (the copy is driven by
        the applied torque), ``disturbance`` (constant or per sample; the plant's only) and ``sensor``;
        needs ``history="constant"``, no
        ``delay`` model, and a C compiler. The result's ``sigma``, ``omega`` are the plant's state.
    wheels : mrpctl.wheels.WheelCluster, keyword-only
        Fly the body torque on this reaction-wheel cluster (``design/wheels.md``): the command u_c = K x
        is allocated to the wheels' motor torques, each clipped to its torque limit and cut at its speed
        limit, and the wheel speeds are states of the plant (J is the whole spacecraft's inertia, wheels
        included). With ``rule=Hysteretic(...)`` only, without ``actuator`` and ``predictor``; takes
        ``disturbance``, ``sensor``, ``delay`` and ``law``; needs a C compiler. The result's ``wheels``
        ([`WheelRecord`][mrpctl.simulation.results.WheelRecord]) has the wheel speeds and metrics.
    reference : array_like (n, 9) or object with ``samples(t)``, keyword-only
        Track a reference (``design/tracking.md``; ``rule=Hysteretic(...)`` or the predictor, compiled engine): one row
        (σ_R/N, ω_R/N, ω̇_R/N) per sample t_k = k/rate (ω in rad/s and ω̇ in rad/s², inertial components), at least
        n rows, or an object whose ``samples(t)`` returns the (len(t), 9) rows of the sample times (evaluated
        slice by slice). The controller forms σ_B/R and ω_B/R from the delayed measurement, its rule acts on
        σ_B/R, and u_c = K [σ_c; ω_B/R/4]. The result's ``sigma``, ``omega`` stay the plant's σ_B/N, ω_B/N; its
        ``settling_time`` and ``max_sigma`` are those of the true error σ_B/R, ω_B/R; ``pointing_error`` (deg),
        ``pointing_max``, ``pointing_rms`` and ``slew_time`` report the pointing. None (default): regulation.
    error_time : mrpctl.flight.tracking.ErrorTime, keyword-only
        Which reference the delayed measurement is compared with: ``MEASUREMENT``, the one of its own time
        t_{k−d}, or ``CURRENT``, the one of t_k; default (None) ``MEASUREMENT``, and ``CURRENT`` with a predictor
        (whose prediction is of t_k: its tracking error is formed from x̂ and the reference of t_k, and the
        rule ``OnPredicted(alpha)`` acts on that σ_B/R).
    feedforward : bool, keyword-only
        Add ω̃ × (J ω̃) + J([B̃N] ω̇_R − ω̃ × [B̃N] ω_R) to u_c (ω̃ the delayed measured rate); default False.
    pointing_tolerance : float, keyword-only
        The slew time's tolerance on Φ_B/R (degrees, > 0), default 0.1.

    settling_attitude : float, keyword-only
        Attitude tolerance of "settled": the principal angle Φ (deg) with |σ| = tan(Φ/4), in (0, 180];
        default 4 atan(1e-2) = 2.2918° (|σ| < 1e-2).
    settling_rate : float, keyword-only
        Rate tolerance of "settled": |ω| below this (rad/s), > 0; default 1e-3. Both are run-time
        constants of the compiled sample (no recompilation); the result records them.
    law : mrpctl.flight.steering.SteeringLaw, keyword-only
        The flight loop's saturation-aware law (``rule=Hysteretic(...)`` only): K's attitude term
        scaled down so that the commanded rate stays below the rate from which the body can stop in
        the remaining angle ([`SteeringLaw`][mrpctl.flight.steering.SteeringLaw]; ``design/wheels.md``); the
        law is the PD law K wherever that limit is not reached. With ``wheels`` the law's command is the body
        torque request the allocation takes. None (default): the PD law.
    sensors : mrpctl.estimation.Sensors, keyword-only
        A late star tracker and a rate-integrating gyro: the loop then flies the control law on the
        estimator's attitude and rate (``design/estimation.md``), with ``rule=Hysteretic(...)`` on the
        estimate and ``tau`` the star tracker's latency; the other flight options do not apply. Returns an
        [`EstimatedResult`][mrpctl.simulation.estimated.EstimatedResult] (true, measured and estimated states,
        covariance, innovations). None (default): the loop above, unchanged.
    estimator : mrpctl.estimation.Estimator, keyword-only
        The estimator of that loop (with ``sensors``); default the MEKF.
    sigma0, omega0 : array_like, keyword-only
        The initial state in physical form instead of ``x0``: (3,) MRPs σ₀ and (3,) body rates ω₀
        (rad/s; default zero); the run is bit for bit the one of x0 = [σ₀; ω₀/4].
    gravity_gradient : mrpctl.guidance.CircularOrbit or NadirPointing, keyword-only
        Fly the gravity-gradient torque 3 n² r̂_B × (J r̂_B) of this circular orbit (a ``NadirPointing``: its
        orbit) in the plant (``design/tracking.md``, "The gravity gradient in the flown plant";
        ``rule=Hysteretic(...)``, no predictor, no wheels): a torque of the attitude, evaluated inside every RK4
        stage with r̂_N(t) = cos(u₀ + n t) ê₁ + sin(u₀ + n t) ê₂ at the stage's time (t_k = k h, h = 1/rate, in
        the sample k), J the plant's inertia. The controller does not know it (no feedforward of it). None
        (default): no environment torque, the plant of before bit for bit.

    Returns
    -------
    SimulationResult
        Or an [`EstimatedResult`][mrpctl.simulation.estimated.EstimatedResult] with ``sensors``.

    Raises
    ------
    SpecificationError, DimensionError
        On invalid inputs (NaN, negative τ, rate <= 0, t_final <= 0, τ · rate not an
        integer, wrong shapes, unknown history, substeps outside 1..64, keep_every < 1),
        or when the kept arrays would exceed ``memory_limit``.
    """
    x0 = initial_state(x0, sigma0, omega0)
    if sensors is not None or estimator is not None:
        others = {"actuator": actuator, "disturbance": disturbance, "sensor": sensor, "delay": delay}
        others |= {"predictor": predictor, "progress": progress, "memory_limit": memory_limit}
        others |= {"wheels": wheels, "reference": reference, "law": law, "gravity_gradient": gravity_gradient}
        if sensors is None:
            raise SpecificationError("estimator: give the sensors it estimates from (sensors=Sensors(...))")
        given = [name for name, value in others.items() if value is not None]
        if given or history != "constant" or keep_every != 1:
            given += ["history"] if history != "constant" else []
            given += ["keep_every"] if keep_every != 1 else []
            raise SpecificationError(f"{', '.join(given)}: not options of the estimated loop (sensors=...)")
        return simulate_estimated_as_simulate(
            spacecraft, K, x0, tau=tau, rule=rule, t_final=t_final, rate=rate, substeps=substeps,
            sensors=sensors, estimator=estimator,
        )  # fmt: skip
    spacecraft = check_spacecraft(spacecraft)
    gain = gain_matrix(K)
    rule = check_rule(rule)
    if wheels is not None:
        wheels = check_wheel_run(wheels, spacecraft, rule, actuator=actuator, predictor=predictor)
        if reference is not None:
            raise SpecificationError(
                "wheels: tracking a reference on a wheel cluster is not modelled yet; track with an ideal body "
                "torque (actuator=ActuatorModel(...)) or regulate on the wheels (reference=None)"
            )
    d = delay_samples(tau, rate)
    rate = float(rate)
    t_final, n = sample_horizon(t_final, rate)
    substeps = check_substeps(substeps)
    check_step_rotation(x0, rate, substeps)
    keep = check_keep_every(keep_every)
    settle_attitude, settle_rate, settling = settling_tolerances(settling_attitude, settling_rate)
    history_rows, history_value = measurement_history(history, x0, d)
    limit = memory_limit_bytes(memory_limit)
    checked = check_predictor(predictor, rule, history, delay)
    # the compiled engine checks an array reference's values as it reads them (the same errors)
    tracked, feedforward, pointing_tolerance = tracking_options(
        reference, error_time, feedforward, pointing_tolerance, rule=rule, predictor=checked, n=n, rate=rate, d=d,
        defer_values=True,
    )  # fmt: skip
    law = check_law(law, (rule,), gain, predictor=checked)
    if checked is None:
        options, saturation = flight_options(rule, actuator, disturbance, sensor)
        options = gravity_gradient_options(
            gravity_gradient, rule, options, period=1.0 / rate, substeps=substeps, wheels=wheels
        )
        varying = varying_delay(rule, delay, d, rate, n)
        streamed = streamed_disturbance(disturbance, n)
    else:
        gravity_gradient_options(  # refused with a predictor
            gravity_gradient, rule, None, period=1.0 / rate, substeps=substeps, predictor=checked
        )
        disturbance = predictor_disturbance(disturbance, n)
        options, saturation = flight_constants(actuator, disturbance, sensor)
        options, varying = predictor_constants(options, float(tau), checked.model), None
        streamed = None if disturbance is None or disturbance.constant else disturbance
    width = 1 if checked is None else 2
    records = checked is not None or isinstance(rule, Hysteretic) or tracked is not None
    check_memory(
        run_bytes(n, keep, flight=records)
        + workspace_bytes(n, d, substeps, width)
        + jitter_bytes(varying, d)
        + (0 if wheels is None or keep is None else wheel_run_bytes((n - 1) // keep + 1, wheels)),
        limit,
        t_final=t_final,
        keep_every=keep,
    )

    if wheels is not None:
        output = run_wheels(
            spacecraft=spacecraft,
            wheels=wheels,
            rule=rule,
            d=d,
            rate=rate,
            substeps=substeps,
            n=n,
            x0=x0,
            history_rows=history_rows,
            gain=gain,
            keep=keep,
            disturbance=disturbance,
            streamed=streamed,
            sensor=sensor,
            varying=varying,
            stop=progress_stop(progress, n),
            switch_limit=n if keep == 1 else SWITCH_LIMIT,
            law=law,
        )
        flown = assemble_run(
            output,
            n=n,
            keep_every=keep,
            common=_common(spacecraft, gain, tau, rate, d, rule, history_value, substeps, t_final, x0, None),
        )
        return wheel_result(flown, output, wheels, rate=rate)
    found = engine(
        spacecraft,
        rule,
        d,
        1.0 / rate,
        substeps,
        saturation,
        predictor=None if checked is None else checked.model,
        predictor_form=PredictorForm.NONLINEAR if checked is None else checked.form,
        **engine_structure(checked, options, sensor, actuator, gravity_gradient=gravity_gradient is not None),
        **({} if streamed is None else {"torque_input": True}),
        **({} if tracked is None else {"reference_input": True, "feedforward": feedforward}),
        # a fixed delay at the measurement time: the controller's error is the true error of t_{k-d}
        lagged_settling=tracked is not None and varying is None and tracked.error_time is ErrorTime.MEASUREMENT,
        law=law,
    )
    if tracked is not None and not found.compiled_code:
        tracked.check_rows()  # a bad reference is named first, as when it was checked before the engine
        raise CodegenError("reference: tracking needs the compiled engine (install a C compiler: gcc or cc, or set CC)")
    if streamed is not None and not found.compiled_code:
        raise CodegenError(
            "disturbance: a per-sample torque needs the compiled engine (install a C compiler: gcc or cc, or set CC)"
        )
    stop = None
    if progress is not None:

        def stop(done: int) -> bool:
            progress(done, n)
            return False

    output = found.run(
        x0,
        rule.initial_memory(delay_samples=d),
        history_rows,
        gain,
        np.array(rule.parameters()),
        n,
        spacecraft=spacecraft,
        keep_every=keep,
        workspace=found.workspace(n, switches=True),
        switch_limit=n if keep == 1 else SWITCH_LIMIT,
        stop=stop,
        flight_options=options,
        sensor=sensor,
        delay=varying,
        rate=rate,
        **({} if streamed is None else {"disturbance": streamed}),
        **({} if tracked is None else {"reference": tracked}),
        settling=settling,
    )
    common = dict(
        spacecraft=spacecraft,
        K=readonly(gain),
        tau=float(tau),
        rate=rate,
        delay_samples=d,
        rule=rule,
        history=history_value,
        substeps=substeps,
        t_final=t_final,
        x0=readonly(x0),
        predictor=checked,
        settling_attitude=settle_attitude,
        settling_rate=settle_rate,
    )
    if tracked is None:
        return assemble_run(output, n=n, keep_every=keep, common=common)
    common.update(error_time=tracked.error_time, feedforward=feedforward)
    return assemble_run(output, n=n, keep_every=keep, common=common, pointing_tolerance=pointing_tolerance)


def _common(
    spacecraft: Spacecraft,
    gain: np.ndarray,
    tau: float,
    rate: float,
    d: int,
    rule: SwitchingRule,
    history: Any,
    substeps: int,
    t_final: float,
    x0: np.ndarray,
    predictor: Any,
) -> dict[str, Any]:
    return dict(
        spacecraft=spacecraft,
        K=readonly(gain),
        tau=float(tau),
        rate=rate,
        delay_samples=d,
        rule=rule,
        history=history,
        substeps=substeps,
        t_final=t_final,
        x0=readonly(x0),
        predictor=predictor,
    )


def settling_tolerances(settling_attitude: Any, settling_rate: Any) -> tuple[float, float, tuple[float, float]]:
    """(attitude (deg), rate (rad/s), their squared bounds (|σ|², |ω|²)): the checked settling tolerances."""
    attitude = finite_scalar("settling_attitude", settling_attitude)
    if not 0.0 < attitude <= 180.0:
        raise SpecificationError(
            f"settling_attitude (principal-angle tolerance, deg) must be in (0, 180], got {attitude}"
        )
    rate = positive_scalar("settling_rate", settling_rate)
    return attitude, rate, settling_bounds(attitude, rate)
