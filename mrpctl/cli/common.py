"""What every ``mrpctl`` subcommand shares: the exit codes, the parser and its common options, the output
files and JSON, and the mapping of errors to exit codes.

A subcommand's handler is a function ``handler(args) -> int``; `run_command` runs it, turns every
[MrpctlError][mrpctl.MrpctlError] and `OSError` into one line on stderr and exit code 2, prints warnings
on one line, and ends quietly when the output pipe is closed.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import sys
import tempfile
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO, Any, NoReturn, TextIO

import numpy as np

from mrpctl.design import FlownVerdict
from mrpctl.errors import MrpctlError, SpecificationError
from mrpctl.predictor import PredictorForm
from mrpctl.scenario import RULE_NAMES

__all__ = [
    "EXIT_BROKEN_PIPE",
    "EXIT_CODES",
    "EXIT_DIVERGED",
    "EXIT_INTERRUPTED",
    "NOT_VERIFIED",
    "USER_ERROR",
    "VERIFY_EXIT_CODES",
    "Formatter",
    "Parser",
    "add_flight_options",
    "add_json",
    "add_plant_options",
    "add_rule_options",
    "add_run_options",
    "atomic_output",
    "check_plot_path",
    "joint_json",
    "jsonable",
    "options_given",
    "print_json",
    "refuse_existing",
    "run_command",
    "save_plot",
]


#: Exit code of a run that diverged when ``--fail-on-divergence`` was given.
EXIT_DIVERGED = 1
#: Exit code of ``verify`` when the checks ran and the loop is not verified (or not stable).
NOT_VERIFIED = 1
#: Exit code for a user error (bad input, missing file, a request that would not fit): one line, no traceback.
USER_ERROR = 2
#: Exit code after Ctrl-C (128 + SIGINT, the shell's convention).
EXIT_INTERRUPTED = 130
#: Exit code when the reader of stdout went away (128 + SIGPIPE, as ``yes | head`` gives).
EXIT_BROKEN_PIPE = 141


EXIT_CODES = """\
exit codes:
  0    success (a diverged run is a result: 0 unless simulate or sweep was given --fail-on-divergence)
  1    simulate, sweep: a run diverged and --fail-on-divergence was given
  2    user error: bad option or scenario, missing file, no certified gains, a request that would not fit
  130  interrupted (Ctrl-C); no half-written output file is left
  141  the output pipe was closed (mrpctl ... | head)
"""

VERIFY_EXIT_CODES = """\
exit codes:
  0    checked: the loop as flown is VERIFIED (one certificate covers it jointly) and, with tau > 0,
       at least one LMI criterion certifies the idealised loop at tau; a tracking scenario ([reference]):
       every check of its linearised loop holds and nothing is listed as not covered (a local verdict:
       the loop about its reference motion; no region of attraction is certified)
  1    checked, but not verified: the joint verdict is PARTIAL, NOT_CERTIFIED or UNSTABLE, or no
       criterion certifies the idealised loop at tau (the output says which and why); a tracking
       scenario ([reference]) whose linearised loop fails a check, or has a part no check covers
  2    user error: bad option or scenario, missing file, a request that would not fit
  130  interrupted (Ctrl-C)
  141  the output pipe was closed (mrpctl ... | head)
"""


class Formatter(argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter):
    """Shows "(default: ...)" for options with a real default; keeps the exit-code epilog as written."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        if action.default in (None, False) or action.default is argparse.SUPPRESS:
            return action.help
        return super()._get_help_string(action)


class Parser(argparse.ArgumentParser):
    """argparse's parser whose usage errors are one line (the command, the problem, where the help is) and exit 2,
    like every other bad input of the command line; argparse itself prints the whole usage first."""

    def error(self, message: str) -> NoReturn:
        text = " ".join(message.split())
        self.exit(USER_ERROR, f"{self.prog}: error: {text} (see {self.prog} --help)\n")


