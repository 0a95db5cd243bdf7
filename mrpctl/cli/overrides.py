"""The scenario a command line gives: a file or the paper's example, changed by the plant, gain,
initial-state, run, loop-as-flown and predictor options (each refusal names its option)."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from mrpctl._validation import finite_array, integer, positive_scalar
from mrpctl.cli.common import options_given
from mrpctl.conventions import PDGains, state
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.flight import ActuatorModel, DelayKind, DelayModel, Disturbance, Hysteretic, Saturation, SensorModel
from mrpctl.predictor import OnPredicted, Predictor, PredictorForm
from mrpctl.reproduction import paper_scenarios
from mrpctl.rules import DEFAULT_DELTA, DEFAULT_RULE
from mrpctl.scenario import (
    Scenario,
    delay_sequence,
    delay_values,
    load_scenario,
    predictor_model,
    rule_from_name,
    rule_name,
    samples_file,
    torque_rows,
)
from mrpctl.simulation import settling_tolerances
from mrpctl.spacecraft import Spacecraft

__all__ = [
    "apply_flight_options",
    "apply_overrides",
    "gain_from_args",
    "paper_base",
    "plant_given",
    "scenario_from_args",
    "spacecraft_from",
]


def spacecraft_from(values: Sequence[float]) -> Spacecraft:
    if len(values) == 3:
        return Spacecraft(np.asarray(values, dtype=float))
    if len(values) == 9:
        return Spacecraft(np.reshape(np.asarray(values, dtype=float), (3, 3)))
    raise DimensionError(
        f"--inertia: expected 3 principal values or 9 (a 3x3 matrix, row by row) (kg m^2) but found {len(values)}"
    )


def _per_axis_gain(option: str, values: Sequence[float]) -> np.ndarray:
    if len(values) == 1:
        return float(values[0]) * np.eye(3)
    if len(values) == 3:
        return np.diag(np.asarray(values, dtype=float))
    raise DimensionError(f"{option}: expected 1 value or 3 (one per axis) but found {len(values)}")


def _physical_block(option: str, values: Sequence[float]) -> Any:
    """A gain of --attitude-gain or --rate-gain as PDGains takes it: 1 value, 3 per axis or 9 (3x3, row by row)."""
    if len(values) == 1:
        return float(values[0])
    if len(values) == 3:
        return np.asarray(values, dtype=float)
    if len(values) == 9:
        return np.reshape(np.asarray(values, dtype=float), (3, 3))
    raise DimensionError(f"{option}: expected 1 value, 3 (one per axis) or 9 (a 3x3 matrix) but found {len(values)}")


def _physical_gain(args: argparse.Namespace) -> np.ndarray | None:
    """K from --attitude-gain and --rate-gain (u = -P_sigma sigma - P_omega omega); None when neither was given."""
    attitude, rate = getattr(args, "attitude_gain", None), getattr(args, "rate_gain", None)
    if attitude is None and rate is None:
        return None
    paper_form = options_given(("--K", args.K), ("--k-sigma", args.k_sigma), ("--k-omega", args.k_omega))
    if paper_form:
        raise SpecificationError(
            f"--attitude-gain/--rate-gain and {paper_form[0]} both give the gain; give one form "
            "(the physical gains, or the paper's K on x = [sigma; omega/4])"
        )
    if attitude is None or rate is None:
        raise SpecificationError("--attitude-gain and --rate-gain go together (u = -P_sigma sigma - P_omega omega)")
    p_sigma = _physical_block("--attitude-gain", attitude)
    p_omega = _physical_block("--rate-gain", rate)
    try:
        gains = PDGains(attitude=p_sigma, rate=p_omega)
    except (SpecificationError, DimensionError) as exc:
        option = "--rate-gain" if str(exc).startswith("rate") else "--attitude-gain"
        raise type(exc)(f"{option}: {exc}") from exc
    return np.array(gains.gain())


def gain_from_args(args: argparse.Namespace) -> np.ndarray | None:
    """K from --attitude-gain/--rate-gain (physical), --K or --k-sigma/--k-omega; None when none of them was given."""
    physical = _physical_gain(args)
    if physical is not None:
        return physical
    if args.K is not None:
        if args.k_sigma is not None or args.k_omega is not None:
            raise SpecificationError("--K gives the whole gain: do not combine it with --k-sigma/--k-omega")
        if len(args.K) != 18:
            raise DimensionError(f"--K: expected 18 numbers (the 3x6 K, row by row) but found {len(args.K)}")
        return np.reshape(np.asarray(args.K, dtype=float), (3, 6))
    if args.k_sigma is None and args.k_omega is None:
        return None
    if args.k_sigma is None or args.k_omega is None:
        raise SpecificationError("--k-sigma and --k-omega go together (K = [k_sigma, k_omega], diagonal blocks)")
    return np.hstack((_per_axis_gain("--k-sigma", args.k_sigma), _per_axis_gain("--k-omega", args.k_omega)))


def plant_given(args: argparse.Namespace) -> list[str]:
    return options_given(
        ("--inertia", args.inertia),
        ("--K", args.K),
        ("--k-sigma", args.k_sigma),
        ("--k-omega", args.k_omega),
        ("--attitude-gain", getattr(args, "attitude_gain", None)),
        ("--rate-gain", getattr(args, "rate_gain", None)),
    )


def paper_base() -> Scenario:
    """The paper's example with the default rule: the base of ``simulate`` and ``sweep`` without a file.

    The rule is the controller-side hysteresis ``mrpctl.rules.DEFAULT_RULE``, ``Hysteretic(0.1)``.
    """

    return replace(
        paper_scenarios()["delay_aware"],
        name="paper-hysteretic",
        description=f"the paper's example, controller-side hysteresis (delta = {DEFAULT_DELTA:g})",
        rule=DEFAULT_RULE,
    )


def scenario_from_args(args: argparse.Namespace, *, file: Path | str | None) -> Scenario:
    """A scenario file, or the paper's example, with the plant, gain and initial-state options applied.

    The options override the file's values as every other option does (``--inertia`` the plant, not a
    predictor's model; ``--sigma`` or ``--omega`` one half of the initial state, the other half kept).
    """
    if file is not None:
        base = load_scenario(file)
        changes: dict[str, Any] = {}
    else:
        base = paper_base()
        changes = {"name": "command_line", "description": "from command-line options"}
    sigma, omega = getattr(args, "sigma", None), getattr(args, "omega", None)
    if args.inertia is not None:
        changes["spacecraft"] = spacecraft_from(args.inertia)
    gain = gain_from_args(args)
    if gain is not None:
        changes["K"] = finite_array("--K", gain, (3, 6))
    if sigma is not None or omega is not None:
        changes["x0"] = state(base.sigma0 if sigma is None else sigma, base.omega0 if omega is None else omega)
    return replace(base, **changes) if changes else base


def _predictor_given(args: argparse.Namespace) -> list[str]:
    """The predictor options given on the command line (``simulate`` and ``export`` have them)."""
    return options_given(
        ("--predictor", getattr(args, "predictor", False) or None),
        ("--predictor-inertia", getattr(args, "predictor_inertia", None)),
        ("--predictor-error", getattr(args, "predictor_error", None)),
        ("--predictor-form", getattr(args, "predictor_form", None)),
    )


def apply_overrides(scenario: Scenario, args: argparse.Namespace) -> Scenario:
    changes: dict[str, Any] = {}
    predictor_options = _predictor_given(args)
    if getattr(args, "rule", None) is not None:
        changes["rule"] = rule_from_name(args.rule, eps=args.eps, alpha=args.alpha)
    elif (
        predictor_options
        and getattr(args, "hysteresis", None) is None
        and (args.alpha is not None or not isinstance(scenario.rule, OnPredicted))
    ):
        # A predictor option selects the rule 'on-predicted' (alpha from --alpha, default 1), as --hysteresis does
        if args.eps is not None:
            raise SpecificationError(f"--eps does not apply with {predictor_options[0]} (the rule 'on-predicted')")
        changes["rule"] = _option_value("--alpha", lambda: rule_from_name("on-predicted", alpha=args.alpha))
    elif getattr(args, "eps", None) is not None or getattr(args, "alpha", None) is not None:
        raise SpecificationError("--eps and --alpha need --rule (or, for the predictor's rule, --predictor)")
    for key in ("tau", "t_final", "history", "rate"):
        value = getattr(args, key, None)
        if value is not None:
            changes[key] = value
    substeps = getattr(args, "substeps", None)
    if substeps is not None:
        changes["substeps"] = integer("--substeps", substeps, minimum=1)
    attitude, rate = getattr(args, "settling_attitude", None), getattr(args, "settling_rate", None)
    if attitude is not None:
        changes["settling_attitude"] = _option_value(
            "--settling-attitude", lambda: settling_tolerances(attitude, scenario.settling_rate)[0]
        )
    if rate is not None:
        changes["settling_rate"] = _option_value(
            "--settling-rate", lambda: settling_tolerances(scenario.settling_attitude, rate)[1]
        )
    return replace(scenario, **changes) if changes else scenario


def _option_value(option: str, build: Callable[[], Any], fields: dict[str, str] | None = None) -> Any:
    """``build()``, with a refusal re-raised naming the command-line ``option``, or, when the message starts with
    one of ``fields`` (a model's parameter name -> its option), that parameter's option."""
    try:
        return build()
    except (SpecificationError, DimensionError) as exc:
        text = str(exc)
        for field, flag in (fields or {}).items():
            if text.startswith(field + " ") or text.startswith(field + ":"):
                option = flag
                break
        if text.startswith(option + ":"):
            raise
        raise type(exc)(f"{option}: {exc}") from exc


def apply_flight_options(scenario: Scenario, args: argparse.Namespace) -> Scenario:
    """The loop-as-flown options of ``simulate`` and ``export`` applied to ``scenario``.

    ``--hysteresis DELTA`` selects the controller-side rule; the model options change the
    scenario's own models field by field (or add them); every model needs that rule.
    """

    changes: dict[str, Any] = {}
    if args.hysteresis is not None:
        predictor_options = _predictor_given(args)
        if predictor_options:
            raise SpecificationError(
                f"--hysteresis (the hysteretic rule on the delayed measurement) and {predictor_options[0]} "
                "(the rule on the predicted attitude) are two controllers; give one of them"
            )
        if args.rule not in (None, "hysteretic"):
            raise SpecificationError(
                f"--hysteresis selects the rule 'hysteretic'; it does not apply with --rule {args.rule}"
            )
        if args.alpha is not None:
            raise SpecificationError("--hysteresis (delta) and --alpha give the same bound; give one of them")
        changes["rule"] = _option_value("--hysteresis", lambda: Hysteretic(args.hysteresis))
    actuator_given = [
        o
        for o, v in (
            ("--torque-limit", args.torque_limit),
            ("--torque-norm", args.torque_norm),
            ("--saturation", args.saturation),
        )
        if v is not None
    ]
    if actuator_given:
        old = scenario.actuator
        if old is None and args.torque_limit is None:
            raise SpecificationError(f"{actuator_given[0]} needs --torque-limit (the per-axis limit, N m)")
        limit = args.torque_limit if args.torque_limit is not None else old.u_max  # type: ignore[union-attr]
        if len(limit) not in (1, 3):
            raise DimensionError(f"--torque-limit: expected 1 or 3 values (N m) but found {len(limit)}")
        norm = args.torque_norm if args.torque_norm is not None else (None if old is None else old.norm_max)
        mode = (
            Saturation(args.saturation)
            if args.saturation is not None
            else (Saturation.SCALE if old is None else old.mode)
        )
        changes["actuator"] = _option_value(
            actuator_given[0],
            lambda: ActuatorModel(u_max=limit[0] if len(limit) == 1 else limit, norm_max=norm, mode=mode),
            {"u_max": "--torque-limit", "norm_max": "--torque-norm", "mode": "--saturation"},
        )
    sensor_options = (
        ("--attitude-noise", "attitude_noise", args.attitude_noise),
        ("--rate-noise", "rate_noise", args.rate_noise),
        ("--gyro-bias", "gyro_bias", args.gyro_bias),
        ("--noise-seed", "seed", args.noise_seed),
    )
    sensor_given = {key: value for _, key, value in sensor_options if value is not None}
    if sensor_given:
        base = scenario.sensor if scenario.sensor is not None else SensorModel()
        first = next(option for option, _, value in sensor_options if value is not None)
        fields = {"attitude_noise": base.attitude_noise, "rate_noise": base.rate_noise, "gyro_bias": base.gyro_bias}
        fields["seed"] = base.seed
        fields.update(sensor_given)
        changes["sensor"] = _option_value(
            first, lambda: SensorModel(**fields), {key: option for option, key, _ in sensor_options}
        )

    samples = math.floor(scenario.t_final * scenario.rate + 1e-9) + 1  # n, as mrpctl.simulate counts them
    _check_file_horizons(scenario, args, samples)
    if args.disturbance is not None and args.disturbance_file is not None:
        raise SpecificationError(
            "--disturbance (a constant torque) and --disturbance-file (one torque row per sample) both give the "
            "disturbance; give one of them"
        )
    if args.disturbance is not None:
        changes["disturbance"] = _option_value("--disturbance", lambda: Disturbance(args.disturbance))
    if args.disturbance_file is not None:
        rows = torque_rows(samples_file(args.disturbance_file, "--disturbance-file"), "--disturbance-file", samples)
        changes["disturbance"] = Disturbance(rows)
    if args.delay_file is not None:
        if args.jitter is not None:
            raise SpecificationError(
                "--jitter (seeded random delays) and --delay-file (a given delay per sample) both give the delay; "
                "give one of them"
            )
        values = delay_values(samples_file(args.delay_file, "--delay-file"), "--delay-file", samples)
        changes["delay"] = _option_value(
            "--delay-file", lambda: delay_sequence(values, "--delay-file", tau=scenario.tau, rate=scenario.rate)
        )
    if args.jitter is not None:
        low, high = args.jitter
        if args.tau is not None and args.tau != high:
            raise SpecificationError(
                f"--jitter TMIN TMAX sets tau = TMAX = {high:g} s; it contradicts --tau {args.tau:g}"
            )
        model = _option_value(
            "--jitter", lambda: DelayModel.jitter(low, high, seed=0 if args.jitter_seed is None else args.jitter_seed)
        )
        changes["delay"] = model
        changes["tau"] = model.tau_max
    elif args.jitter_seed is not None:
        raise SpecificationError("--jitter-seed needs --jitter TMIN TMAX")
    updated = _apply_predictor_options(replace(scenario, **changes) if changes else scenario, args)
    if updated.flight_options and not isinstance(updated.rule, Hysteretic | OnPredicted):
        given = [name for name in ("actuator", "sensor", "disturbance", "delay") if name in updated.flight_options]
        raise SpecificationError(
            f"the {', '.join(given)} model(s) apply only to the loop as flown: add --hysteresis DELTA "
            f"(the controller-side rule) or --predictor, got the rule {rule_name(updated.rule)!r}"
        )
    if updated.delay is not None:
        if updated.delay.tau_max != updated.tau:
            raise SpecificationError(
                f"the jittering delay's tau_max = {updated.delay.tau_max:g} s must equal tau = {updated.tau:g} s; "
                "give --jitter TMIN TMAX instead of --tau"
            )
        positive_scalar("rate", updated.rate)  # a bad --rate is the rate's error, not the jitter's
        # the delay of --jitter, or the scenario's own [delay] at the rate of --rate (or of the file)
        where = "--jitter" if args.jitter is not None else f"the scenario's [delay] at rate = {updated.rate:g} Hz"
        low_samples, _ = _option_value(where, lambda: updated.delay.bounds(updated.rate))  # type: ignore[union-attr]
        if low_samples < 1:
            raise SpecificationError(f"{where}: TMIN must be >= 1/rate = {1.0 / updated.rate:g} s")
    return updated


def _check_file_horizons(scenario: Scenario, args: argparse.Namespace, samples: int) -> None:
    """The scenario file's per-sample rows ([disturbance] torque_file, [delay] sequence_file) against the n of
    --t-final / --rate: a clear refusal naming both (the run would refuse the rows without naming the file)."""

    overrides = [
        f"{flag} {value:g}"
        for flag, value in (("--t-final", getattr(args, "t_final", None)), ("--rate", getattr(args, "rate", None)))
        if value is not None
    ]
    if not overrides:
        return
    found: list[tuple[str, int]] = []
    torque = scenario.disturbance
    if (
        torque is not None
        and getattr(args, "disturbance", None) is None
        and getattr(args, "disturbance_file", None) is None
        and torque.shape is not None
        and len(torque.shape) == 2
    ):
        found.append(("[disturbance] torque_file", torque.shape[0]))
    delay = scenario.delay
    if (
        delay is not None
        and delay.kind is DelayKind.SEQUENCE
        and delay.delays is not None
        and getattr(args, "delay_file", None) is None
        and getattr(args, "jitter", None) is None
    ):
        found.append(("[delay] sequence_file", len(delay.delays)))
    for where, rows in found:
        if rows != samples:
            raise SpecificationError(
                f"{' '.join(overrides)} gives n = {samples} samples, but the scenario's {where} has {rows} rows (one "
                f"per sample of the file's own t_final and rate): give a file of {samples} rows, or leave out "
                f"{' and '.join(flag.split()[0] for flag in overrides)}"
            )


def _apply_predictor_options(scenario: Scenario, args: argparse.Namespace) -> Scenario:
    """``--predictor``, ``--predictor-inertia J...`` and ``--predictor-error E...`` applied to ``scenario``,
    then the predictor checked against the rule, the history and the delay model (one-line errors)."""

    predictor = scenario.predictor
    given = _predictor_given(args)
    if args.predictor_inertia is not None and args.predictor_error is not None:
        raise SpecificationError(
            "--predictor-inertia (the model's J) and --predictor-error (relative to the plant) both give the "
            "controller's model; give one of them"
        )
    if args.predictor_inertia is not None:
        values = args.predictor_inertia
        if len(values) not in (3, 9):
            raise DimensionError(
                f"--predictor-inertia: expected 3 principal values or 9 (a 3x3 matrix, row by row; kg m^2) but "
                f"found {len(values)}"
            )
        inertia = values if len(values) == 3 else np.reshape(values, (3, 3))
        model = _option_value("--predictor-inertia", lambda: predictor_model(scenario.spacecraft, inertia=inertia))
        predictor = Predictor(model=model)
    elif args.predictor_error is not None:
        errors = args.predictor_error
        if len(errors) not in (1, 3):
            raise DimensionError(f"--predictor-error: expected 1 or 3 relative errors but found {len(errors)}")
        error = errors[0] if len(errors) == 1 else errors
        model = _option_value("--predictor-error", lambda: predictor_model(scenario.spacecraft, inertia_error=error))
        predictor = Predictor(model=model)
    elif args.predictor or (getattr(args, "predictor_form", None) is not None and predictor is None):
        predictor = Predictor(model=scenario.spacecraft)
    if getattr(args, "predictor_form", None) is not None:
        assert predictor is not None
        predictor = replace(predictor, form=PredictorForm.parse(args.predictor_form, "--predictor-form"))
    updated = replace(scenario, predictor=predictor) if predictor is not scenario.predictor else scenario
    on_predicted = isinstance(updated.rule, OnPredicted)
    if on_predicted and updated.predictor is None:
        raise SpecificationError(
            "--rule on-predicted switches on the predicted attitude: add --predictor (model = plant), "
            "--predictor-inertia J... or --predictor-error E"
        )
    if updated.predictor is not None and not on_predicted:
        where = given[0] if given else "the scenario's [predictor]"
        raise SpecificationError(
            f"{where}: the predictor chooses its MRP set on the predicted attitude, rule 'on-predicted' "
            f"(--rule on-predicted, --alpha A), got the rule {rule_name(updated.rule)!r}"
        )
    if updated.predictor is not None:
        if updated.history != "constant":
            raise SpecificationError(
                f"--history {updated.history}: the predictor's model copy starts at x0; only the constant "
                "history applies with a predictor"
            )
        if updated.delay is not None:
            raise SpecificationError(
                "--jitter does not apply with the predictor: it runs with the constant delay tau only "
                "(its correction needs the age of each measurement)"
            )
    return updated
