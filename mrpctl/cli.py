"""The ``mrpctl`` command: a thin layer over the public API that maps errors to exit codes."""

from __future__ import annotations

import argparse
import csv
import sys
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from mrpctl import paper
from mrpctl.errors import MrpctlError, SpecificationError
from mrpctl.scenario import RULE_NAMES, Scenario, load_scenario, rule_from_name, tumbling_states

__all__ = ["build_parser", "main"]

#: Exit code for a user error (bad input, missing file): a one-line message, no traceback.
USER_ERROR = 2


# ------------------------------------------------------------------------------ helpers
def _progress(done: int, total: int, label: str, stream: TextIO) -> None:
    width = 30
    filled = round(width * done / max(total, 1))
    stream.write(f"\r{label} [{'#' * filled}{'.' * (width - filled)}] {done}/{total}")
    if done >= total:
        stream.write("\n")
    stream.flush()


def _gain_from_args(args: argparse.Namespace) -> np.ndarray:
    if args.K is not None:
        return np.asarray(args.K, dtype=float).reshape(3, 6)
    return np.hstack((args.k_sigma * np.eye(3), args.k_omega * np.eye(3)))


def _apply_overrides(scenario: Scenario, args: argparse.Namespace) -> Scenario:
    changes: dict[str, Any] = {}
    if getattr(args, "rule", None) is not None:
        changes["rule"] = rule_from_name(args.rule, eps=args.eps, alpha=args.alpha)
    elif getattr(args, "eps", None) is not None or getattr(args, "alpha", None) is not None:
        raise SpecificationError("--eps and --alpha need --rule")
    for key in ("tau", "t_final", "history"):
        value = getattr(args, key, None)
        if value is not None:
            changes[key] = value
    return replace(scenario, **changes) if changes else scenario


def _write_csv(path: Path, header: Sequence[str], rows: Any) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        writer.writerows(rows)


# ------------------------------------------------------------------------------ commands
def _example(_: argparse.Namespace) -> int:
    print(paper.summary())
    return 0


def _reproduce(args: argparse.Namespace) -> int:
    from mrpctl.reproduction import reproduce

    result = reproduce(args.out, t_final=args.t_final)
    print(result)
    print(f"figures, claims.md and summary.json written to {args.out}")
    return 0


def _design(args: argparse.Namespace) -> int:
    from mrpctl.design import analyze_gains, synthesize_pd
    from mrpctl.spacecraft import Spacecraft

    spacecraft = Spacecraft(args.inertia)
    design = synthesize_pd(spacecraft, args.tau, zeta=args.zeta, order=args.order)
    print(design)
    print(analyze_gains(spacecraft, design.gains.K))
    return 0


def _verify(args: argparse.Namespace) -> int:
    from mrpctl.design import criterion_name, linearized_loop
    from mrpctl.spacecraft import Spacecraft

    if args.scenario is not None:
        scenario = load_scenario(args.scenario)
        spacecraft, gain, tau = scenario.spacecraft, scenario.K, scenario.tau
        if args.tau is not None:
            tau = args.tau
    else:
        spacecraft, gain = Spacecraft(args.inertia), _gain_from_args(args)
        tau = paper.TAU if args.tau is None else args.tau
    loop = linearized_loop(spacecraft, gain)
    margin = loop.delay_margin()
    print(f"{loop}; K = {(np.round(gain, 4) + 0.0).tolist()}")
    print(f"exact delay margin: {margin.margin:.6g} s (stable at tau = {tau:g} s: {margin.is_stable(tau)})")
    print(f"{'criterion':<24} {'at tau':<16} {'largest certified tau (s)':>26} {'ratio to exact':>15}")
    for order in args.orders:
        certificate = loop.certify(tau, order=order)
        search = loop.max_certified_delay(order=order)
        ratio = search.tau / margin.margin if np.isfinite(margin.margin) and margin.margin > 0 else float("nan")
        print(f"{criterion_name(order):<24} {certificate.status.name:<16} {search.tau:>26.6g} {ratio:>15.4f}")
    return 0


def _simulate(args: argparse.Namespace) -> int:
    scenario = _apply_overrides(load_scenario(args.scenario), args)
    result = scenario.simulate()
    print(scenario)
    print(result)
    if args.plot is not None:
        from mrpctl import plots

        print(f"plot written to {plots.save_figure(plots.plot_response(result), args.plot)}")
    if args.csv is not None:
        rows = np.column_stack((result.t, result.sigma, result.omega, result.u))
        _write_csv(
            Path(args.csv),
            [
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
            ],
            rows.tolist(),
        )
        print(f"trajectory written to {args.csv}")
    return 0


