"""``mrpctl analyze``: how well the delayed loop performs (spectrum, margins, H∞ exact and certified, H₂, pointing)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

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
from mrpctl.design.performance import (
    hinf_bound,
    hinf_norm,
    spacecraft_margins,
)
from mrpctl.design.pointing import (
    h2_norm,
    pointing_budget,
    torque_to_attitude,
)
from mrpctl.design.spectra import characteristic_roots, plot_spectrum
from mrpctl.errors import SpecificationError
from mrpctl.scenario import load_scenario

__all__ = ["add_parser"]


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
    check_plot_path(args.plot)
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
    if args.plot is not None:
        figure = plot_spectrum(spectrum)
        with atomic_output(args.plot, "wb") as stream:
            figure.savefig(stream, format=args.plot.suffix.lstrip(".").lower())
    if args.json:
        print_json(payload)
    else:
        print("\n".join(lines))
    return 0 if stable else NOT_VERIFIED


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
    add_json(parser)
    parser.set_defaults(handler=_analyze)
