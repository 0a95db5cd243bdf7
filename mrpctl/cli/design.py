"""``mrpctl design``: PD gains (nominal or robust) or an LMI state feedback certified for a delay, and the
runnable scenario of ``--toml``."""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

import mrpctl.design
from mrpctl._scenario_steering import check_steering_scenario
from mrpctl._validation import nonnegative_scalar, positive_scalar
from mrpctl.cli.common import (
    EXIT_CODES,
    Formatter,
    add_json,
    add_rule_options,
    atomic_output,
    joint_json,
    options_given,
    print_json,
    refuse_existing,
)
from mrpctl.cli.overrides import paper_base, spacecraft_from
from mrpctl.conventions import PDGains, state
from mrpctl.design import FlownVerdict, SynthesisStatus, analyze_gains, synthesize_lmi, verify_flown
from mrpctl.design.actuator import design_for_actuator
from mrpctl.design.robust import RobustPDSynthesis, RobustStatus
from mrpctl.errors import MrpctlError, SpecificationError
from mrpctl.flight import ActuatorModel, Hysteretic
from mrpctl.rules import DEFAULT_DELTA, DEFAULT_RULE
from mrpctl.scenario import Scenario, check_delay, load_scenario, rule_from_name, scenario_toml
from mrpctl.spacecraft import Spacecraft
from mrpctl.wheels import WheelCluster

__all__ = ["add_parser"]


def _physical_json(K: np.ndarray) -> dict[str, Any]:
    """K's physical gains for the JSON: u = -P_sigma sigma - P_omega omega (N m, N m s)."""
    gains = PDGains.from_gain(K)
    return {"attitude_gain": gains.attitude, "rate_gain": gains.rate}


def _print_physical(K: np.ndarray) -> None:
    """K's physical gains, u = -P_sigma sigma - P_omega omega (per axis when diagonal, else 3x3)."""
    gains = PDGains.from_gain(K)
    if gains.is_diagonal:
        print(
            "physical: u = -P_sigma sigma - P_omega omega, attitude gain P_sigma = "
            f"{np.array2string(np.diag(gains.attitude), precision=6)} N m, rate gain P_omega = "
            f"{np.array2string(np.diag(gains.rate), precision=6)} N m s (per axis)"
        )
        return
    print("physical: u = -P_sigma sigma - P_omega omega, attitude gain P_sigma (N m) and rate gain P_omega (N m s):")
    print(np.array2string(gains.attitude, precision=6, max_line_width=200, suppress_small=False))
    print(np.array2string(gains.rate, precision=6, max_line_width=200, suppress_small=False))


def _damping_kind(zeta: float) -> str:
    """The CLI's words for a damping ratio: ζ = 1 (to 1e-9) is critically damped."""
    if not math.isfinite(zeta):
        return "no restoring gain"
    if abs(zeta - 1.0) <= 1e-9:
        return "critically damped"
    return "overdamped" if zeta > 1.0 else "underdamped"


