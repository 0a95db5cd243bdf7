"""``mrpctl verify``: the LMI verdict per criterion, the exact delay margin and the certificates of the loop
as flown (sampled, jittering delay, inertia box); a tracking scenario's verdict is
[`verify_tracking`][mrpctl.cli.verify_tracking]'s."""

from __future__ import annotations

import argparse
import math
from typing import Any

import numpy as np

from mrpctl import paper
from mrpctl._scenario_steering import STEERING_NOT_CERTIFIED
from mrpctl._validation import nonnegative_scalar, positive_scalar
from mrpctl.cli.common import (
    NOT_VERIFIED,
    VERIFY_EXIT_CODES,
    Formatter,
    add_json,
    add_plant_options,
    flown_options_given,
    joint_json,
    print_json,
)
from mrpctl.cli.overrides import gain_from_args, plant_given, spacecraft_from
from mrpctl.cli.verify_predictor import check_predictor_options, verify_predictor
from mrpctl.cli.verify_tracking import check_tracking_options, verify_tracking
from mrpctl.cli.wheels import WHEELS_NOT_CERTIFIED
from mrpctl.design import (
    FlownVerdict,
    analyze_gains,
    certify_interval,
    certify_polytope,
    certify_sampled,
    criterion_name,
    inertia_polytope,
    linearized_loop,
    sampled_stability,
    spacecraft_axes,
    verify_flown,
)
from mrpctl.design.interval import rate_value
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.scenario import Scenario, check_delay, load_scenario
from mrpctl.spacecraft import Spacecraft

__all__ = ["add_parser"]


def _flown_plan(args: argparse.Namespace, tau: float, scenario: Scenario | None) -> dict[str, Any]:
    """What ``verify`` certifies besides the idealised loop: the options, else the scenario's loop as flown.

    A scenario brings its sample ``rate`` (the sampled-data loop: exact lifted check + certificate), its
    ``[delay]`` bounds (the interval certificate, rate unknown: the flown delay jumps from sample to sample)
    and its ``[uncertainty]`` inertia box. ``--jitter``, ``--jitter-rate``, ``--sampled`` and
    ``--inertia-tolerance`` override the scenario's values; ``--no-flown`` keeps the idealised loop only.
    """
    given = flown_options_given(args, no_flown=False)
    if args.no_flown and given:
        raise SpecificationError(f"{given[0]} does not apply with --no-flown (the idealised loop only)")
    from_file = scenario is not None and not args.no_flown
    plan: dict[str, Any] = {"jitter": None, "sampled": None, "inertia": None}
    if args.jitter is not None:
        plan["jitter"] = (nonnegative_scalar("--jitter", args.jitter), "--jitter")
    elif from_file and scenario is not None and scenario.delay is not None:
        plan["jitter"] = (scenario.delay.tau_min, "[delay] tau_min")
    if args.jitter_rate is not None and plan["jitter"] is None:
        raise SpecificationError("--jitter-rate applies only with --jitter TAU_MIN (or a scenario's [delay] table)")
    if args.sampled is not None:
        plan["sampled"] = (positive_scalar("--sampled", args.sampled), "--sampled")
    elif from_file and scenario is not None:
        plan["sampled"] = (scenario.rate, "rate")
    if args.product_bound is not None and args.inertia_tolerance is None:
        raise SpecificationError("--product-bound applies only with --inertia-tolerance TOL")
    if args.inertia_tolerance is not None:
        bound = 0.0 if args.product_bound is None else nonnegative_scalar("--product-bound", args.product_bound)
        plan["inertia"] = (positive_scalar("--inertia-tolerance", args.inertia_tolerance), bound, "--inertia-tolerance")
    elif from_file and scenario is not None and scenario.uncertainty is not None:
        plan["inertia"] = (scenario.uncertainty.tolerance, scenario.uncertainty.product_bound, "[uncertainty]")
    if tau <= 0:
        flagged = [option for option in ("--jitter", "--sampled", "--inertia-tolerance") if option in given]
        if flagged:
            raise SpecificationError(
                f"{flagged[0]} needs a delay --tau > 0 (--jitter, --sampled and --inertia-tolerance)"
            )
        # tau = 0 from a scenario: no jitter interval, no delay to certify over the box; the sampled loop
        # (d = 0) is still flown.
        plan["jitter"] = plan["inertia"] = None
    return plan


