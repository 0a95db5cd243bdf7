"""The campaign's one call into the simulator: dispersed runs in, per-run metrics out.

``simulate_batch`` takes one spacecraft per run (J and J⁻¹ are run-time inputs of the compiled
engine), so a campaign with dispersed inertia compiles one engine per delay, not one per run.

A tracking campaign (a reference per run) also returns the pointing metrics of `POINTING_METRICS`. They
are computed from every sample of the true error σ_B/R, which only a run with its records kept gives
(``simulate_batch(..., trajectories=True, keep_every=1)``, the scalar engine): such runs go in groups
whose kept samples fit in `TRACKING_BATCH_BYTES` (estimated before each call with simulate_batch's own
per-run rule, `mrpctl.simulation.kept_run_bytes`), each group's trajectories dropped once its metrics are read.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np

from mrpctl.campaign.wheels import wheel_metrics
from mrpctl.flight import Disturbance
from mrpctl.flight.steering import SteeringLaw
from mrpctl.predictor import Predictor
from mrpctl.simulation import SETTLING_ATTITUDE_DEG, SETTLING_OMEGA, kept_run_bytes, simulate_batch
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import SwitchingRule
from mrpctl.wheels import WheelCluster

__all__ = ["METRICS", "POINTING_METRICS", "TRACKING_BATCH_BYTES", "flight_keywords", "simulate_runs"]

#: Per-run metrics, in the order they are stored, with their dtype and "missing" value.
METRICS: dict[str, tuple[Any, Any]] = {
    "switch_count": (np.int64, -1),
    "first_switch_time": (np.float64, np.nan),
    "last_switch_time": (np.float64, np.nan),
    "settling_time": (np.float64, np.nan),
    "converged": (np.bool_, False),
    "diverged": (np.bool_, False),
    "max_sigma": (np.float64, np.nan),
    "peak_torque": (np.float64, np.nan),
}

#: A tracking campaign's per-run pointing metrics (besides `METRICS`): Φ_B/R's max and RMS after the settling
#: time (deg), the slew time (s; the first t from which Φ_B/R stays below the pointing tolerance); NaN when
#: the run never settled (never came within the tolerance).
POINTING_METRICS: dict[str, tuple[Any, Any]] = {
    "pointing_max": (np.float64, np.nan),
    "pointing_rms": (np.float64, np.nan),
    "slew_time": (np.float64, np.nan),
}

#: The most bytes of kept samples a tracking campaign holds at once (all its concurrent simulate_batch calls).
TRACKING_BATCH_BYTES = 64e6


def flight_keywords(models: dict[str, Any]) -> dict[str, Any]:
    """A run's flight models (`mrpctl.campaign._task.run_models`) as keywords of
    [`mrpctl.simulate_batch`][mrpctl.simulate_batch]
    and [`mrpctl.simulate`][mrpctl.simulation.simulate]: ``actuator``, ``sensor``, ``delay`` and ``disturbance``.

    The torque is the run's constant w (3,) or, with ``flight.disturbance_file``, the (n, 3) rows
    W_k + w: the file's rows themselves when w = 0 (so such a run equals a run given the file's rows),
    else one new (n, 3) array (one per call, never one per run of a chunk).
    """
    rows, constant = models.get("disturbance_rows"), np.asarray(models["disturbance"])
    if rows is None:
        torque = constant
    elif not np.any(constant):
        torque = rows
    else:
        torque = rows + constant[None, :]
    return {"actuator": models["actuator"], "sensor": models["sensor"], "delay": models["delay"], "disturbance": torque}


def _batch(
    spacecraft: list[Spacecraft],
    K: np.ndarray,
    x0: np.ndarray,
    tau: np.ndarray,
    rule: Sequence[SwitchingRule],
    options: dict[str, Any],
) -> dict[str, np.ndarray]:
    """The runs' metrics from one metrics-only batch (the peak torque is accumulated by the engine), with a
    reference (``options["reference"]``, one per run) their pointing metrics from the kept samples, and on a
    wheel cluster (``options["wheels"]``) the `WHEEL_METRICS`."""
    if options.get("reference") is None:
        batch = simulate_batch(spacecraft, K, x0, tau=tau, rule=rule, **options)
        found = {name: np.asarray(getattr(batch, name)) for name in METRICS}
        wheels = options.get("wheels")
        if wheels is not None:
            found.update(wheel_metrics(batch.wheels, len(x0), wheels.count))
        return found
    batch = simulate_batch(spacecraft, K, x0, tau=tau, rule=rule, trajectories=True, keep_every=1, **options)
    out = {name: np.asarray(getattr(batch, name)) for name in METRICS}
    runs: Sequence[Any] = batch.runs or ()
    for name, (dtype, missing) in POINTING_METRICS.items():
        values = [getattr(run, name) for run in runs]
        out[name] = np.array([missing if value is None else value for value in values], dtype=dtype)
    return out


def _group_size(t_final: float, rate: float, concurrent: int) -> int:
    """Runs per tracking call: their kept samples and records within `TRACKING_BATCH_BYTES` over the
    ``concurrent`` calls in flight (at least one run: simulate_batch then refuses one that does not fit)."""
    per_run = kept_run_bytes(t_final, rate, 1, records=True)
    return max(1, int(TRACKING_BATCH_BYTES // (per_run * max(1, concurrent))))


def _cpus() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def _spacecraft(inertia: np.ndarray) -> list[Spacecraft]:
    """One Spacecraft per run, built once per distinct inertia (the same values give the same object,
    so an undispersed inertia costs one eigen-decomposition per chunk, not one per run)."""
    built: dict[bytes, Spacecraft] = {}
    crafts = []
    for J in np.asarray(inertia, dtype=float):
        key = J.tobytes()
        craft = built.get(key)
        if craft is None:
            craft = built[key] = Spacecraft(J)
        crafts.append(craft)
    return crafts


def _model_keys(models: dict[str, Any]) -> tuple[Any, Any, Any]:
    """The actuator's, the sensor's and the delay model's values as keys: runs with equal keys have equal models."""
    actuator, sensor, delay = models["actuator"], models["sensor"], models["delay"]
    return (
        None if actuator is None else (actuator.u_max.tobytes(), actuator.norm_limit, actuator.mode),
        (sensor.attitude_noise, sensor.rate_noise, sensor.gyro_bias.tobytes(), 0 if sensor.ideal else sensor.seed),
        None if delay is None else (delay.kind, delay.tau_min, delay.tau_max, delay.seed, id(delay.delays)),
    )


