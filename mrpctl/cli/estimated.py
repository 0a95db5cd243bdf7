"""``mrpctl simulate`` of a scenario with an ``[estimator]`` table: the loop on the estimate of a late star tracker
and a gyro (``design/estimation.md``), its summary, trajectory and plot."""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from mrpctl._validation import integer
from mrpctl.cli.common import EXIT_DIVERGED, atomic_output, check_plot_path, options_given, print_json, save_plot
from mrpctl.cli.limits import check_run_fits
from mrpctl.errors import SpecificationError
from mrpctl.estimation import ARCSEC, EstimatedLoop, EstimatorKind, Sensors
from mrpctl.flight import Hysteretic
from mrpctl.mrp import b_matrix_inverse
from mrpctl.scenario import Scenario
from mrpctl.simulation.estimated import EstimatedResult

__all__ = ["add_estimator_options", "attitude_sigma", "estimator_options_given", "simulate_estimated_scenario"]

_CSV_HEADER = (
    "t_s",
    *(f"sigma{i}" for i in (1, 2, 3)),
    *(f"omega{i}_rad_s" for i in (1, 2, 3)),
    *(f"sigma_hat{i}" for i in (1, 2, 3)),
    *(f"omega_hat{i}_rad_s" for i in (1, 2, 3)),
    *(f"bias{i}_rad_s" for i in (1, 2, 3)),
    *(f"bias_hat{i}_rad_s" for i in (1, 2, 3)),
    *(f"u{i}_Nm" for i in (1, 2, 3)),
)
#: The settling time's attitude tolerance of the summary (rad): the one of ``design/estimation.md``'s table.
SETTLED = 0.01
#: The options of the other loops, which the estimated loop does not fly.
_OTHER_OPTIONS = (
    ("--torque-limit", "torque_limit"),
    ("--torque-norm", "torque_norm"),
    ("--saturation", "saturation"),
    ("--attitude-noise", "attitude_noise"),
    ("--rate-noise", "rate_noise"),
    ("--gyro-bias", "gyro_bias"),
    ("--disturbance", "disturbance"),
    ("--disturbance-file", "disturbance_file"),
    ("--delay-file", "delay_file"),
    ("--jitter", "jitter"),
    ("--jitter-seed", "jitter_seed"),
    ("--predictor-inertia", "predictor_inertia"),
    ("--predictor-error", "predictor_error"),
    ("--predictor-form", "predictor_form"),
    ("--pointing-plot", "pointing_plot"),
    ("--wheels-plot", "wheels_plot"),
)


def add_estimator_options(parser: argparse.ArgumentParser) -> None:
    """``--estimator KIND``: the estimator of a scenario's [estimator] table (``--noise-seed`` its sensors' seed)."""
    group = parser.add_argument_group(
        "the estimated loop (a scenario with an [estimator] table; design/estimation.md; --noise-seed sets the seed "
        "of its star tracker's and gyro's noise)"
    )
    group.add_argument(
        "--estimator",
        choices=[kind.value for kind in EstimatorKind],
        help="the estimator: the multiplicative EKF or the MRP-based EKF with shadow sets (default the scenario's)",
    )


def estimator_options_given(args: argparse.Namespace) -> list[str]:
    """The estimated loop's own options given on the command line."""
    return options_given(("--estimator", getattr(args, "estimator", None)))


def _apply(scenario: Scenario, args: argparse.Namespace) -> tuple[Scenario, EstimatedLoop]:
    loop = scenario.estimated_loop
    if loop is None:
        raise SpecificationError(
            f"{estimator_options_given(args)[0]} applies to a scenario with an [estimator] table (the sensors and "
            "the estimator of the estimated loop)"
        )
    others = [option for option, name in _OTHER_OPTIONS if getattr(args, name, None) is not None]
    others += ["--predictor"] if getattr(args, "predictor", False) else []
    if others:
        raise SpecificationError(
            f"{others[0]} does not apply to a scenario with an [estimator] table: the estimated loop flies the PD law "
            "on the estimate without actuator limits, disturbance, delay jitter, predictor, reference or wheels"
        )
    if getattr(args, "hysteresis", None) is not None:
        try:
            scenario = replace(scenario, rule=Hysteretic(args.hysteresis))
        except SpecificationError as exc:
            raise SpecificationError(f"--hysteresis: {exc}") from exc
    sensors, estimator = loop.sensors, loop.estimator
    if args.noise_seed is not None:
        sensors = Sensors(sensors.star_tracker, sensors.gyro, seed=integer("--noise-seed", args.noise_seed, minimum=0))
    if getattr(args, "estimator", None) is not None:
        estimator = replace(estimator, kind=args.estimator)
    loop = EstimatedLoop(sensors, estimator)
    return replace(scenario, estimated_loop=loop), loop