def _design(args: argparse.Namespace) -> int:
    if args.toml is None:
        for option, value in (("--rate", args.rate), ("--t-final", args.t_final), ("--rule", args.rule)):
            if value is not None:
                raise SpecificationError(f"{option} applies only with --toml (it goes into the written scenario)")
        if args.eps is not None or args.alpha is not None:
            raise SpecificationError("--eps and --alpha apply only with --toml and --rule")
    if args.zeta < 1.0 and not args.allow_underdamped:
        raise SpecificationError(
            f"--zeta {args.zeta:g} is underdamped (zeta < 1: the response overshoots); "
            "pass --allow-underdamped to design it anyway"
        )
    positive_scalar("--tau", args.tau)
    spacecraft = spacecraft_from(args.inertia)
    if any(v is not None for v in (args.torque_limit, args.wheels, args.max_rate, args.settling_time)):
        return _actuator_design(args, spacecraft)
    toml_path = None if args.toml is None else Path(args.toml)
    if args.product_bound and args.inertia_tolerance is None:
        raise SpecificationError("--product-bound applies only with --inertia-tolerance TOL")
    if args.jitter_rate is not None and args.jitter is None:
        raise SpecificationError("--jitter-rate applies only with --jitter TAU_MIN")
    if args.jitter is not None and args.sampled is not None:
        raise SpecificationError("give either --jitter TAU_MIN or --sampled HZ, not both")
    if args.decay_rate is not None and args.method != "lmi":
        raise SpecificationError("--decay-rate applies only with --method lmi")
    if args.method == "lmi":
        return _lmi_design(args, spacecraft, toml_path)
    if args.inertia_tolerance is not None or args.sampled is not None or args.jitter is not None:
        return _robust_design(args, spacecraft, toml_path)
    if args.rtol is not None:
        raise SpecificationError("--rtol applies only with --inertia-tolerance, --sampled or --jitter")
    rate = 1000.0 if args.rate is None else args.rate
    if toml_path is not None:
        refuse_existing(toml_path, args.overwrite, "--toml")
        check_delay(args.tau, rate)
    order = 3 if args.order is None else args.order
    # through the package, so that a replaced mrpctl.design.synthesize_pd (a test's stub) is the one called
    design = mrpctl.design.synthesize_pd(
        spacecraft, args.tau, zeta=args.zeta, order=order, allow_underdamped=args.allow_underdamped
    )
    if not design.synthesized or design.gains is None:
        raise SpecificationError(
            f"no certified gains for tau = {args.tau:g} s at zeta = {args.zeta:g} "
            f"({design.status.value}): {design.reason}; try another --order or --zeta"
        )
    K = np.asarray(design.gains.K, dtype=float)
    analysis = analyze_gains(spacecraft, K)
    k1, k2 = np.diag(analysis.K1), np.diag(analysis.K2)
    decay = getattr(design, "decay_rate", None)
    written = None
    written_verdict = None
    if toml_path is not None:
        written_verdict = _write_design_toml(
            toml_path,
            spacecraft,
            K,
            args,
            rate,
            design.status.value,
            f" --zeta {args.zeta:g} --order {order}",
            f"{design.status.value}: omega_n = {design.omega_n:.6g} rad/s, "
            f"exact delay margin {design.margin.margin if design.margin else float('nan'):.6g} s",
        )
        written = toml_path
    if args.json:
        print_json(
            {
                "status": design.status.name,
                "synthesized": design.synthesized,
                "tau": args.tau,
                "order": order,
                "omega_n": design.omega_n,
                "zeta": design.gains.zeta,
                "decay_rate": decay,
                "K": K,
                **_physical_json(K),
                "K1": k1,
                "K2": k2,
                "certified": design.certificate.certified if design.certificate is not None else False,
                "exact_delay_margin": design.margin.margin if design.margin is not None else None,
                "reason": design.reason,
                "toml": written,
                "written_verdict": None if written_verdict is None else joint_json(written_verdict),
            }
        )
        return 0
    print(design)
    print("K (3x6, N m) on x = [sigma; omega/4], u = K x(t - tau):")
    print(np.array2string(K, precision=6, max_line_width=200, suppress_small=False))
    print("per axis, sigma'' = K1 sigma + K2 sigma' (K = [4 J K1, 4 J K2]):")
    for axis in analysis.axes:
        print(
            f"  axis {axis.axis}: K1 = {axis.K1:.6g} 1/s^2, K2 = {axis.K2:.6g} 1/s, omega_n = {axis.omega_n:.6g} "
            f"rad/s, zeta = {axis.zeta:.4g} ({_damping_kind(axis.zeta)})"
        )
    if not analysis.axes:
        print("  axes coupled: K1, K2 are not diagonal")
    if decay is not None:
        print(f"certified decay rate {float(decay):.6g} 1/s")
    _print_physical(K)
    if written is not None:
        if written_verdict is not None:
            print(written_verdict)
        print(f"scenario written to {written} (run: mrpctl verify {written}; mrpctl simulate {written})")
    return 0