def _flown_checks(
    args: argparse.Namespace, spacecraft: Spacecraft, gain: np.ndarray, tau: float, scenario: Scenario | None = None
) -> list[dict[str, Any]]:
    """The certificates of the loop as flown (`_flown_plan`), as rows (check, verdict, fields, text)."""

    plan = _flown_plan(args, tau, scenario)
    rows: list[dict[str, Any]] = []
    hold = 0.0
    if plan["sampled"] is not None:
        rate, source = plan["sampled"]
        d = round(tau * rate)
        if abs(tau * rate - d) > 1e-9 * max(1.0, tau * rate):
            raise SpecificationError(f"{source}: tau * HZ must be a whole number of samples, got {tau * rate!r}")
        hold = 1.0 / rate
        axes = spacecraft_axes(spacecraft, gain)
        try:
            exact = [sampled_stability(a, b, k, hold, delay_samples=d) for a, b, k in axes]
        except SpecificationError as exc:  # the lifted system is refused above MAX_LIFTED_SIZE rows
            raise SpecificationError(
                f"{source} = {rate:g} Hz: {exc}; or leave the sampled check out (--no-flown)"
            ) from exc
        certified = [certify_sampled(a, b, k, hold, delay_samples=d, order=0) for a, b, k in axes]
        names = _axis_names(spacecraft, len(axes))
        rows.append(
            {
                "check": "sampled",
                "source": source,
                "rate_hz": rate,
                "delay_samples": d,
                "criterion": "input delay, Jensen + reciprocal convexity (N=0)",
                "certified": all(c.certified for c in certified),
                "statuses": [c.status.name for c in certified],
                "exact_stable": all(e.stable for e in exact),
                "spectral_radius": max(e.spectral_radius for e in exact),
                "axes": names,
                "text": "\n".join(
                    [f"{name}: {e}" for name, e in zip(names, exact, strict=True)]
                    + [f"{name}: {c}" for name, c in zip(names, certified, strict=True)]
                ),
            }
        )
    if plan["jitter"] is not None:
        tau_min, source = plan["jitter"]
        if tau_min >= tau:
            raise SpecificationError(f"{source} must be < tau = {tau:g} s, got {tau_min:g}")
        # Sampled and held, the delay the plant sees grows by up to one period after each sample.
        tau_max = tau + hold
        rate_bound = rate_value(args.jitter_rate)
        loop = linearized_loop(spacecraft, gain)
        pairs = loop.axes if loop.split else ((loop.A, loop.A_d),)
        certificates = [certify_interval(a, a_d, tau_max, tau_min=tau_min, delay_rate=rate_bound) for a, a_d in pairs]
        rows.append(
            {
                "check": "jitter",
                "source": source,
                "tau_min": tau_min,
                "tau_max": tau_max,
                "delay_rate": str(rate_bound),
                "criterion": "interval delay, Wirtinger + reciprocal convexity (N=1)",
                "certified": all(c.certified for c in certificates),
                "statuses": [c.status.name for c in certificates],
                "text": "\n".join(str(c) for c in certificates),
            }
        )
    if plan["inertia"] is not None:
        tolerance, bound, source = plan["inertia"]
        try:
            polytope = inertia_polytope(spacecraft, tolerance, product_bound=bound)
        except (SpecificationError, DimensionError) as exc:
            raise type(exc)(f"{source}: {exc}") from exc
        certificate = certify_polytope(polytope, gain, tau)
        rows.append(
            {
                "check": "inertia",
                "source": source,
                "inertia_tolerance": tolerance,
                "product_bound": bound,
                "criterion": f"{certificate.functional.name.lower()} functional over {certificate.vertices} "
                f"vertices, N={certificate.order}",
                "certified": certificate.certified,
                "statuses": [certificate.status.name],
                "text": f"{polytope}\n{certificate}",
            }
        )
    return rows


