"""``mrpctl simulate`` and ``mrpctl sweep``: one closed-loop run, and batches over eps, tau or tumbling
initial states, with their tables, plots and JSON."""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm  # type: ignore[import-untyped]

from mrpctl import paper
from mrpctl._scenario_steering import check_steering_scenario, steering_json
from mrpctl._scenario_wheels import check_wheel_scenario
from mrpctl._validation import integer
from mrpctl.cli.common import (
    EXIT_CODES,
    EXIT_DIVERGED,
    Formatter,
    add_flight_options,
    add_plant_options,
    add_run_options,
    atomic_output,
    check_plot_path,
    options_given,
    print_json,
    save_plot,
)
from mrpctl.cli.estimated import add_estimator_options, estimator_options_given, simulate_estimated_scenario
from mrpctl.cli.limits import check_run_fits, check_sweep_fits
from mrpctl.cli.overrides import apply_flight_options, apply_overrides, scenario_from_args
from mrpctl.cli.wheels import (
    add_wheel_options,
    check_wheel_options,
    wheel_lines,
    wheel_summary,
    wheels_json,
)
from mrpctl.conventions import state_parts
from mrpctl.design import linearized_loop
from mrpctl.errors import SpecificationError
from mrpctl.predictor import OnPredicted
from mrpctl.rules import DEFAULT_DELTA
from mrpctl.scenario import Scenario, rule_name, shipped_scenarios, tumbling_states
from mrpctl.simulation import BatchResult, SimulationResult, simulate_batch
from mrpctl.switching import BoundaryLayer
from mrpctl.wheels import rest_momentum_load

__all__ = ["add_simulate", "add_sweep"]


_CSV_HEADER = (
    "t_s",
    "sigma1",
    "sigma2",
    "sigma3",
    "omega1_rad_s",
    "omega2_rad_s",
    "omega3_rad_s",
    "u1_Nm",
    "u2_Nm",
    "u3_Nm",
)


def _result_summary(result: SimulationResult) -> dict[str, Any]:
    return {
        "tau": result.tau,
        "rate": result.rate,
        "t_final": result.t_final,
        "rule": rule_name(result.rule),
        "switch_count": result.switch_count,
        "first_switch_time": result.first_switch_time,
        "last_switch_time": result.last_switch_time,
        "sign_flips": result.sign_flips,
        "max_sigma": result.max_sigma,
        "settling_time": result.settling_time,
        "settling_attitude_deg": result.settling_attitude,
        "settling_rate": result.settling_rate,
        "converged": result.converged,
        "diverged": result.diverged,
        "final_sigma": result.sigma[-1],
        "final_omega": result.omega[-1],
        "saturated_fraction": result.saturated_fraction,
        "peak_command": result.peak_command,
        **(
            {}
            if result.error_time is None
            else {
                "error_time": result.error_time.value,
                "feedforward": result.feedforward,
                "pointing_max_deg": result.pointing_max,
                "pointing_rms_deg": result.pointing_rms,
                "slew_time": result.slew_time,
                "pointing_tolerance_deg": result.pointing_tolerance,
            }
        ),
    }


def _scenario_summary(scenario: Scenario) -> dict[str, Any]:
    return {
        "name": scenario.name,
        "inertia": scenario.spacecraft.inertia,
        "K": scenario.K,
        "attitude_gain": scenario.gains.attitude,
        "rate_gain": scenario.gains.rate,
        "sigma0": scenario.sigma0,
        "omega0": scenario.omega0,
        "tau": scenario.tau,
        "rate": scenario.rate,
        "t_final": scenario.t_final,
        "rule": rule_name(scenario.rule),
        "rule_repr": str(scenario.rule),
        "history": scenario.history,
        "substeps": scenario.substeps,
        "flight_models": {name: str(model) for name, model in scenario.flight_options.items()},
        "predictor_inertia": None if scenario.predictor is None else scenario.predictor.model.inertia,
        "predictor_form": None if scenario.predictor is None else scenario.predictor.form.value,
        "wheels": wheels_json(scenario),
        "reference": None if scenario.reference is None else str(scenario.reference),
        "steering": None if scenario.law is None else steering_json(scenario.law),
    }