def attitude_sigma(result: EstimatedResult, loop: EstimatedLoop) -> np.ndarray:
    """(N, 3) the filter's 1σ of the attitude error rotation δθ (rad) about each axis: the covariance's
    attitude block, mapped from the MRP error δσ = ¼ B(σ̂) δθ for the MRP-EKF."""
    block = result.covariance[:, :3, :3]
    if loop.estimator.kind is EstimatorKind.MRP_EKF:
        mapping = 4 * b_matrix_inverse(result.sigma_hat)  # δθ = 4 B(σ̂)⁻¹ δσ
        block = mapping @ block @ np.transpose(mapping, (0, 2, 1))
    return np.sqrt(np.diagonal(block, axis1=1, axis2=2))


def _summary(result: EstimatedResult, loop: EstimatedLoop) -> dict[str, Any]:
    error = result.estimation_error
    sigma = attitude_sigma(result, loop)
    half = result.t >= 0.5 * result.t[-1]
    return {
        "estimator": EstimatorKind(loop.estimator.kind).value,
        "rate": result.rate,
        "t_final": float(result.t[-1]),
        "switches": result.switches,
        "settling_time": result.settling_time(SETTLED),
        "settling_attitude_rad": SETTLED,
        "final_pointing_arcsec": float(result.pointing_error[-1]) / ARCSEC,
        "pointing_rms_arcsec": result.pointing_rms(0.5 * float(result.t[-1])) / ARCSEC,
        "estimation_error_rms_arcsec": float(np.sqrt(np.mean(np.sum(error[half] ** 2, axis=1)))) / ARCSEC,
        "filter_sigma_rms_arcsec": float(np.sqrt(np.mean(np.sum(sigma[half] ** 2, axis=1)))) / ARCSEC,
        "final_sigma": result.sigma[-1],
        "final_omega": result.omega[-1],
        "final_bias": result.bias[-1],
        "final_bias_hat": result.bias_hat[-1],
        "diverged": not bool(np.all(np.isfinite(result.sigma))),
    }


def _text(summary: dict[str, Any]) -> str:
    settling = summary["settling_time"]
    settled = (
        f"not settled within {SETTLED:g} rad"
        if math.isnan(settling)
        else f"settled within {SETTLED:g} rad at {settling:.2f} s"
    )
    return "\n".join(
        (
            f"estimated loop ({summary['estimator']}) at {summary['rate']:g} Hz over {summary['t_final']:g} s, "
            f"{summary['switches']} switch(es)",
            f"  pointing: {settled}; final {summary['final_pointing_arcsec']:.2f} "
            f"arcsec, RMS over the last half {summary['pointing_rms_arcsec']:.2f} arcsec",
            f"  estimation error RMS over the last half {summary['estimation_error_rms_arcsec']:.2f} arcsec "
            f"(the filter's 1 sigma: {summary['filter_sigma_rms_arcsec']:.2f} arcsec)",
            f"  bias: estimated {np.round(summary['final_bias_hat'], 8).tolist()} rad/s, "
            f"true {np.round(summary['final_bias'], 8).tolist()} rad/s",
        )
    )


def simulate_estimated_scenario(
    scenario: Scenario, args: argparse.Namespace, scenario_summary: Callable[[Scenario], dict[str, Any]]
) -> int:
    """``mrpctl simulate`` of an [estimator] scenario (``scenario_summary`` its JSON part); the exit code."""
    scenario, loop = _apply(scenario, args)
    check_plot_path(args.plot)
    check_run_fits(scenario)
    result = scenario.simulate_estimated()
    summary = _summary(result, loop)
    files: dict[str, Path] = {}
    if args.plot is not None:
        # deferred: matplotlib (through mrpctl.plots), only for --plot
        from mrpctl import plots

        sigma = attitude_sigma(result, loop)
        figure = plots.plot_estimation_error(result.t, result.estimation_error, sigma, title=scenario.name)
        files["plot"] = save_plot(figure, Path(args.plot))
    if args.csv is not None:
        path = Path(args.csv)
        parts = (result.sigma, result.omega, result.sigma_hat, result.omega_hat, result.bias, result.bias_hat)
        rows = np.column_stack((result.t, *parts, result.u))
        with atomic_output(path) as stream:
            stream.write(",".join(_CSV_HEADER) + "\n")
            np.savetxt(stream, rows, delimiter=",", fmt="%.17g")
        files["csv"] = path
    if args.json:
        body = scenario_summary(scenario) | {"estimated_loop": str(scenario.estimated_loop)}
        print_json({"scenario": body, "result": summary, "files": files})
    else:
        print(scenario)
        print(_text(summary))
        if "plot" in files:
            print(f"plot (estimation error with its 3 sigma envelope) written to {files['plot']}")
        if "csv" in files:
            print(f"trajectory written to {files['csv']}")
    if summary["diverged"] and args.fail_on_divergence:
        print("mrpctl: the estimated loop diverged", file=sys.stderr)
        return EXIT_DIVERGED
    return 0