def _flight_key(models: dict[str, Any] | None) -> Any:
    """Runs with the same key share one simulate_batch call.

    The key is the models' structure only (whether there is an actuator and its saturation mode, the shared rows
    of a ``disturbance_file``): simulate_batch takes each run's actuator, sensor (its noise seed, levels and gyro
    bias) and delay model (its jitter seed), and the lanes stream each run its own noise rows and newest-arrived
    schedule, so a fully dispersed chunk is one call that fills every lane (the predictor's lanes and the wheel
    lanes too: each run's sensor, jitter and torque; the predictor's actuator).

    A constant torque w is not part of the key: runs that differ only in w (``[dispersions.disturbance]``)
    share one call with one w per run (simulate_batch's per-run constants, on the lanes; with a
    ``disturbance_file`` each run's W_k + w as a function of the sample times, evaluated slice by
    slice, so that no (runs, n, 3) array is made).
    """
    if models is None:
        return None
    rows = models.get("disturbance_rows")  # shared by the runs (one array): its identity names it
    actuator = models["actuator"]
    return ("per run", None if actuator is None else actuator.mode, None if rows is None else id(rows))


def _rows_plus(rows: np.ndarray, constant: np.ndarray, rate: float, times: np.ndarray) -> np.ndarray:
    """W_k + w at the sample times t_k = k / rate of a slice (the same additions as ``rows + w``)."""
    return rows[np.rint(times * rate).astype(np.int64)] + constant