def _simulate(args: argparse.Namespace) -> int:
    scenario = apply_overrides(scenario_from_args(args, file=args.scenario), args)
    if scenario.estimated_loop is not None or estimator_options_given(args):
        return simulate_estimated_scenario(scenario, args, _scenario_summary)
    scenario = apply_flight_options(scenario, args)
    check_plot_path(args.plot)
    check_plot_path(args.pointing_plot)
    if args.pointing_plot is not None and scenario.reference is None:
        raise SpecificationError(
            "--pointing-plot draws a tracking run's pointing error: give a scenario with a [reference] table"
        )
    check_wheel_options(scenario, args)
    check_steering_scenario(
        scenario.law, scenario.rule, scenario.K, predictor=scenario.predictor, reference=scenario.reference
    )
    check_run_fits(scenario)
    result = scenario.simulate()
    files: dict[str, Path] = {}
    if args.plot is not None or args.pointing_plot is not None or args.wheels_plot is not None:
        # deferred: matplotlib (through mrpctl.plots), only for --plot / --pointing-plot / --wheels-plot
        from mrpctl import plots

        if args.plot is not None:
            files["plot"] = save_plot(plots.plot_response(result), Path(args.plot))
        if args.pointing_plot is not None:
            files["pointing_plot"] = save_plot(plots.plot_pointing(result), Path(args.pointing_plot))
        if args.wheels_plot is not None:  # a wheel scenario (check_wheel_options)
            files["wheels_plot"] = save_plot(plots.plot_wheels(result), Path(args.wheels_plot))
    if args.csv is not None:
        path = Path(args.csv)
        rows = np.column_stack((result.t, result.sigma, result.omega, result.u))
        with atomic_output(path) as stream:
            stream.write(",".join(_CSV_HEADER) + "\n")
            np.savetxt(stream, rows, delimiter=",", fmt="%.17g")
        files["csv"] = path
    if args.json:
        summary = {**_result_summary(result), "wheels": wheel_summary(result)}
        print_json({"scenario": _scenario_summary(scenario), "result": summary, "files": files})
    else:
        print(scenario)
        print(result)
        print(*wheel_lines(result), sep="\n")
        if "wheels_plot" in files:
            print(f"wheel plot written to {files['wheels_plot']}")
        if "plot" in files:
            print(f"plot written to {files['plot']}")
        if "pointing_plot" in files:
            print(f"pointing error plot written to {files['pointing_plot']}")
        if "csv" in files:
            print(f"trajectory written to {files['csv']}")
    if result.diverged and args.fail_on_divergence:
        print(f"mrpctl: run diverged at t = {result.t[-1]:.3f} s", file=sys.stderr)
        return EXIT_DIVERGED
    return 0


def add_simulate(commands: Any) -> None:
    names = ", ".join(shipped_scenarios())
    parser = commands.add_parser(
        "simulate",
        help="simulate a scenario file, or a run given by options",
        description=(
            "Simulate one closed-loop run: a scenario file, a shipped scenario by name "
            f"({names}), or without a file the paper's example (rule hysteretic, delta = {DEFAULT_DELTA:g}) changed by "
            "--inertia, the gains (--attitude-gain/--rate-gain in physical form, or the paper's "
            "--K/--k-sigma/--k-omega), --sigma/--omega (rad/s) and the run options."
        ),
        formatter_class=Formatter,
        epilog=EXIT_CODES,
    )
    parser.add_argument("scenario", nargs="?", help="scenario TOML or shipped name")
    add_plant_options(parser, "the paper's 140 100 80 (or the scenario's)")
    parser.add_argument("--sigma", type=float, nargs=3, metavar="S", help="initial MRPs sigma0 (overrides the file)")
    parser.add_argument("--omega", type=float, nargs=3, metavar="W", help="initial body rates omega0 (rad/s)")
    add_run_options(
        parser, plot="write sigma, omega, u against t to this image", csv="write the trajectory to this CSV"
    )
    parser.add_argument(
        "--pointing-plot",
        type=Path,
        metavar="FILE",
        help="a tracking scenario ([reference]): write the pointing error (deg, log scale, tolerance band) to this "
        "image",
    )
    add_flight_options(parser)
    add_estimator_options(parser)
    add_wheel_options(parser)
    parser.set_defaults(handler=_simulate)


