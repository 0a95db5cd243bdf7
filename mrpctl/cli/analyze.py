"""``mrpctl analyze``: how well the delayed loop performs (spectrum, margins, H∞ exact and certified, H₂, pointing)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import numpy as np

from mrpctl import paper
from mrpctl._scenario_steering import STEERING_NOT_CERTIFIED
from mrpctl.cli.common import (
    NOT_VERIFIED,
    VERIFY_EXIT_CODES,
    Formatter,
    add_json,
    add_plant_options,
    atomic_output,
    check_plot_path,
    print_json,
)
from mrpctl.cli.overrides import gain_from_args, plant_given, spacecraft_from
from mrpctl.cli.wheels import WHEELS_NOT_CERTIFIED
from mrpctl.design.fixed_order import OBJECTIVES, STRUCTURES, FixedOrderSynthesis, synthesize_fixed_order
from mrpctl.design.performance import (
    hinf_bound,
    hinf_norm,
    loop_margins_delayed,
    sigma_max,
    spacecraft_margins,
)
from mrpctl.design.pointing import (
    h2_norm,
    pointing_budget,
    torque_to_attitude,
)
from mrpctl.design.sampled_margins import loop_margins_sampled
from mrpctl.design.sampled_performance import sampled_h2_norm, sampled_hinf_norm, sampled_l2_gain, sampled_sigma
from mrpctl.design.spectra import characteristic_roots, plot_spectrum
from mrpctl.errors import SpecificationError
from mrpctl.model import gain_matrix
from mrpctl.scenario import load_scenario

__all__ = ["add_parser"]

#: The designs ``--synthesize`` takes: structure-objective.
DESIGNS = tuple(f"{s}-{o}" for s in STRUCTURES for o in OBJECTIVES)


def _finite_nonnegative(option: str, value: float) -> float:
    if not math.isfinite(value) or value < 0.0:
        raise SpecificationError(f"{option} must be finite and >= 0, got {value}")
    return value


def _analyze(args: argparse.Namespace) -> int:
    if args.scenario is not None:
        given = plant_given(args)
        if given:
            raise SpecificationError(
                f"{given[0]} does not apply with a scenario file (the file gives the plant and gain); "
                "leave out the file or the option"
            )
        scenario = load_scenario(args.scenario)
        if scenario.wheels is not None:
            raise SpecificationError(WHEELS_NOT_CERTIFIED.format(command="analyze"))
        if scenario.law is not None:
            raise SpecificationError(STEERING_NOT_CERTIFIED.format(command="analyze"))
        spacecraft, gain, tau = scenario.spacecraft, scenario.K, scenario.tau
    else:
        spacecraft = spacecraft_from(list(paper.INERTIA) if args.inertia is None else args.inertia)
        given_gain = gain_from_args(args)
        gain, tau = (paper.GAIN if given_gain is None else given_gain), paper.TAU
    if args.tau is not None:
        tau = args.tau
    if not math.isfinite(tau) or tau <= 0:
        raise SpecificationError(f"--tau must be finite and > 0 s, got {tau}")
    psd = _finite_nonnegative("--torque-psd", args.torque_psd)
    att = _finite_nonnegative("--attitude-noise", args.attitude_noise)
    rate = _finite_nonnegative("--rate-noise", args.rate_noise)
    samples = _delay_samples(args.period, tau)
    check_plot_path(args.plot)
    _check_sigma_path(args.plot_sigma)
    design: FixedOrderSynthesis | None = None
    if args.synthesize is not None:
        if args.scenario is not None or gain_from_args(args) is not None:
            raise SpecificationError("--synthesize designs the gain: leave out the scenario file's or the given gain")
        structure, objective = args.synthesize.split("-")
        if structure == "pid" and (psd or att or rate or args.period is not None):
            raise SpecificationError(
                "--synthesize pid-...: the pointing budget and --period take a PD gain; "
                "use a pd design or leave them out"
            )
        design = synthesize_fixed_order(
            spacecraft, tau, structure=structure, objective=objective, starts=args.starts, order=None
        )
        gain = design.K
    if design is not None and design.K_i is not None:
        return _analyze_pid(args, design)
    a, a_d, b, c = torque_to_attitude(spacecraft, gain)
    spectrum = characteristic_roots(a, a_d, tau, count=6)
    exact = hinf_norm(a, a_d, tau, b, c)
    stable = exact.stable
    payload: dict[str, Any] = {
        "tau": tau,
        "spectral_abscissa": spectrum.abscissa,
        "spectrum_certified": spectrum.certified,
        "stable": stable,
        "hinf_exact": exact.value if stable else None,
        "hinf_frequency": exact.frequency if stable else None,
    }
    lines = [f"delayed loop of {spacecraft} at tau = {tau:g} s", f"  {str(spectrum).splitlines()[0]}"]
    if design is not None:
        lines.insert(0, str(design))
        payload["design"] = {"structure": design.structure, "objective": design.objective, "K": design.K.tolist()}
    if stable:
        margins = spacecraft_margins(spacecraft, gain, tau)
        bound = hinf_bound(a, a_d, tau, b, c, order=args.order)
        h2 = h2_norm(a, a_d, tau, b, c)
        payload.update(
            {
                "gain_margin": margins.coupled.gain_margin,
                "phase_margin_deg": math.degrees(margins.coupled.phase_margin),
                "delay_margin_more": margins.coupled.delay_margin,
                "hinf_certified": bound.value if bound.certified else None,
                "hinf_ratio": exact.value / bound.value if bound.certified else None,
                "h2": h2.value,
            }
        )
        lines += [f"  margins: {margins.coupled}"]
        lines += [f"    axis {i + 1}: {m}" for i, m in enumerate(margins.axes)]
        lines += [
            f"  torque -> attitude angle: {exact}",
            f"  {bound}" + (f"; exact/certified = {exact.value / bound.value:.6f}" if bound.certified else ""),
            f"  {h2}",
        ]
        if psd or att or rate:
            budget = pointing_budget(spacecraft, gain, tau, torque_psd=psd, attitude_noise=att, rate_noise=rate)
            payload["pointing_three_sigma_arcsec"] = list(budget.three_sigma)
            payload["pointing_total_three_sigma_arcsec"] = budget.total_three_sigma
            lines.append(f"  {budget}")
    else:
        lines.append(f"  {exact}")
    sampled_stable = True
    if args.period is not None:
        k = gain_matrix(gain)
        sh2 = sampled_h2_norm(a, b, k, args.period, delay_samples=samples, C=c)
        shinf = sampled_hinf_norm(a, b, k, args.period, delay_samples=samples, C=c)
        sl2 = sampled_l2_gain(a, b, k, args.period, delay_samples=samples, C=c)
        sampled_margins = loop_margins_sampled(a, b, k, args.period, delay_samples=samples)
        sampled_stable = shinf.finite
        lines += [
            f"  sampled loop, period {args.period:g} s, {samples} samples of delay (ZOH):",
            f"    margins: {sampled_margins}",
            f"    {sh2}",
            f"    {sl2} (continuous torque -> continuous attitude)",
            f"    {shinf} (torque held over each sample, attitude sampled)",
        ]
        payload.update(
            {
                "period": args.period,
                "delay_samples": samples,
                "sampled_spectral_radius": shinf.spectral_radius,
                "sampled_h2": sh2.value if sh2.finite else None,
                "sampled_hinf": shinf.value if shinf.finite else None,
                "sampled_hinf_frequency": shinf.frequency if shinf.finite else None,
                "sampled_l2_gain": sl2.value if sl2.finite else None,
                "sampled_l2_bracket_certified": sl2.bracket_certified,
                "sampled_gain_margin": sampled_margins.gain_margin,
                "sampled_phase_margin_deg": math.degrees(sampled_margins.phase_margin),
                "sampled_delay_margin_samples": sampled_margins.delay_margin_samples,
            }
        )
    if args.plot_sigma is not None:
        _plot_sigma(args, a, a_d, b, c, tau, exact, gain, samples)
    if args.plot is not None:
        figure = plot_spectrum(spectrum)
        with atomic_output(args.plot, "wb") as stream:
            figure.savefig(stream, format=args.plot.suffix.lstrip(".").lower())
    if args.json:
        print_json(payload)
    else:
        print("\n".join(lines))
    return 0 if stable and sampled_stable else NOT_VERIFIED


def _delay_samples(period: float | None, tau: float) -> int:
    """d = τ/h for ``--period h``: h finite, > 0 and dividing τ (a whole number of samples of delay)."""
    if period is None:
        return 0
    if not math.isfinite(period) or period <= 0.0:
        raise SpecificationError(f"--period must be finite and > 0 s, got {period}")
    d = round(tau / period)
    if d < 0 or abs(d * period - tau) > 1e-9 * max(tau, period):
        raise SpecificationError(f"--period {period:g} s must divide --tau {tau:g} s (a whole number of samples)")
    return d


def _check_sigma_path(path: Path | None) -> None:
    try:
        check_plot_path(path)
    except SpecificationError as err:
        raise SpecificationError(str(err).replace("--plot ", "--plot-sigma ", 1)) from None


def _analyze_pid(args: argparse.Namespace, design: FixedOrderSynthesis) -> int:
    """The PID design's loop on (σ, ω/4, ∫σ): its spectrum, margins, H∞ and H₂ (the budget takes a PD gain)."""
    a_d = design.B @ design.gain
    margins = loop_margins_delayed(design.A, design.B, design.gain, design.tau)
    stable = design.hinf.finite
    lines = [str(design), f"  margins: {margins}", f"  torque -> attitude angle: {design.hinf}", f"  {design.h2}"]
    payload: dict[str, Any] = {
        "tau": design.tau,
        "design": {"structure": "pid", "objective": design.objective, "K": design.gain.tolist()},
        "spectral_abscissa": design.abscissa,
        "stable": stable,
        "hinf_exact": design.hinf.value if stable else None,
        "h2": design.h2.value if stable else None,
        "gain_margin": margins.gain_margin,
        "phase_margin_deg": math.degrees(margins.phase_margin),
        "delay_margin_more": margins.delay_margin,
    }
    if args.plot_sigma is not None:
        _plot_sigma(args, design.A, a_d, design.B_w, design.C, design.tau, design.hinf, None, 0)
    if args.plot is not None:
        figure = plot_spectrum(characteristic_roots(design.A, a_d, design.tau, count=6))
        with atomic_output(args.plot, "wb") as stream:
            figure.savefig(stream, format=args.plot.suffix.lstrip(".").lower())
    if args.json:
        print_json(payload)
    else:
        print("\n".join(lines))
    return 0 if stable else NOT_VERIFIED