def _write_design_toml(
    path: Path,
    spacecraft: Spacecraft,
    K: np.ndarray,
    args: argparse.Namespace,
    rate: float,
    status: str,
    options: str,
    summary: str,
) -> FlownVerdict:
    """The runnable scenario of ``design --toml``; its comment names the command (``options`` after --tau).

    The written loop (the nominal spacecraft sampled at ``rate``, d = tau·rate) is verified first
    ([verify_flown][mrpctl.design.flown.verify_flown]): the header says "verified" only when that joint
    verdict is VERIFIED; otherwise it says what holds, and a warning goes to stderr. Returns the verdict.
    """
    verdict = verify_flown(spacecraft, K, float(args.tau), rate=float(rate))
    if not verdict.verified:
        what = f"designed for the continuous-time loop; the written {rate:g} Hz loop is {verdict.status.name}"
        if verdict.witness is not None:
            what += f" ({verdict.witness})"
        status = what
        # The design's own status says "verified" of the continuous-time loop: not of the written one.
        design = summary.replace("synthesized and verified", "synthesized for the continuous-time loop")
        summary = f"NOT verified at {rate:g} Hz: {verdict.status.value}. The continuous-time design: {design}"
        print(
            f"mrpctl design: warning: the scenario written to {path} is not verified at its rate {rate:g} Hz: "
            f"{verdict.status.name}" + ("" if verdict.witness is None else f", {verdict.witness}"),
            file=sys.stderr,
        )
    else:
        summary = f"{summary}; the written loop at {rate:g} Hz (d = {round(args.tau * rate)}) verified jointly"
    comment = (
        f"Written by: mrpctl design --inertia {' '.join(f'{v:g}' for v in args.inertia)} --tau {args.tau:g}{options}\n"
        f"{summary}\n"
        "Initial state: the paper's tumble (Phi = 171.69 deg about x, omega = 0.46 rad/s); edit freely."
    )
    scenario = replace(
        paper_base(),
        name=path.stem,
        description=f"mrpctl design: tau = {args.tau:g} s, {status}",
        spacecraft=spacecraft,
        K=K,
        tau=float(args.tau),
        rate=float(rate),
        t_final=60.0 if args.t_final is None else float(args.t_final),
        rule=DEFAULT_RULE if args.rule is None else rule_from_name(args.rule, eps=args.eps, alpha=args.alpha),
    )
    with atomic_output(path) as stream:
        stream.write(scenario_toml(scenario, comment=comment))
    return verdict


def _robust_options(
    args: argparse.Namespace, spacecraft: Spacecraft
) -> tuple[float, float, float | None, float, float | None, float | None]:
    """(tolerance, product bound, period, --toml rate, tau_min, jitter rate) of ``design``'s robust options."""
    tolerance = 0.0
    if args.inertia_tolerance is not None:
        tolerance = nonnegative_scalar("--inertia-tolerance", args.inertia_tolerance)
        if tolerance >= 1.0:
            raise SpecificationError(f"--inertia-tolerance must be < 1 (a relative tolerance), got {tolerance:g}")
    bound = nonnegative_scalar("--product-bound", args.product_bound)
    if not spacecraft.is_diagonal:
        raise SpecificationError(
            "--inertia: --inertia-tolerance, --sampled and --jitter need a diagonal nominal inertia "
            "(3 principal values)"
        )
    period = None
    rate = 1000.0 if args.rate is None else args.rate
    if args.sampled is not None:
        hz = positive_scalar("--sampled", args.sampled)
        samples = args.tau * hz
        if abs(samples - round(samples)) > 1e-9 * max(1.0, samples):
            raise SpecificationError(f"--sampled: tau * HZ must be a whole number of samples, got {samples!r}")
        if args.rate is not None and args.rate != hz:
            raise SpecificationError(f"--rate {args.rate:g} differs from --sampled {hz:g}: give one rate")
        period, rate = 1.0 / hz, hz
    tau_min = None
    jitter_rate = None
    if args.jitter is not None:
        tau_min = nonnegative_scalar("--jitter", args.jitter)
        if tau_min >= args.tau:
            raise SpecificationError(f"--jitter TAU_MIN must be < tau = {args.tau:g} s, got {tau_min:g}")
        if args.jitter_rate is not None:
            jitter_rate = nonnegative_scalar("--jitter-rate", args.jitter_rate)
    return tolerance, bound, period, rate, tau_min, jitter_rate


