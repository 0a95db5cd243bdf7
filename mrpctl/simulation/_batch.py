"""``simulate_batch``: many runs on the lanes or the scalar engine, on a thread pool."""

from __future__ import annotations

import functools
import logging
import os
import queue
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_EXCEPTION, ThreadPoolExecutor, wait
from typing import Any

import numpy as np

from mrpctl._compile import find_compiler
from mrpctl._validation import finite_array, integer, positive_scalar, readonly
from mrpctl.conventions import initial_state
from mrpctl.engines import lanes as lane_engines
from mrpctl.engines.common import RunOutput
from mrpctl.engines.lanes import DEFAULT_WIDTH
from mrpctl.engines.scalar import engine, rule_key, slice_samples, tracking_memory, wheel_engine
from mrpctl.engines.stats import SETTLING_ATTITUDE_DEG, SETTLING_OMEGA, STATS_SIZE
from mrpctl.errors import CodegenError, DimensionError, SpecificationError
from mrpctl.flight import (
    FLIGHT_MEMORY_SIZE,
    ActuatorModel,
    DelayModel,
    Disturbance,
    Hysteretic,
    Saturation,
    SensorModel,
)
from mrpctl.flight.steering import SteeringLaw, check_law
from mrpctl.flight.tracking import DEFAULT_POINTING_TOLERANCE, ErrorTime, ReferenceStream
from mrpctl.loop import check_rule, check_substeps, delay_samples, inertia_input
from mrpctl.loop.options import (
    NO_FLIGHT_OPTIONS,
    as_disturbance,
    check_predictor,
    flight_constants,
    flight_memory,
    flight_options,
    flight_structure,
    gravity_gradient_options,
    predictor_constants,
    predictor_disturbance,
    predictor_memory,
    varying_delay,
)
from mrpctl.loop.wheels import wheel_memory, wheel_memory_roots
from mrpctl.model import INPUT_SIZE, STATE_SIZE
from mrpctl.predictor import Predictor, PredictorForm
from mrpctl.simulation._batch_inputs import (
    SHARED_HINT,
    batch_gains,
    broadcast,
    each_run_models,
    each_run_reference,
    per_run_disturbances,
    shared_saturation,
)
from mrpctl.simulation._budget import (
    SWITCH_LIMIT,
    batch_run_bytes,
    check_keep_every,
    check_memory,
    jitter_bytes,
    lane_bytes,
    lane_stream_bytes,
    memory_limit_bytes,
    sample_horizon,
    workspace_bytes,
)
from mrpctl.simulation._guards import check_step_rotation
from mrpctl.simulation._simulate import engine_structure, measurement_history, settling_tolerances, streamed_disturbance
from mrpctl.simulation._wheels import (
    check_wheel_run,
    wheel_record,
    wheel_result,
)
from mrpctl.simulation.results import BatchResult, SimulationResult, assemble_batch, assemble_run
from mrpctl.spacecraft import Spacecraft, check_spacecraft
from mrpctl.switching import SwitchingRule
from mrpctl.wheels import WheelCluster

#: Metrics-only batches (``trajectories=False``) of compiled code run on the lane engine
#: (`mrpctl.engines.lanes`); False runs them on the scalar engine (tests, benchmarks).
_LANES = True
_LOGGER = logging.getLogger(__name__)


def _threads(threads: Any) -> int:
    if threads is None:
        return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return integer("threads", threads, minimum=1)


