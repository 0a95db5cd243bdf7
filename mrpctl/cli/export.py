"""``mrpctl export``: the closed loop of a scenario as CasADi functions and C code; a scenario with [reference]
exports the tracking loop (``export(..., tracking=True)``: ``tracking_controller`` takes the reference row of its
error time)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from mrpctl._export import ExportResult, export, export_wheel_controller
from mrpctl._scenario_wheels import check_wheel_scenario
from mrpctl.cli.common import EXIT_CODES, Formatter, add_flight_options, add_json, add_rule_options, print_json
from mrpctl.cli.limits import check_history_fits
from mrpctl.cli.overrides import apply_flight_options, apply_overrides
from mrpctl.errors import SpecificationError
from mrpctl.flight import Hysteretic
from mrpctl.flight.tracking import ErrorTime
from mrpctl.scenario import Scenario, load_scenario

__all__ = ["add_parser"]


def _export(args: argparse.Namespace) -> int:
    scenario = apply_flight_options(apply_overrides(load_scenario(args.scenario), args), args)
    if scenario.estimated_loop is not None:
        raise SpecificationError(
            "[estimator]: the command exports the loop on the delayed measurement; export the estimator's sample "
            "(its buffer and ports) with mrpctl.estimation.export.export_estimator in Python"
        )
    check_history_fits(scenario)
    if args.out.exists() and any(args.out.iterdir()) and not args.overwrite:
        raise SpecificationError(f"--out {args.out} is not empty; choose a new folder or pass --overwrite")
    if scenario.gravity_gradient:
        raise SpecificationError(
            "[reference] gravity_gradient = true: the exported plant functions (dynamics, step, sample) do not model "
            "the gravity-gradient torque; remove the key to export (the controller does not depend on it)"
        )
    if scenario.law is not None and scenario.wheels is None:
        raise SpecificationError(
            "[steering]: export writes the PD law's controller (u = K x) on an ideal torque; the steering law is "
            "exported with a [wheels] table (the wheel controller), or remove [steering] from a copy of the scenario "
            "to export its gains"
        )
    if scenario.wheels is not None:
        return _print(_export_wheels(scenario, args), args, scenario)
    result = export(
        scenario.spacecraft,
        scenario.K,
        args.out,
        tau=scenario.tau,
        rule=scenario.rule,
        rate=scenario.rate,
        substeps=scenario.substeps,
        overwrite=args.overwrite,
        compile=not args.no_compile,
        physical=args.physical,
        **_tracking(scenario),
        **scenario.run_options,
    )
    return _print(result, args, scenario)


def _export_wheels(scenario: Scenario, args: argparse.Namespace) -> ExportResult:
    """A wheel scenario's controller with its allocation (wheel torques out): ``export_wheel_controller``."""
    check_wheel_scenario(scenario.wheels, scenario.rule, actuator=scenario.actuator, predictor=scenario.predictor)
    if scenario.flight_options:
        raise SpecificationError(
            f"[wheels]: the wheel controller is exported without the {', '.join(scenario.flight_options)} model(s) "
            "(they act on the plant, not in the controller); remove them to export the wheel controller"
        )
    if args.physical:
        raise SpecificationError("--physical: the wheel controller's ports are x = [sigma; omega/4]; leave it out")
    assert scenario.wheels is not None and isinstance(scenario.rule, Hysteretic)
    return export_wheel_controller(
        scenario.spacecraft,
        scenario.K,
        scenario.wheels,
        args.out,
        tau=scenario.tau,
        rule=scenario.rule,
        rate=scenario.rate,
        substeps=scenario.substeps,
        overwrite=args.overwrite,
        compile=not args.no_compile,
        law=scenario.law,
    )


def _print(result: ExportResult, args: argparse.Namespace, scenario: Scenario) -> int:
    if args.json:
        print_json(
            {
                "folder": result.folder,
                "files": list(result.files),
                "library": result.library,
                "skipped_reason": result.skipped_reason,
                "content_hash": result.content_hash,
            }
        )
    else:
        print(result)
        if scenario.reference is not None:
            print(
                _REFERENCE_NOTE.format(reference=scenario.reference, error_time=_tracking(scenario)["error_time"].value)
            )
    return 0


#: What the export of a tracking scenario leaves to the caller: the reference rows.
_REFERENCE_NOTE = (
    "  tracking   reference input: one row (sigma_RN, omega_RN_N, domega_RN_N) per sample, of the {error_time} "
    "time;\n             the profile itself is not exported: feed its rows (mrpctl.guidance.reference_samples)"
)


def _tracking(scenario: Scenario) -> dict[str, Any]:
    """A tracking scenario's keywords of export (``tracking=True``, its error time and feedforward); {} without
    [reference]."""
    if scenario.reference is None:
        return {}
    return {
        "tracking": True,
        "error_time": ErrorTime.MEASUREMENT if scenario.error_time is None else scenario.error_time,
        "feedforward": scenario.feedforward,
    }


def add_parser(commands: Any) -> None:
    parser = commands.add_parser(
        "export",
        help="export the closed loop as CasADi functions and C code",
        formatter_class=Formatter,
        epilog=EXIT_CODES,
    )
    parser.add_argument("scenario", help="scenario TOML or shipped name (spacecraft, gains, tau, rate, rule)")
    parser.add_argument("--out", type=Path, required=True, help="output folder")
    parser.add_argument("--overwrite", action="store_true", help="replace a non-empty output folder")
    parser.add_argument("--no-compile", action="store_true", help="write sources only, no shared library")
    parser.add_argument(
        "--physical",
        action="store_true",
        help="state ports in physical units: sigma and omega (rad/s) instead of x = [sigma; omega/4] "
        "(x -> sigma, omega; x_meas -> sigma_meas, omega_meas; history -> history_sigma, history_omega; ...)",
    )
    add_rule_options(parser)
    parser.add_argument("--tau", type=float, help="override the delay (s)")
    add_flight_options(parser)
    add_json(parser)
    parser.set_defaults(handler=_export)