def add_json(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print the results as one JSON object on stdout")


def add_rule_options(parser: argparse.ArgumentParser, what: str = "override the scenario's switching rule") -> None:
    parser.add_argument("--rule", choices=sorted(RULE_NAMES), help=what)
    parser.add_argument("--eps", type=float, help="boundary layer thickness (with --rule boundary-layer)")
    parser.add_argument(
        "--alpha",
        type=float,
        help="switching threshold >= 1 (with --rule delay-aware, hysteretic or on-predicted; default 1)",
    )


def add_run_options(parser: argparse.ArgumentParser, *, plot: str, csv: str) -> None:
    """Overrides of a scenario's rule, delay, horizon and history, and the output files."""
    add_rule_options(parser)
    parser.add_argument("--tau", type=float, help="override the delay (s)")
    parser.add_argument("--t-final", type=float, help="override the horizon (s)")
    parser.add_argument("--rate", type=float, help="override the measurement rate (Hz)")
    parser.add_argument("--history", choices=("constant", "zero-input"), help="override the history")
    parser.add_argument("--substeps", type=int, help="override the RK4 substeps per sample")
    parser.add_argument(
        "--settling-attitude",
        type=float,
        metavar="DEG",
        help="settled: principal angle below DEG (default 2.2918 = 4 atan(0.01), i.e. |sigma| < 0.01)",
    )
    parser.add_argument(
        "--settling-rate", type=float, metavar="RAD_S", help="settled: |omega| below RAD_S (default 1e-3 rad/s)"
    )
    parser.add_argument("--plot", type=Path, help=plot + " (format from the suffix: .png, .pdf, .svg, ...)")
    parser.add_argument("--csv", type=Path, help=csv)
    parser.add_argument(
        "--fail-on-divergence", action="store_true", help=f"exit with code {EXIT_DIVERGED} when a run diverged"
    )
    add_json(parser)


def add_flight_options(parser: argparse.ArgumentParser) -> None:
    """The loop as flown (design/flight.md): controller-side rule, actuator, sensor, disturbance, jitter."""
    flown = parser.add_argument_group(
        "the loop as flown (controller-side set selection; the models need --hysteresis or a hysteretic scenario)"
    )
    flown.add_argument(
        "--hysteresis", type=float, metavar="DELTA", help="controller-side rule with hysteresis delta in [0, 1) on q0"
    )
    flown.add_argument(
        "--torque-limit", type=float, nargs="+", metavar="U", help="per-axis torque limit: 1 or 3 values (N m)"
    )
    flown.add_argument("--torque-norm", type=float, metavar="U", help="limit on |u| (N m), with --torque-limit")
    flown.add_argument(
        "--saturation", choices=("scale", "clip"), help="saturation mode (default scale: direction kept)"
    )
    flown.add_argument("--attitude-noise", type=float, metavar="RAD", help="attitude noise, 1 sigma per axis (rad)")
    flown.add_argument("--rate-noise", type=float, metavar="RAD_S", help="white rate noise, 1 sigma per axis (rad/s)")
    flown.add_argument("--gyro-bias", type=float, nargs=3, metavar="B", help="constant gyro bias (rad/s)")
    flown.add_argument("--noise-seed", type=int, help="seed (>= 0) of the sensor noise")
    flown.add_argument("--disturbance", type=float, nargs=3, metavar="W", help="constant body-frame torque (N m)")
    flown.add_argument(
        "--disturbance-file",
        metavar="F",
        help="per-sample body-frame torque: a .csv or .npy file of n = floor(t_final * rate) + 1 rows of 3 (N m)",
    )
    flown.add_argument(
        "--delay-file",
        metavar="F",
        help="per-sample delay sequence: a .csv or .npy file of n delays (s), each a whole number of periods in "
        "[1/rate, tau]",
    )
    flown.add_argument(
        "--jitter",
        type=float,
        nargs=2,
        metavar=("TMIN", "TMAX"),
        help="seeded random delay uniform over the whole periods in [TMIN, TMAX] (s); sets tau = TMAX",
    )
    flown.add_argument("--jitter-seed", type=int, help="seed (>= 0) of the delay jitter (default 0)")
    predicted = parser.add_argument_group(
        "delay compensation (design/predictor.md): u = K x_hat, the state predicted by the controller's model; "
        "each option selects the rule on-predicted (--alpha A: switch when |sigma_hat| >= A, default 1; inf: never)"
    )
    predicted.add_argument("--predictor", action="store_true", help="the predictor controller, model = the plant")
    predicted.add_argument(
        "--predictor-inertia",
        type=float,
        nargs="+",
        metavar="J",
        help="the predictor with this model inertia: 3 principal values or 9 (3x3, row by row; kg m^2)",
    )
    predicted.add_argument(
        "--predictor-error",
        type=float,
        nargs="+",
        metavar="E",
        help="the predictor with the model J_m = J / (1 + E) of the plant J (J = (1 + E) J_m): 1 value, or 3 per axis",
    )
    predicted.add_argument(
        "--predictor-form",
        choices=[form.value for form in PredictorForm],
        help="the predictor's form: nonlinear (default; the model copy by RK4, corrected on the rotation group) or "
        "linear (the linearised copy, the FSA increment on the group: cheaper, exact about a fixed axis only)",
    )


def add_plant_options(parser: argparse.ArgumentParser, default: str) -> None:
    parser.add_argument(
        "--inertia",
        type=float,
        nargs="+",
        metavar="J",
        help=f"3 principal inertias or 9 entries of J row by row (kg m^2); default {default}",
    )
    parser.add_argument(
        "--k-sigma",
        type=float,
        nargs="+",
        metavar="KS",
        help="attitude gain: 1 value (k I3) or 3 per axis; K = [diag(k_sigma), diag(k_omega)] (N m)",
    )
    parser.add_argument(
        "--k-omega", type=float, nargs="+", metavar="KW", help="rate gain on omega/4: 1 value or 3 per axis (N m)"
    )
    parser.add_argument(
        "--K",
        type=float,
        nargs="+",
        metavar="Kij",
        help="the full 3x6 gain on x = [sigma; omega/4]: 18 numbers K11 ... K16 K21 ... K36, row by row (N m)",
    )
    parser.add_argument(
        "--attitude-gain",
        type=float,
        nargs="+",
        metavar="P",
        help="physical PD gains u = -P_sigma sigma - P_omega omega (Basilisk's mrpFeedback K, P; with --rate-gain): "
        "the attitude gain P_sigma (N m), 1 value or 3 per axis (> 0) or 9 (3x3, row by row); K = [-P_sigma, "
        "-4 P_omega]",
    )
    parser.add_argument(
        "--rate-gain",
        type=float,
        nargs="+",
        metavar="P",
        help="the rate gain P_omega (N m s, on omega in rad/s) with --attitude-gain: 1, 3 or 9 values",
    )


def options_given(*options: tuple[str, object]) -> list[str]:
    """The names of the (name, value) options whose value is not None (the ones given)."""
    return [option for option, value in options if value is not None]


def flown_options_given(args: argparse.Namespace, *, no_flown: bool = True) -> list[str]:
    """The loop-as-flown options of ``verify`` that were given (with ``no_flown``, ``--no-flown`` too)."""
    return options_given(
        ("--jitter", args.jitter),
        ("--jitter-rate", args.jitter_rate),
        ("--sampled", args.sampled),
        ("--inertia-tolerance", args.inertia_tolerance),
        ("--product-bound", args.product_bound),
        *((("--no-flown", args.no_flown or None),) if no_flown else ()),
    )


@contextlib.contextmanager
def atomic_output(path: Path, mode: str = "w") -> Iterator[IO[Any]]:
    """Open a temporary sibling of ``path`` for writing; move it onto ``path`` only when the block succeeds."""
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".partial", dir=path.parent)
    try:
        stream: IO[Any] = (
            os.fdopen(handle, mode) if "b" in mode else os.fdopen(handle, mode, encoding="utf-8", newline="")
        )
        with stream:
            yield stream
        os.replace(temporary, path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(temporary)


def refuse_existing(path: Path, overwrite: bool, option: str) -> None:
    if path.exists() and not overwrite:
        raise SpecificationError(f"{option} {path} already exists; choose another name or pass --overwrite")


def check_plot_path(path: Path | None) -> None:
    """Refuse an image format matplotlib cannot write before any work is done."""
    if path is None:
        return
    # deferred: matplotlib, only for --plot
    from matplotlib.figure import Figure

    formats = Figure().canvas.get_supported_filetypes()
    suffix = path.suffix.lower().lstrip(".")
    if suffix not in formats:
        raise SpecificationError(
            f"--plot {path}: unknown image format {suffix or '(no suffix)'!r}; use one of {', '.join(sorted(formats))}"
        )


def save_plot(figure: Any, path: Path) -> Path:
    """Write ``figure`` with [save_figure][mrpctl.plots.save_figure] to a temporary sibling, then `os.replace` it."""
    # deferred: matplotlib (through mrpctl.plots), only for --plot
    from mrpctl import plots

    path.parent.mkdir(parents=True, exist_ok=True)
    handle, name = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".partial{path.suffix}", dir=path.parent)
    os.close(handle)
    try:
        plots.save_figure(figure, name)
        os.replace(name, path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(name)
    return path


def jsonable(value: Any) -> Any:
    """Plain JSON values: arrays to lists, NaN and inf to null, enums to their value."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, Path):
        return str(value)
    if value is None or isinstance(value, str):
        return value
    return str(value)


def joint_json(verdict: FlownVerdict) -> dict[str, Any]:
    """The JSON of a joint verdict on the loop as flown (``verify``'s ``joint``, ``design``'s ``written_verdict``)."""
    witness = verdict.witness
    return {
        "status": verdict.status.name,
        "verified": verdict.verified,
        "flown": verdict.flown,
        "not_covered": list(verdict.not_covered),
        "spectral_radius": verdict.spectral_radius,
        "witness": None
        if witness is None
        else {
            "inertia": np.array(witness.inertia).reshape(3, 3),
            "delay": witness.delay,
            "delay_samples": witness.delay_samples,
            "spectral_radius": witness.spectral_radius,
            "text": witness.text,
        },
        "checks": [
            {
                "name": c.name,
                "kind": c.kind.name,
                "outcome": c.outcome.name,
                "joint": c.joint,
                "covers": c.covers,
                "spectral_radius": c.spectral_radius,
                "detail": c.detail,
            }
            for c in verdict.checks
        ],
    }


def print_json(payload: dict[str, Any]) -> None:
    print(json.dumps(jsonable(payload), indent=2, allow_nan=False))


def _show_warning(
    message: Warning | str,
    category: type[Warning],
    filename: str,
    lineno: int,
    file: TextIO | None = None,
    line: str | None = None,
) -> None:
    """Warnings on one line without a file path: ``mrpctl: warning: ... (InertiaWarning)``."""
    text = " ".join(str(message).split())
    stream = sys.stderr if file is None else file
    with contextlib.suppress(OSError, ValueError):
        stream.write(f"mrpctl: warning: {text} ({category.__name__})\n")


def _silence_stdout() -> None:
    """After a broken pipe: point stdout at /dev/null so the interpreter's final flush stays quiet."""
    with contextlib.suppress(AttributeError, OSError, ValueError):
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())


def run_command(handler: Callable[[argparse.Namespace], int], args: argparse.Namespace) -> int:
    """``handler(args)``, with its errors mapped to the exit codes of `EXIT_CODES`.

    A [MrpctlError][mrpctl.MrpctlError] or an `OSError` is one line on stderr and `USER_ERROR`; Ctrl-C is
    `EXIT_INTERRUPTED`; a closed output pipe is `EXIT_BROKEN_PIPE`, quietly; warnings are one line each.
    """
    with warnings.catch_warnings():
        warnings.showwarning = _show_warning
        try:
            code = int(handler(args))
            sys.stdout.flush()
            return code
        except BrokenPipeError:
            _silence_stdout()
            return EXIT_BROKEN_PIPE
        except KeyboardInterrupt:
            print("mrpctl: interrupted", file=sys.stderr)
            return EXIT_INTERRUPTED
        except (MrpctlError, OSError) as exc:
            message = " ".join(str(exc).split())
            print(f"mrpctl: error: {message}", file=sys.stderr)
            return USER_ERROR