def _plot_sigma(
    args: argparse.Namespace, a: Any, a_d: Any, b: Any, c: Any, tau: float, exact: Any, gain: Any, d: int
) -> None:
    """σ_max of torque → attitude angle over ω, the exact H∞ peak marked; the sampled loop's too with --period."""
    # deferred: matplotlib, only for --plot-sigma
    from matplotlib.figure import Figure

    top = 10.0 * max(exact.frequency if exact.finite else 1.0, 1.0 / tau)
    omega = np.geomspace(1e-3, top, 2000)
    figure = Figure(figsize=(6.0, 4.0))
    ax = figure.add_subplot(1, 1, 1)
    ax.loglog(omega, sigma_max(a, a_d, tau, b, c, omega), label=f"delayed loop, tau = {tau:g} s")
    if exact.finite:
        ax.plot([exact.frequency], [exact.value], "o", color="C0", label=f"H-infinity {exact.value:.4g}")
    if args.period is not None and gain is not None:
        nyquist = np.pi / args.period
        w = omega[omega < nyquist]
        s = sampled_sigma(a, b, gain_matrix(gain), args.period, w, delay_samples=d, C=c)
        ax.loglog(w, s, "--", color="C1", label=f"sampled, h = {args.period:g} s (held torque)")
    ax.set_xlabel("omega (rad/s)")
    ax.set_ylabel("sigma_max, rad/(N m)")
    ax.set_title("torque -> attitude angle")
    ax.legend(fontsize=8)
    with atomic_output(args.plot_sigma, "wb") as stream:
        figure.savefig(stream, format=args.plot_sigma.suffix.lstrip(".").lower())