def _robust_flags(tolerance: float, bound: float, period: float | None, rate: float, tau_min: float | None) -> str:
    """The robust options as written on the command line (for the --toml comment)."""
    out = f" --inertia-tolerance {tolerance:g} --product-bound {bound:g}"
    if period is not None:
        out += f" --sampled {rate:g}"
    if tau_min is not None:
        out += f" --jitter {tau_min:g}"
    return out


def _robust_design(args: argparse.Namespace, spacecraft: Spacecraft, toml_path: Path | None) -> int:
    """``mrpctl design --inertia-tolerance TOL [--product-bound P] [--sampled HZ | --jitter TAU_MIN]``."""

    tolerance, bound, period, rate, tau_min, jitter_rate = _robust_options(args, spacecraft)
    if toml_path is not None:
        refuse_existing(toml_path, args.overwrite, "--toml")
        check_delay(args.tau, rate)
    # Wirtinger and higher orders are numerically inaccurate for the 0.2 % wide sampled interval at 1 kHz
    # (design/lmi.md section 7.3): the sampled loop defaults to Jensen; the constant delay to N = 2.
    order = (0 if period is not None else 2) if args.order is None else args.order
    rtol = 1e-3 if args.rtol is None else positive_scalar("--rtol", args.rtol)
    # The robust synthesize_pd: the decay-optimal nominal design when the whole set certifies it, else the
    # largest certified omega_n below it (not the largest certified omega_n, which sits on the stability boundary).
    result = mrpctl.design.synthesize_pd(
        spacecraft,
        args.tau,
        zeta=args.zeta,
        order=order,
        allow_underdamped=args.allow_underdamped,
        tolerance=tolerance,
        product_bound=bound,
        period=period,
        tau_min=tau_min,
        delay_rate=jitter_rate,
        rtol=rtol,
    )
    assert isinstance(result, RobustPDSynthesis)
    if result.gains is None or result.status is RobustStatus.INFEASIBLE:
        raise SpecificationError(
            f"no robustly certified gains for tau = {args.tau:g} s at zeta = {args.zeta:g}, "
            + ("nominal inertia " if tolerance == 0.0 else f"inertia +-{100 * tolerance:g} % ")
            + f"({result.status.value}): {result.reason}; try another --order, --zeta or a smaller --inertia-tolerance"
        )
    if result.status is RobustStatus.NOT_VERIFIED:
        raise MrpctlError(
            f"the certified gains failed the exact check (a soundness bug, please report): {result.exact_check}"
        )
    K = np.asarray(result.gains.K, dtype=float)
    analysis = analyze_gains(spacecraft, K)
    cert = result.certificate
    written = None
    written_verdict = None
    if toml_path is not None:
        written_verdict = _write_design_toml(
            toml_path,
            spacecraft,
            K,
            args,
            rate,
            result.status.value,
            f" --zeta {args.zeta:g} --order {order}" + _robust_flags(tolerance, bound, period, rate, tau_min),
            f"{result.status.value}: omega_n = {result.omega_n:.6g} rad/s; {result.exact_check}",
        )
        written = toml_path
    if args.json:
        print_json(
            {
                "status": result.status.name,
                "synthesized": result.status is RobustStatus.SYNTHESIZED,
                "model": result.model.name,
                "tau": args.tau,
                "tau_min": result.tau_min,
                "tau_max": result.tau_max,
                "inertia_tolerance": tolerance,
                "product_bound": bound,
                "sampled_rate": None if period is None else rate,
                "order": order,
                "omega_n": result.omega_n,
                "zeta": result.gains.zeta,
                "K": K,
                **_physical_json(K),
                "K1": np.diag(analysis.K1),
                "K2": np.diag(analysis.K2),
                "certified": cert is not None and cert.certified,
                "certificate": str(cert) if cert is not None else None,
                "exact_check": result.exact_check,
                "reason": result.reason,
                "toml": written,
                "written_verdict": None if written_verdict is None else joint_json(written_verdict),
            }
        )
        return 0
    print(result)
    if cert is not None:
        print(cert)
    print("K (3x6, N m) on x = [sigma; omega/4], u = K x(t - tau):")
    print(np.array2string(K, precision=6, max_line_width=200, suppress_small=False))
    for axis in analysis.axes:
        print(
            f"  axis {axis.axis}: K1 = {axis.K1:.6g} 1/s^2, K2 = {axis.K2:.6g} 1/s, omega_n = {axis.omega_n:.6g} "
            f"rad/s, zeta = {axis.zeta:.4g} ({_damping_kind(axis.zeta)}) at the nominal inertia"
        )
    _print_physical(K)
    if written is not None:
        if written_verdict is not None:
            print(written_verdict)
        print(f"scenario written to {written} (run: mrpctl verify {written}; mrpctl simulate {written})")
    return 0