def _sweep(args: argparse.Namespace) -> int:
    from mrpctl.simulation import simulate_batch
    from mrpctl.switching import BoundaryLayer

    base = load_scenario(args.scenario) if args.scenario else _paper_base()
    base = _apply_overrides(base, args)
    if args.parameter == "eps":
        values = np.asarray(args.values or paper.EPS_STUDY, dtype=float)
        label, runs = "boundary layer thickness eps (-)", [{"rule": BoundaryLayer(eps=v)} for v in values]
    elif args.parameter == "tau":
        if not args.values:
            raise SpecificationError("sweep tau needs --values (delays in s)")
        values = np.asarray(args.values, dtype=float)
        label, runs = "delay tau (s)", [{"tau": v} for v in values]
    else:
        states = tumbling_states(args.count, seed=args.seed)
        values = np.arange(args.count, dtype=float)
        label, runs = "tumbling initial state (run index)", [{"x0": x} for x in states]
    rows = []
    stream = sys.stderr
    chunk = max(1, args.chunk)
    for start in range(0, len(runs), chunk):
        part = runs[start : start + chunk]
        batch = simulate_batch(
            base.spacecraft,
            base.K,
            np.array([r.get("x0", base.x0) for r in part]),
            tau=[r.get("tau", base.tau) for r in part],
            rule=[r.get("rule", base.rule) for r in part],
            t_final=base.t_final,
            rate=base.rate,
            history=base.history,
            substeps=base.substeps,
        )
        for i in range(len(part)):
            rows.append(
                (
                    float(values[start + i]),
                    int(batch.switch_count[i]),
                    float(batch.last_switch_time[i]),
                    float(batch.settling_time[i]),
                    bool(batch.converged[i]),
                    float(batch.max_sigma[i]),
                )
            )
        _progress(min(start + chunk, len(runs)), len(runs), f"sweep {args.parameter}", stream)
    header = ("value", "switches", "last_switch_s", "settling_s", "converged", "max_abs_sigma")
    print(f"{label}; rule {base.rule if args.parameter != 'eps' else 'BoundaryLayer(eps)'}, tau = {base.tau:g} s")
    print("  ".join(f"{h:>13}" for h in header))
    for row in rows:
        print("  ".join(f"{v:>13.6g}" if isinstance(v, float) else f"{v!s:>13}" for v in row))
    converged = sum(r[4] for r in rows)
    print(f"{converged}/{len(rows)} runs converged; switches: median {np.median([r[1] for r in rows]):g}")
    if args.plot is not None:
        from mrpctl import plots

        fig = plots.plot_sweep(
            [r[0] for r in rows],
            switch_count=[r[1] for r in rows],
            settling_time=[r[3] for r in rows],
            converged=[r[4] for r in rows],
            parameter_label=label,
        )
        print(f"plot written to {plots.save_figure(fig, args.plot)}")
    if args.csv is not None:
        _write_csv(Path(args.csv), header, rows)
        print(f"table written to {args.csv}")
    return 0


def _paper_base() -> Scenario:
    from mrpctl.reproduction import paper_scenarios

    return paper_scenarios()["paper_fig7_boundary_layer"]


def _export(args: argparse.Namespace) -> int:
    from mrpctl.export import export

    scenario = _apply_overrides(load_scenario(args.scenario), args)
    if args.out.exists() and any(args.out.iterdir()) and not args.overwrite:
        raise SpecificationError(f"--out {args.out} is not empty; choose a new folder or pass --overwrite")
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
    )
    print(result)
    return 0


# ------------------------------------------------------------------------------ parser
def _add_rule_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--rule", choices=sorted(RULE_NAMES), help="override the scenario's switching rule")
    parser.add_argument("--eps", type=float, help="boundary layer thickness (with --rule boundary-layer)")
    parser.add_argument("--alpha", type=float, help="switching threshold >= 1 (with --rule delay-aware)")


def _add_run_options(parser: argparse.ArgumentParser, *, plot: str, csv: str) -> None:
    """Overrides of a scenario's rule, delay, horizon and history, and the output files."""
    _add_rule_options(parser)
    parser.add_argument("--tau", type=float, help="override the delay (s)")
    parser.add_argument("--t-final", type=float, help="override the horizon (s)")
    parser.add_argument("--history", choices=("constant", "zero-input"), help="override the history")
    parser.add_argument("--plot", type=Path, help=plot)
    parser.add_argument("--csv", type=Path, help=csv)