_SWEEP_HEADER = (
    "value",
    "sigma0_1",
    "sigma0_2",
    "sigma0_3",
    "omega0_1_rad_s",
    "omega0_2_rad_s",
    "omega0_3_rad_s",
    "switches",
    "last_switch_s",
    "settling_s",
    "converged",
    "diverged",
    "max_abs_sigma",
)


def progress(total: int, label: str) -> Any:
    """A tqdm bar on stderr, silent when stderr is not a terminal (no ``\\r`` frames into a pipe or file)."""

    stream = sys.stderr
    tty = bool(getattr(stream, "isatty", lambda: False)())
    return tqdm(total=total, desc=label, file=stream, disable=not tty, leave=True, unit="run")


def _sweep_runs(args: argparse.Namespace, base: Scenario) -> tuple[np.ndarray, str, list[dict[str, Any]]]:
    """The swept values, their label and one dict of changes per run; refuses options that do not apply."""
    tumble_options = options_given(
        ("--count", args.count),
        ("--seed", args.seed),
        ("--angle-range", args.angle_range),
        ("--rate-range", args.rate_range),
        ("--cross-rate", args.cross_rate),
    )
    if args.parameter != "tumble" and tumble_options:
        raise SpecificationError(f"{tumble_options[0]} applies only to 'sweep tumble', not to 'sweep {args.parameter}'")
    if args.parameter == "eps":
        for option, value in (("--rule", args.rule), ("--eps", args.eps), ("--alpha", args.alpha)):
            if value is not None:
                raise SpecificationError(
                    f"{option} does not apply to 'sweep eps': every run uses the boundary-layer rule with the swept eps"
                )
        values = np.asarray(args.values or paper.EPS_STUDY, dtype=float)

        return values, "boundary layer thickness eps (-)", [{"rule": BoundaryLayer(eps=v)} for v in values]
    if args.parameter == "tau":
        if args.tau is not None:
            raise SpecificationError("--tau does not apply to 'sweep tau': give the delays with --values")
        if not args.values:
            raise SpecificationError("sweep tau needs --values (delays in s)")
        values = np.asarray(args.values, dtype=float)
        return values, "delay tau (s)", [{"tau": float(v)} for v in values]
    if args.values:
        raise SpecificationError("--values does not apply to 'sweep tumble': use --count, --angle-range, --rate-range")
    count = integer("--count", 50 if args.count is None else args.count, minimum=1)
    check_sweep_fits(base, count, [base.tau], integer("--chunk", args.chunk, minimum=1))
    states = tumbling_states(
        count,
        seed=0 if args.seed is None else args.seed,
        angle_deg=(160.0, 179.0) if args.angle_range is None else tuple(args.angle_range),
        body_rate=(0.5, 1.2) if args.rate_range is None else tuple(args.rate_range),
        cross_rate=0.05 if args.cross_rate is None else args.cross_rate,
    )
    return np.arange(count, dtype=float), "tumbling initial state (run index)", [{"x0": x} for x in states]


def _wheel_loads(base: Scenario, runs: list[dict[str, Any]]) -> np.ndarray | None:
    """Each run's wheel momentum load at rest at the origin (`rest_momentum_load`), or None.

    Only where the total momentum is conserved and the target is the origin: a wheel scenario
    without a reference, a disturbance or the gravity gradient.
    """
    if base.wheels is None or base.reference is not None or base.disturbance is not None or base.gravity_gradient:
        return None
    sigma, omega = state_parts(np.array([r.get("x0", base.x0) for r in runs]))
    return rest_momentum_load(base.wheels, base.spacecraft.inertia, sigma, omega)