def simulate_runs(
    inertia: np.ndarray,
    K: np.ndarray,
    x0: np.ndarray,
    tau: np.ndarray,
    rule: SwitchingRule | Sequence[SwitchingRule],
    *,
    t_final: float,
    rate: float,
    history: str,
    substeps: int,
    threads: int | None = None,
    peak_torque: bool = True,
    flight: Sequence[dict[str, Any] | None] | None = None,
    predictor: Predictor | None = None,
    settling_attitude: float = SETTLING_ATTITUDE_DEG,
    settling_rate: float = SETTLING_OMEGA,
    reference: Sequence[Any] | None = None,
    tracking: dict[str, Any] | None = None,
    wheels: WheelCluster | None = None,
    law: SteeringLaw | None = None,
) -> dict[str, np.ndarray]:
    """Simulate N runs, each with its own inertia, gain, initial state, delay, rule and flight models.

    Parameters
    ----------
    inertia : numpy.ndarray
        (N, 3, 3) inertia matrices (kg m²).
    K : numpy.ndarray
        (N, 3, 6) gains on x = [σ; ω/4].
    x0 : numpy.ndarray
        (N, 6) initial states.
    tau : numpy.ndarray
        (N,) delays (s).
    rule : SwitchingRule or sequence of SwitchingRule
        The rule of every run, or one per run.
    t_final, rate, history, substeps, threads
        As in [`mrpctl.simulate_batch`][mrpctl.simulate_batch].
    peak_torque : bool
        Also return the peak torque max_k |u_k|_∞ (N m) per run (NaN when False).
    flight : sequence of dict or None, optional
        Per run, None or the flight models (``actuator``, ``disturbance``, ``sensor``, ``delay``
        of [`mrpctl.simulate_batch`][mrpctl.simulate_batch], and ``disturbance_rows``: see
        [`flight_keywords`][mrpctl.campaign.simulation.flight_keywords]).
        Runs whose models share their structure share one call, each with its own actuator, sensor and delay
        model; the calls run on ``threads`` threads (one each), and every run's result is the same either way.
    predictor : Predictor or None, optional
        The predictor controller shared by every run (every rule an
        [`OnPredicted`][mrpctl.predictor.OnPredicted]): each call to [`mrpctl.simulate_batch`][mrpctl.simulate_batch]
        takes it.
    settling_attitude, settling_rate : float, optional
        The settling tolerances (principal angle in deg, rate in rad/s) of
        [`mrpctl.simulate_batch`][mrpctl.simulate_batch] (the campaign file's ``settling_attitude_deg`` and
        ``settling_rate``).
    reference : sequence or None, optional
        One reference per run (a guidance profile, ``samples(t)``, evaluated slice by slice; runs may share
        one object): the runs fly the tracking loop and the result also holds `POINTING_METRICS`.
    tracking : dict, optional
        ``error_time``, ``feedforward``, ``pointing_tolerance`` of [`mrpctl.simulate_batch`][mrpctl.simulate_batch]
        for every run (with ``reference``).
    wheels : WheelCluster or None, optional
        The reaction-wheel cluster every run flies on (every rule a [`Hysteretic`][mrpctl.flight.Hysteretic]);
        the wheel metrics of `mrpctl.campaign.wheels.WHEEL_METRICS` are returned too.
    law : SteeringLaw or None, optional
        The steering law every run flies ([`mrpctl.simulate_batch`][mrpctl.simulate_batch]'s ``law``; every rule a
        [`Hysteretic`][mrpctl.flight.Hysteretic]), each run's K the law near the target. None: the PD law.

    Returns
    -------
    dict of numpy.ndarray
        One (N,) array per name in `METRICS` (and `POINTING_METRICS` with ``reference``, the (N,) or (N, wheels)
        arrays of `WHEEL_METRICS` with ``wheels``), in input order.
    """
    n = len(x0)
    options: dict[str, Any] = dict(t_final=t_final, rate=rate, history=history, substeps=substeps, threads=threads)
    if (settling_attitude, settling_rate) != (SETTLING_ATTITUDE_DEG, SETTLING_OMEGA):
        options.update(settling_attitude=settling_attitude, settling_rate=settling_rate)
    if predictor is not None:
        options["predictor"] = predictor
    names = {**METRICS, **(POINTING_METRICS if reference is not None else {})}
    if reference is not None:
        options.update(tracking or {})
    if wheels is not None:
        options["wheels"] = wheels
    if law is not None:
        options["law"] = law
    if n == 0:
        return {
            **{name: np.full(0, missing, dtype=dtype) for name, (dtype, missing) in names.items()},
            **({} if wheels is None else wheel_metrics(None, 0, wheels.count)),
        }
    rules = [rule] * n if isinstance(rule, SwitchingRule) else list(rule)
    models = [None] * n if flight is None else list(flight)
    crafts = _spacecraft(inertia)
    groups: dict[Any, list[int]] = {}
    for i in range(n):  # every loop's lanes take per-run models (the flight laws, the predictor, the wheels)
        groups.setdefault(_flight_key(models[i]), []).append(i)
    out = {name: np.full(n, missing, dtype=dtype) for name, (dtype, missing) in names.items()}
    if wheels is not None:
        out.update(wheel_metrics(None, n, wheels.count))
    flown_calls = sum(key is not None for key in groups)  # the calls after the first run on a pool
    concurrent = max(1, min(flown_calls - 1, threads or _cpus()))

    def call(members: list[int], **extra: Any) -> None:
        if reference is not None:  # the kept samples of a group at a time (their memory bounded)
            size = _group_size(t_final, rate, concurrent)
            for first in range(0, len(members), size):
                one_call(
                    members[first : first + size],
                    reference=[reference[i] for i in members[first : first + size]],
                    **extra,
                )
            return
        one_call(members, **extra)

    def one_call(members: list[int], **extra: Any) -> None:
        given = models[members[0]]
        found = {} if given is None else flight_keywords(given)
        if given is not None and len(members) > 1:  # each run's own models where the runs' differ
            keys = [_model_keys(models[i] or given) for i in members]
            for slot, name in enumerate(("actuator", "sensor", "delay")):
                if any(key[slot] != keys[0][slot] for key in keys[1:]):
                    found[name] = [(models[i] or given)[name] for i in members]
        if given is not None:
            torques = [np.asarray((models[i] or given)["disturbance"], dtype=np.float64) for i in members]
            rows = given.get("disturbance_rows")
            if any(not np.array_equal(torque, torques[0]) for torque in torques[1:]):
                # one w per run, each run as simulate with its own: a constant, or W_k + w of the slice's samples
                found["disturbance"] = (
                    torques
                    if rows is None
                    else [Disturbance(function=functools.partial(_rows_plus, rows, w, rate)) for w in torques]
                )
        batch = _batch(
            [crafts[i] for i in members],
            K[members],
            x0[members],
            tau[members],
            [rules[i] for i in members],
            {**options, **extra, **found},
        )
        for name in batch:  # the metrics, and the pointing or the wheel metrics of the campaign
            out[name][members] = batch[name]

    plain = groups.pop(None, None)
    if plain is not None:  # one call: simulate_batch takes a spacecraft and a rule per run
        call(plain)
    flown = list(groups.values())
    if len(flown) == 1:  # one set of models: one call, on every thread
        call(flown[0])
    elif flown:
        call(flown[0], threads=1)  # loads the flight engine once before the pool shares it
    if len(flown) > 1:
        workers = max(1, min(len(flown) - 1, threads or _cpus()))
        with ThreadPoolExecutor(max_workers=workers) as pool:
            for future in [pool.submit(call, members, threads=1) for members in flown[1:]]:
                future.result()
    if not peak_torque:
        out["peak_torque"] = np.full(n, np.nan)
    return out