def simulate_batch(
    spacecraft: Spacecraft | Sequence[Spacecraft],
    K: Any,
    x0: Any = None,
    *,
    tau: Any,
    rule: SwitchingRule | Sequence[SwitchingRule],
    t_final: float,
    rate: float = 1000.0,
    history: Any = "constant",
    substeps: int = 1,
    trajectories: bool = False,
    keep_every: int | None = 1,
    threads: int | None = None,
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
    switches: bool = False,
    law: SteeringLaw | None = None,
    sigma0: Any = None,
    omega0: Any = None,
    gravity_gradient: Any = None,
    sensors: Any = None,
    estimator: Any = None,
) -> BatchResult:
    """Simulate many runs at once on several threads.

    Compiled runs are spread over a pool of worker threads, each with its own buffers
    (reused from run to run), calling the generated library slice by slice; Ctrl-C (or an
    exception from ``progress``) sets a stop flag that the workers check between slices.
    Without ``trajectories`` the runs go to the lane engine (`mrpctl.engines.lanes`): the
    same sample vectorised across runs, W = 8 runs per C call, each run's metrics bit for bit
    those of the scalar engine (about 5x its runs/s per core; ``design/lanes.md``).
    Without a C compiler the runs are evaluated one after the other in CasADi's virtual
    machine.

    Any of ``spacecraft``, ``x0``, ``K``, ``tau`` and ``rule`` may be given once (shared)
    or once per run.

    Parameters
    ----------
    spacecraft : Spacecraft or sequence of Spacecraft
        The plant, or one per run.
    K : array_like, PDGains or sequence of PDGains
        (3, 6) or (N, 3, 6) gains on x = [σ; ω/4], or physical gains
        ([`PDGains`][mrpctl.conventions.PDGains], one or one per run; K = [−P_σ, −4 P_ω], exact).
    x0 : array_like, optional
        (6,) or (N, 6) initial states x = [σ; ω/4]; or give ``sigma0`` and ``omega0`` instead.
    tau : float or array_like, keyword-only
        Delay(s) (s), each a whole number of periods 1/rate; runs of the same structure
        (spacecraft, delay) share one compiled engine.
    rule : SwitchingRule or sequence of SwitchingRule, keyword-only
        One rule, or one per run (their parameters, such as ε, may differ).
    t_final, rate, history, substeps
        As in [`simulate`][mrpctl.simulation.simulate]; ``history`` is shared by all runs (an array is allowed
        only when all runs have the same delay).
    trajectories : bool, keyword-only
        Also return every run as a [`SimulationResult`][mrpctl.SimulationResult] (memory: about 104 bytes per
        kept sample and run).
    keep_every : int or None, keyword-only
        With ``trajectories``, the samples kept per run, as in [`simulate`][mrpctl.simulation.simulate].
    threads : int, keyword-only
        Worker threads; default: the CPUs available to this process.
    memory_limit : float, keyword-only
        As in [`simulate`][mrpctl.simulation.simulate], for all the runs kept.
    progress : callable, keyword-only
        ``progress(samples_done, samples_total)``, called from the calling thread while
        the workers run; an exception raised by it stops the batch and propagates.

    actuator, sensor, delay : keyword-only
        The flight loop's models (as in [`simulate`][mrpctl.simulation.simulate]), shared by every run, or a list
        or tuple of N (one per run, each a model or None: its own limits, noise levels, gyro bias and noise seed,
        its own jitter seed; the actuators of one call share their saturation mode); each rule
        must then be a [`mrpctl.flight.Hysteretic`][mrpctl.flight.Hysteretic]. Without trajectories flight runs take
        the lane engine too (noise and jitter streamed per slice, shared by the lanes; with per-run sensors or
        delays each lane is streamed its own run's noise rows and newest-arrived schedule), each run bit
        for bit [`simulate`][mrpctl.simulation.simulate] with its own models; the result then has
        ``saturated_fraction`` and ``peak_command``.
    disturbance : keyword-only
        The body-frame torque w (N m), shared by every run in any form [`simulate`][mrpctl.simulation.simulate] takes
        (constant (3,), (n, 3) rows, ``Disturbance(function=w)`` of the sample times), or one per
        run: a list or tuple of N items, each None, a [`mrpctl.flight.Disturbance`][mrpctl.flight.Disturbance] or a
        NumPy
        array ((3,) or (n, 3)), or a (N, n, 3) array. Nothing of size (N, n, 3) is made that was not
        given: a shared per-sample torque is evaluated slice by slice (a function on the slice's
        times) and streamed, a given (N, n, 3) array is read through views. Each run equals
        [`simulate`][mrpctl.simulation.simulate] with its own disturbance bit for bit. Metrics-only runs take the lane
        engine, a shared torque's rows streamed beside the noise, per-run torques as a per-lane
        stream.
    predictor : mrpctl.Predictor, keyword-only
        The predictor controller (as in [`simulate`][mrpctl.simulation.simulate]), shared by every run; each rule must
        then be a [`mrpctl.OnPredicted`][mrpctl.predictor.OnPredicted]. Metrics-only predictor runs take the lane
        engine (τ and the model's inertia per-lane constants, the delayed measurements and model states in the lane
        driver's ring; one lane group per delay and structure: a sensor given, an actuator given; each run's sensor
        noise shared or its own), bit for bit the scalar engine's; with ``trajectories``, ``switches`` or a
        ``reference`` the scalar engine on the thread pool. ``disturbance`` is taken in every form above
        (shared or per run), each run streaming its own rows.
    wheels : mrpctl.wheels.WheelCluster, keyword-only
        Every run on this wheel cluster (as in [`simulate`][mrpctl.simulation.simulate]; ``rule=Hysteretic(...)``,
        no ``actuator``, no ``predictor``; ``law`` taken): metrics-only runs take the wheel lane engine (per-run
        sensors and delays as above, each lane its own noise and jitter), with ``trajectories`` the scalar engine
        on the thread pool, and the result's ``wheels`` holds each run's wheel
        metrics (and, with ``trajectories``, its wheel speeds and torques).
    reference : keyword-only
        Track a reference (as in [`simulate`][mrpctl.simulation.simulate]; every rule a
        [`Hysteretic`][mrpctl.flight.Hysteretic]): one reference shared by the runs (an (n, 9) array, read
        through views, or an object with ``samples(t)``), or a list of N of them, one per run. Metrics-only runs
        take the lane engine: a shared reference's rows streamed beside the noise and a shared torque,
        per-run references (or a shared one beside per-run torques) a per-lane stream of each run's rows; each
        run equals [`simulate`][mrpctl.simulation.simulate] with its reference bit for bit. The batch's
        ``settling_time`` and ``max_sigma`` are then those of the true error σ_B/R, ω_B/R; the pointing metrics
        are in ``runs`` (``trajectories=True``).
    error_time, feedforward, pointing_tolerance : keyword-only
        As in [`simulate`][mrpctl.simulation.simulate], shared by the runs.

    settling_attitude : float, keyword-only
        Attitude tolerance of "settled": the principal angle Φ (deg) with |σ| = tan(Φ/4), in (0, 180];
        default 4 atan(1e-2) = 2.2918° (|σ| < 1e-2).
    settling_rate : float, keyword-only
        Rate tolerance of "settled": |ω| below this (rad/s), > 0; default 1e-3. Both are run-time
        constants of the compiled sample (no recompilation); the result records them.
    switches : bool, keyword-only
        Also keep every run's switch indices (``BatchResult.switch_indices``; at most 2**20 per run, the
        counts stay exact) without the trajectories: the runs then take the scalar engine on the thread
        pool, not the lanes (the same metrics bit for bit). With ``trajectories`` they are kept anyway.
    law : mrpctl.flight.steering.SteeringLaw, keyword-only
        The flight loop's steering law (as in [`simulate`][mrpctl.simulation.simulate]), shared by every run;
        on an ideal torque such runs take the scalar engine (on the thread pool), also when ``trajectories`` is
        False; on ``wheels`` metrics-only runs take the wheel lane engine (the law compiled in).
    gravity_gradient : mrpctl.guidance.CircularOrbit or NadirPointing, keyword-only
        The gravity-gradient torque of this orbit in every run's plant (as in [`simulate`][mrpctl.simulation.simulate];
        every rule a [`Hysteretic`][mrpctl.flight.Hysteretic]), the orbit shared by the runs. Metrics-only runs take
        the lane engine (the orbit's constants a per-lane constant), each run bit for bit
        [`simulate`][mrpctl.simulation.simulate]'s.
    sigma0, omega0 : array_like, keyword-only
        The initial states in physical form instead of ``x0``: (3,) or (N, 3) MRPs σ₀ and (3,) or
        (N, 3) body rates ω₀ (rad/s; default zero), broadcast against each other; each run is bit
        for bit the one of x0 = [σ₀; ω₀/4].
    sensors, estimator : keyword-only
        Refused: the estimated loop (``simulate(..., sensors=..., estimator=...)``) flies one case per compiled
        call, not lanes of runs; call it once per run.

    Returns
    -------
    BatchResult
    """
    if sensors is not None or estimator is not None:
        raise SpecificationError(
            "sensors, estimator: simulate_batch does not fly the estimated loop (its compiled run flies one case "
            "per call, not lanes of runs); call simulate(..., sensors=Sensors(..., seed=s), estimator=...) once "
            "per run, or mrpctl.simulation.estimated.simulate_estimated"
        )
    settle_attitude, settle_rate, settling = settling_tolerances(settling_attitude, settling_rate)
    if not isinstance(switches, bool):
        raise SpecificationError(f"switches must be True or False, got {switches!r}")
    crafts = (spacecraft,) if isinstance(spacecraft, Spacecraft) else tuple(spacecraft)
    if not crafts:
        raise SpecificationError("spacecraft: give a Spacecraft or a non-empty sequence of them")
    for i, each in enumerate(crafts):
        check_spacecraft(each, "spacecraft" if len(crafts) == 1 else f"spacecraft[{i}]")
    states = initial_state(x0, sigma0, omega0, batch=True).reshape(-1, STATE_SIZE)
    gains = batch_gains(K)
    if gains.shape == (INPUT_SIZE, STATE_SIZE):
        gains = gains[None]
    if gains.ndim != 3 or gains.shape[1:] != (INPUT_SIZE, STATE_SIZE):
        raise DimensionError(f"K: expected shape (3, 6) or (N, 3, 6) but found {gains.shape}")
    delays = np.atleast_1d(finite_array("tau", tau))
    if delays.ndim != 1:
        raise DimensionError(f"tau: expected a scalar or shape (N,) but found {delays.shape}")
    rules = (rule,) if isinstance(rule, SwitchingRule) else tuple(rule)
    if not rules:
        raise SpecificationError("rule: give a switching rule or a non-empty sequence of rules")
    for one in rules:
        check_rule(one)
    given: tuple[Any, ...] = (actuator, sensor, delay)
    models = [len(value) for value in given if isinstance(value, list | tuple)]  # per run
    n_runs = max(len(states), len(gains), len(delays), len(rules), len(crafts), *models)
    if len(states) == 0:
        raise DimensionError("x0: expected at least one initial state (shape (6,) or (N, 6)) but found none")
    for name, count in (
        ("spacecraft", len(crafts)),
        ("x0", len(states)),
        ("K", len(gains)),
        ("tau", len(delays)),
        ("rule", len(rules)),
    ):
        broadcast(name, count, n_runs)
    states = np.broadcast_to(states, (n_runs, STATE_SIZE))
    gains = np.broadcast_to(gains, (n_runs, INPUT_SIZE, STATE_SIZE))
    delays = np.broadcast_to(delays, (n_runs,))
    rules = rules * n_runs if len(rules) == 1 else rules
    crafts = crafts * n_runs if len(crafts) == 1 else crafts
    if wheels is not None:
        for pair in {(id(c), id(r)): (c, r) for c, r in zip(crafts, rules, strict=True)}.values():
            wheels = check_wheel_run(
                wheels, pair[0], pair[1], predictor=predictor,
                actuator=next((one for one in actuator if one is not None), None) if isinstance(actuator, list | tuple)
                else actuator,
            )  # fmt: skip
        if reference is not None:
            raise SpecificationError(
                "wheels: tracking a reference on a wheel cluster is not modelled yet; track with an ideal body "
                "torque (actuator=ActuatorModel(...)) or regulate on the wheels (reference=None)"
            )
    rate = positive_scalar("rate", rate)
    t_final, n = sample_horizon(t_final, rate)
    substeps = check_substeps(substeps)
    check_step_rotation(states, rate, substeps)
    threads = _threads(threads)
    keep = check_keep_every(keep_every) if trajectories else None
    limit = memory_limit_bytes(memory_limit)
    # what the runs need whatever their delays, checked before any per-run object is made (30 million runs took
    # 9 GB and 109 s of those before the refusal)
    check_memory(
        n_runs * batch_run_bytes(n, keep, trajectories, records=False), limit, t_final=t_final, keep_every=keep,
        runs=n_runs,
    )  # fmt: skip
    samples_by_run = [delay_samples(value, rate) for value in delays]
    if not isinstance(history, str) and len(set(samples_by_run)) > 1:
        raise SpecificationError("history: an array history needs all runs to have the same tau")
    histories = [measurement_history(history, states[i], samples_by_run[i]) for i in range(n_runs)]
    workers = min(threads, n_runs)
    width = 1 if predictor is None else 2
    records = trajectories and (
        predictor is not None or reference is not None or any(isinstance(one, Hysteretic) for one in rules)
    )
    estimate = workers * workspace_bytes(n, max(samples_by_run), substeps, width)
    estimate += n_runs * batch_run_bytes(n, keep, trajectories, records=records)
    if not trajectories and _LANES:
        estimate += lane_bytes(n_runs, max(samples_by_run), workers)
    check_memory(estimate, limit, t_final=t_final, keep_every=keep, runs=n_runs)

    saturation = Saturation.SCALE
    actuators, _ = each_run_models("actuator", actuator, ActuatorModel, n_runs)
    sensors, per_run_sensor = each_run_models("sensor", sensor, SensorModel, n_runs)
    delay_models, per_run_delay = each_run_models("delay", delay, DelayModel, n_runs)
    mode = shared_saturation(actuators)
    per_run_models = isinstance(actuator, list | tuple) or per_run_sensor or per_run_delay
    if per_run_models:  # each worker's per-lane noise rows and schedules of one slice
        estimate += lane_stream_bytes(
            n, max(samples_by_run), substeps, workers, noise=per_run_sensor, jitter=per_run_delay
        )
        check_memory(estimate, limit, t_final=t_final, keep_every=keep, runs=n_runs)
    checked = None
    delay_model = next((m for m in delay_models if m is not None), None)
    for index, one in enumerate(rules):  # every run's rule; the compiler once (it is a search of PATH)
        checked = check_predictor(predictor, one, history, delay_model, compiled=index == 0)
    tracked_by_run = each_run_reference(
        reference, error_time, feedforward, pointing_tolerance, rules, checked, n, rate, samples_by_run
    )
    feedforward = feedforward is True
    law = check_law(law, rules, gains, predictor=checked)
    per_run = per_run_disturbances(disturbance, n_runs, n)
    shared = per_run is None
    hint = SHARED_HINT if shared and isinstance(disturbance, list | tuple) else ""
    if shared and disturbance is not None and not isinstance(disturbance, Disturbance) and checked is None:
        disturbance = as_disturbance(disturbance)  # checked and copied once, shared by the runs
    items = [disturbance] * n_runs if per_run is None else per_run
    options_by_run: list[np.ndarray | None] = [None] * n_runs
    streamed_by_run: list[Disturbance | None] = [None] * n_runs
    predictor_by_run: list[np.ndarray | None] = [None] * n_runs  # the predictor sample's constants per run
    if checked is None:
        orbit_rows: dict[bytes | None, np.ndarray | None] = {}  # by the run's flight constants
        for i, one in enumerate(rules):  # every rule must be the flight rule when an option is given
            options_by_run[i], saturation = flight_options(one, actuators[i], items[i], sensors[i])
            if gravity_gradient is not None:  # the orbit's constants after the flight constants, shared by the runs
                constants = options_by_run[i]
                row_key = None if constants is None else constants.tobytes()
                if row_key not in orbit_rows:
                    orbit_rows[row_key] = gravity_gradient_options(
                        gravity_gradient, one, constants, period=1.0 / rate, substeps=substeps, wheels=wheels
                    )
                options_by_run[i] = orbit_rows[row_key]
            streamed_by_run[i] = (
                streamed_disturbance(items[i], n, "disturbance" if shared else f"disturbance[{i}]", hint)
                if (i == 0 or not shared)
                else streamed_by_run[0]
            )
        made_delays: dict[tuple[int, int], DelayModel | None] = {}  # by (model, d): alive during the call
        varying = []
        for i in range(n_runs):
            delay_key = (id(delay_models[i]), samples_by_run[i])
            if delay_key not in made_delays:
                made_delays[delay_key] = varying_delay(rules[i], delay_models[i], samples_by_run[i], rate, n)
            varying.append(made_delays[delay_key])
        # the driver's arrival ring: one per worker (one delay model at a time)
        jitter = max(jitter_bytes(model, max(samples_by_run)) for model in made_delays.values())
        check_memory(estimate + workers * jitter, limit, t_final=t_final, keep_every=keep, runs=n_runs)
    else:  # the predictor: shared or per-run torques (constant or per sample), as the flight loop takes them
        gravity_gradient_options(  # refused with a predictor
            gravity_gradient, rules[0], None, period=1.0 / rate, substeps=substeps, predictor=checked
        )
        for i in range(n_runs):
            if i == 0 or not shared or per_run_models:
                item = predictor_disturbance(items[i], n, "disturbance" if shared else f"disturbance[{i}]")
                options_by_run[i], saturation = flight_constants(actuators[i], item, sensors[i])
                streamed_by_run[i] = None if item is None or item.constant else item
            else:
                options_by_run[i], streamed_by_run[i] = options_by_run[0], streamed_by_run[0]
        varying = [None] * n_runs
        made: dict[tuple[int, float], np.ndarray] = {}  # by (id of the run's constants, tau): alive during the call
        for i in range(n_runs):
            made_key = (id(options_by_run[i]), float(delays[i]))
            if made_key not in made:
                made[made_key] = predictor_constants(options_by_run[i], float(delays[i]), checked.model)
            predictor_by_run[i] = made[made_key]
    saturation = saturation if mode is None else mode  # the runs' shared mode (a run without actuator: any)
    if any(each is not None for each in streamed_by_run):
        if find_compiler() is None:
            raise CodegenError(
                "disturbance: a per-sample torque needs the compiled engine "
                "(install a C compiler: gcc or cc, or set CC)"
            )

        # each worker's torque rows of one slice (the lanes: W runs' rows side by side)
        rows = INPUT_SIZE * (1 if trajectories or checked is not None else DEFAULT_WIDTH)
        check_memory(
            estimate + workers * min(slice_samples(substeps), n) * rows * 8,
            limit,
            t_final=t_final,
            keep_every=keep,
            runs=n_runs,
        )

    stats = np.full((n_runs, STATS_SIZE), np.nan)
    # the flight rule's and the predictor's runs keep the actuator's accumulators (the predictor's memory begins
    # with the flight sample's FLIGHT_MEMORY_SIZE entries)
    any_flight = checked is not None or any(isinstance(one, Hysteretic) for one in rules)
    flight_rows = np.full((n_runs, FLIGHT_MEMORY_SIZE), np.nan) if any_flight else None
    scalar_runs = list(range(n_runs))
    wheel_rows = None if wheels is None else np.full((n_runs, FLIGHT_MEMORY_SIZE + 4 * wheels.count + 1), np.nan)
    if reference is not None and find_compiler() is None:
        raise CodegenError("reference: tracking needs the compiled engine (install a C compiler: gcc or cc, or set CC)")
    lanes_take_law = law is None or wheels is not None  # the flight sample's law is not on the lanes (not done)
    # the predictor tracking a reference stays on the scalar engine (its lane form is not done)
    lanes_take_predictor = checked is None or reference is None
    on_lanes = not trajectories and not switches and _LANES and lanes_take_predictor and lanes_take_law
    if on_lanes and find_compiler() is not None:
        scalar_runs = _run_lanes(
            stats,
            flight_rows,
            crafts=crafts,
            rules=rules,
            samples_by_run=samples_by_run,
            states=states,
            gains=gains,
            history=history,
            histories=histories,
            n=n,
            rate=rate,
            substeps=substeps,
            threads=threads,
            progress=progress,
            flight=(options_by_run, saturation, sensors, varying),
            torques=(streamed_by_run, shared),
            wheels=None if wheels is None or wheel_rows is None else (wheels, wheel_rows),
            tracking=(tracked_by_run, feedforward, isinstance(reference, list | tuple)),
            settling=settling,
            law=law,
            gravity_gradient=gravity_gradient is not None,
            predicted=None if checked is None else (checked, predictor_by_run, actuators),
        )

    by_structure: dict[tuple[Any, ...], Any] = {}  # objects alive during the call: id() is safe
    engines: dict[int, Any] = {}
    for i in scalar_runs:
        structure = engine_structure(
            checked, options_by_run[i], sensors[i], actuators[i], gravity_gradient=gravity_gradient is not None
        )
        torque_input = streamed_by_run[i] is not None
        tracked = tracked_by_run[i]
        tracking = tracked is not None
        # a fixed delay at the measurement time: the controller's error is the true error of t_{k-d}
        lagged = tracked is not None and varying[i] is None and tracked.error_time is ErrorTime.MEASUREMENT
        key = (
            id(crafts[i]),
            id(rules[i]),
            samples_by_run[i],
            tuple(sorted(structure.items())),
            torque_input,
            tracking,
            lagged,
        )
        if key not in by_structure and wheels is not None:
            by_structure[key] = wheel_engine(
                crafts[i],
                rules[i],
                samples_by_run[i],
                1.0 / rate,
                substeps,
                wheels=wheels,
                sensor=structure["sensor"],
                disturbed=structure["disturbed"],
                torque_input=torque_input,
                law=law,
            )  # (wheels with the gravity gradient are refused above)
        if key not in by_structure:
            by_structure[key] = engine(
                crafts[i],
                rules[i],
                samples_by_run[i],
                1.0 / rate,
                substeps,
                saturation,
                predictor=None if checked is None else checked.model,
                predictor_form=PredictorForm.NONLINEAR if checked is None else checked.form,
                **structure,
                **({"torque_input": True} if torque_input else {}),
                **({} if tracked_by_run[i] is None else {"reference_input": True, "feedforward": feedforward}),
                lagged_settling=lagged,
                law=law,
            )
        engines[i] = by_structure[key]
    outputs: list[RunOutput | None] = [None] * n_runs
    stop_flag = threading.Event()
    done_samples = [0] * workers
    work: queue.SimpleQueue[int] = queue.SimpleQueue()
    for i in scalar_runs:
        work.put(i)

    def worker(slot: int) -> None:
        spaces: dict[int, Any] = {}
        previous = 0

        def stop(done: int) -> bool:
            done_samples[slot] = previous + done
            return stop_flag.is_set()

        while not stop_flag.is_set():
            try:
                i = work.get_nowait()
            except queue.Empty:
                return
            found = engines[i]
            space = spaces.get(id(found))
            if space is None:
                space = spaces[id(found)] = found.workspace(n, switches=trajectories or switches)
            d = samples_by_run[i]
            outputs[i] = found.run(
                states[i],
                rules[i].initial_memory(delay_samples=d),
                histories[i][0],
                gains[i],
                np.array(rules[i].parameters()),
                n,
                spacecraft=crafts[i],
                keep_every=keep,
                workspace=space,
                switch_limit=n if keep == 1 else SWITCH_LIMIT,
                stop=stop,
                flight_options=options_by_run[i] if checked is None else predictor_by_run[i],
                sensor=sensors[i],
                delay=varying[i],
                rate=rate,
                **({} if streamed_by_run[i] is None else {"disturbance": streamed_by_run[i]}),
                **({} if tracked_by_run[i] is None else {"reference": tracked_by_run[i]}),
                settling=settling,
            )
            previous += n
            done_samples[slot] = previous

    if scalar_runs:
        compiled = all(each.compiled_code for each in engines.values())
        count = workers if compiled else 1  # the virtual machine: one run after the other
        jobs: list[Callable[[], None]] = [functools.partial(worker, slot) for slot in range(count)]
        _run_polled(jobs, progress, done_samples, n * len(scalar_runs), stop_flag, count)
        for i in scalar_runs:
            output = outputs[i]
            assert output is not None
            stats[i] = output.stats
            if flight_rows is not None and output.memory is not None and output.memory.size >= FLIGHT_MEMORY_SIZE:
                flight_rows[i] = output.memory[:FLIGHT_MEMORY_SIZE]
            if wheel_rows is not None and output.memory is not None:
                wheel_rows[i] = output.memory

    indices: tuple[np.ndarray, ...] | None = None
    if switches and not trajectories:
        kept = [outputs[i] for i in range(n_runs)]
        indices = tuple(
            readonly(np.zeros(0) if o is None or o.switch_indices is None else o.switch_indices, np.int64) for o in kept
        )
    runs: list[SimulationResult] | None = None
    if trajectories:
        runs = []
        for i, output in enumerate(outputs):
            assert output is not None
            stream = tracked_by_run[i]
            runs.append(
                assemble_run(
                    output,
                    n=n,
                    keep_every=keep,
                    common=dict(
                        spacecraft=crafts[i],
                        K=readonly(gains[i]),
                        tau=float(delays[i]),
                        rate=rate,
                        delay_samples=samples_by_run[i],
                        rule=rules[i],
                        history=histories[i][1],
                        substeps=substeps,
                        t_final=t_final,
                        x0=readonly(states[i]),
                        predictor=checked,
                        **({} if stream is None else {"error_time": stream.error_time, "feedforward": feedforward}),
                        settling_attitude=settle_attitude,
                        settling_rate=settle_rate,
                    ),
                    pointing_tolerance=None if stream is None else float(pointing_tolerance),
                )
            )
    wheel_records = None
    if wheels is not None:
        cluster = wheels
        if runs is not None:
            runs = [wheel_result(run, outputs[i], cluster, rate=rate) for i, run in enumerate(runs)]
            wheel_records = tuple(run.wheels for run in runs if run.wheels is not None)
        else:
            assert wheel_rows is not None
            wheel_records = tuple(wheel_record(row, None, cluster, rate=rate, kept=0) for row in wheel_rows)
    return assemble_batch(
        stats,
        n=n,
        rate=rate,
        runs=runs,
        flight_memory=flight_rows,
        wheels=wheel_records,
        common=dict(
            x0=readonly(states),
            K=readonly(gains),
            tau=readonly(delays),
            rules=tuple(rules),
            spacecraft=tuple(crafts),
            t_final=t_final,
            substeps=substeps,
            history=history if isinstance(history, str) else readonly(history),
            settling_attitude=settle_attitude,
            settling_rate=settle_rate,
            switch_indices=indices if runs is None else tuple(run.switch_indices for run in runs),
        ),
    )