def _sweep(args: argparse.Namespace) -> int:
    base = scenario_from_args(args, file=args.scenario or None)
    if base.estimated_loop is not None:
        raise SpecificationError(
            "sweep does not fly the estimated loop of an [estimator] scenario (one compiled run per case): run "
            "mrpctl simulate once per case (--noise-seed N), or mrpctl.simulation.estimated.simulate_estimated "
            "from Python"
        )
    if args.parameter == "tau" and (base.delay is not None or args.jitter is not None or args.delay_file is not None):
        raise SpecificationError(
            "sweep tau with a jittering delay (the scenario's [delay], --jitter or --delay-file): the delay model "
            "fixes every run's delay (tau = its tau_max); sweep tau without it, or run mrpctl simulate --jitter "
            "TMIN TMAX once per delay window"
        )
    base = apply_overrides(base, args)
    if base.predictor is not None or isinstance(base.rule, OnPredicted):
        raise SpecificationError(
            "sweep does not run the predictor (rule 'on-predicted') yet; use mrpctl simulate, or "
            "mrpctl.simulate_batch(..., predictor=mrpctl.Predictor(model)) from Python"
        )
    base = apply_flight_options(base, args)
    check_plot_path(args.plot)
    chunk = integer("--chunk", args.chunk, minimum=1)
    values, label, runs = _sweep_runs(args, base)
    check_wheel_scenario(base.wheels, runs[0].get("rule", base.rule), actuator=base.actuator, reference=base.reference)
    check_steering_scenario(base.law, runs[0].get("rule", base.rule), base.K, reference=base.reference)
    check_sweep_fits(base, len(runs), [r.get("tau", base.tau) for r in runs], chunk)
    loads = _wheel_loads(base, runs)
    rows: list[tuple[Any, ...]] = []
    batches: list[Any] = []
    with progress(len(runs), f"sweep {args.parameter}") as bar:
        for start in range(0, len(runs), chunk):
            part = runs[start : start + chunk]
            x0 = np.array([r.get("x0", base.x0) for r in part])
            batch = simulate_batch(
                base.spacecraft,
                base.K,
                x0,
                tau=[r.get("tau", base.tau) for r in part],
                rule=[r.get("rule", base.rule) for r in part],
                t_final=base.t_final,
                rate=base.rate,
                history=base.history,
                substeps=base.substeps,
                settling_attitude=base.settling_attitude,
                settling_rate=base.settling_rate,
                **base.flight_options,  # a flight scenario's models, shared by the runs
                wheels=base.wheels,  # a shared wheel cluster, or None
                law=base.law,  # the scenario's steering law, or None (the PD law)
            )
            batches.append(batch)
            for i in range(len(part)):
                sigma0, omega0 = state_parts(x0[i])
                rows.append(
                    (
                        float(values[start + i]),
                        *(float(v) for v in sigma0),
                        *(float(v) for v in omega0),
                        int(batch.switch_count[i]),
                        float(batch.last_switch_time[i]),
                        float(batch.settling_time[i]),
                        bool(batch.converged[i]),
                        bool(batch.diverged[i]),
                        float(batch.max_sigma[i]),
                    )
                )
            bar.update(len(part))
    column = {name: i for i, name in enumerate(_SWEEP_HEADER)}
    converged = sum(bool(r[column["converged"]]) for r in rows)
    diverged = sum(bool(r[column["diverged"]]) for r in rows)
    rule_text = "BoundaryLayer(eps)" if args.parameter == "eps" else str(base.rule)
    files: dict[str, Path] = {}
    if args.plot is not None:
        # deferred: matplotlib (through mrpctl.plots), only for --plot
        from mrpctl import plots

        if args.parameter == "tumble":
            # Independent runs: distributions and a scatter against the initial state, not a line over run index.
            fig = plots.plot_monte_carlo(BatchResult.concatenate(batches))
        else:
            margin = None
            if args.parameter == "tau":
                margin = linearized_loop(base.spacecraft, base.K).delay_margin().margin
            fig = plots.plot_sweep(
                [r[0] for r in rows],
                switch_count=[r[column["switches"]] for r in rows],
                settling_time=[r[column["settling_s"]] for r in rows],
                converged=[r[column["converged"]] for r in rows],
                diverged=[r[column["diverged"]] for r in rows],
                max_sigma=[r[column["max_abs_sigma"]] for r in rows],
                parameter_label=label,
                margin=margin,
            )
        files["plot"] = save_plot(fig, Path(args.plot))
    if args.csv is not None:
        path = Path(args.csv)
        with atomic_output(path) as stream:
            writer = csv.writer(stream)
            writer.writerow(_SWEEP_HEADER)
            writer.writerows(rows)
        files["csv"] = path
    if args.json:
        print_json(
            {
                "parameter": args.parameter,
                "label": label,
                "rule": rule_text,
                "tau": base.tau,
                "t_final": base.t_final,
                "runs": [dict(zip(_SWEEP_HEADER, row, strict=True)) for row in rows],
                "converged": converged,
                "diverged": diverged,
                **({} if loads is None else {"wheel_momentum_load": [float(v) for v in loads]}),
                "files": files,
            }
        )
    else:
        shown = ("value", "switches", "last_switch_s", "settling_s", "converged", "diverged", "max_abs_sigma")
        print(f"{label}; rule {rule_text}, tau = {base.tau:g} s")
        print("  ".join(f"{h:>13}" for h in shown))
        for row in rows:
            cells = (row[column[h]] for h in shown)
            print("  ".join(f"{v:>13.6g}" if isinstance(v, float) else f"{v!s:>13}" for v in cells))
        median = np.median([r[column["switches"]] for r in rows])
        print(f"{converged}/{len(rows)} runs converged, {diverged} diverged; switches: median {median:g}")
        if loads is not None and np.any(loads > 1.0):
            beyond = int(np.sum(loads > 1.0))
            print(
                f"{beyond} of {len(rows)} runs start with more angular momentum than the wheels hold at rest "
                f"(up to {np.max(loads):.3g}x their capacity): without an external torque they cannot settle "
                "at the target, whatever the law"
            )
        if "plot" in files:
            print(f"plot written to {files['plot']}")
        if "csv" in files:
            print(f"table written to {files['csv']}")
    if diverged and args.fail_on_divergence:
        print(f"mrpctl: {diverged} of {len(rows)} runs diverged", file=sys.stderr)
        return EXIT_DIVERGED
    return 0