def _axis_names(spacecraft: Spacecraft, count: int) -> list[str]:
    """'axis 1 (J = 140 kg m^2)', ... for a loop that splits per axis, else the one coupled 6x6 loop."""
    if count == 3:
        return [f"axis {i + 1} (J = {spacecraft.inertia[i][i]:g} kg m^2)" for i in range(3)]
    return ["coupled 6x6 loop"]


def _joint_verdict(
    args: argparse.Namespace, spacecraft: Spacecraft, gain: np.ndarray, tau: float, scenario: Scenario | None
) -> FlownVerdict:
    """The joint verdict on the loop as flown ([verify_flown][mrpctl.design.flown.verify_flown]) of `_flown_plan`.

    The lifted checks take 5 inertias per axis and 5 delays of a jitter interval, or only the box ends
    and the interval's ends when one lifted loop has more than 400 rows (1 kHz with d = 500: 1002 rows,
    seconds per eigenproblem); the verdict names what it checked.
    """
    plan = _flown_plan(args, tau, scenario)
    rate = None if plan["sampled"] is None else plan["sampled"][0]
    tau_min = None if plan["jitter"] is None else plan["jitter"][0]
    tolerance, bound = (None, 0.0) if plan["inertia"] is None else plan["inertia"][:2]
    dense = rate is None or 2 * (round(tau * rate) + 1) <= 400
    return verify_flown(
        spacecraft,
        gain,
        tau,
        rate=rate,
        tau_min=tau_min,
        jitter_rate=args.jitter_rate if tau_min is not None else None,
        tolerance=tolerance,
        product_bound=bound,
        grid=5 if dense else 2,
        delay_points=5 if dense else 2,
    )


def _phase_margins(spacecraft: Spacecraft, gain: np.ndarray) -> Any:
    """Per-axis phase margin and crossover (python-control), or None when the axes are coupled."""
    # deferred: python-control and matplotlib (through mrpctl.interop, about 3.5 s to import), only for verify
    from mrpctl.interop import loop_margins

    try:
        return loop_margins(spacecraft, gain)
    except SpecificationError:
        return None