def _add_gain_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--inertia",
        type=float,
        nargs=3,
        default=list(paper.INERTIA),
        metavar="J",
        help="principal inertias (kg m^2)",
    )
    parser.add_argument("--k-sigma", type=float, default=paper.GAIN_SIGMA, help="K = [k_sigma I3, k_omega I3]")
    parser.add_argument("--k-omega", type=float, default=paper.GAIN_OMEGA, help="K = [k_sigma I3, k_omega I3]")
    parser.add_argument("--K", type=float, nargs=18, help="full 3x6 gain, row by row (overrides --k-sigma/--k-omega)")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``mrpctl`` command."""
    parser = argparse.ArgumentParser(
        prog="mrpctl",
        description="Delayed-feedback attitude control with MRP shadow-set switching.",
    )
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    example = commands.add_parser("example", help="print the paper's example (plant, gains, state, delay)")
    example.set_defaults(handler=_example)

    reproduce = commands.add_parser("reproduce", help="run every scenario of the paper; figures and claims table")
    reproduce.add_argument("--out", type=Path, default=Path("results"), help="output folder (default: results)")
    reproduce.add_argument("--t-final", type=float, default=60.0, help="horizon of every run in s (default 60)")
    reproduce.set_defaults(handler=_reproduce)

    design = commands.add_parser("design", help="synthesize overdamped PD gains certified for a delay")
    design.add_argument(
        "--inertia", type=float, nargs=3, required=True, metavar="J", help="principal inertias (kg m^2)"
    )
    design.add_argument("--tau", type=float, required=True, help="measurement delay (s)")
    design.add_argument("--zeta", type=float, default=1.0, help="damping ratio >= 1 (default 1)")
    design.add_argument("--order", type=int, default=3, help="Bessel-Legendre LMI order (0 Jensen, 1 Wirtinger)")
    design.set_defaults(handler=_design)

    verify = commands.add_parser("verify", help="LMI verdict per criterion and the exact delay margin")
    verify.add_argument("scenario", nargs="?", type=Path, help="scenario TOML (else --inertia and gains)")
    _add_gain_options(verify)
    verify.add_argument("--tau", type=float, help="delay to certify (s); default the scenario's or 0.5")
    verify.add_argument("--orders", type=int, nargs="+", default=[0, 1, 2, 3], help="LMI orders (default 0 1 2 3)")
    verify.set_defaults(handler=_verify)

    simulate = commands.add_parser("simulate", help="simulate a scenario file")
    simulate.add_argument("scenario", type=Path, help="scenario TOML (see examples/scenarios)")
    _add_run_options(
        simulate, plot="write sigma, omega, u against t to this PNG", csv="write the trajectory to this CSV"
    )
    simulate.set_defaults(handler=_simulate)

    sweep = commands.add_parser("sweep", help="batch runs over eps, tau or random tumbling initial states")
    sweep.add_argument("parameter", choices=("eps", "tau", "tumble"), help="what to sweep")
    sweep.add_argument("--scenario", type=Path, help="base scenario TOML (default: the paper's, boundary layer)")
    sweep.add_argument("--values", type=float, nargs="+", help="values of eps or tau")
    sweep.add_argument("--count", type=int, default=50, help="number of tumbling states (default 50)")
    sweep.add_argument("--seed", type=int, default=0, help="seed of the tumbling states (default 0)")
    sweep.add_argument("--chunk", type=int, default=25, help="runs per batch call (progress granularity)")
    _add_run_options(sweep, plot="write the sweep plot to this PNG", csv="write the table to this CSV")
    sweep.set_defaults(handler=_sweep)

    export = commands.add_parser("export", help="export the closed loop as CasADi functions and C code")
    export.add_argument("scenario", type=Path, help="scenario TOML (spacecraft, gains, tau, rate, rule)")
    export.add_argument("--out", type=Path, required=True, help="output folder")
    export.add_argument("--overwrite", action="store_true", help="replace a non-empty output folder")
    export.add_argument("--no-compile", action="store_true", help="write sources only, no shared library")
    _add_rule_options(export)
    export.add_argument("--tau", type=float, help="override the delay (s)")
    export.set_defaults(handler=_export)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code (0 success, 2 user error)."""
    args = build_parser().parse_args(argv)
    try:
        return int(args.handler(args))
    except (MrpctlError, OSError) as exc:
        print(f"mrpctl: error: {exc}", file=sys.stderr)
        return USER_ERROR


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