def add_parser(commands: Any) -> None:
    parser = commands.add_parser(
        "analyze",
        help="spectrum, margins, H-infinity (exact and certified), H2 and pointing of the delayed loop",
        formatter_class=Formatter,
        epilog=VERIFY_EXIT_CODES,
    )
    parser.add_argument(
        "scenario", nargs="?", help="scenario TOML or shipped name (else the plant and gain options, or the paper's)"
    )
    add_plant_options(parser, "the paper's 140 100 80")
    parser.add_argument("--tau", type=float, help="delay (s); default the scenario's or 0.5")
    parser.add_argument("--order", type=int, default=2, help="Bessel-Legendre order of the H-infinity LMI bound")
    parser.add_argument("--torque-psd", type=float, default=0.0, help="torque disturbance PSD, N^2 m^2/Hz one-sided")
    parser.add_argument("--attitude-noise", type=float, default=0.0, help="attitude sensor ASD, rad/sqrt(Hz)")
    parser.add_argument("--rate-noise", type=float, default=0.0, help="rate sensor ASD, rad/s/sqrt(Hz)")
    parser.add_argument("--plot", type=Path, help="save the characteristic roots as a figure (png, pdf, svg)")
    parser.add_argument(
        "--plot-sigma", type=Path, help="save sigma_max(omega) of torque -> attitude as a figure (png, pdf, svg)"
    )
    parser.add_argument(
        "--period", type=float, help="also the sampled loop: period h (s, dividing tau), ZOH, tau/h samples of delay"
    )
    parser.add_argument(
        "--synthesize",
        choices=DESIGNS,
        help="design the per-axis gains first: structure-objective (spectral abscissa, H-infinity or H2 at tau)",
    )
    parser.add_argument("--starts", type=int, default=3, help="starting points of the --synthesize search")
    add_json(parser)
    parser.set_defaults(handler=_analyze)