def _lmi_design(args: argparse.Namespace, spacecraft: Spacecraft, toml_path: Path | None) -> int:
    """``mrpctl design --method lmi --decay-rate ALPHA [robust options]``: synthesize_lmi (descriptor method)."""

    if args.decay_rate is None:
        raise SpecificationError("--method lmi needs --decay-rate ALPHA (1/s): the decay rate the LMI imposes")
    alpha = nonnegative_scalar("--decay-rate", args.decay_rate)
    if args.rtol is not None:
        raise SpecificationError("--rtol applies only with --method pd (the omega_n search)")
    robust = args.inertia_tolerance is not None or args.sampled is not None or args.jitter is not None
    rate = 1000.0 if args.rate is None else args.rate
    options: dict[str, Any] = {}
    flags = ""
    period = None
    if robust:
        tolerance, bound, period, rate, tau_min, jitter_rate = _robust_options(args, spacecraft)
        options = {
            "tolerance": tolerance,
            "product_bound": bound,
            "period": period,
            "tau_min": tau_min,
            "delay_rate": jitter_rate,
        }
        flags = _robust_flags(tolerance, bound, period, rate, tau_min)
    if toml_path is not None:
        refuse_existing(toml_path, args.overwrite, "--toml")
        check_delay(args.tau, rate)
    # As for the PD design: Jensen for the sampled loop (Wirtinger's re-verification is inaccurate at 1 kHz).
    order = (0 if period is not None else 1) if args.order is None else args.order
    result = synthesize_lmi(spacecraft, args.tau, decay_rate=alpha, order=order, **options)
    if result.K is None or result.status is not SynthesisStatus.SYNTHESIZED:
        raise SpecificationError(
            f"no certified state feedback for tau = {args.tau:g} s at decay rate {alpha:g} 1/s "
            f"({result.status.value}): {result.reason}; try a smaller --decay-rate or another --order"
        )
    K = np.asarray(result.K, dtype=float)
    written = None
    written_verdict = None
    if toml_path is not None:
        written_verdict = _write_design_toml(
            toml_path,
            spacecraft,
            K,
            args,
            rate,
            result.status.value,
            f" --method lmi --decay-rate {alpha:g} --order {order}{flags}",
            f"{result.status.value}: {result.reason}",
        )
        written = toml_path
    analysis = analyze_gains(spacecraft, K)
    cert = result.certificate
    if args.json:
        print_json(
            {
                "status": result.status.name,
                "synthesized": result.synthesized,
                "method": "lmi",
                "model": result.model.name,
                "tau": args.tau,
                "tau_min": result.tau_min,
                "tau_max": result.tau_max,
                "inertia_tolerance": result.tolerance,
                "product_bound": result.product_bound,
                "sampled_rate": None if period is None else rate,
                "order": order,
                "decay_rate": alpha,
                "epsilon": result.epsilon,
                "K": K,
                **_physical_json(K),
                "K1": np.diag(analysis.K1) if analysis.axes else None,
                "K2": np.diag(analysis.K2) if analysis.axes else None,
                "certified": cert is not None and cert.certified,
                "exact_delay_margin": result.margin.margin if result.margin is not None else None,
                "exact_check": result.exact_check,
                "reason": result.reason,
                "toml": written,
                "written_verdict": None if written_verdict is None else joint_json(written_verdict),
            }
        )
        return 0
    print(result)
    if cert is not None and result.robust:
        print(cert)
    print("K (3x6, N m) on x = [sigma; omega/4], u = K x(t - tau):")
    print(np.array2string(K, precision=6, max_line_width=200, suppress_small=False))
    for axis in analysis.axes:
        print(
            f"  axis {axis.axis}: K1 = {axis.K1:.6g} 1/s^2, K2 = {axis.K2:.6g} 1/s, omega_n = {axis.omega_n:.6g} "
            f"rad/s, zeta = {axis.zeta:.4g} ({_damping_kind(axis.zeta)}) at the nominal inertia"
        )
    if not analysis.axes:
        print("  axes coupled: K1, K2 are not diagonal")
    _print_physical(K)
    if written is not None:
        if written_verdict is not None:
            print(written_verdict)
        print(f"scenario written to {written} (run: mrpctl verify {written}; mrpctl simulate {written})")
    return 0