def _run_lanes(
    stats: np.ndarray,
    flight_rows: np.ndarray | None,
    *,
    crafts: Sequence[Spacecraft],
    rules: Sequence[SwitchingRule],
    samples_by_run: list[int],
    states: np.ndarray,
    gains: np.ndarray,
    history: Any,
    histories: list[tuple[np.ndarray, Any]],
    n: int,
    rate: float,
    substeps: int,
    threads: int,
    progress: Callable[[int, int], Any] | None,
    flight: tuple[list[np.ndarray | None], Saturation, list[SensorModel | None], list[DelayModel | None]],
    torques: tuple[list[Disturbance | None], bool],
    wheels: tuple[WheelCluster, np.ndarray] | None = None,
    tracking: tuple[list[ReferenceStream | None], bool, bool] | None = None,
    settling: tuple[float, float] | None = None,
    law: SteeringLaw | None = None,
    gravity_gradient: bool = False,
    predicted: tuple[Predictor, list[np.ndarray | None], list[ActuatorModel | None]] | None = None,
) -> list[int]:
    """Run the metrics-only batch on the lane engine, one packed group per structure (inertia
    layout, rule expressions, d, a torque stream; the flight sample specialised to the union of its
    runs' `flight_structure`), W runs per C call, the batches on the thread
    pool; write the rows of ``stats`` (and of ``flight_rows``: the flight sample's memory).
    ``flight`` is the flight loop's (per-run constants, saturation, per-run sensor, per-run varying delay: a
    group whose runs differ in them streams each lane its own noise rows and schedule),
    ``torques`` the per-run per-sample disturbances and whether one is shared by all runs (then
    streamed beside the noise; else each lane is streamed its run's rows). Returns the runs left
    to the scalar engine (a rule without lane form). ``wheels``: every run on this wheel cluster
    (`wheel_lane_engine`: one library per spacecraft inertia), the memory rows written into the array beside it.
    ``tracking``: each run's reference, the feedforward and
    whether the references are per run (then, or beside per-run torques, each lane is streamed its own rows;
    a shared one is streamed beside the noise). ``law``: the wheel runs' steering law (the wheel lanes take it).
    ``gravity_gradient``: the runs' plant flies the gravity-gradient torque (the orbit's constants at the end of
    each run's flight constants). ``predicted``: the runs fly the predictor (its model, each run's predictor
    constants, each run's actuator), a group per structure (a sensor given, an actuator given)."""
    options_by_run, saturation, sensors, varying = flight
    streamed_by_run, shared = torques
    tracked_by_run, feedforward, per_run_reference = (
        ([None] * len(crafts), False, False) if tracking is None else tracking
    )

    groups: dict[Any, list[int]] = {}
    keys: dict[tuple[int, int, int, bool], Any] = {}  # objects alive during the call: id() is safe
    left: list[int] = []
    for i in range(len(crafts)):
        own_torque = streamed_by_run[i] is not None and not shared  # streamed per lane
        memo = (id(crafts[i]), id(rules[i]), samples_by_run[i], own_torque)
        key = keys.get(memo)
        if key is None:
            d = samples_by_run[i]
            key = keys[memo] = (inertia_input(crafts[i]), type(rules[i]), rule_key(rules[i], d), d, own_torque)
            if wheels is not None:  # J is a constant of a wheel library
                key += (crafts[i].inertia.tobytes(),)
            if tracked_by_run[i] is not None:  # a shared reference: the group's; per run: one per lane
                key += (None if per_run_reference or own_torque else id(tracked_by_run[i]),)
        if predicted is not None:  # the predictor sample's structure: a sensor given, an actuator given
            key += (sensors[i] is not None, predicted[2][i] is not None)
        groups.setdefault(key, []).append(i)
    packs: list[tuple[list[int], lane_engines.LaneBatches]] = []
    step = slice_samples(substeps)
    for members in groups.values():
        first = members[0]
        d = samples_by_run[first]
        if predicted is not None:
            try:
                packed = _predictor_batches(
                    members, predicted, crafts, states, gains, rules, flight, torques, d=d, n=n, rate=rate,
                    substeps=substeps, threads=threads, settling=settling,
                )  # fmt: skip
            except CodegenError as error:
                _LOGGER.info("the scalar engine runs %d predictor runs: %s", len(members), error)
                left.extend(members)
                continue
            packs.append((members, packed))
            continue
        is_flight = isinstance(rules[first], Hysteretic)
        own_torque = is_flight and streamed_by_run[first] is not None and not shared
        torque: Any = streamed_by_run[first] if is_flight else None
        reference: Any = tracked_by_run[first] if is_flight else None
        own_reference = reference is not None and (per_run_reference or own_torque)
        if own_reference:
            reference = [tracked_by_run[i] for i in members]
        if own_torque:
            torque = [streamed_by_run[i] for i in members]
        options = _lane_options(options_by_run, members) if is_flight else None
        sensor, own_sensors = _lane_sensors(sensors, members)
        own_noise = own_sensors is not None
        delay: Any = varying[first]
        if any(varying[i] is not delay for i in members):  # each run its own jitter (or sequence)
            delay = [varying[i] for i in members]
        # each lane's own noise and seeded jitter, drawn and scheduled by the lane driver
        own = is_flight and (own_noise or isinstance(delay, list))  # the wheel sample's too
        if own and own_sensors is None:
            own_sensors = [sensor] * len(members)
        # the group's structure: the union over its runs (flight_structure of their rows), as the scalar engine's
        structure = flight_structure(options, sensor) if is_flight else {}
        try:
            if wheels is not None:
                lanes = lane_engines.wheel_lane_engine(
                    crafts[first],
                    d,
                    1.0 / rate,
                    substeps,
                    wheels=wheels[0],
                    sensor=structure["sensor"],
                    disturbed=structure["disturbed"],
                    torque_input=torque is not None,
                    torque_per_lane=own_torque,
                    law=law,
                    own_streams=own,
                )
            else:
                lanes = lane_engines.lane_engine(
                    crafts[first],
                    rules[first],
                    d,
                    1.0 / rate,
                    substeps,
                    saturation=saturation,
                    torque_input=torque is not None,
                    torque_per_lane=own_torque,
                    **structure,
                    **(
                        {}
                        if reference is None
                        else {
                            "reference_input": True,
                            "feedforward": feedforward,
                            "reference_per_lane": own_reference,
                        }
                    ),
                    **({"gravity_gradient": True} if gravity_gradient and is_flight else {}),
                    **({"own_streams": True} if own else {}),
                )
        except CodegenError as error:
            _LOGGER.info("the scalar engine runs %d runs: %s", len(members), error)
            left.extend(members)
            continue
        if isinstance(history, str) or d == 0:  # one row per run (constant, zero-input; d = 0: unused)
            rows = np.stack([histories[i][0][0] for i in members])[:, :, None]
        else:  # the array history is shared: a view, copied W runs at a time
            rows = np.broadcast_to(histories[first][0].T, (len(members), STATE_SIZE, d))
        if wheels is not None:  # the flight memory, then the wheel speeds and the wheel accumulators at 0
            memory0 = np.array([wheel_memory(flight_memory(states[i], histories[i][0], d), wheels[0]) for i in members])
        elif is_flight:  # h = c = +1 and the sigma seen at k = 0, as Engine.run starts a flight run
            memory0 = np.array([flight_memory(states[i], histories[i][0], d) for i in members])
            if reference is not None:  # the controller's previous MRP is the error σ_B/R it sees at k = 0
                streams = reference if own_reference else [reference] * len(members)
                sigmas = [tracking_memory(row[2:5], stream) for row, stream in zip(memory0, streams, strict=True)]
                memory0[:, 2:5] = sigmas
        else:
            memory0 = np.array([rules[i].initial_memory(delay_samples=d) for i in members], dtype=float)
        packs.append(
            (
                members,
                lane_engines.closed_loop_batches(
                    lanes,
                    states[members],
                    memory0,
                    rows,
                    gains[members],
                    np.array([rules[i].parameters() for i in members], dtype=float),
                    n,
                    spacecraft=[crafts[i] for i in members],
                    threads=threads,
                    slice_samples=step,
                    flight_options=options,
                    sensor=(sensor if own_sensors is None else own_sensors) if is_flight else None,
                    delay=delay if is_flight else None,
                    rate=rate,
                    disturbance=torque,
                    **({} if reference is None else {"reference": reference}),
                    settling=settling,
                ),
            )
        )
    if not packs:
        return left
    work: queue.SimpleQueue[tuple[int, int]] = queue.SimpleQueue()
    for g, (_, packed) in enumerate(packs):
        for b in range(packed.count):
            work.put((g, b))
    units = sum(packed.count for _, packed in packs)
    workers = min(threads, units)
    done_samples = [0] * workers
    stop_flag = threading.Event()

    def worker(slot: int) -> None:
        previous = 0

        def stop(done: int) -> bool:
            done_samples[slot] = previous + done
            return stop_flag.is_set()

        while not stop_flag.is_set():
            try:
                g, b = work.get_nowait()
            except queue.Empty:
                return
            packed = packs[g][1]
            if not packed.run(b, stop):
                return
            previous += packed.lanes(b) * n
            done_samples[slot] = previous

    total = n * sum(len(members) for members, _ in packs)
    jobs: list[Callable[[], None]] = [functools.partial(worker, slot) for slot in range(workers)]
    _run_polled(jobs, progress, done_samples, total, stop_flag, workers)
    for members, packed in packs:
        stats[members] = lane_engines.lane_stats(packed)
        if wheels is not None:  # the wheel sample's memory: the flight sample's ten entries, then the wheels'
            memory = wheel_memory_roots(lane_engines.lane_memory(packed))  # the peaks kept squared: their roots
            wheels[1][members] = memory
            if flight_rows is not None:
                flight_rows[members] = memory[:, :FLIGHT_MEMORY_SIZE]
        elif flight_rows is not None and packed.engine.structure is not None:  # the flight sample's memory
            flight_rows[members] = lane_engines.lane_memory(packed)[:, :FLIGHT_MEMORY_SIZE]
    return left