def add_sweep(commands: Any) -> None:
    parser = commands.add_parser(
        "sweep",
        help="batch runs over eps, tau or random tumbling initial states",
        formatter_class=Formatter,
        epilog=EXIT_CODES,
    )
    parser.add_argument("parameter", choices=("eps", "tau", "tumble"), help="what to sweep")
    parser.add_argument(
        "--scenario",
        help=(
            "base scenario TOML or shipped name "
            f"(default: the paper's example, rule hysteretic, delta = {DEFAULT_DELTA:g})"
        ),
    )
    parser.add_argument("--values", type=float, nargs="+", help="values of eps or tau (eps default: 0.001 ... 0.2)")
    parser.add_argument("--count", type=int, help="tumble: number of initial states (default 50)")
    parser.add_argument("--seed", type=int, help="tumble: seed of the initial states, >= 0 (default 0)")
    parser.add_argument(
        "--angle-range",
        type=float,
        nargs=2,
        metavar=("LOW", "HIGH"),
        help="tumble: initial principal angle range (deg; default 160 179)",
    )
    parser.add_argument(
        "--rate-range",
        type=float,
        nargs=2,
        metavar=("LOW", "HIGH"),
        help="tumble: body rate about the principal axis (rad/s; default 0.5 1.2)",
    )
    parser.add_argument("--cross-rate", type=float, help="tumble: largest rate across the axis (rad/s; default 0.05)")
    parser.add_argument("--chunk", type=int, default=25, help="runs per batch call (progress granularity)")
    add_plant_options(parser, "the paper's 140 100 80 (or the scenario's)")
    add_run_options(parser, plot="write the sweep plot to this image", csv="write the table to this CSV")
    add_flight_options(parser)
    parser.set_defaults(handler=_sweep)