def _actuator_design(args: argparse.Namespace, spacecraft: Spacecraft) -> int:
    """``--torque-limit`` or ``--wheels``: the steering law for the actuator and the envelope
    (``design_for_actuator``), and with ``--toml`` the scenario that flies it."""
    if args.torque_limit is None and args.wheels is None:
        raise SpecificationError(
            "--max-rate and --settling-time apply only with --torque-limit U (N m) or --wheels SCENARIO"
        )
    if args.torque_limit is not None and args.wheels is not None:
        raise SpecificationError("give --torque-limit U (an ideal torque) or --wheels SCENARIO (its wheels), not both")
    given = options_given(
        ("--method lmi", args.method == "lmi" or None),
        ("--inertia-tolerance", args.inertia_tolerance),
        ("--sampled", args.sampled),
        ("--jitter", args.jitter),
        ("--decay-rate", args.decay_rate),
    )
    if given:
        option = "--torque-limit" if args.wheels is None else "--wheels"
        raise SpecificationError(f"{option}: the design for the actuator does not take {', '.join(given)}")
    actuator: ActuatorModel | WheelCluster
    if args.wheels is not None:
        wheels = load_scenario(args.wheels).wheels
        if wheels is None:
            raise SpecificationError(f"--wheels {args.wheels}: the scenario has no [wheels] table")
        actuator = wheels
    else:
        actuator = ActuatorModel(positive_scalar("--torque-limit", args.torque_limit))
    max_rate = 0.0 if args.max_rate is None else nonnegative_scalar("--max-rate", args.max_rate)
    settling = 60.0 if args.settling_time is None else positive_scalar("--settling-time", args.settling_time)
    order = 3 if args.order is None else args.order
    toml_path = None if args.toml is None else Path(args.toml)
    scenario = None
    if toml_path is not None:
        refuse_existing(toml_path, args.overwrite, "--toml")
        scenario = _actuator_scenario(args, spacecraft, actuator, max_rate)  # its options checked before the design
    design = design_for_actuator(spacecraft, args.tau, actuator, max_rate=max_rate, settling_time=settling, order=order)
    if not design.designed:
        raise SpecificationError(f"--settling-time {settling:g}: {design.status.value}: {design.reason}")
    if toml_path is not None and scenario is not None:
        scenario = replace(scenario, K=design.K, law=design.law)
        check_steering_scenario(design.law, scenario.rule, design.K)
        comment = (
            f"Written by: mrpctl design --inertia {' '.join(f'{v:g}' for v in args.inertia)} --tau {args.tau:g} "
            + (f"--torque-limit {args.torque_limit:g}" if args.wheels is None else f"--wheels {args.wheels}")
            + f" --max-rate {max_rate:g} --settling-time {settling:g}\n"
            f"{design.status.value}: predicted worst-case settling {design.predicted_time:.4g} s of the envelope "
            f"(|omega0| <= {max_rate:g} rad/s, any attitude), lower bound of any law {design.lower_bound:.4g} s\n"
            "[steering] is the designed law, [gains] its K near the target. Initial state: a 170 deg slew about "
            "(1, 1, 1) with |omega0| = --max-rate about x; edit freely. The [steering] table goes into a campaign "
            "file as it is."
        )
        with atomic_output(toml_path) as stream:
            stream.write(scenario_toml(scenario, comment=comment))
    if args.json:
        print_json(
            {
                "status": design.status.name,
                "K": design.K,
                "rate_limit": design.law.rate_limit,
                "acceleration": design.law.acceleration,
                "lag": design.law.lag,
                "momentum_limit": design.law.momentum_limit,
                "predicted_time": design.predicted_time,
                "lower_bound": design.lower_bound,
                "reason": design.reason,
                "toml": toml_path,
            }
        )
        return 0
    print(design)
    print("K (3x6, N m) on x = [sigma; omega/4] (the law near the target):")
    print(np.array2string(design.K, precision=6, max_line_width=200, suppress_small=False))
    if toml_path is not None:
        print(f"scenario written to {toml_path} (run: mrpctl simulate {toml_path})")
    return 0