def _predictor_batches(
    members: list[int],
    predicted: tuple[Predictor, list[np.ndarray | None], list[ActuatorModel | None]],
    crafts: Sequence[Spacecraft],
    states: np.ndarray,
    gains: np.ndarray,
    rules: Sequence[SwitchingRule],
    flight: tuple[list[np.ndarray | None], Saturation, list[SensorModel | None], list[DelayModel | None]],
    torques: tuple[list[Disturbance | None], bool],
    *,
    d: int,
    n: int,
    rate: float,
    substeps: int,
    threads: int,
    settling: tuple[float, float] | None,
) -> lane_engines.LaneBatches:
    """The lane batches of a group of predictor runs of one structure: each run's predictor constants (τ, the
    model's J_m) a per-lane constant, its noise shared or its own, its torque rows shared or its own; the delayed
    entries (m, z) start with z = m = x0 (the constant history), the memory with `predictor_memory`, as the scalar
    engine's run."""
    predictor, constants_by_run, actuators = predicted
    model = predictor.model
    _, saturation, sensors, _ = flight
    streamed_by_run, shared = torques
    first = members[0]
    own_torque = streamed_by_run[first] is not None and not shared
    torque: Any = [streamed_by_run[i] for i in members] if own_torque else streamed_by_run[first]
    sensor, own_sensors = _lane_sensors(sensors, members)
    lanes = lane_engines.predictor_lane_engine(
        crafts[first], inertia_input(model), d, 1.0 / rate, substeps, saturation=saturation,
        sensor=sensors[first] is not None, limited=actuators[first] is not None, torque_input=torque is not None,
        torque_per_lane=own_torque, own_streams=own_sensors is not None, form=predictor.form,
    )  # fmt: skip
    x0 = states[members]
    rows = np.concatenate((x0, x0), axis=1)[:, :, None]  # (m, z) = x0 before t = 0: one column, constant in time
    return lane_engines.closed_loop_batches(
        lanes,
        x0,
        np.array([predictor_memory(state) for state in x0]),
        rows,
        gains[members],
        np.array([rules[i].parameters() for i in members], dtype=float),
        n,
        spacecraft=[crafts[i] for i in members],
        threads=threads,
        slice_samples=slice_samples(substeps),
        flight_options=np.array([constants_by_run[i] for i in members]),
        sensor=sensor if own_sensors is None else own_sensors,
        rate=rate,
        disturbance=torque,
        settling=settling,
    )