def _verify(args: argparse.Namespace) -> int:
    if args.scenario is not None:
        given = plant_given(args)
        if given:
            raise SpecificationError(
                f"{given[0]} does not apply with a scenario file (the file gives the plant and gain); "
                "leave out the file or the option"
            )
        scenario: Scenario | None = load_scenario(args.scenario)
        assert scenario is not None
        if scenario.wheels is not None:
            raise SpecificationError(WHEELS_NOT_CERTIFIED.format(command="verify"))
        if scenario.law is not None:
            raise SpecificationError(STEERING_NOT_CERTIFIED.format(command="verify"))
        spacecraft, gain, tau = scenario.spacecraft, scenario.K, scenario.tau
    else:
        scenario = None
        spacecraft = spacecraft_from(list(paper.INERTIA) if args.inertia is None else args.inertia)
        gain_or_none = gain_from_args(args)
        gain, tau = (paper.GAIN if gain_or_none is None else gain_or_none), paper.TAU
    if args.tau is not None:
        tau = args.tau
    if not math.isfinite(tau) or tau < 0:
        raise SpecificationError(f"--tau must be finite and >= 0 s, got {tau}")
    if scenario is not None and (scenario.reference is not None or scenario.predictor is not None):
        # a tracking scenario: the tracking-error loop linearised about its reference (verify_tracking); a
        # predictor scenario: the predictor loop linearised about the origin (verify_predictor), not the plain
        # delayed loop
        tracking = scenario.reference is not None
        (check_tracking_options if tracking else check_predictor_options)(args)
        try:
            check_delay(tau, scenario.rate)
        except SpecificationError as exc:
            raise SpecificationError(f"--tau {tau:g} at the scenario's rate {scenario.rate:g} Hz: {exc}") from exc
        return (verify_tracking if tracking else verify_predictor)(args, scenario, tau)
    # The loop as flown first: a refusal (bad option, lifted system too large) comes before the long searches.
    flown = _flown_checks(args, spacecraft, gain, tau, scenario)
    joint = _joint_verdict(args, spacecraft, gain, tau, scenario)
    loop = linearized_loop(spacecraft, gain)
    margin = loop.delay_margin()
    rows: list[dict[str, Any]] = []
    undelayed = analyze_gains(spacecraft, gain)
    if tau > 0:
        for order in args.orders:
            certificate = loop.certify(tau, order=order)
            search = loop.max_certified_delay(order=order)
            finite = np.isfinite(margin.margin) and margin.margin > 0
            rows.append(
                {
                    "criterion": criterion_name(order),
                    "order": order,
                    "status": certificate.status.name,
                    "certified": certificate.certified,
                    "max_certified_tau": search.tau,
                    "ratio_to_exact": search.tau / margin.margin if finite else float("nan"),
                }
            )
    margins = _phase_margins(spacecraft, gain)
    idealised_certified = tau == 0 or any(row["certified"] for row in rows)
    code = 0 if joint.verified and idealised_certified else NOT_VERIFIED
    if args.json:
        print_json(
            {
                "tau": tau,
                "K": gain,
                "inertia": spacecraft.inertia,
                "flown": [{key: value for key, value in row.items() if key != "text"} for row in flown],
                "phase_margins": None
                if margins is None
                else [
                    {
                        "axis": m.axis,
                        "phase_margin_deg": math.degrees(m.phase_margin),
                        "crossover_rad_s": m.crossover,
                        "delay_margin_s": m.delay_margin,
                    }
                    for m in margins.axes
                ],
                "exact_delay_margin": margin.margin,
                "stable_at_tau": margin.is_stable(tau) if tau > 0 else undelayed.stable,
                "undelayed_stable": undelayed.stable,
                "undelayed_poles_real": undelayed.poles.real,
                "undelayed_poles_imag": undelayed.poles.imag,
                "criteria": rows,
                "joint": joint_json(joint),
                "exit_code": code,
            }
        )
        return code
    print(f"{loop}; K = {(np.round(gain, 4) + 0.0).tolist()}")
    if tau == 0:
        worst = float(np.max(undelayed.poles.real))
        print(
            "tau = 0: no delay, so no delay certificate is needed; the undelayed loop is "
            f"{'stable' if undelayed.stable else 'NOT stable'} (rightmost pole real part {worst:.6g} 1/s)"
        )
        print(f"exact delay margin: {margin.margin:.6g} s (largest delay this gain tolerates)")
        _print_flown(flown)
        _print_joint(joint, code)
        return code
    print(f"exact delay margin: {margin.margin:.6g} s (stable at tau = {tau:g} s: {margin.is_stable(tau)})")
    if margins is not None:
        print(str(margins))
    print(f"{'criterion':<24} {'at tau':<16} {'largest certified tau (s)':>26} {'ratio to exact':>15}")
    for row in rows:
        print(
            f"{row['criterion']:<24} {row['status']:<16} {row['max_certified_tau']:>26.6g} "
            f"{row['ratio_to_exact']:>15.4f}"
        )
    if not idealised_certified:
        print(f"no criterion of --orders certifies the idealised loop at tau = {tau:g} s")
    _print_flown(flown)
    _print_joint(joint, code)
    return code


def _print_flown(flown: list[dict[str, Any]]) -> None:
    """The loop-as-flown rows of ``verify``: verdict, where the check comes from, and each certificate."""
    if flown:
        print("each part of the loop as flown, separately (the others at their idealised values):")
    for row in flown:
        verdict = "certified" if row["certified"] else "NOT certified"
        print(f"{row['check']} ({row['source']}): {verdict}{_why_not(row)}")
        print("  " + row["text"].replace("\n", "\n  "))