def _actuator_scenario(
    args: argparse.Namespace, spacecraft: Spacecraft, actuator: ActuatorModel | WheelCluster, max_rate: float
) -> Scenario:
    """The scenario ``design --torque-limit/--wheels --toml`` writes (K and the law set after the design): the
    actuator's [actuator] or [wheels], the rule (hysteretic), rate and horizon of the options."""
    rate = 1000.0 if args.rate is None else args.rate
    check_delay(args.tau, rate)
    rule = DEFAULT_RULE if args.rule is None else rule_from_name(args.rule, eps=args.eps, alpha=args.alpha)
    if not isinstance(rule, Hysteretic):
        raise SpecificationError(
            f"--rule {args.rule}: the steering law flies with the controller-side rule only; use --rule hysteretic "
            "(with --alpha, or the default delta)"
        )
    angle = math.radians(170.0)
    axis = np.ones(3) / math.sqrt(3.0)
    x0 = state(math.tan(angle / 4.0) * axis, np.array([max_rate, 0.0, 0.0]))
    wheels = actuator if isinstance(actuator, WheelCluster) else None
    limit = actuator if isinstance(actuator, ActuatorModel) else None
    return replace(
        paper_base(),
        name=Path(args.toml).stem,
        description=f"mrpctl design: tau = {args.tau:g} s, the steering law for "
        + ("the wheels" if limit is None else f"a {float(np.max(limit.u_max)):g} N m torque limit"),
        spacecraft=spacecraft,
        x0=x0,
        tau=float(args.tau),
        rate=float(rate),
        t_final=60.0 if args.t_final is None else float(args.t_final),
        rule=rule,
        actuator=limit,
        wheels=wheels,
    )