def _lane_sensors(
    sensors: list[SensorModel | None], members: list[int]
) -> tuple[SensorModel | None, list[SensorModel | None] | None]:
    """A lane group's sensor for its structure and its noise: the shared one and None; or, when the runs' sensors
    differ, a noisy one of them and the run's sensors (each lane's own noise, drawn by the lane driver), or None and
    None when none of them is noisy (no noise: the gyro biases are in the runs' constants)."""
    first = sensors[members[0]]
    if all(sensors[i] is first for i in members):
        return first, None
    noisy = [one for one in (sensors[i] for i in members) if one is not None and not one.ideal]
    noisy = [one for one in noisy if one.attitude_noise > 0.0 or one.rate_noise > 0.0]
    if not noisy:
        return None, None
    return noisy[0], [sensors[i] for i in members]


def _lane_options(options_by_run: list[np.ndarray | None], members: list[int]) -> np.ndarray | None:
    """The flight constants of a lane group: one shared row, or (members, 10) when they differ by run
    ((members, 20) with the gravity gradient's orbit: no run's row is then None)."""
    rows = [options_by_run[i] for i in members]
    if all(row is rows[0] for row in rows):
        return rows[0]
    return np.array([NO_FLIGHT_OPTIONS if row is None else row for row in rows])


def _run_polled(
    jobs: list[Callable[[], None]],
    progress: Callable[[int, int], Any] | None,
    done_samples: list[int],
    total: int,
    stop_flag: threading.Event,
    count: int,
) -> None:
    """Run ``jobs`` on ``count`` threads; the calling thread waits (so Ctrl-C reaches it),
    calls ``progress`` and, on any exception, sets ``stop_flag`` and waits for the workers
    (each stops within one slice) before re-raising."""
    pool = ThreadPoolExecutor(max_workers=count)
    try:
        futures = [pool.submit(job) for job in jobs]
        reported = -1
        pending = set(futures)
        while pending:
            finished, pending = wait(pending, timeout=0.05, return_when=FIRST_EXCEPTION)
            for future in finished:
                future.result()  # a worker's exception propagates
            if progress is not None:
                done = sum(done_samples)
                if done != reported:
                    reported = done
                    progress(done, total)
    except BaseException:
        stop_flag.set()
        raise
    finally:
        pool.shutdown(wait=True)