def _why_not(row: dict[str, Any]) -> str:
    """Why a separate row is NOT certified, in plain words (empty when it is certified)."""
    if row["certified"]:
        return ""
    failed = " or ".join(sorted({s for s in row["statuses"] if s != "CERTIFIED"}))
    lmi = "the solver gave no usable answer" if failed == "SOLVER_FAILED" else "the LMI found no proof"
    if row["check"] == "sampled":
        bad = [name for name, s in zip(row["axes"], row["statuses"], strict=True) if s != "CERTIFIED"]
        where = ", ".join(bad)
        if not row["exact_stable"]:
            return (
                f": the sampled loop is unstable (largest lifted spectral radius {row['spectral_radius']:.9f} > 1), "
                f"so no certificate can exist ({where})"
            )
        return (
            f": the exact lifted check finds the sampled loop stable (spectral radius "
            f"{row['spectral_radius']:.9f} < 1), but {lmi} on {where} (the sampled-data LMI is a sufficient "
            "condition: stable, not certified)"
        )
    return f": {lmi} ({failed}); the LMI is a sufficient condition, so this does not say the loop is unstable"


def _print_joint(verdict: FlownVerdict, code: int) -> None:
    """The joint verdict on the loop as flown, and the exit code it gives."""
    print(verdict)
    print(f"exit code {code}: " + ("verified" if code == 0 else "checked, NOT verified (see above)"))


def add_parser(commands: Any) -> None:
    parser = commands.add_parser(
        "verify",
        help="LMI verdict per criterion and the exact delay margin",
        formatter_class=Formatter,
        epilog=VERIFY_EXIT_CODES,
    )
    parser.add_argument(
        "scenario", nargs="?", help="scenario TOML or shipped name (else the plant and gain options, or the paper's)"
    )
    add_plant_options(parser, "the paper's 140 100 80")
    parser.add_argument("--tau", type=float, help="delay to certify (s); default the scenario's or 0.5")
    parser.add_argument("--orders", type=int, nargs="+", default=[0, 1, 2, 3], help="LMI orders")
    flown = parser.add_argument_group(
        "the loop as flown (each adds a certificate; see design/lmi.md section 7). A scenario file adds them "
        "itself: its rate (sampled loop), [delay] (jitter, rate unknown) and [uncertainty] (inertia box); "
        "these options override the file's values. A tracking scenario ([reference]) is verified as its tracking "
        "loop linearised about the reference (exact margin, LMI at tau, the sampled loop at its rate), a "
        "predictor scenario ([predictor]) as its predictor loop linearised about the origin (the exact test of the "
        "sampled loop at its rate, with the inertia mismatch margin); these options do not apply to either, and "
        "what their checks do not cover is listed and makes them NOT VERIFIED"
    )
    flown.add_argument(
        "--jitter",
        type=float,
        metavar="TAU_MIN",
        help="time-varying delay tau(t) in [TAU_MIN, tau] (+ one period when the loop is sampled): interval "
        "certificate (Wirtinger + reciprocal convexity)",
    )
    flown.add_argument(
        "--jitter-rate", type=float, metavar="MU", help="with --jitter: |d tau/dt| <= MU (default: rate unknown)"
    )
    flown.add_argument(
        "--sampled",
        type=float,
        metavar="HZ",
        help="sampled-data loop at HZ with ZOH and d = tau*HZ samples: exact lifted check and Jensen certificate",
    )
    flown.add_argument(
        "--inertia-tolerance",
        type=float,
        metavar="TOL",
        help="every inertia with J_ii within +-TOL (relative): a vertex-dependent LK functional "
        "(a common one above 8 vertices)",
    )
    flown.add_argument(
        "--product-bound", type=float, metavar="P", help="with --inertia-tolerance: |J_ij| <= P kg m^2 (default 0)"
    )
    flown.add_argument(
        "--no-flown",
        action="store_true",
        help="a scenario's idealised loop only: leave out the certificates of its rate, [delay] and [uncertainty]",
    )
    add_json(parser)
    parser.set_defaults(handler=_verify)