def add_parser(commands: Any) -> None:
    parser = commands.add_parser(
        "design",
        help="synthesize PD gains (critically damped by default) certified for a delay",
        description="Synthesize PD gains certified by an LMI for the delay tau; prints K (3x6) and per-axis K1, K2.",
        formatter_class=Formatter,
        epilog=EXIT_CODES,
    )
    parser.add_argument(
        "--inertia", type=float, nargs="+", required=True, metavar="J", help="3 principal inertias or 9 (kg m^2)"
    )
    parser.add_argument("--tau", type=float, required=True, help="measurement delay (s)")
    parser.add_argument("--zeta", type=float, default=1.0, help="damping ratio (1 = critically damped)")
    parser.add_argument("--allow-underdamped", action="store_true", help="accept --zeta below 1")
    parser.add_argument(
        "--order",
        type=int,
        help="Bessel-Legendre order (0 Jensen, 1 Wirtinger); default 3, with --inertia-tolerance 2, with --sampled 0 "
        "(with --jitter 2; --method lmi: 1, with --sampled 0)",
    )
    parser.add_argument(
        "--method",
        choices=("pd", "lmi"),
        default="pd",
        help="pd: PD gains (synthesize_pd, also the robust options); lmi: state feedback by the descriptor "
        "LMI (synthesize_lmi, needs --decay-rate; --zeta does not apply)",
    )
    parser.add_argument(
        "--decay-rate", type=float, metavar="ALPHA", help="with --method lmi: the decay rate (1/s) the LMI imposes"
    )
    robust = parser.add_argument_group(
        "robust design (synthesize_pd with the robust options, or synthesize_lmi with --method lmi; "
        "see design/lmi.md 7.5, 7.9)"
    )
    robust.add_argument(
        "--inertia-tolerance",
        type=float,
        metavar="TOL",
        help="certify for every inertia with J_ii within +-TOL (relative) of --inertia (vertex-dependent functional)",
    )
    robust.add_argument(
        "--product-bound", type=float, default=0.0, metavar="P", help="with --inertia-tolerance: |J_ij| <= P kg m^2"
    )
    robust.add_argument(
        "--sampled",
        type=float,
        metavar="HZ",
        help="certify the sampled loop at HZ with ZOH and d = tau*HZ samples (sawtooth delay); also the --toml rate",
    )
    robust.add_argument(
        "--jitter",
        type=float,
        metavar="TAU_MIN",
        help="certify every time-varying delay tau(t) in [TAU_MIN, tau] (interval criterion, common functional)",
    )
    robust.add_argument(
        "--jitter-rate", type=float, metavar="MU", help="with --jitter: |d tau/dt| <= MU (default: rate unknown)"
    )
    robust.add_argument(
        "--rtol", type=float, metavar="R", help="relative width of the final omega_n bracket (default 1e-3)"
    )
    actuator = parser.add_argument_group(
        "design for the actuator (the rate-limited steering law, design/wheels.md; not with the robust options)"
    )
    actuator.add_argument(
        "--torque-limit", type=float, metavar="U", help="body torque limit per axis (N m): design the steering law"
    )
    actuator.add_argument(
        "--wheels",
        metavar="SCENARIO",
        help="design the steering law for the wheels of this scenario's [wheels] table (a file or a shipped name), "
        "with their momentum limit; instead of --torque-limit",
    )
    actuator.add_argument(
        "--max-rate", type=float, metavar="W", help="with --torque-limit: largest initial rate to recover (rad/s)"
    )
    actuator.add_argument(
        "--settling-time",
        type=float,
        metavar="T",
        help="with --torque-limit or --wheels: the time the envelope must settle in (s); default 60",
    )
    parser.add_argument("--toml", type=Path, help="write a runnable scenario with the designed K to this file")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing --toml file")
    parser.add_argument("--rate", type=float, help="measurement rate written with --toml (Hz); default 1000")
    parser.add_argument("--t-final", type=float, help="horizon written with --toml (s); default 60")
    add_rule_options(parser, f"switching rule written with --toml; default hysteretic, delta = {DEFAULT_DELTA:g}")
    add_json(parser)
    parser.set_defaults(handler=_design)
